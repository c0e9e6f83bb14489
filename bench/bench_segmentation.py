"""Segmentation runtime on a 10 m x 10 m scene at 50 mm: robust vs baseline, same run.

Times ``segment(height_map)`` (the algorithm; the height map is built once), median of repeats,
on a generated scene with 4 large planes and 25 mm noise; also the whole cloud-to-graph pipeline.
Usage: python bench/bench_segmentation.py [--repeats 7]
"""

from __future__ import annotations

import argparse

import numpy as np

from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.heightmap import HeightMap
from baseplace.terrain.pipeline import make_segmenter, terrain_from_points
from baseplace.terrain.voxels import VoxelMap
from common import median_time, report


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    rng = np.random.default_rng(11)
    scene = generate_scene(SceneSettings(size_class="large", n_planes=4), rng)
    points = scene.sample_cloud(rng)
    hmap = HeightMap.from_voxels(VoxelMap.from_points(points, 0.025), 0.05)
    result: dict[str, object] = {"scene": "10 m x 10 m, 4 large planes, sigma 25 mm", "points": len(points),
                                 "cells": int(np.prod(hmap.shape))}  # fmt: skip
    for name in ("robust", "baseline"):
        segmenter = make_segmenter(name)
        segmenter.segment(hmap)  # compile outside the timing
        result[f"{name}_segment_s_median"] = round(
            median_time(lambda s=segmenter: s.segment(hmap), args.repeats), 4
        )
    terrain_from_points(points)
    result["pipeline_s_median"] = round(median_time(lambda: terrain_from_points(points), 3), 3)
    result["robust_over_baseline"] = round(
        result["robust_segment_s_median"] / result["baseline_segment_s_median"], 2
    )  # type: ignore[operator]
    result["target"] = "robust <= 0.5 s"
    report("segmentation_runtime", result)


if __name__ == "__main__":
    main()
