"""Issue 25 item 3 baseline: the reaching-motion check's verdicts against a 100x-budget planner.

A development measurement (not a held-out result), so that a faster edge check has a baseline:
how often does the landed check (:class:`~baseplace.placement.motion.MotionChecker`: a straight
joint line first, else OMPL RRTConnect with a Python state-validity callback over coal; the
approach walked by IK) say "no motion" where the same checker with 100 times the budget finds one,
and what does one check cost?

* Scenes: seed 004's table grid as ``baseplace_experiments.execution_experiment.execution_trial``
  draws it (trial k = 0 of a cell: the true bottle, its estimate, the cloud of table and bottle
  with 3 mm noise), plus a floor at z = 0 (``with_floor``), as ``baseplace place --floor 0`` sees
  it. Development seeds :data:`SEEDS` (dev data in every experiment here; none of the held-out
  seeds of docs/protocols/execution_table_grid.md, 11-13, nor those of earlier runs, 3-10).
  ``--split held-out`` runs a protocol of :data:`PROTOCOLS` (``--protocol``, default the newest,
  v2: docs/protocols/motion_verdicts_v2.md) on its held-out seeds, the product against the
  reference only.
* Grasps: :data:`GRASPS` of the 32 grasps ``TableGridSettings.grasps`` makes at the *estimate*
  (16 side, 16 top-down 2 cm under the top), one target per query.
* Inputs: the product's own: ``place`` with the pose-only checks (footprint, IK, collision; no
  motion, no robustness score), the object ``auto``, default settings otherwise, gives up to
  :data:`PER_GRASP` verified base poses and their grasp configurations; ``scene_checks`` on the
  same scene cache gives the two collision models the product's motion check uses (transit:
  nothing touched; approach: only the hand on the grasped object).
* Per (scene, grasp, base pose): ``MotionChecker.check`` with the product's ``MotionSettings()``
  (1 s wall limit), with the experiments' ``max_checks=500`` (30 s wall cap), and the reference:
  the same checker, ``max_checks=50_000``, ``time_limit=100``, ``approach_restarts=40``. One OMPL
  seed per check (:func:`check_seed`), the same for the three. Every motion found is re-checked
  state by state (every joint line at ``joint_resolution / 4``; transit in the transit model,
  approach in the approach model), and on the true table and bottle by the execution oracle
  (``ExecutionOracle.path_free``, coal, same step; the hand may touch the bottle in the approach
  only). False "no motion": the product says None, the reference finds a motion that passes the
  re-check in its own models; its rate is given over all checks and over those where such a
  motion exists. The results file keeps each check's inputs (base pose, target, grasp
  configuration) and every motion's waypoints, for a later checker to run on the same inputs. A refusal's reason: ``approach_ik`` (no IK walk along the approach line,
  restarts included), ``approach_collision``, ``pregrasp_collision`` / ``transit_start_collision``
  (an end of the transit collides in the transit model, where nothing may be touched),
  ``no_rrt_path`` (RRTConnect ran out of its budget).
* Timing: wall time of ``check``; the transit states checked (``MotionChecker.state_checks``, the
  ``max_checks`` budget), calls of ``Environment.colliding_arm`` (one state) and
  ``Environment.first_colliding_arm`` (a whole joint line, one compiled call) and the time in them;
  before the whole-line check, the time inside ``colliding_arm``'s two parts, the obstacle check (``Environment._touches_obstacles``) and
  self-collision (``SelfCollision.colliding_arm``). One process, no pools.

* Checkers (``--checkers``, default the three above): also ``product_500_exact``, the 500-check
  product with every state checked by coal on every pair
  (:meth:`~baseplace.world.environment.Environment.colliding_arm_exact`, the check before the
  pre-filter of :mod:`baseplace.world.state_filter`), for a before/after on the same placements in one
  process; and ``product_500_point``, the 500-check product with ``point_step=0.01`` (the Cartesian
  edge bound, off by default). Without the reference, false "no motion" is not counted (None).

Usage: python bench/bench_motion_verdicts.py [--seeds 0 1] [--cells 4] [--per-grasp 2]
       [--checkers product_500 product_500_exact]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
import os
import time
from collections import Counter, defaultdict
from collections.abc import Callable
from typing import Any

import numpy as np

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.placement.motion import MotionChecker, MotionSettings
from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings, place, scene_checks, with_floor
from baseplace.placement.robustness import wilson_interval
from baseplace.placement.scene_cache import SceneCache
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace.world.environment import Environment
from baseplace_experiments.execution import ExecutionOracle, ExecutionSettings
from baseplace_experiments.execution_experiment import trial_scene
from baseplace_experiments.results import fixed_protocol
from baseplace_experiments.table_grid import (
    RobotShapes,
    TableGridSettings,
    true_bottle,
    true_table,
)
from common import report

SEEDS = (0, 1, 2)
"""Development seeds of the table grid (see the module docstring)."""
PROTOCOLS: dict[int, tuple[str, tuple[int, ...]]] = {
    1: ("docs/protocols/motion_verdicts_v1.md", tuple(range(40, 50))),
    2: ("docs/protocols/motion_verdicts_v2.md", tuple(range(50, 70))),
}
"""Per protocol version: its file and its held-out seeds, each set run once (v1's are spent)."""
PROTOCOL = max(PROTOCOLS)
"""The protocol ``--split held-out`` runs unless ``--protocol`` names another."""
CELLS = ((0, 0), (1, 0), (2, 0), (1, 1))
GRASPS = (0, 2, 4, 6, 8, 20)
"""Indices into ``TableGridSettings.grasps``: side grasps approaching along yaw 0, 45, 90, 135 and
180 deg (the table's short edge lies at -y, so these come from its sides and that edge) and a
top-down one rotated 90 deg."""
SIDE_LIFT = 0.04
"""Side grasps hold the bottle this far above its centre [m]: at the centre (10 cm above the table
top) every side grasp of every scene tried was refused by the pose check, a finger or the hand's
safety box touching the support's model (issue 25 item 1), so none reached the motion check."""
PER_GRASP = 1
TRIES = 60
PRODUCT = MotionSettings()
PRODUCT_500 = MotionSettings(time_limit=30.0, max_checks=500)
REFERENCE = MotionSettings(time_limit=100.0, max_checks=50_000, approach_restarts=40, search_step=None)
"""100x the product's budget; it searches with its edges at the 1 cm point bound (``search_step``
None), as every reference run did before the coarser search existed."""
CHECKERS: dict[str, tuple[MotionSettings, bool]] = {
    "product": (PRODUCT, False),
    "product_500": (PRODUCT_500, False),
    "reference": (REFERENCE, False),
    "product_500_exact": (PRODUCT_500, True),
    "product_500_point": (dataclasses.replace(PRODUCT_500, point_step=0.01), False),
    "product_point": (dataclasses.replace(PRODUCT, point_step=0.01), False),
}
"""Per checker name: its settings, and whether every state goes to coal on every pair (the old check)."""
RECHECK = 4
"""The reference path is re-checked at ``joint_resolution / RECHECK``."""
APPROACH_VARIANTS: dict[str, MotionSettings] = {
    "product": PRODUCT,
    **{f"restarts{k}": MotionSettings(approach_restarts=k) for k in (8, 12, 16, 40)},
    "reference": REFERENCE,
}
"""The product's checker with more approach restarts, and the reference: what the approach benches
(approach_refusals_dev.py, approach_restarts_dev.py) run a refused check again with."""


@dataclasses.dataclass
class Meter:
    """Counts and times the state checks of the collision models while active."""

    calls: Counter[str] = dataclasses.field(default_factory=Counter)
    seconds: defaultdict[str, float] = dataclasses.field(default_factory=lambda: defaultdict(float))

    def wrap(self, owner: object, name: str, key: str) -> None:
        """Replace ``owner.name`` (a bound method) by a counted, timed one (once per owner and name)."""
        inner = getattr(owner, name)
        if getattr(inner, "_metered", False):
            return

        def metered(*args: Any, **kwargs: Any) -> Any:
            t = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.calls[key] += 1
                self.seconds[key] += time.perf_counter() - t

        metered._metered = True  # type: ignore[attr-defined]
        setattr(owner, name, metered)

    def reset(self) -> None:
        self.calls.clear()
        self.seconds.clear()

    def snapshot(self) -> dict[str, Any]:
        return {"calls": dict(self.calls), "ms": {k: round(v * 1e3, 2) for k, v in self.seconds.items()}}


class ExactStates:
    """An environment whose ``colliding_arm`` is its ``colliding_arm_exact`` (coal on every pair)."""

    def __init__(self, env: Environment) -> None:
        self._env = env
        self.colliding_arm = env.colliding_arm_exact

    def first_colliding_arm(self, arm: Any, Q: FloatArray, T_world_base: FloatArray) -> int:
        """The whole-line check, state by state with coal on every pair."""
        return next((i for i, q in enumerate(Q) if self._env.colliding_arm_exact(arm, q, T_world_base)), -1)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)


