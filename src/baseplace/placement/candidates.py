"""Radial base-placement candidates and the pickup loop (seed 004, section 3, Algorithms 1 and 2).

Seed 004 ("Planning Robot Placement for Object Grasping", Saini et al.) places the base before
any grasp is planned: along radial unit vectors around the object, spaced by the angle ``theta``,
it walks outwards from ``d_min`` in steps of the footprint radius ``r_r`` while the distance stays
below ``d_max``, and keeps the first position without a risk of collision (Algorithm 1). Candidates
face the object. The pickup loop (Algorithm 2) ranks them by ``MotionCost`` (robot -> candidate
plus candidate -> object distance), navigates to the best, and on a navigation failure re-ranks the
rest from the robot's current pose.

``HasCollisionRisk`` (section 3.2) counts cloud points in two cuboids, the robot body
(``2 r_r x 2 r_r x h_r`` at the candidate, aligned with the radial direction, from the floor up)
and the arm sweep (from the object to the candidate at the object's height, ``w_o`` wide and
``h_o`` high), and rejects the candidate when either holds more than ``k_obs`` points; it also
rejects a candidate when a disc of radius ``r_r`` around it touches an occupied grid cell.
Where the seed leaves details open, this module decides (each documented at its setting):

* the cuboids leave out the floor (``ground_clearance``), the object's own points and the surface
  it stands on (``surface_margin``); otherwise every candidate in a real cloud would count them;
* the disc test is exact (disc against cell squares) and unknown or off-map cells count as
  occupied by default; the candidate must also be a goal the grid planner accepts
  (:mod:`baseplace.navigation.gridnav`), so the planner never refuses a candidate as a goal;
* ``theta`` is ``2 arcsin(r_r / (2 d_min))`` as the seed's footnote 5 writes it, and
  ``ceil(2 pi / theta)`` rays are spaced equally by ``2 pi / n <= theta``. The footnote says this
  angle gives a chord of ``2 r_r`` at ``d_min``, but its chord is ``2 d_min sin(theta / 2) = r_r``
  (a ``2 r_r`` chord needs ``2 arcsin(r_r / d_min)``); the formula is kept, so neighbouring
  candidates at ``d_min`` are at most ``r_r`` apart: twice as many rays, none missed;
* distances to the object are horizontal (the seed generates candidates around "the projected
  object's position").

The seed names reachability maps as future work; :mod:`baseplace.placement.irm_candidates` ranks
base poses with a reachability map instead and verifies them with the shared verifier; both
methods return :class:`~baseplace.placement.verified.Placement`, feed :func:`pickup` and can be compared.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Generic, Literal, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, FloatArray
from baseplace.navigation.gridnav import OBSTACLE, GridNavigator, blocked_by_inflation
from baseplace.navigation.path import Path
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.model import Robot
from baseplace.world.occupancy import UNKNOWN, OccupancyGrid

Risk = Literal["body", "arm", "occupancy"]
Navigate = Callable[[BasePose, BasePose], Path | None]
"""Seed 004's ``Navigate``: (current pose, goal pose) -> the path, or None on failure."""
Travel = Callable[[BasePose, FloatArray], FloatArray]
"""(robot pose, goal points (N, 2) [m]) -> travel distances (N,) [m], inf where unreachable."""


