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
* **Reaching motion** (:meth:`ExecutionOracle.execute`): the robot re-plans on its own, and the
  oracle only judges. The robot tries the grasps nearest its base first (one rule for every method:
  :func:`grasp_order`); for each it solves IK itself (:func:`own_grasp_configuration`: its own
  kinematic model, from its stowed configuration, then from random starts of its own generator),
  keeping the first solution its own collision model (the planner's perceived voxels; only the hand
  on the grasped object) calls free, and plans the reaching motion to it with its own planner
  (:class:`~baseplace.placement.motion.MotionChecker`). Nothing the oracle found on the true scene
  is handed over. The executed path (transit and approach, every state at most ``path_step`` apart
  in joint space) is then checked against the true scene: nothing may be touched in the transit,
  only the hand may touch the grasped object in the approach, and the final state must put the TCP
  on the grasp (pinocchio FK, the tolerances above).

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
        ik_solutions: IK starts per grasp and draw, the oracle's and the robot's alike: the stowed
            configuration, then uniform random starts (each solved on its own).
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

        The robot tries the grasps (K, 4, 4) in :func:`grasp_order` (whatever order they come in),
        each with its own IK solution (:func:`own_grasp_configuration`, from ``rng``, the robot's
        generator) and its ``planner``'s reaching motion; at most ``motion_tries`` grasps with a
        solution are planned. The oracle checks the executed path on the true scene. Returns "ok",
        "no_grasp" (the robot found no IK solution its own model calls free), "no_motion" (the
        planner found no motion to any solution tried) or "motion_collision" (every planned motion
        tried touches the true scene or ends off the grasp).
        """
        T = np.asarray(T_world_base, dtype=float)
        G = np.asarray(grasps, dtype=float).reshape(-1, 4, 4)
        tries, planned = 0, False
        for k in grasp_order(T, G):
            q = own_grasp_configuration(planner, T, G[k], rng, self.settings.ik_solutions)
            if q is None:
                continue
            motion = planner.check(q, T, G[k], seed=int(rng.integers(2**31 - 1)))
            tries += 1
            if motion is not None:
                planned = True
                T_base_tcp = invert_transforms(T) @ G[k]
                if (self._reaches(motion.approach[-1], T_base_tcp)
                        and self.path_free(motion.path, T, hand_may_touch=False)
                        and self.path_free(motion.approach, T, hand_may_touch=True)):  # fmt: skip
                    return "ok"
            if tries >= self.settings.motion_tries:
                break
        if tries == 0:
            return "no_grasp"
        return "motion_collision" if planned else "no_motion"


def grasp_order(T_world_base: ArrayLike, grasps: ArrayLike) -> list[int]:
    """The order in which the robot tries grasps (K, 4, 4) from a base pose (4, 4): nearest TCP first.

    Horizontal distance from the base to each grasp's TCP, ties in the given order. The one rule of
    every method: no method's own grasp goes first.
    """
    T = np.asarray(T_world_base, dtype=float)
    G = np.asarray(grasps, dtype=float).reshape(-1, 4, 4)
    distance = np.hypot(G[:, 0, 3] - T[0, 3], G[:, 1, 3] - T[1, 3])
    return [int(k) for k in np.argsort(distance, kind="stable")]


def own_grasp_configuration(planner: MotionChecker, T_world_base: ArrayLike, grasp: ArrayLike,
                            rng: np.random.Generator, starts: int) -> FloatArray | None:  # fmt: skip
    """The robot's own IK solution (n,) of the world grasp (4, 4) from a base pose (4, 4), or None.

    IK on the robot's kinematic model from its stowed configuration (its joint state when it
    arrives), then from ``starts - 1`` uniform random starts drawn from ``rng``; the first solution
    that is within the joint limits and that the robot's own collision model (the ``planner``'s
    approach model: only the hand may touch the grasped object) calls free. No true shape is seen.
    """
    arm = planner.arm
    T_base = np.asarray(T_world_base, dtype=float)
    T_base_tcp = invert_transforms(T_base) @ np.asarray(grasp, dtype=float)
    environment = (
        planner.environment if planner.approach_environment is None else planner.approach_environment
    )
    ik = DampedLeastSquaresIK(arm, restarts=0)
    q_stowed = stowed_configuration(planner.robot, arm)
    for k in range(starts):
        q0 = q_stowed if k == 0 else rng.uniform(arm.lower, arm.upper)
        q = ik.solve_from(T_base_tcp, q0[None])
        if q is not None and arm.within_limits(q) and not environment.colliding_arm(arm, q, T_base):
            return q
    return None


__all__ = ["ExecutionOracle", "ExecutionSettings", "grasp_order", "own_grasp_configuration"]
