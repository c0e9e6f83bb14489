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

Session 14 adds a candidate edge model (:func:`on_edges`, ``edge_model`` per shape: its points'
signed distance, the share of the top's raw points it takes, and the distance from each probe
that neither raw nor denoised cells refuse to its cells, the u it would need), in two settings
(:data:`EDGE_SETTINGS`).

Development data only (synthetic scenes, seeds 2521-2526); nothing of bench/find_rate.py's splits.

Usage: python bench/clearance_errors.py --out bench/results/clearance_errors.json
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from baseplace.world.sensor_resolution import (
    CLEARANCE_SIGMAS,
    EDGE_CELL,
    FINE,
    PLANAR_FACTOR,
    SURFACE_CHORD,
    denoised,
    max_shift,
    surface_error,
    surface_noise,
)
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


@dataclass(frozen=True)
class EdgeSettings:
    """The candidate edge model's parameters (:func:`on_edges`)."""

    neighbours: int = 32
    """The two faces are fitted to this many nearest points."""
    trials: int = 48
    """Planes through three of them tried."""
    inlier: float = 2.0
    """A point lies on a face within this many sigma."""
    min_face: int = 8
    """Each face holds at least this many points (those near both planes left out)."""
    min_angle: float = 60.0
    """The faces meet at this angle [deg] or more."""
    cross: float = 0.1
    """At most this share of a face's points lie on the far side of the other face's plane."""
    reach: float = 0.015
    """The faces' edge line lies within this distance [m] of the point."""
    seed: int = 25
    """The seed of the triples."""


EDGE_SETTINGS = {
    "strict": EdgeSettings(),
    "loose": EdgeSettings(neighbours=48, min_face=5, cross=0.25, reach=0.03),
}
"""The two settings measured: strict (the fewest bad fits) and loose (the most edges taken)."""


