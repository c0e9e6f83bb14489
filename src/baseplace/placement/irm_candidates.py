"""IRM-verified base-placement candidates: seed 004's stated future work, on its interface.

Base poses around the object are ranked by a reachability map (the inverse reachability of a set
of grasp poses) and verified, best first, with the shared IK + collision
:class:`~baseplace.placement.verify.Verifier`; they come back as the same
:class:`~baseplace.placement.verified.Placement` type as the radial method's (and every other
method's), so both feed :func:`~baseplace.placement.candidates.pickup` and can be compared.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import (
    BasePose,
    FloatArray,
    invert_transforms,
    pose_from_xyz_rpy,
    rotation_taking,
)
from baseplace.placement.candidates import RadialCandidate, _object, occupancy_risk
from baseplace.placement.motion import MotionChecker
from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings, perturbed
from baseplace.placement.verified import Candidate, ObjectApproach, Placement
from baseplace.placement.verify import Verifier
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.terrain.polygons import footprint_outline
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment, HandFilter
from baseplace.world.occupancy import OccupancyGrid


def grasp_poses(
    p_o: ArrayLike,
    n: int = 8,
    top_down: bool = False,
    standoff: float = 0.0,
    top_offset: float = 0.0,
    approach_axis: ArrayLike = (1.0, 0.0, 0.0),
) -> FloatArray:
    """World TCP poses (K, 4, 4) grasping an object at ``p_o`` (3,) [m] from ``n`` directions.

    Side grasps put the TCP's approach axis (``approach_axis``, (3,) in the TCP frame: the arm's
    ``Arm.approach_axis``; x for TIAGo's ``arm_tool_link`` and PR2's ``*_gripper_tool_frame``)
    horizontal, pointing at the object from yaw ``k 2 pi / n``; with
    ``top_down`` another ``n`` poses point it straight down, rotated by the same yaws (K = 2 n),
    at ``top_offset`` [m] above ``p_o``: a tall object is taken from above near its top (half its
    height less a little), or the open fingers reach down into its support.
    The TCP stands ``standoff`` [m] back from the object along the approach axis: TIAGo's TCP is
    the wrist flange, and its hand grasps 0.15 m ahead of it (``hand_grasping_frame``).
    """
    p = _object(p_o, "a grasp pose")
    if n < 1:
        raise InputError(f"need n >= 1 grasp directions, got {n}")
    if not (math.isfinite(standoff) and standoff >= 0):
        raise InputError(f"standoff must be a finite distance >= 0 m, got {standoff}")
    if not math.isfinite(top_offset):
        raise InputError(f"top_offset must be a finite height [m], got {top_offset}")
    yaws = np.arange(n) * (2.0 * math.pi / n)
    pitches = [0.0, math.pi / 2] if top_down else [0.0]
    rows = [
        [p[0], p[1], p[2] + (top_offset if pitch else 0.0), 0.0, pitch, yaw]
        for pitch in pitches
        for yaw in yaws
    ]
    T = pose_from_xyz_rpy(np.array(rows))
    T[:, :3, 3] -= standoff * T[:, :3, 0]
    T[:, :3, :3] = T[:, :3, :3] @ rotation_taking(approach_axis, (1.0, 0.0, 0.0))  # approach onto that x
    return T


def hand_feasible(
    robot: Robot, arm_name: str | None, grasps: FloatArray, environment: Environment
) -> NDArray[np.bool_]:
    """(K,) True for the grasps whose hand alone is clear of the environment's obstacles.

    A grasp whose hand touches an obstacle fails the whole-robot check from every base pose
    (:class:`~baseplace.world.environment.HandFilter`); skipping it saves a verifier call per
    base pose and loses nothing. The hand is checked as the environment checks it: with each
    obstacle's security margin (the clearance from the parts at sensor resolution), so a hand
    the verifier would find touching a part is not "clear" here at zero margin.
    """
    obstacles = environment.obstacle_geometries  # the voxels and the obstacles given by hand
    if not obstacles:
        return np.ones(len(grasps), dtype=bool)
    hand = HandFilter(robot, arm_name, environment.geom)  # the environment's own meshes, not a second load
    margins = environment.obstacle_margins
    return np.array([hand.clear(g, obstacles, margins) for g in grasps], dtype=bool)


@dataclass(frozen=True)
class IrmSettings:
    """How :func:`irm_candidates` searches (the seed's future work: reachability maps).

    Attributes:
        resolution: spacing of the base positions around the object [m] (the map's voxel size).
        n_yaw: base headings per position, spaced by ``2 pi / n_yaw``.
        count: verified candidates to return at most (M).
        max_checks: verifier calls at most (IK + collision, ~10 ms each when IK fails).
        separation: returned candidates are at least this far apart [m], so that one blocked
            approach does not take all of them.
        unknown_is_risk: unknown grid cells count as occupied (as :class:`RadialSettings`).
        reach_sigmas: the reach margin against the navigation error, in standard deviations of
            ``error`` (:func:`reach_margin`): a (pose, grasp) pair is verified only when the arm
            still reaches the grasp, clear of the obstacles, from the pose moved that margin
            straight away from it (:func:`keeps_reach_margin`); pairs
            without the margin are verified only when no pair keeps it. With a reaching-motion
            check, the stowed arm must also be clear at the poses this far from it
            (:func:`stowed_clear_under_error`). 0: neither. 1 was chosen over 2 on the
            table-grid execution dev seeds 0-2 (docs/placement.md).
        error: the base's navigation error the margin is taken from (default
            :class:`~baseplace.placement.robustness.BaseErrorModel`: 3 cm, 2 deg; a job's search
            takes its robustness score's own error model, :func:`irm_settings_for`).
    """

    resolution: float = 0.05
    n_yaw: int = 36
    count: int = 8
    max_checks: int = 300
    separation: float = 0.2
    unknown_is_risk: bool = True
    reach_sigmas: float = 1.0
    error: BaseErrorModel = field(default_factory=BaseErrorModel)

    def __post_init__(self) -> None:
        if not (self.resolution > 0 and self.n_yaw >= 1 and self.count >= 1 and self.max_checks >= 1):
            raise InputError("need resolution > 0 m and n_yaw, count, max_checks >= 1")
        if not self.separation >= 0:
            raise InputError(f"separation must be >= 0 m, got {self.separation}")
        if not (math.isfinite(self.reach_sigmas) and self.reach_sigmas >= 0):
            raise InputError(f"reach_sigmas must be a finite number >= 0, got {self.reach_sigmas}")


def irm_settings_for(robustness: RobustnessSettings) -> IrmSettings:
    """The search's default settings with the reach margin taken from a job's own base error model."""
    return IrmSettings(error=robustness.error)


def reach_margin(lever: ArrayLike, error: BaseErrorModel, sigmas: float) -> FloatArray:
    """How much further [m] than its nominal pose the base may stop from a grasp, (N,) per lever (N,) [m].

    ``sigmas`` standard deviations of the grasp's displacement relative to the base under
    ``error``: the offset along the base -> grasp line has ``sigma_xy``; a heading error rotates the
    arm about the base's z axis and moves a TCP ``lever`` [m] away (horizontally) by ``lever``
    times the heading error, counted here as if it were along that line too (the arm's reach
    boundary is not a circle about the base origin). The two are independent:
    ``sigmas * hypot(sigma_xy, lever * sigma_yaw)``; 1 sigma at TIAGo's 0.8 m: 4.1 cm.
    """
    L = np.asarray(lever, dtype=float)
    return sigmas * np.hypot(error.sigma_xy, L * error.sigma_yaw)


def reach_margin_json(settings: IrmSettings) -> dict[str, object]:
    """How the search's reach margin is derived, for a report (the ``candidates`` JSON's ``settings``)."""
    e = settings.error
    return {"sigmas": settings.reach_sigmas, "sigma_xy": e.sigma_xy, "sigma_yaw": round(e.sigma_yaw, 6),
            "at_lever_0.8_m": round(float(reach_margin(0.8, e, settings.reach_sigmas)), 4),
            "rule": "sigmas * hypot(sigma_xy, lever * sigma_yaw) [m], lever: base -> TCP distance; a pose is "
                    "kept when the grasp is still reached, collision-free, from it moved that far away (if any pose is)"}  # fmt: skip


def stowed_clear_under_error(
    motion: MotionChecker,
    T_world_base: FloatArray,
    T_world_tcp: FloatArray,
    error: BaseErrorModel,
    sigmas: float,
) -> bool:
    """Whether the motion's start configuration is clear of its transit model at the base poses a navigation error reaches.

    Six poses, ``sigmas`` standard deviations of ``error`` from the base pose (4, 4): moved
    ``sigmas * sigma_xy`` towards the TCP target (4, 4) or to either side of that line, each turned
    by ``+- sigmas * sigma_yaw``. The reaching motion starts from the stowed arm wherever the base
    stopped; a pose where it is refused there leaves the robot without a motion.
    """
    toward = T_world_tcp[:2, 3] - T_world_base[:2, 3]
    length = float(np.hypot(toward[0], toward[1]))
    toward = toward / length if length > 1e-9 else np.array([1.0, 0.0])
    side = np.array([-toward[1], toward[0]])
    step, turn = sigmas * error.sigma_xy, sigmas * error.sigma_yaw
    offsets = [(*(step * d), a) for d in (toward, side, -side) for a in (turn, -turn)]
    return not any(
        motion.environment.colliding_arm(motion.arm, motion.q_start, T)
        for T in perturbed(T_world_base, np.array(offsets))
    )


def keeps_reach_margin(
    ik: DampedLeastSquaresIK,
    environment: Environment,
    T_world_base: FloatArray,
    T_world_tcp: FloatArray,
    margin: float,
    rng: np.random.Generator,
) -> bool:
    """Whether ``ik`` reaches the TCP target (4, 4) from the base pose (4, 4) moved ``margin`` [m] away from it.

    The move is horizontal, along the line from the target's position to the base's, heading kept:
    the direction in which a navigation error takes the grasp out of reach first. The arm there
    must be clear of ``environment`` too (a reach that only a colliding configuration gives is
    none). A base right under its target has no such direction: True.
    """
    away = T_world_base[:2, 3] - T_world_tcp[:2, 3]
    length = float(np.hypot(away[0], away[1]))
    if length < 1e-9:
        return True
    T = T_world_base.copy()
    T[:2, 3] += margin * away / length
    q = ik.solve(invert_transforms(T) @ T_world_tcp, rng)
    return q is not None and not environment.colliding_arm(ik.arm, q, T)


def irm_candidates(
    robot: Robot,
    rmap: ReachabilityMap,
    p_o: ArrayLike,
    grasps: ArrayLike,
    environment: Environment | None = None,
    occupancy: OccupancyGrid | None = None,
    settings: IrmSettings | None = None,
    rng: np.random.Generator | None = None,
    motion: MotionChecker | None = None,
) -> list[Placement]:
    """Base placements ranked by inverse reachability and verified by IK + collision.

    Base poses on an xy grid (``resolution``) within the map's horizontal reach of the object,
    outside the footprint radius, times ``n_yaw`` headings, are scored by the best reachability
    of any grasp (``rmap.inverse``) whose hand alone is clear of the obstacles
    (:func:`hand_feasible`); poses whose footprint disc risks collision on the grid
    (:func:`occupancy_risk`) are dropped. The (pose, grasp) pairs are checked with the shared
    :class:`~baseplace.placement.verify.Verifier` positions before headings (:func:`search_order`):
    each position's best pair first, ranked by its value, then each position's second best, until
    ``count`` poses passed or ``max_checks`` checks were spent. With ``reach_sigmas`` > 0 a pair
    is verified only when it keeps the reach margin (:func:`keeps_reach_margin`,
    :func:`reach_margin` of the base -> TCP distance): a navigation error of that size still
    leaves the grasp in reach. The pairs without the margin (at most ``max_checks`` of them are
    looked at, an IK call each) are verified in the same order only when no pair with the margin
    passed: a grasp reachable only from the nominal pose is still better than none.

    Args:
        robot: the robot.
        rmap: its reachability map (of the arm used).
        p_o: (3,) object position in the map frame [m].
        grasps: (K, 4, 4) alternative world TCP poses, e.g. :func:`grasp_poses`; one must be reached.
        environment: obstacle collision checker; remove the object's own voxels first (the closing
            hand surrounds it). Default: self-collision only.
        occupancy: occupancy grid for the footprint test, or None.
        settings: search settings.
        rng: randomness for IK restarts (default: seed 0).
        motion: also check the reaching motion (:mod:`baseplace.placement.motion`), or None.

    Returns:
        Verified placements, best reachability first (possibly empty); each carries its grasp
        index (``approach``), target and the joint values the verifier found.
    """
    s = settings or IrmSettings()
    rng = rng if rng is not None else np.random.default_rng(0)
    p = _object(p_o, "a grasp search")
    G = np.asarray(grasps, dtype=float).reshape(-1, 4, 4)
    if len(G) == 0:
        raise InputError("need at least one grasp pose (K, 4, 4), got none")
    if not np.all(np.isfinite(G)):
        raise InputError("grasp poses contain NaN or infinity")
    radius = robot.spec.footprint_bounding_radius
    reach = rmap.horizontal_reach
    axis = np.arange(-math.floor(reach / s.resolution), math.floor(reach / s.resolution) + 1) * s.resolution
    X, Y = np.meshgrid(axis, axis, indexing="ij")
    offsets = np.stack([X.ravel(), Y.ravel()], axis=1)
    dist = np.hypot(offsets[:, 0], offsets[:, 1])
    xy = p[:2] + offsets[(dist > radius) & (dist <= reach)]
    if occupancy is not None:
        xy = xy[~occupancy_risk(occupancy, xy, radius, s.unknown_is_risk)]
    yaws = np.arange(s.n_yaw) * (2.0 * math.pi / s.n_yaw)
    yaws = (yaws + math.pi) % (2.0 * math.pi) - math.pi
    poses = np.column_stack([np.repeat(xy, s.n_yaw, axis=0), np.tile(yaws, len(xy))])
    T = BasePose.batch_matrix(poses)
    env = environment
    if env is None:  # self-collision only
        env = Environment(robot, VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64)))
    values = np.stack([rmap.inverse(g, T) for g in G]) if len(T) else np.zeros((len(G), 0))
    values[~hand_feasible(robot, rmap.info.arm, G, env)] = 0.0

    arm = robot.arm(rmap.info.arm)
    ik = DampedLeastSquaresIK(arm)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    verifiers = [Verifier(arm, ik, env, g[None], {}, outline, motion=motion) for g in G]
    found: list[Placement] = []
    placed: set[int] = set()
    checks = 0
    short: list[NDArray[np.int64]] = []  # the pairs without the reach margin, in search order
    margin_rng = rng.spawn(1)[0]  # the margin's IK restarts leave the verification's draws as they were

    def verify(pairs: Sequence[NDArray[np.int64]] | NDArray[np.int64], margin: bool) -> None:
        nonlocal checks
        for k, i in pairs:
            if checks >= s.max_checks or len(found) >= s.count:
                return
            if i in placed or any(math.dist(poses[i, :2], c.xy) < s.separation for c in found):
                continue
            if margin:
                lever = float(np.hypot(*(G[k, :2, 3] - poses[i, :2])))
                needed = float(reach_margin(lever, s.error, s.reach_sigmas))
                kept = keeps_reach_margin(ik, env, T[i], G[k], needed, margin_rng)
                if kept and motion is not None:
                    kept = stowed_clear_under_error(motion, T[i], G[k], s.error, s.reach_sigmas)
                if not kept:
                    if len(short) >= s.max_checks:
                        return
                    short.append(np.array([k, i]))
                    continue
            checks += 1
            placement = verifiers[k].check(Candidate(T[i], -1, float(values[k, i])), rng)
            if placement is not None:
                placed.add(int(i))
                approach = ObjectApproach("irm", float(math.dist(poses[i, :2], p[:2])), -1, int(k))
                found.append(dataclasses.replace(placement, approach=approach))

    verify(search_order(values, s.n_yaw), margin=s.reach_sigmas > 0)
    if not found:  # no pose keeps the margin: those that reach the grasp from where they stand
        verify(short, margin=False)
    found.sort(key=lambda c: -c.reachability)
    return found


def search_order(values: NDArray[np.floating], n_yaw: int) -> NDArray[np.int64]:
    """The (grasp, pose) checks of the search, (C, 2), positions before headings.

    ``values`` (K, N): each grasp's map value at each pose, poses grouped by position (``n_yaw``
    headings each). Only pairs with a value > 0 are checked. Each position's best (heading, grasp)
    pair comes first, positions by that pair's value; then each position's second best pair, and so
    on: a position blocked at every heading (its footprint, an obstacle beside it, an arm that
    cannot move there) costs one check per round, not the whole budget, and the positions the map
    values lower are reached.
    """
    k, i = np.nonzero(values > 0)
    r = values[k, i]
    by_rank = np.lexsort((i, k, -r))  # ties: a stable, deterministic order
    k, i, r = k[by_rank], i[by_rank], r[by_rank]
    position = i // n_yaw
    first = np.lexsort((np.arange(len(position)), position))  # by position, best rank first within it
    turn = np.empty(len(position), dtype=np.int64)
    starts = np.flatnonzero(np.r_[True, position[first][1:] != position[first][:-1]])
    counts = np.diff(np.r_[starts, len(first)])
    turn[first] = np.arange(len(first)) - np.repeat(starts, counts)
    order = np.lexsort((np.arange(len(turn)), turn))  # round by round, by rank within a round
    return np.stack([k[order], i[order]], axis=1)


def grasp_standoff(robot: Robot, arm_name: str | None = None) -> float:
    """How far [m] behind the grasp point the arm's TCP frame sits on its approach axis, for :func:`grasp_poses`.

    The arm spec's ``grasp_frame``, read from the URDF: TIAGo's ``arm_tool_link`` is the wrist
    flange, 0.151 m behind ``hand_grasping_frame``; PR2's ``*_gripper_tool_frame`` is between the
    fingertips already (no grasp frame: 0).
    """
    offset = robot.T_tcp_grasp(arm_name)[:3, 3] @ np.asarray(robot.spec.arm(arm_name).approach_vector)
    return round(float(offset), 4)


def verify_candidates(
    robot: Robot,
    arm_name: str | None,
    candidates: Sequence[RadialCandidate | Placement],
    grasps: ArrayLike,
    environment: Environment,
    rng: np.random.Generator,
    motion: MotionChecker | None = None,
) -> tuple[list[Placement], list[tuple[RadialCandidate | Placement, str, str | None]]]:
    """Run the shared verification on candidates of any method: IK for one of the grasps + collision.

    With ``motion``, the reaching motion to the grasp is checked too.

    Returns:
        (verified placements carrying their grasp index, joints and motion, rejected candidates with
        the verifier's reason for the grasp that got furthest: "motion", "collision" or "no_ik",
        and for "motion" the reaching-motion check's reason of the last grasp it refused
        (:data:`~baseplace.placement.motion.MOTION_FAILURES`), else None).
    """
    G = np.asarray(grasps, dtype=float).reshape(-1, 4, 4)
    arm = robot.arm(arm_name)
    ik = DampedLeastSquaresIK(arm)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    verifiers = [Verifier(arm, ik, environment, g[None], {}, outline, motion=motion) for g in G]
    usable = np.flatnonzero(hand_feasible(robot, arm_name, G, environment))
    verified: list[Placement] = []
    rejected: list[tuple[RadialCandidate | Placement, str, str | None]] = []
    for c in candidates:
        reasons: list[str] = [] if len(usable) else ["collision"]  # no grasp leaves the hand clear
        motion_reason = None
        for k in usable:
            verifier = verifiers[k]
            placement = verifier.check(Candidate(c.T_world_base, -1, _reachability(c)), rng)
            if placement is not None:
                verified.append(dataclasses.replace(placement, approach=_approach(c, int(k))))
                break
            if verifier.failures["motion"] and motion is not None:
                motion_reason = motion.last_failure
            reasons.extend(verifier.failures.elements())
            verifier.failures.clear()
        else:
            why = next((r for r in ("motion", "collision") if r in reasons), "no_ik")
            rejected.append((c, why, motion_reason if why == "motion" else None))
    return verified, rejected


def _reachability(c: RadialCandidate | Placement) -> float:
    return c.reachability if isinstance(c, Placement) else 0.0


def _approach(c: RadialCandidate | Placement, grasp: int) -> ObjectApproach:
    """Where ``c`` stands, now reaching grasp ``grasp``."""
    if isinstance(c, Placement):
        assert c.approach is not None, "only seed-004 placements are verified again for other grasps"
        return dataclasses.replace(c.approach, grasp=grasp)
    return ObjectApproach("radial", c.distance, c.ray, grasp)
