from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.fk import forward_kinematics
from baseplace.sim.scenes import Plane, Scene, SceneSettings, generate_scene
from baseplace_experiments.osrm_experiment import GroundTruth, grasp_candidates


def test_ground_truth_oracle_accepts_fk_targets_and_rejects_unreachable(tiago):
    rmap = build_map(tiago, None, BuildSettings(samples=300_000))
    floor = Plane(0, "floor", (0.0, 0.0), (6.0, 6.0), 0.0, 0.0, 0.0, 0.0)
    scene = Scene(SceneSettings(n_planes=0, extent=(6.0, 6.0), with_box=False), (floor,))
    arm = tiago.arm()
    rng = np.random.default_rng(3)
    # FK of a configuration from a base at (0.2, -0.1), heading 60 deg: reachable, so the grid search finds some pose.
    T_world_base = pose_from_xyz_rpy([0.2, -0.1, 0.0, 0.0, 0.0, math.radians(60)])
    q = np.array([0.2, 0.3, 0.2, -1.0, 1.5, 0.5, 0.3, 0.2])
    grasp = T_world_base @ forward_kinematics(arm, q)
    truth = GroundTruth()
    assert truth.reachable(tiago, rmap, scene, grasp, rng)
    assert not truth.reachable(tiago, rmap, scene, pose_from_xyz_rpy([0.0, 0.0, 2.5, 0.0, 0.0, 0.0]), rng)


def test_grasp_candidates_lie_above_the_objects():
    rng = np.random.default_rng(1)
    scene = generate_scene(SceneSettings(n_planes=0, box_elevation=0.5), rng)
    assert min(o.bottom for o in scene.objects) == pytest.approx(0.5 + scene.box.wall)
    grasps, objects, _ = grasp_candidates(scene, rng, 20)
    assert len(objects) == 20  # per grasp the true shape of the object it takes, nothing larger
    centres = np.array([o.center for o in scene.objects])
    for obj in objects:
        true = scene.objects[int(np.argmin(np.linalg.norm(centres - obj.center, axis=1)))]
        assert np.allclose(obj.center, true.center) and obj.size[2] == pytest.approx(true.size[2])
    assert grasps.shape == (20, 4, 4)
    tops = np.array([o.top for o in scene.objects])
    assert np.all(grasps[:, 2, 3] > tops.min() + 0.1)  # the TCP sits 0.151 m back along the approach
    # top-down with at most 20 deg tilt: the approach (x) axis points down
    assert np.all(grasps[:, 2, 0] <= -math.cos(math.radians(20)) + 1e-9)
    assert grasps[:, 2, 0].max() > -math.cos(math.radians(5))  # some are tilted, not all straight down


def test_hand_filter_rejects_a_hand_sunk_into_a_slab(tiago):
    import coal

    from baseplace.world.environment import HandFilter

    xs, ys = np.meshgrid(np.arange(-0.5, 0.5, 0.02), np.arange(-0.5, 0.5, 0.02))
    slab = coal.makeOctree(np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, 0.44)], 0.025)
    hand = HandFilter(tiago)
    assert hand.clear(pose_from_xyz_rpy([0, 0, 0.80, 0, math.pi / 2, 0]), slab)  # high above: clear
    assert not hand.clear(pose_from_xyz_rpy([0, 0, 0.50, 0, math.pi / 2, 0]), slab)  # fingers in the slab


