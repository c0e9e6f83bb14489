"""Reachability maps: the SE(3) grid, building by joint sampling, inverse queries, storage."""

from __future__ import annotations

from typing import TYPE_CHECKING

from baseplace.lazy import lazy_getattr

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


__getattr__ = lazy_getattr(__name__, _LAZY, globals())


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