@dataclass(frozen=True)
class RadialSettings:
    """Parameters of Algorithm 1 and ``HasCollisionRisk`` (seed 004, section 3.2). Defaults: TIAGo.

    Attributes:
        r_r: radius of the robot footprint [m]; TIAGo's PMB2 base is a 0.54 m disc, 0.275 m with
            the spec's margin (:meth:`for_robot` takes the robot's footprint bounding radius).
        h_r: robot height [m]: TIAGo is 1.10 m with its torso down and 1.45 m raised; it raises the
            torso to grasp from tables, so the body cuboid covers 1.45 m.
        d_min: minimum base-to-object distance [m], the seed's "minimum safe distance for
            grasping": 0.45 m keeps the base edge 0.175 m from the object centre, where TIAGo's
            reachability map starts to reach table-height grasps well.
        d_max: candidates stay strictly closer than this [m], the arm's reach; 0.95 m is the
            horizontal reach of TIAGo's default map (:meth:`for_robot` takes the map's).
        k_obs: a cuboid holding more than this many cloud points is a collision risk (the seed's
            fixed threshold, not given there; 10 tolerates stray depth noise).
        w_o: detected object width [m], the arm cuboid's width (a cup: 0.08 m).
        h_o: detected object height [m], the arm cuboid's height (0.12 m).
        floor_z: height of the floor in the map frame [m]; the body cuboid starts here.
        ground_clearance: points less than this above the floor [m] are the floor itself, not
            obstacles (a base clears the ground by a few cm; depth noise on the floor is below 5 cm).
        surface_margin: the arm cuboid starts this far beyond the object's near face
            (``w_o / 2 + margin`` from its centre) and this far above its bottom
            (``z_o - h_o / 2 + margin``) [m], so the object's own points and the table top under
            it do not count; the seed's cuboid would contain both and reject every candidate.
        unknown_is_risk: unknown (-1) and off-map cells count as occupied in the occupancy test
            (the robot cannot know that space is free, and a planner without ``allow_unknown``
            cannot reach it).
    """

    r_r: float = 0.275
    h_r: float = 1.45
    d_min: float = 0.45
    d_max: float = 0.95
    k_obs: int = 10
    w_o: float = 0.08
    h_o: float = 0.12
    floor_z: float = 0.0
    ground_clearance: float = 0.05
    surface_margin: float = 0.02
    unknown_is_risk: bool = True

    def __post_init__(self) -> None:
        positive = {"r_r": self.r_r, "h_r": self.h_r, "d_min": self.d_min, "d_max": self.d_max,
                    "w_o": self.w_o, "h_o": self.h_o}  # fmt: skip
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a finite number > 0 m, got {value}")
        for name, value in {
            "ground_clearance": self.ground_clearance,
            "surface_margin": self.surface_margin,
        }.items():
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a finite number >= 0 m, got {value}")
        if not math.isfinite(self.floor_z):
            raise InputError(f"floor_z must be a finite height [m], got {self.floor_z}")
        if self.d_min >= self.d_max:
            raise InputError(f"need d_min < d_max, got d_min={self.d_min} m, d_max={self.d_max} m")
        if self.r_r > 2 * self.d_min:
            raise InputError(
                f"need r_r <= 2 d_min for theta = 2 arcsin(r_r / (2 d_min)), got r_r={self.r_r} m"
            )
        if isinstance(self.k_obs, bool) or not isinstance(self.k_obs, (int, np.integer)) or self.k_obs < 0:
            raise InputError(f"k_obs must be an integer >= 0 (points), got {self.k_obs!r}")

    @property
    def theta(self) -> float:
        """Largest angle between rays [rad]: ``2 arcsin(r_r / (2 d_min))`` (seed 004, footnote 5).

        Its chord at ``d_min`` is ``r_r`` (the footnote's text says ``2 r_r``; see the module notes).
        """
        return 2.0 * math.asin(self.r_r / (2.0 * self.d_min))

    @property
    def n_rays(self) -> int:
        """Number of radial unit vectors, ``ceil(2 pi / theta)``, spaced equally by ``2 pi / n_rays``."""
        return max(1, math.ceil(2.0 * math.pi / self.theta - 1e-9))

    @classmethod
    def for_robot(cls, robot: Robot, rmap: ReachabilityMap | None = None, **changes: Any) -> RadialSettings:
        """Settings with ``r_r`` from the robot's footprint and ``d_max`` from the map's horizontal reach."""
        values: dict[str, Any] = {"r_r": robot.spec.footprint_bounding_radius}
        if rmap is not None:
            values["d_max"] = rmap.horizontal_reach
        values.update(changes)
        return cls(**values)


