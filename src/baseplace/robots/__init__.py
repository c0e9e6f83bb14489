"""Robot models: specs, pinocchio models, compiled FK, IK and self-collision.

The models are imported on first use (PEP 562), so that :data:`DEFAULT_ROBOT` costs no pinocchio.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from baseplace.lazy import lazy_getattr
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.robots.collision import SelfCollision
    from baseplace.robots.fk import forward_kinematics
    from baseplace.robots.ik import DampedLeastSquaresIK, IKSolver
    from baseplace.robots.model import Arm, Robot
    from baseplace.robots.spec import BUILTIN_ROBOTS, ArmSpec, Mount, RobotSpec, load_spec

_LAZY = {
    "SelfCollision": "baseplace.robots.collision",
    "forward_kinematics": "baseplace.robots.fk",
    "DampedLeastSquaresIK": "baseplace.robots.ik",
    "IKSolver": "baseplace.robots.ik",
    "Arm": "baseplace.robots.model",
    "Robot": "baseplace.robots.model",
    "BUILTIN_ROBOTS": "baseplace.robots.spec",
    "ArmSpec": "baseplace.robots.spec",
    "Mount": "baseplace.robots.spec",
    "RobotSpec": "baseplace.robots.spec",
    "load_spec": "baseplace.robots.spec",
}


__getattr__ = lazy_getattr(__name__, _LAZY, globals())


__all__ = [
    "BUILTIN_ROBOTS",
    "DEFAULT_ROBOT",
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
