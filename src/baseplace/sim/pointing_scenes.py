"""Generated RGB-D frames of a person pointing at an object on a table (the pointing experiment).

A head camera (pinhole, optical frame) looks down at a table standing on the floor; boxes and
vertical cylinders of several sizes stand on the table, at least ``gap`` apart. The operator's
hand (21 MediaPipe landmarks, a pointing hand: index finger stretched, the others curled) is placed
by the generator above the table beside the target, its index finger aimed at the target's centre
in 3-D; its landmarks are projected into the image (MediaPipe's normalised coordinates) and
perturbed by ``landmark_sigma_px``. The hand is rendered into the depth image as spheres (fingers
and palm), as a real depth camera sees it. Depth noise follows the Kinect's axial model of Nguyen,
Izadi and Lovell (2012), ``sigma(r) = 0.0012 + 0.0019 (r - 0.4)^2`` [m], as ``sim/camera.py``.

Every frame is rendered by ray casting per pixel (floor plane, table box, object boxes and
cylinders, hand spheres); nothing here is used by the library.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.perception.rgbd import Intrinsics
from baseplace.sim.camera import look_at

FloatArray = NDArray[np.float64]


PALETTE = {-1: (0, 0, 0), 0: (120, 120, 120), 1: (150, 110, 70), 1000: (225, 180, 150)}
"""RGB of what is not an object: nothing, the floor, the table, the hand (objects get random colours)."""


@dataclass(frozen=True)
class PointingSceneSettings:
    """The generator's ranges (the experiment's protocol fixes them).

    Attributes:
        width, height: image size [px].
        fov_deg: horizontal field of view [deg].
        camera_height: camera height above the floor [m].
        table_size: table top (x, y) [m]; its near edge 0.5 m in front of the camera.
        table_height: range of the table top's height [m].
        n_objects: range (inclusive) of objects on the table.
        box_side: range of a box's side [m].
        cylinder_radius, cylinder_height: ranges of a cylinder's radius and height [m].
        gap: least horizontal gap between two objects [m].
        hand_distance: range of the fingertip's horizontal distance from the target's centre [m].
        hand_height: range of the fingertip's height above the target's top [m].
        landmark_sigma_px: landmark noise (each coordinate) [px].
        depth_noise: apply the axial noise model.
    """

    width: int = 640
    height: int = 480
    fov_deg: float = 65.0
    camera_height: float = 1.35
    table_size: tuple[float, float] = (0.8, 1.2)
    table_height: tuple[float, float] = (0.7, 0.8)
    n_objects: tuple[int, int] = (2, 5)
    box_side: tuple[float, float] = (0.04, 0.14)
    cylinder_radius: tuple[float, float] = (0.025, 0.06)
    cylinder_height: tuple[float, float] = (0.06, 0.22)
    gap: float = 0.06
    hand_distance: tuple[float, float] = (0.2, 0.35)
    hand_height: tuple[float, float] = (0.12, 0.25)
    landmark_sigma_px: float = 2.0
    depth_noise: bool = True


@dataclass(frozen=True)
class TrueObject:
    """An object's truth: ``shape`` "box" (size = sides) or "cylinder" (size = 2r, 2r, height), world frame."""

    shape: str
    centre: FloatArray
    size: FloatArray

    def to_json(self) -> dict[str, Any]:
        """``{"shape", "centre", "size"}``."""
        return {
            "shape": self.shape,
            "centre": self.centre.round(5).tolist(),
            "size": self.size.round(5).tolist(),
        }