@dataclass(frozen=True, eq=False)
class RadialCandidate:
    """A base pose Algorithm 1 proposes, facing the object (seed 004's ``q_r``), not yet verified.

    :func:`~baseplace.placement.irm_candidates.verify_candidates` turns the ones that pass into
    :class:`~baseplace.placement.verified.Placement` values.

    Attributes:
        pose: base pose in the map frame (x, y [m], yaw [rad]).
        distance: horizontal distance from the object [m].
        ray: index of the radial unit vector it lies on.
    """

    pose: BasePose
    distance: float
    ray: int = -1

    @property
    def xy(self) -> FloatArray:
        """(2,) position [m]."""
        return np.array([self.pose.x, self.pose.y])

    @property
    def T_world_base(self) -> FloatArray:
        """(4, 4) base pose."""
        return self.pose.matrix()


class Posed(Protocol):
    """Anything with a planar base pose: a proposed :class:`RadialCandidate` or a verified placement."""

    @property
    def pose(self) -> BasePose:
        """The base pose (x, y [m], yaw [rad])."""
        ...


P = TypeVar("P", bound=Posed)


@dataclass(frozen=True)
class Rejection:
    """A position Algorithm 1 tried and rejected (red in the seed's Fig. 2).

    Attributes:
        xy: (x, y) position [m].
        ray: index of its radial unit vector.
        distance: distance from the object [m].
        reason: "body" or "arm" (too many cloud points in that cuboid) or "occupancy".
    """

    xy: tuple[float, float]
    ray: int
    distance: float
    reason: Risk


@dataclass(frozen=True)
class RadialSearch:
    """Everything Algorithm 1 produced, for ranking and for plots.

    Attributes:
        p_o: (3,) object position [m] (z = 0 when given in 2-D).
        directions: (n_rays, 2) radial unit vectors, object -> robot.
        candidates: at most one per ray, in ray order.
        rejected: the positions tried and rejected, in the order tried.
        settings: the parameters used.
    """

    p_o: FloatArray
    directions: FloatArray
    candidates: list[RadialCandidate]
    rejected: list[Rejection]
    settings: RadialSettings


def _object(p_o: ArrayLike, need_z: str = "") -> FloatArray:
    """(3,) object position; ``need_z`` names what needs its height when (x, y) is not enough."""
    p = np.asarray(p_o, dtype=float).reshape(-1)
    if p.shape not in ((2,), (3,)) or not np.all(np.isfinite(p)):
        raise InputError(f"object position must be 2 or 3 finite numbers (x, y[, z]) [m], got {p.tolist()}")
    if p.shape == (2,):
        if need_z:
            raise InputError(f"{need_z} needs the object's height: give the object position as (x, y, z) [m]")
        p = np.append(p, 0.0)
    return p


def _cloud(points: ArrayLike | None) -> FloatArray | None:
    if points is None:
        return None
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3) [m], got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise InputError("points contain NaN or infinity; drop those rows first (load_cloud does)")
    return pts


def cuboid_counts(
    xy_r: ArrayLike, p_o: ArrayLike, settings: RadialSettings, points: ArrayLike
) -> tuple[int, int]:
    """Cloud points in the body cuboid and in the arm cuboid of one candidate (seed 004, section 3.2).

    Args:
        xy_r: (2,) candidate position in the map frame [m].
        p_o: (3,) object centre [m].
        settings: cuboid sizes and margins.
        points: (P, 3) cloud in the map frame [m].

    Returns:
        (points in the body cuboid, points in the arm cuboid).
    """
    s = settings
    p = np.asarray(p_o, dtype=float)
    r = np.asarray(xy_r, dtype=float)
    pts = np.asarray(points, dtype=float)
    u = r - p[:2]
    length = float(np.hypot(u[0], u[1]))
    if length < 1e-9:
        raise InputError("the candidate position coincides with the object: no radial direction")
    u /= length
    w = np.array([-u[1], u[0]])
    z = pts[:, 2]
    d = pts[:, :2] - r
    body = (np.abs(d @ u) <= s.r_r) & (np.abs(d @ w) <= s.r_r)
    body &= (z >= s.floor_z + s.ground_clearance) & (z <= s.floor_z + s.h_r)
    e = pts[:, :2] - p[:2]
    along = e @ u
    arm = (along >= 0.5 * s.w_o + s.surface_margin) & (along <= length) & (np.abs(e @ w) <= 0.5 * s.w_o)
    arm &= (z >= p[2] - 0.5 * s.h_o + s.surface_margin) & (z <= p[2] + 0.5 * s.h_o)
    return int(body.sum()), int(arm.sum())


