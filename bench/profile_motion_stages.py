"""Where the reaching-motion check spends its time, by stage (issue 25 item 3; development only).

Replays the checks of a ``bench_motion_verdicts.py`` results file (its inputs: seed, cell, grasp,
base pose, target, grasp configuration; development seeds only, as that bench runs them) with the
product's ``MotionSettings()`` and the same OMPL seed, rebuilding each scene's two collision models
as that bench does (``scene_checks``), without the ``place`` calls that found the inputs. Each
check's wall time is split by wrapping the checker's and the state filter's methods with
``perf_counter`` timers (nested stages are counted in each: the table is inclusive):

* ``approach``: the whole approach walk, of which ``walk_ik`` (the walk's IK steps,
  ``DampedLeastSquaresIK.solve_from``), ``approach_edges`` (the joint lines between walk steps in the
  approach model) and ``walk_stop`` (the transit-model test that ends a walk back early);
* ``transit_ends`` (the start and pre-grasp states); the transit's joint lines by what asked for
  them (:data:`LINE_CALLERS`): ``straight_line`` (tried first), ``rrt_edges`` (RRTConnect's, at
  ``search_step``), ``shortcut_lines`` and ``path_recheck`` (the returned path at ``point_step``);
* ``rrt`` (OMPL RRTConnect, with its shortcut), of which ``shortcut``;
* across all stages: ``kernel`` (the compiled sphere pre-filter on given states,
  ``_uncertified_states``), ``kernel_line`` (on a joint line's states, ``_uncertified_line``),
  ``coal_scene`` / ``coal_self`` (the exact fallbacks, with their calls).

Also verdicts: the number found, and each check whose verdict differs from the file's ``product``.
``--cprofile N``: cProfile the first N checks instead and print the top functions.
``--kernel-split``: also record the state batches the timed checks hand to
``StateFilter.first_colliding`` (single states and the like: a joint line goes to
``StateFilter.first_colliding_line`` since session 22 and is not recorded) (up to the first state that touches, as the check took them) and
time the compiled pre-filter on every state of them (going on after each state it leaves to coal,
without coal) with the scene parts, the self pairs, both or
neither: the pre-filter's cost per state and its split (development only; no verdict is taken
from it).

Usage: python bench/profile_motion_stages.py [--results motion_verdicts_s12_final_a] [--repeat 1]
"""

from __future__ import annotations

import argparse
import cProfile
import functools
import json
import pstats
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

import baseplace.world.state_filter as state_filter
from baseplace.geometry.poses import FloatArray
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.reachability.cache import resolve_map
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from bench_motion_verdicts import PROTOCOLS, check_seed, row_models
from common import alternated, ratio_summary
from find_rate import library_commit

RESULTS = Path(__file__).parent / "results"