@dataclass(frozen=True)
class PointingScene:
    """One generated frame and its truth.

    Attributes:
        rgb: (H, W, 3) uint8.
        depth: (H, W) float32 [m], NaN without return.
        intrinsics: the camera.
        T_world_camera: (4, 4) the optical frame in the world.
        objects: the objects' truth.
        target: index of the object pointed at.
        landmarks: (21, 3) MediaPipe normalised landmarks (x, y in image fractions, z relative).
        landmarks_world: (21, 3) the hand's true landmarks [m].
    """

    rgb: NDArray[np.uint8]
    depth: NDArray[np.float32]
    intrinsics: Intrinsics
    T_world_camera: FloatArray
    objects: list[TrueObject]
    target: int
    landmarks: FloatArray
    landmarks_world: FloatArray = field(repr=False)

    def landmarks_json(self) -> list[dict[str, float]]:
        """The landmarks as MediaPipe writes them: ``[{"x", "y", "z"}, ...]``."""
        return [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in self.landmarks]


def _hand(tip: FloatArray, direction: FloatArray, rng: np.random.Generator) -> FloatArray:
    """(21, 3) world landmarks of a right hand pointing along ``direction`` with its index tip at ``tip``."""
    d = direction / np.linalg.norm(direction)
    side = np.cross(d, [0.0, 0.0, 1.0])
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-6 else np.array([0.0, 1.0, 0.0])
    down = np.cross(side, d)  # palm faces down-ish: the curled fingers fold this way
    L = np.zeros((21, 3))
    seg = np.array([0.04, 0.025, 0.022]) * rng.uniform(0.9, 1.1)  # MCP-PIP, PIP-DIP, DIP-TIP [m]
    L[8] = tip
    L[7] = tip - seg[2] * d
    L[6] = L[7] - seg[1] * d
    L[5] = L[6] - seg[0] * d
    L[0] = L[5] - 0.09 * d - 0.02 * side  # wrist
    for k, mcp in enumerate((9, 13, 17)):
        offset = (k + 1) * 0.02
        L[mcp] = L[5] - offset * side - 0.005 * k * d
        L[mcp + 1] = L[mcp] + 0.035 * d + 0.01 * down  # PIP forward
        L[mcp + 2] = L[mcp + 1] + 0.02 * down - 0.005 * d  # DIP folded down
        L[mcp + 3] = L[mcp + 2] - 0.02 * d - 0.005 * down  # TIP back towards the palm
    L[1] = L[0] + 0.03 * side + 0.02 * d  # thumb along the side
    L[2] = L[1] + 0.02 * side + 0.02 * d
    L[3] = L[2] + 0.01 * side + 0.02 * d + 0.01 * down
    L[4] = L[3] + 0.015 * d + 0.01 * down
    return L


def _spheres(L: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Spheres (centres (K, 3), radii (K,)) standing for the hand's fingers and palm in depth."""
    centres, radii = [], []
    chains = [
        (0, 1, 2, 3, 4),
        (5, 6, 7, 8),
        (9, 10, 11, 12),
        (13, 14, 15, 16),
        (17, 18, 19, 20),
        (0, 5),
        (0, 9),
        (0, 13),
        (0, 17),
        (5, 17),
    ]
    for chain in chains:
        for a, b in itertools.pairwise(chain):
            for t in np.linspace(0, 1, 4):
                centres.append(L[a] + t * (L[b] - L[a]))
                radii.append(0.009 if a != 0 else 0.015)
    return np.asarray(centres), np.asarray(radii)


def _render(o: FloatArray, rays: FloatArray, table: FloatArray, objects: list[TrueObject],
            spheres: tuple[FloatArray, FloatArray]) -> tuple[FloatArray, NDArray[np.int64]]:  # fmt: skip
    """Ray parameter t (N,) of the first hit and what was hit.

    Rays have camera z = 1, so t is the depth. Labels: -1 none, 0 floor, 1 table, 2 + k object k, 1000 hand.
    """
    n = len(rays)
    best = np.full(n, np.inf)
    what = np.full(n, -1, dtype=np.int64)

    def keep(t: FloatArray, label: int) -> None:
        better = (t > 1e-6) & (t < best)
        best[better], what[better] = t[better], label

    with np.errstate(divide="ignore", invalid="ignore"):
        keep(np.where(rays[:, 2] < 0, -o[2] / rays[:, 2], np.inf), 0)
        keep(_box_hits(o, rays, table), 1)
        for k, obj in enumerate(objects):
            lo, hi = obj.centre - obj.size / 2, obj.centre + obj.size / 2
            if obj.shape == "box":
                keep(_box_hits(o, rays, np.stack([lo, hi])), 2 + k)
            else:
                keep(_cylinder_hits(o, rays, obj.centre[:2], obj.size[0] / 2, lo[2], hi[2]), 2 + k)
        for c, r in zip(*spheres, strict=True):
            oc = o - c
            b = rays @ oc
            a = np.einsum("ij,ij->i", rays, rays)
            disc = b * b - a * (oc @ oc - r * r)
            keep(np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / a, np.inf), 1000)
    return best, what


