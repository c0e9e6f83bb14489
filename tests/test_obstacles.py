"""Collision objects given by hand beside the cloud: ``--obstacle`` box, cylinder, mesh (issue 29, item 7).

Oracles: the true shapes built here as coal solids from the numbers given (a box, a cylinder; the
cube the test writes as an STL), against the robot's collision meshes loaded here from the URDF
and placed by pinocchio's FK at the returned joints: every returned placement must be at a
positive distance from the obstacle, at its grasp configuration and along its reaching motion.
"""

from __future__ import annotations

import json
import math
import struct

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.jobs.explain import ExplainJob, explain_job
from baseplace.jobs.inputs import CloudInput
from baseplace.jobs.place import PlaceJob, place_job
from baseplace.jobs.report import NoResultError
from baseplace.placement.pipeline import PlaceSettings
from baseplace.placement.robustness import RobustnessSettings
from baseplace.placement.scene_cache import SceneCache
from baseplace.reachability.storage import save_map
from baseplace.sim.scenes import Plane, Scene, SceneSettings
from conftest import run_cli
from peak_memory import CAP_MB, cli_peak

TARGET = f"0.5 0.3 0.75 0 {math.pi / 2!r} 0"  # top-down, the grasp point 0.151 m below: z = 0.6
SETTINGS = PlaceSettings(tries=60, placements=2, robustness=RobustnessSettings(samples=8))


@pytest.fixture(scope="module")
def floor_points() -> np.ndarray:
    floor = Plane(0, "floor", (0.0, 0.0), (4.0, 4.0), 0.0, 0.0, 0.0, 0.0)
    scene = Scene(SceneSettings(n_planes=0, extent=(4.0, 4.0), with_box=False), (floor,))
    return scene.sample_cloud(np.random.default_rng(5), sigma=0.005)


@pytest.fixture(scope="module")
def cache(floor_points) -> SceneCache:
    return SceneCache(floor_points)


def _place(tiago, tiago_map, floor_points, cache, obstacles=()) -> dict:
    given = {"obstacles": list(obstacles)} if obstacles else {}  # the baseline runs on the landed code too
    job = PlaceJob([TARGET], tiago, cloud=CloudInput(points=floor_points), map=tiago_map, settings=SETTINGS,
                   cache=cache, **given)  # fmt: skip
    try:
        return place_job(job).to_json()
    except NoResultError as exc:
        return exc.report.to_json()


@pytest.fixture(scope="module")
def baseline(tiago, tiago_map, floor_points, cache) -> dict:
    """The best placement without obstacles."""
    out = _place(tiago, tiago_map, floor_points, cache)
    assert out["placements"], out["failures"]
    return out["placements"][0]


def _pose(T_world: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(T_world[:3, :3]), np.asarray(T_world[:3, 3]))


def _yawed(x: float, y: float, z: float, yaw: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = (x, y, z)
    return T


def _clearance(robot, placement: dict, shape: coal.CollisionGeometry, T_world_shape: np.ndarray) -> float:
    """Least distance [m] of the URDF's collision meshes from the solid, at the placement's joints and
    every waypoint of its reaching motion (pinocchio FK, coal distance)."""
    model = robot.model
    geom = pin.buildGeomFromUrdf(model, str(robot.spec.urdf), pin.COLLISION,
                                 package_dirs=[str(p) for p in robot.spec.package_dirs])  # fmt: skip
    arm = robot.arm()
    T_world_base = np.array(placement["base_pose"])
    configurations = [np.array([j[n] for n in arm.joint_names]) for j in placement["joints"]]
    for m in placement.get("motion", []):
        configurations += [np.array(q) for q in (*m["path"], *m["approach"])]
    data, gdata = model.createData(), pin.GeometryData(geom)
    least = math.inf
    for q_arm in configurations:
        q = arm.to_pinocchio(q_arm, robot.q_reference)
        pin.framesForwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, geom, gdata, q)
        T_world_root = T_world_base @ data.oMf[model.getFrameId(robot.spec.base_frame)].inverse().homogeneous
        for k, g in enumerate(geom.geometryObjects):
            T = T_world_root @ gdata.oMg[k].homogeneous
            result = coal.DistanceResult()
            d = coal.distance(
                g.geometry, _pose(T), shape, _pose(T_world_shape), coal.DistanceRequest(), result
            )
            least = min(least, float(d))
    return least


