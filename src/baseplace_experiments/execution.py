"""Executing a placement under navigation error, judged on the true scene (issue 20).

A placement is verified at its exact base pose; a robot stops a few centimetres and degrees off
it (:class:`~baseplace.placement.robustness.BaseErrorModel`) and then re-plans its grasp from
where it stands. :class:`ExecutionOracle` asks what that robot would find, independently of the
method that chose the placement:

* **Grasp**: from the drawn base pose, is there a collision-free IK solution of the grasp? IK is
  solved from the robot's stowed configuration (what a robot's IK is seeded with: its current
  joint state) and from ``ik_solutions - 1`` uniform random starts, each solved on its own (not
  the method's nominal configuration); each solution is accepted only when pinocchio's FK puts
  the TCP on the grasp (1 mm, 0.01 rad) and the robot there touches nothing of the *true* scene
  (coal on the true shapes: :class:`~baseplace_experiments.table_grid.RobotShapes`, its own geometry
  model, no voxels, no octree): no self-collision, only the hand may touch the grasped object.
  The draw succeeds when any solution passes. The IK solver only proposes configurations; FK and
  coal decide, so an IK error could only make the oracle stricter.
* **Reaching motion** (:meth:`ExecutionOracle.execute`): the robot plans its arm motion with its
  own planner (:class:`~baseplace.placement.motion.MotionChecker` on its perceived voxels) to the
  oracle's grasp configuration, and the executed path (transit and approach, every state at most
  ``path_step`` apart in joint space) is checked against the true scene: nothing may be touched in
  the transit, only the hand may touch the grasped object in the approach.

The table-grid scene of seed 004 (:mod:`baseplace_experiments.table_grid`) provides the true shapes.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray, invert_transforms
from baseplace.placement.motion import MotionChecker, stowed_configuration
from baseplace.placement.robustness import perturbed
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace_experiments.table_grid import RobotShapes, TrueShape


@dataclass(frozen=True)
class ExecutionSettings:
    """How the oracle re-plans at the drawn base pose.

    Attributes:
        ik_solutions: IK solutions per grasp and draw: one from the stowed configuration, the
            others each from one uniform random start.
        tol_position: FK must put the TCP within this of the grasp [m].
        tol_rotation: and within this angle of its orientation [rad].
        path_step: executed paths are checked at states at most this far apart [rad, joint space].
        motion_tries: per draw, at most this many grasp configurations go to the motion planner.
    """

    ik_solutions: int = 16
    tol_position: float = 1e-3
    tol_rotation: float = 1e-2
    path_step: float = 0.02
    motion_tries: int = 3

    def __post_init__(self) -> None:
        if self.ik_solutions < 1 or self.motion_tries < 1:
            raise InputError(
                f"need ik_solutions >= 1, motion_tries >= 1; got {self.ik_solutions}, {self.motion_tries}"
            )
        for name in ("tol_position", "tol_rotation", "path_step"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a finite number > 0, got {value}")


class ExecutionOracle:
    """Independent IK + collision (and executed-motion) checks on the true scene (module docstring).

    Args:
        shapes: the robot's own geometry model (built once per robot).
        scene: the true obstacles (table top, legs ...), world frame.
        grasped: the true grasped object (only the hand may touch it), or None.
        settings: IK and path settings.
    """

    def __init__(self, shapes: RobotShapes, scene: Sequence[TrueShape], grasped: TrueShape | None,
                 settings: ExecutionSettings | None = None) -> None:  # fmt: skip
        self.shapes = shapes
        self.robot = shapes.robot
        self.arm = shapes.arm
        self.scene = list(scene)
        self.grasped = grasped
        self.settings = settings or ExecutionSettings()
        self.q_stowed = stowed_configuration(self.robot, self.arm)
        self._ik = DampedLeastSquaresIK(self.arm, restarts=0)
        model = self.robot.model
        self._data = model.createData()
        self._base = model.getFrameId(self.arm.base_frame)
        self._tcp = model.getFrameId(self.arm.tcp_frame)

    def _reaches(self, q: FloatArray, T_base_tcp: FloatArray) -> bool:
        """Pinocchio FK: the TCP at ``q`` lies on ``T_base_tcp`` (4, 4), within the tolerances."""
        model = self.robot.model
        pin.framesForwardKinematics(model, self._data, self.arm.to_pinocchio(q, self.robot.q_reference))
        T = (self._data.oMf[self._base].inverse() * self._data.oMf[self._tcp]).homogeneous
        dp = float(np.linalg.norm(T[:3, 3] - T_base_tcp[:3, 3]))
        c = (np.trace(T[:3, :3].T @ T_base_tcp[:3, :3]) - 1.0) / 2.0
        return (
            dp <= self.settings.tol_position
            and math.acos(min(1.0, max(-1.0, c))) <= self.settings.tol_rotation
        )

    def free(self, q: FloatArray, T_world_base: FloatArray, hand_may_touch: bool = True) -> bool:
        """True if the robot at arm joints (n,) and base pose (4, 4) touches nothing of the true scene.

        With ``hand_may_touch`` the hand may touch the grasped object (at the grasp); without,
        the grasped object is an obstacle like the rest (in the transit).
        """
        if not bool(self.arm.within_limits(q)):
            return False
        if hand_may_touch or self.grasped is None:
            return self.shapes.touching(q, T_world_base, self.scene, self.grasped) is None
        return self.shapes.touching(q, T_world_base, [*self.scene, self.grasped]) is None

    def grasp_configurations(self, T_world_base: ArrayLike, grasp: ArrayLike, rng: np.random.Generator,
                             limit: int | None = None) -> list[FloatArray]:  # fmt: skip
        """Collision-free IK solutions (each (n,)) of the world grasp (4, 4) from a base pose (4, 4).

        Stowed start first, then random starts; at most ``limit`` (default: all found).
        """
        T_base = np.asarray(T_world_base, dtype=float)
        T_base_tcp = invert_transforms(T_base) @ np.asarray(grasp, dtype=float)
        arm = self.arm
        starts = np.vstack(
            [self.q_stowed, rng.uniform(arm.lower, arm.upper, (self.settings.ik_solutions - 1, arm.n_joints))]
        )
        out: list[FloatArray] = []
        for q0 in starts:
            q = self._ik.solve_from(T_base_tcp, q0[None])
            if q is None or not self._reaches(q, T_base_tcp) or not self.free(q, T_base):
                continue
            if any(np.allclose(q, other, atol=1e-3) for other in out):
                continue
            out.append(q)
            if limit is not None and len(out) >= limit:
                break
        return out

    def grasp_rate(self, T_world_base: ArrayLike, grasp: ArrayLike, offsets: ArrayLike,
                   rng: np.random.Generator) -> float:  # fmt: skip
        """Fraction of the base poses ``T_world_base`` (4, 4) moved by ``offsets`` (S, 3) with a grasp."""
        poses = perturbed(T_world_base, offsets)
        return float(np.mean([bool(self.grasp_configurations(T, grasp, rng, limit=1)) for T in poses]))

    def path_free(self, waypoints: ArrayLike, T_world_base: FloatArray, hand_may_touch: bool) -> bool:
        """Every state of the joint path (P, n), at most ``path_step`` apart, free on the true scene."""
        W = np.asarray(waypoints, dtype=float)
        if not self.free(W[0], T_world_base, hand_may_touch):
            return False
        for a, b in itertools.pairwise(W):
            steps = max(1, math.ceil(float(np.linalg.norm(b - a)) / self.settings.path_step))
            for k in range(1, steps + 1):
                if not self.free(a + (b - a) * (k / steps), T_world_base, hand_may_touch):
                    return False
        return True

    def execute(self, T_world_base: ArrayLike, grasps: ArrayLike, planner: MotionChecker,
                rng: np.random.Generator) -> str:  # fmt: skip
        """Outcome of one grasp attempt from the base pose (4, 4) the robot reached.

        Grasps (K, 4, 4), in the order the robot tries them (the method's chosen one first): for
        each, a collision-free IK solution on the true scene; the robot's ``planner`` plans the
        reaching motion to it on its own collision model; the executed path is checked on the
        true scene. Returns "ok", "no_grasp" (no grasp has a collision-free IK solution), "no_motion"
        (the planner found no motion to any solution tried) or "motion_collision" (every planned
        motion tried touches the true scene).
        """
        T = np.asarray(T_world_base, dtype=float)
        tries, planned = 0, False
        any_grasp = False
        for grasp in np.asarray(grasps, dtype=float).reshape(-1, 4, 4):
            solutions = self.grasp_configurations(T, grasp, rng, limit=1)
            if not solutions:
                continue
            any_grasp = True
            motion = planner.check(solutions[0], T, grasp, seed=int(rng.integers(2**31 - 1)))
            tries += 1
            if motion is not None:
                planned = True
                if self.path_free(motion.path, T, hand_may_touch=False) and self.path_free(
                    motion.approach, T, hand_may_touch=True
                ):
                    return "ok"
            if tries >= self.settings.motion_tries:
                break
        if not any_grasp:
            return "no_grasp"
        return "motion_collision" if planned else "no_motion"


__all__ = ["ExecutionOracle", "ExecutionSettings"]
