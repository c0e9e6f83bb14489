"""The reaching motion: a collision-free arm path from the stowed configuration to the grasp.

Seed 004 (section 4) reports that grasps from a fixed base pose failed by "hitting the table while
reaching": a placement whose final configuration is free can still be unreachable in motion. This
check, run after the shared verification (:class:`~baseplace.placement.verify.Verifier`), asks for

1. a joint-space path from the start configuration (the robot's stowed one, or a given current
   one) to a pre-grasp configuration, planned with OMPL's RRTConnect after a straight joint-space
   line is tried first (searching with its edges checked at ``search_step``, then keeping only a
   path free at ``point_step``: :meth:`MotionChecker._plan`); every state is checked with the same
   whole-robot collision model as the verification (:meth:`Environment.colliding_arm`), the grasped
   object included for every link;
2. a straight approach from the pre-grasp, at most ``pregrasp_distance`` back along the TCP's
   approach axis, to the grasp: with a grasped object, the walk back from the grasp ends at the
   first state where the whole robot clears the transit model (the object an obstacle of every
   link, the hand's included), so a grasp near the top of the arm's reach is not refused for a
   pre-grasp higher than the hand needs, and goes on past ``pregrasp_distance`` (up to the whole
   open hand behind the grasp's TCP) while the hand is not yet clear of a deep object; the Cartesian line is followed in ``approach_step`` steps (halved where a
   step fails) by IK seeded with the previous step, an IK that uses the arm's redundancy to keep
   off the joint limits rather than stall against them (walked backwards from the verified grasp configuration, so the motion ends in
   exactly that configuration) and the joint line between steps is checked. The pre-grasp distance
   can be derived from the hand (``pregrasp_distance=None``: :func:`hand_reach` +
   :data:`PREGRASP_MARGIN`, the open hand at the pre-grasp wholly behind the plane through the
   grasp's TCP, so clear of any object held between the fingers). Only here may the robot touch the
   grasped object, and only with the hand: the steps are checked against ``approach_environment``,
   an :class:`Environment` built with ``grasped=`` (:mod:`baseplace.world.grasped_object`), whose
   grasped-object voxels every link but the hand must clear. In the transit (part 1) nothing may
   be touched: ``environment`` has the grasped object as an ordinary obstacle group
   (:func:`transit_environment`).

Every joint-space edge (the straight line, the shortcut, OMPL's edges, the joint lines between
approach steps) is checked at states ``joint_resolution`` apart in joint space; with
``point_step`` set (the default, 1 cm), also close
enough that no point of the robot moves more than ``point_step`` between two of them: a joint's change times its lever arm
(:func:`lever_arms`, an upper bound at any configuration), summed over the joints, bounds how far
any point of the links they move travels along the edge.

The result is the joint waypoints of both parts (:class:`ReachingMotion`).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import time
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray, invert_transforms
from baseplace.placement import deadline
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Arm, Robot
from baseplace.world.environment import GRASPED, Environment, HandFilter
from baseplace.world.obstacles import Obstacle
from baseplace.world.sensor_resolution import Group, group_size, object_obstacle
from baseplace.world.state_filter import bisection_order, hull_points

PREGRASP_MARGIN = 0.02
"""How far [m] behind the plane through the grasp's TCP (normal: the approach axis) the open hand's
foremost collision geometry stands at the derived pre-grasp."""

MOTION_FAILURES: dict[str, str] = {
    "approach_ik": "the straight approach leaves the arm's reach or joint limits",
    "approach_collision": "the straight approach touches the scene or the robot itself",
    "pregrasp_collision": "the pre-grasp touches the scene or the robot itself",
    "transit_start_collision": "the start configuration touches the scene or the robot itself",
    "no_rrt_path": "no collision-free path to the pre-grasp within the time limit",
}
"""Why :meth:`MotionChecker.check` found no motion (:attr:`MotionChecker.last_failure`): code, and
what it says, for an error line."""
WALK_SUBDIVISIONS = 2
"""An approach step that fails is cut in halves at most this often (0.01 m steps down to 2.5 mm)."""
WALK_LIMIT_GAIN = 0.01
"""The approach walk's IK moves a joint near a limit off it by up to this fraction of its range per
iteration (:attr:`DampedLeastSquaresIK.limit_gain`). Small: on 300 top-down walks from TIAGo
configurations with the torso at its top, 0.05 and more failed more often than none (the null-space
motion makes joint changes above ``max_joint_step``); the saturation does most of the work."""


def hand_reach(robot: Robot, arm: Arm, geom: object | None = None) -> float:
    """How far [m] the hand's collision geometry reaches ahead of the TCP along the approach axis.

    The hand as :class:`~baseplace.world.environment.HandFilter` takes it (every geometry the arm's
    last joint moves, at the robot's reference configuration: TIAGo's open fingers), measured on
    the URDF's collision model (``geom``, e.g. ``Environment.geom``; default: loaded). 0.245 m for
    TIAGo (the middle fingertip).
    """
    parts = HandFilter(robot, arm.name, geom).parts
    axis = approach_axis(arm)
    reach = [float(np.max((hull_points(g) @ T[:3, :3].T + T[:3, 3]) @ axis)) for g, T in parts]
    return max(reach, default=0.0)


def lever_arms(robot: Robot, arm: Arm, geom: object) -> FloatArray:
    """(n,) per arm joint, how far a point of the links it moves can be from its axis [m], at most.

    An upper bound at every configuration, from the collision model ``geom`` (pinocchio
    GeometryModel, e.g. ``Environment.geom``): the farthest geometry point from each joint's
    origin, plus the distances between successive joint origins down the kinematic tree (a
    prismatic joint's travel added). 1 for a prismatic joint (a point moves as far as the joint).
    Along a straight joint line a -> b no point of the robot moves more than
    ``sum(|b - a| * lever_arms)``.
    """
    model = robot.model
    bound = np.zeros(model.njoints)
    for obj in geom.geometryObjects:  # type: ignore[attr-defined]
        if obj.parentJoint == 0:
            continue  # the world's obstacles
        M = obj.placement
        p = hull_points(obj.geometry) @ np.asarray(M.rotation).T + np.asarray(M.translation)
        bound[obj.parentJoint] = max(bound[obj.parentJoint], float(np.max(np.linalg.norm(p, axis=1))))
    for k in range(model.njoints - 1, 0, -1):  # pinocchio numbers children after their parents
        offset = float(np.linalg.norm(model.jointPlacements[k].translation))
        if _prismatic(model, k):
            i = model.joints[k].idx_q
            offset += float(max(abs(model.lowerPositionLimit[i]), abs(model.upperPositionLimit[i])))
        parent = model.parents[k]
        bound[parent] = max(bound[parent], offset + bound[k])
    ids = [model.getJointId(name) for name in arm.joint_names]
    return np.array([1.0 if _prismatic(model, j) else bound[j] for j in ids])


T = TypeVar("T")
_KEPT: weakref.WeakKeyDictionary[Robot, dict[tuple[str, str, int], object]] = weakref.WeakKeyDictionary()
"""Per robot, what :func:`_kept` computed, by name, arm and number of robot geometries (no reference to the robot)."""


def _kept(robot: Robot, arm: Arm, geom: object, name: str, compute: Callable[[], T]) -> T:
    """``compute()``, once per robot, arm and ``name``: a quantity of the robot's collision geometries only.

    :func:`lever_arms` (3 ms) and :func:`hand_reach` (9 ms) were computed for every
    :class:`MotionChecker`, that is every query. An :class:`Environment`'s scene parts hang on the
    world (joint 0), which both pass over, so every environment of a robot with as many robot
    geometries gives the same.
    """
    n_robot = len([obj for obj in geom.geometryObjects if obj.parentJoint != 0])  # type: ignore[attr-defined]
    kept = _KEPT.setdefault(robot, {})
    key = (name, arm.name, n_robot)
    if key not in kept:
        kept[key] = compute()
    return kept[key]  # type: ignore[return-value]


def _read_only_lever_arms(robot: Robot, arm: Arm, geom: object) -> FloatArray:
    levers = lever_arms(robot, arm, geom)
    levers.flags.writeable = False
    return levers


def _prismatic(model: object, joint: int) -> bool:
    return "P" in model.joints[joint].shortname().removeprefix("JointModel")  # type: ignore[attr-defined]


def stowed_configuration(robot: Robot, arm: Arm) -> FloatArray:
    """The arm's stowed joint values (n,): its spec's (``ArmSpec.stowed``), else the reference values in limits."""
    if arm.stowed is not None:
        return np.array(arm.stowed, dtype=float)
    return np.clip(arm.from_pinocchio(robot.q_reference), arm.lower, arm.upper)


def approach_axis(arm: Arm) -> FloatArray:
    """Unit (3,) axis of the TCP frame along which the hand moves onto a grasp.

    The arm's ``approach_axis`` from the robot file (+x for the built-in robots' TCP frames).
    """
    axis = np.asarray(arm.approach_axis, dtype=float)
    norm = float(np.linalg.norm(axis))
    if axis.shape != (3,) or not math.isfinite(norm) or norm < 1e-9:
        raise InputError(
            f"approach axis of arm {arm.name!r} must be a non-zero 3-vector, got {axis.tolist()}"
        )
    return axis / norm


def transit_environment(
    robot: Robot,
    groups: Mapping[str, Group],
    grasped: Group | None,
    shapes: Sequence[Obstacle] = (),
    clearance: float = 0.0,
    plane_clearance: float | None = None,
) -> Environment | None:
    """The collision model of the transit to the pre-grasp, where nothing may be touched.

    ``groups`` and ``grasped`` are what the verification's :class:`Environment` was built from
    (:func:`~baseplace.world.environment.contact_groups`), its obstacles given by hand
    (``shapes``), its ``clearance`` and ``plane_clearance`` [m]; here the grasped object is one more
    obstacle group, checked against every link, the hand's included: its fitted whole shape where
    one was accepted, else its cells (:func:`~baseplace.world.sensor_resolution.object_obstacle`).
    None when there is no grasped object: the verification's environment already allows no contact.
    """
    if grasped is None or group_size(grasped) == 0:
        return None
    return Environment(
        robot,
        {**groups, GRASPED: object_obstacle(grasped)},
        shapes=shapes,
        clearance=clearance,
        plane_clearance=plane_clearance,
    )


@dataclass(frozen=True)
class MotionSettings:
    """How the reaching motion is checked.

    Attributes:
        pregrasp_distance: the pre-grasp lies at most this far back from the grasp along the
            approach axis [m]; the last segment, the straight approach, is at most this long.
            With a grasped object the walk back ends sooner, at the first state that clears
            the transit model: top-down grasps of bottles on tables (find-rate dev seeds) were
            refused because TIAGo cannot reach 0.15 m above them, while its hand clears the
            bottle about 0.13 m back. The whole open hand
            must be clear of the object there (the transit checks it), since only the approach
            may touch it. 0.15 m leaves TIAGo's open fingertips (0.245 m ahead of its TCP) 5.5 cm
            short of the grasp point: for objects deeper than that towards the hand the walk back
            goes on past this distance, up to the whole open hand behind the TCP
            (:attr:`MotionChecker.hand_clear_distance`), and ends at the first state that clears
            (find-rate dev seed 25030: a side grasp of a 4.4 cm bottle, whose pre-grasps 0.15 m
            back were still in its cells). None: derived from the hand, :func:`hand_reach` +
            :data:`PREGRASP_MARGIN` (0.265 m for TIAGo), the whole open hand behind the grasp's
            TCP; not the default, since TIAGo cannot follow a 0.265 m straight line down onto a
            top-down grasp on a table (find-rate dev seeds: every top-down approach walk failed).
        approach_step: Cartesian step along the approach line [m]; each step is IK + collision
            (0.01 m: below the 25 mm obstacle voxels).
        max_joint_step: largest joint change between two approach steps [rad or m]; a larger
            one means the IK jumped branches, so the arm would not move straight.
        joint_resolution: the joint path is checked at states at most this far apart
            (Euclidean in joint space [rad]).
        point_step: and, when set, at states close enough that no point of the robot moves more
            than this between two of them [m] (bounded by :func:`lever_arms`); a robot kept
            ``clearance`` from the scene at every checked state keeps ``clearance - point_step / 2``
            in between. At 0.05 rad alone a fingertip 1 m from the shoulder moves 5 cm between
            checks: without the bound (None) 5 of 54 motions found on the table-grid dev scenes
            passed through the robot's own scene model between checked states, none with it
            (bench/bench_motion_verdicts.py, ``motion_verdicts_point_dev.json``). Default 0.01:
            it found the same 12 of 28 extra dev find-rate scenes, and became affordable
            with the state pre-filter (:mod:`baseplace.world.state_filter`) and the whole-line
            check (one compiled call per joint line, :meth:`Environment.first_colliding_arm_line`).
            The check's time with it: the median of the 72 table-grid dev checks was 46.9 ms at stop 39
            (``bench/results/motion_verdicts_s14q_final_a.json``, from
            ``python bench/bench_motion_verdicts.py --checkers product``); measure again there.
        search_step: RRTConnect searches with its edges checked at states this far apart
            (``point_step``'s bound, and ``joint_resolution`` scaled alike) [m]; the path it
            returns is then checked at ``point_step``, edge by edge, and only a path that passes
            is kept: otherwise the search runs again at ``point_step``, with what is left of the
            time limit and the check budget. The motion found is checked exactly as without it;
            only the search's own edges, most of them discarded, are checked more coarsely. 0.05
            (5x ``point_step``), chosen on the 72 table-grid dev checks (a scratch comparison of
            0.02, 0.03, 0.05 and 0.08 m: median time 0.98x, 0.80x, 0.81x, 0.80x, the same 62
            found, 1, 1, 5 and 7 searches run again); measured with
            ``bench/bench_motion_verdicts.py --checkers product`` in ``motion_verdicts_s16_search_*.json``.
            None, or at most ``point_step``: the search checks at ``point_step`` (as before).
        time_limit: OMPL planning time for one joint path [s]; no path in it rejects the placement.
        max_checks: also stop planning after this many state validity checks (None: no such
            limit). A budget that does not depend on the machine's load, for experiments on a
            shared machine (wall time counts every other process's share).
        approach_restarts: other pre-grasp IK solutions tried when the approach cannot start
            from the verified grasp configuration. 8 (was 4): on 168 table-grid dev checks
            (seeds 0-2, grasps 1 3 5 7 9 18 22, ``motion_verdicts_s15_wide_dev.json``) both
            false "no motion" (approach_ik) were found by restarts 6 and 7, with 0 touching the
            model or the true scene; 8, 16, 40 recover the same two
            (``approach_restarts_s15_refused_dev.json``). The first four restarts are drawn as
            before, so every motion found with 4 is found with 8. Restarts seeded from the grasp
            configuration recovered both too, but lost two found otherwise. On the four find-rate
            dev scenes refused for the motion none helps: the reference's 40 fail there too
            (``approach_refusals_s15_dev.json``: the pre-grasp out of reach).
        q_start: start arm configuration (n,), e.g. the robot's current one; default: stowed.
    """

    pregrasp_distance: float | None = 0.15
    approach_step: float = 0.01
    max_joint_step: float = 0.2
    joint_resolution: float = 0.05
    point_step: float | None = 0.01
    search_step: float | None = 0.05
    time_limit: float = 1.0
    approach_restarts: int = 8
    q_start: tuple[float, ...] | None = None
    max_checks: int | None = None

    def __post_init__(self) -> None:
        for name in (
            "pregrasp_distance",
            "approach_step",
            "max_joint_step",
            "joint_resolution",
            "point_step",
            "search_step",
            "time_limit",
        ):
            value = getattr(self, name)
            if value is None and name in ("pregrasp_distance", "point_step", "search_step"):
                continue
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"motion setting {name} must be a finite number > 0, got {value}")
        if self.approach_restarts < 0:
            raise InputError(f"approach_restarts must be >= 0, got {self.approach_restarts}")
        if self.max_checks is not None and self.max_checks < 1:
            raise InputError(f"max_checks must be >= 1 or None, got {self.max_checks}")


@dataclass(frozen=True)
class ReachingMotion:
    """A checked reaching motion for one target.

    Attributes:
        path: (P, n) joint waypoints from the start configuration to the pre-grasp; consecutive
            waypoints are joined by straight joint-space lines (checked every ``joint_resolution``).
        approach: (A, n) joint configurations along the straight Cartesian approach, pre-grasp
            first, the grasp configuration last (the verified one, or another that passed the
            same checks when the approach could not start from it).
        planned: True if OMPL planned the path; False if the straight joint-space line was free.
    """

    path: FloatArray
    approach: FloatArray
    planned: bool

    @property
    def waypoints(self) -> FloatArray:
        """(P + A - 1, n) the whole motion, start to grasp."""
        return np.concatenate([self.path, self.approach[1:]])


class MotionChecker:
    """Checks the reaching motion of verified placements (see the module docstring).

    Args:
        robot: the robot.
        arm: the arm that reaches.
        environment: the whole-robot collision model of the transit, where nothing may be touched
            (the grasped object, if any, an obstacle of every link: :func:`transit_environment`).
        approach_environment: the model of the straight approach, where only the hand may touch
            the grasped object (an :class:`Environment` built with ``grasped=``, as the
            verification's); default: ``environment`` (no contact allowed).
        settings: motion settings.
    """

    def __init__(
        self,
        robot: Robot,
        arm: Arm,
        environment: Environment,
        approach_environment: Environment | None = None,
        settings: MotionSettings | None = None,
    ) -> None:
        self.robot = robot
        self.arm = arm
        self.environment = environment
        self.approach_environment = approach_environment
        self.settings = settings or MotionSettings()
        s = self.settings
        q0 = stowed_configuration(robot, arm) if s.q_start is None else np.asarray(s.q_start, dtype=float)
        if q0.shape != (arm.n_joints,) or not np.all(np.isfinite(q0)) or not arm.within_limits(q0):
            raise InputError(
                f"start configuration must be {arm.n_joints} finite joint values within the limits "
                f"of {list(arm.joint_names)}, got {q0.tolist()}"
            )
        self.q_start = q0
        self.axis = approach_axis(arm)
        reach = _kept(
            robot, arm, environment.geom, "hand_reach", lambda: hand_reach(robot, arm, environment.geom)
        )
        self.hand_clear_distance = reach + PREGRASP_MARGIN
        """How far back [m] the whole open hand stands behind the grasp's TCP (:func:`hand_reach`)."""
        self.pregrasp_distance = (
            self.hand_clear_distance if s.pregrasp_distance is None else s.pregrasp_distance
        )
        """The approach's length [m]: the setting, or derived from the hand."""
        self.levers = _kept(
            robot,
            arm,
            environment.geom,
            "levers",
            lambda: _read_only_lever_arms(robot, arm, environment.geom),
        )
        """(n,) the arm joints' lever arms [m] (:func:`lever_arms`)."""
        self.state_checks = 0
        """Collision checks of transit states so far."""
        self._ik = DampedLeastSquaresIK(arm, saturate_limits=True, limit_gain=WALK_LIMIT_GAIN)
        """The approach walk's IK: joints held at a limit hand their share to the others, and
        joints near a limit move off it in the null space (:class:`DampedLeastSquaresIK`)."""
        self._ik_any = DampedLeastSquaresIK(
            arm, restarts=20, saturate_limits=True, limit_gain=WALK_LIMIT_GAIN
        )
        self.elapsed_s = 0.0
        """Time spent in :meth:`check` so far [s]."""
        self.last_contacts: list[tuple[str, str]] = []
        """Why the last :meth:`check` failed, when a collision blocked it: (robot link, what it
        touched, tagged "during the approach" or "during the transit"); empty otherwise (IK, or
        no path found)."""
        self.last_failure: str | None = None
        """Why the last :meth:`check` found no motion, one of :data:`MOTION_FAILURES`; None after a motion."""
        self._blocked: tuple[FloatArray, str] | None = None
        self._search_factor = 1.0
        """``search_step / point_step`` while RRTConnect searches, else 1 (:meth:`edge_states`)."""

    def _explain(self, T_world_base: FloatArray) -> None:
        """Fill :attr:`last_contacts` from the configuration that blocked the last check, if any."""
        if self._blocked is None:
            return
        q, stage = self._blocked
        environment = self.environment
        if stage == "approach" and self.approach_environment is not None:
            environment = self.approach_environment
        self.last_contacts = _contacts_of(environment, self.arm, q, T_world_base, stage)

    def _free(self, q: FloatArray, T_world_base: FloatArray) -> bool:
        self.state_checks += 1
        return not self.environment.colliding_arm(self.arm, q, T_world_base)

    @property
    def _approach_model(self) -> Environment:
        return self.environment if self.approach_environment is None else self.approach_environment

    def _approach_free(self, q: FloatArray, T_world_base: FloatArray) -> bool:
        if self.approach_environment is None:
            return self._free(q, T_world_base)
        return not self.approach_environment.colliding_arm(self.arm, q, T_world_base)

    def approach(
        self, q_grasp: ArrayLike, T_base_tcp: FloatArray, T_world_base: FloatArray, seed: int = 0
    ) -> FloatArray | None:
        """(A, n) configurations along the straight approach, pre-grasp first, or None.

        First walks from the verified grasp configuration back along the approach axis, IK seeded
        with the last step, so that the motion ends in that configuration. When that fails (the
        configuration's branch cannot follow the line within the limits), up to ``approach_restarts``
        other IK solutions of the pre-grasp are walked forward to the grasp instead; the motion
        then ends in another grasp configuration, checked the same way. A walk fails on an IK
        failure, a joint jump above ``max_joint_step`` or a collision.
        """
        s, distance = self.settings, self.pregrasp_distance
        n_steps = max(1, math.ceil(distance / s.approach_step))
        step = distance / n_steps
        # with a grasped object the walk back goes on past the pre-grasp distance while the hand is
        # not yet clear of it, up to the whole open hand behind the grasp (find-rate dev seed 25030:
        # a side grasp of a 4.4 cm bottle, 72 of 100 candidates' pre-grasps 0.15 m back still in it)
        far = max(distance, self.hand_clear_distance) if self.approach_environment is not None else distance
        n_line = max(n_steps, math.ceil(far / step - 1e-9))
        direction = T_base_tcp[:3, :3] @ self.axis
        line = []
        for k in range(n_line + 1):  # grasp first, pre-grasp (at n_steps) and beyond last
            T = T_base_tcp.copy()
            T[:3, 3] -= min(k * step, far) * direction
            line.append(T)
        q = np.asarray(q_grasp, dtype=float)
        if not self._approach_free(q, T_world_base):
            self._blocked = (q, "approach")
        else:
            back = self._walk(q, line, T_world_base, stop=self._clear_of_object)
            # past the pre-grasp distance only to a state clear of the object: else the restarts
            if back is not None and (n_line == n_steps or self._clear_of_object(back[-1], T_world_base)):
                return back[::-1]
        rng = np.random.default_rng(seed)
        for _ in range(s.approach_restarts):
            deadline.check()
            q_pre = self._ik_any.solve(line[n_steps], rng, q_seed=self.arm.sample(rng, 1)[0])
            if q_pre is None or not self._approach_free(q_pre, T_world_base):
                continue
            forward = self._walk(q_pre, line[n_steps::-1], T_world_base)
            if forward is not None:
                return forward
        return None

    def _clear_of_object(self, q: FloatArray, T_world_base: FloatArray) -> bool:
        """Whether a walk back from the grasp may end at ``q`` (n,), the pre-grasp.

        It may where the whole robot, the hand included, clears the grasped object and everything
        else, as the transit demands. Never without a grasped object (``approach_environment``
        None): the approach then has its full ``pregrasp_distance``.
        """
        if self.approach_environment is None:
            return False
        return not self.environment.colliding_arm(self.arm, q, T_world_base)

    def _walk(
        self,
        q0: FloatArray,
        poses: list[FloatArray],
        T_world_base: FloatArray,
        stop: Callable[[FloatArray, FloatArray], bool] | None = None,
    ) -> FloatArray | None:
        """(m, n) configurations from ``q0`` (at the TCP pose ``poses[0]``) through the others, or None.

        The (4, 4) poses lie on a straight line with one orientation (the approach), so a step that fails
        (no IK solution near the last configuration, or a joint change above ``max_joint_step``)
        is cut in halves, down to :data:`WALK_SUBDIVISIONS` halvings; the states of a cut step are
        walked in turn (m >= len(poses) + 1). The IK keeps joints off their limits through the
        arm's redundancy (:attr:`_ik`), which plain clamped DLS runs into along a line. With
        ``stop``, the walk ends at the first state after ``q0`` for which ``stop(q, T_world_base)``
        holds, that state included.
        """
        # seeds: the last step, then small perturbations of it
        jitter = np.random.default_rng(0).normal(0.0, 0.05, size=(4, self.arm.n_joints))
        q, steps = q0, [q0]
        for T_last, T in itertools.pairwise(poses):
            p_from = T_last[:3, 3]
            todo = [(T, 0)]  # the targets still to reach, nearest first, with their halvings
            while todo:
                T_next, depth = todo.pop()
                seeds = np.clip(np.vstack([q, q + jitter]), self.arm.lower, self.arm.upper)
                q_next = self._ik.solve_from(T_next, seeds)
                if q_next is None or np.max(np.abs(q_next - q)) > self.settings.max_joint_step:
                    if depth >= WALK_SUBDIVISIONS:
                        return None
                    T_mid = T_next.copy()
                    T_mid[:3, 3] = 0.5 * (p_from + T_next[:3, 3])
                    todo += [(T_next, depth + 1), (T_mid, depth + 1)]
                    continue
                blocked = self._blocking(q, q_next, T_world_base, self._approach_model)
                if blocked is not None:
                    self._blocked = (blocked, "approach")
                    return None
                q, p_from = q_next, T_next[:3, 3]
                steps.append(q)
                if stop is not None and stop(q, T_world_base):
                    return np.array(steps)
        return np.array(steps)

    def edge_states(self, a: FloatArray, b: FloatArray) -> int:
        """Steps a straight joint line a -> b (n,) is cut into for checking (>= 1).

        Enough that consecutive states are at most ``joint_resolution`` apart in joint space and
        no point of the robot moves more than ``point_step`` between them (:func:`lever_arms`);
        both scaled to ``search_step`` while RRTConnect searches (:meth:`_plan`).
        """
        s, d, k = self.settings, np.abs(b - a), self._search_factor
        by_joints = float(np.linalg.norm(d)) / (s.joint_resolution * k)
        by_points = 0.0 if s.point_step is None else float(d @ self.levers) / (s.point_step * k)
        return max(1, math.ceil(by_joints), math.ceil(by_points))

    def _blocking(
        self, a: FloatArray, b: FloatArray, T_world_base: FloatArray, environment: Environment
    ) -> FloatArray | None:
        """The first state of the line a -> b (n,) that touches ``environment``, or None; a itself is not checked.

        The states (:meth:`edge_states`) are the same whatever the order; they are taken end
        first, then in bisection order (midpoint, quarter points, ...), the whole line in one
        compiled call (:meth:`Environment.first_colliding_arm_line`), which asks a pair at a state
        only where its gaps at the states around do not already clear it (``lever_arms`` bound
        the robot's move along the line): the verdict, and the state returned, are those of
        checking every state. Transit states count towards ``max_checks`` as they are asked.
        """
        n = self.edge_states(a, b)
        k, asked = environment.first_colliding_arm_line(
            self.arm, a, b, n, float(np.abs(b - a) @ self.levers), T_world_base
        )
        if environment is self.environment:
            self.state_checks += asked
        return None if k < 0 else a + (b - a) * (k / n)

    def _line_free(self, a: FloatArray, b: FloatArray, T_world_base: FloatArray) -> bool:
        """Whether the straight joint line a -> b (n,) of the transit is free (:meth:`_blocking`)."""
        return self._blocking(a, b, T_world_base, self.environment) is None

    def _shortcut(self, path: FloatArray, T_world_base: FloatArray) -> FloatArray:
        """The path (P, n) with waypoints skipped greedily.

        From each kept waypoint to the farthest later one joined to it by a free straight line
        (deterministic: no random shortcuts, no time budget). Consecutive waypoints of ``path``
        must already be joined by free lines.
        """
        out, i, last = [path[0]], 0, len(path) - 1
        while i < last:
            j = last
            while j > i + 1 and not self._line_free(path[i], path[j], T_world_base):
                j -= 1
            out.append(path[j])
            i = j
        return np.array(out)

    def joint_path(
        self, q_goal: FloatArray, T_world_base: FloatArray, seed: int
    ) -> tuple[FloatArray | None, bool]:
        """Collision-free joint waypoints (P, n) from the start configuration to ``q_goal``, or None.

        Also returns whether OMPL planned them (False: the straight joint-space line was free).
        """
        q0 = self.q_start
        for q in (q0, q_goal):
            if not self._free(q, T_world_base):
                self._blocked = (q, "transit")
                return None, False
        if self._line_free(q0, q_goal, T_world_base):
            return np.array([q0, q_goal]), False
        return self._plan(q0, q_goal, T_world_base, seed), True

    def _plan(
        self, q0: FloatArray, q_goal: FloatArray, T_world_base: FloatArray, seed: int
    ) -> FloatArray | None:
        """RRTConnect's path (P, n) from q0 to q_goal, every edge free at ``point_step``, or None.

        With ``search_step`` above ``point_step``, RRTConnect first searches with its edges
        checked at ``search_step`` (:meth:`edge_states`); its path is kept only when each of its
        edges is free at ``point_step``, else the search runs again at ``point_step``. The time
        limit and the check budget hold for both together.
        """
        s = self.settings
        t_end = time.perf_counter() + s.time_limit
        stop_at = None if s.max_checks is None else self.state_checks + s.max_checks
        factor = 1.0
        if s.point_step is not None and s.search_step is not None:
            factor = max(1.0, s.search_step / s.point_step)
        if factor > 1.0:
            self._search_factor = factor
            try:
                path = self._rrt(q0, q_goal, T_world_base, seed, t_end, stop_at)
            finally:
                self._search_factor = 1.0
            if path is not None and all(
                self._line_free(a, b, T_world_base) for a, b in itertools.pairwise(path)
            ):
                return path
            if time.perf_counter() >= t_end or (stop_at is not None and self.state_checks >= stop_at):
                return None
        return self._rrt(q0, q_goal, T_world_base, seed, t_end, stop_at)

    def _rrt(
        self,
        q0: FloatArray,
        q_goal: FloatArray,
        T_world_base: FloatArray,
        seed: int,
        t_end: float,
        stop_at: int | None,
    ) -> FloatArray | None:
        """One RRTConnect search until the clock reads ``t_end`` or ``stop_at`` transit checks (None: no budget).

        ``q0`` and ``q_goal`` must be free (:meth:`joint_path` checks them): with the checker's own
        edge states the edge validator checks every other state, and the planner's state validity
        checker nothing.
        """
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou

        arm, n = self.arm, self.arm.n_joints
        ou.setLogLevel(ou.LOG_NONE)
        ou.RNG.setSeed(seed + 1)  # OMPL takes seeds > 0
        try:
            space = ob.RealVectorStateSpace(n)
            bounds = ob.RealVectorBounds(n)
            for i in range(n):
                bounds.setLow(i, float(arm.lower[i]))
                bounds.setHigh(i, float(arm.upper[i]))
            space.setBounds(bounds)
            setup = og.SimpleSetup(space)

            def valid(state: object) -> bool:
                return self._free(np.array([state[i] for i in range(n)]), T_world_base)  # type: ignore[index]

            def known(state: object) -> bool:  # q0 and q_goal, and what the edge validator checks
                return True

            own_edges = self.settings.point_step is not None
            setup.setStateValidityChecker(known if own_edges else valid)
            info = setup.getSpaceInformation()
            validator = None  # referenced here while OMPL calls it
            if not own_edges:  # OMPL's own edge checks, at the joint resolution
                info.setStateValidityCheckingResolution(
                    self.settings.joint_resolution / space.getMaximumExtent()
                )
            else:  # our edge states (:meth:`edge_states`), not OMPL's resolution
                validator = _edge_validator(info, self, T_world_base, (q0, q_goal))
                info.setMotionValidator(validator)
            a, b = space.allocState(), space.allocState()
            for i in range(n):
                a[i], b[i] = float(q0[i]), float(q_goal[i])
            setup.setStartAndGoalStates(a, b, 1e-6)
            setup.setPlanner(og.RRTConnect(info))
            seconds = max(t_end - time.perf_counter(), 0.0)
            if stop_at is None and not deadline.active():
                solved = setup.solve(seconds)
            else:  # a check budget, or a request's time limit: planning stops when either is spent
                solved = setup.solve(
                    ob.plannerOrTerminationCondition(
                        ob.timedPlannerTerminationCondition(seconds),
                        ob.PlannerTerminationCondition(
                            lambda: (
                                (stop_at is not None and self.state_checks >= stop_at) or deadline.expired()
                            )
                        ),
                    )
                )
                deadline.check()
            if not solved or not setup.haveExactSolutionPath():
                return None
            states = setup.getSolutionPath().getStates()
            path = np.array([[s[i] for i in range(n)] for s in states])
        finally:
            setup = info = validator = None  # drop the OMPL objects (and the callbacks they hold) now
        path[0], path[-1] = q0, q_goal
        # RRTConnect's tree vertices, joined by lines checked by the edge validator;
        # shortened here instead of by OMPL's random shortcutting, which checked ~5x more states
        # than planning did (bench/bench_robustness.py, motion timing)
        return self._shortcut(path, T_world_base)

    def check(
        self, q_grasp: ArrayLike, T_world_base: ArrayLike, T_world_tcp: ArrayLike, seed: int = 0
    ) -> ReachingMotion | None:
        """The reaching motion to a verified grasp configuration, or None if there is none.

        Args:
            q_grasp: (n,) the verified arm configuration at the grasp.
            T_world_base: (4, 4) base pose.
            T_world_tcp: (4, 4) the grasp (TCP target) in the world.
            seed: OMPL's random seed.
        """
        deadline.check()  # one planning call per target: a request past its time limit stops before it
        t0 = time.perf_counter()
        self.last_contacts, self.last_failure, self._blocked = [], None, None
        try:
            T_base = np.asarray(T_world_base, dtype=float)
            T_base_tcp = invert_transforms(T_base) @ np.asarray(T_world_tcp, dtype=float)
            approach = self.approach(q_grasp, T_base_tcp, T_base, seed)
            if approach is None:
                self.last_failure = "approach_ik" if self._blocked is None else "approach_collision"
                self._explain(T_base)
                return None
            self._blocked = None  # a walk that touched before a restart's walk went through
            path, planned = self.joint_path(approach[0], T_base, seed)
            if path is None:
                if self._blocked is None:
                    self.last_failure = "no_rrt_path"
                else:  # an end of the transit: the start, or the pre-grasp (the approach's first state)
                    start = np.array_equal(self._blocked[0], self.q_start)
                    self.last_failure = "transit_start_collision" if start else "pregrasp_collision"
                self._explain(T_base)
                return None
            return ReachingMotion(path, approach, planned)
        finally:
            self.elapsed_s += time.perf_counter() - t0


@functools.cache
def _edge_validator_class() -> type:
    from ompl import base as ob

    class EdgeValidator(ob.MotionValidator):
        """OMPL's edges checked at the checker's edge states (:meth:`MotionChecker.edge_states`), their ends included.

        OMPL's motion validators may take an edge's first state as valid; RRTConnect asks the state
        validity checker for it first where it is new (an edge of the goal tree runs from the new
        state to the tree). Here every state an edge validated is remembered (bytes of its joint
        values; the start and goal given), and an edge whose first state is new is checked from its
        other end: the same states (a line's states are those of its reverse), the new one among them,
        in one compiled call, and the tree's end, already free, not again. So the planner's state
        validity checker need not check anything (:meth:`MotionChecker._rrt`).
        """

        def __init__(self, info: object, checker: MotionChecker, T_world_base: FloatArray,
                     free: tuple[FloatArray, ...]) -> None:  # fmt: skip
            super().__init__(info)
            self.checker, self.T_world_base = checker, T_world_base
            self.n = checker.arm.n_joints
            self.free = {np.asarray(q, dtype=float).tobytes() for q in free}

        def checkMotion(self, s1: object, s2: object, *last_valid: object) -> bool:
            if last_valid:
                raise NotImplementedError("RRTConnect asks only whether a motion is valid")
            a = np.array([s1[i] for i in range(self.n)])  # type: ignore[index]
            b = np.array([s2[i] for i in range(self.n)])  # type: ignore[index]
            key_a, key_b = a.tobytes(), b.tobytes()
            checker, T = self.checker, self.T_world_base
            if key_a in self.free:
                ok = checker._line_free(a, b, T)
            elif key_b in self.free:
                ok = checker._line_free(b, a, T)
            else:
                ok = checker._free(a, T) and checker._line_free(a, b, T)
            if ok:
                self.free.update((key_a, key_b))
            return ok

    return EdgeValidator


def _edge_validator(info: object, checker: MotionChecker, T_world_base: FloatArray,
                    free: tuple[FloatArray, ...]) -> object:  # fmt: skip
    return _edge_validator_class()(info, checker, T_world_base, free)


def _contacts_of(environment: Environment, arm: Arm, q: FloatArray, T_world_base: FloatArray, stage: str
                 ) -> list[tuple[str, str]]:  # fmt: skip
    pairs = dict.fromkeys(environment.contacts_arm(arm, q, T_world_base))  # one per pair, in order
    return [(link, f"{what} during the {stage}") for link, what in pairs]


def with_start(settings: MotionSettings, q_start: ArrayLike | None) -> MotionSettings:
    """``settings`` with another start configuration (None: stowed)."""
    q = None if q_start is None else tuple(float(v) for v in np.asarray(q_start, dtype=float).ravel())
    return dataclasses.replace(settings, q_start=q)


__all__ = [
    "MOTION_FAILURES",
    "PREGRASP_MARGIN",
    "MotionChecker",
    "MotionSettings",
    "ReachingMotion",
    "approach_axis",
    "bisection_order",
    "hand_reach",
    "lever_arms",
    "stowed_configuration",
    "transit_environment",
    "with_start",
]
