"""Segmentation accuracy on generated scenes (seed 000 VI: 97.8 % of cells, 0.65 deg normals).

Noise (seed 000 VI: "Gaussian noise with a standard deviation of 25 mm added to the height map"):

* ``heightmap`` (the seed's model, the headline): the height map of the noise-free cloud (highest
  25 mm voxel per 50 mm cell), then N(0, sigma) added to every known cell's height, then the usual
  Gaussian smoothing of the height map;
* ``cloud`` (a second row): N(0, sigma) added to the z of every point of the dense cloud before
  voxels and height map; the highest-voxel height map then averages the noise of ~16 points per
  cell away (and biases it upward), which makes this the easier problem.

Protocol (fixed before the held-out run): scenes of every size class x {2, 4} planes, the robust
and the baseline segmenter at their default settings (nothing is tuned here); development seed 0
(the seed all earlier numbers came from), held-out seed 1 for the reported table
(:data:`SEEDS`).

A cell counts as correct when the region it is assigned to is the region of its true plane: each
region is matched to the true plane under most of its cells, and truth is the top-most surface at
the cell centre (``sim.scenes.truth_grid``). Cells whose truth is the box or an object, and cells
with no data, are left out. The normal error of a true plane is the angle between its normal and
that of the region covering most of it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from baseplace.errors import unknown
from baseplace.sim.scenes import SIZE_CLASSES, Scene, SceneSettings, generate_scene, truth_grid
from baseplace.terrain.heightmap import HeightMap, smooth_nan
from baseplace.terrain.pipeline import make_segmenter
from baseplace.terrain.segmentation import Segmentation
from baseplace.terrain.voxels import VoxelMap
from baseplace_experiments.results import SeedSplit

NOISE_MODELS = ("heightmap", "cloud")
"""Where the noise goes: the height map (seed 000 VI) or the dense cloud's z."""
SEEDS = SeedSplit(dev=(0,), held_out=(1,))
"""Development and held-out seeds of the segmentation experiment."""
PROTOCOL_FILE = "docs/protocols/segmentation.md"
"""The protocol, committed before a held-out run (:func:`~baseplace_experiments.results.fixed_protocol`)."""
SIGMA = 0.025
"""Noise standard deviation [m] (seed 000 VI)."""
PAPER = {"cell_accuracy": 0.978, "mean_normal_error_deg": 0.65}
"""Seed 000 VI, the robust segmentation."""


def noisy_height_map(
    scene: Scene,
    rng: np.random.Generator,
    noise: str = "heightmap",
    sigma: float = SIGMA,
    resolution: float = 0.05,
) -> HeightMap:
    """The height map the segmenters see, with ``noise`` ("heightmap" or "cloud", see the module docstring).

    Args:
        scene: the scene.
        rng: random generator (cloud sampling and noise).
        noise: where the Gaussian noise of std ``sigma`` [m] goes.
        sigma: noise std [m].
        resolution: height map cell [m] over 25 mm voxels.
    """
    if noise not in NOISE_MODELS:
        raise unknown("noise model", noise, NOISE_MODELS)
    if noise == "cloud":
        return HeightMap.from_voxels(
            VoxelMap.from_points(scene.sample_cloud(rng, sigma=sigma), 0.025), resolution
        )
    clean = HeightMap.from_voxels(VoxelMap.from_points(scene.sample_cloud(rng, sigma=0.0), 0.025), resolution,
                                  sigma_cells=0.0)  # fmt: skip
    raw = clean.raw + rng.normal(0.0, sigma, clean.raw.shape)  # NaN (unknown) cells stay NaN
    return HeightMap(clean.origin, clean.resolution, raw, smooth_nan(raw, 1.0))


@dataclass(frozen=True)
class SegmentationScore:
    """Accuracy of one segmentation against its scene.

    Attributes:
        cells: cells scored (planar truth, with data).
        correct: cells assigned to the region of their true plane.
        normal_errors_deg: per true plane that some region covers, the normal error [deg].
        missed_planes: true planes no region covers.
        regions: regions found.
        seconds: segmentation time [s].
    """

    cells: int
    correct: int
    normal_errors_deg: list[float]
    missed_planes: int
    regions: int
    seconds: float

    @property
    def accuracy(self) -> float:
        """Share of scored cells assigned to their true plane."""
        return self.correct / self.cells if self.cells else float("nan")


