"""The IK solver of this checkout against another checkout's, paired in one process (development only).

This shared machine drifts between processes by as much as a solver change gains, so both solvers
run here on the same problems, taking turns. The other checkout's
``baseplace/robots/ik.py`` (``--other``: that checkout's root, e.g. a ``git worktree`` of the
commit to compare with) is loaded as a module of its own; its :class:`DampedLeastSquaresIK` solves
with this checkout's arm model (the compiled FK it imports is this checkout's).

Problems (TIAGo's arm, one fixed draw, seed 7), the three ways the product calls the solver:

* ``robustness``: batches of 64 TCP targets of one configuration seen from bases drawn around
  its own (3 cm, 2 deg, the robustness score's error model), solved from that configuration and
  4 random restarts (``solve_batch``, :class:`RobustnessSettings`' restarts), 40 batches;
* ``verification``: single FK targets of random configurations solved from mid-range and 80
  random restarts (``solve``, the verifier's), 400 targets, and 100 targets out of reach
  (every restart runs to its stall test);
* ``walk``: the approach walk's steps: a configuration's TCP walked back 1 cm at a time for 15 cm
  along its approach axis, each step from the last solution and 4 perturbations of it
  (``solve_from`` with the walk's limit-aware settings), 60 walks.

Per set the two solvers take turns ``--turns`` times (the first turn of each not counted: numba
compiles), the fastest of the rest kept. Reported: ms per set for each, the ratio, and whether
the two solved the same problems (solutions checked by pinocchio FK, 1e-4 m and 1e-3 rad).

Usage: python bench/paired_ik.py --other ../base [--turns 4] [--name paired_ik]
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

import baseplace.robots.ik as this_ik
from baseplace.geometry.poses import FloatArray
from baseplace.placement.motion import WALK_LIMIT_GAIN
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.model import Arm, Robot
from common import alternated, other_module, reaches, report
from find_rate import library_commit


def planar_offsets(rng: np.random.Generator, count: int) -> FloatArray:
    """(count, 4, 4) base errors: x, y ~ N(0, 3 cm), yaw ~ N(0, 2 deg)."""
    x, y = rng.normal(0.0, 0.03, (2, count))
    yaw = rng.normal(0.0, np.radians(2.0), count)
    T = np.tile(np.eye(4), (count, 1, 1))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = np.cos(yaw), -np.sin(yaw), np.sin(yaw), np.cos(yaw)
    T[:, 0, 3], T[:, 1, 3] = x, y
    return T


def problems(arm: Arm) -> dict[str, list[tuple[Any, ...]]]:
    """The three sets of the docstring, drawn once."""
    rng = np.random.default_rng(7)
    robust = []
    for q in arm.sample(rng, 40):
        T0 = forward_kinematics(arm, q)
        robust.append((np.linalg.inv(planar_offsets(rng, 64)) @ T0, q))
    verify = [(T, None) for T in forward_kinematics(arm, arm.sample(rng, 400))]
    far = np.tile(np.eye(4), (100, 1, 1))
    far[:, :3, 3] = rng.uniform([1.6, -1.5, 0.0], [2.5, 1.5, 2.0], (100, 3))
    verify += [(T, None) for T in far]
    walks = []
    jitter = np.random.default_rng(0).normal(0.0, 0.05, size=(4, arm.n_joints))
    for q in arm.sample(rng, 60):
        T0 = forward_kinematics(arm, q)
        steps = [T0.copy() for _ in range(16)]
        for k, T in enumerate(steps):
            T[:3, 3] -= 0.01 * k * T0[:3, 2]
        walks.append((q, steps, jitter))
    return {"robustness": robust, "verification": verify, "walk": walks}


Answer = tuple[FloatArray, FloatArray | None]
"""A target (4, 4) and the solution found for it (None: none)."""


def runner(module: ModuleType, arm: Arm, name: str) -> Callable[[list[tuple[Any, ...]]], list[Answer]]:
    """Solves one set with ``module``'s solver, as the product calls it."""
    ik = module.DampedLeastSquaresIK

    def robustness(items: list[tuple[Any, ...]]) -> list[Answer]:
        solver, rng, out = ik(arm, restarts=4), np.random.default_rng(1), []
        for T, q in items:
            Q, ok = solver.solve_batch(T, rng, q)
            out += [(T[i], Q[i] if ok[i] else None) for i in range(len(T))]
        return out

    def verification(items: list[tuple[Any, ...]]) -> list[Answer]:
        solver, rng = ik(arm), np.random.default_rng(2)
        return [(T, solver.solve(T, rng)) for T, _ in items]

    def walk(items: list[tuple[Any, ...]]) -> list[Answer]:
        solver, out = ik(arm, saturate_limits=True, limit_gain=WALK_LIMIT_GAIN), []
        for q0, steps, jitter in items:
            q = q0
            for T in steps[1:]:  # as the walk: each step from the last solution, until one fails
                seeds = np.clip(np.vstack([q, q + jitter]), arm.lower, arm.upper)
                found = solver.solve_from(T, seeds)
                out.append((T, found))
                if found is None:
                    break
                q = found
        return out

    return {"robustness": robustness, "verification": verification, "walk": walk}[name]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--other", type=Path, required=True, help="the other checkout's root")
    parser.add_argument("--turns", type=int, default=4, help="turns per solver and set (>= 2)")
    parser.add_argument("--name", default="paired_ik", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    if args.turns < 2:
        parser.error("--turns must be >= 2 (the first turn is not counted)")
    modules = {"this": this_ik, "other": other_module(args.other, "robots/ik.py", "other_ik")}
    robot = Robot("tiago")
    arm = robot.arm()
    sets = problems(arm)
    summary: dict[str, Any] = {}
    for name, items in sets.items():
        best, answers = alternated(
            args.turns,
            lambda who, name=name, items=items: functools.partial(runner(modules[who], arm, name), items),
        )
        a, b = answers["this"], answers["other"]
        solved = {who: sum(q is not None for _, q in answers[who]) for who in answers}
        same = sum((x is None) == (y is None) for (_, x), (_, y) in zip(a, b, strict=False))
        summary[name] = {
            "ms": {k: round(v, 2) for k, v in best.items()},
            "ratio": round(best["this"] / best["other"], 3),
            "solved": solved,
            "answers": {"this": len(a), "other": len(b), "same_verdict_in_order": same},
            "fk_checked": {who: fk_checked(robot, arm, answers[who]) for who in answers},
        }
        print(name, summary[name], flush=True)
    other = library_commit(args.other / "src" / "baseplace")
    report(args.name, {"turns": args.turns, "other": other, "library": library_commit(), "summary": summary})


def fk_checked(robot: Robot, arm: Arm, answers: list[Answer]) -> int:
    """How many solutions pinocchio's FK puts within the solver's tolerances of their targets."""
    data = robot.model.createData()
    return sum(reaches(robot, arm, q, T, data) for T, q in answers if q is not None)


if __name__ == "__main__":
    main()
