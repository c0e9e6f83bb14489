"""Fusion experiment: three camera views fused into an OctoMap vs their union (docs/terrain.md).

    nice python bench/bench_fusion.py [--seeds 1 4] [--out bench/results/experiment_fusion.json]

Writes the results JSON and, for the held-out scene (small, seed 1, transient), the segmentations
of the union and of the fused map as docs/img/fusion_union.png and docs/img/fusion_fused.png.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from baseplace.viz.regions import plot_regions
from baseplace_experiments.fusion_experiment import fusion_trial, run_fusion_experiment
from baseplace_experiments.results import write_results
from common import STARTED

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, nargs=2, default=[1, 4], help="held-out seeds [start, stop)")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "experiment_fusion.json"))
    parser.add_argument("--figures", default=str(ROOT / "docs" / "img"))
    args = parser.parse_args()
    result = run_fusion_experiment(range(*args.seeds), progress=lambda _: print(".", end="", flush=True))
    write_results(args.out, result, STARTED, used_seeds=list(range(*args.seeds)))
    print()
    print(json.dumps(result["overall"], indent=1))
    _, _, terrains = fusion_trial("small", args.seeds[0], True)
    for name, file in (("union", "fusion_union.png"), ("fused_miss_0.35", "fusion_fused.png")):
        t = terrains[name]
        plot_regions(t.segmentation, t.graph, Path(args.figures) / file)


if __name__ == "__main__":
    main()
