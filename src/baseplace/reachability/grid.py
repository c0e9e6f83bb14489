"""The SE(3) grid of a reachability map: position voxels x orientation bins.

Positions: a regular voxel grid (default 50 mm) over a box that provably contains every TCP
position of the arm.

Orientations: a Hopf-fibration grid (Yershova et al. 2010, "Generating uniform incremental grids
on SO(3) using the Hopf fibration"). A rotation R is split into the direction of its z axis, a
point of S^2 binned by HEALPix (equal-area pixels), and the twist about that axis, binned
uniformly in ``n_twist`` bins. In ZYZ Euler angles R = Rz(phi) Ry(theta) Rz(psi) the Haar measure
is ``sin(theta) dtheta dphi dpsi``, i.e. area on S^2 times uniform twist, so every cell has the
same Haar measure: sample counts per cell are comparable and uniform rotations fill the bins
evenly, which an Euler-angle grid does not (its bins shrink towards the poles). The twist is
measured as ``chi = psi + cos(theta) * (phi - phi_pixel_centre)``, the ZYZ twist transported from
the pixel centre; the shear has unit Jacobian, so cells stay equal-measure, and it keeps cells
compact next to the poles where plain ZYZ psi degenerates.

Default resolution: every bin is at most the requested angular size along each axis
(HEALPix pixel width ``sqrt(4 pi / n_pix)`` and twist width ``2 pi / n_twist``); 0.8 rad gives
nside 2 (48 directions, 0.51 rad) x 8 twists (0.79 rad) = 384 orientation bins.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numba as nb
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.healpix import TWO_PI, ang2pix_ring, pix2ang_ring
from baseplace.geometry.poses import FloatArray

IntArray = NDArray[np.int64]


def orientation_bins_for(resolution: float) -> tuple[int, int]:
    """``(nside, n_twist)`` such that every orientation bin is at most ``resolution`` [rad] wide."""
    if not (0.05 <= resolution <= math.pi):
        raise InputError(f"orientation resolution must be in [0.05, pi] rad, got {resolution}")
    nside = max(1, math.ceil(math.sqrt(math.pi / 3.0) / resolution))
    n_twist = max(1, math.ceil(TWO_PI / resolution - 1e-9))
    return nside, n_twist


@dataclass(frozen=True)
class SE3Grid:
    """Voxels x orientation bins over TCP poses relative to the base, ``T_base_tcp``.

    Attributes:
        origin: (3,) lower corner of the voxel box in the base frame [m].
        voxel_size: voxel edge [m].
        shape: voxel counts (nx, ny, nz).
        nside: HEALPix nside of the approach-direction bins (12 nside^2 pixels).
        n_twist: bins of the twist about the TCP z axis.
    """

    origin: tuple[float, float, float]
    voxel_size: float
    shape: tuple[int, int, int]
    nside: int
    n_twist: int
    _pixel_phi: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (self.voxel_size > 0 and math.isfinite(self.voxel_size)):
            raise InputError(f"voxel size must be a positive number of metres, got {self.voxel_size}")
        if min(self.shape) < 1 or self.nside < 1 or self.n_twist < 1:
            raise InputError(f"grid shape and bins must be positive, got {self.shape}")
        object.__setattr__(self, "_pixel_phi", pix2ang_ring(self.nside)[1])

    @classmethod
    def covering(
        cls, lo: ArrayLike, hi: ArrayLike, voxel_size: float, orientation_resolution: float
    ) -> SE3Grid:
        """The smallest grid, aligned to multiples of ``voxel_size``, that contains [lo, hi]."""
        if not (0.005 <= voxel_size <= 1.0):
            raise InputError(f"voxel size must be in [0.005, 1] m, got {voxel_size}")
        lo_i = np.floor(np.asarray(lo, dtype=float) / voxel_size).astype(int)
        hi_i = np.floor(np.asarray(hi, dtype=float) / voxel_size).astype(int) + 1
        nside, n_twist = orientation_bins_for(orientation_resolution)
        origin = tuple(float(v) for v in lo_i * voxel_size)
        shape = tuple(int(v) for v in hi_i - lo_i)
        return cls(origin, float(voxel_size), shape, nside, n_twist)  # type: ignore[arg-type]

    @property
    def n_voxels(self) -> int:
        """Number of position voxels."""
        return int(np.prod(self.shape))

    @property
    def n_orientations(self) -> int:
        """Number of orientation bins per voxel."""
        return 12 * self.nside * self.nside * self.n_twist

    @property
    def n_cells(self) -> int:
        """Number of SE(3) cells (voxels x orientation bins)."""
        return self.n_voxels * self.n_orientations

    @cached_property
    def params(self) -> tuple[FloatArray, float, IntArray, int, int, FloatArray]:
        """The grid as plain arrays for the compiled kernels."""
        return (
            np.asarray(self.origin, dtype=np.float64),
            float(self.voxel_size),
            np.asarray(self.shape, dtype=np.int64),
            int(self.nside),
            int(self.n_twist),
            self._pixel_phi,
        )

    def cell_index(self, T_base_tcp: ArrayLike) -> IntArray:
        """Flat cell index of each pose, -1 where the position lies outside the voxel box.

        Args:
            T_base_tcp: (N, 4, 4) TCP poses in the base frame.

        Returns:
            (N,) int64 indices ``voxel * n_orientations + orientation``.
        """
        T = np.ascontiguousarray(np.asarray(T_base_tcp, dtype=np.float64).reshape(-1, 4, 4))
        out = np.empty(len(T), dtype=np.int64)
        _cell_index_batch(T, *self.params, out)
        return out

    def voxel_centre(self, voxel: ArrayLike) -> FloatArray:
        """Centre [m] in the base frame of flat voxel indices (N,) -> (N, 3)."""
        ijk = np.stack(np.unravel_index(np.asarray(voxel, dtype=np.int64), self.shape), axis=-1)
        return np.asarray(self.origin) + (ijk + 0.5) * self.voxel_size

    def orientation_centre(self, orientation: ArrayLike) -> FloatArray:
        """Rotation at the centre of orientation bins (N,) -> (N, 3, 3)."""
        o = np.asarray(orientation, dtype=np.int64)
        pix, k = np.divmod(o, self.n_twist)
        z, phi = pix2ang_ring(self.nside)
        theta = np.arccos(z[pix])
        chi = (k + 0.5) * TWO_PI / self.n_twist
        return _rz(phi[pix]) @ _ry(theta) @ _rz(chi)

    def cell_centre(self, cell: ArrayLike) -> FloatArray:
        """Pose ``T_base_tcp`` at the centre of flat cell indices (N,) -> (N, 4, 4)."""
        v, o = np.divmod(np.asarray(cell, dtype=np.int64), self.n_orientations)
        T = np.zeros((len(v), 4, 4))
        T[:, :3, :3] = self.orientation_centre(o)
        T[:, :3, 3] = self.voxel_centre(v)
        T[:, 3, 3] = 1.0
        return T


def _rz(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((*np.shape(a), 3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def _ry(a: FloatArray) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((*np.shape(a), 3, 3))
    R[..., 0, 0], R[..., 0, 2], R[..., 2, 0], R[..., 2, 2], R[..., 1, 1] = c, s, -s, c, 1.0
    return R


@nb.njit(cache=True, inline="always")
def zyz_angles(R: FloatArray) -> tuple[float, float, float]:
    """``(z, phi, psi)`` of a rotation (3, 3) with ``R = Rz(phi) Ry(theta) Rz(psi)``.

    ``z = cos(theta)`` and the azimuth ``phi`` in [0, 2 pi) of its z axis, and the ZYZ twist ``psi``.
    """
    z = min(1.0, max(-1.0, R[2, 2]))
    phi = math.atan2(R[1, 2], R[0, 2])
    if phi < 0.0:
        phi += TWO_PI
    # phi + psi and phi - psi are well conditioned near the north and south pole respectively.
    if z >= 0.0:
        psi = math.atan2(R[1, 0] - R[0, 1], R[0, 0] + R[1, 1]) - phi
    else:
        psi = phi - math.atan2(-(R[1, 0] + R[0, 1]), R[1, 1] - R[0, 0])
    return z, phi, psi


@nb.njit(cache=True, inline="always")
def twist(z: float, phi: float, psi: float, pixel_phi: float) -> float:
    """The twist ``chi`` in [0, 2 pi) of a rotation in the pixel centred at azimuth ``pixel_phi``.

    The ZYZ twist transported from the pixel centre (see the module docstring).
    """
    dphi = phi - pixel_phi
    dphi -= TWO_PI * math.floor((dphi + math.pi) / TWO_PI)
    return (psi + z * dphi) % TWO_PI


@nb.njit(cache=True, inline="always")
def orientation_bin(R: FloatArray, nside: int, n_twist: int, pixel_phi: FloatArray) -> int:
    """Orientation bin of a rotation (3, 3): HEALPix pixel of its z axis, then twist bin."""
    z, phi, psi = zyz_angles(R)
    pix = ang2pix_ring(nside, z, phi)
    chi = twist(z, phi, psi, pixel_phi[pix])
    k = int(chi * (n_twist / TWO_PI))
    if k >= n_twist:
        k = n_twist - 1
    return pix * n_twist + k


@nb.njit(cache=True, inline="always")
def cell_of(
    R: FloatArray,
    px: float,
    py: float,
    pz: float,
    origin: FloatArray,
    voxel_size: float,
    shape: IntArray,
    nside: int,
    n_twist: int,
    pixel_phi: FloatArray,
) -> int:
    """Flat cell index of one pose (rotation R, position p), -1 outside the voxel box."""
    ix = math.floor((px - origin[0]) / voxel_size)
    iy = math.floor((py - origin[1]) / voxel_size)
    iz = math.floor((pz - origin[2]) / voxel_size)
    if ix < 0 or iy < 0 or iz < 0 or ix >= shape[0] or iy >= shape[1] or iz >= shape[2]:
        return -1
    voxel = (ix * shape[1] + iy) * shape[2] + iz
    n_orient = 12 * nside * nside * n_twist
    return voxel * n_orient + orientation_bin(R, nside, n_twist, pixel_phi)


@nb.njit(cache=True, parallel=True)
def _cell_index_batch(T, origin, voxel_size, shape, nside, n_twist, pixel_phi, out):
    for i in nb.prange(T.shape[0]):
        out[i] = cell_of(
            T[i, :3, :3], T[i, 0, 3], T[i, 1, 3], T[i, 2, 3],
            origin, voxel_size, shape, nside, n_twist, pixel_phi,
        )  # fmt: skip
