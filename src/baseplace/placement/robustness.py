"""Robustness of a placement to the navigation error of the base.

A navigation stack stops near its goal, not on it: Nav2's goal checker accepts any pose within
``xy_goal_tolerance`` (default 0.25 m) and ``yaw_goal_tolerance`` (0.25 rad) of the goal, and a
well-tuned base lands a few centimetres and degrees off. A placement verified at the exact pose
(seed 000 Alg. 2, seed 004 Alg. 2) may fail from the pose the robot actually reaches. Following
action-related places (Stulp et al., "Learning and reasoning with action-related places for robust
mobile manipulation", JAIR 2012), each verified placement is scored by its success probability
under that error: the fraction of base poses drawn from a :class:`BaseErrorModel` around it from
which every target is still reachable (IK, seeded with the nominal configuration; with
``ik_solutions`` > 1, further solutions from random starts when that one collides) and the whole
robot there is collision-free, with a Wilson score interval for the estimate. With
``RobustnessSettings.motion`` a draw also needs the reaching motion from that pose (the
placement's own :class:`~baseplace.placement.motion.MotionChecker`: stowed to pre-grasp, then the
straight approach) to every target's configuration there.

The error draws are fixed per estimator (common random numbers), so placements of one query are
compared on the same draws; IK runs batched over the draws, and results are cached per drawn pose.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, unknown
from baseplace.geometry.poses import BasePose, FloatArray, invert_transforms, yaw_of
from baseplace.placement import deadline
from baseplace.placement.verified import Placement, Robustness, wilson_interval
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Arm
from baseplace.world.environment import Environment

if TYPE_CHECKING:
    from baseplace.placement.motion import MotionChecker

ERROR_DISTRIBUTIONS = ("gaussian", "box")


@dataclass(frozen=True)
class BaseErrorModel:
    """Where the base stops when sent to a goal pose: offsets in x, y [m] (world) and heading [rad].

    Attributes:
        distribution: ``gaussian``: independent normal offsets in x, y and yaw, redrawn when they
            leave the tolerance box (the goal checker would not stop there); ``box``: uniform over
            the tolerance box (a Nav2 goal checker's worst case, no tuning assumed).
        sigma_xy: standard deviation of the x and the y offset [m] (default 3 cm).
        sigma_yaw: standard deviation of the heading offset [rad] (default 2 deg).
        xy_tolerance: the base stops within this distance of the goal [m] (Nav2 default 0.25).
        yaw_tolerance: and within this heading difference [rad] (Nav2 default 0.25).
    """

    distribution: Literal["gaussian", "box"] = "gaussian"
    sigma_xy: float = 0.03
    sigma_yaw: float = math.radians(2.0)
    xy_tolerance: float = 0.25
    yaw_tolerance: float = 0.25

    def __post_init__(self) -> None:
        if self.distribution not in ERROR_DISTRIBUTIONS:
            raise unknown("base error distribution", self.distribution, ERROR_DISTRIBUTIONS)
        for name in ("sigma_xy", "sigma_yaw"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a finite number >= 0, got {value}")
        for name in ("xy_tolerance", "yaw_tolerance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a finite number > 0, got {value}")
        if self.yaw_tolerance > math.pi:
            raise InputError(f"yaw_tolerance must be <= pi rad, got {self.yaw_tolerance}")

    def sample(self, rng: np.random.Generator, n: int) -> FloatArray:
        """(n, 3) offsets (dx [m], dy [m], dyaw [rad]) within the tolerance box."""
        out = np.empty((0, 3))
        while len(out) < n:
            m = 2 * (n - len(out)) + 8
            if self.distribution == "box":
                r = self.xy_tolerance * np.sqrt(rng.random(m))
                phi = rng.uniform(-math.pi, math.pi, m)
                d = np.column_stack(
                    [r * np.cos(phi), r * np.sin(phi), rng.uniform(-1, 1, m) * self.yaw_tolerance]
                )
            else:
                d = rng.normal(0.0, 1.0, (m, 3)) * [self.sigma_xy, self.sigma_xy, self.sigma_yaw]
            keep = (np.hypot(d[:, 0], d[:, 1]) <= self.xy_tolerance) & (np.abs(d[:, 2]) <= self.yaw_tolerance)
            out = np.concatenate([out, d[keep]])
        return out[:n]


def perturbed(T_world_base: ArrayLike, offsets: ArrayLike) -> FloatArray:
    """(S, 4, 4) base poses: ``T_world_base`` (4, 4) moved by (S, 3) world offsets (dx, dy, dyaw)."""
    T = np.asarray(T_world_base, dtype=float)
    d = np.asarray(offsets, dtype=float).reshape(-1, 3)
    out = T @ BasePose.batch_matrix(d * (0.0, 0.0, 1.0))  # heading error about the base's own z axis
    out[:, 0, 3] += d[:, 0]
    out[:, 1, 3] += d[:, 1]
    return out


@dataclass(frozen=True)
class RobustnessSettings:
    """How placements are scored and chosen by robustness.

    Attributes:
        samples: error draws per placement (0: no score).
        error: the base error model.
        rank: ``reachability`` (the strategy's order, the seeds') or ``robustness``: verify
            ``pool`` placements and return the ``placements`` most robust.
        minimum: reject placements whose rate is below this (reason ``robustness``).
        pool: verified placements collected before ranking by robustness (at least the number
            asked for).
        ik_restarts: random IK restarts per draw after the attempt from the nominal configuration.
        ik_solutions: IK solutions tried per draw and target: the first from the nominal
            configuration (as above), the others each from one random start; the draw counts when
            one of them is collision-free (a robot at that pose re-plans its grasp; one colliding
            IK branch does not make the pose fail). 1: only the first.
        z: normal quantile of the confidence interval (1.96: 95 %).
        seed: seed of the error draws.
        motion: a draw also needs the reaching motion from its pose to each target's configuration
            there (the placement's motion check, so the query must run one). One motion check per
            draw and target: on PCL's mug (the README's grasp-point command) 2.6 s of scoring for
            64 draws instead of 0.06 s, hence off by default.
    """

    samples: int = 64
    error: BaseErrorModel = field(default_factory=BaseErrorModel)
    rank: Literal["reachability", "robustness"] = "reachability"
    minimum: float = 0.0
    pool: int = 5
    ik_restarts: int = 4
    ik_solutions: int = 1
    z: float = 1.96
    seed: int = 0
    motion: bool = False

    def __post_init__(self) -> None:
        if self.rank not in ("reachability", "robustness"):
            raise unknown("placement ranking", self.rank, ("reachability", "robustness"))
        if self.samples < 0 or self.pool < 1 or self.ik_restarts < 0 or self.ik_solutions < 1:
            raise InputError(
                "need samples >= 0, pool >= 1, ik_restarts >= 0, ik_solutions >= 1; got "
                f"{self.samples}, {self.pool}, {self.ik_restarts}, {self.ik_solutions}"
            )
        if not (0.0 <= self.minimum <= 1.0):
            raise InputError(f"minimum robustness must be in [0, 1], got {self.minimum}")
        if (self.rank == "robustness" or self.minimum > 0) and self.samples == 0:
            raise InputError("ranking by or requiring robustness needs samples > 0")
        if not (math.isfinite(self.z) and self.z > 0):
            raise InputError(f"z must be > 0, got {self.z}")


def _motion_of(settings: RobustnessSettings, motion: MotionChecker | None) -> MotionChecker | None:
    """The motion check a score uses: ``motion`` when ``settings.motion`` asks for one, else None."""
    if settings.motion and motion is None:
        raise InputError(
            "a robustness score with the reaching motion needs the motion check (drop --no-motion-check)"
        )
    return motion if settings.motion else None


class RobustnessEstimator:
    """Scores base poses by the fraction of error draws that still reach every target.

    Args:
        arm: the arm.
        environment: the whole-robot collision model of the verification.
        targets: (K, 4, 4) world TCP targets.
        settings: samples, error model, IK restarts, seed.
        resolution: drawn poses are cached on this grid ([m] in x, y; [rad] in yaw).
        motion: the reaching-motion check; required when ``settings.motion`` is set, not used otherwise.

    Raises:
        InputError: ``settings.motion`` without a motion check.
    """

    def __init__(
        self,
        arm: Arm,
        environment: Environment,
        targets: ArrayLike,
        settings: RobustnessSettings | None = None,
        resolution: float = 1e-3,
        motion: MotionChecker | None = None,
    ) -> None:
        self.settings = settings or RobustnessSettings()
        self.motion = _motion_of(self.settings, motion)
        self.arm = arm
        self.environment = environment
        self.targets = np.asarray(targets, dtype=float).reshape(-1, 4, 4)
        self.offsets = self.settings.error.sample(
            np.random.default_rng(self.settings.seed), self.settings.samples
        )
        self._ik = DampedLeastSquaresIK(arm, restarts=self.settings.ik_restarts)
        self._ik_one = DampedLeastSquaresIK(arm, restarts=0)
        self._rng = np.random.default_rng(self.settings.seed + 1)
        self._resolution = resolution
        self._cache: dict[tuple[int, int, int], bool] = {}

    def _keys(self, poses: FloatArray) -> list[tuple[int, int, int]]:
        """Per pose (S, 4, 4), its cell of the cache grid: x, y and yaw rounded to the resolution."""
        xyyaw = np.stack([poses[:, 0, 3], poses[:, 1, 3], yaw_of(poses)], axis=1) / self._resolution
        return [(a, b, c) for a, b, c in np.rint(xyyaw).astype(np.int64).tolist()]

    def successes(
        self, T_world_base: ArrayLike, q_seeds: list[FloatArray] | None = None
    ) -> NDArray[np.bool_]:
        """(S,) per error draw: every target reached by IK, and the robot there collision-free.

        With a motion check, also the reaching motion to each target's configuration there, planned
        with a seed per draw (the same draws and seeds for every placement of the estimator).
        The draws' IK solutions are checked for collision together, each at its own pose
        (:meth:`~baseplace.world.environment.Environment.colliding_arm_poses`, coal's verdicts).

        Args:
            T_world_base: (4, 4) nominal base pose.
            q_seeds: per target, the nominal arm configuration (n,) that seeds the IK.
        """
        poses = perturbed(T_world_base, self.offsets)
        keys = self._keys(poses)
        todo = [i for i, k in enumerate(keys) if k not in self._cache]
        if todo:
            ok = np.ones(len(todo), dtype=bool)
            T_base_world = invert_transforms(poses[todo])
            for k, target in enumerate(self.targets):
                deadline.check()
                live = np.flatnonzero(ok)
                if len(live) == 0:
                    break
                seed = None if q_seeds is None else q_seeds[k]
                T_base_tcp = T_base_world[live] @ target
                q, found = self._ik.solve_batch(T_base_tcp, self._rng, seed)
                draw_poses = poses[np.asarray(todo)[live]]
                hit = ~np.asarray(found, dtype=bool)  # every draw's IK solution checked in one call
                hit[~hit] = self.environment.colliding_arm_poses(self.arm, q[~hit], draw_poses[~hit])
                for j, row in enumerate(live.tolist()):
                    if j % 64 == 0:
                        deadline.check()
                    T_draw = draw_poses[j]
                    q_ok: FloatArray | None = q[j]
                    if hit[j]:
                        q_ok = self._other_solution(T_base_tcp[j], T_draw)
                    if q_ok is not None and self.motion is not None:
                        plan_seed = self.settings.seed + 1000 * todo[row] + k
                        if self.motion.check(q_ok, T_draw, target, seed=plan_seed) is None:
                            q_ok = None
                    ok[row] = q_ok is not None
            for i, value in zip(todo, ok.tolist(), strict=True):
                self._cache[keys[i]] = value
        return np.array([self._cache[k] for k in keys], dtype=bool)

    def _other_solution(self, T_base_tcp: FloatArray, T_world_base: FloatArray) -> FloatArray | None:
        """The first of ``ik_solutions - 1`` IK solutions from random starts that is collision-free, or None."""
        arm = self.arm
        for q0 in self._rng.uniform(arm.lower, arm.upper, (self.settings.ik_solutions - 1, arm.n_joints)):
            q = self._ik_one.solve_from(T_base_tcp, q0[None])
            if q is not None and not self.environment.colliding_arm(arm, q, T_world_base):
                return q
        return None

    def score(self, T_world_base: ArrayLike, q_seeds: list[FloatArray] | None = None) -> Robustness:
        """The :class:`Robustness` of a base pose (4, 4)."""
        ok = self.successes(T_world_base, q_seeds)
        k, n = int(ok.sum()), len(ok)
        low, high = wilson_interval(k, n, self.settings.z)
        return Robustness(k, n, low, high)

    def scored(self, placement: Placement) -> Placement:
        """The placement with its robustness filled in."""
        return dataclasses.replace(placement, robustness=self.score(placement.T_world_base, placement.joints))


class RobustnessScorer:
    """The one robustness score of verified placements, from any method.

    Placements that reach the same targets share one :class:`RobustnessEstimator`, hence one set
    of error draws (common random numbers): all of a ``place`` query's, and a seed-004 query's per
    grasp pose.

    Args:
        arm: the arm.
        environment: the verification's whole-robot collision model.
        settings: samples, error model, IK restarts, seed, the minimum rate.
        motion: the placements' reaching-motion check (used when ``settings.motion`` is set).
    """

    def __init__(
        self,
        arm: Arm,
        environment: Environment,
        settings: RobustnessSettings | None = None,
        motion: MotionChecker | None = None,
    ) -> None:
        self.arm = arm
        self.motion = _motion_of(settings or RobustnessSettings(), motion)
        self.environment = environment
        self.settings = settings or RobustnessSettings()
        self._estimators: dict[bytes, RobustnessEstimator] = {}

    def scored(self, placement: Placement) -> Placement:
        """The placement with its robustness filled in (it must carry its targets, as verified ones do)."""
        if placement.targets is None:
            raise InputError("robustness needs verified placements (with the targets their joints reach)")
        key = placement.targets.tobytes()
        if key not in self._estimators:
            self._estimators[key] = RobustnessEstimator(
                self.arm, self.environment, placement.targets, self.settings, motion=self.motion
            )
        return self._estimators[key].scored(placement)

    def too_low(self, placement: Placement) -> bool:
        """Whether its score is below the settings' minimum rate."""
        return placement.robustness is not None and placement.robustness.rate < self.settings.minimum


def rank_by_robustness(placements: list[Placement], then: Sequence[float] | None = None) -> list[Placement]:
    """Placements by robustness rate, best first; ties broken by ``then`` (N,) ascending if given.

    Without ``then``, ties go to the higher lower confidence bound, then to the higher reachability.
    The sort is stable: placements that tie on everything keep their order.
    """

    def rate(p: Placement) -> float:
        return -(p.robustness.rate if p.robustness else 0.0)

    if then is not None:
        order = sorted(range(len(placements)), key=lambda i: (rate(placements[i]), then[i]))
        return [placements[i] for i in order]
    return sorted(
        placements, key=lambda p: (rate(p), -(p.robustness.low if p.robustness else 0.0), -p.reachability)
    )


__all__ = [
    "ERROR_DISTRIBUTIONS",
    "BaseErrorModel",
    "Robustness",
    "RobustnessEstimator",
    "RobustnessScorer",
    "RobustnessSettings",
    "perturbed",
    "rank_by_robustness",
    "wilson_interval",
]
