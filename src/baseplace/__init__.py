"""baseplace: where should a mobile manipulator stand?

The public API; see the README and docs/ for the conventions (``T_a_b`` maps frame b to a,
``R = Rz(yaw) Ry(pitch) Rx(roll)``, SI units).

Three layers are exported here: the library (maps, placement, terrain, navigation), the jobs
(:mod:`baseplace.jobs`: one function per job, a typed input and one versioned :class:`Report`, what
the CLI runs) and the errors. Names are imported on first use (PEP 562), so ``import baseplace``
stays cheap and does not load numba or the robot models until they are needed.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from baseplace.errors import BaseplaceError, InputError, NothingFoundError
from baseplace.lazy import lazy_getattr

__version__ = "0.1.0"

_LAZY: dict[str, str] = {
    # the library
    "BasePose": "baseplace.geometry",
    "parse_base_pose": "baseplace.geometry",
    "parse_pose6": "baseplace.geometry",
    "plane_base_poses": "baseplace.geometry",
    "ArmCombination": "baseplace.reachability",
    "BuildSettings": "baseplace.reachability",
    "ReachabilityMap": "baseplace.reachability",
    "build_map": "baseplace.reachability",
    "inverse_reachability": "baseplace.reachability",
    "load_map": "baseplace.reachability",
    "save_map": "baseplace.reachability",
    "BUILTIN_ROBOTS": "baseplace.robots",
    "DampedLeastSquaresIK": "baseplace.robots",
    "Robot": "baseplace.robots",
    "forward_kinematics": "baseplace.robots",
    "Cloud": "baseplace.terrain.io",
    "load_cloud": "baseplace.terrain.io",
    "Terrain": "baseplace.terrain.pipeline",
    "terrain_from_points": "baseplace.terrain.pipeline",
    "PlaceSettings": "baseplace.placement.pipeline",
    "PlacementResult": "baseplace.placement.pipeline",
    "place": "baseplace.placement.pipeline",
    "MotionSettings": "baseplace.placement.motion",
    "BaseErrorModel": "baseplace.placement.robustness",
    "RobustnessSettings": "baseplace.placement.robustness",
    "RadialSettings": "baseplace.placement.candidates",
    "NavigationMap": "baseplace.navigation.navmap",
    "navigation_map": "baseplace.navigation.navmap",
    "Path": "baseplace.navigation.planners",
    "plan_path": "baseplace.navigation.planners",
    "GridNavigator": "baseplace.navigation.gridnav",
    "OccupancyGrid": "baseplace.world.occupancy",
    "load_occupancy": "baseplace.world.occupancy",
    # the jobs, their inputs and their report
    "SCHEMA_VERSION": "baseplace.jobs",
    "NoResultError": "baseplace.jobs",
    "Report": "baseplace.jobs",
    "RobotRef": "baseplace.jobs",
    "result_schema": "baseplace.jobs",
    "BagInput": "baseplace.jobs.inputs",
    "CloudInput": "baseplace.jobs.inputs",
    "PlaceJob": "baseplace.jobs.place",
    "place_job": "baseplace.jobs.place",
    "CandidatesJob": "baseplace.jobs.candidates",
    "candidates_job": "baseplace.jobs.candidates",
    "NavigateJob": "baseplace.jobs.navigate",
    "navigate_job": "baseplace.jobs.navigate",
    "SegmentJob": "baseplace.jobs.navigate",
    "segment_job": "baseplace.jobs.navigate",
    "SurfaceMapJob": "baseplace.jobs.surface",
    "surface_map_job": "baseplace.jobs.surface",
    "SurfaceSamplesJob": "baseplace.jobs.surface",
    "surface_samples_job": "baseplace.jobs.surface",
    "ReachJob": "baseplace.jobs.reach",
    "reach_job": "baseplace.jobs.reach",
    "BuildMapJob": "baseplace.jobs.reach",
    "build_map_job": "baseplace.jobs.reach",
    "DemoJob": "baseplace.jobs.demo",
    "demo_job": "baseplace.jobs.demo",
    "RobotCheckJob": "baseplace.jobs.world",
    "robot_check_job": "baseplace.jobs.world",
    "robots_job": "baseplace.jobs.world",
    "occupancy_job": "baseplace.jobs.world",
    "SceneJob": "baseplace.jobs.world",
    "scene_job": "baseplace.jobs.world",
}
"""Public name -> the module it is imported from on first use."""

if TYPE_CHECKING:  # what type checkers and IDEs see; at run time __getattr__ imports these
    from baseplace.geometry import BasePose, parse_base_pose, parse_pose6, plane_base_poses
    from baseplace.jobs import SCHEMA_VERSION, NoResultError, Report, RobotRef, result_schema
    from baseplace.jobs.candidates import CandidatesJob, candidates_job
    from baseplace.jobs.demo import DemoJob, demo_job
    from baseplace.jobs.inputs import BagInput, CloudInput
    from baseplace.jobs.navigate import NavigateJob, SegmentJob, navigate_job, segment_job
    from baseplace.jobs.place import PlaceJob, place_job
    from baseplace.jobs.reach import BuildMapJob, ReachJob, build_map_job, reach_job
    from baseplace.jobs.surface import SurfaceMapJob, SurfaceSamplesJob, surface_map_job, surface_samples_job
    from baseplace.jobs.world import (
        RobotCheckJob,
        SceneJob,
        occupancy_job,
        robot_check_job,
        robots_job,
        scene_job,
    )
    from baseplace.navigation.gridnav import GridNavigator
    from baseplace.navigation.navmap import NavigationMap, navigation_map
    from baseplace.navigation.planners import Path, plan_path
    from baseplace.placement.candidates import RadialSettings
    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.pipeline import PlacementResult, PlaceSettings, place
    from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings
    from baseplace.reachability import (
        ArmCombination,
        BuildSettings,
        ReachabilityMap,
        build_map,
        inverse_reachability,
        load_map,
        save_map,
    )
    from baseplace.robots import BUILTIN_ROBOTS, DampedLeastSquaresIK, Robot, forward_kinematics
    from baseplace.terrain.io import Cloud, load_cloud
    from baseplace.terrain.pipeline import Terrain, terrain_from_points
    from baseplace.world.occupancy import OccupancyGrid, load_occupancy


__getattr__ = lazy_getattr(__name__, _LAZY, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [  # every name above: the errors, __version__ and each of _LAZY (tests/test_api.py checks)
    "BUILTIN_ROBOTS",
    "SCHEMA_VERSION",
    "ArmCombination",
    "BagInput",
    "BaseErrorModel",
    "BasePose",
    "BaseplaceError",
    "BuildMapJob",
    "BuildSettings",
    "CandidatesJob",
    "Cloud",
    "CloudInput",
    "DampedLeastSquaresIK",
    "DemoJob",
    "GridNavigator",
    "InputError",
    "MotionSettings",
    "NavigateJob",
    "NavigationMap",
    "NoResultError",
    "NothingFoundError",
    "OccupancyGrid",
    "Path",
    "PlaceJob",
    "PlaceSettings",
    "PlacementResult",
    "RadialSettings",
    "ReachJob",
    "ReachabilityMap",
    "Report",
    "Robot",
    "RobotCheckJob",
    "RobotRef",
    "RobustnessSettings",
    "SceneJob",
    "SegmentJob",
    "SurfaceMapJob",
    "SurfaceSamplesJob",
    "Terrain",
    "__version__",
    "build_map",
    "build_map_job",
    "candidates_job",
    "demo_job",
    "forward_kinematics",
    "inverse_reachability",
    "load_cloud",
    "load_map",
    "load_occupancy",
    "navigate_job",
    "navigation_map",
    "occupancy_job",
    "parse_base_pose",
    "parse_pose6",
    "place",
    "place_job",
    "plan_path",
    "plane_base_poses",
    "reach_job",
    "result_schema",
    "robot_check_job",
    "robots_job",
    "save_map",
    "scene_job",
    "segment_job",
    "surface_map_job",
    "surface_samples_job",
    "terrain_from_points",
]