def meter_environment(meter: Meter, env: Environment | ExactStates, stage: str) -> None:
    """Count ``env.colliding_arm`` as ``stage`` checks and its whole-line checks as ``stage`` edges; time them."""
    meter.wrap(env, "colliding_arm", f"states_{stage}")
    meter.wrap(env, "first_colliding_arm", f"edges_{stage}")
    meter.wrap(env, "_touches_obstacles", "obstacles")
    if env._self is not None:
        meter.wrap(env._self, "colliding_arm", "self_collision")


def scene(
    seed: int, cell: tuple[int, int], s: TableGridSettings
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(true bottle centre, its estimate, the noisy cloud), drawn as ``execution_trial`` draws them."""
    return trial_scene(seed, cell, s)


def check_seed(seed: int, cell: tuple[int, int], grasp: int, k: int) -> int:
    """OMPL's seed for one check, the same for the product and the reference."""
    return int(np.random.default_rng([seed, *cell, grasp, k]).integers(2**31 - 1))


def row_models(
    robot: Robot, arm_name: str, row: dict[str, Any]
) -> tuple[Environment, Environment | None, FloatArray]:
    """The product's two motion models (transit, approach) for a results row's scene and target, as
    this bench builds them, and the true bottle's position (3,) (for the execution oracle)."""
    p_true, _, seen = trial_scene(row["seed"], tuple(row["cell"]), TableGridSettings())
    points = with_floor(seen, 0.0)
    cache = SceneCache(points)
    checks = scene_checks(robot, arm_name, points, cache.terrain(None), np.array(row["target"])[None],
                          PlaceSettings(), "auto", cache)  # fmt: skip
    product = checks.verifier.motion
    assert product is not None
    return product.environment, product.approach_environment, p_true


class Recorder:
    """What one ``MotionChecker.check`` did: its approach, whether RRT ran and what it returned, and their times."""

    def __init__(self, checker: MotionChecker) -> None:
        self.approach: FloatArray | None = None
        self.rrt_called = False
        self.rrt_found = False
        self.approach_s = 0.0
        self.rrt_s = 0.0
        approach, rrt = checker.approach, checker._rrt

        def recorded_approach(*args: Any, **kwargs: Any) -> FloatArray | None:
            t = time.perf_counter()
            self.approach = approach(*args, **kwargs)
            self.approach_s += time.perf_counter() - t
            return self.approach

        def recorded_rrt(*args: Any, **kwargs: Any) -> FloatArray | None:
            self.rrt_called = True
            t = time.perf_counter()
            path = rrt(*args, **kwargs)
            self.rrt_s += time.perf_counter() - t
            self.rrt_found = path is not None
            return path

        checker.approach = recorded_approach
        checker._rrt = recorded_rrt


def run_check(
    checker: MotionChecker, meter: Meter, q: FloatArray, T_base: FloatArray, target: FloatArray, seed: int
) -> tuple[dict[str, Any], Any]:
    rec = Recorder(checker)
    meter.reset()
    t = time.perf_counter()
    motion = checker.check(q, T_base, target, seed=seed)
    wall = time.perf_counter() - t
    out: dict[str, Any] = {"found": motion is not None, "wall_ms": round(wall * 1e3, 2),
                           "state_checks": checker.state_checks,
                           "approach_ms": round(rec.approach_s * 1e3, 2), "rrt_ms": round(rec.rrt_s * 1e3, 2),
                           **meter.snapshot()}  # fmt: skip
    if motion is None:
        out["reason"] = checker.last_failure  # the library's reason (MOTION_FAILURES)
        out["contacts"] = [list(c) for c in checker.last_contacts[:3]]
    else:
        out["planned"] = motion.planned
        out["path_waypoints"] = len(motion.path)
    if rec.rrt_called:
        out["rrt"] = "found" if rec.rrt_found else "none"
    return out, motion


def recheck(
    checker: MotionChecker, path: FloatArray, approach: FloatArray, T_base: FloatArray
) -> dict[str, Any]:
    """Every state of a motion, joint lines cut at ``joint_resolution / RECHECK``, in its model.

    Returns the states checked, how many collide, in which part, and what the colliding ones touch.
    """
    step = checker.settings.joint_resolution / RECHECK
    approach_env = checker.approach_environment or checker.environment
    states, colliding, touched = 0, [], Counter[str]()
    for part, env, waypoints in (
        ("transit", checker.environment, path),
        ("approach", approach_env, approach),
    ):
        for a, b in itertools.pairwise(waypoints):
            n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
            for k in range(n + 1):
                states += 1
                q = a + (b - a) * (k / n)
                if env.colliding_arm(checker.arm, q, T_base):
                    colliding.append(part)
                    touched.update(
                        f"{link} / {what}" for link, what in env.contacts_arm(checker.arm, q, T_base)
                    )
    return {
        "states": states,
        "colliding": len(colliding),
        "parts": sorted(set(colliding)),
        "touched": dict(touched),
    }


def true_scene(
    oracle: ExecutionOracle, path: FloatArray, approach: FloatArray, T_base: FloatArray
) -> dict[str, Any]:
    """What a motion's states touch of the true table and bottle (``ExecutionOracle``'s rule and step).

    The transit may touch nothing; in the approach the hand may touch the bottle. Per part, the
    number of states per contact ("self" or "LINK GEOMETRY - SHAPE", the first found).
    """
    out: dict[str, Any] = {}
    for part, waypoints, hand_may_touch in (("transit", path, False), ("approach", approach, True)):
        scene = oracle.scene if hand_may_touch or oracle.grasped is None else [*oracle.scene, oracle.grasped]
        held = oracle.grasped if hand_may_touch else None
        touched: Counter[str] = Counter()
        states = [waypoints[0]]
        for a, b in itertools.pairwise(waypoints):
            n = max(1, math.ceil(float(np.linalg.norm(b - a)) / oracle.settings.path_step))
            states += [a + (b - a) * (k / n) for k in range(1, n + 1)]
        for q in states:
            what = oracle.shapes.touching(q, T_base, scene, held)
            if what is not None:
                touched[what] += 1
        out[part] = dict(touched)
    return out


def stats(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"median": None, "p90": None, "mean": None}
    v = np.asarray(values, dtype=float)
    return {"median": round(float(np.median(v)), 2), "p90": round(float(np.quantile(v, 0.9)), 2),
            "mean": round(float(v.mean()), 2)}  # fmt: skip


ON_FLOOR = 0.3
"""A base pose below this height [m] stands on the floor; above it, ``place`` put the robot on the
table top (a 0.8 x 1.8 m plane, large enough for TIAGo's footprint, is a region it may stand on)."""


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The figures over every check, and over those whose base pose stands on the floor."""
    floor = [row for row in rows if row["T_world_base"][2][3] < ON_FLOOR]
    return {**figures(rows), "base_on_table_top": len(rows) - len(floor), "floor_only": figures(floor)}


def figures(rows: list[dict[str, Any]]) -> dict[str, Any]:
    names = [name for name in CHECKERS if rows and name in rows[0]]
    with_reference = "reference" in names
    feasible = sum(row["reference_valid"] for row in rows) if with_reference else None
    out: dict[str, Any] = {
        "checks": len(rows),
        "scenes": len({(row["seed"], *row["cell"]) for row in rows}),
        "reference_feasible": feasible,
    }
    for name in (n for n in names if n != "reference"):
        r = [row[name] for row in rows]
        false_none = (
            sum(1 for row in rows if not row[name]["found"] and row["reference_valid"])
            if with_reference
            else None
        )
        low, high = wilson_interval(false_none, len(rows)) if rows and false_none is not None else (0.0, 1.0)
        low_f, high_f = (
            wilson_interval(false_none, feasible) if feasible and false_none is not None else (0.0, 1.0)
        )
        states = [
            x.get("state_checks", sum(v for k, v in x["calls"].items() if k.startswith("states_"))) for x in r
        ]
        obstacle_ms = sum(x["ms"].get("obstacles", 0.0) for x in r)
        self_ms = sum(x["ms"].get("self_collision", 0.0) for x in r)
        obstacle_n = sum(x["calls"].get("obstacles", 0) for x in r)
        self_n = sum(x["calls"].get("self_collision", 0) for x in r)
        total_states = sum(states)
        total_ms = sum(x["wall_ms"] for x in r)
        state_ms = sum(sum(v for k, v in x["ms"].items() if k.startswith(("states_", "edges_"))) for x in r)
        out[name] = {
            "found": sum(x["found"] for x in r),
            "false_no_motion": false_none,
            "false_no_motion_rate": round(false_none / len(rows), 4) if rows and false_none is not None else None,
            "false_no_motion_ci95": [round(low, 4), round(high, 4)],
            "false_no_motion_of_feasible": (
                round(false_none / feasible, 4) if feasible and false_none is not None else None
            ),
            "false_no_motion_of_feasible_ci95": [round(low_f, 4), round(high_f, 4)],
            "false_no_motion_per_scene": dict(
                Counter(
                    f"{row['seed']} {tuple(row['cell'])}"
                    for row in rows
                    if with_reference and not row[name]["found"] and row["reference_valid"]
                )
            ),
            "found_touching_at_finer_recheck": sum(1 for x in r if x["found"] and x["recheck"]["colliding"]),
            "found_touching_true_scene": sum(1 for x in r if x["found"] and any(x["true_scene"].values())),
            "found_touching_true_scene_in_transit": sum(
                1 for x in r if x["found"] and x["true_scene"]["transit"]
            ),
            "found_touching_true_scene_in_approach": sum(
                1 for x in r if x["found"] and x["true_scene"]["approach"]
            ),
            "approach_ms": stats([x["approach_ms"] for x in r]),
            "approach_share": round(sum(x["approach_ms"] for x in r) / total_ms, 3) if total_ms else None,
            "rrt_share": round(sum(x["rrt_ms"] for x in r) / total_ms, 3) if total_ms else None,
            "refusals": dict(Counter(x["reason"] for x in r if not x["found"])),
            "ms": stats([x["wall_ms"] for x in r]),
            "ms_found": stats([x["wall_ms"] for x in r if x["found"]]),
            "ms_refused": stats([x["wall_ms"] for x in r if not x["found"]]),
            "state_checks": stats([float(n) for n in states]),
            "ms_per_state_check": round(state_ms / total_states, 3) if total_states else None,
            "ms_per_obstacle_check": round(obstacle_ms / obstacle_n, 3) if obstacle_n else None,
            "ms_per_self_collision_check": round(self_ms / self_n, 3) if self_n else None,
            "share_in_state_checks": round(state_ms / total_ms, 3) if total_ms else None,
            "planned_by_rrt": sum(1 for x in r if x.get("rrt") is not None),
            "state_ms": stats([sum(v for k, v in x["ms"].items() if k.startswith(("states_", "edges_"))) / n
                               for x, n in zip(r, states, strict=True) if n]),
        }  # fmt: skip
    if not with_reference:
        return out
    ref = [row["reference"] for row in rows]
    out["reference"] = {
        "found": sum(x["found"] for x in ref),
        "found_and_rechecked_free": feasible,
        "found_touching_at_finer_recheck": sum(1 for x in ref if x["found"] and x["recheck"]["colliding"]),
        "found_touching_true_scene": sum(1 for x in ref if x["found"] and any(x["true_scene"].values())),
        "refusals": dict(Counter(x["reason"] for x in ref if not x["found"])),
        "ms": stats([x["wall_ms"] for x in ref]),
    }
    return out


def main(argv: list[str] | None = None) -> None:
    """Run the bench on the command line ``argv`` (default ``sys.argv[1:]``); refusals exit 2 before any work."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--split", choices=["dev", "held-out"], default="dev",
                        help=f"dev seeds {list(SEEDS)} or the held-out seeds of --protocol")  # fmt: skip
    parser.add_argument("--protocol", type=int, choices=sorted(PROTOCOLS), default=PROTOCOL,
                        help="which protocol's file and held-out seeds (docs/protocols/motion_verdicts_vN.md)")  # fmt: skip
    parser.add_argument(
        "--seeds", type=int, nargs="+", default=None, help="table-grid dev seeds (dev split only)"
    )
    parser.add_argument("--cells", type=int, default=len(CELLS), help=f"first N of {list(CELLS)}")
    parser.add_argument("--grasps", type=int, nargs="+", default=list(GRASPS),
                        help="indices into the 32 table-grid grasps (0-15 side, 16-31 top-down)")  # fmt: skip
    parser.add_argument(
        "--side-lift", type=float, default=SIDE_LIFT, help="side grasps this far above the centre [m]"
    )
    parser.add_argument("--per-grasp", type=int, default=PER_GRASP, help="verified base poses per grasp")
    parser.add_argument("--max-checks", type=int, default=None, help="stop after this many motion checks")
    parser.add_argument("--name", default="motion_verdicts_dev", help="results file bench/results/NAME.json")
    parser.add_argument("--checkers", nargs="+", choices=list(CHECKERS), default=["product", "product_500", "reference"],
                        help="which motion checkers run on each placement (module docstring)")  # fmt: skip
    args = parser.parse_args(argv)
    protocol_path, protocol_seeds = PROTOCOLS[args.protocol]
    if args.split == "held-out":
        if args.seeds is not None or args.cells != len(CELLS) or args.max_checks is not None:
            parser.error(
                f"the held-out split runs protocol v{args.protocol} as written: no --seeds, --cells or --max-checks"
            )
        if (
            args.checkers != ["product", "reference"]
            or args.grasps != list(GRASPS)
            or args.per_grasp != PER_GRASP
        ):
            parser.error(
                f"the held-out split runs protocol v{args.protocol} as written: --checkers product reference, default grasps and --per-grasp"
            )
        args.seeds = list(protocol_seeds)
    elif args.seeds is None:
        args.seeds = list(SEEDS)
    every_held_out = {seed for _, seeds in PROTOCOLS.values() for seed in seeds}
    held_out = {*range(3, 38), *every_held_out} if args.split == "dev" else set()
    if held_out & set(args.seeds):
        parser.error(f"seeds {sorted(held_out & set(args.seeds))} are held out by an experiment")
    try:
        protocol_file = fixed_protocol(protocol_path, args.split)
    except InputError as e:
        parser.error(str(e))
    load_start = os.getloadavg()
    robot = Robot("tiago")
    rmap = resolve_map(robot, None).rmap
    arm = robot.arm(rmap.info.arm)
    s = TableGridSettings()
    meter = Meter()
    shapes = RobotShapes(robot, arm.name)
    true_step = ExecutionSettings(path_step=PRODUCT.joint_resolution / RECHECK)
    rows: list[dict[str, Any]] = []
    t_run = time.perf_counter()
    for seed in args.seeds:
        for cell in CELLS[: args.cells]:
            p_true, p_est, seen = scene(seed, cell, s)
            oracle = ExecutionOracle(shapes, true_table(s), true_bottle(p_true, s), true_step)
            points = with_floor(seen, 0.0)
            cache = SceneCache(points)
            grasps = s.grasps(p_est, s.method_top_below)
            grasps[: s.grasp_directions, 2, 3] += args.side_lift
            for g in args.grasps:
                if args.max_checks is not None and len(rows) >= args.max_checks:
                    break
                target = grasps[g]
                pose_only = PlaceSettings(tries=TRIES, placements=args.per_grasp, **POSE_ONLY_CHECKS)
                t = time.perf_counter()
                res = place(robot, rmap, points, target, pose_only, np.random.default_rng([seed, *cell, g]),
                            grasped="auto", cache=cache)  # fmt: skip
                t_place = time.perf_counter() - t
                print(seed, cell, g, f"{len(res.placements)} placements in {res.tries} tries, {t_place:.1f} s",
                      dict(res.failures), res.contacts.most_common(2), flush=True)  # fmt: skip
                if not res.placements:
                    continue
                checks = scene_checks(robot, arm.name, points, cache.terrain(None), target[None],
                                      PlaceSettings(), "auto", cache)  # fmt: skip
                product = checks.verifier.motion
                assert product is not None
                models: dict[bool, tuple[Any, Any]] = {}
                for exact in sorted({CHECKERS[name][1] for name in args.checkers}):
                    transit, approach = product.environment, product.approach_environment
                    if exact:
                        transit = ExactStates(transit)
                        approach = None if approach is None else ExactStates(approach)
                    meter_environment(meter, transit, "transit")
                    if approach is not None:
                        meter_environment(meter, approach, "approach")
                    models[exact] = (transit, approach)
                for k, placement in enumerate(res.placements):
                    if args.max_checks is not None and len(rows) >= args.max_checks:
                        break
                    q, T_base = placement.joints[0], placement.T_world_base
                    ompl_seed = check_seed(seed, cell, g, k)
                    row: dict[str, Any] = {
                        "seed": seed, "cell": list(cell), "grasp": g, "placement": k,
                        "base": [round(float(T_base[0, 3]), 3), round(float(T_base[1, 3]), 3),
                                 round(math.atan2(T_base[1, 0], T_base[0, 0]), 3)],
                        "grasped": res.grasped_note.split(" at ")[0],
                        "T_world_base": np.round(T_base, 6).tolist(), "target": np.round(target, 6).tolist(),
                        "q_grasp": np.round(q, 6).tolist(),
                    }  # fmt: skip
                    for name in args.checkers:
                        settings, exact = CHECKERS[name]
                        checker = MotionChecker(robot, arm, *models[exact], settings)
                        row[name], motion = run_check(checker, meter, q, T_base, target, ompl_seed)
                        if motion is not None:
                            row[name]["recheck"] = recheck(checker, motion.path, motion.approach, T_base)
                            row[name]["true_scene"] = true_scene(oracle, motion.path, motion.approach, T_base)
                            row[name]["path"] = np.round(motion.path, 5).tolist()
                            row[name]["approach"] = np.round(motion.approach, 5).tolist()
                    if "reference" in row:
                        ref = row["reference"]
                        row["reference_valid"] = ref["found"] and ref["recheck"]["colliding"] == 0
                    rows.append(row)
                    print("  ", k, {n: (row[n]["found"], row[n]["wall_ms"], row[n].get("reason"))
                                    for n in args.checkers}, flush=True)  # fmt: skip
    summary = summarise(rows)
    result = {
        "protocol": {
            "seeds": list(args.seeds), "cells": [list(c) for c in CELLS[: args.cells]], "grasps": list(args.grasps),
            "per_grasp": args.per_grasp, "side_lift_m": args.side_lift, "tries": TRIES, "scene": "table grid (execution_trial draws), floor at z = 0",
            "product": dataclasses.asdict(PRODUCT), "product_500": dataclasses.asdict(PRODUCT_500),
            "reference": dataclasses.asdict(REFERENCE), "recheck_resolution_divisor": RECHECK,
            "checkers": {n: {**dataclasses.asdict(CHECKERS[n][0]), "every_pair_to_coal": CHECKERS[n][1]}
                         for n in args.checkers},
            "split": args.split, "protocol_version": args.protocol if args.split == "held-out" else None,
            "load_average": {"start": load_start, "end": os.getloadavg()},
            "wall_s": round(time.perf_counter() - t_run, 1),
        },
        "summary": summary,
        "checks": rows,
    }  # fmt: skip
    report(args.name, result, split=args.split, used_seeds=list(args.seeds), protocol_file=protocol_file)
    print_table(summary)
    print("base on the floor only:")
    print_table(summary["floor_only"])