def _box_hits(o: FloatArray, rays: FloatArray, box: FloatArray) -> FloatArray:
    t1, t2 = (box[0] - o) / rays, (box[1] - o) / rays
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((far >= near) & (far > 0), near, np.inf)


def _cylinder_hits(
    o: FloatArray, rays: FloatArray, c: FloatArray, r: float, z0: float, z1: float
) -> FloatArray:
    ox, oy = o[0] - c[0], o[1] - c[1]
    a = rays[:, 0] ** 2 + rays[:, 1] ** 2
    b = ox * rays[:, 0] + oy * rays[:, 1]
    disc = b * b - a * (ox * ox + oy * oy - r * r)
    t_side = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / a, np.inf)
    z = o[2] + t_side * rays[:, 2]
    t_side = np.where((z >= z0) & (z <= z1), t_side, np.inf)
    t_top = (z1 - o[2]) / rays[:, 2]
    x, y = ox + t_top * rays[:, 0], oy + t_top * rays[:, 1]
    t_top = np.where((x * x + y * y <= r * r) & (rays[:, 2] < 0), t_top, np.inf)
    return np.asarray(np.minimum(t_side, t_top))


def generate_pointing_scene(seed: int, settings: PointingSceneSettings | None = None) -> PointingScene:
    """One frame of a person pointing at one of the objects on a table, from its seed."""
    s = settings or PointingSceneSettings()
    rng = np.random.default_rng(seed)
    fx = s.width / 2 / math.tan(math.radians(s.fov_deg) / 2)
    K = Intrinsics(fx, fx, (s.width - 1) / 2, (s.height - 1) / 2)
    top = rng.uniform(*s.table_height)
    x0 = 0.5
    table = np.array([[x0, -s.table_size[1] / 2, 0.0], [x0 + s.table_size[0], s.table_size[1] / 2, top]])
    T = look_at([0.0, 0.0, s.camera_height], [x0 + s.table_size[0] / 2, 0.0, top])
    objects: list[TrueObject] = []
    n_objects = int(rng.integers(s.n_objects[0], s.n_objects[1] + 1))
    for _ in range(200):
        if len(objects) == n_objects:
            break
        if rng.random() < 0.5:
            size = np.r_[rng.uniform(*s.box_side, 2), rng.uniform(*s.box_side)]
            shape = "box"
        else:
            r = rng.uniform(*s.cylinder_radius)
            size, shape = np.array([2 * r, 2 * r, rng.uniform(*s.cylinder_height)]), "cylinder"
        margin = size[:2] / 2 + 0.05
        xy = rng.uniform(table[0, :2] + margin, table[1, :2] - margin)
        if any(np.all(np.abs(xy - o.centre[:2]) < (size[:2] + o.size[:2]) / 2 + s.gap) for o in objects):
            continue
        objects.append(TrueObject(shape, np.r_[xy, top + size[2] / 2], size))
    target = int(rng.integers(len(objects)))
    goal = objects[target].centre
    v, u = np.mgrid[0 : s.height, 0 : s.width]
    rays_cam = K.pixel_rays(u.ravel(), v.ravel())
    rays = rays_cam @ T[:3, :3].T
    o = T[:3, 3]
    for _ in range(200):  # the hand: beside the target, in view, hiding no object from the camera
        angle = rng.uniform(0, 2 * math.pi)
        tip = goal + np.r_[rng.uniform(*s.hand_distance) * np.array([math.cos(angle), math.sin(angle)]),
                           objects[target].size[2] / 2 + rng.uniform(*s.hand_height)]  # fmt: skip
        L = _hand(tip, goal - tip, rng)
        p_cam = (L - o) @ T[:3, :3]
        px = K.project(p_cam)
        if (
            np.any(p_cam[:, 2] < 0.3)
            or np.any(px < 10)
            or np.any(px[:, 0] > s.width - 11)
            or np.any(px[:, 1] > s.height - 11)
        ):
            continue
        _depth_bare, what_bare = _render(o, rays, table, objects, (np.zeros((0, 3)), np.zeros(0)))
        depth, what = _render(o, rays, table, objects, _spheres(L))
        if np.any((what_bare >= 2) & (what == 1000)):
            continue  # the hand would hide part of an object
        break
    else:  # pragma: no cover - the ranges always leave room
        raise RuntimeError(f"no hand position for scene {seed}")
    depth = depth.astype(np.float64)
    if s.depth_noise:
        finite = np.isfinite(depth)
        depth[finite] += rng.normal(size=int(finite.sum())) * (0.0012 + 0.0019 * (depth[finite] - 0.4) ** 2)
    depth_img = depth.reshape(s.height, s.width).astype(np.float32)
    depth_img[~np.isfinite(depth_img)] = np.nan
    palette = PALETTE
    colours = rng.integers(30, 255, size=(len(objects), 3))
    rgb = np.zeros((len(what), 3), dtype=np.uint8)
    for label in np.unique(what):
        rgb[what == label] = palette.get(
            int(label), tuple(colours[int(label) - 2]) if 2 <= label < 1000 else (0, 0, 0)
        )
    px_noisy = px + rng.normal(scale=s.landmark_sigma_px, size=px.shape)
    z_rel = (p_cam[:, 2] - p_cam[0, 2]) * fx / s.width / p_cam[0, 2]
    landmarks = np.c_[(px_noisy[:, 0] + 0.5) / s.width, (px_noisy[:, 1] + 0.5) / s.height, z_rel]
    return PointingScene(rgb.reshape(s.height, s.width, 3), depth_img, K, T, objects, target, landmarks, L)


