"""Each model element's own error against the TRUE surface, at the scene's noise (development data).

Measures what :data:`~baseplace.world.sensor_resolution.SURFACE_ERROR_SIGMAS` and
:data:`~baseplace.world.sensor_resolution.SURFACE_GAP` state. A neighbour (a cylinder of the radii
of bench/find_rate.py's bottles, 3-4.5 cm, with its top; or a 10 cm box) 5 cm beside a grasped
bottle on a table, sampled every centimetre with 3 mm Gaussian noise per axis (the scenes of
tests/test_clearance_from_true_surface.py); the table top's points leave (they become the exact
plane), the others go through :func:`~baseplace.world.sensor_resolution.denoised`. Per point of the
neighbour: its signed distance to the true shape (positive outside), denoised or raw, and where it
lies (side, rim: within 2 cm of the top's edge, foot: within 2 cm of the table). Per probe (a 5 mm
sphere touching the neighbour's true surface, over the gaps between the points, edges and corners
included): its distance to the nearest denoised cell (:data:`FINE` cubes), i.e. the margin from the
denoised cells that refuses it.

Development data only (synthetic scenes, seeds 2521-2526); nothing of bench/find_rate.py's splits.

Usage: python bench/clearance_errors.py --out bench/results/clearance_errors.json
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from baseplace.world.sensor_resolution import CLEARANCE_SIGMAS, EDGE_CELL, FINE, denoised
from baseplace_experiments.results import RunClock, write_results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_clearance_bound import _cylinder
from test_clearance_from_true_surface import BOTTLE, SIGMA, TOP, _box_points

SEEDS = (2521, 2522, 2523)
RADII = (0.03, 0.0375, 0.045)
HEIGHT = 0.2
BOX_HALF = 0.05
PROBE = 0.005
"""Probe sphere radius [m] (a fingertip)."""


def _sdf_cylinder(p: np.ndarray, xy: tuple[float, float], r: float) -> np.ndarray:
    radial = np.hypot(p[:, 0] - xy[0], p[:, 1] - xy[1]) - r
    axial = np.abs(p[:, 2] - (TOP + HEIGHT / 2)) - HEIGHT / 2
    return np.hypot(np.maximum(radial, 0), np.maximum(axial, 0)) + np.minimum(np.maximum(radial, axial), 0)


def _sdf_box(p: np.ndarray, centre: tuple[float, float], half: float) -> np.ndarray:
    q = np.abs(p - [centre[0], centre[1], TOP + half]) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _scene(kind: str, size: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(points after denoising, smooth, signed distance to the neighbour, which are the neighbour's)."""
    rng = np.random.default_rng(seed)
    at = (BOTTLE[0] + 0.035 + 0.05 + size, BOTTLE[1])
    neighbour = _cylinder(at, size) if kind == "cylinder" else _box_points(at, size)
    clean = np.concatenate([_cylinder(BOTTLE, 0.035), neighbour])
    noisy = clean + rng.normal(0.0, SIGMA, clean.shape)
    keep = noisy[:, 2] > TOP + CLEARANCE_SIGMAS * SIGMA  # the table's band becomes the exact plane
    moved, smooth = denoised(noisy[keep])
    mine = np.arange(len(clean))[keep] >= len(clean) - len(neighbour)
    sdf = _sdf_cylinder(moved, at, size) if kind == "cylinder" else _sdf_box(moved, at, size)
    return moved[mine], smooth[mine], sdf[mine], np.asarray(at)


