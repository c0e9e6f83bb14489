"""Joint sampling in chunks and the counts they add up to: the body of a reachability-map build.

Samples are drawn in fixed-size chunks, chunk ``k`` from ``default_rng([seed, k])``, so a map
depends only on (robot, arm, grid, samples, seed), never on how the chunks are split across
threads or machines. Each chunk runs the compiled FK kernel and bins the TCP poses in parallel;
counts are integers, so partial maps add up exactly: a :class:`PartialMap` of any set of chunks
merges into a :class:`MapAccumulator` (the distributed build, ``distributed.py``) and is what a
checkpoint stores (``checkpoint.py``). :func:`baseplace.reachability.build.build_map` drives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.reachability.certify import CertifySettings, certify_map, record_quality
from baseplace.reachability.grid import SE3Grid, cell_of
from baseplace.reachability.rmap import MapInfo, ReachabilityMap, reach_bounds
from baseplace.reachability.settings import BuildSettings
from baseplace.reachability.support import choose_support
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.fk import chain_pose
from baseplace.robots.ik import _pose_and_jacobian
from baseplace.robots.model import Arm, Robot

CHUNK = 1 << 20
SAMPLES_PER_SUPPORT_COUNT = 16.0
"""The support count of a map is its mean count per reached cell divided by this, rounded, at least 1."""
MIN_MEAN_COUNT = 4.0
"""Below this mean count per reached cell a map has too few samples to tell the cells that sampling
missed from the unreachable ones: its support test is off (its cells answer alone)."""


def grid_for(arm: Arm, settings: BuildSettings) -> SE3Grid:
    """The grid covering every TCP position of ``arm`` at the settings' resolution."""
    lo, hi = reach_bounds(arm.placements, arm.axes, arm.kinds, arm.T_last_tcp, arm.lower, arm.upper)
    return SE3Grid.covering(lo, hi, settings.voxel_size, settings.orientation_resolution)


@nb.njit(cache=True, parallel=True)
def _bin_chunk(Q, placements, axes, kinds, T_last, origin, voxel_size, shape, nside, n_twist,
               pixel_phi, want_manip, cells, manip):  # fmt: skip
    n = Q.shape[1]
    for i in nb.prange(Q.shape[0]):
        R = np.empty((3, 3))
        t = np.empty(3)
        if want_manip:
            J = np.empty((6, n))
            _pose_and_jacobian(Q[i], placements, axes, kinds, T_last, R, t, J)
            manip[i] = math.sqrt(max(0.0, np.linalg.det(J @ J.T)))
        else:
            chain_pose(Q[i], placements, axes, kinds, T_last, R, t)
        cells[i] = cell_of(R, t[0], t[1], t[2], origin, voxel_size, shape, nside, n_twist, pixel_phi)


@dataclass(frozen=True)
class PartialMap:
    """The sparse sum of some chunks of a build: what a worker returns and a checkpoint stores.

    Attributes:
        chunks: (C,) sorted indices of the chunks it covers.
        cells: (K,) sorted flat indices of the cells reached.
        counts: (K,) samples per reached cell.
        best: (K,) best manipulability per cell (float32), or None if not kept.
        dropped: samples dropped as self-colliding.
    """

    chunks: NDArray[np.int64]
    cells: NDArray[np.int64]
    counts: NDArray[np.uint32]
    best: NDArray[np.float32] | None
    dropped: int


@nb.njit(cache=True)
def _accumulate(cells, keep, counts, manip, best, want_manip):
    outside = 0
    for i in range(cells.shape[0]):
        c = cells[i]
        if not keep[i]:
            continue
        if c < 0:
            outside += 1
            continue
        counts[c] += 1
        if want_manip and manip[i] > best[c]:
            best[c] = manip[i]
    return outside