def _same_pose(a: dict, b: dict) -> bool:
    return np.allclose(a["base_pose"], b["base_pose"], atol=1e-6)


def _check_blocked(out: dict, refused: dict, name: str, robot, shape, T_world_shape) -> None:
    """The refused placement is gone, every returned one clears the true shape, one is found elsewhere."""
    assert not any(_same_pose(p, refused) for p in out["placements"])
    assert any(c["touched"] == f"obstacle {name}" for c in out["collisions"]), out["collisions"]
    assert out["placements"], out["failures"]  # the floor is wide: the robot stands elsewhere
    for p in out["placements"]:
        assert _clearance(robot, p, shape, T_world_shape) > 0.0


def test_the_baseline_placement_touches_a_box_at_its_base(tiago, baseline):
    # the oracle sees the box where the base stands: the tests below block something real
    x, y = baseline["x"], baseline["y"]
    assert _clearance(tiago, baseline, coal.Box(0.2, 0.2, 0.4), _yawed(x, y, 0.3)) < 0.0


def test_a_box_where_the_base_stands_removes_that_placement(tiago, tiago_map, floor_points, cache, baseline):
    x, y = baseline["x"], baseline["y"]
    out = _place(tiago, tiago_map, floor_points, cache, [f"box {x!r} {y!r} 0.3 0.2 0.2 0.4 0.5"])
    _check_blocked(out, baseline, "box#0", tiago, coal.Box(0.2, 0.2, 0.4), _yawed(x, y, 0.3, 0.5))
    assert out["inputs"]["obstacles"] == [f"box {x!r} {y!r} 0.3 0.2 0.2 0.4 0.5"]


def _link_origin(robot, placement: dict, link: str) -> np.ndarray:
    arm, model = robot.arm(), robot.model
    q = arm.to_pinocchio(np.array([placement["joints"][0][n] for n in arm.joint_names]), robot.q_reference)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    T_base_link = (
        data.oMf[model.getFrameId(robot.spec.base_frame)].inverse() * data.oMf[model.getFrameId(link)]
    )
    return (np.array(placement["base_pose"]) @ T_base_link.homogeneous)[:3, 3]


def test_a_cylinder_where_the_arm_is_removes_that_placement(tiago, tiago_map, floor_points, cache, baseline):
    elbow = _link_origin(tiago, baseline, "arm_4_link")  # TIAGo's elbow, placed by pinocchio
    x, y, z = (float(v) for v in elbow)
    out = _place(tiago, tiago_map, floor_points, cache, [f"cylinder {x!r} {y!r} {z!r} 0.06 0.12"])
    _check_blocked(out, baseline, "cylinder#0", tiago, coal.Cylinder(0.06, 0.12), _yawed(x, y, z))


def _stl_cube(path, centre, side) -> None:
    """A binary STL of the cube, written by hand: 12 triangles."""
    c, h = np.asarray(centre, dtype=float), side / 2
    corners = np.array([[sx, sy, sz] for sx in (-h, h) for sy in (-h, h) for sz in (-h, h)]) + c
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = [t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))]
    with open(path, "wb") as f:
        f.write(b"cube".ljust(80, b" ") + struct.pack("<I", len(triangles)))
        for t in triangles:
            f.write(
                struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *corners[i]) for i in t) + b"\0\0"
            )


