"""Target selection by a pointing gesture (seed 004, section 3.1).

The seed fits a line to the detected landmarks of the pointing finger, extends it from the
fingertip, and takes the object whose bounding box the line meets first. Landmarks follow
MediaPipe's hand model (21 points, https://developers.google.com/mediapipe/solutions/vision/hand_landmarker):
the index finger is ``INDEX_FINGER_MCP`` (5), ``_PIP`` (6), ``_DIP`` (7) and ``_TIP`` (8). Here
the line is the least-squares fit through those four points (for a straight finger, the line from
MCP through the tip), oriented from MCP to tip, starting at the tip's projection onto the line.

Everything works in 3-D (landmarks and axis-aligned boxes in the camera or map frame, metres) or,
as in the seed, in 2-D (pixel landmarks and image boxes). Boxes are hit by the slab method.
When the ray meets no box, :func:`pointed_object` returns None: finding nothing is an outcome a
caller may retry (wait for another gesture), not an error.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray

N_LANDMARKS = 21
INDEX_FINGER = (5, 6, 7, 8)
"""MediaPipe landmark indices of the index finger: MCP, PIP, DIP, TIP."""


def pointing_ray(landmarks: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The pointing ray of a hand: origin at the fingertip, unit direction away from the hand.

    Args:
        landmarks: (21, D) MediaPipe hand landmarks, D = 3 (metres, any frame) or 2 (pixels).

    Returns:
        (origin (D,), direction (D,) unit): the least-squares line through landmarks 5-8, oriented
        from MCP (5) to TIP (8), starting at the tip's projection onto it.

    Raises:
        InputError: wrong shape, NaN/inf, or an index finger without length.
    """
    L = np.asarray(landmarks, dtype=float)
    if L.ndim != 2 or L.shape[0] != N_LANDMARKS or L.shape[1] not in (2, 3):
        raise InputError(f"hand landmarks must have shape (21, 3) or (21, 2) (MediaPipe), got {L.shape}")
    if not np.all(np.isfinite(L)):
        raise InputError("hand landmarks contain NaN or infinity")
    finger = L[list(INDEX_FINGER)]
    mcp, tip = finger[0], finger[-1]
    span = float(np.linalg.norm(tip - mcp))
    if span < 1e-9 * max(1.0, float(np.abs(finger).max())):
        raise InputError("the index finger's MCP (5) and tip (8) coincide: no pointing direction")
    centre = finger.mean(axis=0)
    direction = np.linalg.svd(finger - centre)[2][0]
    if direction @ (tip - mcp) < 0:
        direction = -direction
    origin = centre + ((tip - centre) @ direction) * direction
    return origin, direction


def _boxes(boxes: ArrayLike, dim: int) -> FloatArray:
    B = np.asarray(boxes, dtype=float)
    if B.ndim == 2:
        B = B[None]
    if B.ndim != 3 or B.shape[1:] != (2, dim):
        raise InputError(f"boxes must have shape (M, 2, {dim}) as (min corner, max corner), got {B.shape}")
    if not np.all(np.isfinite(B)):
        raise InputError("boxes contain NaN or infinity")
    bad = np.nonzero(np.any(B[:, 0] > B[:, 1], axis=1))[0]
    if len(bad):
        raise InputError(f"box {int(bad[0])} has a min corner above its max corner: {B[bad[0]].tolist()}")
    return B


def ray_box_distances(origin: ArrayLike, direction: ArrayLike, boxes: ArrayLike) -> FloatArray:
    """Distance along a ray to where it enters each axis-aligned box (slab method).

    Args:
        origin: (D,) ray origin.
        direction: (D,) ray direction (normalised here).
        boxes: (M, 2, D) closed boxes as (min corner, max corner).

    Returns:
        (M,) entry distance >= 0 (0 when the origin lies inside), inf when the ray misses the box.
    """
    o = np.asarray(origin, dtype=float).reshape(-1)
    d = np.asarray(direction, dtype=float).reshape(-1)
    if o.shape != d.shape or o.shape[0] not in (2, 3) or not np.all(np.isfinite(np.r_[o, d])):
        raise InputError(
            f"ray origin and direction must be finite and both 2-D or 3-D, got {o.shape}, {d.shape}"
        )
    norm = float(np.linalg.norm(d))
    if norm == 0:
        raise InputError("ray direction must not be zero")
    d = d / norm
    B = _boxes(boxes, len(o))
    lo, hi = B[:, 0], B[:, 1]
    parallel = d == 0
    safe = np.where(parallel, 1.0, d)
    t1, t2 = (lo - o) / safe, (hi - o) / safe
    within = (lo <= o) & (o <= hi)  # for axes the ray runs parallel to: inside the slab or never
    t_in = np.where(parallel, np.where(within, -np.inf, np.inf), np.minimum(t1, t2))
    t_out = np.where(parallel, np.where(within, np.inf, -np.inf), np.maximum(t1, t2))
    near, far = t_in.max(axis=1), t_out.min(axis=1)
    entry = np.maximum(near, 0.0)
    return np.where(far >= entry, entry, np.inf)


def pointed_object(landmarks: ArrayLike, boxes: ArrayLike, max_range: float = math.inf) -> int | None:
    """Index of the box the pointing ray enters first, or None when it meets none within ``max_range``.

    Args:
        landmarks: (21, D) MediaPipe hand landmarks (D = 3 [m] or 2 [px]).
        boxes: (M, 2, D) detected objects' axis-aligned boxes (min corner, max corner), same frame.
        max_range: ignore boxes entered farther than this from the fingertip (the seed's image
            boundary; default: unlimited).

    Returns:
        The box index (the first on a tie), or None.

    Raises:
        InputError: malformed landmarks or boxes.
    """
    origin, direction = pointing_ray(landmarks)
    B = _boxes(boxes, len(origin))
    if len(B) == 0:
        return None
    t: NDArray[np.float64] = ray_box_distances(origin, direction, B)
    best = int(np.argmin(t))
    return best if np.isfinite(t[best]) and t[best] <= max_range else None


__all__ = ["INDEX_FINGER", "N_LANDMARKS", "pointed_object", "pointing_ray", "ray_box_distances"]
