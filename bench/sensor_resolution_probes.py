"""How far from the TRUE surface the model near the object keeps a small link (development probes).

Measures what :mod:`baseplace.world.sensor_resolution`'s docstring reports: a neighbour (a 3.5 cm
bottle with its top, or a 10 cm box) 5 cm beside the grasped bottle on a table, sampled every
centimetre with Gaussian noise, through the library's own ``contact_groups``. Per probe (a point
``q`` of the true surface and an outward direction ``u`` in its normal cone, edges and corners
included): the largest true distance ``d`` [0, 40 mm] at which a sphere of :data:`PROBE` radius
centred at ``q + (d + PROBE) u`` still touches a cell of the model (with the security margin
``Environment`` gives the cell), minus the clearance: the margin beyond the clearance. Negative:
the model lets a link nearer than the clearance. The cells' residuals are their centres' signed
distances to the true shape, per kind of cell (denoised 1.25 mm, raw edge 5 mm).

Development data only (synthetic scenes, seeds 2511-2516); nothing of bench/find_rate.py's splits.

Usage: python bench/sensor_resolution_probes.py --out bench/results/sensor_resolution_probes.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.terrain.voxels import VoxelMap
from baseplace.world.sensor_resolution import (
    EDGE_CELL,
    FINE,
    derived_clearance,
    group_parts,
    margin,
)
from baseplace_experiments.results import RunClock, write_results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_clearance_from_true_surface import (
    HEIGHT,
    RADIUS,
    SIGMA,
    TOP,
    _box_points,
    _cylinder_points,
    noisy_scene,
)

BOX_HALF = 0.05
PROBE = 0.005
"""Probe sphere radius [m] (a fingertip)."""
SEEDS = (2511, 2512, 2513)
STEPS = np.arange(0.0, 0.040, 0.0002)


def _model(neighbour: np.ndarray, footprint: Any, seed: int) -> tuple[list[tuple[VoxelMap, float]], float]:
    groups, plane = noisy_scene(neighbour, footprint, seed)
    clearance, _ = derived_clearance(plane)
    parts = [(p, margin(p, clearance)) for g in groups.values() for p in group_parts(g)
             if isinstance(p, VoxelMap) and p.resolution <= EDGE_CELL + 1e-12 and len(p)]  # fmt: skip
    return parts, clearance


def _reach(parts: list[tuple[VoxelMap, float]], q: np.ndarray, u: np.ndarray) -> tuple[float, str]:
    """The largest d in :data:`STEPS` at which the probe touches a cell, and that cell's kind."""
    centres = q + (STEPS[:, None] + PROBE) * u  # (S, 3)
    best, kind = -1.0, "none"
    for part, m in parts:
        lo = part.keys * part.resolution
        near = np.linalg.norm(lo + part.resolution / 2 - q, axis=1) < 0.07
        if not near.any():
            continue
        lo = lo[near]
        hi = lo + part.resolution
        gap = np.maximum(np.maximum(lo[None] - centres[:, None], centres[:, None] - hi[None]), 0.0)
        touching = (np.linalg.norm(gap, axis=2) - PROBE < m).any(axis=1)
        if touching.any():
            d = float(STEPS[np.flatnonzero(touching).max()])
            if d > best:
                best, kind = d, ("fine" if part.resolution <= FINE + 1e-12 else "edge")
    return best, kind