def test_grasp_planner_turns_down_hands_in_true_solids_only(tiago):
    """The planner checks the open hand against the true shapes (coal), never against voxels."""
    import coal

    from baseplace.world.environment import HandFilter
    from baseplace_experiments.osrm_experiment import _hand_touches, true_solids

    rng = np.random.default_rng(5)
    scene = generate_scene(
        SceneSettings(n_planes=0, box_elevation=0.5, box_height=0.12, object_height=(0.15, 0.25)), rng
    )
    hand = HandFilter(tiago)
    grasps, objects, turned_down = grasp_candidates(scene, rng, 10, hand=hand)
    assert len(grasps) == 10 and turned_down >= 0
    solids = true_solids(scene)
    for g, obj in zip(grasps, objects, strict=True):
        i = int(np.argmin([np.linalg.norm(np.array(o.center) - obj.center) for o in scene.objects]))
        others = [p for name, p in solids.items() if name != f"object{i}"]
        # oracle: every hand geometry against every other true solid, one coal call each
        for geometry, T_tcp_geom in hand.parts:
            T = g @ T_tcp_geom
            for solid in others:
                for shape, S in solid:
                    res = coal.CollisionResult()
                    assert not coal.collide(geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), shape,
                                            coal.Transform3s(S[:3, :3], S[:3, 3]), coal.CollisionRequest(), res)  # fmt: skip
    # a hand sunk into the tray bottom is turned down
    box = scene.box
    sunk = pose_from_xyz_rpy([box.center[0], box.center[1], box.elevation + 0.15, 0, math.pi / 2, 0])
    assert _hand_touches(hand, sunk, [solids["tray"]])


def test_incline_only_scene_reachable_only_from_the_incline(tiago):
    from baseplace.world.environment import HandFilter
    from baseplace_experiments.osrm_experiment import ExperimentSettings, GroundTruth, experiment_scene

    rmap = build_map(tiago, None, BuildSettings(samples=300_000))
    rng, scene, _, _ = experiment_scene(ExperimentSettings(seed=3), 7, 0)
    assert len(scene.planes) == 2 and scene.box is not None
    plane = scene.planes[1]
    box_xy = np.array(scene.box.center)
    assert plane.contains(box_xy[None])[0]
    # every floor pose the ground truth may use lies beyond the arm's reach of the tray
    half = min(plane.size) / 2
    assert half - 0.15 - math.hypot(0.3, 0.2) + tiago.spec.footprint_bounding_radius > rmap.horizontal_reach
    assert all(o.bottom > plane.z(np.array([o.center[:2]]))[0] + 0.5 for o in scene.objects)
    # so a grasp the ground truth counts is one it reached from a pose on the incline
    grasps, _, _ = grasp_candidates(scene, rng, 4, hand=HandFilter(tiago))
    assert any(GroundTruth().reachable(tiago, rmap, scene, g, rng) for g in grasps)


def test_experiment_smoke_flat_scene(tiago):
    from baseplace_experiments.osrm_experiment import (
        DEV_SEEDS,
        HELD_OUT_SEEDS,
        ExperimentSettings,
        run_osrm_experiment,
    )

    rmap = build_map(tiago, None, BuildSettings(samples=5_000_000, seed=2))
    # The seed's setup (protocol v3): the 25 mm noise on the height map, the collision model from the
    # clean cloud. On the noisy cloud the derived clearance is 3 sigma of its 25 mm z-noise (~75 mm)
    # and next to no grasp in the tray is placeable, correctly (docs/placement.md).
    settings = ExperimentSettings(grasps_per_scene=3, tries=60, seed=1, collision_cloud="clean")
    result = run_osrm_experiment(tiago, rmap, 1, settings, classes=(("flat", 0),))
    assert result["seed_role"] == "other" and not set(DEV_SEEDS) & set(HELD_OUT_SEEDS)
    rows = {r["strategy"]: r for r in result["rows"]}
    assert set(rows) == {"orm", "TO", "MR", "MRTO"}
    for r in rows.values():
        assert r["grasps"] == 3 and 0 < r["reachable_grasps"] <= 3 and r["queries"] == r["reachable_grasps"]
        at = [r["success_rate_at"][b] for b in ("1", "3", "10", "100")]
        assert at == sorted(at) and at[-1] == r["success_rate"]  # success can only grow with the budget
        assert set(r["failures"]) <= {"no_ik", "collision", "footprint", "exhausted"}
        assert r["on_inclined_plane"] in (None, 0.0)  # a flat scene has no incline
        assert set(r["collisions_touching"]) <= {
            "support",
            "support_plane",
            "obstacle",
            "grasped_object",
            "self",
        }
    assert rows["MR"]["success_rate"] > 0  # a grasp on a flat scene is placeable (1 of 3 here)