def test_a_mesh_where_the_base_stands_removes_that_placement(tiago, tiago_map, floor_points, cache, baseline,
                                                            tmp_path):  # fmt: skip
    x, y = baseline["x"], baseline["y"]
    stl = tmp_path / "crate.stl"
    _stl_cube(stl, (x, y, 0.3), 0.3)
    out = _place(tiago, tiago_map, floor_points, cache, [str(stl)])
    _check_blocked(out, baseline, "mesh#0", tiago, coal.Box(0.3, 0.3, 0.3), _yawed(x, y, 0.3))


def test_explain_at_the_blocked_pose_names_the_obstacle(tiago, tiago_map, floor_points, baseline):
    x, y, yaw = baseline["x"], baseline["y"], baseline["yaw"]
    box = f"box {x!r} {y!r} 0.3 0.2 0.2 0.4"
    obj = explain_job(ExplainJob((x, y, yaw), TARGET, tiago_map, tiago, cloud=CloudInput(points=floor_points),
                                 obstacles=[box], settings=PlaceSettings(motion=None))).to_json()  # fmt: skip
    touched = {c["touched"] for c in obj["collisions"]}
    assert touched == {"obstacle box#0"}, obj["collisions"]
    assert obj["verdict"]["failed_check"] == "collision"
    assert "touched obstacle box#0" in obj["verdict"]["summary"]


