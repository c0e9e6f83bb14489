"""Which object the operator points at (seed 004, section 3.1).

As in the seed, the line fitted to the index finger's landmarks (in the image) is extended from the
fingertip until it enters an object's image box or leaves the image; the box it enters first is the
target. The geometry is :mod:`baseplace.placement.pointing`'s (least-squares line through landmarks
5-8, slab-method box entry). Beside it, when the depth at the index finger is valid, the same fit
through the finger's 3-D points gives a world ray and the world box it enters first: reported, not
used to choose (the seed's choice is the image line's).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.placement.pointing import INDEX_FINGER, pointing_ray, ray_box_distances

FloatArray = NDArray[np.float64]
MIN_FINGER_LENGTH = 0.01
"""The 3-D ray needs the index finger's MCP and tip at least this far apart [m]."""


@dataclass(frozen=True)
class Ray:
    """A pointing ray and where it ends.

    Attributes:
        origin: (D,) at the fingertip (D = 2: pixels; D = 3: world metres).
        direction: (D,) unit.
        hit: index of the box it enters first, or None.
        length: distance from the origin to the box entry, or to the image border (2-D) when it
            meets no box; inf for a 3-D ray that meets nothing.
    """

    origin: FloatArray
    direction: FloatArray
    hit: int | None
    length: float

    @property
    def end(self) -> FloatArray:
        """Where the ray stops (D,); the origin when the length is infinite."""
        return self.origin + (self.length if np.isfinite(self.length) else 0.0) * self.direction

    def to_json(self) -> dict[str, Any]:
        """``{"origin", "direction", "end", "hit", "length"}`` (length null when infinite)."""
        return {"origin": np.round(self.origin, 4).tolist(), "direction": np.round(self.direction, 5).tolist(),
                "end": np.round(self.end, 4).tolist(), "hit": self.hit,
                "length": round(self.length, 4) if np.isfinite(self.length) else None}  # fmt: skip


def border_distance(origin: ArrayLike, direction: ArrayLike, width: int, height: int) -> float:
    """Distance along a unit 2-D ray from ``origin`` [px] to where it leaves the image (0 if outside)."""
    o, d = np.asarray(origin, dtype=float), np.asarray(direction, dtype=float)
    hi = np.array([width - 0.5, height - 0.5])
    lo = np.array([-0.5, -0.5])
    if np.any(o < lo) or np.any(o > hi):
        return 0.0
    exits = [((hi[k] if d[k] > 0 else lo[k]) - o[k]) / d[k] for k in range(2) if d[k] != 0]
    return float(min(exits))


def image_ray(landmarks_px: ArrayLike, image_boxes: ArrayLike, width: int, height: int) -> Ray:
    """The seed's selection: the index-finger line from the fingertip to the first image box or the border.

    Args:
        landmarks_px: (21, 2) hand landmarks (u, v) [px].
        image_boxes: (M, 2, 2) objects' pixel boxes (min corner, max corner), inclusive pixel indices.
        width: image width [px].
        height: image height [px].
    """
    origin, direction = pointing_ray(np.asarray(landmarks_px, dtype=float)[:, :2])
    border = border_distance(origin, direction, width, height)
    boxes = np.asarray(image_boxes, dtype=float).reshape(-1, 2, 2)
    if len(boxes):
        pixel_edges = boxes + np.array([[-0.5, -0.5], [0.5, 0.5]])  # a pixel covers +-0.5 around its index
        t = ray_box_distances(origin, direction, pixel_edges)
        best = int(np.argmin(t))
        if np.isfinite(t[best]) and t[best] <= border:
            return Ray(origin, direction, best, float(t[best]))
    return Ray(origin, direction, None, border)


SELECTION_RULES = ("first", "nearest")
"""``first``: the seed's rule, the first image box the line enters. ``nearest``: the object whose
image-box centre lies at the smallest angle from the line, seen from the fingertip, within
:data:`NEAREST_MAX_ANGLE_DEG` (robust to a line grazing the corner of a nearer box, or passing just beside a
small target)."""
NEAREST_MAX_ANGLE_DEG = 12.0
"""The ``nearest`` rule's widest angle [deg] between the line and an object's centre, chosen on the
pointing experiment's development scenes (docs/protocols/pointing.md; 640x480): of 100, 61 selected at
4 deg, 75 at 6, 81 at 8, 85 at 10, 88 at 12, 15 and 20 (``first``: 83); 12 deg is the smallest angle
of the plateau."""


