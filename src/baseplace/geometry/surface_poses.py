"""Base poses constrained to a support plane (seed 000, section III-A).

A plane in Hessian normal form ``n . p + d = 0`` with the unit normal ``n`` pointing up
(``n_z > 0``). A base pose on it is parameterized by ``(x, y, gamma)``: the position is the point
of the plane above ``(x, y)``, and the orientation is ``R = R_{x,y,0} Rz(gamma)`` where
``R_{x,y,0} = (y_hat x n, y_hat, n)`` and ``y_hat`` is the unit vector in the plane whose
projection onto the xy plane points along the world y axis. On the flat floor (``n = e_z``)
``R_{x,y,0}`` is the identity and gamma is the ordinary yaw.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray


def _unit_up_normal(normal: ArrayLike) -> FloatArray:
    n = np.asarray(normal, dtype=float).reshape(3)
    norm = np.linalg.norm(n)
    if not np.isfinite(norm) or norm < 1e-12:
        raise InputError(f"plane normal must be a finite non-zero vector, got {n.tolist()}")
    n = n / norm
    if n[2] <= 1e-6:
        raise InputError(
            f"support plane normal must point up (n_z > 0), got {n.round(4).tolist()}; "
            "flip the plane (n, d) -> (-n, -d) or check the cloud's up direction"
        )
    return n


def plane_frame(normal: ArrayLike) -> FloatArray:
    """``R_{x,y,0} = (y_hat x n, y_hat, n)`` of seed 000 III-A for an upward plane normal.

    Args:
        normal: plane normal (3,), any length, must have a positive z component.

    Returns:
        (3, 3) rotation whose columns are the base x, y and z axes at gamma = 0.
    """
    n = _unit_up_normal(normal)
    # The in-plane unit vector with no x component: its xy projection points along +y.
    y_hat = np.array([0.0, n[2], -n[1]]) / np.hypot(n[1], n[2])
    x_hat = np.cross(y_hat, n)
    return np.column_stack([x_hat, y_hat, n])


def plane_base_poses(x: ArrayLike, y: ArrayLike, gamma: ArrayLike, normal: ArrayLike, d: float) -> FloatArray:
    """World base poses ``T_world_base`` on the plane ``n . p + d = 0``.

    Args:
        x: base x [m], shape (N,) (or broadcastable with y and gamma).
        y: base y [m].
        gamma: rotation about the plane normal [rad]; 0 means the base y axis projects onto +y.
        normal: upward plane normal (3,).
        d: plane offset [m] in ``n . p + d = 0``.

    Returns:
        (N, 4, 4) poses; the base origin lies on the plane and the base z axis is ``n``.
    """
    n = _unit_up_normal(normal)
    scale = float(np.linalg.norm(np.asarray(normal, dtype=float)))
    d = float(d) / scale
    x, y, gamma = np.broadcast_arrays(*(np.asarray(a, dtype=float).ravel() for a in (x, y, gamma)))
    R0 = plane_frame(n)
    c, s = np.cos(gamma), np.sin(gamma)
    T = np.zeros((len(x), 4, 4))
    # R = R0 @ Rz(gamma): columns x' = c x_hat + s y_hat, y' = -s x_hat + c y_hat, z' = n.
    T[:, :3, 0] = c[:, None] * R0[:, 0] + s[:, None] * R0[:, 1]
    T[:, :3, 1] = -s[:, None] * R0[:, 0] + c[:, None] * R0[:, 1]
    T[:, :3, 2] = R0[:, 2]
    T[:, 0, 3] = x
    T[:, 1, 3] = y
    T[:, 2, 3] = -(d + n[0] * x + n[1] * y) / n[2]
    T[:, 3, 3] = 1.0
    return T