def save_pointing_scene(scene: PointingScene, folder: str | Path) -> dict[str, str]:
    """Write a frame as the ``point`` command reads it; returns the files and the intrinsics text.

    ``rgb.png``, ``depth.png`` (16-bit millimetres, 0 without return), ``landmarks.json``
    (MediaPipe's ``[{"x", "y", "z"}]``), ``T_world_camera.txt`` (4x4) and ``truth.json``.
    """
    import cv2

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    files = {k: str(out / name) for k, name in (("rgb", "rgb.png"), ("depth", "depth.png"), ("landmarks", "landmarks.json"),
                                                 ("transform", "T_world_camera.txt"), ("truth", "truth.json"))}  # fmt: skip
    cv2.imwrite(files["rgb"], scene.rgb[..., ::-1])
    mm = np.where(np.isfinite(scene.depth), np.rint(scene.depth * 1000), 0).clip(0, 65535).astype(np.uint16)
    cv2.imwrite(files["depth"], mm)
    Path(files["landmarks"]).write_text(json.dumps(scene.landmarks_json()))
    np.savetxt(files["transform"], scene.T_world_camera)
    truth = {"target": scene.target, "objects": [o.to_json() for o in scene.objects]}
    Path(files["truth"]).write_text(json.dumps(truth))
    K = scene.intrinsics
    files["intrinsics"] = f"{K.fx!r} {K.fy!r} {K.cx!r} {K.cy!r}"
    return files


__all__ = [
    "PALETTE",
    "PointingScene",
    "PointingSceneSettings",
    "TrueObject",
    "generate_pointing_scene",
    "save_pointing_scene",
]
