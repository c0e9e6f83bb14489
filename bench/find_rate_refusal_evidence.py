"""Evidence for two kinds of find-rate dev refusal (development data only, seeds 25000-25059).

* ``reach``: how far back along a top-down grasp's approach the TCP can go from any base pose on
  the floor (IK only: ``DampedLeastSquaresIK`` with 30 restarts, no collision check; base poses on
  rings of 0.35-0.75 m around the pre-grasp, 24 directions, 12 headings each), in 1 cm steps until
  no base pose reaches; and how far back the fingertips (:func:`~baseplace.placement.motion.hand_reach`
  ahead of the TCP) clear the true bottle top. A scene whose clearing offset lies beyond every
  reachable one has no straight top-down approach at all (the find-rate oracle checks no motion).
* ``smooth``: the share of each true shape's points (within 0.35 m of the grasped bottle, above
  the table top) that :func:`~baseplace.world.sensor_resolution.denoised` finds on a smooth
  surface; the others stay raw points at the full clearance; per neighbour bottle also by band
  (``neighbour_bands``: its bottom 3 cm, its side, its top 2 cm with its top face, the rim).

Usage: python bench/find_rate_refusal_evidence.py {reach,smooth} --seeds 25011 ... --out x.json
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baseplace.errors import InputError
from baseplace.geometry.poses import invert_transforms, pose_from_xyz_rpy
from baseplace.placement.motion import approach_axis, hand_reach
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.world.sensor_resolution import denoised
from baseplace_experiments.results import RunClock, write_results
from find_rate import SEEDS, make_scene
from find_rate_refusals import nearest_shape

RADII = (0.35, 0.45, 0.55, 0.65, 0.75)
"""Base distances from the target TCP position [m]."""
DIRECTIONS, HEADINGS = 24, 12
MAX_BACK = 0.15
"""The largest offset along the approach tried [m]."""
RIM = 0.02
"""``smooth``: a neighbour's points this close [m] under its top, and its top, are its rim band."""
BOTTOM = 0.03
"""``smooth``: a neighbour's points this close [m] over the table top are its bottom band."""


def reachable(ik: DampedLeastSquaresIK, T: np.ndarray, rng: np.random.Generator) -> bool:
    """Whether IK reaches the world TCP pose ``T`` (4, 4) from some base pose on the rings."""
    for r in RADII:
        for phi in np.linspace(0.0, 2 * math.pi, DIRECTIONS, endpoint=False):
            x, y = T[0, 3] - r * math.cos(phi), T[1, 3] - r * math.sin(phi)
            for heading in np.linspace(-math.pi, math.pi, HEADINGS, endpoint=False):
                T_base = pose_from_xyz_rpy([x, y, 0.0, 0.0, 0.0, phi + heading])
                if ik.solve(invert_transforms(T_base) @ T, rng) is not None:
                    return True
    return False


def reach_row(robot: Robot, seed: int) -> dict[str, Any]:
    arm = robot.arm()
    scene = make_scene(seed)
    if scene.kind != "top-down":
        raise InputError(f"seed {seed} is a {scene.kind} grasp; reach is for top-down ones")
    axis, ik, rng = approach_axis(arm), DampedLeastSquaresIK(arm, restarts=30), np.random.default_rng(seed)
    T_tcp = pose_from_xyz_rpy(scene.grasp) @ np.linalg.inv(robot.T_tcp_grasp(None))
    direction = T_tcp[:3, :3] @ axis
    top = scene.table[2] + scene.bottle[3]
    fingertip = hand_reach(robot, arm)
    clears = top - (T_tcp[2, 3] - fingertip)  # the TCP rises along -direction (straight up)
    furthest = None
    for k in range(round(MAX_BACK / 0.01) + 1):
        T = T_tcp.copy()
        T[:3, 3] -= 0.01 * k * direction
        if not reachable(ik, T, rng):
            break
        furthest = round(0.01 * k, 2)
    return {"seed": seed, "tcp_z": round(float(T_tcp[2, 3]), 4), "bottle_top_z": round(top, 4),
            "fingertips_clear_top_at_m": round(float(clears), 4), "furthest_reachable_m": furthest,
            "straight_approach_exists": bool(furthest is not None and furthest >= clears)}  # fmt: skip


def smooth_row(seed: int) -> dict[str, Any]:
    scene = make_scene(seed)
    bx, by, _, _ = scene.bottle
    p = scene.cloud
    near = p[(np.hypot(p[:, 0] - bx, p[:, 1] - by) < 0.35) & (p[:, 2] > scene.table[2] + 0.006)]
    names = np.array(nearest_shape(near, scene)[0])
    keep = names != "bottle (own points)"
    _, smooth = denoised(near[keep])
    names, near = names[keep], near[keep]
    bands = {}
    for k, (_, _, _, h) in enumerate(scene.neighbours):  # where on each neighbour bottle the raw points lie
        mine = names == f"neighbour {k}"
        z = near[mine, 2] - scene.table[2]
        band = np.where(z > h - RIM, "rim", np.where(z < BOTTOM, "bottom", "side"))
        bands[f"neighbour {k}"] = {b: {"points": int(np.sum(band == b)), "smooth_share": round(float(smooth[mine][band == b].mean()), 3)}
                                   for b in ("bottom", "side", "rim") if np.any(band == b)}  # fmt: skip
    return {"seed": seed, "smooth_share": {n: round(float(smooth[names == n].mean()), 3) for n in sorted(set(names))},
            "points": {n: int(np.sum(names == n)) for n in sorted(set(names))}, "neighbour_bands": bands}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("reach", "smooth"))
    parser.add_argument("--seeds", type=int, nargs="+", required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    if any(s not in range(25000, 25060) or s in SEEDS.held_out for s in args.seeds):
        raise InputError("development seeds 25000-25059 only")
    clock = RunClock()
    robot = Robot("tiago")
    rows = []
    for seed in args.seeds:
        rows.append(reach_row(robot, seed) if args.what == "reach" else smooth_row(seed))
        print(rows[-1], flush=True)
    write_results(args.out, {"benchmark": f"find_rate_refusal_evidence_{args.what}", "scenes": rows}, clock,
                  used_seeds=args.seeds)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
