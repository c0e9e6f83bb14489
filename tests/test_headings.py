"""Headings within +-2 pi are normalized to (-pi, pi] on input, for every command that takes one.

The oracle for the wrapped value is ``atan2(sin a, cos a)`` (which also lands on pi for -pi
after the sign fix below); for the commands, the same pose written with its heading 2 pi apart
must give the same result.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, parse_base_pose, wrap_angle
from conftest import DATA, SHARED
from conftest import run_cli as run

TWO_PI = 2.0 * math.pi


def test_wrap_angle_lands_in_the_half_open_range():
    angles = np.r_[np.linspace(-50, 50, 2001), [math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 0.0, 5.328]]
    wrapped = wrap_angle(angles)
    assert np.all(wrapped > -math.pi) and np.all(wrapped <= math.pi)
    oracle = np.arctan2(np.sin(angles), np.cos(angles))
    oracle[np.isclose(oracle, -math.pi)] = math.pi
    np.testing.assert_allclose(wrapped, oracle, atol=1e-9)
    assert float(wrap_angle(math.pi)) == math.pi and float(wrap_angle(-math.pi)) == math.pi


def test_wrap_angle_stays_in_range_next_to_odd_multiples_of_pi():
    # The division inside wrap_angle rounds across the boundary for these (found by a scan of k pi).
    k = np.arange(-41, 42)
    angles = np.r_[-122.52211349000193, -78.53981633974483, np.pi * k, np.nextafter(np.pi * k, np.inf)]
    wrapped = wrap_angle(angles)
    assert np.all(wrapped > -math.pi) and np.all(wrapped <= math.pi), angles[
        (wrapped <= -math.pi) | (wrapped > math.pi)
    ]
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angles), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angles), atol=1e-12)


def test_wrap_angle_keeps_the_deviations_of_the_old_half_open_wrap():
    # The OSRM strategies took |wrap| of [-pi, pi) (the old (a + pi) % 2 pi - pi): -pi and pi count alike.
    differences = np.r_[np.linspace(-2 * math.pi, 2 * math.pi, 4001), [math.pi, -math.pi, 2 * math.pi, 0.0]]
    old = (differences + math.pi) % TWO_PI - math.pi
    assert old[-4] == -math.pi and float(wrap_angle(math.pi)) == math.pi  # the two ranges differ at pi ...
    np.testing.assert_allclose(np.abs(wrap_angle(differences)), np.abs(old), atol=1e-12)  # ... not in |.|


@pytest.mark.parametrize("heading", [5.328, -0.955, 6.2, -6.2, TWO_PI, math.pi, -math.pi])
def test_parse_base_pose_wraps_the_heading_and_keeps_the_pose(heading):
    pose = parse_base_pose(f"1.5 -2 {heading!r}")
    assert -math.pi < pose.yaw <= math.pi
    oracle = BasePose(1.5, -2.0, heading).matrix()  # the rotation does not care about the range
    np.testing.assert_allclose(pose.matrix(), oracle, atol=1e-12)
    with pytest.raises(InputError, match="NaN or infinity"):
        parse_base_pose("0 0 inf")


@pytest.mark.parametrize("heading", [7.0, -7.0, 90.0])
def test_parse_base_pose_refuses_headings_beyond_two_pi(heading):
    """Beyond +-2 pi a heading is degrees given for radians, most likely (tests/test_input_units.py)."""
    with pytest.raises(
        InputError, match=rf"yaw {heading:g} is outside \[-2 pi, 2 pi\] rad; angles are in radians"
    ):
        parse_base_pose(f"1.5 -2 {heading!r}")


@pytest.fixture(scope="module")
def ramp_cloud(tmp_path_factory) -> Path:
    from test_navigation import _ramp_scene

    cloud = tmp_path_factory.mktemp("ramp") / "ramp.npy"
    np.save(cloud, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))
    return cloud


def test_navigate_same_path_whatever_the_goal_heading_range(ramp_cloud):
    """The issue's case: goal heading 5.328 exited 3 "no path"; -0.955 found one."""
    paths = {}
    for heading in ("5.328", repr(5.328 - TWO_PI), "-0.955"):
        proc = run("navigate", "--cloud", str(ramp_cloud), "--start", "-2 0.6 0", "--goal", f"1.7 0.6 {heading}",
                   "--json")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        paths[heading] = json.loads(proc.stdout)
    same, wrapped, rounded = paths["5.328"], paths[repr(5.328 - TWO_PI)], paths["-0.955"]
    assert same["goal"]["yaw"] == pytest.approx(5.328 - TWO_PI, abs=1e-4)  # the schema rounds to 1e-4
    assert (
        same["poses"] == wrapped["poses"] and same["length"] == wrapped["length"]
    )  # the same pose: same path
    assert same["poses"][-1][2] == pytest.approx(5.328 - TWO_PI, abs=1e-4)
    # -0.955 is the same heading to 2e-4 rad: RRT's goal tree grows from a slightly other state,
    # a path of about the same length
    assert rounded["length"] == pytest.approx(same["length"], rel=0.05)
    # the deterministic region-graph planner: the same path for 5.328 and -0.955, to that 2e-4 rad
    regions = []
    for heading in ("5.328", "-0.955"):
        proc = run("navigate", "--cloud", str(ramp_cloud), "--start", "-2 0.6 0", "--goal", f"1.7 0.6 {heading}",
                   "--planner", "regions", "--json")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        regions.append(json.loads(proc.stdout))
    assert regions[0]["regions"] == regions[1]["regions"] and len(regions[0]["poses"]) == len(
        regions[1]["poses"]
    )
    np.testing.assert_allclose(regions[0]["poses"], regions[1]["poses"], atol=3e-4)
    assert all(-math.pi < p[2] <= math.pi for r in regions for p in r["poses"])