def print_table(summary: dict[str, Any]) -> None:
    n = summary["checks"]
    ref = summary.get("reference")
    print(
        f"\n{n} motion checks; reference found {ref['found']} ({ref['found_and_rechecked_free']} re-checked free)"
        if ref is not None
        else f"\n{n} motion checks; no reference"
    )
    line: Callable[[str, dict[str, Any]], str] = lambda name, x: (  # noqa: E731
        f"{name:18s} found {x['found']:3d}  false none {x['false_no_motion']} "
        f"({x['false_no_motion_rate']}, CI95 {x['false_no_motion_ci95']}; of feasible "
        f"{x['false_no_motion_of_feasible']}, CI95 {x['false_no_motion_of_feasible_ci95']})  "
        f"found touching at finer recheck {x['found_touching_at_finer_recheck']}, true scene "
        f"{x['found_touching_true_scene']}  "
        f"ms median {x['ms']['median']} p90 {x['ms']['p90']}  states median {x['state_checks']['median']}  "
        f"ms/state {x['ms_per_state_check']} (obstacles {x['ms_per_obstacle_check']}, "
        f"self {x['ms_per_self_collision_check']})"
    )
    for name in (n for n in CHECKERS if n != "reference" and n in summary):
        print(line(name, summary[name]))


if __name__ == "__main__":
    main()
