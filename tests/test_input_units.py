"""Inputs checked before any search: degrees, millimetres, targets out of the scene or above the arm's reach.

Every refusal is exit 2 with one line, before a reachability map is built or loaded and before the
segmentation: the commands run with an empty cache and a map file that does not exist, and must
answer within seconds with the cache still holding no map.
"""

from __future__ import annotations

import json
import math
import subprocess
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from baseplace.errors import InputError
from baseplace.robots.model import Robot
from conftest import DATA, run_cli

QUICK_S = 20.0  # a refusal takes ~2 s; building the default map takes minutes


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict[str, Path]:
    """A flat floor cloud (x, y in -3..2.95 m, z 0), a free 5 m occupancy grid (x, y in -2.5..2.5 m),
    a small planar3 map and an empty cache."""
    d = tmp_path_factory.mktemp("units")
    xy = np.mgrid[-3:3:0.05, -3:3:0.05].reshape(2, -1).T
    np.save(d / "floor.npy", np.c_[xy, np.zeros(len(xy))])
    (d / "free.pgm").write_bytes(b"P5 100 100 255\n" + bytes([254]) * 10_000)
    (d / "free.yaml").write_text("image: free.pgm\nresolution: 0.05\norigin: [-2.5, -2.5, 0]\nnegate: 0\n"
                                 "occupied_thresh: 0.65\nfree_thresh: 0.196\n")  # fmt: skip
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.storage import save_map

    save_map(
        build_map(Robot(DATA / "planar3.toml"), None, BuildSettings(samples=200_000, seed=1)), d / "p3.rmap"
    )
    (d / "unreadable.rmap").write_bytes(b"not a map")  # there, so refused only when read
    return {"cloud": d / "floor.npy", "map": d / "p3.rmap", "cache": d / "cache",
            "unreadable": d / "unreadable.rmap", "grid": d / "free.yaml"}  # fmt: skip


def cli(scene: dict[str, Path], *args: str) -> subprocess.CompletedProcess[str]:
    """The command (in this process) with the empty cache; checks it was quick and built no map.

    Nothing keeps a map in memory between commands (maps are loaded per job): a command that went
    for its map before refusing builds the default one into the empty cache (minutes), or fails on
    the unreadable map file with another message than the refusal's (a missing one is refused
    before anything else: tests/test_cli_imports.py).
    """
    t0 = time.perf_counter()
    proc = run_cli(*args, env={"BASEPLACE_CACHE": str(scene["cache"])})
    elapsed = time.perf_counter() - t0
    maps = scene["cache"] / "maps"
    assert not (maps.exists() and any(maps.iterdir())), sorted(maps.iterdir())
    assert elapsed < QUICK_S, (elapsed, proc.stderr)
    return proc


def one_line(proc: subprocess.CompletedProcess[str], *fragments: str) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


DEGREES = ("angles are in radians", "or pass --degrees")
METRES = ("coordinates are in metres",)

PLACE = [
    (["--target", "1.0 0.5 0.75 0 90 0"], ["--target: pitch 90 is outside [-pi, pi] rad", "90 deg = 1.5708 rad", *DEGREES]),
    (["--target", "1.0 0.5 0.75 180 90 45"], ["--target: roll 180 is outside [-2 pi, 2 pi] rad", *DEGREES]),
    (["--target", "1.0 0.5 0.75 0 1.5708 0", "--target", "1 0.5 0.75 0 0 45"], ["--target 1: yaw 45", *DEGREES]),
    (["--target", "1.0 0.5 0.75 0 1.5708 0", "--start", "-2 -2 90"], ["--start: yaw 90", *DEGREES]),
    (["--target", "1.0 0.5 0.75 0 1.5708 0", "--object", "box 1 0.5 0.75 0.1 0.1 0.1 30"],
     ["--object: box yaw 30", *DEGREES]),
    (["--target", "1000 500 750 0 1.5708 0"],
     ["target 0 at (1000, 500, 750) m is 1343.0 m outside the cloud's bounds (x -3.00..2.95", *METRES]),
    (["--target", "1.0 0.5 3.0 0 0 0"], ["target 0 at (1, 0.5, 3) m is", "m higher than tiago's 'arm' arm reaches", *METRES]),
    (["--target", "1.0 0.5 0.75 0 1.5708 0", "--start", "-2000 -2000 0"],
     ["--start (-2000, -2000) m is", "outside the scanned area", *METRES]),
]  # fmt: skip