def occupancy_risk(
    grid: OccupancyGrid, xy: ArrayLike, radius: float, unknown_is_risk: bool = True
) -> NDArray[np.bool_]:
    """(N,) whether a robot disc of ``radius`` [m] at world points ``xy`` (N, 2) risks collision on the grid.

    True when the closed disc touches the square of an obstacle cell (value >= ``OBSTACLE``; also
    unknown and off-map cells when ``unknown_is_risk``), or when the planner of
    :mod:`~baseplace.navigation.gridnav` could not stand there (its inflation measures between cell centres).
    """
    pts = np.asarray(xy, dtype=float).reshape(-1, 2)
    res = grid.resolution
    c, s = math.cos(grid.origin[2]), math.sin(grid.origin[2])
    local = (pts - np.array(grid.origin[:2])) @ np.array([[c, -s], [s, c]])  # rows R^T (p - o)
    k = math.ceil(radius / res) + 1
    di, dj = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1), indexing="ij")
    stencil = np.stack([di.ravel(), dj.ravel()], axis=1)
    risk = np.zeros(len(pts), dtype=bool)
    for lo in range(0, len(pts), 2048):  # bounded memory: 2048 x stencil cells at a time
        loc = local[lo : lo + 2048]
        cells = np.floor(loc / res).astype(np.int64)[:, None, :] + stencil[None]
        corner = cells * res
        gap = np.maximum(np.maximum(corner - loc[:, None], 0.0), loc[:, None] - (corner + res))
        touches = (gap**2).sum(axis=2) <= radius**2
        inside = (cells[..., 0] >= 0) & (cells[..., 0] < grid.width) & (cells[..., 1] >= 0)
        inside &= cells[..., 1] < grid.height
        values = np.full(inside.shape, UNKNOWN, dtype=np.int16)
        values[inside] = grid.data[cells[..., 1][inside], cells[..., 0][inside]]
        bad = values >= OBSTACLE
        if unknown_is_risk:
            bad |= values == UNKNOWN
        risk[lo : lo + 2048] = (bad & touches).any(axis=1)
    return risk | blocked_by_inflation(grid, pts, radius, allow_unknown=not unknown_is_risk)


def collision_risk(
    xy_r: ArrayLike,
    p_o: ArrayLike,
    settings: RadialSettings,
    points: ArrayLike | None = None,
    occupancy: OccupancyGrid | None = None,
) -> Risk | None:
    """Why the candidate risks a collision, or None: seed 004's ``HasCollisionRisk`` (section 3.2).

    Args:
        xy_r: (2,) candidate base position in the map frame [m].
        p_o: (3,) object centre in the map frame [m] ((2,) when no points are given).
        settings: robot and object dimensions, ``k_obs``, margins.
        points: (P, 3) cloud of the scene in the map frame [m], or None to skip the cloud tests.
        occupancy: the occupancy grid, or None to skip the grid test.

    Returns:
        "body" or "arm" when that cuboid holds more than ``k_obs`` points, "occupancy" when the
        footprint disc touches an occupied cell, else None (checked in that order).
    """
    pts = _cloud(points)
    p = _object(p_o, "the cloud test" if pts is not None else "")
    r = np.asarray(xy_r, dtype=float).reshape(-1)
    if r.shape != (2,) or not np.all(np.isfinite(r)):
        raise InputError(f"candidate position must be 2 finite numbers (x, y) [m], got {r.tolist()}")
    if pts is not None:
        body, arm = cuboid_counts(r, p, settings, pts)
        if body > settings.k_obs:
            return "body"
        if arm > settings.k_obs:
            return "arm"
    if occupancy is not None and occupancy_risk(occupancy, r, settings.r_r, settings.unknown_is_risk)[0]:
        return "occupancy"
    return None