def score_segmentation(scene: Scene, seg: Segmentation, seconds: float = 0.0) -> SegmentationScore:
    """Compare a segmentation with the scene's ground truth."""
    hmap = seg.hmap
    truth, _ = truth_grid(scene, hmap.origin, hmap.resolution, hmap.shape)
    scored = (truth >= 0) & hmap.known
    labels = seg.labels
    match = np.full(len(seg.regions), -1)
    for r in seg.regions:
        ids = truth[(labels == r.id) & scored]
        if len(ids):
            match[r.id] = np.bincount(ids).argmax()
    assigned = np.where(labels >= 0, match[np.maximum(labels, 0)], -1)
    correct = int((scored & (assigned == truth)).sum())
    errors, missed = [], 0
    for plane in scene.planes:
        on_plane = scored & (truth == plane.id)
        covering = labels[on_plane]
        covering = covering[covering >= 0]
        if len(covering) == 0:
            missed += int(on_plane.sum() > 0)
            continue
        region = seg.regions[int(np.bincount(covering).argmax())]
        cos = float(np.clip(region.normal @ plane.normal, -1.0, 1.0))
        errors.append(float(np.degrees(np.arccos(cos))))
    return SegmentationScore(int(scored.sum()), correct, errors, missed, len(seg.regions), seconds)


def run_segmentation_experiment(
    scenes_per_class: int = 10, seed: int = 0, algorithms: tuple[str, ...] = ("baseline", "robust"),
    resolution: float = 0.05, progress: Any = None, noise: str = "heightmap", sigma: float = SIGMA,
) -> dict[str, Any]:  # fmt: skip
    """Both algorithms on ``scenes_per_class`` scenes per size class x {2, 4} planes.

    Scene ``k`` of a class draws from ``default_rng([seed, class index, planes, k])``; the scenes
    do not depend on ``noise``.

    Returns:
        ``{"noise": ..., "sigma_m": ..., "seed": ..., "rows": [...], "overall": {...}}``, one row
        per class, planes and algorithm.
    """
    if noise not in NOISE_MODELS:
        raise unknown("noise model", noise, NOISE_MODELS)
    rows = []
    totals: dict[str, list[SegmentationScore]] = {a: [] for a in algorithms}
    for size_class in SIZE_CLASSES:
        for n_planes in (2, 4):
            per_alg: dict[str, list[SegmentationScore]] = {a: [] for a in algorithms}
            for k in range(scenes_per_class):
                rng = np.random.default_rng([seed, list(SIZE_CLASSES).index(size_class), n_planes, k])
                scene = generate_scene(SceneSettings(size_class=size_class, n_planes=n_planes), rng)
                hmap = noisy_height_map(scene, rng, noise, sigma, resolution)
                for alg in algorithms:
                    t = time.perf_counter()
                    seg = make_segmenter(alg).segment(hmap)
                    per_alg[alg].append(score_segmentation(scene, seg, time.perf_counter() - t))
                if progress is not None:
                    progress(1)
            for alg in algorithms:
                rows.append(
                    {"size_class": size_class, "planes": n_planes, "algorithm": alg, **_summary(per_alg[alg])}
                )
                totals[alg].extend(per_alg[alg])
    return {"noise": noise, "sigma_m": sigma, "seed": seed, "scenes_per_class": scenes_per_class, "rows": rows,
            "overall": {alg: _summary(totals[alg]) for alg in algorithms}}  # fmt: skip


def _summary(scores: list[SegmentationScore]) -> dict[str, Any]:
    cells = sum(s.cells for s in scores)
    errors = [e for s in scores for e in s.normal_errors_deg]
    return {
        "scenes": len(scores),
        "cell_accuracy": round(sum(s.correct for s in scores) / cells, 5) if cells else None,
        "mean_normal_error_deg": round(float(np.mean(errors)), 4) if errors else None,
        "max_normal_error_deg": round(float(np.max(errors)), 4) if errors else None,
        "missed_planes": sum(s.missed_planes for s in scores),
        "median_seconds": round(float(np.median([s.seconds for s in scores])), 4),
    }