def nearest_box(ray: Ray, image_boxes: ArrayLike, max_angle_deg: float = NEAREST_MAX_ANGLE_DEG) -> Ray:
    """The ``nearest`` rule: the box whose centre, seen from the fingertip, lies closest in angle to the line.

    Args:
        ray: the image line from :func:`image_ray` (its origin, direction and the border).
        image_boxes: (M, 2, 2) objects' pixel boxes (min corner, max corner).
        max_angle_deg: boxes whose centre lies farther from the line than this [deg] are not chosen.

    Returns:
        The line ending at the chosen box's centre, or ``ray`` unchanged (hit None) when none is within the angle.
    """
    boxes = np.asarray(image_boxes, dtype=float).reshape(-1, 2, 2)
    if len(boxes) == 0:
        return Ray(ray.origin, ray.direction, None, ray.length)
    to_centre = boxes.mean(axis=1) - ray.origin
    distance = np.linalg.norm(to_centre, axis=1)
    cos = (to_centre @ ray.direction) / np.maximum(distance, 1e-9)
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    best = int(np.argmin(angle))
    if angle[best] > max_angle_deg:
        return Ray(ray.origin, ray.direction, None, ray.length)
    return Ray(ray.origin, ray.direction, best, float(distance[best] * cos[best]))


def finger_points(landmarks_px: ArrayLike, points: NDArray[np.float64], window: int = 2) -> FloatArray | None:
    """The index finger's 3-D points (4, 3) from an organised cloud (H, W, 3), or None.

    Each of MCP, PIP, DIP and TIP is the median of the valid points within ``window`` px of its
    landmark; None when one of them has no depth.
    """
    L = np.asarray(landmarks_px, dtype=float)
    H, W = points.shape[:2]
    out = []
    for i in INDEX_FINGER:
        u, v = L[i, 0], L[i, 1]
        r, c = round(v), round(u)
        if not (0 <= r < H and 0 <= c < W):
            return None
        patch = points[max(r - window, 0) : r + window + 1, max(c - window, 0) : c + window + 1].reshape(
            -1, 3
        )
        patch = patch[np.all(np.isfinite(patch), axis=1)]
        if len(patch) == 0:
            return None
        out.append(np.median(patch, axis=0))
    return np.asarray(out)


def world_ray(
    landmarks_px: ArrayLike, points_world: NDArray[np.float64], boxes_world: ArrayLike
) -> Ray | None:
    """The 3-D ray through the index finger's depth points, and the world box it enters first.

    Args:
        landmarks_px: (21, 2) hand landmarks [px].
        points_world: (H, W, 3) the frame's world points [m], NaN without depth.
        boxes_world: (M, 2, 3) objects' world boxes [m].

    Returns:
        The ray, or None when the finger has no depth or its points are closer than
        :data:`MIN_FINGER_LENGTH` (the finger points along the camera's view).
    """
    finger = finger_points(landmarks_px, points_world)
    if finger is None or np.linalg.norm(finger[-1] - finger[0]) < MIN_FINGER_LENGTH:
        return None
    full = np.zeros((21, 3))
    full[list(INDEX_FINGER)] = finger
    origin, direction = pointing_ray(full)
    boxes = np.asarray(boxes_world, dtype=float).reshape(-1, 2, 3)
    if len(boxes):
        t = ray_box_distances(origin, direction, boxes)
        best = int(np.argmin(t))
        if np.isfinite(t[best]):
            return Ray(origin, direction, best, float(t[best]))
    return Ray(origin, direction, None, float("inf"))


def depth_hole(
    ray: Ray, depth: NDArray[np.floating[Any]], start: float = 0.0
) -> tuple[int, FloatArray | None]:
    """The longest run of pixels without depth along a 2-D ray, from ``start`` px past the fingertip.

    Returns:
        (its length [px], its first pixel (u, v) or None when the ray has depth everywhere).
    """
    n = int(ray.length - start)
    if n <= 0:
        return 0, None
    t = start + np.arange(n) + 0.5
    uv = np.rint(ray.origin + t[:, None] * ray.direction).astype(int)
    H, W = depth.shape
    uv = uv[(uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)]
    missing = ~np.isfinite(depth[uv[:, 1], uv[:, 0]])
    best, best_start, run = 0, -1, 0
    for k, m in enumerate(missing):
        run = run + 1 if m else 0
        if run > best:
            best, best_start = run, k - run + 1
    return best, None if best == 0 else uv[best_start].astype(float)


__all__ = [
    "NEAREST_MAX_ANGLE_DEG",
    "SELECTION_RULES",
    "Ray",
    "border_distance",
    "depth_hole",
    "finger_points",
    "image_ray",
    "nearest_box",
    "world_ray",
]