@pytest.mark.parametrize(("args", "fragments"), PLACE)
@pytest.mark.parametrize("map_arg", ["default", "unreadable"])
def test_place_refuses_before_the_map(scene, args, fragments, map_arg):
    maps = [] if map_arg == "default" else ["--map", str(scene["unreadable"])]  # neither built nor loaded
    one_line(cli(scene, "place", "--cloud", str(scene["cloud"]), *maps, *args), *fragments)


def test_place_on_a_grid_refuses_millimetres(scene):
    proc = cli(scene, "place", "--occupancy", str(scene["grid"]), "--target", "-1025 -775 600 0 0 0")
    one_line(
        proc, "outside the occupancy grid's bounds (x -2.50..2.50, y -2.50..2.50, z 0.00..0.00)", *METRES
    )


CANDIDATES = [
    (["--object", "1.0 0.5 0.6", "--robot-pose", "0 0 90"], ["--robot-pose: yaw 90", *DEGREES]),
    (["--object", "1.0 0.5 0.6", "--object-shape", "box 1 0.5 0.6 0.1 0.1 0.1 30"],
     ["--object-shape: box yaw 30", *DEGREES]),
    (["--object", "-1025 -775 600"], ["--object at (-1025, -775, 600) m is", "outside the occupancy grid's bounds",
                                      *METRES]),
    (["--object", "1.0 0.5 3.0"], ["m higher than tiago's 'arm' arm reaches", *METRES]),
    (["--object", "1.0 0.5 0.6", "--robot-pose", "-1875 75 0"], ["--robot-pose (-1875, 75) m is", *METRES]),
]  # fmt: skip


@pytest.mark.parametrize(("args", "fragments"), CANDIDATES)
@pytest.mark.parametrize("map_arg", ["default", "unreadable"])
def test_candidates_refuses_before_the_map(scene, args, fragments, map_arg):
    maps = [] if map_arg == "default" else ["--map", str(scene["unreadable"])]
    one_line(cli(scene, "candidates", "--occupancy", str(scene["grid"]), *maps, *args), *fragments)


NAVIGATE = [
    (["--start", "-2 0.6 90", "--goal", "1.7 0.6 0"], ["--start: yaw 90", *DEGREES]),
    (["--start", "-2 0.6 0", "--goal", "1.7 0.6 -180"], ["--goal: yaw -180", *DEGREES]),
    (["--start", "-2000 600 0", "--goal", "1700 600 0"], ["--start (-2000, 600) m is", "outside the scanned area", *METRES]),
]  # fmt: skip


@pytest.mark.parametrize(("args", "fragments"), NAVIGATE)
def test_navigate_refuses_before_the_segmentation(scene, args, fragments):
    one_line(cli(scene, "navigate", "--cloud", str(scene["cloud"]), *args), *fragments)
    assert not (scene["cache"] / "terrain").exists() or not list(
        (scene["cache"] / "terrain").glob("terrain-*")
    )


REACH = [
    (["--target", "0.5 0.2 0.1 0 0 0", "--base", "0.2 0.6 60"], ["--base: yaw 60", *DEGREES]),
    (["--target", "0.5 0.2 0.1 0 90 0", "--base", "0 0 0"], ["--target: pitch 90", *DEGREES]),
    (["--target", "1000 500 100 0 0 0", "--base", "200 600 0"], ["--target is", "beyond the arm's reach from --base",
                                                                  "the map's reach box", *METRES]),
    (["--target", "0.1 0 3 0 0 0", "--base", "0 0 0"], ["--target is", "beyond the arm's reach", *METRES]),
]  # fmt: skip


@pytest.mark.parametrize(("args", "fragments"), REACH)
def test_reach_refuses_before_loading_the_map(scene, args, fragments, monkeypatch):
    import baseplace.reachability.cache as cache  # imported first: it binds storage.load_map at import
    import baseplace.reachability.storage as storage

    def no_load(*_: object, **__: object) -> None:
        raise AssertionError("the map was loaded")

    monkeypatch.setattr(storage, "load_map", no_load)
    monkeypatch.setattr(cache, "load_map", no_load)
    from conftest import run_cli

    proc = run_cli("reach", "--map", str(scene["map"]), *args)
    one_line(proc, *fragments)


