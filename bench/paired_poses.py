"""The robustness score's batched collision check, one compiled call for all draws against one a draw, paired (development only).

``StateFilter.colliding_poses`` checks each error draw's arm state at the draw's own base pose.
Since session 35 it hands all draws to one compiled call (``_uncertified_poses``) up to the next
state with pairs left; before, it called the state kernel once a draw (:func:`per_draw`, that
loop as it was, kept here as the baseline). Both run in this process on the same inputs, in turns
(the first turn of each not counted, the fastest of the others kept).

Inputs: the table scenes of ``tests/test_state_filter.py`` (table-grid dev seeds 0 and 1, both
collision models); per scene and model, ``--batches`` batches of 64 draws around a collision-free
state of that test's states (arm joints moved by 0.005 rad, the base by 3 cm and 2 deg, the
robustness score's default error). Reported: the medians, the per-batch ratio's median and
quartiles, and how many batches got the same verdicts from both.

Usage: python bench/paired_poses.py [--batches 20] [--turns 3] [--name paired_poses]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.placement.robustness import perturbed
from baseplace.robots.model import Robot
from baseplace.world.state_filter import _uncertified_states
from common import alternated, ratio_summary, report
from find_rate import library_commit

sys.path.insert(0, str(Path(__file__).parent.parent / "tests"))
from test_state_filter import scene_models


def per_draw(flt: Any, Q: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``colliding_poses`` as it was before session 35: the state kernel called once a draw."""
    hit = np.zeros(len(T), dtype=bool)
    T_armbase = np.ascontiguousarray(T @ flt._T_base_armbase)
    static = flt._static_uncertified(T_armbase)
    P = len(flt._scene_rows)
    out = np.empty((1, P + len(flt._self_pairs)), dtype=np.bool_)
    robot, scene_and_self = flt._kernel_args
    for s in range(len(T)):
        q_full = flt._full(Q[s]) if static[s] else None
        if q_full is not None and flt._scene_coal(static[s], q_full, T[s]):
            hit[s] = True
            continue
        if _uncertified_states(Q[s : s + 1], *robot, T_armbase[s], *scene_and_self, 0, out) < 0:
            continue
        if flt._touch_proven(Q[s], out[0, :P], T_armbase[s]):
            hit[s] = True
            continue
        q_full = flt._full(Q[s]) if q_full is None else q_full
        scene = flt._scene_row_pair[np.flatnonzero(out[0, :P])]
        if len(scene) and flt._scene_coal(scene.tolist(), q_full, T[s]):
            hit[s] = True
            continue
        own = flt._self_index[np.flatnonzero(out[0, P:])]
        hit[s] = bool(len(own)) and flt._self_coal(own, q_full)
    return hit


def _turns(flt: Any, Q: np.ndarray, T: np.ndarray) -> Callable[[str], Callable[[], Any]]:
    """Per side ("batched", "per_draw"), the work of one turn on the draws (Q, T)."""
    return lambda side: (
        (lambda: flt.colliding_poses(Q, T)) if side == "batched" else (lambda: per_draw(flt, Q, T))
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batches", type=int, default=20, help="batches of 64 draws per scene and model")
    parser.add_argument("--turns", type=int, default=3, help="turns per side and batch (>= 2)")
    parser.add_argument("--name", default="paired_poses", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    if args.turns < 2 or args.batches < 1:
        parser.error("--turns must be >= 2 (the first turn is not counted) and --batches >= 1")
    tiago = Robot("tiago")
    arm = tiago.arm()
    rng = np.random.default_rng(3)
    ms: dict[str, list[float]] = {"batched": [], "per_draw": []}
    same = 0
    for env, T_base, states in scene_models(tiago, rng):
        flt = env.state_filter(arm)
        for _ in range(args.batches):
            q = states[rng.integers(len(states))]
            while env.colliding_arm(arm, q, T_base):
                q = states[rng.integers(len(states))]
            Q = np.clip(q + rng.normal(0.0, 0.005, (64, arm.n_joints)), arm.lower, arm.upper)
            T = perturbed(T_base, rng.normal(0.0, 1.0, (64, 3)) * (0.03, 0.03, np.radians(2.0)))
            best, answer = alternated(args.turns, _turns(flt, Q, T), ("batched", "per_draw"))
            for side in ms:
                ms[side].append(best[side])
            same += bool(np.array_equal(answer["batched"], answer["per_draw"]))
    summary = {"batches": len(ms["batched"]), "same_verdicts": same, **ratio_summary(ms)}
    print(summary)
    report(args.name, {"turns": args.turns, "library": library_commit(), "summary": summary, "ms": ms})


if __name__ == "__main__":
    main()
