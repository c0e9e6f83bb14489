"""IK success and time per solve on 1,000 reachable targets (FK of random configurations).

Success is checked with pinocchio FK (the oracle), not with the solver's own kernel.
Usage: python bench/bench_ik.py [--robot tiago] [--arm ARM] [--n 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from common import reaches, report


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--robot", default="tiago")
    parser.add_argument("--arm", default=None)
    parser.add_argument("--n", type=int, default=1000)
    args = parser.parse_args()
    robot = Robot(args.robot)
    arm = robot.arm(args.arm)
    rng = np.random.default_rng(7)
    targets = forward_kinematics(arm, arm.sample(rng, args.n))
    ik = DampedLeastSquaresIK(arm)
    ik.solve(targets[0], rng)  # compile
    data = robot.model.createData()
    times, ok = [], 0
    for T in targets:
        start = time.perf_counter()
        q = ik.solve(T, rng)
        times.append(time.perf_counter() - start)
        ok += q is not None and reaches(robot, arm, q, T, data)
    ms = np.array(times) * 1e3
    report(
        f"ik_{args.robot}_{arm.name}",
        {
            "targets": args.n,
            "success_rate": ok / args.n,
            "median_ms": round(float(np.median(ms)), 3),
            "p90_ms": round(float(np.percentile(ms, 90)), 3),
            "max_ms": round(float(ms.max()), 3),
            "tolerances": "1e-4 m, 1e-3 rad",
            "target": ">= 99.5% success, median <= 3 ms",
        },
    )


if __name__ == "__main__":
    main()
