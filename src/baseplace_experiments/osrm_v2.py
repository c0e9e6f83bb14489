"""Protocol v2 of seed 000's Tables I and II (issue 27): several seeds, intervals, the allowed grasps.

The protocol is docs/protocols/osrm_v2.md, committed before the held-out run. What changes from v1
(:mod:`baseplace_experiments.osrm_experiment`, whose scenes, grasp draws, ground truth and queries
are reused unchanged):

* Three seeds per split (:data:`SEEDS`), :data:`SCENES` scenes per seed and class: 21 per class.
  Scene k of class c under seed s is v1's scene ``(s, c, k)``.
* Grasp planner v2 (fixed before the held-out run): v1's top-down draws (the same draws), each
  moved back along its approach axis until the rigid hand meets the grasped object's true shape
  (:class:`~baseplace_experiments.allowed_grasps.ContactApproach`), then v1's open-hand rule.
* The method runs at its default settings (its own derived clearance). Every counted grasp is
  also put to the oracle of :mod:`~baseplace_experiments.allowed_grasps` (whole robot clear of the
  true solids by the clearance the method's queries on that grasp report, the rigid hand at most
  ``GRASP_DEPTH`` into the grasped object). Success is reported over the counted grasps and over
  the allowed ones.
* 95 % intervals from :func:`~baseplace_experiments.scene_bootstrap.scene_bootstrap`: scenes
  resampled within each seed and class.
* Each verified placement's own joints are checked on the true shapes (no margin): contacts are
  reported per row (``touched_true_scene``).
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from baseplace.errors import InputError
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace_experiments.allowed_grasps import (
    APPROACH_LIMIT,
    APPROACH_TOLERANCE,
    GRASP_DEPTH,
    SOLUTIONS,
    AllowedGrasps,
)
from baseplace_experiments.osrm_experiment import (
    PAPER,
    SCENE_CLASSES,
    ExperimentSettings,
    SceneOutcome,
    _class_name,
    _Tally,
    osrm_scene,
    strategies_for,
)
from baseplace_experiments.results import SeedSplit
from baseplace_experiments.scene_bootstrap import DRAWS, SEED, pooled_rate, scene_bootstrap
from baseplace_experiments.table_grid import RobotShapes

SEEDS = SeedSplit((1000, 1001, 1002), (4101, 4102, 4103))
"""v2's development seeds (any choice of parameters) and fresh held-out seeds (never used before v2)."""
PROTOCOL_FILE = "docs/protocols/osrm_v2.md"
"""The protocol, committed before the held-out run."""
SCENES = 7
"""Scenes per seed and class (3 seeds: 21 per class)."""
GRASPS = 3
"""Grasp candidates per scene, from planner v2 (fixed before the held-out run)."""
TRIES = 100
"""N: candidates per query; success is read at N = 1 and N = 100."""
BUDGETS = (1, 100)
"""Budgets N at which success and its interval are reported."""


def held_out_settings_check(scenes: int, grasps: int, tries: int, version: int = 2) -> None:
    """A held-out run of protocol ``version`` (v2 or v3, the same counts) takes the protocol's counts: else refused before any work."""
    if (scenes, grasps, tries) != (SCENES, GRASPS, TRIES):
        raise InputError(f"a held-out protocol-v{version} run uses --scenes {SCENES} --grasps {GRASPS} --tries {TRIES} "
                         f"(the protocol's), got {scenes}, {grasps}, {tries}")  # fmt: skip


def run_osrm_v2(
    robot: Robot,
    rmap: ReachabilityMap,
    seeds: Sequence[int],
    scenes: int = SCENES,
    grasps: int = GRASPS,
    tries: int = TRIES,
    classes: tuple[tuple[str, int], ...] = SCENE_CLASSES,
    progress: Any = None,
    base: ExperimentSettings | None = None,
    protocol: int = 2,
) -> dict[str, Any]:
    """Table I and II rows of protocol v2: per class and strategy, success with scene-bootstrap intervals.

    ``base``: the scene and query settings but the seed, grasps and tries (default v2's,
    :class:`ExperimentSettings`'s defaults); protocol v3 hands the method the clean cloud this way.
    ``protocol`` is recorded in the result.
    """
    base = base or ExperimentSettings()
    if not seeds or scenes < 1 or grasps < 1 or tries < 1:
        raise InputError(
            f"need seeds and scenes, grasps, tries >= 1; got {list(seeds)}, {scenes}, {grasps}, {tries}"
        )
    oracle = AllowedGrasps(RobotShapes(robot, rmap.info.arm))
    outcomes: dict[tuple[int, int], list[SceneOutcome]] = {}
    for seed in seeds:
        s = dataclasses.replace(base, grasps_per_scene=grasps, seed=seed, tries=tries)
        for c in range(len(classes)):
            for k in range(scenes):
                outcomes.setdefault((seed, c), []).append(osrm_scene(robot, rmap, c, k, s, classes, oracle))
                if progress is not None:
                    progress(1)
    rows = [
        _row(classes[c], name, [outcomes[(seed, c)] for seed in seeds])
        for c in range(len(classes))
        for name in strategies_for(classes[c][1])
    ]
    every = [r for x in outcomes.values() for r in x]
    return {"protocol": protocol, "rows": rows, "seeds": [int(s) for s in seeds], "scenes_per_seed": scenes,
            "grasps_per_scene": grasps, "tries": tries, "budgets": list(BUDGETS),
            "planner": _planner_summary(every), "clearance": _clearance_summary(every),
            "grasp_depth_m": GRASP_DEPTH, "oracle_ik_solves_per_pose": SOLUTIONS,
            "bootstrap": {"draws": DRAWS, "seed": SEED, "level": 0.95, "resampled": "scenes within seed and class"},
            "settings": dataclasses.asdict(dataclasses.replace(base, grasps_per_scene=grasps, tries=tries))}  # fmt: skip