def test_reach_pose_files_in_degrees(scene, tmp_path):
    from conftest import run_cli

    (tmp_path / "t.txt").write_text("0.5 0.2 0.1 0 0 0\n0.5 0.2 0.1 0 0 90\n")
    (tmp_path / "b.txt").write_text("0 0 0\n0 0 0\n")
    (tmp_path / "b_deg.txt").write_text("0 0 30\n0 0 -45\n")
    (tmp_path / "b_rad.txt").write_text(f"0 0 {math.radians(30)!r}\n0 0 {math.radians(-45)!r}\n")
    one_line(run_cli("reach", "--map", str(scene["map"]), "--targets", str(tmp_path / "t.txt"), "--bases",
                     str(tmp_path / "b.txt")), "t.txt:2: yaw 90 is outside", *DEGREES)  # fmt: skip
    one_line(run_cli("reach", "--map", str(scene["map"]), "--target", "0.5 0.2 0.1 0 0 0", "--bases",
                     str(tmp_path / "b_deg.txt")), "b_deg.txt:1: yaw 30", *DEGREES)  # fmt: skip
    rad = run_cli("reach", "--map", str(scene["map"]), "--target", "0.5 0.2 0.1 0 0 0", "--bases",
                  str(tmp_path / "b_rad.txt"), "--json")  # fmt: skip
    deg = run_cli("reach", "--map", str(scene["map"]), "--target", "0.5 0.2 0.1 0 0 0", "--bases",
                  str(tmp_path / "b_deg.txt"), "--json", "--degrees")  # fmt: skip
    assert rad.returncode == deg.returncode == 0, (rad.stderr, deg.stderr)
    assert json.loads(deg.stdout)["values"] == json.loads(rad.stdout)["values"]


def test_degrees_give_the_same_answer_as_radians(scene):
    """The planar3 TCP at known joints (pinocchio), asked for in radians and in degrees."""
    from baseplace.geometry.poses import matrix_to_rpy
    from conftest import run_cli

    robot = Robot(DATA / "planar3.toml")
    arm = robot.arm()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio([0.2, 0.3, -0.4, 0.5], robot.q_reference))
    T_base_tcp = data.oMf[robot.model.getFrameId(arm.tcp_frame)].homogeneous
    c, s = math.cos(0.7), math.sin(0.7)
    T = np.array([[c, -s, 0, 1.0], [s, c, 0, 2.0], [0, 0, 1, 0], [0, 0, 0, 1]]) @ T_base_tcp
    rpy = matrix_to_rpy(T[:3, :3])
    rad = " ".join(repr(float(v)) for v in [*T[:3, 3], *rpy])
    deg = " ".join(repr(float(v)) for v in [*T[:3, 3], *np.degrees(rpy)])
    a = run_cli("reach", "--map", str(scene["map"]), "--target", rad, "--base", "1 2 0.7", "--json")
    b = run_cli("reach", "--map", str(scene["map"]), "--target", deg, "--base", f"1 2 {math.degrees(0.7)!r}",
                "--json", "--degrees")  # fmt: skip
    assert a.returncode == b.returncode == 0, (a.stderr, b.stderr)
    values = json.loads(b.stdout)["values"]
    assert values == json.loads(a.stdout)["values"] and values[0] > 0


def test_degrees_reach_the_job_as_radians(scene):
    """--degrees converts before the job: the failure report echoes the converted values."""
    proc = cli(scene, "place", "--cloud", str(scene["cloud"]), "--target", "1000 500 750 0 90 0", "--degrees",
               "--start", "0 0 -90", "--object", "box 1 0.5 0.75 0.1 0.1 0.1 180", "--yaw-tolerance", "10", "--json")  # fmt: skip
    one_line(proc, "outside the cloud's bounds")
    inputs = json.loads(proc.stdout)["inputs"]
    assert [float(v) for v in inputs["target"][0].split()] == [1000, 500, 750, 0, math.pi / 2, 0]
    assert [float(v) for v in inputs["start"].split()] == [0, 0, -math.pi / 2]
    assert float(inputs["object"].split()[-1]) == math.pi
    assert inputs["yaw_tolerance"] == pytest.approx(math.radians(10))


