"""Map precision and recall on the poses ``place`` and ``candidates`` query, per pose distribution.

Protocol: docs/protocols/map_precision.md (issue 27 item 4), committed before the first run: side
grasps (``candidates``), tilted top-down grasps (``place``) 0.5-1.0 m high within 1.3 m of a floor
base, and the uniform draw over the reached cells (``bench_accuracy.py``); precision and recall
against damped least-squares IK (80 restarts) with 95 % Wilson intervals; recall on held-out FK
poses too.

Protocol 2 (docs/protocols/map_precision_v2.md, ``--protocol 2``): the same, with each map of
>= 1e7 samples read with the support settings its build chose on its own recall (the ladder of
``reachability/support.py``, hole fill included) and a new held-out seed; ``--protocol 1`` (the
default) reads every map with the build's fixed threshold and no fill, as v1's results were measured.

``--diagnose`` (dev split only) adds, per distribution, where the misses (IK solves, the map says
no) and the false calls (the map says yes, IK fails) lie next to the hits and the true rejections:
the pose's cell's sample count, its support (the map's own count, and count 1: the share of the 64
interpolation neighbours reached, a proxy for the distance from the reached set's boundary), its
offset from the cell's centre (position in voxels, orientation in rad), and for the IK-solved poses
how many joints of the solution lie within 2 % of their range of a limit; and, for the side and
top-down draws, the ceiling of any reading of the support: for the map's support count and for
count 1, the strictest step (threshold and fill alike) whose recall reaches 98.5 % and its precision;
and whether the bin's reachable part lies off the pose: for up to :data:`TILT_POSES` poses of each
group (the true rejections only in reached cells), the share IK solves once the TCP z axis is tilted
by :data:`TILT` about the TCP's x or y axis (4 directions, the position kept; still inside the bin
for most poses); and how often the ground truth itself misses: the share of the false calls and
of up to :data:`TILT_POSES` true rejections that IK solves in :data:`RETRY_RUNS` more runs of its
restarts. Its IK draws from :data:`DIAGNOSIS_SEED`, never from the split's seed stream, so the
protocol's figures are the same with or without ``--diagnose``.

Usage: python bench/bench_map_precision.py [--samples 1e7 | --map FILE] [--n 4000] [--split dev]
       [--protocol 2] [--name map_precision_1e7] [--diagnose]
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from numpy.typing import NDArray

from baseplace.geometry.poses import FloatArray, pose_from_xyz_rpy, rotation_taking
from baseplace.placement.robustness import wilson_interval
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.certify import poses_in_cells
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import load_map
from baseplace.reachability.support import LADDER_FROM, TARGET_RECALL, choose_support
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace_experiments.results import fixed_protocol
from common import report

PROTOCOL_FILES = {1: "docs/protocols/map_precision.md", 2: "docs/protocols/map_precision_v2.md"}
SPLITS = {1: {"held-out": 4242, "dev": 2424}, 2: {"held-out": 4343, "dev": 2424}}
RADIUS = 1.3
"""Grasp points lie within this horizontal distance of the base [m]."""
HEIGHTS = (0.5, 1.0)
"""Grasp points lie this high above the floor [m]."""
SIDE_STANDOFF = 0.15
"""``candidates``: the TCP stands this far back from the grasp point along the approach [m]."""
TOP_STANDOFF = 0.151
"""``place`` (``osrm_experiment.grasp_candidates``): the same for its top-down grasps [m]."""
MAX_TILT = math.radians(20)


def grasp_points(rng: np.random.Generator, n: int) -> FloatArray:
    """(n, 3) points uniform in area in the disc of radius :data:`RADIUS`, uniform in :data:`HEIGHTS`."""
    r = RADIUS * np.sqrt(rng.uniform(0.0, 1.0, n))
    bearing = rng.uniform(-math.pi, math.pi, n)
    return np.c_[r * np.cos(bearing), r * np.sin(bearing), rng.uniform(*HEIGHTS, n)]


def side_grasps(rng: np.random.Generator, n: int, approach_axis: FloatArray) -> FloatArray:
    """(n, 4, 4) side grasps as ``irm_candidates.grasp_poses``: approach horizontal, random yaw, roll 0."""
    p = grasp_points(rng, n)
    yaw = rng.uniform(-math.pi, math.pi, n)
    T = pose_from_xyz_rpy(np.c_[p, np.zeros(n), np.zeros(n), yaw])
    T[:, :3, 3] -= SIDE_STANDOFF * T[:, :3, 0]
    T[:, :3, :3] = T[:, :3, :3] @ rotation_taking(approach_axis, (1.0, 0.0, 0.0))
    return T


def top_down_grasps(rng: np.random.Generator, n: int, approach_axis: FloatArray) -> FloatArray:
    """(n, 4, 4) top-down grasps as ``osrm_experiment.grasp_candidates``: tilt <= 20 deg, random roll."""
    p = grasp_points(rng, n)
    tilt = rng.uniform(0.0, MAX_TILT, n)
    roll, heading = rng.uniform(-math.pi, math.pi, (2, n))
    T = pose_from_xyz_rpy(np.c_[np.zeros((n, 3)), roll, math.pi / 2 - tilt, heading])
    T[:, :3, 3] = p - TOP_STANDOFF * T[:, :3, 0]
    T[:, :3, :3] = T[:, :3, :3] @ rotation_taking(approach_axis, (1.0, 0.0, 0.0))
    return T


def uniform_kept(rmap: ReachabilityMap, rng: np.random.Generator, n: int) -> FloatArray:
    """(n, 4, 4) poses uniform over the reached cells that the map keeps (``bench_accuracy.py``'s draw)."""
    kept: list[FloatArray] = []
    total = 0
    while total < n:
        T = poses_in_cells(rmap.grid, rmap.cells[rng.integers(len(rmap.cells), size=n)], rng)
        T = T[rmap.reachability(T) > 0]
        kept.append(T)
        total += len(T)
    return np.concatenate(kept)[:n]


def _rate(k: int, n: int) -> dict[str, object]:
    low, high = wilson_interval(k, n) if n else (math.nan, math.nan)
    return {"value": round(k / n, 4) if n else None, "k": k, "n": n, "ci95": [round(low, 4), round(high, 4)]}


def measure(rmap: ReachabilityMap, ik: DampedLeastSquaresIK, T: FloatArray, rng: np.random.Generator,
            with_recall: bool, diagnose: bool = False) -> dict[str, object]:  # fmt: skip
    """Precision (and recall) of the map's verdict on poses (N, 4, 4) against IK."""
    called = rmap.reachability(T) > 0
    q, solved = ik.solve_batch(T, rng)
    solved = np.asarray(solved, dtype=bool)
    out: dict[str, object] = {
        "poses": len(T),
        "called_reachable": round(float(called.mean()), 4),
        "ik_solved": round(float(solved.mean()), 4),
        "precision": _rate(int((called & solved).sum()), int(called.sum())),
    }
    if with_recall:
        out["recall"] = _rate(int((called & solved).sum()), int(solved.sum()))
    if diagnose:
        out["diagnosis"] = diagnosis(rmap, ik, T, called, solved, q)
    return out


DIAGNOSIS_SEED = 0xD1A6
"""The IK restarts of ``--diagnose``'s tilted poses (dev only; independent of every split's seed)."""
TILT = 0.3
"""How far ``--diagnose`` tilts the TCP z axis [rad]: under the 0.8 rad orientation bin."""
TILT_POSES = 100
"""Poses per group that ``--diagnose`` tilts."""
RETRY_RUNS = 5
"""More runs of the IK's restarts that ``--diagnose`` gives the poses IK did not solve."""

SUPPORT_STEPS = np.round(np.arange(0.05, 1.0001, 0.05), 2)
"""The support of a pose is read to this resolution (the largest step whose test it passes)."""


def support_at(rmap: ReachabilityMap, T: FloatArray, count: int) -> FloatArray:
    """(N,) support of each pose with support count ``count``, to :data:`SUPPORT_STEPS`; 0 below the first.

    Read through the map's own lookup with the test at each step, the fill at the same step (so a pose
    in an unreached cell gets its support too).
    """
    out = np.zeros(len(T))
    for step in SUPPORT_STEPS:
        out[rmap.with_support(count, float(step), float(step)).reachability(T) > 0] = step
    return out


def cell_counts(rmap: ReachabilityMap, T: FloatArray) -> NDArray[np.int64]:
    """(N,) samples in each pose's cell (0: unreached or outside the grid)."""
    c = rmap.grid.cell_index(T)
    i = np.minimum(np.searchsorted(rmap.cells, c), max(len(rmap.cells) - 1, 0))
    hit = (c >= 0) & (rmap.cells[i] == c) if len(rmap.cells) else np.zeros(len(T), dtype=bool)
    return np.where(hit, rmap.counts[i].astype(np.int64), 0)


def _summary(values: FloatArray, bins: list[float]) -> dict[str, object]:
    if len(values) == 0:
        return {"n": 0}
    hist = np.histogram(values, bins=bins)[0]
    return {
        "n": len(values),
        "median": round(float(np.median(values)), 3),
        "histogram": {
            f"[{lo:g}, {hi:g})": int(k) for lo, hi, k in zip(bins[:-1], bins[1:], hist, strict=True)
        },
    }


def diagnosis(rmap: ReachabilityMap, ik: DampedLeastSquaresIK, T: FloatArray, called: NDArray[np.bool_],
              solved: NDArray[np.bool_], q: FloatArray) -> dict[str, object]:  # fmt: skip
    """Where the hits, misses, false calls and true rejections lie (module docstring)."""
    arm = ik.arm
    grid = rmap.grid
    counts = cell_counts(rmap, T)
    count = rmap.info.support_count or 1
    own = support_at(rmap, T, count)
    occupied = support_at(rmap, T, 1)
    inside = counts > 0
    centre = grid.cell_centre(np.where(grid.cell_index(T) >= 0, grid.cell_index(T), 0))
    offset_pos = np.abs(T[:, :3, 3] - centre[:, :3, 3]).max(axis=1) / grid.voxel_size
    cos = (np.einsum("nij,nij->n", centre[:, :3, :3], T[:, :3, :3]) - 1.0) / 2.0
    offset_rot = np.arccos(np.clip(cos, -1.0, 1.0))
    lower, upper = np.asarray(arm.lower), np.asarray(arm.upper)
    margin = np.minimum(q - lower, upper - q) / (upper - lower)
    at_limit = (margin < 0.02).sum(axis=1)
    groups = {
        "hit": called & solved,
        "miss": ~called & solved,
        "false_call": called & ~solved,
        "true_reject": ~called & ~solved,
    }
    tilt_rng = np.random.default_rng(DIAGNOSIS_SEED)
    count_bins = [0, 1, 2, 3, 5, 10, 20, 50, 1e9]
    unit = [0, 0.05, 0.2, 0.4, 0.6, 0.8, 1.01]
    out: dict[str, object] = {}
    for name, m in groups.items():
        row: dict[str, object] = {
            "n": int(m.sum()),
            "cell_count": _summary(counts[m], count_bins),
            "support": _summary(own[m], unit),
            "support_count_1": _summary(occupied[m], unit),
            "offset_position_voxels": _summary(offset_pos[m & inside], [0, 0.25, 0.4, 0.5001]),
            "offset_orientation_rad": _summary(offset_rot[m & inside], [0, 0.2, 0.4, 0.6, 0.8, 4]),
        }
        if name in ("hit", "miss"):
            row["joints_within_2pct_of_limit"] = _summary(at_limit[m], [0, 1, 2, 3, 9])
        if name != "miss":
            row["ik_solves_tilted"] = _tilted(ik, T[m & inside][:TILT_POSES], tilt_rng)
        if name in ("false_call", "true_reject"):
            row["ik_solves_with_more_restarts"] = _retried(ik, T[m][:TILT_POSES], tilt_rng)
        out[name] = row
    if not solved.all() and called.any() and (~called).any():  # a draw with recall: the readings' ceiling
        out["best_reading_at_target_recall"] = {
            f"support_count_{count}": _best_reading(own, solved),
            "support_count_1": _best_reading(occupied, solved),
        }
    return out


def _tilted(ik: DampedLeastSquaresIK, T: FloatArray, rng: np.random.Generator) -> dict[str, object]:
    """Share of poses IK solves with the TCP z axis tilted by :data:`TILT` in at least one of 4 directions."""
    if len(T) == 0:
        return {"n": 0}
    c, s = math.cos(TILT), math.sin(TILT)
    turns = np.array([
        [[1, 0, 0], [0, c, -s], [0, s, c]], [[1, 0, 0], [0, c, s], [0, -s, c]],
        [[c, 0, s], [0, 1, 0], [-s, 0, c]], [[c, 0, -s], [0, 1, 0], [s, 0, c]],
    ])  # fmt: skip
    tilted = np.repeat(T, 4, axis=0)
    tilted[:, :3, :3] = tilted[:, :3, :3] @ np.tile(turns, (len(T), 1, 1))
    _, solved = ik.solve_batch(tilted, rng)
    solved = np.asarray(solved, dtype=bool).reshape(len(T), 4)
    return {"n": len(T), "tilt_rad": TILT, "any_direction": _rate(int(solved.any(axis=1).sum()), len(T)),
            "per_direction": round(float(solved.mean()), 4)}  # fmt: skip


def _retried(ik: DampedLeastSquaresIK, T: FloatArray, rng: np.random.Generator) -> dict[str, object]:
    """Share of poses IK solves in :data:`RETRY_RUNS` more runs of its restarts."""
    solved = np.zeros(len(T), dtype=bool)
    for _ in range(RETRY_RUNS if len(T) else 0):
        solved |= np.asarray(ik.solve_batch(T, rng)[1], dtype=bool)
    return {"runs": RETRY_RUNS, "restarts_per_run": ik.restarts, **_rate(int(solved.sum()), len(T))}


def _best_reading(support: FloatArray, solved: NDArray[np.bool_]) -> dict[str, object]:
    """The strictest support step whose recall reaches :data:`TARGET_RECALL` (else the loosest), its precision."""
    for step in SUPPORT_STEPS[::-1]:
        called = support >= step
        hits = int((called & solved).sum())
        if hits >= TARGET_RECALL * solved.sum() or step == SUPPORT_STEPS[0]:
            return {
                "step": float(step),
                "met": bool(hits >= TARGET_RECALL * solved.sum()),
                "precision": _rate(hits, int(called.sum())),
                "recall": _rate(hits, int(solved.sum())),
            }
    raise AssertionError("unreachable")


def as_protocol(rmap: ReachabilityMap, robot: Robot, protocol: int, threshold: float) -> ReachabilityMap:
    """The map read as the protocol says: v1 with ``threshold`` and no fill, v2 with the ladder's choice."""
    info = rmap.info
    if not info.supported:
        return rmap
    if protocol == 1:
        return rmap.with_support(info.support_count, threshold)
    if info.samples >= LADDER_FROM and not (info.quality and "ladder" in info.quality):
        return choose_support(rmap, robot, info.support_count, info.support_threshold)
    return rmap


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--map", default=None, help="a map file (default: build one)")
    parser.add_argument("--samples", type=float, default=1e7, help="samples of the map built (default 1e7)")
    parser.add_argument("--seed", type=int, default=0, help="the build's seed")
    parser.add_argument("--n", type=int, default=4000, help="poses per distribution")
    parser.add_argument("--split", choices=sorted(SPLITS[1]), default="dev")
    parser.add_argument("--protocol", type=int, choices=sorted(PROTOCOL_FILES), default=1)
    parser.add_argument("--name", default=None, help="results file bench/results/NAME.json")
    parser.add_argument("--diagnose", action="store_true", help="where the misses and false calls lie")
    args = parser.parse_args()
    if args.diagnose and args.split != "dev":
        parser.error("--diagnose is for the dev split only")
    protocol_file = fixed_protocol(PROTOCOL_FILES[args.protocol], args.split)
    seed = SPLITS[args.protocol][args.split]
    robot = Robot("tiago")
    arm = robot.arm()
    if args.map:
        rmap = load_map(args.map, robot)
        threshold = rmap.info.support_threshold
    else:
        settings = BuildSettings(samples=int(args.samples), seed=args.seed)
        rmap = build_map(robot, None, settings)
        threshold = settings.support_threshold
    rmap = as_protocol(rmap, robot, args.protocol, threshold)
    rng = np.random.default_rng(seed)
    ik = DampedLeastSquaresIK(arm)
    axis = np.asarray(arm.approach_axis, dtype=float)
    held_out = forward_kinematics(arm, arm.sample(rng, 10_000))
    distributions = {
        "side": measure(rmap, ik, side_grasps(rng, args.n, axis), rng, True, args.diagnose),
        "top-down": measure(rmap, ik, top_down_grasps(rng, args.n, axis), rng, True, args.diagnose),
        "uniform": measure(rmap, ik, uniform_kept(rmap, rng, args.n), rng, False, args.diagnose),
    }
    called = int((rmap.reachability(held_out) > 0).sum())
    result = {
        "map": {
            "samples": rmap.info.samples,
            "seed": args.seed if not args.map else None,
            "support": {
                "count": rmap.info.support_count,
                "threshold": rmap.info.support_threshold,
                "fill": rmap.info.fill_threshold,
            },
            "cells_reached": rmap.n_reached,
            "recorded_quality": rmap.info.quality or None,
        },
        "recall_held_out_fk": _rate(called, len(held_out)),
        "distributions": distributions,
        "target": "precision >= 96% at recall >= 98.5% per distribution (issue 27 item 4)",
    }
    version = "" if args.protocol == 1 else f"_v{args.protocol}"
    name = args.name or f"map_precision{version}_{rmap.info.samples:.0e}_{args.split}".replace(
        "+0", ""
    ).replace("+", "")
    report(name, result, split=args.split, used_seeds=[seed], protocol_file=protocol_file)


if __name__ == "__main__":
    main()