def has_collision_risk(
    xy_r: ArrayLike,
    p_o: ArrayLike,
    settings: RadialSettings,
    points: ArrayLike | None = None,
    occupancy: OccupancyGrid | None = None,
) -> bool:
    """Seed 004's ``HasCollisionRisk``: True if :func:`collision_risk` finds a reason."""
    return collision_risk(xy_r, p_o, settings, points, occupancy) is not None


def radial_search(
    p_o: ArrayLike,
    settings: RadialSettings | None = None,
    points: ArrayLike | None = None,
    occupancy: OccupancyGrid | None = None,
) -> RadialSearch:
    """Seed 004's Algorithm 1, keeping the rejected positions too (for the seed's Fig. 2).

    Along each radial unit vector (angle ``k 2 pi / n_rays`` from the map's x axis) the position
    starts at ``d_min`` and moves out by ``r_r`` while closer than ``d_max``; the first position
    without collision risk becomes a candidate with yaw pointing at the object.

    Args:
        p_o: (3,) object centre in the map frame [m] ((2,) without points).
        settings: the parameters (default: TIAGo's, :class:`RadialSettings`).
        points: (P, 3) scene cloud in the map frame [m], e.g. ``load_cloud(path).transformed(T).points``.
        occupancy: occupancy grid in the map frame.

    Returns:
        The candidates (at most one per ray) and the rejected positions.
    """
    s = settings or RadialSettings()
    pts = _cloud(points)
    p = _object(p_o, "the cloud test" if pts is not None else "")
    if pts is not None:  # only points near the object can fall into a cuboid
        near = np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1]) <= s.d_max + math.sqrt(2) * s.r_r + s.w_o
        pts = pts[near]
    angles = np.arange(s.n_rays) * (2.0 * math.pi / s.n_rays)
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    candidates: list[RadialCandidate] = []
    rejected: list[Rejection] = []
    for i, v in enumerate(directions):
        distance = s.d_min
        while distance < s.d_max:
            xy = p[:2] + distance * v
            risk = collision_risk(xy, p, s, pts, occupancy)
            if risk is None:
                yaw = math.atan2(-v[1], -v[0])  # the robot points in -v, at the object
                candidates.append(RadialCandidate(BasePose(float(xy[0]), float(xy[1]), yaw), distance, i))
                break
            rejected.append(Rejection((float(xy[0]), float(xy[1])), i, distance, risk))
            distance += s.r_r
    return RadialSearch(p, directions, candidates, rejected, s)


def radial_candidates(
    p_o: ArrayLike,
    settings: RadialSettings | None = None,
    points: ArrayLike | None = None,
    occupancy: OccupancyGrid | None = None,
) -> list[RadialCandidate]:
    """Seed 004's Algorithm 1: the base placement candidates S (see :func:`radial_search`)."""
    return radial_search(p_o, settings, points, occupancy).candidates


def motion_cost(candidate: Posed, p_o: ArrayLike, robot_pose: BasePose, travel: float | None = None) -> float:
    """Seed 004's ``MotionCost`` (section 3.3): robot -> candidate plus candidate -> object distance [m].

    Args:
        candidate: the candidate.
        p_o: (2,) or (3,) object position [m]; the candidate -> object distance is horizontal.
        robot_pose: the robot's current pose.
        travel: the robot -> candidate distance when known, e.g. a path length on the grid
            (:meth:`GridNavigator.travel`); default: the straight-line distance, as in the seed.
    """
    p = _object(p_o)
    to_object = math.hypot(candidate.pose.x - p[0], candidate.pose.y - p[1])
    if travel is None:
        travel = math.hypot(candidate.pose.x - robot_pose.x, candidate.pose.y - robot_pose.y)
    return float(travel) + to_object