def test_jobs_refuse_degrees_without_the_cli(scene):
    """The library's and the service's way in: the jobs themselves refuse, with the same message."""
    from baseplace.jobs.inputs import CloudInput
    from baseplace.jobs.navigate import NavigateJob, navigate_job
    from baseplace.jobs.place import PlaceJob, place_job
    from baseplace.jobs.reach import ReachJob, reach_job

    floor = np.load(scene["cloud"])
    with pytest.raises(
        InputError, match=r"^--target: pitch 90 is outside \[-pi, pi\] rad; angles are in radians"
    ):
        place_job(
            PlaceJob(
                [[1.0, 0.5, 0.75, 0.0, 90.0, 0.0]],
                cloud=CloudInput(points=floor),
                map=str(scene["unreadable"]),
            )
        )
    with pytest.raises(
        InputError, match=r"^target 0 at \(1000, 500, 750\) m is .* outside the cloud's bounds"
    ):
        place_job(
            PlaceJob(["1000 500 750 0 0 0"], cloud=CloudInput(points=floor), map=str(scene["unreadable"]))
        )
    with pytest.raises(InputError, match=r"^--start: yaw 90 is outside"):
        navigate_job(NavigateJob([0.0, 0.0, 90.0], "1 1 0", CloudInput(points=floor)))
    with pytest.raises(InputError, match=r"^--base: yaw 60 is outside"):
        reach_job(ReachJob(str(scene["map"]), target="0.5 0.2 0.1 0 0 0", base="0.2 0.6 60"))


ARMS = [("tiago", "arm"), ("pr2", "left"), ("pr2", "right"), ("tiago_dual", "left"), ("tiago_dual", "right")]


@pytest.fixture(scope="module")
def fk_tcps() -> dict[tuple[str, str], tuple[Robot, np.ndarray]]:
    """1e5 TCP positions per arm in its base frame, by pinocchio FK at random joints within the limits."""
    out = {}
    robots = {name: Robot(name) for name in ("tiago", "pr2", "tiago_dual")}
    robots["planar3"] = Robot(DATA / "planar3.toml")
    for name, arm_name in [*ARMS, ("planar3", robots["planar3"].spec.default_arm)]:
        robot = robots[name]
        arm = robot.arm(arm_name)
        data = robot.model.createData()
        base, tcp = robot.model.getFrameId(arm.base_frame), robot.model.getFrameId(arm.tcp_frame)
        Q = arm.sample(np.random.default_rng(29), 100_000)
        P = np.empty((len(Q), 3))
        for i, q in enumerate(Q):
            pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio(q, robot.q_reference))
            P[i] = (data.oMf[base].inverse() * data.oMf[tcp]).translation
        out[(name, arm_name)] = (robot, P)
    return out


def test_reach_bound_holds_for_every_fk_sample(fk_tcps):
    from baseplace.jobs.inputs import ReachBound

    for (name, arm_name), (robot, P) in fk_tcps.items():
        bound = ReachBound.of_arm(robot.arm(arm_name))
        far, high = float(np.linalg.norm(P, axis=1).max()), float(P[:, 2].max())
        assert far <= bound.radius and high <= bound.height, (name, arm_name, far, high, bound)
        if name == "planar3":  # random joints rarely stretch its links in a line: the samples fall short
            continue
        # and tight enough to be of use: within 25 % of what the samples reach
        assert bound.radius < 1.25 * far and bound.height < 1.25 * high, (name, arm_name, far, high, bound)
    # every arm's bound is within the robot's bound over all arms (a map file's arm is not known yet)
    for name in ("pr2", "tiago_dual"):
        robot = fk_tcps[(name, "left")][0]
        whole = ReachBound.of_robot(robot)
        for arm_name in robot.spec.arms:
            one = ReachBound.of_arm(robot.arm(arm_name))
            assert one.radius <= whole.radius and one.height <= whole.height


@pytest.mark.parametrize(("name", "arm_name"), ARMS)
def test_no_fk_tcp_is_refused(fk_tcps, name, arm_name):
    """Bases on the floor cloud's edge, with targets the arm reaches: the scene check lets every one pass."""
    from baseplace.jobs.inputs import ReachBound, check_in_reach, points_bounds

    robot, P = fk_tcps[(name, arm_name)]
    xy = np.mgrid[-3:3:0.05, -3:3:0.05].reshape(2, -1).T
    bounds = points_bounds(np.c_[xy, np.zeros(len(xy))])
    rng = np.random.default_rng(3)
    yaw = rng.uniform(-math.pi, math.pi, len(P))
    corner = np.array([bounds[1][0], bounds[1][1]])  # the worst place: a corner, targets pointing out
    world = np.c_[corner + np.c_[P[:, 0] * np.cos(yaw) - P[:, 1] * np.sin(yaw),
                                 P[:, 0] * np.sin(yaw) + P[:, 1] * np.cos(yaw)], P[:, 2]]  # fmt: skip
    for arm in (arm_name, None):
        check_in_reach(world, [f"fk {i}" for i in range(len(world))], bounds, "the cloud's bounds",
                       ReachBound.of_robot(robot, arm), robot.name)  # fmt: skip