@pytest.fixture(scope="module")
def tiago_map(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tiago") / "tiago.rmap"
    assert run("build-map", "--samples", "5e6", "--seed", "4", "--out", str(path)).returncode == 0
    return path


def test_place_start_heading_in_any_range(tiago_map, tmp_path):
    """With the default planner (OMPL RRT) a start heading of 3.2 found no path before."""
    cloud = tmp_path / "flat.ply"
    proc = run(
        "scene", "generate", "--planes", "0", "--no-box", "--extent", "6", "--seed", "2", "--out", str(cloud)
    )
    assert proc.returncode == 0, proc.stderr
    outs = []
    for heading in ("3.2", repr(3.2 - TWO_PI)):
        proc = run("place", "--cloud", str(cloud), "--target", "1.0 0.5 0.75 0 1.5708 0", "--map", str(tiago_map),
                   "--tries", "200", "--placements", "1", "--start", f"-2 -2 {heading}", "--json")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        outs.append(json.loads(proc.stdout))
    first = outs[0]["placements"][0]["path"]["poses"][0]
    assert first == pytest.approx([-2.0, -2.0, 3.2 - TWO_PI], abs=1e-4)
    assert outs[0]["placements"][0]["path"]["poses"] == outs[1]["placements"][0]["path"]["poses"]


def test_candidates_robot_pose_heading_in_any_range(tiago_map):
    yaml = SHARED / "maps" / "tb3_sandbox.yaml"
    outs = []
    for heading in ("6.0", repr(6.0 - TWO_PI)):
        proc = run("candidates", "--occupancy", str(yaml), "--object", "-1.025 -0.775 0.6", "--robot-pose",
                   f"-1.875 0.075 {heading}", "--map", str(tiago_map), "--json")  # fmt: skip
        assert proc.returncode == 0, proc.stderr
        outs.append(json.loads(proc.stdout))
    assert outs[0]["robot_pose"]["yaw"] == pytest.approx(6.0 - TWO_PI, abs=1e-4)
    assert outs[0]["candidates"] == outs[1]["candidates"] and outs[0]["path"] == outs[1]["path"]
    assert outs[0]["path"] is not None


def test_reach_base_heading_in_any_range(tmp_path):
    rmap = tmp_path / "planar3.rmap"
    proc = run("build-map", "--robot", str(DATA / "planar3.toml"), "--samples", "2e5", "--out", str(rmap))
    assert proc.returncode == 0, proc.stderr
    target = "1.2 0.4 0.0 0 0 0.3"
    values = []
    for heading in ("0.2", repr(0.2 - TWO_PI)):
        proc = run("reach", "--map", str(rmap), "--target", target, "--base", f"0.3 -0.1 {heading}", "--json")
        assert proc.returncode == 0, proc.stderr
        values.append(json.loads(proc.stdout)["values"])
    assert values[0] == values[1]


def test_surface_sample_prints_headings_navigate_accepts(tmp_path):
    env = {**os.environ, "BASEPLACE_CACHE": str(tmp_path / "cache")}
    smap = tmp_path / "table.smap"
    proc = run("surface-map", "--robot", "tiago", "--samples", "3e5", "--height", "0.7", "--resolution", "0.1",
               "--orientations", "8", "--polygon", "0,0;1.2,0;1.2,0.6;0,0.6", "--out", str(smap), env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    proc = run("surface-sample", "--map", str(smap), "--n", "12", "--candidates", "5", "--json", env=env)
    assert proc.returncode == 0, proc.stderr
    thetas = np.array([p["yaw"] for p in json.loads(proc.stdout)["poses"]])
    assert np.all(thetas > -math.pi) and np.all(thetas <= math.pi)
    assert (thetas < 0).any()  # 12 draws: some face the other half-turn (was [0, 2 pi))
