"""How a true table top's residuals look to the support-plane test at several noise levels (development only).

The find-rate generator's dev scenes (``find_rate.make_scene``, seeds 25000-25059: a table, the
grasped bottle, 0-2 neighbours), with the per-axis Gaussian noise of the cloud set to each level of
:data:`NOISES` instead of the generator's 3 mm; the footprint the fit leaves out is the true
bottle's (this measures the plane test, not the object's detection). Per scene, as
:func:`~baseplace.world.support_plane.fit_support_slab` computes them: the plane points' robust
standard deviation, the 99th percentile of the residuals above the plane, their ratio, and whether
the fit gives a slab with the library's constants. Chose :data:`~baseplace.world.support_plane.P99_SIGMAS`
(3.5: every ratio here is at most 3.35) and shows what the old absolute limit (10 mm) refused.

Usage: python bench/support_plane_ratios.py [--name support_plane_ratios_dev]
"""

from __future__ import annotations

import argparse

import numpy as np

import baseplace.world.support_plane as sp
import find_rate
from common import report

NOISES = (0.002, 0.003, 0.004, 0.005, 0.006, 0.008)
SEEDS = tuple(range(25000, 25060))
OLD_LIMIT = 0.01
"""The absolute limit [m] on the 99th percentile before session 20."""


def residual_stats(points: np.ndarray, distance, bottom: float, voxel: float = 0.025) -> tuple[float, float]:
    """(robust sigma, 99th percentile above the plane) [m] of the plane's points, as the fit reads them
    (:func:`~baseplace.world.support_plane.plane_points`, before its quality is judged)."""
    fit = sp.plane_points(points, distance, bottom, voxel)
    if fit is None:
        raise SystemExit("too few points for a plane")
    _, _, r = fit
    return sp._robust_sigma(r), float(np.percentile(r[r > 0], 99))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--name", default="support_plane_ratios_dev", help="results file bench/results/NAME.json"
    )
    args = parser.parse_args()
    levels = []
    for noise in NOISES:
        rows = []
        for seed in SEEDS:
            scene = find_rate.make_scene(seed, noise)
            x, y, radius, _ = scene.record()["bottle"]
            top = scene.record()["table"][2]

            def distance(xy: np.ndarray, x: float = x, y: float = y, radius: float = radius) -> np.ndarray:
                return np.maximum(np.hypot(xy[:, 0] - x, xy[:, 1] - y) - radius, 0.0)

            sigma, p99 = residual_stats(scene.cloud, distance, top)
            slab = sp.fit_support_slab(scene.cloud, distance, top, 0.025)
            rows.append({"seed": seed, "sigma_mm": round(sigma * 1e3, 3), "p99_above_mm": round(p99 * 1e3, 3),
                         "ratio": round(p99 / sigma, 3), "slab": slab is not None,
                         "old_limit_refuses": p99 > OLD_LIMIT})  # fmt: skip
        ratio = np.array([r["ratio"] for r in rows])
        levels.append({"noise_mm": noise * 1e3, "ratio_min": round(float(ratio.min()), 3),
                       "ratio_median": round(float(np.median(ratio)), 3), "ratio_max": round(float(ratio.max()), 3),
                       "slabs": sum(r["slab"] for r in rows), "old_limit_refused": sum(r["old_limit_refuses"] for r in rows),
                       "scenes": len(rows), "rows": rows})  # fmt: skip
        print(f"noise {noise * 1e3:.0f} mm: ratio {ratio.min():.2f}-{ratio.max():.2f}, slab in "
              f"{levels[-1]['slabs']} of {len(rows)}, the old 10 mm limit refused {levels[-1]['old_limit_refused']}")  # fmt: skip
    report(args.name, {"p99_sigmas": sp.P99_SIGMAS, "max_sigma": sp.MAX_SIGMA, "levels": levels},
           used_seeds=list(SEEDS), split="dev")  # fmt: skip


if __name__ == "__main__":
    main()
