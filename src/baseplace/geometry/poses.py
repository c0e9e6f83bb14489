"""Pose conventions shared by every module and the CLI.

* ``T_a_b`` is the pose of frame b in frame a, a (4, 4) homogeneous matrix mapping points from b
  to a: ``p_a = T_a_b @ p_b``. Batches are (N, 4, 4).
* Euler angles follow ROS (REP 103): ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``, radians.
* A 6D pose on the command line is ``"x y z roll pitch yaw"`` (metres, radians); a base pose on
  the floor is ``"x y yaw"``. Parsed angles beyond +-2 pi (pitch: +-pi) are refused
  (:func:`check_angles`): such a value is almost always degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError

FloatArray = NDArray[np.float64]


def rpy_to_matrix(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> FloatArray:
    """Rotation matrices ``Rz(yaw) Ry(pitch) Rx(roll)``.

    Args:
        roll: angle about x [rad], scalar or shape (N,).
        pitch: angle about y [rad], same shape.
        yaw: angle about z [rad], same shape.

    Returns:
        (3, 3) for scalars, else (N, 3, 3).
    """
    r, p, y = (np.asarray(a, dtype=float) for a in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    R = np.empty((*np.broadcast(r, p, y).shape, 3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def matrix_to_rpy(R: ArrayLike) -> FloatArray:
    """Inverse of :func:`rpy_to_matrix`: (..., 3, 3) -> (..., 3) as (roll, pitch, yaw) [rad]."""
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def pose_from_xyz_rpy(xyz_rpy: ArrayLike) -> FloatArray:
    """Homogeneous poses from ``(x, y, z, roll, pitch, yaw)``.

    Args:
        xyz_rpy: shape (6,) or (N, 6), metres and radians.

    Returns:
        (4, 4) or (N, 4, 4).
    """
    v = np.asarray(xyz_rpy, dtype=float)
    if v.shape[-1] != 6:
        raise InputError(f"a 6D pose needs 6 numbers (x y z roll pitch yaw), got {v.shape[-1]}")
    T = np.zeros((*v.shape[:-1], 4, 4))
    T[..., :3, :3] = rpy_to_matrix(v[..., 3], v[..., 4], v[..., 5])
    T[..., :3, 3] = v[..., :3]
    T[..., 3, 3] = 1.0
    return T


def invert_transforms(T: ArrayLike) -> FloatArray:
    """Invert rigid transforms (..., 4, 4) using R^T, without a general matrix inverse."""
    T = np.asarray(T, dtype=float)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def _unit_vector(v: ArrayLike, what: str) -> FloatArray:
    a = np.asarray(v, dtype=float)
    norm = float(np.linalg.norm(a)) if a.shape == (3,) else 0.0
    if not (np.isfinite(norm) and norm > 1e-9):
        raise InputError(f"{what} must be a finite non-zero 3-vector, got {a.tolist()}")
    return a / norm


def rotation_taking(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """The smallest rotation (3, 3) with ``R @ a/|a| = b/|b|``, for (3,) directions (Rodrigues).

    Opposite directions: half a turn about an axis perpendicular to ``a``.
    """
    u, w = _unit_vector(a, "a direction"), _unit_vector(b, "a direction")
    axis, c = np.cross(u, w), float(u @ w)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        k = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        k /= np.linalg.norm(k)
        return 2.0 * np.outer(k, k) - np.eye(3)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]]) / s
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Angles [rad], scalar or any shape, wrapped to (-pi, pi]: the one range headings have."""
    a = np.asarray(angle, dtype=float)
    wrapped = a - (2.0 * np.pi) * np.ceil((a - np.pi) / (2.0 * np.pi))
    # Near odd multiples of pi the division rounds across the boundary and lands a few ulp out.
    wrapped = np.where(wrapped > np.pi, wrapped - 2.0 * np.pi, wrapped)
    return np.where(wrapped <= -np.pi, wrapped + 2.0 * np.pi, wrapped)


def yaw_of(T_world_base: ArrayLike) -> FloatArray:
    """Heading [rad] in (-pi, pi] of poses' x axes in the world xy plane: the one yaw extraction.

    Args:
        T_world_base: (..., 4, 4) or (..., 3, 3), any batch shape.

    Returns:
        Shape (...): a 0-d array for one pose.
    """
    T = np.asarray(T_world_base, dtype=float)
    return wrap_angle(np.arctan2(T[..., 1, 0], T[..., 0, 0]))


def pose_json(T_world_base: ArrayLike) -> dict[str, Any]:
    """A base pose in the one JSON shape of every report, from its (4, 4) ``T_world_base``.

    ``{"base_pose": the 4x4 (6 decimals), "x", "y", "z" [m] (4 decimals), "yaw" [rad] in (-pi, pi]
    (:func:`yaw_of`, 4 decimals)}``; a placement on an incline keeps its tilt in ``base_pose``.
    """
    T = np.asarray(T_world_base, dtype=float)
    return {"base_pose": np.round(T, 6).tolist(), "x": round(float(T[0, 3]), 4),
            "y": round(float(T[1, 3]), 4), "z": round(float(T[2, 3]), 4), "yaw": round(float(yaw_of(T)), 4)}  # fmt: skip