@pytest.mark.slow  # ~75 s: a cluster start and two workers loading TIAGo; run with -m slow
def test_experiment_scenes_on_a_two_worker_cluster_match_a_local_run(tiago, tiago_map):
    from baseplace.reachability.distributed import connect
    from baseplace_experiments.osrm_experiment import ExperimentSettings, run_osrm_experiment

    settings = ExperimentSettings(grasps_per_scene=2, tries=30)
    classes = (("flat", 0),)
    local = run_osrm_experiment(tiago, tiago_map, 2, settings, classes)
    with connect("local", n_workers=2) as client:
        remote = run_osrm_experiment(
            tiago, tiago_map, 2, settings, classes, client=client, robot_spec="tiago"
        )
    for a, b in zip(local["rows"], remote["rows"], strict=True):
        for key in ("strategy", "grasps", "reachable_grasps", "success_rate", "failures"):
            assert a[key] == b[key], key


def test_the_oracle_keeps_the_clearance_the_queries_report_and_a_disagreement_fails_loudly():
    from baseplace.world.sensor_resolution import MIN_CLEARANCE
    from baseplace_experiments.osrm_experiment import query_clearance

    assert query_clearance({"MR": 0.004, "ORM": 0.004}) == (0.004, True)
    assert query_clearance({}) == (MIN_CLEARANCE, False)  # no query returned: 3 mm, marked
    with pytest.raises(RuntimeError, match="different clearances"):
        query_clearance({"MR": 0.004, "ORM": 0.003})


def test_planner_v2_moves_v1s_own_draws_back_to_contact(tiago):
    """Planner v2 takes v1's draws (the same generator use) and moves each back along its approach axis."""
    from baseplace.world.environment import HandFilter
    from baseplace_experiments.allowed_grasps import AllowedGrasps, ContactApproach
    from baseplace_experiments.table_grid import RobotShapes

    settings = SceneSettings(n_planes=0, box_elevation=0.5, box_height=0.12, object_height=(0.15, 0.25))
    scene = generate_scene(settings, np.random.default_rng(5))
    hand = HandFilter(tiago)
    v1, _, _ = grasp_candidates(scene, np.random.default_rng(6), 4)
    approach = ContactApproach(AllowedGrasps(RobotShapes(tiago)), scene)
    standoffs: list[float] = []
    v2, objects, _ = grasp_candidates(
        scene, np.random.default_rng(6), 4, approach=approach, standoffs=standoffs
    )
    assert len(standoffs) == len(v2) == 4
    assert all(0.005 < d < 0.15 for d in standoffs)  # every v1 draw buries the palm: each is moved back
    # with no hand check both take the same draws: v2's grasp is v1's moved back by its standoff
    for a, b, d in zip(v1, v2, standoffs, strict=True):
        np.testing.assert_allclose(b[:3, 3], a[:3, 3] - d * a[:3, 0], atol=1e-12)
    centres = np.array([o.center for o in scene.objects])
    for g, obj in zip(v2, objects, strict=True):
        i = int(np.argmin(np.linalg.norm(centres - obj.center, axis=1)))
        closer = g.copy()
        closer[:3, 3] += 0.002 * g[:3, 0]  # 2 mm further along the approach
        assert not approach.meets(g, i) and approach.meets(closer, i)  # contact, within the bisection's step
    # with the hand's check the kept draws still clear every other true solid
    kept, _, turned_down = grasp_candidates(scene, np.random.default_rng(6), 4, hand=hand, approach=approach)
    assert len(kept) == 4 and turned_down >= 0
