"""Certifying a reachability map's sparse cells by inverse kinematics, and measuring its quality.

A cell that random joint sampling reached only a few times is often a boundary cell: only part of
its poses are reachable (on the default TIAGo map, a random pose in a one-sample cell is reachable
57 % of the time, against 99 % in cells of 20 samples or more). Certification resolves these cells
by IK: every cell with fewer than ``below`` samples gets ``poses`` poses drawn inside it (position
uniform in the voxel, orientation uniform over the cell's Haar measure), each solved by damped
least squares started from a configuration the build drew in that cell, then from random
restarts. A cell is kept if at least ``keep_share`` of its poses solve, otherwise it is removed
from the map, so every consumer (forward and inverse queries, the fused plane lookup, surface
maps, candidates) reads the same certified cells. The share solved is stored per cell
(:attr:`ReachabilityMap.quality`, NaN where the cell was not certified).

The map's precision and recall are then measured on draws independent of the build and the
certification (their own seed stream): recall on held-out FK poses, precision against IK with
restarts on random poses inside cells drawn uniformly, and recorded in the map's
:class:`~baseplace.reachability.rmap.MapInfo`.

The reachability index is a Monte Carlo density (seed 000, section III-A; Zacharias et al. 2007);
certifying cells by IK is how capability maps settle the boundary (Porges et al. 2014, Freiburg
capability maps, which resolve cells by IK rather than by sampling).
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.geometry.healpix import TWO_PI
from baseplace.geometry.poses import FloatArray
from baseplace.reachability.grid import SE3Grid
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.model import Arm, Robot

CERTIFY_STREAM = 0xCE27
"""Seed stream of the certification's poses and restarts: ``default_rng([seed, CERTIFY_STREAM])``."""
MEASURE_STREAM = 0x0A11
"""Seed stream of the recorded precision and recall: disjoint from the build's chunks
``[seed, k]`` (k < 2^17 chunks) and from the certification."""
BATCH = 1 << 18


@dataclass(frozen=True)
class CertifySettings:
    """How to certify a map's sparse cells.

    Attributes:
        below: cells with fewer samples than this are certified (0: none).
        poses: IK poses drawn per certified cell.
        keep_share: a cell is kept if at least this share of its poses solves.
        restarts: random IK restarts after the start from the cell's own sample.
        max_iterations: iterations per IK attempt.
    """

    below: int = 5
    poses: int = 2
    keep_share: float = 0.5
    restarts: int = 2
    max_iterations: int = 60

    def __post_init__(self) -> None:
        if not (0 <= self.below <= 2**31):
            raise InputError(f"certify below must be a sample count >= 0, got {self.below}")
        if not (1 <= self.poses <= 64):
            raise InputError(f"certification poses per cell must be in 1..64, got {self.poses}")
        if not (0.0 < self.keep_share <= 1.0):
            raise InputError(f"certification keep share must be in (0, 1], got {self.keep_share}")
        if not (0 <= self.restarts <= 100 and 1 <= self.max_iterations <= 1000):
            raise InputError("certification restarts must be in 0..100 and iterations in 1..1000")


def certify_map(
    rmap: ReachabilityMap, robot: Robot, settings: CertifySettings, chunk_samples: object
) -> ReachabilityMap:
    """The map with its sparse cells resolved by IK (module docstring).

    Args:
        rmap: an uncertified map of ``robot``.
        robot: the robot.
        settings: what to certify.
        chunk_samples: ``k -> (n, joints)`` samples of build chunk ``k`` (the build's own draws,
            regenerated from its seed), to start IK from a configuration inside each cell.

    Returns:
        The certified map: removed cells gone, :attr:`quality` set, ``info`` recording how.
    """
    start = time.perf_counter()
    arm = robot.arm(rmap.info.arm)
    grid = rmap.grid
    low = np.flatnonzero(rmap.counts < settings.below)
    quality = np.full(len(rmap.cells), np.nan, dtype=np.float32)
    if len(low):
        low_cells = rmap.cells[low]
        seeds_q = _cell_configurations(arm, grid, low_cells, rmap.info.samples, chunk_samples)
        rng = np.random.default_rng([rmap.info.seed, CERTIFY_STREAM])
        solved = np.zeros(len(low), dtype=np.int64)
        for lo in range(0, len(low), BATCH):
            sl = slice(lo, lo + BATCH)
            cells = np.repeat(low_cells[sl], settings.poses)
            T = poses_in_cells(grid, cells, rng)
            ok = _solve(arm, T, np.repeat(seeds_q[sl], settings.poses, axis=0), settings, rng)
            solved[sl] = ok.reshape(-1, settings.poses).sum(axis=1)
        quality[low] = solved / settings.poses
    keep = ~(quality < settings.keep_share - 1e-9)  # NaN (not certified) is kept
    info = dataclasses.replace(
        rmap.info,
        certification=json.dumps(
            {
                **dataclasses.asdict(settings),
                "cells_certified": len(low),
                "cells_removed": int((~keep).sum()),
                "certify_time_s": round(time.perf_counter() - start, 2),
                "seed_stream": [rmap.info.seed, CERTIFY_STREAM],
            }
        ),
    )
    manip = rmap.manipulability[keep] if rmap.manipulability is not None else None
    return ReachabilityMap(grid, rmap.cells[keep], rmap.counts[keep], info, manip, quality[keep])