def on_edges(
    points: np.ndarray, smooth: np.ndarray, sigma: float, shift_limit: float, s: EdgeSettings
) -> tuple[np.ndarray, np.ndarray]:
    """A candidate edge model (session 14, measured here, not in the product): the raw points (N, 3)
    [m] whose neighbourhood splits into two smooth faces put onto the nearer face.

    For each point not ``smooth`` (:func:`~baseplace.world.sensor_resolution.denoised`), a two-plane
    fit to its ``s.neighbours`` nearest points: RANSAC (Fischler and Bolles 1981), ``s.trials``
    planes through three of them, the pair meeting at ``s.min_angle`` or more whose points within
    ``s.inlier`` sigma together hold the most (:func:`_best_pair`); then each point goes to the
    nearer face and both are refitted to their points away from the other plane (those near both
    lie near the edge, either face's), three times. It is an edge when each face holds at least
    ``s.min_face`` such points, the refitted faces still meet at ``s.min_angle`` or more, each
    face's residuals' standard deviation is within the smoothness test's bound (PLANAR_FACTOR times
    ``sigma``, the noise across the local planes, plus the chord SURFACE_CHORD of a bottle's
    side), at most ``s.cross`` of a face's points lie on the far side of the other plane (a plane
    across a corner has points on both), and the edge line lies within ``s.reach`` of the point.
    The point goes onto the nearer face; where that carries it past the edge line (beyond the other
    plane, away from the face's own points) onto the edge line itself (the point of both planes
    nearest it): no corner is rounded off. A move beyond ``shift_limit`` [m]
    (:func:`~baseplace.world.sensor_resolution.max_shift`) keeps it raw. Deterministic (``s.seed``).

    Returns:
        The points (the edge points moved, the others as given) and which were moved (N,).
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    rows = np.flatnonzero(~np.asarray(smooth, dtype=bool))
    out, edge = p.copy(), np.zeros(len(p), dtype=bool)
    k = s.neighbours
    if len(rows) == 0 or len(p) < k or sigma <= 0:
        return out, edge
    nb = p[cKDTree(p).query(p[rows], k=k)[1]]  # (R, k, 3)
    centre = nb.mean(axis=1)
    local = nb - centre[:, None, :]
    rng = np.random.default_rng(s.seed)
    tri = np.stack([rng.choice(k, 3, replace=False) for _ in range(s.trials)])  # (M, 3)
    a, b, c = local[:, tri[:, 0]], local[:, tri[:, 1]], local[:, tri[:, 2]]  # (R, M, 3)
    normal = np.cross(b - a, c - a)
    length = np.linalg.norm(normal, axis=2, keepdims=True)
    normal = normal / np.maximum(length, 1e-12)
    offset = np.einsum("rmi,rmi->rm", normal, a)
    dist = np.abs(np.einsum("rki,rmi->rmk", local, normal) - offset[..., None])  # (R, M, k)
    inlier = (dist <= s.inlier * sigma) & (length > 1e-9)
    first, second = _best_pair(normal, inlier, s.min_angle)
    R = np.arange(len(rows))
    planes = [(normal[R, first], offset[R, first]), (normal[R, second], offset[R, second])]
    for _ in range(3):
        d = np.stack([np.abs(np.einsum("rki,ri->rk", local, n) - o[:, None]) for n, o in planes])  # (2, R, k)
        face = np.argmin(d, axis=0)
        keep = d.min(axis=0) <= s.inlier * sigma
        fit = keep & (d.max(axis=0) > s.inlier * sigma)  # near both planes: near the edge, either face's
        planes, spread, count = [], [], []
        for f in (0, 1):
            w = ((face == f) & fit).astype(float)
            m = np.maximum(w.sum(axis=1), 1.0)
            mu = np.einsum("rk,rki->ri", w, local) / m[:, None]
            cen = local - mu[:, None, :]
            vals, vecs = np.linalg.eigh(np.einsum("rk,rki,rkj->rij", w, cen, cen))
            n = vecs[:, :, 0]
            planes.append((n, np.einsum("ri,ri->r", n, mu)))
            spread.append(np.sqrt(np.maximum(vals[:, 0], 0.0) / np.maximum(m - 3.0, 1.0)))
            count.append(w.sum(axis=1))
    (na, da), (nb_, db) = planes
    cos = np.abs(np.einsum("ri,ri->r", na, nb_))
    bound = PLANAR_FACTOR * sigma + SURFACE_CHORD
    ok = (
        (np.minimum(count[0], count[1]) >= s.min_face)
        & (cos <= math.cos(math.radians(s.min_angle)))
        & (np.maximum(spread[0], spread[1]) <= bound)
    )
    x = p[rows] - centre
    sa, sb = np.einsum("ri,ri->r", x, na) - da, np.einsum("ri,ri->r", x, nb_) - db
    nearer_a = np.abs(sa) <= np.abs(sb)
    n1, s1 = np.where(nearer_a[:, None], na, nb_), np.where(nearer_a, sa, sb)
    n2, d2 = np.where(nearer_a[:, None], nb_, na), np.where(nearer_a, db, da)
    own = np.where(nearer_a, 0, 1)  # the nearer face's own points lie on one side of the other plane
    w = (face == own[:, None]) & keep
    side = np.sign(np.einsum("rk,rk->r", w, np.einsum("rki,ri->rk", local, n2) - d2[:, None]))
    # a true edge: each face's points on one side of the other face's plane
    da_b = np.einsum("rki,ri->rk", local, nb_) - db[:, None]
    db_a = np.einsum("rki,ri->rk", local, na) - da[:, None]
    wa, wb = (face == 0) & fit, (face == 1) & fit
    for w_, s_ in ((wa, da_b), (wb, db_a)):
        pos, neg = (w_ & (s_ > 0)).sum(axis=1), (w_ & (s_ < 0)).sum(axis=1)
        ok &= np.minimum(pos, neg) <= s.cross * np.maximum(w_.sum(axis=1), 1)
    y = x - s1[:, None] * n1
    past = side * (np.einsum("ri,ri->r", y, n2) - d2) < 0  # beyond the edge line
    # the point of both planes nearest x: x - N^T (N N^T)^-1 (N x - d)
    N = np.stack([na, nb_], axis=1)  # (R, 2, 3)
    gram = np.einsum("rai,rbi->rab", N, N) + 1e-12 * np.eye(2)
    lam = np.linalg.solve(gram, np.stack([sa, sb], axis=1)[..., None])[..., 0]
    on_line = x - np.einsum("rab,ra->rb", N, lam)
    y = np.where(past[:, None], on_line, y)
    ok &= np.einsum("ri,ri->r", on_line - x, on_line - x) <= s.reach * s.reach  # the faces meet here
    move = y - x
    ok &= np.einsum("ri,ri->r", move, move) <= shift_limit * shift_limit
    out[rows[ok]] = y[ok] + centre[ok]
    edge[rows[ok]] = True
    return out, edge


def _best_pair(normal: np.ndarray, inlier: np.ndarray, min_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Per row, the two trial planes (of (R, M, 3) normals) meeting at ``min_angle`` [deg] or more
    whose inliers (R, M, k) together hold the most points."""
    r_, m, _ = inlier.shape
    first, second = np.zeros(r_, dtype=np.intp), np.zeros(r_, dtype=np.intp)
    limit = math.cos(math.radians(min_angle))
    for lo in range(0, r_, 64):
        sl = slice(lo, lo + 64)
        inl = inlier[sl]
        joint = (inl[:, :, None, :] | inl[:, None, :, :]).sum(axis=3)  # (r, M, M)
        cos = np.abs(np.einsum("rai,rbi->rab", normal[sl], normal[sl]))
        joint = np.where(cos <= limit, joint, -1)
        best = np.argmax(joint.reshape(len(inl), -1), axis=1)
        first[sl], second[sl] = best // m, best % m
    return first, second


