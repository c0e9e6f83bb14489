"""Reachability maps: the SE(3) grid, building by joint sampling, inverse queries, storage."""

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
