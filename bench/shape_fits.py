"""Neighbour objects fitted as whole shapes: each fit's error against the TRUE shape, its own u, and
which shapes the acceptance test rejects (:mod:`baseplace.world.neighbour_shapes`; development data).

A neighbour on a table top (z = TOP), sampled every centimetre as bench/find_rate.py samples them
(tests/test_clearance_bound.py's ``_cylinder``, tests/test_clearance_from_true_surface.py's
``_box_points``), with 3 mm Gaussian noise per axis; the points more than 3 sigma above the table are
clustered and fitted (:func:`~baseplace.world.neighbour_shapes.fit_neighbours`) with n = 3 sigma.
Per shape and draw: accepted or not, the kind, the fit's errors (radius or half sides, centre, top)
against the truth, u, and the largest distance [m] by which the true surface lies outside the
fitted solid (sampled densely; what u must cover). Shapes: cylinders of 3, 3.75 and 4.5 cm radius
(20 cm high), a 10 cm box, a 4 cm box, a mug (a 4 cm cylinder 10 cm high with a 1 x 3 x 6 cm handle
out of its side), a bottle with a neck (4 cm body 14 cm high, 1.5 cm neck 6 cm above it), a 5 cm
cylinder with a 1 cm band 6 mm proud (narrower than a patch), a 3 cm cylinder seen from one
side only, and a 4 cm cylinder with a 2 cm square bump 6 or 10 mm proud of its side (the fit's known
limit: when such a bump is accepted, the true surface may lie beyond u).

With ``--scenes`` also the neighbour bottles of bench/find_rate.py's development scenes (seeds
25000-25059; its held-out seeds are refused): the cloud through
:func:`~baseplace.world.environment.contact_groups` with the true grasped bottle, and per true
neighbour within reach of the fine cells whether a fitted shape stands at it, its u and how far the
true neighbour lies outside it.

    python bench/shape_fits.py --out bench/results/shape_fits_s15.json --scenes
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.world.neighbour_shapes import fit_neighbours
from baseplace.world.support_plane import SupportSlab
from baseplace_experiments.results import RunClock, write_results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_clearance_from_true_surface import SIGMA, TOP, _box_points
from test_neighbour_shapes import _box, _side

DRAWS = tuple(range(2541, 2551))
AT = np.array([0.2, 0.1])


def level_slab() -> SupportSlab:
    """The true table top as a fitted plane (z = TOP)."""
    hull = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    return SupportSlab(np.array([0.0, 0.0, TOP]), 0.01, 0.01, hull, 0.01, 10000, SIGMA)


cylinder_points = _side
"""Side (and top) points of an upright cylinder (tests/test_neighbour_shapes.py's)."""


def box_surface(lo, hi, step: float = 0.01) -> np.ndarray:
    """Points on an axis-aligned box's six faces, about ``step`` apart, each once."""
    return np.unique(np.round(_box(lo, hi, step), 9), axis=0)


def shapes() -> dict[str, tuple[np.ndarray, np.ndarray, dict[str, float]]]:
    """name -> (surface samples as the sensor sees them, dense true-surface samples, truth)."""
    out = {}
    for r in (0.03, 0.0375, 0.045):
        out[f"cylinder {r * 1e3:.1f} mm"] = (
            cylinder_points(AT, r, TOP, TOP + 0.2),
            cylinder_points(AT, r, TOP, TOP + 0.2, 0.002),
            {"radius": r, "top": 0.2},
        )
    for half in (0.05, 0.02):
        out[f"box {half * 1e3:.0f} mm"] = (
            _box_points(AT, half),
            box_surface([*(AT - half), TOP], [*(AT + half), TOP + 2 * half], 0.002),
            {"half": half, "top": 2 * half},
        )
    handle_lo, handle_hi = (
        [AT[0] + 0.04, AT[1] - 0.005, TOP + 0.02],
        [AT[0] + 0.07, AT[1] + 0.005, TOP + 0.08],
    )
    handle = box_surface(handle_lo, handle_hi)
    handle = handle[np.hypot(handle[:, 0] - AT[0], handle[:, 1] - AT[1]) > 0.04]
    out["mug (4 cm, handle)"] = (
        np.concatenate([cylinder_points(AT, 0.04, TOP, TOP + 0.1), handle]),
        np.concatenate(
            [cylinder_points(AT, 0.04, TOP, TOP + 0.1, 0.002), box_surface(handle_lo, handle_hi, 0.002)]
        ),
        {"radius": 0.04, "top": 0.1},
    )
    neck = [cylinder_points(AT, 0.04, TOP, TOP + 0.14), cylinder_points(AT, 0.015, TOP + 0.14, TOP + 0.2)]
    neck_dense = [
        cylinder_points(AT, 0.04, TOP, TOP + 0.14, 0.002),
        cylinder_points(AT, 0.015, TOP + 0.14, TOP + 0.2, 0.002),
    ]
    out["bottle with neck"] = (np.concatenate(neck), np.concatenate(neck_dense), {"radius": 0.04, "top": 0.2})
    band = [
        cylinder_points(AT, 0.05, TOP, TOP + 0.2),
        cylinder_points(AT, 0.056, TOP + 0.1, TOP + 0.11, top=False),
    ]
    band_dense = [cylinder_points(AT, 0.05, TOP, TOP + 0.2, 0.002),
                  cylinder_points(AT, 0.056, TOP + 0.1, TOP + 0.11, 0.002, top=False)]  # fmt: skip
    out["cylinder 50 mm, 1 cm band 6 mm proud"] = (
        np.concatenate(band),
        np.concatenate(band_dense),
        {"radius": 0.05, "top": 0.2},
    )
    for proud in (0.006, 0.01):  # a 2 cm square feature proud of a 4 cm bottle's side: the fit's known limit
        lo, hi = [AT[0] + 0.038, AT[1] - 0.01, TOP + 0.08], [AT[0] + 0.04 + proud, AT[1] + 0.01, TOP + 0.1]
        bump = box_surface(lo, hi)
        out[f"cylinder 40 mm, 2 cm bump {proud * 1e3:.0f} mm proud"] = (
            np.concatenate([cylinder_points(AT, 0.04, TOP, TOP + 0.2), bump[bump[:, 0] > AT[0] + 0.04]]),
            np.concatenate([cylinder_points(AT, 0.04, TOP, TOP + 0.2, 0.002), box_surface(lo, hi, 0.002)]),
            {"radius": 0.04, "top": 0.2},
        )
    one = cylinder_points(AT, 0.03, TOP, TOP + 0.2)
    seen = (one[:, 0] - AT[0] <= 0.005) | (one[:, 2] > TOP + 0.2 - 1e-9)
    out["cylinder 30 mm, one side seen"] = (
        one[seen],
        cylinder_points(AT, 0.03, TOP, TOP + 0.2, 0.002),
        {"radius": 0.03, "top": 0.2},
    )
    return out


def find_rate_scenes(seeds: range) -> dict[str, Any]:
    """Per development scene of bench/find_rate.py, its true neighbours and the fits that replaced them."""
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import contact_groups
    from baseplace.world.grasped_object import GraspedObject
    from baseplace.world.neighbour_shapes import FittedShape
    from baseplace.world.sensor_resolution import group_parts
    from find_rate import SEEDS, make_scene

    rows = []
    for seed in seeds:
        if seed in SEEDS.held_out:
            raise SystemExit(f"seed {seed} is held out")
        scene = make_scene(seed)
        x, y, r, hb = scene.bottle
        h = scene.table[2]
        grasped = GraspedObject.cylinder([x, y, h + hb / 2], r, hb)
        voxels = VoxelMap.from_points(scene.cloud)
        groups, _ = contact_groups(voxels, voxels, grasped, scene.cloud)
        fits = [p for g in groups.values() for p in group_parts(g) if isinstance(p, FittedShape)]
        for k, (nx, ny, rn, hn) in enumerate(scene.neighbours):
            mine = [f for f in fits if np.hypot(*(f.origin[:2] + f.axes[:2, :2] @ f.centre - [nx, ny])) < rn]
            row: dict[str, Any] = {"seed": seed, "neighbour": k, "radius_mm": round(rn * 1e3, 1),
                                   "height_mm": round(hn * 1e3, 1), "fitted": bool(mine)}  # fmt: skip
            if mine:
                f = mine[0]
                a = np.linspace(0, 2 * np.pi, 90, endpoint=False)
                Z = np.linspace(h, h + hn, 40)
                A, ZZ = np.meshgrid(a, Z)
                side = np.c_[nx + rn * np.cos(A.ravel()), ny + rn * np.sin(A.ravel()), ZZ.ravel()]
                g = np.linspace(-rn, rn, 15)
                X, Y = np.meshgrid(g, g)
                inside = np.hypot(X, Y).ravel() <= rn
                top = np.c_[nx + X.ravel()[inside], ny + Y.ravel()[inside], np.full(inside.sum(), h + hn)]
                outside = float(f.signed_distance(np.concatenate([side, top])).max())
                row.update({"kind": f.kind, "u_mm": round(f.error * 1e3, 2),
                            "true_surface_outside_mm": round(outside * 1e3, 2),
                            "u_covers_it": bool(outside <= f.error)})  # fmt: skip
            rows.append(row)
    fitted = [r for r in rows if r["fitted"]]
    return {
        "seeds": [seeds.start, seeds.stop - 1],
        "neighbours": len(rows),
        "fitted": len(fitted),
        "u_mm": sorted(r["u_mm"] for r in fitted),
        "true_surface_outside_mm_max": max((r["true_surface_outside_mm"] for r in fitted), default=None),
        "u_covers_all": all(r["u_covers_it"] for r in fitted),
        "rows": rows,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument(
        "--scenes", action="store_true", help="also bench/find_rate.py's dev scenes 25000-25059"
    )
    args = parser.parse_args(argv)
    clock = RunClock()
    n = 3 * SIGMA
    slab = level_slab()
    result: dict[str, Any] = {
        "noise_mm": SIGMA * 1e3,
        "noise_margin_mm": n * 1e3,
        "draws": list(DRAWS),
        "shapes": {},
    }
    for name, (clean, dense, truth) in shapes().items():
        rows = []
        for seed in DRAWS:
            rng = np.random.default_rng(seed)
            noisy = clean + rng.normal(0.0, SIGMA, clean.shape)
            noisy = noisy[noisy[:, 2] > TOP + n]
            fits = fit_neighbours(noisy, slab, n)
            if not fits:
                rows.append({"seed": seed, "accepted": False})
                continue
            shape, members = fits[0]
            row: dict[str, Any] = {"seed": seed, "accepted": True, "kind": shape.kind, "points": len(members),
                                   "of": len(noisy), "u_mm": round(shape.error * 1e3, 2),
                                   "top_error_mm": round((shape.height - truth["top"]) * 1e3, 2),
                                   "centre_error_mm": round(float(np.linalg.norm(shape.centre - AT)) * 1e3, 2)}  # fmt: skip
            if "radius" in truth and shape.kind == "cylinder":
                row["radius_error_mm"] = round((shape.size[0] - truth["radius"]) * 1e3, 2)
            if "half" in truth and shape.kind == "box":
                row["half_errors_mm"] = [round((h - truth["half"]) * 1e3, 2) for h in shape.size]
            outside = float(shape.signed_distance(dense).max())
            row["true_surface_outside_mm"] = round(outside * 1e3, 2)
            row["u_covers_it"] = bool(outside <= shape.error)
            rows.append(row)
        accepted = [r for r in rows if r["accepted"]]
        summary = {
            "accepted": f"{len(accepted)}/{len(rows)}",
            "u_mm_max": max((r["u_mm"] for r in accepted), default=None),
            "true_surface_outside_mm_max": max(
                (r["true_surface_outside_mm"] for r in accepted), default=None
            ),
            "u_covers_all": all(r["u_covers_it"] for r in accepted),
        }
        result["shapes"][name] = {"summary": summary, "draws": rows}
        print(name, summary, flush=True)
    if args.scenes:
        result["find_rate_dev_scenes"] = find_rate_scenes(range(25000, 25060))
        print({k: v for k, v in result["find_rate_dev_scenes"].items() if k != "rows"}, flush=True)
    write_results(Path(args.out), {"benchmark": "shape_fits", **result}, clock)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
