"""Protocol v3 of seed 000's Tables I and II (issue 27): v2 with the method's collision model from the clean cloud.

The protocol is docs/protocols/osrm_v3.md, committed before the held-out run. What changes from v2
(:mod:`baseplace_experiments.osrm_v2`, whose scenes, grasp planner v2, ground truth, oracle, counts
and analysis are reused unchanged):

* The cloud the method builds its collision model from (``place``'s ``points``: the fine cells
  near the grasped object, the derived clearance) is the noise-free sensor sample of the scene
  (12.5 mm spacing, the same sampler as the noisy cloud, its own generator) that already gives the
  terrain's 25 mm collision voxels: seed 000 VI adds its 25 mm noise to the height map only, and
  checks collisions on the OctoMap of the clouds. The segmentation (height map, planar regions) is
  the noisy cloud's, as in v2. Nothing of the true shapes reaches the method.
* Fresh seeds (:data:`SEEDS`): dev 1000-1002 as v2, held-out 4201-4203 (used by no experiment before).
* The rows of v2's results file go beside (:func:`with_v2`).
"""

from __future__ import annotations

import functools
from typing import Any

from baseplace.errors import InputError
from baseplace_experiments import osrm_v2
from baseplace_experiments.osrm_experiment import ExperimentSettings
from baseplace_experiments.osrm_v2 import BUDGETS
from baseplace_experiments.results import SeedSplit

PROTOCOL = 3
SEEDS = SeedSplit((1000, 1001, 1002), (4201, 4202, 4203))
"""v3's development seeds (v2's) and fresh held-out seeds (never used before v3)."""
PROTOCOL_FILE = "docs/protocols/osrm_v3.md"
"""The protocol, committed before the held-out run."""
SETTINGS = ExperimentSettings(collision_cloud="clean")
"""v2's scene and query settings, the method's collision model from the clean cloud."""


def held_out_settings_check(scenes: int, grasps: int, tries: int) -> None:
    """A held-out run takes v2's counts: anything else is refused before any work."""
    osrm_v2.held_out_settings_check(scenes, grasps, tries, version=PROTOCOL)


run_osrm_v3 = functools.partial(osrm_v2.run_osrm_v2, base=SETTINGS, protocol=PROTOCOL)
"""Table I and II rows of protocol v3 (:func:`~baseplace_experiments.osrm_v2.run_osrm_v2` on :data:`SETTINGS`)."""


def beside_check(v2: Any) -> None:
    """The file whose rows go beside v3's is a protocol-2 results file: else refused before any work."""
    got = v2.get("protocol") if isinstance(v2, dict) else None
    if got != 2 or not isinstance(v2.get("rows"), list):
        raise InputError(
            f"--beside for protocol 3 takes a protocol-2 results file with rows, got protocol {got}"
        )


def with_v2(result: dict[str, Any], v2: dict[str, Any]) -> dict[str, Any]:
    """``result`` with each row's v2 figures beside it (same class and strategy), from v2's results file."""
    beside_check(v2)
    old = {(r["scene"], r["strategy"]): r for r in v2.get("rows", [])}
    keys = ["scenes", "counted_grasps", "allowed_grasps"] + [
        f"{what}_{over}_N{b}"
        for over in ("counted", "allowed")
        for b in BUDGETS
        for what in ("success", "ci95")
    ]
    for row in result["rows"]:
        r = old.get((row["scene"], row["strategy"]))
        row["v2"] = None if r is None else {**{k: r.get(k) for k in keys}, "seeds": v2.get("seeds")}
    return result


__all__ = [
    "PROTOCOL_FILE",
    "SEEDS",
    "SETTINGS",
    "beside_check",
    "held_out_settings_check",
    "run_osrm_v3",
    "with_v2",
]