class Timers:
    """Inclusive wall time and calls per stage name."""

    def __init__(self) -> None:
        self.s: defaultdict[str, float] = defaultdict(float)
        self.n: defaultdict[str, int] = defaultdict(int)
        self.active = False
        """Count only while set (the timed repeat of a check)."""

    def wrap(self, owner: Any, name: str, key: str) -> None:
        inner = getattr(owner, name)

        def timed(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                if self.active:
                    self.s[key] += time.perf_counter() - t
                    self.n[key] += 1

        setattr(owner, name, timed)


LINE_CALLERS = {
    "checkMotion": "rrt_edges",
    "_shortcut": "shortcut_lines",
    "<genexpr>": "path_recheck",
    "joint_path": "straight_line",
}
"""A transit line's stage by the function that called ``MotionChecker._line_free``: RRTConnect's
edges (checked at ``search_step``), the shortcut's lines, the re-check of the path RRTConnect
returned at ``point_step`` (:meth:`MotionChecker._plan`) and the straight line tried first."""


def instrument(timers: Timers) -> Callable[[MotionChecker], None]:
    """Wrap the module-level stages once; returns the per-checker wrapping."""
    timers.wrap(state_filter, "_uncertified_states", "kernel")
    timers.wrap(state_filter, "_uncertified_line", "kernel_line")
    timers.wrap(state_filter.StateFilter, "_scene_coal", "coal_scene")
    timers.wrap(state_filter.StateFilter, "_self_coal", "coal_self")
    timers.wrap(DampedLeastSquaresIK, "solve_from", "walk_ik")

    def per_checker(checker: MotionChecker) -> None:
        timers.wrap(checker, "approach", "approach")
        timers.wrap(checker, "_clear_of_object", "walk_stop")
        timers.wrap(checker, "_rrt", "rrt")
        timers.wrap(checker, "_shortcut", "shortcut")
        timers.wrap(checker, "_free", "transit_ends")
        inner_blocking = checker._blocking

        def blocking(a: Any, b: Any, T: Any, environment: Any) -> Any:
            key = "approach_edges"
            if environment is checker.environment:  # by what asked for the transit's line
                key = LINE_CALLERS.get(sys._getframe(2).f_code.co_name, "transit_line")
            t = time.perf_counter()
            try:
                return inner_blocking(a, b, T, environment)
            finally:
                timers.s[key] += time.perf_counter() - t
                timers.n[key] += 1

        checker._blocking = blocking  # type: ignore[method-assign]

    return per_checker


def record_batches(timers: Timers) -> list[tuple[Any, FloatArray, FloatArray]]:
    """Per call of ``StateFilter.first_colliding`` while ``timers.active``: the filter, the states it checked, the base pose."""
    batches: list[tuple[Any, FloatArray, FloatArray]] = []
    inner = state_filter.StateFilter.first_colliding

    def recorded(self: Any, Q: Any, T: Any) -> int:
        i = inner(self, Q, T)
        if timers.active:  # the states checked: up to the first that touches
            Q = np.array(Q, dtype=float, ndmin=2)
            batches.append((self, Q if i < 0 else Q[: i + 1], np.array(T, dtype=float)))
        return i

    state_filter.StateFilter.first_colliding = recorded  # type: ignore[method-assign]
    return batches


SPLIT = {"full": (), "scene only": ("self",), "self only": ("scene",), "neither": ("scene", "self")}
"""The pre-filter's variants: which of its two halves is left out (no scene parts, no self runs)."""


def print_kernel_split(batches: list[tuple[Any, FloatArray, FloatArray]], checks: int) -> None:
    """The pre-filter's time per state over every recorded state, per variant of :data:`SPLIT` (twice, alternated)."""
    states = sum(len(Q) for _, Q, _ in batches)
    times: defaultdict[str, list[float]] = defaultdict(list)
    for _ in range(2):
        for name, off in SPLIT.items():
            t = 0.0
            for f, Q, T in batches:
                robot, after = f._kernel_args
                after = list(after)
                if "scene" in off:  # no scene parts (``parts``, the third argument after the base pose)
                    after[2] = after[2][:0]
                if "self" in off:  # no self runs
                    after[15] = after[15][:0]
                out = np.empty((len(Q), len(f._scene_rows) + len(f._self_pairs)), dtype=np.bool_)
                T_arm = T @ f._T_base_armbase
                i, t0 = -1, time.perf_counter()
                while i < len(Q) - 1:
                    i = state_filter._uncertified_states(Q, *robot, T_arm, *after, i + 1, out)
                    if i < 0:
                        break
                t += time.perf_counter() - t0
            times[name].append(t / states * 1e6)
    print(f"pre-filter on every recorded state: {states} states, {states / checks:.0f} per check")
    for name, ts in times.items():
        print(f"  {name:12s} us/state {min(ts):6.2f} (runs {', '.join(f'{x:.2f}' for x in ts)})")


def held_out_seeds() -> set[int]:
    """The table-grid seeds no development bench may replay: the execution protocol's and every motion protocol's."""
    return {*range(3, 38), *(seed for _, seeds in PROTOCOLS.values() for seed in seeds)}


def development_checks(parser: argparse.ArgumentParser, results: str) -> list[dict[str, Any]]:
    """The checks of results file ``results`` (``bench_motion_verdicts.py``'s); refused (exit 2) if it holds held-out seeds."""
    rows: list[dict[str, Any]] = json.loads((RESULTS / f"{results}.json").read_text())["checks"]
    held = held_out_seeds() & {row["seed"] for row in rows}
    if held:
        parser.error(f"{results} holds held-out seeds {sorted(held)}")
    return rows


def paired_arguments(doc: str, turns: int, name: str) -> tuple[argparse.Namespace, list[dict[str, Any]]]:
    """The paired benches' arguments (``--other``, ``--results``, ``--turns``, ``--name``) and the checks of ``--results``.

    Refused (exit 2) with fewer than 2 turns or a results file that holds held-out seeds.
    """
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--other", type=Path, required=True, help="the other checkout's root")
    parser.add_argument("--results", default="motion_verdicts_s17_final_a", help="bench/results/NAME.json")
    parser.add_argument("--turns", type=int, default=turns, help="turns per checkout and check (>= 2)")
    parser.add_argument("--name", default=name, help="results file bench/results/NAME.json")
    args = parser.parse_args()
    if args.turns < 2:
        parser.error("--turns must be >= 2 (the first turn is not counted)")
    return args, development_checks(parser, args.results)


def paired_checks(args: argparse.Namespace, rows: list[dict[str, Any]], side: Callable[[str], tuple[Any, Any]]
                  ) -> dict[str, Any]:  # fmt: skip
    """The paired benches' run: per check of ``rows``, the two sides take ``args.turns`` turns each.

    ``side(name)`` readies side ``name`` ("this" or "other") for a turn and returns its motion
    checker and settings classes; the first turn of each side is not counted (caches), the
    fastest of the others is kept. Returns what the bench reports: the summary (medians, means,
    the per-check ratio's median and quartiles, motions found in the last turn, checks with the
    same answer: no motion in both, or the same path and approach to 1e-9 rad), the times and
    both checkouts' commits.
    """
    robot = Robot("tiago")
    arm = robot.arm(resolve_map(robot, None).rmap.info.arm)
    models: dict[tuple[Any, ...], Any] = {}
    best: dict[str, list[float]] = {"this": [], "other": []}
    found = {"this": 0, "other": 0}
    agree = 0
    for row in rows:
        key = (row["seed"], tuple(row["cell"]), row["grasp"])
        if key not in models:
            models[key] = row_models(robot, arm.name, row)[:2]
        seed = check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        q, T_base, target = (np.array(row[k]) for k in ("q_grasp", "T_world_base", "target"))
        turn = functools.partial(_check_turn, side, robot, arm, models[key], q, T_base, target, seed)
        fastest, answer = alternated(args.turns, turn)
        for name in best:
            best[name].append(fastest[name])
            found[name] += answer[name] is not None
        agree += _same_answer(answer["this"], answer["other"])
    side("this")
    summary = {"checks": len(rows), "found": found, "same_answer": agree, **ratio_summary(best)}
    print(summary)
    other = library_commit(args.other / "src" / "baseplace")
    return {"inputs": args.results, "turns": args.turns, "other": other, "library": library_commit(),
            "summary": summary, "ms": best}  # fmt: skip


def _check_turn(side: Callable[[str], tuple[Any, Any]], robot: Robot, arm: Any, models: Any, q: FloatArray,
                T_base: FloatArray, target: FloatArray, seed: int, name: str) -> Callable[[], Any]:  # fmt: skip
    """Side ``name`` readied (``side``) and its motion checker built on ``models``: one turn's check, to time."""
    checker_class, settings_class = side(name)
    checker = checker_class(robot, arm, *models, settings_class())
    return lambda: checker.check(q, T_base, target, seed=seed)


def _same_answer(a: Any, b: Any) -> bool:
    """Whether two motion checks' answers agree: both none, or the same path and approach."""
    if a is None or b is None:
        return a is None and b is None
    return bool(
        a.path.shape == b.path.shape
        and a.approach.shape == b.approach.shape
        and np.allclose(a.path, b.path, rtol=0.0, atol=1e-9)
        and np.allclose(a.approach, b.approach, rtol=0.0, atol=1e-9)
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", default="motion_verdicts_s12_final_a", help="bench/results/NAME.json")
    parser.add_argument("--repeat", type=int, default=1, help="check each input this often (times: the last)")
    parser.add_argument("--cprofile", type=int, default=0, help="cProfile the first N checks instead")
    parser.add_argument("--uninstrumented", action="store_true", help="no stage timers (wall times only)")
    parser.add_argument(
        "--kernel-split", action="store_true", help="time the pre-filter per state, split (docstring)"
    )
    args = parser.parse_args()
    rows = development_checks(parser, args.results)
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    arm = robot.arm(rmap.info.arm)
    timers = Timers()
    per_checker = None if args.uninstrumented or args.cprofile else instrument(timers)
    batches = record_batches(timers) if args.kernel_split else None
    models: dict[tuple[Any, ...], Any] = {}
    walls, cpus, found, changed = [], [], 0, []
    profile = cProfile.Profile() if args.cprofile else None
    todo = rows[: args.cprofile] if args.cprofile else rows
    for row in todo:
        key = (row["seed"], tuple(row["cell"]), row["grasp"])
        target = np.array(row["target"])
        if key not in models:
            models[key] = row_models(robot, arm.name, row)[:2]
        seed = check_seed(row["seed"], tuple(row["cell"]), row["grasp"], row["placement"])
        q, T_base = np.array(row["q_grasp"]), np.array(row["T_world_base"])
        for r in range(args.repeat):
            checker = MotionChecker(robot, arm, *models[key], MotionSettings())
            timers.active = r == args.repeat - 1
            if per_checker is not None and timers.active:
                per_checker(checker)
            if profile is not None and r == args.repeat - 1:
                profile.enable()
            t, c = time.perf_counter(), time.process_time()
            motion = checker.check(q, T_base, target, seed=seed)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            if profile is not None and r == args.repeat - 1:
                profile.disable()
        walls.append(wall * 1e3)
        cpus.append(cpu * 1e3)
        found += motion is not None
        if "product" in row and row["product"]["found"] != (motion is not None):
            changed.append((key, row["placement"], row["product"]["found"], motion is not None))
    w = np.array(walls)
    print(f"{len(w)} checks, found {found}; ms median {np.median(w):.2f} p90 {np.quantile(w, 0.9):.2f} "
          f"mean {w.mean():.2f}; cpu ms median {np.median(cpus):.2f} mean {np.mean(cpus):.2f}; verdicts changed against the file: {changed}")  # fmt: skip
    if batches is not None:
        print_kernel_split(batches, len(w))
    if timers.s:
        total = w.sum() / 1e3
        print(f"{'stage':16s} {'ms/check':>9s} {'share':>6s} {'calls/check':>11s} {'us/call':>8s}")
        for k, v in sorted(timers.s.items(), key=lambda kv: -kv[1]):
            n = timers.n[k]
            print(f"{k:16s} {v / len(w) * 1e3:9.2f} {v / total:6.1%} {n / len(w):11.1f} {v / n * 1e6:8.1f}")
    if profile is not None:
        pstats.Stats(profile).sort_stats("tottime").print_stats(25)


if __name__ == "__main__":
    main()
