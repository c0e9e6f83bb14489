"""Reachability maps: the SE(3) grid, building by joint sampling, inverse queries, storage."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.grid import SE3Grid, orientation_bins_for
    from baseplace.reachability.rmap import (
        ArmCombination,
        MapInfo,
        ReachabilityMap,
        ReachabilityQuery,
        inverse_reachability,
    )
    from baseplace.reachability.storage import load_map, save_map

_LAZY = {
    "BuildSettings": "baseplace.reachability.build", "build_map": "baseplace.reachability.build",
    "SE3Grid": "baseplace.reachability.grid", "orientation_bins_for": "baseplace.reachability.grid",
    "ArmCombination": "baseplace.reachability.rmap", "MapInfo": "baseplace.reachability.rmap",
    "ReachabilityMap": "baseplace.reachability.rmap", "ReachabilityQuery": "baseplace.reachability.rmap",
    "inverse_reachability": "baseplace.reachability.rmap", "load_map": "baseplace.reachability.storage",
    "save_map": "baseplace.reachability.storage",
}  # fmt: skip
"""Public name -> its module, imported on first use (PEP 562): a query that loads a map never imports the builder."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'baseplace.reachability' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


__all__ = [
    "ArmCombination",
    "BuildSettings",
    "MapInfo",
    "ReachabilityMap",
    "ReachabilityQuery",
    "SE3Grid",
    "build_map",
    "inverse_reachability",
    "load_map",
    "orientation_bins_for",
    "save_map",
]
