"""The allowed-grasp oracle of protocol v2 on constructed scenes (coal on the true shapes)."""

from __future__ import annotations

import math

import numpy as np

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.robots.fk import forward_kinematics
from baseplace.sim.scenes import Plane, Scene, SceneObject, SceneSettings
from baseplace_experiments.allowed_grasps import AllowedGrasps, scene_solids
from baseplace_experiments.table_grid import RobotShapes
from conftest import run_cli

FLOOR = Plane(0, "floor", (0.0, 0.0), (6.0, 6.0), 0.0, 0.0, 0.0, 0.0)
FAR = SceneObject("cylinder", (2.5, 2.5, 0.1), 0.0, (0.06, 0.06, 0.2))  # the "grasped" object, out of the way


def _case(tiago):
    T_world_base = pose_from_xyz_rpy([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    q = np.array([0.2, 0.3, 0.2, -1.0, 1.5, 0.5, 0.3, 0.2])
    grasp = T_world_base @ forward_kinematics(tiago.arm(), q)
    return T_world_base, q, grasp


def _scene(*objects: SceneObject) -> Scene:
    return Scene(
        SceneSettings(n_planes=0, extent=(6.0, 6.0), with_box=False), (FLOOR,), None, (FAR, *objects)
    )


def test_a_wall_the_arm_must_pass_through_makes_a_grasp_not_allowed(tiago):
    T_world_base, _, grasp = _case(tiago)
    oracle = AllowedGrasps(RobotShapes(tiago))
    tcp = grasp[:2, 3]
    reach = float(np.hypot(*tcp))
    assert reach > 0.6  # the wall fits between the base (radius ~0.3 m) and the TCP
    heading = math.atan2(tcp[1], tcp[0])
    mid = 0.45 / reach * tcp  # 0.45 m from the base centre, across the line to the TCP
    wall = SceneObject("cube", (float(mid[0]), float(mid[1]), 1.5), heading, (0.02, 4.0, 3.0))
    rng = np.random.default_rng(0)
    assert oracle.allowed(_scene(), grasp, 0, T_world_base[None], [0], rng)
    assert not oracle.allowed(_scene(wall), grasp, 0, T_world_base[None], [0], rng)


def test_the_clearance_is_kept_from_every_solid(tiago):
    T_world_base, q, grasp = _case(tiago)
    # a small cube 4 cm beside the TCP: clear with no margin, a contact at 0.5 m
    p = grasp[:3, 3] + 0.04 * grasp[:3, 1] + np.array([0.0, 0.0, 0.3])
    cube = SceneObject("cube", tuple(p), 0.0, (0.02, 0.02, 0.02))
    scene = _scene(cube)
    shapes = RobotShapes(tiago)
    solids = scene_solids(scene, 0, 0)
    assert AllowedGrasps(shapes, clearance=0.0).touching(q, T_world_base, *solids) is None
    contact = AllowedGrasps(shapes, clearance=0.5).touching(q, T_world_base, *solids)
    assert contact is not None and contact.shape == "object 1"
    # the base stands on the floor: its own links may touch it, the arm's may not
    low = T_world_base.copy()
    low[2, 3] = -0.05
    assert AllowedGrasps(shapes, clearance=0.0).touching(q, low, *scene_solids(_scene(), 0, 0)) is None


def test_a_held_out_v2_run_with_other_counts_or_mixed_seeds_is_refused_before_any_work():
    import subprocess

    def run(*args: str) -> subprocess.CompletedProcess[str]:
        return run_cli("experiment", "osrm", "--protocol", "2", *args)

    r = run("--split", "held-out", "--grasps", "5")
    assert r.returncode == 2 and "uses --scenes 7 --grasps 3 --tries 100" in r.stderr
    r = run("--seeds", "1000,4101")
    assert r.returncode == 2 and "held-out seeds" in r.stderr


def test_planner_v2_moves_a_draw_that_buries_the_palm_back_to_contact(tiago):
    import coal
    import pinocchio as pin

    from baseplace_experiments.allowed_grasps import GRASP_DEPTH, ContactApproach, object_solid

    bottle = SceneObject("cylinder", (1.0, 0.0, 0.6), 0.0, (0.06, 0.06, 0.2))
    scene = _scene(bottle)
    # v1's draw: top-down, tilted 10 deg, grasp point 3 cm below the top, the TCP 0.151 m behind it
    T = pose_from_xyz_rpy([0.0, 0.0, 0.0, 0.4, math.pi / 2 - math.radians(10), 0.2])
    T[:3, 3] = np.array([1.0, 0.0, 0.7 - 0.03]) - 0.151 * T[:3, 0]

    # the rigid hand placed independently: pinocchio at the reference configuration, moved to the TCP
    shapes = RobotShapes(tiago)
    model, data = shapes.model, shapes.model.createData()
    pin.framesForwardKinematics(model, data, tiago.q_reference)
    gdata = pin.GeometryData(shapes.geom)
    pin.updateGeometryPlacements(model, data, shapes.geom, gdata, tiago.q_reference)
    T_tcp_world = data.oMf[model.getFrameId(shapes.arm.tcp_frame)].inverse().homogeneous
    rigid = [o for o in shapes.geom.geometryObjects
             if o.name.startswith(("arm_tool_link", "wrist_ft", "hand_palm_link"))]  # fmt: skip
    assert len(rigid) == 4

    def distance(T_world_tcp, solid):  # the rigid hand's distance [m] to a solid (negative: inside)
        out = []
        for o in rigid:
            k = shapes.geom.getGeometryId(o.name)
            P = T_world_tcp @ T_tcp_world @ gdata.oMg[k].homogeneous
            out.append(coal.distance(o.geometry, coal.Transform3s(P[:3, :3], P[:3, 3]), solid.geometry,
                                     solid.transform(), coal.DistanceRequest(), coal.DistanceResult()))  # fmt: skip
        return min(out)

    inner = object_solid(bottle, "inner", GRASP_DEPTH)
    assert distance(T, inner) <= 0.0  # the draw buries the palm more than 5 mm
    moved = ContactApproach(AllowedGrasps(shapes), scene)(T, 1)
    assert moved is not None
    T_moved, standoff = moved
    assert 0.0 < standoff < 0.15
    np.testing.assert_allclose(T_moved[:3, 3], T[:3, 3] - standoff * T[:3, 0], atol=1e-12)
    np.testing.assert_allclose(T_moved[:3, :3], T[:3, :3])
    assert distance(T_moved, inner) > 0.0  # at most 5 mm into the bottle
    assert distance(T_moved, object_solid(bottle, "bottle")) < 0.001  # and touching it (within 1 mm)
