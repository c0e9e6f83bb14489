"""Which object the operator points at (seed 004, section 3.1).

As in the seed (rule ``first``), the line fitted to the index finger's landmarks (in the image) is
extended from the fingertip until it enters an object's image box or leaves the image; the box it
enters first is the target. The geometry is :mod:`baseplace.placement.pointing`'s (least-squares
line through landmarks 5-8, slab-method box entry). That line cannot tell an object between the hand
and the target in the image from the target, nor a box corner beside the line; depth can: the
default rule ``finger3d`` (:func:`select`) fits the finger's 3-D line to the front-most depth points
along its image line (:func:`finger_line`) and takes the object whose centre lies closest in angle
to it (:func:`aimed_object`), falling back on ``nearest`` (the image-box centre closest in angle to
the image line), then on ``first``, when the finger has no usable depth. Chosen on the pointing
experiment's development scenes (docs/protocols/pointing_v2.md, pointing_v3.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.placement.pointing import pointing_ray, ray_box_distances

FloatArray = NDArray[np.float64]
FINGER_FROM = 6
"""The 3-D finger line is fitted from this landmark's projection (6, the PIP) to the tip: nearer the
knuckles the curled fingers lie beside and in front of the index finger."""
MIN_FINGER_SPAN = 0.03
"""The front-most points must span this much of the finger [m] (an adult's index finger is 4-6 cm
from the PIP joint to the tip): less is the back of a hand that hides a finger pointing away."""
FINGER_JUMP_M = 0.015
"""Neighbouring front-most points (1 px apart along the line) farther apart than this [m] are not
one surface: the finger's points are those joined to the tip."""
FRONT_HALF_WIDTH_PX = 3
""":func:`front_points` looks this far across the finger's image line [px]."""
MIN_FINGER_POINTS = 8
"""The 3-D finger line needs at least this many front-most points on it."""
FINGER_INLIER_M = 0.006
"""Front-most points farther than this from the fitted finger line are not the finger's [m]."""
MAX_RANSAC_POINTS = 48
"""Line hypotheses through pairs of at most this many of the finger's points, counted on them (memory ~ its cube)."""
FINGER3D_MAX_ANGLE_DEG = 16.0
"""The ``finger3d`` rule's widest angle [deg] between the 3-D finger line and an object's centre.

Chosen on the 600 development scenes (docs/protocols/pointing_v3.md), with every target detected
that the scene shows: of the 495 with a 3-D line and the target detected, the target's angle was
at most 15.4 deg (99th percentile 10.6 deg); 12 deg (protocol v2) selected 588, 15 deg 589,
16-25 deg 592 with no more wrong objects; 16 deg is the smallest angle of the plateau."""


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


