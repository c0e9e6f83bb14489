"""Reachability maps (RM) and their inverse queries (IRM).

A :class:`ReachabilityMap` stores, for each SE(3) cell of TCP poses relative to the base
(:class:`~baseplace.reachability.grid.SE3Grid`), how many random joint samples landed in it. The
reachability index of a cell is its count divided by the largest count, in [0, 1]; 0 means no
sample reached the cell. Inverse queries evaluate ``T_base_tcp = inv(T_world_base) @
T_world_target`` for batches of world base poses (seed 000, section III-A; Vahrenkamp et al. 2013).

The support test. A cell that sampling reached can still be mostly unreachable: the boundary of the
reachable set cuts it (on the default TIAGo grid, a random pose in a reached cell was reachable 80-87 %
of the time). A map with a support threshold answers a pose with its cell's index only if the
pose's *support* reaches the threshold, else 0. The support is the multilinear interpolation, at the
pose, of ``min(count / support_count, 1)`` over the 64 cell centres around it: the 8 voxel centres
around its position (trilinear) times the 4 direction pixels around its z axis (HEALPix bilinear
interpolation on the sphere) times the 2 twist bins around its twist. Deep inside the reached set it
is 1; it falls across the last half cell towards unreached cells, so the test cuts each boundary cell
near where the reachable set ends instead of keeping the whole cell (in one dimension, a density
threshold at half the interior density finds the boundary to a tenth of a cell). At a cell's centre
the support is the cell's own ``min(count / support_count, 1)``, which is what consumers that read
whole cells use (:attr:`ReachabilityMap.cell_floor`).

The hole fill. The support test never answers a pose whose own cell sampling missed, and a sparse
map misses reachable cells by chance (a 1e7-sample TIAGo map, 4 samples per reached cell: 7 % of
reachable poses fall in unreached cells). A map with a fill threshold (``MapInfo.fill_threshold`` >
0, only with the support test) answers a pose in an unreached cell (or unreached voxel) if its
support, the same interpolation over the 64 cell centres around it, reaches the fill threshold.
Such a pose gets half the index of a one-sample cell (``0.5 / max count``), below every reached
cell's, so consumers that rank poses by index rank it last; consumers that read whole cells from
the tables never see it. The support of a pose in an unreached cell is 0 at the cell's centre and
rises towards reached neighbours, so the fill answers the parts of a hole next to reached cells.
With the fill threshold 0 (the default, and maps written before it) the lookup is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Literal, Protocol

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.healpix import TWO_PI, interp_weights_ring
from baseplace.geometry.poses import FloatArray
from baseplace.guards import check_alloc
from baseplace.reachability.grid import SE3Grid, cell_of, twist, zyz_angles


@dataclass(frozen=True)
class MapInfo:
    """Provenance of a map, stored with it.

    Attributes:
        robot: robot name.
        urdf_sha256: SHA-256 of the URDF the map was built from.
        arm: arm name.
        joint_names: the sampled joints, in chain order.
        base_frame: frame the TCP poses are relative to.
        tcp_frame: the TCP frame.
        samples: joint samples drawn.
        seed: random seed of the build.
        build_time_s: wall time of the build [s].
        self_collision: whether self-colliding samples were dropped.
        dropped_self_collision: samples dropped as self-colliding.
        self_collision_checker: which self-collision check dropped them (empty without one).
        certification: JSON of how the sparse cells were certified by IK (``certify.py``), or "".
        quality: JSON of the measured recall and precision (``certify.measure_quality``), or "".
        support_count: samples at which a cell gives full support (see the module docstring);
            0: no support test, every pose in a reached cell gets the cell's index.
        support_threshold: the support a pose needs, in [0, 1]; 0: no support test.
        fill_threshold: the support a pose in an unreached cell needs to be answered (the hole
            fill, module docstring), in [0, 1]; 0 (maps written before it): off. Only with the
            support test.
    """

    robot: str
    urdf_sha256: str
    arm: str
    joint_names: tuple[str, ...]
    base_frame: str
    tcp_frame: str
    samples: int
    seed: int
    build_time_s: float = 0.0
    self_collision: bool = False
    dropped_self_collision: int = 0
    self_collision_checker: str = ""
    certification: str = ""
    quality: str = ""
    support_count: int = 0
    support_threshold: float = 0.0
    fill_threshold: float = 0.0

    def __post_init__(self) -> None:
        count = self.support_count
        if type(count) is not int or not 0 <= count <= 2**32:
            raise InputError(f"support_count must be an integer in [0, 2^32], got {count!r}")
        for name in ("support_threshold", "fill_threshold"):
            threshold = getattr(self, name)
            if type(threshold) not in (int, float) or not 0.0 <= threshold <= 1.0:
                raise InputError(f"{name} must be a number in [0, 1], got {threshold!r}")

    @property
    def supported(self) -> bool:
        """Whether the map answers with the support test."""
        return self.support_count > 0 and self.support_threshold > 0.0


@dataclass(frozen=True)
class ReachabilityMap:
    """Sample counts over an SE(3) grid of ``T_base_tcp``, stored sparsely.

    Attributes:
        grid: the SE(3) grid.
        cells: (K,) sorted flat indices of the cells reached by at least one sample.
        counts: (K,) samples per reached cell.
        info: provenance.
        manipulability: (K,) best Yoshikawa manipulability per cell, or None.
        quality: (K,) share of IK-solved certification poses per cell (NaN: not certified, the
            cell had enough samples), or None for an uncertified map (``certify.py``).
    """

    grid: SE3Grid
    cells: NDArray[np.int64]
    counts: NDArray[np.uint32]
    info: MapInfo
    manipulability: NDArray[np.float32] | None = None
    quality: NDArray[np.float32] | None = None
    _lookup: tuple[NDArray[np.int32], NDArray[np.float32]] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    @property
    def n_reached(self) -> int:
        """Number of cells with reachability > 0."""
        return len(self.cells)

    @cached_property
    def reached_voxels(self) -> NDArray[np.int64]:
        """The voxels (sorted, distinct) that hold at least one reached cell."""
        voxels = self.cells // self.grid.n_orientations  # sorted, as the cells are
        first = np.ones(len(voxels), dtype=np.bool_)
        np.not_equal(voxels[1:], voxels[:-1], out=first[1:])
        return voxels[first]

    @cached_property
    def horizontal_reach(self) -> float:
        """Largest horizontal distance [m] from the base origin to a reached voxel's far corner."""
        if len(self.cells) == 0:
            return 0.0
        centres = self.grid.voxel_centre(self.reached_voxels)
        return float(np.hypot(centres[:, 0], centres[:, 1]).max() + self.grid.voxel_size * math.sqrt(0.5))

    @property
    def index(self) -> NDArray[np.float32]:
        """Reachability index per stored cell, ``count / max(count)`` in (0, 1].

        Computed per call, not kept: queries read :attr:`tables`, which hold the same values.
        """
        if len(self.counts) == 0:
            return np.zeros(0, dtype=np.float32)
        return (self.counts / self.counts.max()).astype(np.float32)

    @cached_property
    def tables(self) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
        """Dense lookup: per voxel a row in a (voxels reached, orientations) block, or -1."""
        n_orient = self.grid.n_orientations
        check_alloc(
            self.grid.n_voxels * 4.0, "the lookup table of the map's grid", f"map of {self.info.robot}"
        )
        reached = self.reached_voxels
        offset = np.full(self.grid.n_voxels, -1, dtype=np.int32)
        offset[reached] = np.arange(len(reached), dtype=np.int32)
        blocks = np.zeros((len(reached), n_orient), dtype=np.float32)
        top = float(self.counts.max()) if len(self.counts) else 1.0
        step = 1 << 20  # in slices: the temporaries stay small next to the tables
        for lo in range(0, len(self.cells), step):
            c = self.cells[lo : lo + step]
            v = c // n_orient
            blocks[offset[v], c - v * n_orient] = self.counts[lo : lo + step] / top
        return offset, blocks

    @cached_property
    def support(self) -> tuple[float, float, float, float]:
        """``(full, threshold, fill, filled)`` for the lookup kernels; ``(1, 0, 0, 0)`` without a support test.

        ``full`` is the table value (``count / max``) of full support, ``threshold`` the support a
        pose in a reached cell needs, ``fill`` the support a pose in an unreached cell needs (0:
        no hole fill) and ``filled`` the value such a pose gets: half a one-sample cell's, below
        every reached cell's.
        """
        info = self.info
        if not info.supported or len(self.counts) == 0:
            return 1.0, 0.0, 0.0, 0.0
        top = float(self.counts.max())
        fill = float(info.fill_threshold)
        filled = float(np.float32(0.5 / top)) if fill > 0 else 0.0  # as the batch kernels store it
        return info.support_count / top, float(info.support_threshold), fill, filled

    def with_support(self, count: int, threshold: float, fill: float = 0.0) -> ReachabilityMap:
        """The same cells read with another support test (count or threshold 0: cells read whole).

        ``fill``: the hole fill's threshold (0: off).
        """
        info = replace(self.info, support_count=count, support_threshold=threshold, fill_threshold=fill)
        return replace(self, info=info)

    @property
    def cell_floor(self) -> float:
        """The least table value of a cell whose centre passes the support test.

        The smallest positive value without one. For consumers that read whole cells from
        :attr:`tables`.
        """
        full, threshold, _, _ = self.support
        return max(full * threshold, float(np.finfo(np.float32).tiny))

    @cached_property
    def _one_pose_args(
        self,
    ) -> tuple[FloatArray, NDArray[np.int64], FloatArray, NDArray[np.int32], NDArray[np.float32]]:
        """The grid and tables packed in few arrays: a compiled call's cost grows with its arguments."""
        origin, voxel_size, shape, nside, n_twist, pixel_phi = self.grid.params
        offset, blocks = self.tables
        grid_f = np.array([*origin, voxel_size, *self.support], dtype=np.float64)
        grid_i = np.array([*shape, nside, n_twist], dtype=np.int64)
        return grid_f, grid_i, pixel_phi, offset, blocks

    def value(self, T_base_tcp: ArrayLike) -> float:
        """Reachability index of one TCP pose relative to the base: the single-pose query.

        Runs on the calling thread (no thread pool), so its rate holds on a loaded machine.

        Args:
            T_base_tcp: (4, 4) TCP pose in the base frame [m].

        Returns:
            The index in [0, 1]; 0 outside the map.
        """
        T = T_base_tcp
        if not (
            type(T) is np.ndarray and T.dtype == np.float64 and T.shape == (4, 4) and T.flags.c_contiguous
        ):
            T = _poses(T_base_tcp, "T_base_tcp")
            if len(T) != 1:
                raise InputError(
                    f"value() takes one pose (4, 4), got {len(T)}; use reachability() for a batch"
                )
            T = T[0]
        v = _value_one(T, *self._one_pose_args)
        if v < 0.0:
            raise InputError("T_base_tcp contains NaN or infinity")
        return v

    def reachability(self, T_base_tcp: ArrayLike) -> NDArray[np.float32]:
        """Reachability index of TCP poses relative to the base.

        Args:
            T_base_tcp: (N, 4, 4) or (4, 4).

        Returns:
            (N,) values in [0, 1]; 0 outside the map.
        """
        T = _poses(T_base_tcp, "T_base_tcp")
        out = np.empty(len(T), dtype=np.float32)
        offset, blocks = self.tables
        _batch_kernel(len(T))(_IDENTITY, T, False, *self.grid.params, offset, blocks, *self.support, out)
        return out

    def inverse(self, T_world_target: ArrayLike, T_world_base: ArrayLike) -> NDArray[np.float32]:
        """Reachability of one world target from each of a batch of world base poses.

        Args:
            T_world_target: (4, 4) TCP target in the world.
            T_world_base: (N, 4, 4) base poses in the world.

        Returns:
            (N,) reachability index of ``inv(T_world_base) @ T_world_target``.
        """
        target = _poses(T_world_target, "T_world_target")
        if len(target) != 1:
            raise InputError(f"inverse() takes one target pose (4, 4), got {len(target)}")
        bases = _poses(T_world_base, "T_world_base")
        out = np.empty(len(bases), dtype=np.float32)
        offset, blocks = self.tables
        _batch_kernel(len(bases))(
            target[0], bases, True, *self.grid.params, offset, blocks, *self.support, out
        )
        return out

    def inverse_on_plane(
        self, T_world_target: ArrayLike, xy: ArrayLike, gamma: ArrayLike, normal: ArrayLike, d: float
    ) -> NDArray[np.float32]:
        """:meth:`inverse` for plane-constrained base poses (seed 000 III-A), without building them.

        Args:
            T_world_target: (4, 4) world target.
            xy: (N, 2) base positions [m]; z follows the plane.
            gamma: (N,) rotations about the plane normal [rad].
            normal: (3,) upward plane normal.
            d: offset of the plane ``n . p + d = 0`` [m].

        Returns:
            (N,) the same values as ``inverse(T_world_target, plane_base_poses(...))``.
        """
        from baseplace.geometry.surface_poses import plane_frame

        target = _poses(T_world_target, "T_world_target")[0]
        R0 = plane_frame(normal)
        n = R0[:, 2]
        d_unit = float(d) / float(np.linalg.norm(np.asarray(normal, dtype=float)))
        p = np.ascontiguousarray(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        g = np.ascontiguousarray(np.asarray(gamma, dtype=np.float64).ravel())
        out = np.empty(len(p), dtype=np.float32)
        offset, blocks = self.tables
        plane = _lookup_plane if len(p) >= SERIAL_BELOW else _lookup_plane_serial
        plane(target, p, g, R0, n, d_unit, *self.grid.params, offset, blocks, *self.support, out)
        return out


class ReachabilityQuery(Protocol):
    """Anything that scores world base poses for a world target: higher is more reachable."""

    def inverse(self, T_world_target: ArrayLike, T_world_base: ArrayLike) -> NDArray[np.float32]:
        """(N,) reachability in [0, 1] of the target from each base pose (N, 4, 4)."""
        ...


@dataclass(frozen=True)
class ArmCombination:
    """Several arms' maps as one query: ``any`` arm (max) or ``both``/all arms (min).

    Attributes:
        maps: one map per arm, all of the same robot.
        mode: "any" (either arm reaches: max) or "both" (every arm reaches: min).
    """

    maps: tuple[ReachabilityMap, ...]
    mode: Literal["any", "both"] = "any"

    def __post_init__(self) -> None:
        if self.mode not in ("any", "both"):
            raise InputError(f"unknown arm combination {self.mode!r}; valid: any, both")
        if len({m.info.robot for m in self.maps}) != 1:
            raise InputError("arm combination needs maps of one robot")

    def inverse(self, T_world_target: ArrayLike, T_world_base: ArrayLike) -> NDArray[np.float32]:
        """(N,) combined reachability of the target from each base pose."""
        values = np.stack([m.inverse(T_world_target, T_world_base) for m in self.maps])
        return values.max(axis=0) if self.mode == "any" else values.min(axis=0)


def inverse_reachability(
    query: ReachabilityQuery, T_world_targets: ArrayLike, T_world_base: ArrayLike
) -> NDArray[np.float32]:
    """Reachability of several targets that must all be reached: the min over targets.

    Args:
        query: a map or an arm combination.
        T_world_targets: (K, 4, 4) or (4, 4) world TCP targets.
        T_world_base: (N, 4, 4) world base poses.

    Returns:
        (N,) min over the K targets.
    """
    targets = _poses(T_world_targets, "T_world_targets")
    bases = _poses(T_world_base, "T_world_base")
    value = np.ones(len(bases), dtype=np.float32)
    for target in targets:
        np.minimum(value, query.inverse(target, bases), out=value)
    return value


def _poses(T: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(T, dtype=np.float64)
    if arr.shape[-2:] != (4, 4):
        raise InputError(f"{name} must have shape (4, 4) or (N, 4, 4), got {arr.shape}")
    arr = np.ascontiguousarray(arr.reshape(-1, 4, 4))
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or infinity")
    return arr


# The lookups compile their heavy body (the table value and its support test, inlined into a loop
# over rows) once per kind of row: ``_batch_rows`` and ``_plane_rows``. The serial lookup calls
# them on all rows; the parallel one on chunks of rows (one call per chunk, so their cost is
# nothing beside the rows'). Inlining the body into each parallel and serial kernel instead
# compiled it six times, about 2 minutes of a cold start (docs/maps.md, "Query rate and memory").
ROWS_PER_CHUNK = 256


@nb.njit(cache=True)
def _plane_rows(lo, hi, T_wt, xy, gamma, R0, n, d, origin, voxel_size, shape, nside, n_twist, pixel_phi,
                offset, blocks, full, threshold, fill, filled, out):  # fmt: skip
    """Rows ``lo:hi`` of :meth:`ReachabilityMap.inverse_on_plane`."""
    B = np.empty((3, 4))
    R = np.empty((3, 3))
    scratch = _support_scratch()
    for i in range(lo, hi):
        c, s = math.cos(gamma[i]), math.sin(gamma[i])
        for a in range(3):  # R = R0 Rz(gamma): x' = c x0 + s y0, y' = -s x0 + c y0, z' = n
            B[a, 0] = c * R0[a, 0] + s * R0[a, 1]
            B[a, 1] = -s * R0[a, 0] + c * R0[a, 1]
            B[a, 2] = R0[a, 2]
        B[0, 3] = xy[i, 0]
        B[1, 3] = xy[i, 1]
        B[2, 3] = -(d + n[0] * xy[i, 0] + n[1] * xy[i, 1]) / n[2]
        px, py, pz = _base_to_target(T_wt, B, R)
        out[i] = _table_value(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi, offset,
                              blocks, full, threshold, fill, filled, scratch)  # fmt: skip


@nb.njit(cache=True, inline="always")
def _base_to_target(T_wt, B, R):
    """``inv(B) @ T_wt`` for a base pose B (rows 0-2 of a 4x4): its rotation into R, its position returned."""
    dx, dy, dz = T_wt[0, 3] - B[0, 3], T_wt[1, 3] - B[1, 3], T_wt[2, 3] - B[2, 3]
    px = B[0, 0] * dx + B[1, 0] * dy + B[2, 0] * dz
    py = B[0, 1] * dx + B[1, 1] * dy + B[2, 1] * dz
    pz = B[0, 2] * dx + B[1, 2] * dy + B[2, 2] * dz
    for a in range(3):
        for b in range(3):
            R[a, b] = B[0, a] * T_wt[0, b] + B[1, a] * T_wt[1, b] + B[2, a] * T_wt[2, b]
    return px, py, pz


@nb.njit(cache=True, parallel=True)
def _lookup_plane(T_wt, xy, gamma, R0, n, d, origin, voxel_size, shape, nside, n_twist, pixel_phi,
                  offset, blocks, full, threshold, fill, filled, out):  # fmt: skip
    n_rows = xy.shape[0]
    for k in nb.prange((n_rows + ROWS_PER_CHUNK - 1) // ROWS_PER_CHUNK):
        lo = k * ROWS_PER_CHUNK
        _plane_rows(lo, min(lo + ROWS_PER_CHUNK, n_rows), T_wt, xy, gamma, R0, n, d, origin, voxel_size,
                    shape, nside, n_twist, pixel_phi, offset, blocks, full, threshold, fill, filled, out)  # fmt: skip


@nb.njit(cache=True, inline="always")
def _table_value(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi, offset, blocks,
                 full, threshold, fill, filled, scratch):  # fmt: skip
    """Reachability index of the pose (R, p) from the dense lookup tables.

    A reached cell's value where the pose's support reaches ``threshold`` (> 0; module docstring);
    ``filled`` in an unreached cell whose pose's support reaches ``fill`` (> 0: the hole fill);
    else 0.
    """
    c = cell_of(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi)
    if c < 0:
        return 0.0
    n_orient = blocks.shape[1]
    row = offset[c // n_orient]
    value = blocks[row, c % n_orient] if row >= 0 else 0.0
    if value == 0.0:  # unreached: answered only by the hole fill
        if fill <= 0.0:
            return 0.0
        value, threshold = filled, fill
    elif threshold <= 0.0:
        return value
    supported = _supported(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi, offset,
                           blocks, full, threshold, scratch)  # fmt: skip
    return value if supported else 0.0


@nb.njit(cache=True, inline="always")
def _support_scratch():
    """The arrays :func:`_supported` works in: 4 pixels then 8 twist bins, and their weights.

    Allocated once per run of rows, not per pose.
    """
    return np.empty(12, dtype=np.int64), np.empty(12)


@nb.njit(cache=True, inline="always")
def _supported(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi, offset, blocks, full,
               threshold, scratch):  # fmt: skip
    """Whether the support of the pose (R, p) reaches ``threshold``.

    The support interpolates ``min(table value / full, 1)`` over the 8 voxel centres x 4 direction
    pixels x 2 twist bins around the pose (module docstring). Stops once the answer is certain.
    """
    z, phi, psi = zyz_angles(R)
    cells, weights = scratch
    pix, pixel_w, bins, bin_w = cells[:4], weights[:4], cells[4:], weights[4:]
    interp_weights_ring(nside, z, phi, pix, pixel_w)
    for a in range(4):
        u = twist(z, phi, psi, pixel_phi[pix[a]]) * (n_twist / TWO_PI) - 0.5
        k = math.floor(u)
        w = u - k
        bins[2 * a] = pix[a] * n_twist + k % n_twist
        bins[2 * a + 1] = pix[a] * n_twist + (k + 1) % n_twist
        bin_w[2 * a] = pixel_w[a] * (1.0 - w)
        bin_w[2 * a + 1] = pixel_w[a] * w
    ux = (px - origin[0]) / voxel_size - 0.5
    uy = (py - origin[1]) / voxel_size - 0.5
    uz = (pz - origin[2]) / voxel_size - 0.5
    x0, y0, z0 = math.floor(ux), math.floor(uy), math.floor(uz)
    wx, wy, wz = ux - x0, uy - y0, uz - z0
    support = 0.0
    left = 1.0  # weight of the voxel centres not visited yet
    for dx in range(2):
        for dy in range(2):
            for dz in range(2):
                ix, iy, iz = x0 + dx, y0 + dy, z0 + dz
                w = (wx if dx else 1.0 - wx) * (wy if dy else 1.0 - wy) * (wz if dz else 1.0 - wz)
                left -= w
                if 0 <= ix < shape[0] and 0 <= iy < shape[1] and 0 <= iz < shape[2]:
                    row = offset[(ix * shape[1] + iy) * shape[2] + iz]
                    if row >= 0:
                        for j in range(8):
                            support += w * bin_w[j] * min(blocks[row, bins[j]] / full, 1.0)
                if support >= threshold:
                    return True
                if support + left < threshold - 1e-12:
                    return False
    return support >= threshold


@nb.njit(cache=True)
def _batch_rows(lo, hi, T_wt, T_wb, invert, origin, voxel_size, shape, nside, n_twist, pixel_phi,
                offset, blocks, full, threshold, fill, filled, out):  # fmt: skip
    """Rows ``lo:hi``: the value of ``inv(T_wb[i]) @ T_wt`` (``invert``) or of ``T_wb[i]``."""
    R = np.empty((3, 3))
    scratch = _support_scratch()
    for i in range(lo, hi):
        B = T_wb[i]
        if invert:  # T_base_tcp = B^-1 T_wt
            px, py, pz = _base_to_target(T_wt, B, R)
        else:
            px, py, pz = B[0, 3], B[1, 3], B[2, 3]
            for a in range(3):
                for b in range(3):
                    R[a, b] = B[a, b]
        out[i] = _table_value(R, px, py, pz, origin, voxel_size, shape, nside, n_twist, pixel_phi, offset,
                              blocks, full, threshold, fill, filled, scratch)  # fmt: skip


@nb.njit(cache=True, parallel=True)
def _lookup_batch(T_wt, T_wb, invert, origin, voxel_size, shape, nside, n_twist, pixel_phi,
                  offset, blocks, full, threshold, fill, filled, out):  # fmt: skip
    n_rows = T_wb.shape[0]
    for k in nb.prange((n_rows + ROWS_PER_CHUNK - 1) // ROWS_PER_CHUNK):
        lo = k * ROWS_PER_CHUNK
        _batch_rows(lo, min(lo + ROWS_PER_CHUNK, n_rows), T_wt, T_wb, invert, origin, voxel_size, shape,
                    nside, n_twist, pixel_phi, offset, blocks, full, threshold, fill, filled, out)  # fmt: skip


@nb.njit(cache=True)
def _value_one(T, grid_f, grid_i, pixel_phi, offset, blocks):
    """Index of one pose (4, 4) from the packed tables; -1 if it is not finite."""
    for a in range(3):
        for b in range(4):
            if not math.isfinite(T[a, b]):
                return -1.0
    out = np.empty(1, dtype=np.float32)
    # rows lo:hi and ``invert`` as run-time values, not the constants 0, 1 and False: numba would
    # compile _batch_rows anew for those literal types (about 20 s of a cold start) instead of
    # calling the overload the batch lookups compile and cache
    hi = out.shape[0]
    lo = hi - 1
    invert = hi != hi
    _batch_rows(lo, hi, T, T.reshape((1, 4, 4)), invert, grid_f[:3], grid_f[3], grid_i[:3], grid_i[3],
                grid_i[4], pixel_phi, offset, blocks, grid_f[4], grid_f[5], grid_f[6], grid_f[7], out)  # fmt: skip
    return out[0]


SERIAL_BELOW = 2048
"""Batches smaller than this are looked up on the calling thread: waking the thread pool costs
more than the lookups, and under CPU load a parallel call waits for every worker (a single-pose
query ran 6-13x slower with 2 threads on a loaded 2-core machine than on 1)."""

_IDENTITY = np.eye(4)


def _lookup_batch_serial(*args: object) -> None:
    """:func:`_lookup_batch` on the calling thread."""
    _batch_rows(0, len(args[1]), *args)  # type: ignore[arg-type]


def _lookup_plane_serial(*args: object) -> None:
    """:func:`_lookup_plane` on the calling thread."""
    _plane_rows(0, len(args[1]), *args)  # type: ignore[arg-type]


def _batch_kernel(n: int):
    """The compiled lookup for a batch of ``n`` poses: serial below :data:`SERIAL_BELOW`."""
    return _lookup_batch if n >= SERIAL_BELOW else _lookup_batch_serial


def reach_bounds(placements: FloatArray, axes: FloatArray, kinds: NDArray[np.int64],
                 T_last: FloatArray, lower: FloatArray, upper: FloatArray) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    """Axis-aligned box in the base frame that provably contains every TCP position.

    Every transform after the first joint moves the TCP by at most the length of its
    translation (plus the stroke of prismatic joints), so the TCP lies within that total radius
    of the first joint's origin, which itself slides along its axis if that joint is prismatic.
    """
    radius = float(np.linalg.norm(T_last[:3, 3]))
    radius += sum(float(np.linalg.norm(P[:3, 3])) for P in placements[1:])
    radius += sum(
        max(abs(lo), abs(hi)) for k, lo, hi in zip(kinds[1:], lower[1:], upper[1:], strict=True) if k == 1
    )
    P0 = placements[0]
    ends = [P0[:3, 3] + (P0[:3, :3] @ axes[0]) * (q if kinds[0] == 1 else 0.0) for q in (lower[0], upper[0])]
    lo = np.minimum(*ends) - radius
    hi = np.maximum(*ends) + radius
    margin = 1e-6 + 1e-9 * math.fsum(abs(v) for v in (*lo, *hi))
    return lo - margin, hi + margin
