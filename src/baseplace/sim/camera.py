"""A simulated depth camera looking at a generated scene (for the fusion experiment).

Rays of a pinhole camera (optical frame: x right, y down, z forward) are marched through the
scene's height field (the top-most surface, :meth:`Scene.height`, rasterized at 1 cm) until they
pass below it; the hit is refined by bisection. Vertical faces are hit where a ray crosses them.
A ray that leaves the scene meets the walls of the room around it (2.5 m high, 5 cm outside the
scene), so that, as in a real room, almost every ray returns.
Noise, fixed before any result was looked at:

* along the ray, Gaussian with the Kinect's axial model of Nguyen, Izadi and Lovell (2012):
  ``sigma(r) = 0.0012 + 0.0019 (r - 0.4)^2`` [m];
* a share of returns (default 1 %) are outliers ("flying pixels"): uniform in range between the
  camera and the true hit, i.e. in free space.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.sim.scenes import Scene

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CameraSettings:
    """The simulated camera.

    Attributes:
        width: pixels per row.
        height: rows.
        fov_deg: horizontal field of view [deg] (square pixels).
        near: closest return [m].
        far: farthest return [m].
        outliers: share of returns replaced by a point in free space along the ray.
        raster: height-field raster cell [m].
        wall_height: the scene stands in a room whose walls (this high, 5 cm outside the scene's
            extent) return the rays that leave the scene; 0: no walls, such rays return nothing.
    """

    width: int = 320
    height: int = 240
    fov_deg: float = 70.0
    near: float = 0.3
    far: float = 8.0
    outliers: float = 0.01
    raster: float = 0.01
    wall_height: float = 2.5


def look_at(eye: ArrayLike, target: ArrayLike) -> FloatArray:
    """world_T_camera (4, 4) of an optical-frame camera at ``eye`` (3,) looking at ``target`` (3,), image up = world up."""
    eye, target = np.asarray(eye, dtype=float), np.asarray(target, dtype=float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.c_[x, y, z]
    T[:3, 3] = eye
    return T


class _Raster:
    def __init__(self, scene: Scene, cell: float) -> None:
        x0, y0, x1, y1 = scene.bounds
        nx, ny = math.ceil((x1 - x0) / cell), math.ceil((y1 - y0) / cell)
        X, Y = np.meshgrid(
            x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell, indexing="ij"
        )
        self.h = scene.height(np.c_[X.ravel(), Y.ravel()]).reshape(nx, ny)
        self.x0, self.y0, self.cell, self.shape = x0, y0, cell, (nx, ny)

    def __call__(self, xy: FloatArray) -> FloatArray:
        fx = (xy[..., 0] - self.x0) / self.cell
        fy = (xy[..., 1] - self.y0) / self.cell
        finite = np.isfinite(fx) & np.isfinite(fy)
        i = np.floor(np.where(finite, fx, -1.0)).astype(np.int64)
        j = np.floor(np.where(finite, fy, -1.0)).astype(np.int64)
        ok = (i >= 0) & (i < self.shape[0]) & (j >= 0) & (j < self.shape[1])
        out = np.full(i.shape, np.nan)
        out[ok] = self.h[i[ok], j[ok]]
        return out


def _wall_hits(scene: Scene, origin: FloatArray, rays: FloatArray, s: CameraSettings) -> FloatArray:
    """Range (N,) at which each ray meets the room's walls below ``wall_height``; NaN above or beyond ``far``."""
    x0, y0, x1, y1 = scene.bounds
    lo, hi = np.array([x0 - 0.05, y0 - 0.05]), np.array([x1 + 0.05, y1 + 0.05])
    with np.errstate(divide="ignore", invalid="ignore"):
        t_exit = np.min(np.where(rays[:, :2] > 0, (hi - origin[:2]) / rays[:, :2],
                                 np.where(rays[:, :2] < 0, (lo - origin[:2]) / rays[:, :2], np.inf)), axis=1)  # fmt: skip
    z = origin[2] + t_exit * rays[:, 2]
    ok = (z >= 0) & (z <= s.wall_height) & (t_exit <= s.far) & (t_exit >= s.near)
    return np.where(ok, t_exit, np.nan)


def depth_cloud(
    scene: Scene, T_world_camera: ArrayLike, rng: np.random.Generator, settings: CameraSettings | None = None
) -> FloatArray:
    """The noisy returns (N, 3) of the camera at ``T_world_camera`` (4, 4), in the camera frame [m]."""
    s = settings or CameraSettings()
    T = np.asarray(T_world_camera, dtype=float)
    f = (s.width / 2) / math.tan(math.radians(s.fov_deg) / 2)
    u, v = np.meshgrid(np.arange(s.width) + 0.5 - s.width / 2, np.arange(s.height) + 0.5 - s.height / 2)
    rays_cam = np.c_[u.ravel() / f, v.ravel() / f, np.ones(u.size)]
    rays_cam /= np.linalg.norm(rays_cam, axis=1, keepdims=True)
    rays = rays_cam @ T[:3, :3].T
    origin = T[:3, 3]
    height = _Raster(scene, s.raster)
    step = 0.02
    ts = np.arange(s.near, s.far, step)
    hit_t = np.full(len(rays), np.nan)
    for start in range(0, len(rays), 4096):
        r = rays[start : start + 4096]
        p = origin + ts[None, :, None] * r[:, None, :]  # (R, T, 3)
        below = p[..., 2] <= height(p[..., :2])  # NaN (outside) compares False
        first = np.where(below.any(axis=1), below.argmax(axis=1), -1)
        ok = first > 0
        lo = np.where(ok, ts[np.maximum(first - 1, 0)], np.nan)
        hi = np.where(ok, ts[np.maximum(first, 0)], np.nan)
        for _ in range(6):  # bisection to 0.3 mm
            mid = (lo + hi) / 2
            q = origin + mid[:, None] * r
            under = q[:, 2] <= height(q[:, :2])
            hi = np.where(under, mid, hi)
            lo = np.where(under, lo, mid)
        hit_t[start : start + 4096] = np.where(ok, hi, np.nan)
    if s.wall_height > 0:
        hit_t = np.where(np.isfinite(hit_t), hit_t, _wall_hits(scene, origin, rays, s))
    keep = np.isfinite(hit_t)
    rng_true = hit_t[keep]
    dirs = rays_cam[keep]
    sigma = 0.0012 + 0.0019 * (rng_true - 0.4) ** 2
    measured = rng_true + rng.normal(0.0, 1.0, len(rng_true)) * sigma
    out = rng.random(len(measured)) < s.outliers
    measured[out] = rng.uniform(s.near, rng_true[out])
    # a range along the ray, expressed as depth (z) by the camera: the point is range * direction
    return np.asarray(dirs * measured[:, None], dtype=np.float64)