SELECTION_RULES = ("finger3d", "first", "nearest")
"""``finger3d`` (the default, :func:`select`): the object at the smallest angle from the index
finger's 3-D line (from depth), falling back on ``nearest`` when the finger has no usable depth,
and on ``first`` when ``nearest`` finds no object.
``first``: the seed's rule, the first image box the line enters. ``nearest``: the object whose
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


def front_points(landmarks_px: ArrayLike, points: NDArray[np.float64], viewpoint: ArrayLike,
                 half_width: int = FRONT_HALF_WIDTH_PX) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    """The front-most depth point across the index finger at each pixel of its image line, PIP to tip.

    The finger lies in front of what is behind it (the curled fingers, the table): across the
    finger's 2-D line (landmarks 5-8, :func:`~baseplace.placement.pointing.pointing_ray`), within
    ``half_width`` px on either side, the valid point nearest to the camera is taken, one per pixel
    step from landmark :data:`FINGER_FROM`'s projection onto the line to the tip.

    Args:
        landmarks_px: (21, 2) hand landmarks [px].
        points: (H, W, 3) the frame's points (any frame) [m], NaN without depth.
        viewpoint: (3,) the camera centre in the points' frame [m].
        half_width: how far across the line to look [px].

    Returns:
        (points (K, 3), their distance along the image line from the tip (K,) [px], <= 0), K >= 0.
    """
    L = np.asarray(landmarks_px, dtype=float)[:, :2]
    P = np.asarray(points, dtype=float)
    H, W = P.shape[:2]
    origin, direction = pointing_ray(L)
    normal = np.array([-direction[1], direction[0]])
    start = float((L[FINGER_FROM] - origin) @ direction)
    along = np.arange(min(start, 0.0), 0.0 + 1e-9, 1.0)
    across = np.arange(-half_width, half_width + 1, dtype=float)
    uv = origin + along[:, None, None] * direction + across[None, :, None] * normal  # (K, A, 2)
    c, r = np.rint(uv[..., 0]).astype(int), np.rint(uv[..., 1]).astype(int)
    inside = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    xyz = np.full((*uv.shape[:2], 3), np.nan)
    xyz[inside] = P[r[inside], c[inside]]
    distance = np.linalg.norm(xyz - np.asarray(viewpoint, dtype=float), axis=2)
    distance[~np.isfinite(distance)] = np.inf
    best = np.argmin(distance, axis=1)
    keep = np.isfinite(distance[np.arange(len(along)), best])
    return xyz[np.arange(len(along)), best][keep], along[keep]


def finger_line(landmarks_px: ArrayLike, points: NDArray[np.float64], camera: ArrayLike,
                intrinsics: tuple[float, float, float, float]) -> tuple[FloatArray, FloatArray] | None:  # fmt: skip
    """The index finger's 3-D line from the front-most depth points along it: (tip (3,), direction (3,)).

    The points of :func:`front_points` are fitted by a line (SVD), those farther than
    :data:`FINGER_INLIER_M` from it dropped (depth that is not the finger's: past the tip, beside
    it), refitted; the direction is then turned into the plane through the camera centre and the
    finger's image line (where the landmarks put it; depth only sets its slope in that plane) and
    oriented from the MCP to the tip. The tip is the line's point nearest to the camera ray through
    the fingertip's image point.

    Args:
        landmarks_px: (21, 2) hand landmarks [px].
        points: (H, W, 3) the frame's points in the world frame [m], NaN without depth.
        camera: (4, 4) T_world_camera (the optical frame: x right, y down, z forward).
        intrinsics: (fx, fy, cx, cy) [px].

    Returns:
        (tip, unit direction) in the world frame, or None with fewer than :data:`MIN_FINGER_POINTS`
        finger points, or when they span less than :data:`MIN_FINGER_SPAN` along the line (the
        depth there is not the finger's: it points away, hidden behind the hand).
    """
    T = np.asarray(camera, dtype=float)
    centre = T[:3, 3]
    pts, along = front_points(landmarks_px, points, centre)
    if len(pts) < MIN_FINGER_POINTS:
        return None
    # the run of points joined to the fingertip: a jump in depth is where the hand (or a curled
    # finger) hides the index finger; a short run at the very tip is what lies past it
    cuts = np.r_[0, np.nonzero(np.linalg.norm(np.diff(pts, axis=0), axis=1) > FINGER_JUMP_M)[0] + 1, len(pts)]
    runs = [(a, b) for a, b in itertools.pairwise(cuts) if b - a >= MIN_FINGER_POINTS]
    if not runs:
        return None
    pts, along = pts[runs[-1][0] : runs[-1][1]], along[runs[-1][0] : runs[-1][1]]
    keep = _line_inliers(pts, FINGER_INLIER_M)
    if keep.sum() < MIN_FINGER_POINTS:
        return None
    mean = pts[keep].mean(axis=0)
    axis = np.linalg.svd(pts[keep] - mean)[2][0]
    fx, fy, cx, cy = intrinsics
    origin_px, direction_px = pointing_ray(np.asarray(landmarks_px, dtype=float)[:, :2])

    def view_ray(uv: FloatArray) -> FloatArray:
        ray = T[:3, :3] @ np.array([(uv[0] - cx) / fx, (uv[1] - cy) / fy, 1.0])
        return ray / np.linalg.norm(ray)

    tip_ray = view_ray(origin_px)
    normal = np.cross(tip_ray, view_ray(origin_px + 20.0 * direction_px))
    normal /= np.linalg.norm(normal)
    axis = axis - (axis @ normal) * normal
    t = (pts[keep] - mean) @ axis
    if np.ptp(t) < MIN_FINGER_SPAN or np.linalg.norm(axis) < 1e-6:
        return None
    axis /= np.linalg.norm(axis)
    if np.polyfit(along[keep], (pts[keep] - mean) @ axis, 1)[0] < 0:
        axis = -axis  # from the MCP (most negative along the image line) to the tip
    # the line's point nearest to the camera ray through the fingertip (closest points of two lines)
    w = mean - centre
    b = axis @ tip_ray
    denominator = 1.0 - b * b
    if denominator < 1e-9:
        return None
    s = (b * (tip_ray @ w) - (axis @ w)) / denominator
    return mean + s * axis, axis


def _line_inliers(pts: FloatArray, tolerance: float) -> NDArray[np.bool_]:
    """The points within ``tolerance`` of the line through the pair of points that has the most (exhaustive RANSAC).

    Every pair at least a third of the points apart is tried (ties: the first pair), so the result
    does not depend on a random draw; beyond :data:`MAX_RANSAC_POINTS` points, the pairs and their
    counts come from that many spread evenly over them. Returns (K,) bool over all points.
    """
    n = len(pts)
    sample = pts  # hypotheses and their counts from at most MAX_RANSAC_POINTS points, evenly along the finger
    if n > MAX_RANSAC_POINTS:
        sample = pts[np.linspace(0, n - 1, MAX_RANSAC_POINTS).round().astype(int)]
    m = len(sample)
    i, j = np.triu_indices(m, k=max(m // 3, 1))
    if len(i) == 0:
        return np.zeros(n, dtype=bool)
    axis = sample[j] - sample[i]
    length = np.linalg.norm(axis, axis=1)
    axis = axis / np.maximum(length, 1e-12)[:, None]
    offset = sample[None, :, :] - sample[i][:, None, :]  # (pairs, m, 3): memory bounded by MAX_RANSAC_POINTS
    along = np.einsum("pkd,pd->pk", offset, axis)
    residual = np.linalg.norm(offset - along[..., None] * axis[:, None, :], axis=2)
    best = int(np.argmax(np.where(length > 1e-6, (residual <= tolerance).sum(axis=1), -1)))
    rel = pts - sample[i[best]]
    return np.asarray(np.linalg.norm(rel - np.outer(rel @ axis[best], axis[best]), axis=1) <= tolerance)


def aimed_object(tip: ArrayLike, direction: ArrayLike, boxes_world: ArrayLike,
                 max_angle_deg: float = FINGER3D_MAX_ANGLE_DEG) -> tuple[int | None, FloatArray]:  # fmt: skip
    """The object whose box centre lies at the smallest angle from the 3-D finger line, seen from its tip.

    Args:
        tip: (3,) the fingertip [m].
        direction: (3,) the finger's unit direction.
        boxes_world: (M, 2, 3) objects' world boxes (min corner, max corner) [m].
        max_angle_deg: objects farther from the line than this [deg] are not chosen.

    Returns:
        (the object's index or None, the angles (M,) [deg]).
    """
    boxes = np.asarray(boxes_world, dtype=float).reshape(-1, 2, 3)
    to_centre = boxes.mean(axis=1) - np.asarray(tip, dtype=float)
    distance = np.maximum(np.linalg.norm(to_centre, axis=1), 1e-9)
    angle = np.degrees(np.arccos(np.clip(to_centre @ np.asarray(direction, dtype=float) / distance, -1, 1)))
    if len(angle) == 0:
        return None, angle
    best = int(np.argmin(angle))
    return (best if angle[best] <= max_angle_deg else None), angle


def select(rule: str, landmarks_px: ArrayLike, image_boxes: ArrayLike, boxes_world: ArrayLike,
           points_world: NDArray[np.float64], camera: ArrayLike, intrinsics: tuple[float, float, float, float],
           width: int, height: int) -> tuple[Ray, Ray | None]:  # fmt: skip
    """The object pointed at by one of :data:`SELECTION_RULES`: (the image line, the 3-D finger line).

    The image line (:func:`image_ray`) ends at the selected object (its ``hit``), or at the image
    border when none is selected. The 3-D line (:func:`finger_line`, None when the finger has no
    usable depth) hits the object :func:`aimed_object` finds, whatever the rule; ``finger3d``
    selects that object, and with no 3-D line the ``nearest`` one, else the ``first``
    (:func:`_image_fallback`).

    Args:
        rule: one of :data:`SELECTION_RULES`.
        landmarks_px: (21, 2) hand landmarks [px].
        image_boxes: (M, 2, 2) objects' pixel boxes (min corner, max corner), inclusive.
        boxes_world: (M, 2, 3) the same objects' world boxes [m].
        points_world: (H, W, 3) the frame's world points [m], NaN without depth.
        camera: (4, 4) T_world_camera.
        intrinsics: (fx, fy, cx, cy) [px].
        width: the image width [px].
        height: the image height [px].
    """
    image_boxes = np.asarray(image_boxes, dtype=float).reshape(-1, 2, 2)
    line = image_ray(landmarks_px, image_boxes, width, height)
    finger = finger_line(landmarks_px, points_world, camera, intrinsics)
    ray3 = None
    if finger is not None:
        hit, _ = aimed_object(*finger, boxes_world)
        centre = np.asarray(boxes_world, dtype=float).reshape(-1, 2, 3).mean(axis=1)
        length = float("inf") if hit is None else float((centre[hit] - finger[0]) @ finger[1])
        ray3 = Ray(finger[0], finger[1], hit, length)
    if rule == "nearest":
        return nearest_box(line, image_boxes), ray3
    if rule == "finger3d" and ray3 is None:
        return _image_fallback(line, image_boxes), ray3
    if rule == "finger3d":
        assert ray3 is not None
        if ray3.hit is None:
            return Ray(line.origin, line.direction, None, line.length), ray3
        to_centre = image_boxes[ray3.hit].mean(axis=0) - line.origin
        return Ray(line.origin, line.direction, ray3.hit, max(float(to_centre @ line.direction), 0.0)), ray3
    return line, ray3


def _image_fallback(line: Ray, image_boxes: FloatArray) -> Ray:
    """``finger3d`` without a 3-D line: the ``nearest`` box, else the first box the line enters (``first``).

    A finger without usable depth mostly points away from the camera, hidden behind the hand: its
    image is short (15-20 px), 2 px of landmark noise turn its line by 10 deg or more, and the
    target, near the fingertip in the image, has its centre beyond ``nearest``'s angle although
    the line enters its box (9 of the 105 such development scenes, docs/protocols/pointing_v3.md).
    """
    chosen = nearest_box(line, image_boxes)
    return chosen if chosen.hit is not None else line


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
    "aimed_object",
    "border_distance",
    "depth_hole",
    "finger_line",
    "front_points",
    "image_ray",
    "nearest_box",
    "select",
]