def _sdf_cylinder(p: np.ndarray, xy: tuple[float, float], r: float) -> np.ndarray:
    radial = np.hypot(p[:, 0] - xy[0], p[:, 1] - xy[1]) - r
    axial = np.abs(p[:, 2] - (TOP + HEIGHT / 2)) - HEIGHT / 2
    return np.hypot(np.maximum(radial, 0), np.maximum(axial, 0)) + np.minimum(np.maximum(radial, axial), 0)


def _sdf_box(p: np.ndarray, centre: tuple[float, float], half: float) -> np.ndarray:
    q = np.abs(p - [centre[0], centre[1], TOP + half]) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _scene(kind: str, size: float, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(points after denoising, smooth, signed distance to the neighbour, which are the neighbour's)."""
    moved, _, smooth, _, sdf, at = _edge_scene(kind, size, seed, None)
    return moved, smooth, sdf, at


def _edge_scene(
    kind: str, size: float, seed: int, edges: EdgeSettings | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The neighbour's points: (denoised, and with ``edges`` its raw points on a two-face edge put onto
    it (:func:`on_edges`, both with the product's shift limit :func:`max_shift`), the same before
    :func:`on_edges`, smooth, on an edge, signed distance to the true neighbour, its axis)."""
    rng = np.random.default_rng(seed)
    at = (BOTTLE[0] + 0.035 + 0.05 + size, BOTTLE[1])
    neighbour = _cylinder(at, size) if kind == "cylinder" else _box_points(at, size)
    clean = np.concatenate([_cylinder(BOTTLE, 0.035), neighbour])
    noisy = clean + rng.normal(0.0, SIGMA, clean.shape)
    keep = noisy[:, 2] > TOP + CLEARANCE_SIGMAS * SIGMA  # the table's band becomes the exact plane
    if edges is None:  # as measured before (no shift limit)
        moved, smooth = denoised(noisy[keep])
        edge = np.zeros(len(moved), dtype=bool)
        before = moved
    else:
        limit = max_shift(CLEARANCE_SIGMAS * SIGMA)
        moved, smooth = denoised(noisy[keep], limit)
        noise = surface_noise(noisy[keep], along_z=False)
        assert noise is not None
        before = moved
        moved, edge = on_edges(before, smooth, noise.along_normals, limit, edges)
    mine = np.arange(len(clean))[keep] >= len(clean) - len(neighbour)
    sdf = _sdf_cylinder(moved, at, size) if kind == "cylinder" else _sdf_box(moved, at, size)
    return moved[mine], before[mine], smooth[mine], edge[mine], sdf[mine], np.asarray(at)


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


def _edge_errors(kind: str, size: float, settings: EdgeSettings) -> dict[str, Any]:
    """The candidate edge model's own error (session 14), over :data:`SEEDS`.

    Its points' signed distance to the true shape (where: the top 2 cm with the top face, else), the
    share of the raw points at the top it takes, the signed distance of those it leaves raw, and per
    probe that neither the raw points' cells (:data:`FINE`, kept at c = n) nor the denoised cells (kept
    at c - n + :func:`~baseplace.world.sensor_resolution.surface_error`) refuse at c = n, its distance
    to the nearest edge cell (:data:`FINE`): the u the edge cells must keep for c - n to hold there.
    Probes that the raw points refused neither before the model took some (holes of the model
    without it, counted in ``probes_free_without_the_edge_model``) are left out of that distance.
    """
    n = CLEARANCE_SIGMAS * SIGMA
    top = TOP + (HEIGHT if kind == "cylinder" else 2 * size)
    on_edge, still_raw, probe_d, probe_where = [], [], [], []
    raw_top = edge_top = holes = 0
    for seed in SEEDS:
        p, before, smooth, edge, sdf, at = _edge_scene(kind, size, seed, settings)
        high = p[:, 2] > top - 0.02
        raw_top += int((high & ~smooth).sum())
        edge_top += int((high & edge).sum())
        on_edge.append(sdf[edge])
        still_raw.append(sdf[~smooth & ~edge])
        centres, where = _probes(kind, size, at)
        cells = [np.unique(np.floor(p[m] / FINE).astype(np.int64).reshape(-1, 3), axis=0)
                 for m in (smooth, ~smooth & ~edge, edge)]  # fmt: skip
        d_den, d_raw, d_edge = (_box_distance(centres, c) for c in cells)
        raw_before = np.unique(np.floor(before[~smooth] / FINE).astype(np.int64).reshape(-1, 3), axis=0)
        free = (d_raw >= n) & (d_den >= surface_error(n))
        hole = (_box_distance(centres, raw_before) >= n) & (d_den >= surface_error(n))  # free without it too
        holes += int(hole.sum())
        probe_d.append(np.where(free & ~hole, d_edge, -np.inf))
        probe_where += where
    pd, pw = np.concatenate(probe_d), np.asarray(probe_where)
    return {
        "settings": settings.__dict__,
        "top_raw_points_taken": f"{edge_top}/{raw_top}",
        "edge_signed_distance": _stats(np.concatenate(on_edge)),
        "still_raw_signed_distance": _stats(np.concatenate(still_raw)),
        "probes_free_without_the_edge_model": holes,
        "probe_distance_to_edge_cells_where_raw_and_denoised_cells_do_not_refuse": {
            w: _stats(pd[(pw == w) & np.isfinite(pd)]) for w in sorted(set(probe_where))
        },
    }


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
                "edge_model": {name: _edge_errors(kind, size, e) for name, e in EDGE_SETTINGS.items()},
            }
            print(name, result["shapes"][name], flush=True)
    write_results(Path(args.out), {"benchmark": "clearance_errors", **result}, clock)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
