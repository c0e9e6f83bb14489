"""The scene near the grasped object at sensor resolution, its support an exact plane (issue 25).

A 25 mm voxel over-approximates its points by up to a whole cube, so the hand working a few
centimetres from a table top or a neighbour met voxels while the true scene was free. Within
:data:`~baseplace.world.support_plane.RADIUS` of the object's footprint (the hand's approach plus
its length) the support and obstacle groups are the cloud's own points in :data:`FINE` cells
instead (:func:`fine_groups`); farther away the 25 mm voxels stay. The plane the object stands on,
when the cloud fits one (:func:`~baseplace.world.support_plane.fit_support_slab`), is an exact
plane (:class:`SupportPlane`): a prism whose top face is the fitted plane, and its points leave
the point groups. The robot keeps :attr:`~baseplace.world.environment.Environment.clearance` from
the fine cells and the plane, derived from the scene's noise in its worst direction
(:func:`surface_noise`, :func:`derived_clearance`).

The clearance is stated against the TRUE surface, the same for every kind of model element (the
lead's decision of issue 25). With c the clearance (given, or derived: :func:`derived_clearance`)
and n the derived noise margin (:data:`CLEARANCE_SIGMAS` sigma of the scene's noise, the derived
clearance even when c is given), the robot keeps at least c - n from the true surface at
:data:`CLEARANCE_SIGMAS` sigma: 0 at the derived default, it does not touch. Each kind keeps
c - n + u from its own cells (:func:`margin`), u that kind's own error at :data:`CLEARANCE_SIGMAS`
sigma, measured:

* a point at an edge or a corner stays as measured (no corner is rounded off): its error is the
  noise, u = n, so its margin is c. In :data:`FINE` cells (:class:`RawCells`) where the noise
  margin covers the gaps between the samples (their covering radius h, from the density:
  :func:`sample_spacing`, at most :func:`free_reach`: 1 cm spacing at 3 mm noise), else in
  :data:`EDGE_CELL` cells as before (a 5 mm cell reaches 0-5 mm beyond its point along each axis,
  up to 8.7 mm diagonally; on sparser clouds it still lets spheres through:
  tests/test_clearance_bound_spacing.py);
* a point on a smooth surface (a face, a bottle's side) is put onto the plane fitted to its
  neighbours (:func:`denoised`; not when that moves it beyond its noise at 4 sigma plus the chord,
  :func:`max_shift`: a plane through both faces of an edge), in :data:`FINE` cells (:class:`SurfaceCells`): u =
  :func:`surface_error`, its chord, :data:`CLEARANCE_SIGMAS` of its spread and the gaps between the
  points (9.1 mm at 3 mm noise, where n = 9.2 mm; bench/clearance_errors.py);
* the exact plane: its fit's 3 standard errors, at least :data:`MIN_CLEARANCE`, when c is derived
  (:func:`derived_plane_clearance`), else c.

A neighbour standing on the exact plane that fits an upright cylinder or box as a whole
(:mod:`baseplace.world.neighbour_shapes`: hundreds of points, its acceptance test) is an exact
convex instead of cells, kept at c - n + u with u its fit's error plus the test's allowance
(4.3-7.1 mm on the 61 of 63 bottles of the find-rate dev scenes at 3 mm noise, where a raw rim point's is n = 9 mm;
bench/shape_fits.py); a cluster that fails the test stays cells as above.

The JSON states c, n and c - n (:func:`clearance_record`). Before, the smoothed cells kept c + 4 mm
(13.2 mm at 3 mm noise) and the clearance meant a distance from the points. Raw points stay raw:
putting those that failed the smoothness test on the noise's tail onto the surface of their smoothed
neighbours (a quadric through them within 1 sigma, their centre within 1.5 cm, the point within
3 sigma of it) was measured and left out: it moved points up to 14 mm inside a box's true surface
and left 5 mm spheres at a bottle's rim up to 11.9 mm from the model's cells (bench/clearance_errors.py).
Nor are raw points on an edge put onto its two faces (session 14, bench/clearance_errors.py's
``on_edges``: a RANSAC two-plane fit to a raw point's 32-48 nearest points, the point onto the
nearer face, past the edge line onto the line): at 3 mm noise and 1 cm sampling each face holds
8-20 points, the fits leave the moved points 1.4-2.8 mm (sd) off the true shape, up to 12 mm inside,
and a model that takes 57-79 % of the raw points of a rim's top 2 cm needs u = 5.9-9.9 mm for 5 mm
spheres touching the true rim or edge (n = 9 mm; three draws per shape), one that takes 16-24 % up
to 10.2 mm: no smaller than a raw point's u = n, so no gain (bench/results/clearance_errors_s14_edge.json).
Wired in (u = 1.1 n) where the noise covers the sampling it changed no dev find-rate verdict (3/6,
17/28, 0 false positives); on every raw point it took dev 25023 (18/28) only by replacing the 5 mm
cells of a sparse rim, and left 5 mm spheres at a 12.5 mm box's edges (3 mm noise) free.
tests/test_clearance_bound.py checks with coal on the true shapes (cylinders of 3 and 4.5 cm, a
10 cm box with its corners, the table top; 3 mm noise, three draws) that 5 mm spheres 0.5 mm nearer
than c - n are refused everywhere, and that a palm is free ACCEPT beyond c - n from a noisy bottle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import coal
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from baseplace.geometry.poses import FloatArray
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.grasped_object import GraspedObject, rows_in
from baseplace.world.neighbour_shapes import FittedShape, fit_neighbours
from baseplace.world.support_plane import (
    CLEARANCE_SIGMAS,
    DEPTH,
    RADIUS,
    SUPPORT_PLANE,
    SupportSlab,
    uneven_points,
)

FINE = 0.00125
"""Cell edge [m] of the points near the object (each put onto its local plane first, :func:`denoised`):
a cell reaches 0 to FINE beyond its point along each axis."""
MAX_FINE = 0.005
"""Cells no coarser than this [m] are at sensor resolution and kept at the clearance: the :data:`FINE`
cells here (smoothed, :class:`SurfaceCells`, and raw, :class:`RawCells`) and the experiments' 5 mm slab cells
(:func:`~baseplace.world.support_plane.with_support_slab`)."""
EDGE_CELL = 0.005
"""Cell edge [m] of the points near the object that lie at an edge or a corner (not on a smooth
surface, :func:`denoised`) where the noise does not cover the gaps between the samples
(:func:`free_reach`): kept as measured, at the clearance (no allowance)."""
SPACING_NEIGHBOURS = 12
"""A point's sample spacing is read from the radius R of its this many nearest neighbours
(:func:`sample_spacing`): on a surface sampled every s, a ball of radius R holds pi R^2 / s^2 samples."""
JOINT_SIGMAS = 1.79
"""Two samples' noise both beyond this many sigma is as rare as one sample's beyond
:data:`CLEARANCE_SIGMAS` (Q(1.79)^2 = Q(3.0) = 0.00135): how deep the nearer of a surface point's two
nearest samples lies, at :data:`CLEARANCE_SIGMAS` sigma (:func:`free_reach`)."""
SURFACE_SPREAD = 0.37
"""The standard deviation of a denoised point's distance to the true surface, in the scene's noise
sigma (bench/clearance_errors.py: 1.03-1.10 mm at 3 mm noise, cylinders of 3-4.5 cm radius and a
10 cm box, 1 cm apart, three noise draws)."""
SURFACE_CHORD = 0.0022
"""How far [m] denoised points lie inside a curved true surface on average: their local plane is a
chord (bench/clearance_errors.py: mean -2.2 mm on a 3 cm cylinder, -1.8 at 3.75 cm, -1.5 at 4.5 cm,
-0.25 mm on a box's faces; the largest kept)."""
SURFACE_GAP = 0.0035
"""What [m] a small link (a 5 mm sphere, a fingertip) gains between denoised points 1 cm apart,
beyond their chord and spread (bench/clearance_errors.py, 3 mm noise: 5 mm spheres touching the
true surface where no raw cell is within 3 sigma lie at most 7.7 mm from a denoised cell on a
bottle's side and 9.0 mm at its rim (the side's cells just under it), where the chord and 3 spreads
give 5.5 mm; the rim's 3.5 mm kept)."""
PLANE_DEPTH = 0.05
"""The exact plane is a prism this thick [m] under its top face."""
OBJECT_TOLERANCE = 0.0125
"""Points this close [m] to a given box or cylinder are the object's (4 sigma of 3 mm sensor noise),
at least: above its top the tolerance follows the measured noise (:func:`object_tolerance`)."""
OBJECT_SIGMAS = 4.0
"""Points up to this many sigma of the measured noise above a box's or cylinder's top are the object's
(:func:`object_tolerance`). A noisy top leaves a point beyond 4 sigma once in 30 000 (beyond 3 sigma
once in 740): the few hundred points of an object's top leave none behind, where each left behind
is an obstacle cell at the hand's fingertips (bench/osrm_refusals_dev.py: 25 mm noise lifted the
tops' points 10-24 mm past 12.5 mm and blocked 27 of 28 refused flat grasps)."""
MIN_CLEARANCE = 0.003
"""The derived clearance is at least this [m]: a sensor's quantisation and calibration error."""
DEFAULT_CLEARANCE = 0.01
"""The clearance [m] when no noise can be measured (too few points near the object): 3 sigma of 3 mm
noise, rounded up."""
NOISE_NEIGHBOURS = 16
"""Each local plane of :func:`surface_noise` is fitted to a point's this many nearest neighbours."""
NOISE_QUANTILE = 0.2
"""The share of local fits read (:func:`surface_noise`): at least this many neighbourhoods must be flat."""
NOISE_SAMPLES = 4000
"""At most this many points (every n-th) have their local plane fitted."""
NOISE_MIN_FITS = 30
"""A direction of :func:`surface_noise` is measured on at least this many local fits, else not at all."""
PLANAR_FACTOR = 1.2
"""A point is on a smooth surface (:func:`denoised`) when a quadric through its neighbours leaves
residuals of at most this many times the surfaces' noise (7 % of a flat surface's points fail it)."""
SMOOTH_NEIGHBOURS = 32
"""Whether a point's surface is smooth (:func:`denoised`) is judged on this many nearest neighbours."""
SMOOTH_VOTES = 9
"""A point's surface is smooth when the median quadric residual of its this many nearest points is."""
DENOISE_CHUNK = 65536
""":func:`denoised` fits this many points' neighbourhoods at a time (about 25 MB of (chunk, 32, 3))."""


@dataclass(frozen=True)
class SupportPlane:
    """The surface the grasped object stands on as an exact plane (world frame).

    Attributes:
        slab: the fit (plane z = a x + b y + c, its residuals' sigma).
        hull: (H, 2) counter-clockwise footprint [m] of the points the plane replaces.
        points: how many points it replaces.
    """

    slab: SupportSlab
    hull: FloatArray
    points: int

    def geometry(self) -> coal.Convex:
        """A coal prism over :attr:`hull`: top face on the plane, :data:`PLANE_DEPTH` thick (world frame)."""
        top = np.c_[self.hull, self.slab.height(self.hull)]
        vertices = coal.StdVec_Vec3s()
        for v in np.concatenate([top, top - [0.0, 0.0, PLANE_DEPTH]]):
            vertices.append(np.asarray(v, dtype=float))
        return coal.Convex.convexHull(vertices, False, "")

    def __len__(self) -> int:
        return 1


Part = VoxelMap | SupportPlane | FittedShape
"""One collision geometry of a group: voxels or cells of one resolution, the exact support plane, or
a neighbour fitted as a whole shape (:mod:`baseplace.world.neighbour_shapes`)."""
Group = Part | tuple[Part, ...]
"""An obstacle group of :class:`~baseplace.world.environment.Environment`: one part or several (coarse
far away, fine near)."""
EXACT = (SupportPlane, FittedShape)
"""The parts that are exact geometries (``geometry()``: coal convexes in the world frame), not cells."""


def group_parts(group: Group) -> tuple[Part, ...]:
    """The parts of a group, each one collision geometry."""
    return group if isinstance(group, tuple) else (group,)


def group_size(group: Group) -> int:
    """How many cells (or planes) a group holds."""
    return sum(len(p) for p in group_parts(group))


@dataclass(frozen=True)
class SurfaceCells(VoxelMap):
    """:data:`FINE` cells of points put onto their local surface (:func:`denoised`).

    Attributes:
        noise_margin: the scene's derived noise margin n [m], :data:`CLEARANCE_SIGMAS` sigma of its
            noise (:func:`derived_clearance`).
        noise: the noise near the object it was derived from (:func:`surface_noise`), measured once
            per object for the clearance too (:func:`scene_noise`); None: too few points.
    """

    noise_margin: float = DEFAULT_CLEARANCE
    noise: SurfaceNoise | None = None


@dataclass(frozen=True)
class RawCells(VoxelMap):
    """:data:`FINE` cells of raw points near the object whose sampling the noise margin covers.

    Points kept as measured (at an edge or a corner, :func:`denoised`) where the scene's noise
    margin covers the gaps between the samples (:func:`free_reach`): kept at the clearance.
    """


def scene_noise(groups: dict[str, Group]) -> SurfaceNoise | None:
    """The noise :func:`fine_groups` measured near the object, kept in its denoised cells, or None."""
    for group in groups.values():
        for part in group_parts(group):
            if isinstance(part, SurfaceCells) and part.noise is not None:
                return part.noise
    return None


def surface_error(noise_margin: float) -> float:
    """The error u [m] of the denoised cells in a scene of noise margin ``noise_margin`` (n).

    How far inside the true surface they may let a link reach, at :data:`CLEARANCE_SIGMAS` sigma
    of their own error: their chord (:data:`SURFACE_CHORD`), :data:`CLEARANCE_SIGMAS` of their spread
    (:data:`SURFACE_SPREAD` sigma, sigma = n / :data:`CLEARANCE_SIGMAS`) and the gaps between the
    points (:data:`SURFACE_GAP`): 9.1 mm at 3 mm noise, where a raw point's is n = 9.2 mm.
    """
    return SURFACE_CHORD + SURFACE_SPREAD * noise_margin + SURFACE_GAP


def margin(part: Part, clearance: float, plane_clearance: float | None = None) -> float:
    """The distance [m] below which a link touches ``part`` (coal's security margin).

    Each kind keeps c - n + u from its own cells (the module's docstring): from the denoised cells
    (:class:`SurfaceCells`) ``clearance`` - n + :func:`surface_error` (at least 0); from the raw
    points' cells (:class:`RawCells`, :data:`EDGE_CELL`: u = n) and the other cells of at most
    :data:`MAX_FINE` (the experiments' slab cells) the clearance, nothing from coarser
    voxels; from the exact plane ``plane_clearance`` when given (:func:`derived_plane_clearance`),
    else the clearance; from a fitted neighbour (:class:`~baseplace.world.neighbour_shapes.FittedShape`)
    ``clearance`` - n + its :attr:`~baseplace.world.neighbour_shapes.FittedShape.error` (at least 0).
    """
    if isinstance(part, SupportPlane) and plane_clearance is not None:
        return plane_clearance
    if isinstance(part, FittedShape):
        return max(clearance - part.noise_margin + part.error, 0.0)
    if isinstance(part, SurfaceCells):
        return max(clearance - part.noise_margin + surface_error(part.noise_margin), 0.0)
    return clearance if is_fine(part) else 0.0


def free_reach(noise_margin: float) -> float:
    """The largest covering radius h [m] of a raw point's sampling for which c covers its gaps.

    A link at c - n from the true surface (c the clearance, n ``noise_margin``) stands over a surface
    point with two samples whose true positions lie within h of it (h the sampling's covering
    radius: s / sqrt(2) on a square grid of spacing s, also at an edge whose first rows lie within
    s / 2 of it). Each sample lies off the surface by its noise; the nearer of the two lies deeper
    than :data:`JOINT_SIGMAS` sigma (sigma = n / :data:`CLEARANCE_SIGMAS`) as rarely as one sample
    beyond :data:`CLEARANCE_SIGMAS` sigma, and at least :data:`MIN_CLEARANCE` deep (a calibration
    error moves every sample alike). So the link lies within hypot(h, c - n + e) of a sample, e that
    depth (the gap along the surface, the depth across it): within c, for every c >= n, when
    h^2 <= n^2 - e^2 (tightest at c = n). 7.4 mm at 3 mm noise (n 9.2 mm: 1 cm spacing is covered),
    0 with the noise at its 3 mm floor. A point the :data:`FINE` cell holds lies inside it, so the
    cell reaches at least as far.
    """
    depth = max(JOINT_SIGMAS * noise_margin / CLEARANCE_SIGMAS, MIN_CLEARANCE)
    return math.sqrt(max(noise_margin * noise_margin - depth * depth, 0.0))


def sample_spacing(points: ArrayLike, at: ArrayLike) -> FloatArray:
    """(M,) the sample spacing s [m] of ``points`` (N, 3) near each of ``at`` (M, 3).

    From the density: the radius R of each point's :data:`SPACING_NEIGHBOURS` nearest neighbours
    gives s = R sqrt(pi / k) (a ball of radius R on a surface sampled every s holds pi R^2 / s^2
    samples; the noise across the surface barely changes the count, where the distance to the
    nearest few grows with it); the median over the :data:`SMOOTH_VOTES` points nearest each of
    ``at``. Read on tests/test_clearance_bound_spacing.py's clouds: 9.2 mm for 9 mm, 12.2-12.8 mm
    for 12.5 mm (noise-free), 12.4 mm for 12.5 mm and 6.4 mm for 6 mm at 3 mm noise; on a
    bench/find_rate.py neighbour bottle (1 cm, 3 mm noise) 10.1 mm. 0 for fewer than
    :data:`SPACING_NEIGHBOURS` + 1 points.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    q = np.asarray(at, dtype=float).reshape(-1, 3)
    k = SPACING_NEIGHBOURS
    if len(p) <= k or len(q) == 0:
        return np.zeros(len(q))
    tree = cKDTree(p)
    votes = tree.query(q, k=min(len(p), SMOOTH_VOTES))[1]
    voters, at_voter = np.unique(votes, return_inverse=True)  # only these points' own spacing is read
    own = tree.query(p[voters], k=k + 1)[0][:, -1] * math.sqrt(math.pi / k)
    return np.median(own[at_voter.reshape(votes.shape)], axis=1)


def max_shift(noise_margin: float) -> float:
    """How far [m] :func:`denoised` may move a point onto its local plane in a scene of noise margin n.

    Its noise across the surface at :data:`OBJECT_SIGMAS` sigma (sigma = n / :data:`CLEARANCE_SIGMAS`:
    once in 30 000 points beyond) plus the plane's chord inside a curved surface
    (:data:`SURFACE_CHORD`). A longer move is a plane through both faces of an edge or a corner,
    cutting it off: the point stays raw. About 14.5 mm at 3 mm noise; 6.2 mm on a noise-free cloud
    (n at its 3 mm floor), where the noise read on a sparse cloud's edges (4.5 mm near a 10 cm box
    sampled every 12.5 mm) passes edge rows as smooth and moves them inward (6.3 mm at the box's
    vertical edge). With the limit the noise-free 3 cm bottle sampled every 12.5 mm keeps c - n for
    5 mm spheres at its rim and over its side (tests/test_clearance_bound_spacing.py; 1 mm spheres
    at its rim and the box's edges still not).
    """
    return OBJECT_SIGMAS * noise_margin / CLEARANCE_SIGMAS + SURFACE_CHORD


def clearance_record(clearance: float, note: str, noise_margin: float) -> dict[str, float | str]:
    """The JSON's ``clearance`` block.

    The clearance c [m] (``metres``), how it was chosen (``derived``), the noise margin n [m]
    (``noise_margin``), the bound c - n [m] the robot keeps from the true surface at
    :data:`CLEARANCE_SIGMAS` sigma (``from_true_surface``) outside the grasped object's tolerance,
    and that tolerance above its top [m] (``object_above_top``, :func:`object_tolerance`).
    """
    return {"metres": round(clearance, 5), "derived": note, "noise_margin": round(noise_margin, 5),
            "from_true_surface": round(clearance - noise_margin, 5),
            "object_above_top": round(object_tolerance(noise_margin), 5)}  # fmt: skip


def object_tolerance(noise_margin: float) -> float:
    """How far [m] above a box's or cylinder's top its points are still the object's.

    :data:`OBJECT_SIGMAS` sigma of the measured noise (sigma = ``noise_margin`` /
    :data:`CLEARANCE_SIGMAS`, the worst direction, :func:`derived_clearance`), at least
    :data:`OBJECT_TOLERANCE`: 100 mm at 25 mm noise, 12.5 mm at 3 mm. Sideways the tolerance stays
    :data:`OBJECT_TOLERANCE`: the noise across vertical patches is not measured reliably
    (:attr:`SurfaceNoise.horizontal`), and a wider ring would take more of a neighbour's points.
    The price: an obstacle's points within the tolerance over the object's footprint are the
    object's, which only the hand may touch; c - n (``from_true_surface``) holds for every surface
    outside it (docs/placement.md).
    """
    return max(OBJECT_TOLERANCE, OBJECT_SIGMAS * noise_margin / CLEARANCE_SIGMAS)


def is_fine(part: Part) -> bool:
    """True for the parts the clearance applies to: the exact parts and cells no coarser than :data:`MAX_FINE`."""
    return isinstance(part, EXACT) or part.resolution <= MAX_FINE + 1e-12


@dataclass(frozen=True)
class SurfaceNoise:
    """The sensor noise [m] of a cloud's surfaces by direction (:func:`surface_noise`).

    Attributes:
        vertical: sigma along z, from the horizontal patches (a height z = a x + b y + c fitted to
            each sample's nearest neighbours in xy), or None (fewer than :data:`NOISE_MIN_FITS`).
        horizontal: sigma across the vertical patches (the plane through each sample's nearest
            neighbours in 3-D, its normal within 30 deg of horizontal), or None. Reported, not
            counted in :attr:`worst`: where walls are short, few such neighbourhoods are flat and it
            reads edges (seed 000's noise-free tray: 9.3 mm, its 2 % quantile 4.2 mm).
        along_normals: sigma across every local plane (all 3-D fits): the noise a smoothed surface
            shows (:func:`denoised` compares its residuals with this).
        fits: how many local fits measured each: (vertical, horizontal, along_normals).
    """

    vertical: float | None
    horizontal: float | None
    along_normals: float
    fits: tuple[int, int, int]

    @property
    def worst(self) -> float:
        """The larger sigma [m] along z and across all local planes: what the clearance must cover."""
        return max(self.along_normals, self.vertical or 0.0)

    def describe(self) -> str:
        """The sigma per direction, for the JSON's ``derived`` note."""
        mm = lambda v: "-" if v is None else f"{v * 1e3:.1f} mm"  # noqa: E731
        v, h, a = self.fits
        return (f"sigma along z {mm(self.vertical)} ({v} horizontal patches), across vertical patches "
                f"{mm(self.horizontal)} ({h}, not counted: edges inflate it), across all local planes {mm(self.along_normals)} ({a}); "
                f"{NOISE_QUANTILE:.0%} quantile of the local fits per direction")  # fmt: skip


def chi2_quantile(q: float, dof: int) -> float:
    """The ``q`` quantile of the chi-square distribution with ``dof`` degrees of freedom.

    ``2 P^-1(dof / 2, q)``, P the regularised lower incomplete gamma function: what
    ``scipy.stats.chi2.ppf`` returns, without importing ``scipy.stats`` (0.3 s of every ``place``).
    """
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2, q))


def surface_noise(points: ArrayLike, along_z: bool = True) -> SurfaceNoise | None:
    """The sensor noise of a cloud's surfaces (N, 3) [m] by direction, or None (too few points).

    Noise that moves a point along its surface is invisible to a plane fitted to its neighbours:
    seed 000's clouds carry 25 mm of noise on z only, and the plane through a vertical wall's points
    sees none of it. So each direction is read where it moves points off their surface, at up to
    :data:`NOISE_SAMPLES` points:

    * along z on horizontal patches: the height z = a x + b y + c fitted to the
      :data:`NOISE_NEIGHBOURS` nearest neighbours in xy. Chosen in 3-D, neighbours of similar
      height would be preferred and noise larger than the points' spacing cut (11 mm read for
      25 mm); chosen in xy, the noise on z is not selected. Patches steeper than 45 deg
      (a wall's column of points) are left out;
    * across vertical patches: the plane through the nearest neighbours in 3-D whose normal is
      within 30 deg of horizontal;
    * across every local plane (all 3-D fits).

    Each local fit's standard deviation (its residuals over k - 3 degrees of freedom) is, on a flat
    patch, sigma times a chi variable of k - 3 degrees of freedom; edges, corners and curvature only
    make it larger. So the :data:`NOISE_QUANTILE` quantile of a direction's fits, divided by that chi
    variable's same quantile, is sigma wherever at least that share of them is flat (in a cluttered
    tray the median was 3 to 7 mm on a noise-free cloud, edges everywhere). None for fewer than
    :data:`NOISE_NEIGHBOURS` + 1 points. ``along_z`` False skips the height fits (vertical None):
    :func:`denoised` needs the noise across the local planes only.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    k = NOISE_NEIGHBOURS
    if len(p) <= k:
        return None
    scale = math.sqrt(chi2_quantile(NOISE_QUANTILE, k - 3) / (k - 3))

    def read(local: FloatArray) -> float | None:
        return float(np.quantile(local, NOISE_QUANTILE) / scale) if len(local) >= NOISE_MIN_FITS else None

    samples = p[:: max(1, len(p) // NOISE_SAMPLES)]
    nb = p[cKDTree(p).query(samples, k=k)[1]]
    centred = nb - nb.mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred) / (k - 3))
    across = np.sqrt(np.maximum(values[:, 0], 0.0))
    upright = np.abs(vectors[:, 2, 0]) <= math.sin(math.radians(30.0))  # the normal near horizontal

    if not along_z:
        return SurfaceNoise(
            None, read(across[upright]), read(across) or 0.0, (0, int(upright.sum()), len(samples))
        )
    nb = p[cKDTree(p[:, :2]).query(samples[:, :2], k=k)[1]]
    centred = nb - nb.mean(axis=1, keepdims=True)
    uv, h = centred[..., :2], centred[..., 2]
    gram = np.einsum("nki,nkj->nij", uv, uv) + 1e-12 * np.eye(2)
    slope = np.linalg.solve(gram, np.einsum("nki,nk->ni", uv, h)[..., None])[..., 0]
    residual = h - np.einsum("nki,ni->nk", uv, slope)
    height = np.sqrt(np.einsum("nk,nk->n", residual, residual) / (k - 3))
    level = np.hypot(slope[:, 0], slope[:, 1]) <= 1.0

    vertical, horizontal = read(height[level]), read(across[upright])
    return SurfaceNoise(vertical, horizontal, read(across) or 0.0,
                        (int(level.sum()), int(upright.sum()), len(samples)))  # fmt: skip


def derived_clearance(
    plane: SupportPlane | None, points: ArrayLike | None = None, noise: SurfaceNoise | None = None
) -> tuple[float, str]:
    """The default clearance [m] and how it was derived.

    :data:`CLEARANCE_SIGMAS` sigma of the scene's noise in its worst direction
    (:func:`surface_noise` of ``points``, the cloud near the object, or ``noise`` when already
    measured), and with a support plane at least of its residuals (:func:`plane_sigma`); at least
    :data:`MIN_CLEARANCE`. :data:`DEFAULT_CLEARANCE` only when neither can be measured.
    """
    if noise is None and points is not None:
        noise = surface_noise(points)
    metres = _noise_margin(None if plane is None else plane.slab, noise)
    floor = f", at least {MIN_CLEARANCE * 1e3:.0f} mm" if metres == MIN_CLEARANCE else ""
    if plane is None:
        if noise is None:
            return metres, "default: no support plane fitted and too few points to measure the noise"
        return metres, (
            f"3 sigma of the surfaces' noise near the object in its worst direction, no support plane "
            f"fitted (sigma {noise.worst * 1e3:.1f} mm: {noise.describe()}{floor})"
        )
    surfaces = "" if noise is None else f"; near the object: {noise.describe()}"
    return metres, (
        f"3 sigma of the support plane's residuals (sigma {plane.slab.sigma * 1e3:.1f} mm, {plane.slab.points} "
        f"points within the fit's height window) or of the surfaces' noise in its worst direction, the "
        f"larger (sigma {plane_sigma(plane.slab, noise) * 1e3:.1f} mm{surfaces}{floor})"
    )


def _noise_margin(slab: SupportSlab | None, noise: SurfaceNoise | None) -> float:
    """The noise margin n [m] from a fit and the surfaces' noise: :func:`derived_clearance`'s metres."""
    if slab is not None:
        return max(CLEARANCE_SIGMAS * plane_sigma(slab, noise), MIN_CLEARANCE)
    if noise is None:
        return DEFAULT_CLEARANCE
    return max(CLEARANCE_SIGMAS * noise.worst, MIN_CLEARANCE)


def plane_sigma(slab: SupportSlab, noise: SurfaceNoise | None) -> float:
    """The sensor noise [m] at the support plane: its residuals' sigma, at least the surfaces' worst.

    The fit (:func:`~baseplace.world.support_plane.fit_support_slab`) keeps the points within 15 mm
    of the densest height layer and up to half a voxel above the object's bottom, and refuses a fit
    whose sigma exceeds 5 mm (:data:`~baseplace.world.support_plane.MAX_SIGMA`): within that window
    larger noise is cut off. The surfaces' own noise (:func:`surface_noise`) is read without such a
    window.
    """
    return slab.sigma if noise is None else max(slab.sigma, noise.worst)


def derived_plane_clearance(plane: SupportPlane, noise: SurfaceNoise | None = None) -> tuple[float, str]:
    """The default clearance [m] from the exact support plane, and how it was derived.

    The plane is fitted to thousands of points: where its surface lies is known to its fit's
    standard error, sigma / sqrt(points), not to one point's noise. Keeping 3 sigma of the points'
    noise from it counted the noise that the fit had averaged away (bench/find_rate_refusals.py,
    dev seeds 25000-25059: the fitted plane lay 0.0-0.5 mm above the true table top while the hand
    was refused at 3.6 and 6.0 mm over it, the margin 9 mm). So :data:`CLEARANCE_SIGMAS` standard
    errors, at least :data:`MIN_CLEARANCE` (a sensor's calibration error and a real top's unevenness,
    well above the 0.5 mm measured bias of the fit). sigma is :func:`plane_sigma` (``noise`` the
    surfaces' noise near the object, when measured).
    """
    sigma, n = plane_sigma(plane.slab, noise), max(plane.slab.points, 1)
    error = sigma / math.sqrt(n)
    metres = max(CLEARANCE_SIGMAS * error, MIN_CLEARANCE)
    floor = f", at least {MIN_CLEARANCE * 1e3:.0f} mm" if metres == MIN_CLEARANCE else ""
    return metres, (
        f"the support plane: 3 standard errors of its fit (sigma {sigma * 1e3:.1f} mm / sqrt({n}) = "
        f"{error * 1e3:.3f} mm{floor})"
    )


def fine_groups(
    groups: dict[str, VoxelMap],
    object_voxels: VoxelMap,
    points: ArrayLike,
    grasped: GraspedObject,
    slab: SupportSlab | None,
    radius: float = RADIUS,
    fit_shapes: bool = True,
) -> tuple[dict[str, Group], Group]:
    """The groups with their voxels near the object replaced by their points' :data:`FINE` cells.

    Args:
        groups: name -> 25 mm voxels (e.g. "support", "obstacle"), as
            :func:`~baseplace.world.environment.contact_groups` splits them.
        object_voxels: the grasped object's voxels.
        points: (N, 3) the cloud the voxels were made from [m].
        grasped: the grasped object.
        slab: the fitted support plane, or None (then no plane: its points stay cells).
        radius: voxels whose centre lies within this horizontal distance [m] of the object's
            footprint are replaced.
        fit_shapes: fit the neighbours standing on the plane as whole shapes
            (:func:`~baseplace.world.neighbour_shapes.fit_neighbours`); an accepted one is a part of
            the group of most of its points, and its points leave the cells.

    Returns:
        The groups (each near voxel's points in fine cells of the same group, the object's points
        in fine cells of the object, the plane's points as :data:`SUPPORT_PLANE`) and the object:
        its cells, led by its fitted whole shape when ``fit_shapes`` and one is accepted
        (:func:`_object_shape`; :func:`object_contact` and :func:`object_obstacle` take either).
    """
    res = object_voxels.resolution
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    around = p[grasped.footprint_within(p[:, :2], radius)] if len(p) else p
    near = {name: grasped.footprint_within(v.centres[:, :2], radius) if len(v) else np.zeros(0, bool)
            for name, v in [*groups.items(), (_OBJECT, object_voxels)]}  # fmt: skip
    keys = np.floor(p / res).astype(np.int64)
    owner = np.full(len(p), -1)
    names = list(near)
    for k, name in enumerate(names):
        v = groups[name] if name != _OBJECT else object_voxels
        if near[name].any():
            owner[rows_in(keys, v.keys[near[name]])] = k
    taken = owner >= 0
    p, owner = p[taken], owner[taken]
    sampled = p
    noise = surface_noise(around)  # measured once per object, for the clearance here and in its callers
    is_object = _object_points(p, grasped, object_tolerance(_noise_margin(slab, noise)))
    plane = None
    if slab is not None:
        r = p[:, 2] - slab.height(p[:, :2])
        flat = ~is_object & (r <= slab.margin) & (r >= -slab.depth)
        # where the surface is raised, its points stay cells; what stands on it has feet in its band
        flat[flat] = ~uneven_points(slab, p[flat], p[r > 2 * slab.margin])
        plane = _plane(slab, p[flat])
        if plane is not None:
            p, owner, is_object = p[~flat], owner[~flat], is_object[~flat]
    n = derived_clearance(plane, noise=noise)[0]
    object_shape = None
    shapes: list[tuple[str, FittedShape]] = []  # each fitted neighbour and the group of most of its points
    if plane is not None and fit_shapes:
        object_shape = _object_shape(p[is_object], plane.slab, n)
        others = np.flatnonzero(~is_object)
        fitted = np.zeros(len(p), dtype=bool)
        for shape, rows in fit_neighbours(p[others], plane.slab, n):
            fitted[others[rows]] = True
            name = names[int(np.bincount(owner[others[rows]]).argmax())]
            # an object voxel's other points are obstacles
            shapes.append(("obstacle" if name == _OBJECT else name, shape))
        p, owner, is_object = p[~fitted], owner[~fitted], is_object[~fitted]
    reach = sample_spacing(sampled, p) / math.sqrt(2.0)  # before the plane leaves: its points are samples too
    # the noise once: the clearance stands on the surface, not on the noise
    moved, smooth = denoised(p, max_shift(n))
    surface = SurfaceCells(FINE, np.zeros((0, 3), dtype=np.int64), n, noise)
    out: dict[str, Group] = {}
    for k, name in enumerate(names):
        coarse = (groups[name] if name != _OBJECT else object_voxels).without(near[name])
        mine = is_object if name == _OBJECT else (owner == k) & ~is_object
        if name == _OBJECT:  # an object voxel's other points are obstacles
            mine_other = (owner == k) & ~is_object
            out["obstacle"] = _joined(out.get("obstacle"), *_cells(moved, smooth, mine_other, surface, reach))
        out[name] = _joined(out.get(name), coarse, *_cells(moved, smooth, mine, surface, reach))
    grasped_group = out.pop(_OBJECT)
    if object_shape is not None:  # the object as a whole, where it is an obstacle (:func:`object_obstacle`)
        grasped_group = (object_shape, *group_parts(grasped_group))
    for name, shape in shapes:
        out[name] = (*group_parts(out[name]), shape) if name in out else shape
    out = {name: g for name, g in out.items() if group_size(g)}
    if plane is not None:
        out[SUPPORT_PLANE] = plane
    return out, grasped_group


_OBJECT = "\0object"


def _object_shape(points: FloatArray, slab: SupportSlab, noise_margin: float) -> FittedShape | None:
    """The grasped object's points (N, 3) [m] fitted as one whole shape standing on the plane, or None.

    The points above the plane's band (``slab.margin``: below it they are the plane's, which the
    exact plane stands for) are fitted and accepted as a neighbour's are
    (:func:`~baseplace.world.neighbour_shapes.fit_neighbours`); the shape is taken only when one
    accepted fit holds all of them (a handle, a second object touching it: no shape).
    """
    above = points[points[:, 2] - slab.height(points[:, :2]) > slab.margin]
    fits = fit_neighbours(above, slab, noise_margin)
    if len(fits) != 1 or len(fits[0][1]) != len(above):
        return None
    return fits[0][0]


def object_contact(group: Group) -> Group:
    """The grasped object's group where the hand may touch it: its cells, never its fitted shape.

    At the grasp and in the approach the hand touches the measured surface: the cells of the
    object's points (what only the hand may enter), as before any fit.
    """
    return tuple(part for part in group_parts(group) if not isinstance(part, FittedShape))


def object_obstacle(group: Group) -> Group:
    """The grasped object's group where nothing may touch it (the transit to the pre-grasp).

    Its fitted shape when :func:`fine_groups` accepted one (kept at c - n + u, as a fitted
    neighbour: :func:`margin`), which stands for all its points; else its cells.
    """
    shapes = [part for part in group_parts(group) if isinstance(part, FittedShape)]
    return shapes[0] if shapes else group


def denoised(points: ArrayLike, shift_limit: float | None = None) -> tuple[FloatArray, NDArray[np.bool_]]:
    """The points (N, 3) [m] on smooth surfaces put onto their local plane, and which those are (N,).

    A point's surface is smooth when a quadric fitted to its :data:`SMOOTH_NEIGHBOURS` nearest
    points leaves residuals of at most :data:`PLANAR_FACTOR` times the surfaces' noise across their
    local planes (:attr:`SurfaceNoise.along_normals` of :func:`surface_noise` of ``points``;
    :func:`_smooth_residual`), as the median over its :data:`SMOOTH_VOTES`
    nearest points: a face, a bottle's side. Such a point goes onto the plane fitted to its
    :data:`NOISE_NEIGHBOURS` nearest, which leaves about sigma / 4 of the noise; on a curved
    surface that plane is a chord, inside it by about rho^2 / (8 r) (rho the neighbourhood's
    radius, r the curvature's): 2.6 mm on a 3 cm bottle sampled every centimetre. A point near an
    edge or a corner stays where it was measured: a plane through both faces would cut the corner
    off. All stay when the noise cannot be measured (too few points), and a point whose move would
    exceed ``shift_limit`` [m] (:func:`max_shift`) stays too.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=float).reshape(-1, 3)
    noise = surface_noise(p, along_z=False)
    if noise is None:
        return p, np.zeros(len(p), dtype=bool)
    k = NOISE_NEIGHBOURS
    tree = cKDTree(p)
    shift = np.empty_like(p)  # from each point onto its plane
    residual = np.empty(len(p))
    for lo in range(0, len(p), DENOISE_CHUNK):  # (chunk, k, 3) at a time: bounded memory
        rows = slice(lo, lo + DENOISE_CHUNK)
        wide = p[tree.query(p[rows], k=min(len(p), SMOOTH_NEIGHBOURS))[1]]
        centre = wide[:, :k].mean(axis=1)
        centred = wide - centre[:, None, :]
        near = centred[:, :k]
        _, axes = np.linalg.eigh(near.transpose(0, 2, 1) @ near)
        normal = axes[:, :, 0]
        residual[rows] = _smooth_residual(centred, axes)
        shift[rows] = -np.einsum("ni,ni->n", p[rows] - centre, normal)[:, None] * normal
    # an edge is a line of bad fits; one bad fit among good ones is the noise's tail (the median of
    # the nearest fits decides)
    votes = tree.query(p, k=min(len(p), SMOOTH_VOTES))[1]
    smooth = np.median(residual[votes], axis=1) <= PLANAR_FACTOR * noise.along_normals
    if shift_limit is not None:  # a move beyond the noise is a plane cutting an edge or a corner off
        smooth &= np.einsum("ni,ni->n", shift, shift) <= shift_limit * shift_limit
    return np.where(smooth[:, None], p + shift, p), smooth


def _smooth_residual(centred: FloatArray, axes: FloatArray) -> FloatArray:
    """(N,) the residuals' standard deviation [m] of a quadric fitted to each neighbourhood (N, m, 3).

    The quadric gives the height along the first column of ``axes`` (N, 3, 3) over the other two. A quadric follows a bottle's curve but not an edge: a plane through both faces of an edge
    passes for noise where the points are 1 cm apart and the noise 3 mm; a quadric's residuals do not.
    """
    local = centred @ axes
    h, u, v = local[..., 0], local[..., 1], local[..., 2]
    design = np.empty((*h.shape, 6))  # the columns filled in place, and products by matmul: 7x einsum's speed
    design[..., 0] = 1.0
    design[..., 1], design[..., 2] = u, v
    np.multiply(u, u, out=design[..., 3])
    np.multiply(u, v, out=design[..., 4])
    np.multiply(v, v, out=design[..., 5])
    design_t = design.transpose(0, 2, 1)
    gram = design_t @ design + 1e-12 * np.eye(6)
    coef = np.linalg.solve(gram, design_t @ h[..., None])
    residual = h - (design @ coef)[..., 0]
    return np.sqrt(np.einsum("nk,nk->n", residual, residual) / max(h.shape[1] - 6, 1))


def _object_points(
    p: FloatArray, grasped: GraspedObject, above: float = OBJECT_TOLERANCE
) -> NDArray[np.bool_]:
    """(N,) True for the points (N, 3) on the object.

    Those within :data:`OBJECT_TOLERANCE` of its footprint and no higher than ``above`` [m] above its
    top (:func:`object_tolerance`);
    for a box or cylinder, above its bottom's cell; for points, also down to its support (a found
    object leaves out its foot, the band of its support), and every point in one of its cells.
    """
    if len(p) == 0:
        return np.zeros(0, dtype=bool)
    top = grasped.bottom + grasped.size[2]
    # a shape's lowest cell holds the support's surface too: not the object's
    low = grasped.bottom - DEPTH if grasped.kind == "points" else grasped.bottom + MAX_FINE / 2
    z_ok = (p[:, 2] >= low) & (p[:, 2] <= top + above)
    out = np.zeros(len(p), dtype=bool)
    if z_ok.any():
        out[z_ok] = grasped.footprint_within(p[z_ok, :2], OBJECT_TOLERANCE)
    if grasped.kind == "points":
        mine = np.unique(np.floor(grasped.points / FINE).astype(np.int64), axis=0)
        out |= rows_in(np.floor(p / FINE).astype(np.int64), mine)
    return out


def _cells(
    p: FloatArray, smooth: NDArray[np.bool_], mine: NDArray[np.bool_], surface: SurfaceCells,
    reach: FloatArray,
) -> tuple[VoxelMap, ...]:  # fmt: skip
    """The points ``p[mine]`` (N, 3): smooth ones in cells like ``surface``, the others raw.

    A raw point whose sampling's covering radius ``reach`` (N,) [m] is at most :func:`free_reach`
    goes into a :class:`RawCells` cell, the others into :data:`EDGE_CELL` cells.
    """
    # finer than a user may ask of VoxelMap.from_points: these are the few points near the object
    fine = np.unique(np.floor(p[mine & smooth] / FINE).astype(np.int64).reshape(-1, 3), axis=0)
    raw = mine & ~smooth
    dense = reach <= free_reach(surface.noise_margin)
    covered = np.unique(np.floor(p[raw & dense] / FINE).astype(np.int64).reshape(-1, 3), axis=0)
    sparse = np.unique(np.floor(p[raw & ~dense] / EDGE_CELL).astype(np.int64).reshape(-1, 3), axis=0)
    return replace(surface, keys=fine), RawCells(FINE, covered), VoxelMap(EDGE_CELL, sparse)


def _joined(group: Group | None, *parts: VoxelMap) -> Group:
    """A group of the non-empty parts (merged per resolution and kind: denoised cells stay :class:`SurfaceCells`)."""
    by_kind: dict[tuple[float, str], list[NDArray[np.int64]]] = {}
    like: dict[tuple[float, str], VoxelMap] = {}
    for part in [*(group_parts(group) if group is not None else ()), *parts]:
        if isinstance(part, VoxelMap) and len(part):
            key = (part.resolution, type(part).__name__)
            by_kind.setdefault(key, []).append(part.keys)
            like[key] = part
    merged = tuple(
        replace(like[key], keys=np.unique(np.concatenate(k), axis=0)) for key, k in sorted(by_kind.items())
    )
    if not merged:
        return VoxelMap(FINE, np.zeros((0, 3), dtype=np.int64))
    return merged[0] if len(merged) == 1 else merged


def _plane(slab: SupportSlab, p: FloatArray) -> SupportPlane | None:
    """The exact plane over the footprint of the points ``p`` (N, 3) it replaces, or None (too few)."""
    if len(p) < 3:
        return None
    try:
        hull = p[ConvexHull(p[:, :2]).vertices, :2]
    except (QhullError, ValueError):
        return None
    return SupportPlane(slab, hull, len(p))