def _cell_configurations(
    arm: Arm, grid: SE3Grid, cells: NDArray[np.int64], samples: int, chunk_samples: object
) -> FloatArray:
    """(L, n) one build sample per (sorted) cell, found by replaying the build's ``samples`` in its chunks."""
    kernels = arm_kernels(arm)
    out = np.full((len(cells), arm.n_joints), np.nan)
    found = np.zeros(len(cells), dtype=np.bool_)
    replayed = 0
    for k in itertools.count():
        if replayed >= samples:
            break
        Q = chunk_samples(k)  # type: ignore[operator]
        if not len(Q):
            break
        replayed += len(Q)
        c = np.empty(len(Q), dtype=np.int64)
        kernels.bin_chunk(Q, *grid.params, c)
        pos = np.minimum(np.searchsorted(cells, c), len(cells) - 1)
        hit = (cells[pos] == c) & ~found[pos]
        out[pos[hit]] = Q[hit]
        found[pos[hit]] = True
        if found.all():
            break
    # A self-collision build dropped some samples; any sample in the cell is a start all the same.
    if not found.all():
        raise RuntimeError(f"{int((~found).sum())} map cells were not reached by the build's own samples")
    return out


_BOXES: dict[int, tuple[FloatArray, FloatArray]] = {}


def _pixel_boxes(nside: int, pixel_phi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per HEALPix pixel, bounds of (z, phi - pixel centre phi) that contain it (with margin)."""
    if nside in _BOXES:
        return _BOXES[nside]
    from baseplace.geometry.healpix import ang2pix_ring

    rng = np.random.default_rng(0)
    n_pix = 12 * nside * nside
    m = 4000 * n_pix
    z = rng.uniform(-1.0, 1.0, m)
    phi = rng.uniform(0.0, TWO_PI, m)
    pix = np.array([ang2pix_ring(nside, float(a), float(b)) for a, b in zip(z, phi, strict=True)])
    dphi = phi - pixel_phi[pix]
    dphi -= TWO_PI * np.floor((dphi + math.pi) / TWO_PI)
    lo = np.full((n_pix, 2), np.inf)
    hi = np.full((n_pix, 2), -np.inf)
    np.minimum.at(lo, pix, np.c_[z, dphi])
    np.maximum.at(hi, pix, np.c_[z, dphi])
    pad = 0.05 * (hi - lo) + 1e-3
    lo, hi = lo - pad, hi + pad
    lo[:, 0], hi[:, 0] = np.maximum(lo[:, 0], -1.0), np.minimum(hi[:, 0], 1.0)
    lo[:, 1], hi[:, 1] = np.maximum(lo[:, 1], -math.pi), np.minimum(hi[:, 1], math.pi)
    _BOXES[nside] = (lo, hi)
    return lo, hi


def poses_in_cells(grid: SE3Grid, cells: NDArray[np.int64], rng: np.random.Generator) -> FloatArray:
    """(N, 4, 4) one pose per cell, uniform in the cell (position and Haar measure of rotation).

    Rejection sampling from a box in (z, phi, twist) around the cell's HEALPix pixel: uniform in
    (z, phi, chi) is uniform in the Haar measure (``grid.py``), so accepted poses are uniform.
    """
    _, voxel_size, _, nside, n_twist, pixel_phi = grid.params
    lo, hi = _pixel_boxes(nside, pixel_phi)
    voxel, orient = np.divmod(cells, grid.n_orientations)
    pix, twist = np.divmod(orient, n_twist)
    centres = grid.voxel_centre(voxel)
    out = np.zeros((len(cells), 4, 4))
    todo = np.arange(len(cells))
    for _ in range(200):
        if not len(todo):
            return out
        p, k = pix[todo], twist[todo]
        z = rng.uniform(lo[p, 0], hi[p, 0])
        dphi = rng.uniform(lo[p, 1], hi[p, 1])
        chi = (k + rng.random(len(todo))) * (TWO_PI / n_twist)
        phi = pixel_phi[p] + dphi
        psi = chi - z * dphi
        T = np.zeros((len(todo), 4, 4))
        T[:, :3, :3] = _zyz(phi, np.arccos(np.clip(z, -1.0, 1.0)), psi)
        T[:, :3, 3] = centres[todo] + (rng.random((len(todo), 3)) - 0.5) * voxel_size
        T[:, 3, 3] = 1.0
        hit = grid.cell_index(T) == cells[todo]
        out[todo[hit]] = T[hit]
        todo = todo[~hit]
    raise RuntimeError("could not draw poses inside some cells")  # a bug in the pixel boxes


def _zyz(phi: FloatArray, theta: FloatArray, psi: FloatArray) -> FloatArray:
    cf, sf, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta), np.cos(psi), np.sin(psi)
    R = np.empty((len(phi), 3, 3))
    R[:, 0, 0] = cf * ct * cp - sf * sp
    R[:, 0, 1] = -cf * ct * sp - sf * cp
    R[:, 0, 2] = cf * st
    R[:, 1, 0] = sf * ct * cp + cf * sp
    R[:, 1, 1] = -sf * ct * sp + cf * cp
    R[:, 1, 2] = sf * st
    R[:, 2, 0] = -st * cp
    R[:, 2, 1] = st * sp
    R[:, 2, 2] = ct
    return R


def _solve(
    arm: Arm, T: FloatArray, start: FloatArray, settings: CertifySettings, rng: np.random.Generator
) -> NDArray[np.bool_]:
    from baseplace.robots.ik import DampedLeastSquaresIK, _solve_batch

    ik = DampedLeastSquaresIK(arm)
    seeds = np.empty((len(T), 1 + settings.restarts, arm.n_joints))
    seeds[:, 0] = start
    seeds[:, 1:] = rng.uniform(arm.lower, arm.upper, size=(len(T), settings.restarts, arm.n_joints))
    q = np.zeros((len(T), arm.n_joints))
    attempts = np.empty(len(T), dtype=np.int64)
    # limit_gain and saturate given (their defaults): the same compiled signature as ik.py's call
    _solve_batch(np.ascontiguousarray(T), seeds, arm.placements, arm.axes, arm.kinds, arm.T_last_tcp,
                 arm.lower, arm.upper, arm.continuous, settings.max_iterations, ik.tol_position,
                 ik.tol_rotation, ik.damping, q, attempts, 0.0, False)  # fmt: skip
    return attempts >= 0


def measure_quality(
    rmap: ReachabilityMap, robot: Robot, n_recall: int = 10_000, n_precision: int = 1000, seed: int = 0
) -> dict[str, float]:
    """Recall on held-out FK poses and precision against IK with restarts (cells drawn uniformly).

    The draws come from ``default_rng([seed, MEASURE_STREAM])``, disjoint from the build's chunks
    and the certification's poses. Precision: poses drawn uniformly over what the map calls
    reachable (a reached cell drawn uniformly, a pose uniform in it, kept if the map calls it
    reachable: with the support test, not every pose of a reached cell is), ``n_precision`` of
    them, solved by :class:`~baseplace.robots.ik.DampedLeastSquaresIK` (80 random restarts).

    Returns:
        ``{"recall": ..., "precision": ..., "n_recall": ..., "n_precision": ...}``.
    """
    from baseplace.robots.fk import forward_kinematics
    from baseplace.robots.ik import DampedLeastSquaresIK

    arm = robot.arm(rmap.info.arm)
    rng = np.random.default_rng([seed, MEASURE_STREAM])
    held_out = forward_kinematics(arm, arm.sample(rng, n_recall))
    recall = float((rmap.reachability(held_out) > 0).mean())
    k = min(n_precision, len(rmap.cells))
    kept: list[FloatArray] = []
    for _ in range(100):  # the map calls most of a reached cell reachable: a few rounds suffice
        if sum(len(T) for T in kept) >= k:
            break
        T = poses_in_cells(rmap.grid, rmap.cells[rng.integers(len(rmap.cells), size=k)], rng)
        kept.append(T[rmap.reachability(T) > 0])
    poses = np.concatenate(kept)[:k] if kept else np.zeros((0, 4, 4))
    k = len(poses)
    _, ok = DampedLeastSquaresIK(arm).solve_batch(poses, rng)
    return {
        "recall": round(recall, 4),
        "precision": round(float(ok.mean()), 4) if k else float("nan"),
        "n_recall": n_recall,
        "n_precision": k,
    }


def record_quality(rmap: ReachabilityMap, robot: Robot) -> ReachabilityMap:
    """The map with :func:`measure_quality` recorded in ``info.quality``."""
    start = time.perf_counter()
    measured = measure_quality(rmap, robot, seed=rmap.info.seed)
    measured["measure_time_s"] = round(time.perf_counter() - start, 2)
    return dataclasses.replace(rmap, info=dataclasses.replace(rmap.info, quality=json.dumps(measured)))
