"""baseplace: where should a mobile manipulator stand?

The public API; see the README and docs/ for the conventions (``T_a_b`` maps frame b to a,
``R = Rz(yaw) Ry(pitch) Rx(roll)``, SI units).
"""

from baseplace.errors import BaseplaceError, InputError, NothingFoundError
from baseplace.geometry import BasePose, parse_base_pose, parse_pose6, plane_base_poses
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

__version__ = "0.1.0"

__all__ = [
    "BUILTIN_ROBOTS",
    "ArmCombination",
    "BasePose",
    "BaseplaceError",
    "BuildSettings",
    "DampedLeastSquaresIK",
    "InputError",
    "NothingFoundError",
    "ReachabilityMap",
    "Robot",
    "__version__",
    "build_map",
    "forward_kinematics",
    "inverse_reachability",
    "load_map",
    "parse_base_pose",
    "parse_pose6",
    "plane_base_poses",
    "save_map",
]