def _planner_summary(outcomes: list[SceneOutcome]) -> dict[str, Any]:
    """Planner v2's standoffs [m] over every grasp of the run (how far the draws were moved back)."""
    d = np.array([x for r in outcomes for x in r.standoffs])
    stats = {} if d.size == 0 else {"min": float(d.min()), "median": float(np.median(d)), "max": float(d.max()),
                                    "moved": int(np.count_nonzero(d))}  # fmt: skip
    return {"rule": "v1's draws moved back along the approach until the rigid hand meets the grasped object",
            "approach_limit_m": APPROACH_LIMIT, "approach_tolerance_m": APPROACH_TOLERANCE,
            "grasps": int(d.size), "turned_down": sum(r.turned_down for r in outcomes),
            "standoff_m": {k: round(v, 4) if isinstance(v, float) else v for k, v in stats.items()}}  # fmt: skip


def _clearance_summary(outcomes: list[SceneOutcome]) -> dict[str, Any]:
    """The clearances [m] the oracle kept: per counted grasp the one its queries reported."""
    kept = Counter(f"{g.clearance:.4f}" for r in outcomes for g in r.records if g.clearance is not None)
    return {"rule": "per counted grasp, the clearance every method query on it reports (the method's default, "
                    "derived); 3 mm when no query returned",
            "oracle_clearance_m": dict(sorted(kept.items())),
            "grasps_without_a_query_result": sum(1 for r in outcomes for g in r.records
                                                 if g.clearance is not None and not g.clearance_from_method)}  # fmt: skip


def _row(cls: tuple[str, int], name: str, by_seed: list[list[SceneOutcome]]) -> dict[str, Any]:
    """One row: the class's scenes of every seed (strata), strategy ``name``."""
    size_class, n_planes = cls
    tally = _Tally()
    for scenes in by_seed:
        for r in scenes:
            tally.merge(r.stats[name])
    row: dict[str, Any] = {
        "scene": _class_name(size_class, n_planes), "strategy": name, "scenes": sum(len(x) for x in by_seed),
        "grasps": sum(r.grasps for x in by_seed for r in x),
        "counted_grasps": sum(r.reachable for x in by_seed for r in x),
        "allowed_grasps": sum(1 for x in by_seed for r in x for g in r.records if g.allowed),
        "paper_success_rate": PAPER.get(cls, {}).get(name),
    }  # fmt: skip
    for over in ("counted", "allowed"):
        for b in BUDGETS:
            strata = [[_scene_count(r, name, b, over == "allowed") for r in x] for x in by_seed]
            rate = pooled_rate(strata)
            ci = scene_bootstrap(strata)
            row[f"success_{over}_N{b}"] = None if rate is None else round(rate, 1)
            row[f"ci95_{over}_N{b}"] = None if ci is None else [round(ci[0], 1), round(ci[1], 1)]
    row["succeeded_not_allowed"] = sum(
        1 for x in by_seed for r in x for g in r.records if g.allowed is False and g.tries[name] is not None
    )
    row["failures"] = dict(tally.failures)
    row["touched_true_scene"] = dict(tally.touched_true_scene)
    return row


def _scene_count(r: SceneOutcome, name: str, budget: int, allowed_only: bool) -> tuple[int, int]:
    """(successes within ``budget`` tries, grasps) of one scene, over its counted or allowed grasps."""
    grasps = [g for g in r.records if g.allowed or not allowed_only]
    ok = sum(1 for g in grasps if (t := g.tries[name]) is not None and t <= budget)
    return ok, len(grasps)


def with_v1(result: dict[str, Any], v1: dict[str, Any]) -> dict[str, Any]:
    """``result`` with each row's v1 figures beside it (same class and strategy), from v1's results file."""
    old = {(r["scene"], r["strategy"]): r for r in v1.get("rows", [])}
    for row in result["rows"]:
        r = old.get((row["scene"], row["strategy"]))
        row["v1"] = None if r is None else {
            "scenes": r.get("scenes"), "queries": r.get("queries"), "success_rate": r.get("success_rate"),
            "success_rate_N1": (r.get("success_rate_at") or {}).get("1"), "seed": v1.get("seed"),
        }  # fmt: skip
    return result


__all__ = ["BUDGETS", "GRASPS", "PROTOCOL_FILE", "SCENES", "SEEDS", "TRIES", "held_out_settings_check",
           "run_osrm_v2", "with_v1"]  # fmt: skip
