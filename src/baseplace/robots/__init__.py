"""Robot models: specs, pinocchio models, compiled FK, IK and self-collision."""

from baseplace.robots.collision import SelfCollision
from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK, IKSolver
from baseplace.robots.model import Arm, Robot
from baseplace.robots.spec import BUILTIN_ROBOTS, ArmSpec, Mount, RobotSpec, load_spec

__all__ = [
    "BUILTIN_ROBOTS",
    "Arm",
    "ArmSpec",
    "DampedLeastSquaresIK",
    "IKSolver",
    "Mount",
    "Robot",
    "RobotSpec",
    "SelfCollision",
    "forward_kinematics",
    "load_spec",
]