def motion_costs(
    candidates: Sequence[Posed], p_o: ArrayLike, robot_pose: BasePose, travel: Travel | None = None
) -> FloatArray:
    """(N,) :func:`motion_cost` of each candidate; ``travel`` estimates robot -> candidate distances (inf: unreachable)."""
    if not candidates:
        return np.zeros(0)
    xy = np.array([[c.pose.x, c.pose.y] for c in candidates])
    dist = None if travel is None else np.asarray(travel(robot_pose, xy), dtype=float)
    return np.array(
        [
            motion_cost(c, p_o, robot_pose, None if dist is None else float(dist[k]))
            for k, c in enumerate(candidates)
        ]
    )


@dataclass(frozen=True)
class PickupResult(Generic[P]):
    """The outcome of Algorithm 2 up to the grasp itself.

    Attributes:
        chosen: the candidate the robot reached, or None when every navigation failed.
        path: the path to it, or None.
        tries: navigation attempts made.
        failures: (candidate, why) for each failed attempt, in order.
    """

    chosen: P | None
    path: Path | None
    tries: int
    failures: list[tuple[P, str]] = field(default_factory=list)

    @property
    def succeeded(self) -> bool:
        """Whether a candidate was reached."""
        return self.chosen is not None


def pickup(
    candidates: Sequence[P],
    p_o: ArrayLike,
    start_pose: BasePose,
    navigate: Navigate | None = None,
    *,
    occupancy: OccupancyGrid | None = None,
    settings: RadialSettings | None = None,
    travel: Travel | None = None,
    locate: Callable[[], BasePose] | None = None,
    rerank: bool = True,
) -> PickupResult[P]:
    """Seed 004's Algorithm 2 up to ``Pickup``: navigate to the best candidate, re-ranking after failures.

    Each round ranks the remaining candidates by :func:`motion_cost` from the robot's current pose,
    removes the best and navigates to it; the first success ends the loop.

    Args:
        candidates: the set S (not modified).
        p_o: (2,) or (3,) object position [m].
        start_pose: the robot's pose before the first attempt.
        navigate: ``Navigate(current, goal) -> path or None``; an :class:`InputError` it raises
            (e.g. a goal too close to an obstacle) counts as a failure with its message. Default:
            a :class:`GridNavigator` on ``occupancy`` with radius ``settings.r_r``.
        occupancy: the grid for the default navigator.
        settings: for the default navigator's radius and unknown-space policy.
        travel: robot -> candidate distance for the ranking (default: straight line, as the seed);
            e.g. ``GridNavigator(...).travel`` for path lengths.
        locate: reads the robot's pose after a failed attempt (Algorithm 2, line 2). Default: the
            pose is unchanged, true of planners that fail before the robot moves, as this one does.
        rerank: rank by motion cost (the seed's loop); False: try the candidates in their order
            (ranked otherwise, e.g. by robustness).

    Returns:
        The reached candidate and its path, or ``chosen=None`` when S ran out.

    Raises:
        InputError: no ``navigate`` and no ``occupancy``.
    """
    if navigate is None:
        if occupancy is None:
            raise InputError("pickup needs a navigate function or an occupancy grid to plan on")
        s = settings or RadialSettings()
        navigate = GridNavigator(occupancy, s.r_r, allow_unknown=not s.unknown_is_risk)
    remaining = list(candidates)
    current = start_pose
    failures: list[tuple[P, str]] = []
    while remaining:
        best = int(np.argmin(motion_costs(remaining, p_o, current, travel))) if rerank else 0
        goal = remaining.pop(best)
        try:
            path = navigate(current, goal.pose)
            why = "no path"
        except InputError as exc:
            path, why = None, str(exc)
        if path is not None:
            return PickupResult(goal, path, len(failures) + 1, failures)
        failures.append((goal, why))
        if locate is not None:
            current = locate()
    return PickupResult(None, None, len(failures), failures)


__all__ = [
    "Navigate",
    "PickupResult",
    "Posed",
    "RadialCandidate",
    "RadialSearch",
    "RadialSettings",
    "Rejection",
    "Travel",
    "collision_risk",
    "cuboid_counts",
    "has_collision_risk",
    "motion_cost",
    "motion_costs",
    "occupancy_risk",
    "pickup",
    "radial_candidates",
    "radial_search",
]