def _probes(kind: str, size: float, at: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Centres of spheres touching the true surface from outside (N, 3) and where each touches."""
    out, where = [], []
    if kind == "cylinder":
        for a in np.radians(np.arange(0, 360, 7.5)):
            u = np.array([math.cos(a), math.sin(a), 0.0])
            for z in np.arange(TOP + 0.02, TOP + HEIGHT - 0.02 + 1e-9, 0.0025):
                out.append([*(at[:2] + (size + PROBE) * u[:2]), z])
                where.append("side")
            for t in (0.25, 0.5, 0.75):  # the rim, along its normal cone
                v = math.cos(t * math.pi / 2) * u + [0, 0, math.sin(t * math.pi / 2)]
                out.append(np.r_[at[:2] + size * u[:2], TOP + HEIGHT] + PROBE * v)
                where.append("rim")
    else:
        g = np.linspace(-size, size, 11)
        for x in g:
            for y in g:
                q = np.array([at[0] + x, at[1] + y, TOP + 2 * size])
                ex, ey = abs(x) == size, abs(y) == size
                normals = {(0.0, 0.0, 1.0), (np.sign(x) * ex, np.sign(y) * ey, 1.0)}
                for n in normals:
                    u = np.asarray(n) / np.linalg.norm(n)
                    out.append(q + PROBE * u)
                    where.append("corner" if ex and ey else "edge" if ex or ey else "face")
    return np.asarray(out), where


def _box_distance(centres: np.ndarray, cells: np.ndarray, size: float = FINE) -> np.ndarray:
    """Per sphere centre (N, 3): distance [m] from the sphere to the nearest cell of edge ``size`` (keys (M, 3))."""
    if not len(cells):
        return np.full(len(centres), np.inf)
    lo = cells * size
    tree = cKDTree(lo + size / 2)
    _, idx = tree.query(centres, k=min(len(lo), 64))
    idx = idx.reshape(len(centres), -1)
    a, b = lo[idx], lo[idx] + size
    c = centres[:, None, :]
    gap = np.maximum(np.maximum(a - c, c - b), 0.0)
    return np.linalg.norm(gap, axis=2).min(axis=1) - PROBE


def _stats(x: np.ndarray) -> dict[str, float]:
    mm = np.asarray(x) * 1e3
    q = {"q99_mm": 0.99, "q9987_mm": 0.9987}
    if not len(mm):
        return {"n": 0}
    return {"n": len(mm), "mean_mm": round(float(mm.mean()), 2), "sd_mm": round(float(mm.std()), 2),
            "min_mm": round(float(mm.min()), 2), "max_mm": round(float(mm.max()), 2),
            **{k: round(float(np.quantile(mm, v)), 2) for k, v in q.items()}}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    clock = RunClock()
    result: dict[str, Any] = {"noise_mm": SIGMA * 1e3, "probe_radius_mm": PROBE * 1e3, "shapes": {}}
    for kind, sizes in (("cylinder", RADII), ("box", (BOX_HALF,))):
        for size in sizes:
            den, raw, probe_d, raw_where, probe_where = [], [], [], [], []
            for seed in SEEDS:
                p, smooth, sdf, at = _scene(kind, size, seed)
                den.append(sdf[smooth])
                raw.append(sdf[~smooth])
                z = p[~smooth, 2]
                raw_where += ["rim" if zz > TOP + 2 * size * (kind == "box") + HEIGHT * (kind == "cylinder") - 0.02
                              else "foot" if zz < TOP + 0.02 else "side" for zz in z]  # fmt: skip
                centres, where = _probes(kind, size, at)
                d_fine = _box_distance(
                    centres, np.unique(np.floor(p[smooth] / FINE).astype(np.int64), axis=0)
                )
                raw_cells = np.unique(np.floor(p[~smooth] / EDGE_CELL).astype(np.int64), axis=0)
                covered = _box_distance(centres, raw_cells, EDGE_CELL) < CLEARANCE_SIGMAS * SIGMA
                probe_d.append(np.where(covered, -np.inf, d_fine))  # the raw cells (at n) refuse it
                probe_where += where
            d, r, pd = np.concatenate(den), np.concatenate(raw), np.concatenate(probe_d)
            rw, pw = np.asarray(raw_where), np.asarray(probe_where)
            name = f"{kind} {size * 1e3:.1f} mm"
            result["shapes"][name] = {
                "denoised_signed_distance": _stats(d),
                "raw_share": round(len(r) / (len(r) + len(d)), 3),
                "raw_signed_distance": {w: _stats(r[rw == w]) for w in sorted(set(raw_where))},
                "probes_refused_by_raw_cells_alone": {
                    w: round(float(np.mean(pd[pw == w] == -np.inf)), 3) for w in sorted(set(probe_where))
                },
                "probe_distance_to_denoised_cells_where_raw_cells_do_not_refuse": {
                    w: _stats(pd[(pw == w) & np.isfinite(pd)]) for w in sorted(set(probe_where))
                },
            }
            print(name, result["shapes"][name], flush=True)
    write_results(Path(args.out), {"benchmark": "clearance_errors", **result}, clock)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
