"""IK success and time per solve on 1,000 reachable targets (FK of random configurations).

Success is checked with pinocchio FK (the oracle), not with the solver's own kernel.
Usage: python bench/bench_ik.py [--robot tiago] [--arm ARM] [--n 1000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pinocchio as pin

from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from common import report


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
    model, data = robot.model, robot.model.createData()
    base, tcp = model.getFrameId(arm.base_frame), model.getFrameId(arm.tcp_frame)
    times, ok = [], 0
    for T in targets:
        start = time.perf_counter()
        q = ik.solve(T, rng)
        times.append(time.perf_counter() - start)
        if q is None:
            continue
        pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
        reached = (data.oMf[base].inverse() * data.oMf[tcp]).homogeneous
        rot = np.arccos(np.clip((np.trace(reached[:3, :3].T @ T[:3, :3]) - 1) / 2, -1, 1))
        ok += bool(np.linalg.norm(reached[:3, 3] - T[:3, 3]) < 1e-4 + 1e-9 and rot < 1e-3 + 1e-9)
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
