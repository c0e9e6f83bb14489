"""bench/find_rate.py (issue 25): its scenes are fixed by their seeds, its oracle sees what it must."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import find_rate  # noqa: E402


def test_the_protocol_file_exists_and_the_splits_are_disjoint():
    assert (ROOT / find_rate.PROTOCOL_FILE).is_file()
    assert not set(find_rate.SEEDS.dev) & set(find_rate.SEEDS.held_out)
    kinds = [find_rate.make_scene(s).kind for s in find_rate.SEEDS.held_out[:4]]
    assert kinds == ["side", "top-down", "side", "top-down"]
    assert len(find_rate.SEEDS.held_out) == 60


def test_a_scene_is_fixed_by_its_seed_and_keeps_its_rules():
    for seed in find_rate.SEEDS.dev[:4]:
        a, b = find_rate.make_scene(seed), find_rate.make_scene(seed)
        assert a.record() == b.record()
        lx, ly, h = a.table
        x, y, r, hb = a.bottle
        assert abs(x) <= lx / 2 - r and abs(y) <= ly / 2 - r
        for nx, ny, nr, _ in a.neighbours:
            gap = math.hypot(nx - x, ny - y) - r - nr
            assert 0.03 - 1e-9 <= gap <= 0.08 + 1e-9
        gx, gy, gz = a.grasp[:3]
        assert (gx, gy) == (x, y) and h < gz < h + hb
        noise = a.cloud[np.abs(a.cloud[:, 0]) > lx / 2 + 0.1][:, 2]  # floor points only
        assert 0.002 < float(np.std(noise)) < 0.004
    assert find_rate.make_scene(25000).record() != find_rate.make_scene(25002).record()


@pytest.fixture(scope="module")
def oracle(tiago):
    return find_rate.Oracle(tiago)


def test_the_oracle_finds_a_pose_whose_robot_touches_only_the_bottle_and_sees_a_base_in_the_table(oracle):
    scene = find_rate.make_scene(25001)  # top-down, no neighbour: the dev run found a pose at once
    verdict = oracle.search(scene, np.random.default_rng(0))
    assert verdict["found"]
    x, y, yaw = verdict["base"]
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:2, 3] = x, y
    q = np.array(verdict["joints"])
    touched = oracle.contacts(q, T, scene, first=False)
    assert oracle.counting(touched) == [] and any(c.endswith("bottle (hand)") for c in touched)
    inside = T.copy()
    inside[:2, 3] = 0.0, 0.0  # the base in the middle of the table box
    assert any(
        c.endswith(" - table") for c in oracle.counting(oracle.contacts(q, inside, scene, first=False))
    )
    lifted = T.copy()
    lifted[:3, 3] += [4.0, 4.0, -1.3]  # far from the table, the arm sunk into the floor
    sunk = oracle.counting(oracle.contacts(q, lifted, scene, first=False))
    assert sunk and all(c.endswith(" - floor") for c in sunk)


def test_a_hand_in_a_neighbour_at_the_grasp_means_no_placement(oracle):
    scene = find_rate.make_scene(25000)  # side grasp, the fingers reach the neighbour 3-8 cm beside
    verdict = oracle.search(scene, np.random.default_rng(0))
    assert not verdict["found"] and verdict["poses_tried"] == 0
    assert any("neighbour" in c for c in verdict["hand_at_grasp"])


@pytest.mark.slow
def test_one_dev_scene_end_to_end(tmp_path):
    out = tmp_path / "fr.json"
    assert find_rate.main(["--seeds", "dev", "--seed", "25001", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    row = result["scenes"][0]
    assert row["scene"]["seed"] == 25001 and row["oracle"]["found"]
    summary = result["summary"]["all"]
    assert summary["solvable"] == 1 and summary["found"] == row["method"]["found"]
    assert summary["false_positives"] == sum(bool(p["touches"]) for p in row["method"].get("placements", []))
    assert result["provenance"]["protocol_file"]["file"] == find_rate.PROTOCOL_FILE
    assert result["library"]["commit"] and result["harness"]["commit"]


def test_joints_rounded_past_a_limit_are_put_back_but_a_real_violation_stays(oracle):
    lo, hi = oracle.arm.lower, oracle.arm.upper
    q = 0.5 * (lo + hi)
    q[3] = lo[3] - 2.6e-7  # as a result row's 6-decimal rounding gave (held-out seed 25106)
    fixed, rounded = find_rate.unrounded(q, lo, hi)
    assert rounded and fixed[3] == lo[3] and bool(oracle.arm.within_limits(fixed))
    q[3] = lo[3] - 1e-3
    kept, rounded = find_rate.unrounded(q, lo, hi)
    assert not rounded and kept[3] == q[3]
    scene = find_rate.make_scene(25001)
    far = np.eye(4)
    far[:2, 3] = 4.0, 4.0
    assert oracle.contacts(kept, far, scene, first=False)[0] == "joint limits"


def test_protocol_v2_has_its_own_file_and_fresh_held_out_seeds():
    file, split, with_approach = find_rate.PROTOCOLS["v2"]
    assert (ROOT / file).is_file() and with_approach
    assert not set(split.dev) & set(split.held_out)
    assert not set(split.held_out) & set(find_rate.SEEDS.held_out)  # v1's held-out scenes are not reused
    assert len(split.held_out) == 100
    assert find_rate.PROTOCOLS["v1"] == (find_rate.PROTOCOL_FILE, find_rate.SEEDS, False)


def test_protocol_v2_fresh_runs_v2_on_held_out_seeds_no_find_rate_run_used():
    file, split, with_approach = find_rate.PROTOCOLS["v2-fresh"]
    _, v2, _ = find_rate.PROTOCOLS["v2"]
    assert (ROOT / file).is_file() and with_approach
    assert split.dev == v2.dev and len(split.held_out) == 100
    assert not set(split.held_out) & (set(v2.held_out) | set(find_rate.SEEDS.held_out) | set(split.dev))


@pytest.mark.parametrize("name", ["v2-plane", "v2-plane-4mm"])
def test_protocol_v2_plane_runs_v2_on_held_out_seeds_no_find_rate_run_used(name):
    file, split, with_approach = find_rate.PROTOCOLS[name]
    used = set(find_rate.SEEDS.held_out)
    for other in ("v2", "v2-fresh"):
        used |= set(find_rate.PROTOCOLS[other][1].held_out)
    assert (ROOT / file).is_file() and with_approach and len(split.held_out) == 100
    assert split.dev == find_rate.PROTOCOLS["v2"][1].dev
    assert not set(split.held_out) & (used | set(split.dev))
    assert not set(find_rate.PROTOCOLS["v2-plane"][1].held_out) & set(
        find_rate.PROTOCOLS["v2-plane-4mm"][1].held_out
    )
    assert find_rate.NOISES.get(name, find_rate.NOISE) == {"v2-plane": 0.003, "v2-plane-4mm": 0.004}[name]


def _pose(x, y, yaw):
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:2, 3] = x, y
    return T


def test_the_v2_oracle_walks_the_hand_straight_up_out_of_a_bottle(oracle):
    scene = find_rate.make_scene(25001)  # top-down: the hand comes out of the bottle going up
    verdict = oracle.search(scene, np.random.default_rng(0))
    T_base = _pose(*verdict["base"])
    T_tcp = find_rate.pose_from_xyz_rpy(scene.grasp) @ np.linalg.inv(oracle.T_tcp_grasp)
    walk = oracle.approach(np.array(verdict["joints"]), T_base, T_tcp, scene)
    assert walk["ok"] and 0.05 < walk["distance"] < find_rate.APPROACH_MAX
    # the hand alone clears the bottle at the same distance back, whatever the base pose
    T_clear = oracle.hand_clear_pose(T_tcp, scene)
    assert T_clear is not None
    back = float(np.linalg.norm(T_clear[:3, 3] - T_tcp[:3, 3]))
    assert back == pytest.approx(walk["distance"], abs=1e-9)
    assert not oracle.hand_contacts(T_clear, scene)
    one_short = T_clear.copy()
    one_short[:3, 3] += find_rate.APPROACH_STEP * (T_tcp[:3, :3] @ oracle.arm.approach_axis)
    assert any("bottle" in c for c in oracle.hand_contacts(one_short, scene))
    # the approach goes up, away from the table: the TCP's line, checked apart from the walk
    direction = T_clear[:3, 3] - T_tcp[:3, 3]
    assert direction[2] > 0.99 * np.linalg.norm(direction)


def test_the_v2_oracle_refuses_an_approach_that_meets_a_shelf_or_leaves_the_reach(oracle):
    scene = find_rate.make_scene(25001)
    verdict = oracle.search(scene, np.random.default_rng(0))
    q, T_base = np.array(verdict["joints"]), _pose(*verdict["base"])
    T_tcp = find_rate.pose_from_xyz_rpy(scene.grasp) @ np.linalg.inv(oracle.T_tcp_grasp)
    # a shelf 6 cm above the bottle's top: the hand, which must rise about 0.12 m to clear the
    # bottle, meets it on the way out
    shelf = find_rate.Solid("shelf", find_rate.coal.Box(0.4, 0.4, 0.02), T_tcp.copy())
    shelf.T[:3, :3] = np.eye(3)
    shelf.T[2, 3] = scene.table[2] + scene.bottle[3] + 0.07
    solids = scene.solids

    class Shelved(find_rate.Scene):
        def solids(self):
            obstacles, bottle, floor = solids()
            return [*obstacles, shelf], bottle, floor

    shelved = Shelved(**{f: getattr(scene, f) for f in scene.__dataclass_fields__})
    walk = oracle.approach(q, T_base, T_tcp, shelved)
    assert not walk["ok"] and walk["why"].endswith(" - shelf") and walk["distance"] < 0.115
    assert oracle.approach(q, T_base, T_tcp, scene)["ok"]  # without the shelf it comes out
    # a base pose 0.4 m further away: the grasp is not even reachable from there, so the walk
    # fails on IK at its first step
    far = T_base.copy()
    far[:2, 3] += 0.4 * (far[:2, 3] - T_tcp[:2, 3]) / np.linalg.norm(far[:2, 3] - T_tcp[:2, 3])
    walk = oracle.approach(q, far, T_tcp, scene)
    assert not walk["ok"] and walk["why"] in ("ik", "jump") and walk["distance"] == find_rate.APPROACH_STEP


def test_the_hand_gap_is_where_the_lowered_hand_starts_touching_the_table(oracle):
    from find_rate_hand_gaps import hand_gap

    scene = find_rate.make_scene(25022)  # side grasp: the little finger just above the table top
    gap, between = hand_gap(oracle, scene)
    assert between == "hand_little_flex_3_link - table" and 0.0 < gap < 0.005
    T_tcp = find_rate.pose_from_xyz_rpy(scene.grasp) @ np.linalg.inv(oracle.T_tcp_grasp)
    for drop, touches in ((gap - 0.0003, False), (gap + 0.0003, True)):
        T = T_tcp.copy()
        T[2, 3] -= drop  # straight down: the finger's lowest point meets the flat top first
        assert any(c.endswith(" - table") for c in oracle.hand_contacts(T, scene)) is touches


def test_an_unknown_protocol_is_refused_with_the_choices(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        find_rate.main(["--protocol", "v9", "--seeds", "dev", "--out", str(tmp_path / "x.json")])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--protocol" in err and "'v1'" in err and "'v2'" in err and "v9" in err
    assert not (tmp_path / "x.json").exists()


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--seeds", "held-out", "--noise", "0.004"], "dev split only"),
        (["--seeds", "dev", "--noise", "-0.001"], "in (0, 0.05]"),
        (["--seeds", "dev", "--noise", "nan"], "in (0, 0.05]"),
    ],
)
def test_a_noise_off_the_protocol_is_for_dev_runs_only(tmp_path, capsys, args, says):
    with pytest.raises(SystemExit) as exc:
        find_rate.main(["--protocol", "v2", *args, "--out", str(tmp_path / "x.json")])
    assert exc.value.code == 2
    assert says in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "x.json").exists()
    assert find_rate.NOISE == 0.003  # the protocol's noise is left as it was