def bottle_probes(centre: tuple[float, float]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(where, q, u): the side facing away from the grasped bottle, the top rim and the top."""
    out = []
    for a in np.radians(np.arange(-80, 81, 10)):
        c = np.array([math.cos(a), math.sin(a), 0.0])
        for z in np.arange(TOP + 0.03, TOP + HEIGHT - 0.015, 0.02):
            out.append(("side", np.array([*centre, z]) + RADIUS * c, c))
        rim = np.array([*centre, TOP + HEIGHT]) + RADIUS * c
        for t in np.radians([0, 30, 60, 90]):
            out.append(("rim", rim, math.cos(t) * c + math.sin(t) * np.array([0, 0, 1.0])))
    for x in np.arange(-0.02, 0.021, 0.01):
        for y in np.arange(-0.02, 0.021, 0.01):
            out.append(("top", np.array([centre[0] + x, centre[1] + y, TOP + HEIGHT]), np.array([0, 0, 1.0])))
    return out


def box_probes(centre: tuple[float, float]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(where, q, u) over the box's top and its three sides away from the bottle: faces, edges, corners."""
    out = []
    g = np.linspace(-BOX_HALF, BOX_HALF, 11)
    z_top = TOP + 2 * BOX_HALF
    for x in g:
        for y in g:
            q = np.array([centre[0] + x, centre[1] + y, z_top])
            ex, ey = np.sign(x) * (abs(x) == BOX_HALF), np.sign(y) * (abs(y) == BOX_HALF)
            where = "corner" if ex and ey else "edge" if ex or ey else "face"
            for n in {(ex, ey, 1.0), (ex, 0.0, 1.0), (0.0, ey, 1.0), (0.0, 0.0, 1.0), (ex, ey, 0.0)}:
                if not any(n):
                    continue
                u = np.asarray(n) / np.linalg.norm(n)
                out.append((where, q, u))
    for z in np.arange(TOP + 0.03, z_top - 0.005, 0.02):  # the sides facing away (+x) and along (+-y)
        for s in g:
            for q, u in ((np.array([centre[0] + BOX_HALF, centre[1] + s, z]), np.array([1.0, 0, 0])),
                         (np.array([centre[0] + s, centre[1] + BOX_HALF, z]), np.array([0, 1.0, 0])),
                         (np.array([centre[0] + s, centre[1] - BOX_HALF, z]), np.array([0, -1.0, 0]))):  # fmt: skip
                out.append(("side", q, u))
    return out


def _stats(v: list[float]) -> dict[str, float]:
    a = np.asarray(v) * 1e3
    return {"n": len(a), "min": round(float(a.min()), 1), "p5": round(float(np.quantile(a, 0.05)), 1),
            "median": round(float(np.median(a)), 1), "p95": round(float(np.quantile(a, 0.95)), 1),
            "max": round(float(a.max()), 1)}  # fmt: skip


def _sdf_cylinder(p: np.ndarray, centre: tuple[float, float]) -> np.ndarray:
    radial = np.hypot(p[:, 0] - centre[0], p[:, 1] - centre[1]) - RADIUS
    axial = np.abs(p[:, 2] - (TOP + HEIGHT / 2)) - HEIGHT / 2
    return np.hypot(np.maximum(radial, 0), np.maximum(axial, 0)) + np.minimum(np.maximum(radial, axial), 0)


def _sdf_box(p: np.ndarray, centre: tuple[float, float]) -> np.ndarray:
    q = np.abs(p - [centre[0], centre[1], TOP + BOX_HALF]) - BOX_HALF
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def measure(name: str) -> dict[str, Any]:
    if name == "bottle":
        centre = (0.11, 0.0)
        shape = _cylinder_points(centre, rim_row=True)
        sdf, probes = _sdf_cylinder, bottle_probes(centre)

        def footprint(p: np.ndarray) -> np.ndarray:
            return np.hypot(p[:, 0] - centre[0], p[:, 1] - centre[1]) <= RADIUS
    else:
        centre = (RADIUS + 0.05 + BOX_HALF, 0.0)
        shape = _box_points(centre, BOX_HALF)
        sdf, probes = _sdf_box, box_probes(centre)

        def footprint(p: np.ndarray) -> np.ndarray:
            return np.all(np.abs(p[:, :2] - centre) <= BOX_HALF, axis=1)

    by_where: dict[str, list[float]] = {}
    decided: dict[str, int] = {}
    residual: dict[str, list[float]] = {"fine": [], "edge": []}
    clearances = []
    for seed in SEEDS:
        parts, clearance = _model(shape, footprint, seed)
        clearances.append(clearance)
        for part, _ in parts:
            c = part.centres
            mine = np.linalg.norm(c[:, :2] - centre, axis=1) < 0.09
            if mine.any():
                kind = "fine" if part.resolution <= FINE + 1e-12 else "edge"
                residual[kind] += list(sdf(c[mine], centre))
        for where, q, u in probes:
            d, kind = _reach(parts, q, u)
            by_where.setdefault(where, []).append(d - clearance)
            by_where.setdefault("all", []).append(d - clearance)
            decided[kind] = decided.get(kind, 0) + 1
    res = {k: v for k, v in residual.items() if v}
    return {
        "clearance_mm": [round(c * 1e3, 2) for c in clearances],
        "margin_beyond_clearance_mm": {k: _stats(v) for k, v in by_where.items()},
        "decided_by": decided,
        "cell_centre_outside_true_surface_mm": {k: _stats(v) for k, v in res.items()},
        "cell_centre_residual_sd_mm": {k: round(float(np.std(v)) * 1e3, 2) for k, v in res.items()},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    clock = RunClock()
    result = {"benchmark": "sensor_resolution_probes", "noise_m": SIGMA, "probe_radius_m": PROBE,
              "seeds": list(SEEDS), "bottle": measure("bottle"), "box": measure("box")}  # fmt: skip
    write_results(args.out, result, clock)
    print(json.dumps({k: result[k] for k in ("bottle", "box")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