def _parse_numbers(text: str, count: int, what: str) -> FloatArray:
    parts = text.replace(",", " ").split()
    if len(parts) != count:
        raise InputError(f"{what} needs {count} numbers, got {len(parts)} in {text!r}")
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise InputError(f"{what} must be numbers, got {text!r}") from None
    if not np.all(np.isfinite(values)):
        raise InputError(f"{what} contains NaN or infinity: {text!r}")
    return values


RPY_LIMITS = (("roll", 2.0 * math.pi, "2 pi"), ("pitch", math.pi, "pi"), ("yaw", 2.0 * math.pi, "2 pi"))
"""(name, largest magnitude [rad], as written) of each Euler angle a parsed pose may have."""
YAW_LIMIT = RPY_LIMITS[2]


def check_angles(values: ArrayLike, limits: tuple[tuple[str, float, str], ...]) -> None:
    """Refuse angles [rad] beyond their limits, as degrees given where radians are read.

    Args:
        values: one angle per entry of ``limits``, shape (len(limits),).
        limits: (name, largest magnitude [rad], that magnitude as written) per angle.

    Raises:
        InputError: the first angle out of range, with its value converted as if it were degrees.
    """
    for value, (name, limit, written) in zip(np.asarray(values, dtype=float), limits, strict=True):
        if abs(value) > limit + 1e-9:
            raise InputError(
                f"{name} {value:g} is outside [-{written}, {written}] rad; angles are in radians "
                f"({value:g} deg = {math.radians(value):.4f} rad), or pass --degrees"
            )


def parse_pose6(text: str) -> FloatArray:
    """Parse ``"x y z roll pitch yaw"`` (metres, radians) into a (4, 4) pose.

    Raises:
        InputError: not 6 finite numbers, or an angle out of range (:data:`RPY_LIMITS`).
    """
    values = _parse_numbers(text, 6, "pose 'x y z roll pitch yaw'")
    check_angles(values[3:], RPY_LIMITS)
    return pose_from_xyz_rpy(values)


def parse_base_pose(text: str) -> BasePose:
    """Parse ``"x y yaw"`` (metres, radians) into a :class:`BasePose`.

    The heading may be given in any range within +-2 pi (5.328 or -0.955, say); it comes back
    wrapped to (-pi, pi], the range every planner, map and result uses.
    """
    x, y, yaw = _parse_numbers(text, 3, "base pose 'x y yaw'")
    check_angles([yaw], (YAW_LIMIT,))
    return BasePose(float(x), float(y), float(wrap_angle(yaw)))


@dataclass(frozen=True)
class BasePose:
    """A base pose on a level floor: position (x, y) [m], heading yaw [rad] about world z, floor height z [m].

    z is 0 on the world's floor. ``matrix()`` is ``T_world_base`` with the base frame on that floor; ``to_json()`` is the shape
    every report gives a base pose in (:func:`pose_json`).
    """

    x: float
    y: float
    yaw: float
    z: float = 0.0

    def matrix(self) -> FloatArray:
        """``T_world_base``, shape (4, 4)."""
        return pose_from_xyz_rpy([self.x, self.y, self.z, 0.0, 0.0, self.yaw])

    @classmethod
    def from_xyyaw(cls, x: float, y: float, yaw: float, z: float = 0.0) -> BasePose:
        """From numbers of any numeric type (numpy's too): position [m], heading [rad, any range]."""
        return cls(float(x), float(y), float(yaw), float(z))

    def to_json(self) -> dict[str, Any]:
        """:func:`pose_json` of this pose: the heading wrapped to (-pi, pi]."""
        T = self.batch_matrix([self.x, self.y, self.yaw])[0]
        T[2, 3] = self.z
        return pose_json(T)

    @classmethod
    def from_matrix(cls, T_world_base: ArrayLike) -> BasePose:
        """Project a (4, 4) pose onto the floor: keep x, y and the heading (:func:`yaw_of`)."""
        T = np.asarray(T_world_base, dtype=float)
        return cls(float(T[0, 3]), float(T[1, 3]), float(yaw_of(T)))

    @staticmethod
    def batch_from_matrix(T_world_base: ArrayLike) -> FloatArray:
        """(N, 3) rows ``(x, y, yaw)`` of (N, 4, 4) poses projected onto the floor, as :meth:`from_matrix`."""
        T = np.asarray(T_world_base, dtype=float).reshape(-1, 4, 4)
        return np.c_[T[:, 0, 3], T[:, 1, 3], yaw_of(T)]

    @staticmethod
    def batch_matrix(xy_yaw: ArrayLike) -> FloatArray:
        """``T_world_base`` for an (N, 3) array of ``(x, y, yaw)``; returns (N, 4, 4).

        Also the planar offsets ``Trans(dx, dy, 0) @ Rz(dyaw)`` of rows ``(dx, dy, dyaw)``.
        """
        v = np.asarray(xy_yaw, dtype=float).reshape(-1, 3)
        T = np.zeros((len(v), 4, 4))
        c, s = np.cos(v[:, 2]), np.sin(v[:, 2])
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
        T[:, 2, 2] = T[:, 3, 3] = 1.0
        T[:, 0, 3], T[:, 1, 3] = v[:, 0], v[:, 1]
        return T
