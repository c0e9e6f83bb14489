"""Several posed clouds fused into one OctoMap by ray casting (seed 000, section VI).

Seed 000 builds its scene model by inserting the robot's camera clouds into an OctoMap: each point
is a hit at the end of a ray from the sensor's origin, the voxels the ray passes are misses, and
each voxel keeps a clamped log-odds occupancy. A voxel that one view saw occupied (a noisy point in
front of a surface, a flying pixel) is cleared when other views see through it; overlapping views
of one surface reinforce it. The occupied voxels' centres are the fused cloud, which
:func:`~baseplace.terrain.pipeline.terrain_from_points` segments like any other.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.guards import check_grid_size

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FusionSettings:
    """OctoMap settings (octomap's defaults; seed 000: 25 mm voxels).

    Attributes:
        resolution: voxel edge [m].
        prob_hit: occupancy probability of a hit.
        prob_miss: occupancy probability of a miss (a ray passing through).
        max_range: rays are cut at this range [m]; -1: unlimited.
    """

    resolution: float = 0.025
    prob_hit: float = 0.7
    prob_miss: float = 0.4
    max_range: float = -1.0

    def __post_init__(self) -> None:
        if not (0.005 <= self.resolution <= 1.0):
            raise InputError(f"fusion voxel size must be in [0.005, 1] m, got {self.resolution}")
        if not (0.5 < self.prob_hit < 1.0 and 0.0 < self.prob_miss < 0.5):
            raise InputError(
                f"need 0.5 < prob_hit < 1 and 0 < prob_miss < 0.5, got {self.prob_hit}, {self.prob_miss}"
            )


@dataclass(frozen=True)
class PosedCloud:
    """A cloud in the world frame and the sensor origin its rays start from.

    Attributes:
        points: (N, 3) world points [m].
        origin: (3,) sensor position in the world frame [m] (translation of world_T_sensor).
    """

    points: FloatArray
    origin: FloatArray


def fuse_clouds(
    clouds: Sequence[PosedCloud], settings: FusionSettings | None = None, save: str | Path | None = None
) -> FloatArray:
    """Fuse posed clouds into an OctoMap; returns the occupied voxel centres (M, 3) [m].

    Args:
        clouds: the clouds, each with its sensor origin, in one world frame.
        settings: OctoMap settings.
        save: also write the OctoMap as a ``.bt`` file here.

    Raises:
        InputError: no cloud, a cloud or origin that is not finite, or more voxels than the
            memory cap allows (:func:`check_voxels`).
    """
    import pyoctomap

    from baseplace.terrain.io import load_cloud

    s = settings or FusionSettings()
    if not clouds:
        raise InputError("fusion needs at least one cloud")
    posed = []
    for k, c in enumerate(clouds):
        pts = np.ascontiguousarray(np.asarray(c.points, dtype=np.float64).reshape(-1, 3))
        origin = np.asarray(c.origin, dtype=np.float64).reshape(3)
        if not (np.isfinite(pts).all() and np.isfinite(origin).all()):
            raise InputError(f"cloud {k} or its sensor origin is not finite")
        posed.append((pts, origin))
    check_voxels(posed, s)
    tree = pyoctomap.OcTree(s.resolution)
    tree.setProbHit(s.prob_hit)
    tree.setProbMiss(s.prob_miss)
    for pts, origin in posed:
        if len(pts):
            tree.insertPointCloud(pts, origin, max_range=s.max_range, discretize=True)
    tree.updateInnerOccupancy()
    # The .bt reader expands pruned leaves to the finest voxels and checks sizes (one code path).
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fused.bt"
        if not tree.writeBinary(str(path)):
            raise InputError("octomap could not write the fused map")
        points = load_cloud(path).points
        if save is not None:
            from baseplace.files import atomic_write

            with atomic_write(Path(save), "OctoMap") as out:
                out.write_bytes(path.read_bytes())
    return points


BYTES_PER_VOXEL = 64.0
"""Peak bytes per voxel the rays may touch: the octree's node and its share of its parent's
children, and the key sets of a scan's insertion (measured: 27 to 42 per cell of the box)."""


def check_voxels(clouds: Sequence[tuple[FloatArray, FloatArray]], settings: FusionSettings) -> int:
    """Bound the voxels that fusing ``(points (N, 3), origin (3,))`` pairs can touch, before the octree grows.

    A ray touches at most its L1 length / resolution + 1 voxels, and one cloud at most the cells of
    the box around its points and origin (cut at ``max_range``); all clouds at most the cells of
    their joint box. The bound times :data:`BYTES_PER_VOXEL` must fit ``$BASEPLACE_MAX_MEMORY_MB``.

    Returns:
        The bound [voxels].

    Raises:
        InputError: one line with the voxel count and the limit.
    """
    res = settings.resolution
    per_cloud = 0.0
    lo_all, hi_all = np.full(3, np.inf), np.full(3, -np.inf)
    for pts, origin in clouds:
        if not len(pts):
            continue
        ray = pts - origin
        if settings.max_range > 0:
            length = np.linalg.norm(ray, axis=1, keepdims=True)
            ray = ray * np.minimum(1.0, settings.max_range / np.maximum(length, 1e-12))
        visits = float(np.abs(ray).sum()) / res + len(pts)
        lo, hi = np.minimum(ray.min(axis=0), 0.0) + origin, np.maximum(ray.max(axis=0), 0.0) + origin
        box = float(np.prod(np.floor(hi / res) - np.floor(lo / res) + 1))
        per_cloud += min(visits, box)
        lo_all, hi_all = np.minimum(lo_all, lo), np.maximum(hi_all, hi)
    bound = (
        min(per_cloud, float(np.prod(np.floor(hi_all / res) - np.floor(lo_all / res) + 1)))
        if per_cloud
        else 0.0
    )
    check_grid_size(
        bound, BYTES_PER_VOXEL, f"fusing these clouds may touch {bound:.3g} voxels of {res} m",
        "use larger voxels, a max range or fewer, nearer points", unit="voxels",
    )  # fmt: skip
    return int(bound)


def posed(points: ArrayLike, T_world_sensor: ArrayLike) -> PosedCloud:
    """A :class:`PosedCloud` from sensor-frame points (N, 3) [m] and world_T_sensor (4, 4)."""
    T = np.asarray(T_world_sensor, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return PosedCloud(pts @ T[:3, :3].T + T[:3, 3], T[:3, 3].copy())
