"""Inverse kinematics of an arm's TCP pose relative to its base.

The contract (as in ROS-Industrial reach's ``IKSolver``): :meth:`IKSolver.solve` returns joint
values within the limits that put the TCP at the requested pose, or None. The default solver is
damped least squares (Levenberg-Marquardt) on the compiled chain, with joint clamping, angle
wrapping for unbounded joints and random restarts; pinocchio FK is the test oracle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray, invert_transforms
from baseplace.robots.fk import NO_FRAMES, chain_frames, forward_kinematics
from baseplace.robots.model import Arm


class IKSolver(Protocol):
    """Solves ``T_base_tcp`` for joint values: a (n,) array within the limits, or None."""

    @property
    def arm(self) -> Arm:
        """The arm solved for."""
        ...

    def solve(
        self, T_base_tcp: ArrayLike, rng: np.random.Generator, q_seed: ArrayLike | None = None
    ) -> FloatArray | None:
        """Joint values reaching the pose, or None if none was found."""
        ...


LIMIT_MARGIN = 0.1
"""With a limit gain, a joint within this fraction of its range from a limit is pushed away from it."""


@nb.njit(cache=True, inline="always")
def _pose_and_jacobian(q, placements, axes, kinds, T_last, R, t, J):
    """TCP pose (R, t) and the 6 x n Jacobian (linear; angular), both in the base frame."""
    n = q.shape[0]
    origins = np.empty((n, 3))
    zs = np.empty((n, 3))
    chain_frames(q, placements, axes, kinds, T_last, R, t, zs, origins, True, NO_FRAMES, False)
    for i in range(n):
        zx, zy, zz = zs[i, 0], zs[i, 1], zs[i, 2]
        if kinds[i] == 1:
            J[0, i], J[1, i], J[2, i] = zx, zy, zz
            J[3, i] = J[4, i] = J[5, i] = 0.0
        else:
            dx, dy, dz = t[0] - origins[i, 0], t[1] - origins[i, 1], t[2] - origins[i, 2]
            J[0, i] = zy * dz - zz * dy
            J[1, i] = zz * dx - zx * dz
            J[2, i] = zx * dy - zy * dx
            J[3, i], J[4, i], J[5, i] = zx, zy, zz


@nb.njit(cache=True, inline="always")
def rotation_log(E, out):
    """Rotation vector (3,) of a rotation matrix E (3, 3), robust near 0 and pi."""
    vx = E[2, 1] - E[1, 2]
    vy = E[0, 2] - E[2, 0]
    vz = E[1, 0] - E[0, 1]
    s = 0.5 * math.sqrt(vx * vx + vy * vy + vz * vz)
    c = 0.5 * (E[0, 0] + E[1, 1] + E[2, 2] - 1.0)
    angle = math.atan2(s, c)
    if s > 1e-7:
        k = angle / (2.0 * s)
        out[0], out[1], out[2] = vx * k, vy * k, vz * k
    elif c > 0.0:
        out[0], out[1], out[2] = 0.5 * vx, 0.5 * vy, 0.5 * vz
    else:  # angle ~ pi: E ~ 2 a a^T - I
        k = 0
        if E[1, 1] > E[k, k]:
            k = 1
        if E[2, 2] > E[k, k]:
            k = 2
        a = np.empty(3)
        a[k] = math.sqrt(max(0.0, 0.5 * (E[k, k] + 1.0)))
        for j in range(3):
            if j != k:
                a[j] = 0.5 * (E[k, j] + E[j, k]) / (2.0 * a[k])
        norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        for j in range(3):
            out[j] = a[j] / norm * angle


@nb.njit(cache=True, inline="always")
def _damped_solve(J, e, lam, A, y, dq):
    """The damped least-squares step ``dq = J^T (J J^T + lam I)^-1 e`` (n,) of a 6 x n Jacobian, in place.

    ``J J^T + lam I`` is symmetric positive definite for ``lam > 0``, so a Cholesky factorisation
    of the 6 x 6 system (in ``A``, scratch (6, 6); ``y`` scratch (6,)) solves it, written out: the
    same step as LAPACK's LU to rounding, without numba's matrix products and ``np.linalg.solve``
    allocating and copying at every iteration (solves from a nearby start took 0.44 of the time,
    ``bench/paired_ik.py``).
    """
    n = J.shape[1]
    for r in range(6):
        for c in range(r + 1):
            s = 0.0
            for j in range(n):
                s += J[r, j] * J[c, j]
            A[r, c] = s
        A[r, r] += lam
    for r in range(6):  # A = L L^T, L in the lower triangle
        for c in range(r + 1):
            s = A[r, c]
            for k in range(c):
                s -= A[r, k] * A[c, k]
            A[r, c] = math.sqrt(s) if r == c else s / A[c, c]
    for r in range(6):  # L y = e
        s = e[r]
        for k in range(r):
            s -= A[r, k] * y[k]
        y[r] = s / A[r, r]
    for r in range(5, -1, -1):  # L^T y' = y
        s = y[r]
        for k in range(r + 1, 6):
            s -= A[k, r] * y[k]
        y[r] = s / A[r, r]
    for j in range(n):
        s = 0.0
        for r in range(6):
            s += J[r, j] * y[r]
        dq[j] = s


@nb.njit(cache=True, inline="always")
def _limit_aware_step(q, J, e, lam, lower, upper, continuous, limit_gain, saturate, dq):
    """The DLS step ``dq`` (n,) that uses the redundancy to keep off the joint limits.

    With ``saturate``, a joint the step would carry past a limit is stopped at it and dropped from
    the Jacobian, and the step is solved again with the others taking over its share of the task
    error (the saturation loop of Flacco, De Luca and Khatib's SNS, 2012, without task scaling):
    plain clamping throws that share away, so the solver stalls against the limit. A bounded
    (revolute or prismatic) joint within ``LIMIT_MARGIN`` of its range from a limit is pushed away
    from it by up to ``limit_gain`` (times the range) per iteration, projected onto the null space
    of the free joints' Jacobian, so the TCP stays put to first order.
    """
    n = q.shape[0]
    Jw = J.copy()
    ew = e.copy()
    fixed = np.zeros(n, dtype=np.bool_)
    A6, y6, free_step = np.empty((6, 6)), np.empty(6), np.empty(n)
    for _ in range(n + 1):
        _damped_solve(Jw, ew, lam, A6, y6, free_step)
        for j in range(n):
            if not fixed[j]:
                dq[j] = free_step[j]
        if not saturate:
            break
        changed = False
        for j in range(n):
            if fixed[j] or continuous[j]:
                continue
            v = q[j] + dq[j]
            if v > upper[j] or v < lower[j]:
                fixed[j] = True
                changed = True
                dq[j] = (upper[j] if v > upper[j] else lower[j]) - q[j]
                for a in range(6):
                    ew[a] -= Jw[a, j] * dq[j]
                    Jw[a, j] = 0.0
        if not changed:
            break
    if limit_gain <= 0.0:
        return
    z = np.zeros(n)
    for j in range(n):
        if fixed[j] or continuous[j]:
            continue
        span = upper[j] - lower[j]
        margin = LIMIT_MARGIN * span
        below, above = q[j] - lower[j], upper[j] - q[j]
        if below < margin:
            z[j] = limit_gain * span * (margin - below) / margin
        elif above < margin:
            z[j] = -limit_gain * span * (margin - above) / margin
    if not np.any(z != 0.0):
        return
    # the orthogonal projection onto the null space of Jw (the fixed joints' columns are 0):
    # z - Jw^T (Jw Jw^T)^-1 Jw z, regularised only enough to stay solvable at a singularity
    A = Jw @ Jw.T
    for a in range(6):
        A[a, a] += 1e-12
    ranged = Jw.T @ np.linalg.solve(A, Jw @ z)
    for j in range(n):
        if not fixed[j]:
            dq[j] += z[j] - ranged[j]


@nb.njit(cache=True)
def _solve_one(T_goal, seeds, placements, axes, kinds, T_last, lower, upper, continuous,
               max_iter, tol_p, tol_r, damping, q_out, limit_gain=0.0, saturate=False):  # fmt: skip
    n = seeds.shape[1]
    R = np.empty((3, 3))
    t = np.empty(3)
    J = np.empty((6, n))
    e = np.empty(6)
    E = np.empty((3, 3))
    w = np.empty(3)
    q = np.empty(n)
    dq = np.empty(n)
    A = np.empty((6, 6))
    y = np.empty(6)
    best = np.inf  # the least err_p + err_r seen: its configuration is q_out if no attempt converges
    for attempt in range(seeds.shape[0]):
        for j in range(n):
            q[j] = seeds[attempt, j]
        checkpoint = np.inf
        for it in range(max_iter):
            _pose_and_jacobian(q, placements, axes, kinds, T_last, R, t, J)
            for a in range(3):
                e[a] = T_goal[a, 3] - t[a]
                for b in range(3):  # E = R_goal R^T
                    E[a, b] = T_goal[a, 0] * R[b, 0] + T_goal[a, 1] * R[b, 1] + T_goal[a, 2] * R[b, 2]
            rotation_log(E, w)
            e[3], e[4], e[5] = w[0], w[1], w[2]
            err_p = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            err_r = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
            if err_p < tol_p and err_r < tol_r:
                for j in range(n):
                    q_out[j] = q[j]
                return attempt
            if err_p + err_r < best:
                best = err_p + err_r
                for j in range(n):
                    q_out[j] = q[j]
            if it % 10 == 9:  # stalled (usually against a joint limit): restart elsewhere
                if err_p + err_r > 0.95 * checkpoint:
                    break
                checkpoint = err_p + err_r
            lam = damping * (1.0 + err_p + err_r)
            if saturate or limit_gain > 0.0:
                _limit_aware_step(q, J, e, lam, lower, upper, continuous, limit_gain, saturate, dq)
            else:
                _damped_solve(J, e, lam, A, y, dq)
            step = np.max(np.abs(dq))
            if step > 0.4:
                dq *= 0.4 / step
            for j in range(n):
                v = q[j] + dq[j]
                if continuous[j]:
                    v = (v + math.pi) % (2.0 * math.pi) - math.pi
                q[j] = min(upper[j], max(lower[j], v))
    return -1


@nb.njit(cache=True, parallel=True)
def _solve_batch(T_goals, seeds, placements, axes, kinds, T_last, lower, upper, continuous,
                 max_iter, tol_p, tol_r, damping, q_out, attempts, limit_gain=0.0, saturate=False):  # fmt: skip
    for i in nb.prange(T_goals.shape[0]):
        attempts[i] = _solve_one(T_goals[i], seeds[i], placements, axes, kinds, T_last, lower,
                                 upper, continuous, max_iter, tol_p, tol_r, damping, q_out[i],
                                 limit_gain, saturate)  # fmt: skip


@dataclass(frozen=True)
class IKAttempt:
    """What one IK solve found, converged or not (for a "why not" answer).

    Attributes:
        q: (n,) the solution when ``solved``, else the configuration of the least residual seen
            (position error [m] + rotation error [rad]) over all starts and iterations.
        solved: whether some start converged within the tolerances.
        position_error: |p_target - p_tcp(q)| [m], TCP frame origin, arm base frame.
        rotation_error: angle of R_target R_tcp(q)^T [rad].
        starts: starts the solver had (the seed or mid-range, then the random restarts).
    """

    q: FloatArray
    solved: bool
    position_error: float
    rotation_error: float
    starts: int


@dataclass(frozen=True)
class DampedLeastSquaresIK:
    """Levenberg-Marquardt IK with random restarts on an arm's compiled chain.

    Attributes:
        arm: the arm to solve for.
        restarts: random restarts after the first attempt from the seed (or mid-range).
        max_iterations: iterations per attempt.
        tol_position: position tolerance [m].
        tol_rotation: orientation tolerance [rad].
        damping: Levenberg-Marquardt damping added to J J^T (scaled by the error).
        saturate_limits: a joint that a step would carry past its limit is held at the limit and
            the others take over its share of the step (see :func:`_limit_aware_step`); False:
            the step is clamped, and the solver stalls where the pose needs a joint past a limit
            but the arm's redundancy could do without it.
        limit_gain: per iteration, a joint within :data:`LIMIT_MARGIN` of its range from a limit
            moves away from it by up to this fraction of its range, in the null space of the
            task (the TCP stays put to first order) [1]; 0: off.
    """

    arm: Arm
    restarts: int = 80
    max_iterations: int = 150
    tol_position: float = 1e-4
    tol_rotation: float = 1e-3
    damping: float = 1e-4
    saturate_limits: bool = False
    limit_gain: float = 0.0

    def _seeds(self, rng: np.random.Generator, count: int, q_seed: ArrayLike | None) -> FloatArray:
        arm = self.arm
        seeds = np.empty((count, 1 + self.restarts, arm.n_joints))
        seeds[:, 0] = 0.5 * (arm.lower + arm.upper) if q_seed is None else np.asarray(q_seed, dtype=float)
        seeds[:, 1:] = rng.uniform(arm.lower, arm.upper, size=(count, self.restarts, arm.n_joints))
        return seeds

    def _run(self, T: FloatArray, seeds: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        arm = self.arm
        q_out = np.zeros((len(T), arm.n_joints))
        attempts = np.empty(len(T), dtype=np.int64)
        if len(T) == 1:  # one pose (a verification): no thread team to start and wait for
            attempts[0] = _solve_one(np.ascontiguousarray(T[0]), seeds[0], arm.placements, arm.axes, arm.kinds,
                                     arm.T_last_tcp, arm.lower, arm.upper, arm.continuous, self.max_iterations,
                                     self.tol_position, self.tol_rotation, self.damping, q_out[0],
                                     self.limit_gain, self.saturate_limits)  # fmt: skip
            return q_out, attempts
        _solve_batch(np.ascontiguousarray(T), seeds, arm.placements, arm.axes, arm.kinds,
                     arm.T_last_tcp, arm.lower, arm.upper, arm.continuous, self.max_iterations,
                     self.tol_position, self.tol_rotation, self.damping, q_out, attempts,
                     self.limit_gain, self.saturate_limits)  # fmt: skip
        return q_out, attempts

    def solve(
        self, T_base_tcp: ArrayLike, rng: np.random.Generator, q_seed: ArrayLike | None = None
    ) -> FloatArray | None:
        """Joint values (n,) that put the TCP at ``T_base_tcp`` (4, 4), or None."""
        T = _check_poses(T_base_tcp)
        q, attempts = self._run(T, self._seeds(rng, 1, q_seed))
        return q[0] if attempts[0] >= 0 else None

    def attempt(
        self, T_base_tcp: ArrayLike, rng: np.random.Generator, q_seed: ArrayLike | None = None
    ) -> IKAttempt:
        """:meth:`solve` with its residual: the same starts from the same ``rng`` state, the same answer.

        When no start converges, ``q`` is the configuration that came closest and the errors say
        how close (pose ``T_base_tcp`` (4, 4), errors measured by :func:`forward_kinematics`).
        """
        T = _check_poses(T_base_tcp)
        q, attempts = self._run(T, self._seeds(rng, 1, q_seed))
        reached = forward_kinematics(self.arm, q[0])
        position_error = float(np.linalg.norm(T[0, :3, 3] - reached[:3, 3]))
        cos = 0.5 * (float(np.trace(T[0, :3, :3] @ reached[:3, :3].T)) - 1.0)
        return IKAttempt(q[0], bool(attempts[0] >= 0), position_error, math.acos(min(1.0, max(-1.0, cos))),
                         1 + self.restarts)  # fmt: skip

    def solve_batch(
        self, T_base_tcp: ArrayLike, rng: np.random.Generator, q_seed: ArrayLike | None = None
    ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Solve (N, 4, 4) poses in parallel; returns q (N, n) and success (N,).

        ``q_seed`` (n,), if given, is every pose's first attempt (default: mid-range).
        """
        T = _check_poses(T_base_tcp)
        q, attempts = self._run(T, self._seeds(rng, len(T), q_seed))
        return q, attempts >= 0

    def solve_from(self, T_base_tcp: ArrayLike, seeds: ArrayLike) -> FloatArray | None:
        """Joint values (n,) reaching ``T_base_tcp`` (4, 4), or None; IK that stays near given configurations.

        Tries the (R, n) ``seeds`` in order (no random restarts) and returns the first that converges.
        """
        T = _check_poses(T_base_tcp)[0]
        arm = self.arm
        S = np.ascontiguousarray(np.asarray(seeds, dtype=float).reshape(-1, arm.n_joints))
        q = np.zeros(arm.n_joints)
        attempt = _solve_one(T, S, arm.placements, arm.axes, arm.kinds, arm.T_last_tcp, arm.lower,
                             arm.upper, arm.continuous, self.max_iterations, self.tol_position,
                             self.tol_rotation, self.damping, q, self.limit_gain,
                             self.saturate_limits)  # fmt: skip
        return q if attempt >= 0 else None

    def solve_world(
        self,
        T_world_tcp: ArrayLike,
        T_world_base: ArrayLike,
        rng: np.random.Generator,
        q_seed: ArrayLike | None = None,
    ) -> FloatArray | None:
        """Solve a world TCP pose (4, 4) from a world base pose (4, 4)."""
        T_base_tcp = invert_transforms(np.asarray(T_world_base, dtype=float)) @ np.asarray(
            T_world_tcp, dtype=float
        )
        return self.solve(T_base_tcp, rng, q_seed)


def _check_poses(T: ArrayLike) -> FloatArray:
    arr = np.asarray(T, dtype=np.float64).reshape(-1, 4, 4)
    if not np.all(np.isfinite(arr)):
        raise InputError("IK target pose contains NaN or infinity")
    return arr