class MapAccumulator:
    """Dense per-cell counts that chunks are added into; turns into a sparse map at the end.

    Every chunk is added at most once, either sampled here (:meth:`add_chunk`) or merged from a
    :class:`PartialMap` computed elsewhere (:meth:`merge`); :attr:`done` records which.

    Args:
        robot: the robot.
        arm_name: the arm (default arm if None).
        settings: build settings.
    """

    def __init__(self, robot: Robot, arm_name: str | None, settings: BuildSettings) -> None:
        self.robot = robot
        self.arm = robot.arm(arm_name)
        self.settings = settings
        self.grid = grid_for(self.arm, settings)
        self.counts = np.zeros(self.grid.n_cells, dtype=np.uint32)
        self.best = np.zeros(self.grid.n_cells if settings.manipulability else 1, dtype=np.float32)
        self.dropped = 0
        self.done = np.zeros(self.n_chunks, dtype=np.bool_)
        self._kernels = arm_kernels(self.arm)
        self._checker = None
        if settings.self_collision:
            from baseplace.robots.spheres import SphereModel  # coal stays the oracle (tests)

            self._checker = SphereModel(robot, self.arm.name)

    @property
    def n_chunks(self) -> int:
        """Number of chunks the settings' sample count splits into."""
        return math.ceil(self.settings.samples / CHUNK)

    @property
    def samples_done(self) -> int:
        """Samples in the chunks added so far."""
        n = int(self.done.sum()) * CHUNK
        if self.done[-1]:
            n -= self.n_chunks * CHUNK - self.settings.samples
        return n

    def pending_chunks(self) -> NDArray[np.int64]:
        """(C,) indices of the chunks not added yet, ascending."""
        return np.flatnonzero(~self.done).astype(np.int64)

    def chunk_samples(self, k: int) -> NDArray[np.float64]:
        """The joint samples of chunk ``k``: the same for every run with the same seed."""
        size = min(CHUNK, self.settings.samples - k * CHUNK)
        return self.arm.sample(np.random.default_rng([self.settings.seed, k]), size)

    def add_chunk(self, k: int) -> None:
        """Sample, bin and count chunk ``k``."""
        if self.done[k]:
            raise RuntimeError(f"chunk {k} was already added")
        Q = self.chunk_samples(k)
        arm, s = self.arm, self.settings
        cells = np.empty(len(Q), dtype=np.int64)
        manip = np.empty(len(Q) if s.manipulability else 1)
        if s.manipulability:
            _bin_chunk(Q, arm.placements, arm.axes, arm.kinds, arm.T_last_tcp, *self.grid.params,
                       True, cells, manip)  # fmt: skip
        else:
            self._kernels.bin_chunk(Q, *self.grid.params, cells)
        keep = np.ones(len(Q), dtype=np.bool_)
        if self._checker is not None:
            keep = ~self._checker.colliding_arm(arm, Q)
            self.dropped += int(len(Q) - keep.sum())
        outside = _accumulate(cells, keep, self.counts, manip, self.best, s.manipulability)
        if outside:  # reach_bounds is a proof, so this is a bug, never a user error
            raise RuntimeError(f"{outside} TCP poses fell outside the provable reach box")
        self.done[k] = True

    def partial(self) -> PartialMap:
        """The sparse state: every chunk added so far, its counts, best manipulability, drops."""
        cells = np.flatnonzero(self.counts).astype(np.int64)
        best = self.best[cells] if self.settings.manipulability else None
        done = np.flatnonzero(self.done).astype(np.int64)
        return PartialMap(done, cells, self.counts[cells], best, self.dropped)

    def merge(self, part: PartialMap) -> None:
        """Add a partial map of chunks not added yet; counts add, manipulability takes the max.

        Raises:
            InputError: the partial does not fit this build (chunks or cells out of range, a chunk
                added twice, manipulability present or missing).
        """
        chunks, cells = part.chunks, part.cells
        if np.any(np.diff(chunks) <= 0) or np.any(np.diff(cells) <= 0):
            raise InputError("partial map chunks and cells must be sorted and unique")
        if len(chunks) and (chunks[0] < 0 or chunks[-1] >= self.n_chunks):
            raise InputError(f"partial map has chunks outside 0..{self.n_chunks - 1}")
        if np.any(self.done[chunks]):
            raise InputError("partial map repeats chunks that were already added")
        if len(cells) and (cells[0] < 0 or cells[-1] >= self.grid.n_cells):
            raise InputError(f"partial map has cells outside the grid of {self.grid.n_cells} cells")
        if len(part.counts) != len(cells) or (part.best is not None and len(part.best) != len(cells)):
            raise InputError("partial map cells, counts and manipulability differ in length")
        if (part.best is not None) != self.settings.manipulability:
            raise InputError("partial map and build disagree on keeping manipulability")
        self.counts[cells] += part.counts
        if part.best is not None:
            self.best[cells] = np.maximum(self.best[cells], part.best)
        self.dropped += int(part.dropped)
        self.done[chunks] = True

    def result(self, build_time_s: float) -> ReachabilityMap:
        """The sparse map of everything added so far."""
        cells = np.flatnonzero(self.counts).astype(np.int64)
        s, arm = self.settings, self.arm
        info = MapInfo(
            robot=self.robot.name,
            urdf_sha256=self.robot.spec.urdf_sha256,
            arm=arm.name,
            joint_names=arm.joint_names,
            base_frame=arm.base_frame,
            tcp_frame=arm.tcp_frame,
            samples=s.samples,
            seed=s.seed,
            build_time_s=build_time_s,
            self_collision=s.self_collision,
            dropped_self_collision=self.dropped,
            self_collision_checker=self._checker.description if self._checker is not None else "",
        )
        manip = self.best[cells] if s.manipulability else None
        rmap = ReachabilityMap(self.grid, cells, self.counts[cells], info, manip)
        if s.certify > 0:
            rmap = certify_map(rmap, self.robot, CertifySettings(below=s.certify), self.chunk_samples)
        count = support_count(rmap.counts, arm.n_joints) if s.support_threshold > 0 else 0
        if count:  # the settings kept on the map's measured recall, and its quality recorded
            return choose_support(rmap, self.robot, count, s.support_threshold)
        if s.certify > 0:
            rmap = record_quality(rmap, self.robot)
        return rmap


def support_count(counts: NDArray[np.uint32], n_joints: int) -> int:
    """The support count for a map's counts and its arm's number of joints.

    Their mean over :data:`SAMPLES_PER_SUPPORT_COUNT`, rounded, at least 1. 0 (no support test)
    when the mean is below :data:`MIN_MEAN_COUNT`, or when the arm has fewer than 6 joints: it
    reaches a set of lower dimension than the 6D grid, every reached cell is a boundary cell, and
    the test would call almost nothing reachable. Chosen on development seeds (TIAGo at 5e7-2e8
    samples, the Panda at 0.5 and 0.8 rad; docs/maps.md).
    """
    mean = float(counts.mean()) if len(counts) else 0.0
    if n_joints < 6 or mean < MIN_MEAN_COUNT:
        return 0
    return max(1, round(mean / SAMPLES_PER_SUPPORT_COUNT))