def test_the_cli_refusal_and_explain_name_the_obstacle(tiago_map, floor_points, tmp_path):
    map_file, cloud_file = tmp_path / "tiago.rmap", tmp_path / "floor.npy"
    save_map(tiago_map, map_file)
    np.save(cloud_file, floor_points)
    # a 1.2 m wide drum under the target, its top 5 cm below the grasp point: the arm cannot reach over it
    wall = "cylinder 0.5 0.3 0.275 0.6 0.55"
    proc = run_cli("place", "--cloud", str(cloud_file), "--map", str(map_file), "--target", TARGET, "--obstacle",
                   wall, "--tries", "30", "--no-motion-check", "--robustness-samples", "0", "--json")  # fmt: skip
    assert proc.returncode == 3, proc.stderr
    out = json.loads(proc.stdout)
    worst = out["collisions"][0]
    assert worst["touched"] == "obstacle cylinder#0"
    assert f"link {worst['link']} touched obstacle cylinder#0" in proc.stderr
    # explain at a base pose place refused (the drum's edge under the base) names the same object
    base = "0.5 -0.45 1.5708"
    proc = run_cli("explain", "--map", str(map_file), "--cloud", str(cloud_file), "--base", base, "--target",
                   TARGET, "--obstacle", wall, "--no-motion-check", "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "obstacle cylinder#0" in {c["touched"] for c in json.loads(proc.stdout)["collisions"]}


def test_an_obstacle_at_the_grasp_point_is_refused_before_the_search(tmp_path):
    np.save(tmp_path / "c.npy", np.zeros((10, 3)))
    proc = run_cli("place", "--cloud", str(tmp_path / "c.npy"), "--target", TARGET, "--obstacle",
                   "box 0.5 0.3 0.6 0.1 0.1 0.1")  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "inside obstacle box#0" in lines[0] and "target 0" in lines[0]


@pytest.mark.parametrize(
    "spec, words",
    [
        ("box 1 2 3", "expected"),
        ("sphere 1 2 3 0.5", "expected"),
        ("box 1 2 3 0 1 1", "sizes must be > 0"),
        ("cylinder 1 2 3 0.1", "expected"),
        ("cylinder 1 2 x 0.1 0.2", "not numbers"),
        ("box 1 2 3 1 1 1 nan", "NaN"),
        ("box 1 2 3 1 1 1 90", "--degrees"),
        ("missing.stl", "no such file"),
        ("notes.txt", "expected"),
    ],
)
def test_bad_obstacles_exit_2_with_one_line_naming_the_forms(tmp_path, spec, words):
    np.save(tmp_path / "c.npy", np.zeros((10, 3)))
    proc = run_cli("place", "--cloud", str(tmp_path / "c.npy"), "--target", TARGET, "--obstacle",
                   spec if spec[0].isalpha() and " " in spec else str(tmp_path / spec))  # fmt: skip
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: --obstacle") and words in lines[0], lines[0]
    if words == "expected":
        assert '"box X Y Z SX SY SZ [YAW]"' in lines[0] and "cylinder X Y Z RADIUS HEIGHT" in lines[0]


def test_degrees_converts_a_box_yaw(tmp_path, tiago_map):
    # with --degrees the 90 is a yaw, not an error; the run stops later, at the empty cloud. The small
    # map given spares the run a build of the default map (2e8 samples, ~50 s), which comes before that stop.
    np.save(tmp_path / "c.npy", np.zeros((10, 3)))
    save_map(tiago_map, tmp_path / "tiago.rmap")
    proc = run_cli("place", "--cloud", str(tmp_path / "c.npy"), "--map", str(tmp_path / "tiago.rmap"), "--target",
                   "0.5 0.3 0.75 0 90 0", "--degrees", "--obstacle", "box 3 3 0.3 0.2 0.2 0.4 90", "--json")  # fmt: skip
    out = json.loads(proc.stdout)
    assert out["inputs"]["obstacle"] == [f"box 3 3 0.3 0.2 0.2 0.4 {math.pi / 2!r}"], out  # the argv as read


def _ply_header(faces: int) -> bytes:
    return (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n" % faces)  # fmt: skip


@pytest.mark.parametrize(
    "name, content",
    [
        ("huge.stl", b"x" * 80 + struct.pack("<I", 0xFFFFFFFF) + b"\0" * 50),
        ("huge.ply", _ply_header(2_000_000_000) + b"\0" * 100),
        ("many.ply", _ply_header(1_200_000) + b"\0" * (36 + 1_200_000 * 13)),
    ],
)
def test_a_hostile_mesh_is_refused_before_it_is_parsed(tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    np.save(tmp_path / "c.npy", np.zeros((10, 3)))
    code, stderr, seconds, peak = cli_peak("place", "--cloud", "c.npy", "--target", TARGET, "--obstacle", name,
                                           cwd=tmp_path)  # fmt: skip
    lines = stderr.strip().splitlines()
    assert code == 2 and len(lines) == 1, stderr[-2000:]
    assert lines[0].startswith(f"error: --obstacle {name}") and "triangles" in lines[0], lines[0]
    assert peak < CAP_MB and seconds < 60, (peak, seconds)


def test_an_obj_mesh_loads_without_opening_the_files_it_names(tmp_path):
    from baseplace.world.obstacles import parse_obstacles  # the module this issue adds

    obj = tmp_path / "wedge.obj"
    obj.write_text("mtllib ../../../../etc/shadow\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\n"
                   "f 2 3 4\n")  # fmt: skip
    (o,) = parse_obstacles([str(obj)])
    assert o.name == "mesh#0" and o.label == "obstacle mesh#0"
    assert o.distance([0.0, 0.0, 2.0]) == pytest.approx(1.0, abs=1e-5)  # above the apex (0, 0, 1)


def test_the_service_takes_obstacles_and_refuses_the_same_placement(tiago, tiago_map, floor_points, baseline):
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    from test_serve import UP, make_app, npy_bytes

    x, y = baseline["x"], baseline["y"]
    box = f"box {x!r} {y!r} 0.3 0.2 0.2 0.4"
    with TestClient(make_app(tiago, tiago_map, max_request_bytes=8 * 1024 * 1024)) as client:
        r = client.post("/scenes", params={"format": "npy"}, content=npy_bytes(floor_points), headers=UP)
        assert r.status_code == 200, r.text
        body = {"scene_id": r.json()["scene_id"], "targets": [TARGET], "tries": 60, "placements": 2,
                "robustness_samples": 8}  # fmt: skip
        plain = client.post("/place", json=body).json()
        assert any(_same_pose(p, baseline) for p in plain["placements"])  # the CLI's answer without it
        out = client.post("/place", json={**body, "obstacles": [box]})
        assert out.status_code == 200, out.text
        _check_blocked(out.json(), baseline, "box#0", tiago, coal.Box(0.2, 0.2, 0.4), _yawed(x, y, 0.3))
        mesh = client.post("/place", json={**body, "obstacles": ["/etc/passwd.stl"]})
        assert mesh.status_code in (400, 422) and "obstacles" in mesh.text
        why = client.post("/explain", json={"scene_id": body["scene_id"], "base": f"{x!r} {y!r} {baseline['yaw']!r}",
                                            "target": TARGET, "no_motion_check": True, "obstacles": [box]})  # fmt: skip
        assert why.status_code == 200, why.text
        assert {c["touched"] for c in why.json()["collisions"]} == {"obstacle box#0"}


@pytest.mark.parametrize("method", ["radial", "irm"])
def test_candidates_avoid_a_box_where_the_best_candidate_stood(tiago, tiago_map, method):
    from baseplace.jobs.candidates import CandidatesJob, candidates_job
    from baseplace.world.occupancy import OccupancyGrid

    x0, x1, y0, y1, top = 1.6, 2.4, 1.1, 2.9, 0.74  # test_candidates' table: 0.8 m x 1.8 m
    centres = (np.arange(80) + 0.5) * 0.05
    X, Y = np.meshgrid(centres, centres)  # row j = y, column i = x
    grid = OccupancyGrid(
        np.where((X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1), 100, 0).astype(np.int8), 0.05
    )
    p_o = f"2.2 2.5 {top + 0.1!r}"

    def run(obstacles=()):
        given = {"obstacles": list(obstacles)} if obstacles else {}
        return candidates_job(
            CandidatesJob(p_o, grid, method=method, robot=tiago, map=tiago_map, **given)
        ).to_json()

    best = run()["candidates"][0]
    x, y = best["x"], best["y"]
    out = run([f"box {x!r} {y!r} 0.3 0.2 0.2 0.4"])
    assert out["candidates"] and not any(_same_pose(c, best) for c in out["candidates"])
    for c in out["candidates"]:
        assert (
            _clearance(tiago, {**c, "joints": [c["joints"]]}, coal.Box(0.2, 0.2, 0.4), _yawed(x, y, 0.3)) > 0
        )


def _base_parts(robot) -> list[tuple[coal.CollisionGeometry, np.ndarray]]:
    """The URDF's collision meshes that no joint moves, with their poses (4, 4) in the base frame."""
    model = robot.model
    geom = pin.buildGeomFromUrdf(model, str(robot.spec.urdf), pin.COLLISION,
                                 package_dirs=[str(p) for p in robot.spec.package_dirs])  # fmt: skip
    data, gdata = model.createData(), pin.GeometryData(geom)
    pin.framesForwardKinematics(model, data, robot.q_reference)
    pin.updateGeometryPlacements(model, data, geom, gdata, robot.q_reference)
    T_base_root = data.oMf[model.getFrameId(robot.spec.base_frame)].inverse().homogeneous
    return [(g.geometry, T_base_root @ gdata.oMg[k].homogeneous)
            for k, g in enumerate(geom.geometryObjects) if g.parentJoint == 0]  # fmt: skip


def _base_distance(parts, T_world_base: np.ndarray, shape, T_world_shape: np.ndarray) -> float:
    return min(float(coal.distance(g, _pose(T_world_base @ T), shape, _pose(T_world_shape), coal.DistanceRequest(),
                                   coal.DistanceResult())) for g, T in parts)  # fmt: skip


def test_robustness_fails_every_draw_whose_base_touches_the_obstacle(tiago, baseline):
    from baseplace.placement.robustness import RobustnessEstimator, perturbed
    from baseplace.world.environment import Environment
    from baseplace.world.obstacles import parse_obstacles  # the module this issue adds

    arm = tiago.arm()
    T_nominal = np.array(baseline["base_pose"])
    q = np.array([baseline["joints"][0][n] for n in arm.joint_names])
    target = np.asarray(pin.XYZQUATToSE3(np.r_[0.5, 0.3, 0.75, 0.0, 0.7071067811865476, 0.0, 0.7071067811865476])
                        .homogeneous)  # TARGET: pitch pi/2 about y  # fmt: skip
    parts, low_box = _base_parts(tiago), coal.Box(0.1, 0.4, 0.1)
    # a low box beside the base, 1.5 cm clear of it at the nominal pose (measured here by coal)
    x, y = float(T_nominal[0, 3]), float(T_nominal[1, 3])
    far = _yawed(x + 0.6, y, 0.05)
    gap = _base_distance(parts, T_nominal, low_box, far)
    cx = float(x + 0.6 - (gap - 0.015))
    T_box = _yawed(cx, y, 0.05)
    assert _base_distance(parts, T_nominal, low_box, T_box) == pytest.approx(0.015, abs=2e-3)
    settings = RobustnessSettings(samples=64)
    env = Environment(tiago, {}, shapes=parse_obstacles([f"box {cx!r} {y!r} 0.05 0.1 0.4 0.1"]))
    estimator = RobustnessEstimator(arm, env, target[None], settings)
    ok = estimator.successes(T_nominal, [q])
    touching = np.array(
        [_base_distance(parts, T, low_box, T_box) < 0 for T in perturbed(T_nominal, estimator.offsets)]
    )
    assert touching.sum() >= 5, touching.sum()  # 3 cm sigma: many draws put the base into the box
    assert not ok[touching].any()
    clear = RobustnessEstimator(arm, Environment(tiago, {}), target[None], settings).successes(T_nominal, [q])
    assert clear[touching].sum() > 0  # without the box those draws reach the target: the box is the reason


def test_obstacles_given_with_the_scene_are_checked_by_every_request_on_it(
    tiago, tiago_map, floor_points, baseline
):
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    from test_serve import UP, make_app, npy_bytes

    x, y = baseline["x"], baseline["y"]
    box = f"box {x!r} {y!r} 0.3 0.2 0.2 0.4"
    with TestClient(make_app(tiago, tiago_map, max_request_bytes=8 * 1024 * 1024)) as client:
        bad = client.post("/scenes", params={"format": "npy", "obstacle": ["box 1 2"]},
                          content=npy_bytes(floor_points), headers=UP)  # fmt: skip
        assert bad.status_code == 400 and "obstacle" in bad.json()["error"], bad.text
        mesh = client.post("/scenes", params={"format": "npy", "obstacle": ["/etc/passwd.stl"]},
                           content=npy_bytes(floor_points), headers=UP)  # fmt: skip
        assert mesh.status_code == 422, mesh.text
        r = client.post("/scenes", params={"format": "npy", "obstacle": [box]}, content=npy_bytes(floor_points),
                        headers=UP)  # fmt: skip
        assert r.status_code == 200 and r.json()["obstacles"] == [box], r.text
        body = {"scene_id": r.json()["scene_id"], "targets": [TARGET], "tries": 60, "placements": 2,
                "robustness_samples": 8}  # fmt: skip
        out = client.post("/place", json=body)  # the request names no obstacle: the scene's is checked
        assert out.status_code == 200, out.text
        _check_blocked(out.json(), baseline, "box#0", tiago, coal.Box(0.2, 0.2, 0.4), _yawed(x, y, 0.3))
        why = client.post("/explain", json={"scene_id": body["scene_id"], "base": f"{x!r} {y!r} {baseline['yaw']!r}",
                                            "target": TARGET, "no_motion_check": True})  # fmt: skip
        assert why.status_code == 200, why.text
        assert {c["touched"] for c in why.json()["collisions"]} == {"obstacle box#0"}
