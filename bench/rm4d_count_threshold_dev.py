"""Dev-split study for the RM4D side by side: does dropping sparse cells buy precision on the Panda?

On the dev seeds of ``bench_rm4d.py`` (held-out FK poses 5678, random poses 8765; never the
reported held-out seeds 1234 / 4321), with that benchmark's robot (RM4D's Panda URDF, TCP
``panda_grasptarget``), poses and IK oracle (80 restarts, a solution counts only if coal finds it
free of self-collision, up to 4 rounds): baseplace maps built with self-collision at 0.8, 0.6 and
0.5 rad orientation bins (``--samples``, about the equal-time build's count), each read with a
minimum sample count k per cell (1 = the map as built). Per k: recall on the held-out FK poses,
precision against IK on the random poses the map calls reachable. RM4D is not run here (its
dev-split precision is in ``bench/results/rm4d_side_by_side_dev.json``).

Usage: python bench/rm4d_count_threshold_dev.py --rm4d RM4D_CHECKOUT [--samples 25000000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.rmap import reach_bounds
from baseplace.robots.collision import SelfCollision
from bench_rm4d import VOXEL, ik_oracle, panda, pin_fk, random_poses
from common import report

THRESHOLDS = (1, 2, 3, 4, 5, 6, 8)
RESOLUTIONS = (0.8, 0.6, 0.5)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rm4d", type=Path, required=True, help="checkout of RM4D's repository")
    parser.add_argument("--samples", type=int, default=25_000_000)
    args = parser.parse_args()
    robot = panda(args.rm4d.resolve())
    arm = robot.arm()
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(5678), 11_100)
    heldout = pin_fk(robot, Q[~exact.colliding_arm(arm, Q)][:10_000])
    lo, hi = reach_bounds(arm.placements, arm.axes, arm.kinds, arm.T_last_tcp, arm.lower, arm.upper)
    rand = random_poses(lo, hi, 20_000, np.random.default_rng(8765))
    counts: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    built: dict[float, dict] = {}
    for res in RESOLUTIONS:
        settings = BuildSettings(
            samples=args.samples, voxel_size=VOXEL, orientation_resolution=res, self_collision=True
        )
        m = build_map(robot, settings=settings)
        top = float(m.counts.max())  # reachability = count / max count

        def count(T: np.ndarray, m=m, top=top) -> np.ndarray:
            return np.rint(m.reachability(T).astype(float) * top)

        counts[res] = (count(heldout), count(rand))
        built[str(res)] = {"cells_reached": m.n_reached, "build_time_s": m.info.build_time_s}
        print(f"{res} rad: {m.n_reached} cells, {m.info.build_time_s:.0f} s", flush=True)
    positive = np.zeros(len(rand), dtype=bool)
    for _, r in counts.values():
        positive |= r > 0
    todo = np.flatnonzero(positive)
    _, free = ik_oracle(robot, rand[todo])
    truth = np.zeros(len(rand), dtype=bool)
    truth[todo] = free
    rows: dict[str, list[dict]] = {}
    print("| orientation bins | min count | recall | precision against IK | called reachable |")
    print("|---|---|---|---|---|")
    for res, (h, r) in counts.items():
        rows[str(res)] = []
        for k in THRESHOLDS:
            called = r >= k
            row = {
                "min_count": k,
                "recall_heldout": float(np.mean(h >= k)),
                "precision_ik": float(truth[called].mean()) if called.any() else float("nan"),
                "n_called_reachable": int(called.sum()),
            }
            rows[str(res)].append(row)
            print(
                f"| {res} rad | {k} | {100 * row['recall_heldout']:.2f} % "
                f"| {100 * row['precision_ik']:.1f} % | {row['n_called_reachable']} |"
            )
    argv = [
        "RM4D_CHECKOUT" if prev == "--rm4d" else a
        for prev, a in zip(["", *sys.argv[:-1]], sys.argv, strict=True)
    ]
    report(
        "rm4d_count_threshold_dev",
        {"samples": args.samples, "maps": built, "rows": rows},
        used_seeds=[5678, 8765, 99],
        split="dev",
        argv=argv,
    )


if __name__ == "__main__":
    main()
