"""The clearance is kept from the TRUE surface of a noisy neighbour, not from its noise (issue 25).

A neighbour bottle scanned with 3 mm noise: its points lie up to about 3 sigma outside the true
surface, and each becomes a cell; the clearance (3 sigma of the table's residuals) was then added
on top, so the neighbour stood about 6 sigma plus a cell (2-3 cm) proud while the exact plane stood
3 sigma. Oracle: coal on the true cylinder (the probe's true distance); the model's verdict is
coal's collision against the scene's own groups with the security margin that
:class:`~baseplace.world.environment.Environment` gives each (:func:`~baseplace.world.sensor_resolution.margin`).
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pytest

from baseplace.terrain.voxels import VoxelMap
from baseplace.world import sensor_resolution
from baseplace.world.environment import contact_groups, support_plane
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.neighbour_shapes import FittedShape
from baseplace.world.sensor_resolution import SupportPlane, derived_clearance, group_parts

# Environment's security margin per part (before the allowance for denoised cells: the clearance)
_margin = getattr(sensor_resolution, "margin", lambda part, c: c if sensor_resolution.is_fine(part) else 0.0)

SIGMA = 0.003
TOP = 0.75  # the table top [m]
BOTTLE, NEIGHBOUR = (0.0, 0.0), (0.11, 0.0)  # axes [m]: 5 cm between the surfaces
RADIUS, HEIGHT = 0.035, 0.25
PROBE = 0.04  # edge of the probe cube [m] (about a palm's corner)


def _cylinder_points(xy, step: float = 0.01, rim_row: bool = False) -> np.ndarray:
    """A bottle's side every ``step`` (up to a row below the rim, or the rim with ``rim_row``) and its top."""
    n = math.ceil(2 * math.pi * RADIUS / step)
    rows = np.arange(TOP, TOP + HEIGHT + (1e-9 if rim_row else 0.0), step)
    a, z = np.meshgrid(np.linspace(0, 2 * math.pi, n, endpoint=False), rows)
    side = np.c_[xy[0] + RADIUS * np.cos(a.ravel()), xy[1] + RADIUS * np.sin(a.ravel()), z.ravel()]
    g = np.arange(-RADIUS, RADIUS + 1e-9, step)
    X, Y = np.meshgrid(g, g)
    inside = np.hypot(X, Y).ravel() <= RADIUS
    top = np.c_[xy[0] + X.ravel()[inside], xy[1] + Y.ravel()[inside], np.full(inside.sum(), TOP + HEIGHT)]
    return np.concatenate([side, top])


def _box_points(centre, half: float, step: float = 0.01) -> np.ndarray:
    """A box's top and four sides standing on the table, edges and corners included."""
    g = np.arange(-half, half + 1e-9, step)
    A, B = np.meshgrid(g, g)
    z = np.arange(TOP, TOP + 2 * half + 1e-9, step)
    S, Z = np.meshgrid(g, z)
    parts = [np.c_[centre[0] + A.ravel(), centre[1] + B.ravel(), np.full(A.size, TOP + 2 * half)]]
    for sgn in (-1, 1):
        parts.append(np.c_[centre[0] + S.ravel(), np.full(S.size, centre[1] + sgn * half), Z.ravel()])
        parts.append(np.c_[np.full(S.size, centre[0] + sgn * half), centre[1] + S.ravel(), Z.ravel()])
    return np.unique(np.round(np.concatenate(parts), 9), axis=0)


def noisy_scene(neighbour: np.ndarray, footprint, seed: int, fit_shapes: bool = True):
    """(contact groups, the exact support plane or None) of the grasped bottle on a table beside
    ``neighbour`` (its true surface points; ``footprint`` tells the table points it stands on), all
    sampled every centimetre with :data:`SIGMA` of Gaussian noise (also bench/sensor_resolution_probes.py);
    ``fit_shapes`` False: the neighbour stays cells even where it fits a whole shape."""
    rng = np.random.default_rng(seed)
    X, Y = np.meshgrid(np.arange(-0.4, 0.4, 0.01), np.arange(-0.4, 0.4, 0.01))
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, TOP)]
    table = table[(np.hypot(X.ravel() - BOTTLE[0], Y.ravel() - BOTTLE[1]) > RADIUS) & ~footprint(table)]
    clean = np.concatenate([table, _cylinder_points(BOTTLE), neighbour])
    points = clean + rng.normal(0.0, SIGMA, clean.shape)
    voxels = VoxelMap.from_points(points)
    grasped = GraspedObject.cylinder([*BOTTLE, TOP + HEIGHT / 2], RADIUS, HEIGHT)
    groups, _ = contact_groups(voxels, voxels, grasped, points, fit_shapes=fit_shapes)
    return groups, support_plane(groups)


def _model(neighbour: np.ndarray, footprint, seed: int, times: float = 1.0):
    """(parts: (geometry, security margin) as Environment checks them, clearance) of a noisy scene,
    at ``times`` the derived clearance."""
    groups, plane = noisy_scene(neighbour, footprint, seed)
    assert plane is not None
    clearance, _ = derived_clearance(plane)
    assert 2.5 * SIGMA <= clearance <= 3.5 * SIGMA  # 3 sigma of the plane's residuals
    clearance *= times
    parts = []
    for group in groups.values():
        for part in group_parts(group):
            if isinstance(part, (SupportPlane, FittedShape)):  # exact convexes
                parts.append((part.geometry(), _margin(part, clearance)))
            elif len(part):
                octree = coal.makeOctree(np.ascontiguousarray(part.centres), part.resolution)
                parts.append((octree, _margin(part, clearance)))
    return parts, clearance


@pytest.fixture(scope="module")
def scene():
    return _model(_cylinder_points(NEIGHBOUR), _footprint, 2511)


BOX_HALF = 0.04  # the neighbour box: an 8 cm cube where the bottle stood


@pytest.fixture(scope="module")
def box_scene():
    def footprint(p):
        return np.all(np.abs(p[:, :2] - NEIGHBOUR) <= BOX_HALF, axis=1)

    return _model(_box_points(NEIGHBOUR, BOX_HALF), footprint, 2512)


def _probes(gap: float):
    """Probe cubes whose face is ``gap`` [m] from the neighbour's true side, on the side away from the
    grasped bottle, at three heights: (geometry, pose, true distance by coal)."""
    true = coal.Cylinder(RADIUS, HEIGHT)
    T_true = coal.Transform3s(np.eye(3), np.array([*NEIGHBOUR, TOP + HEIGHT / 2]))
    for angle in np.radians([-75, -40, 0, 40, 75]):
        u = np.array([math.cos(angle), math.sin(angle), 0.0])
        for z in (TOP + 0.06, TOP + 0.12, TOP + 0.18):
            R = np.array([[u[0], -u[1], 0.0], [u[1], u[0], 0.0], [0.0, 0.0, 1.0]])
            centre = np.array([*NEIGHBOUR, z]) + (RADIUS + gap + PROBE / 2) * u
            cube, T = coal.Box(PROBE, PROBE, PROBE), coal.Transform3s(R, centre)
            d = coal.distance(cube, T, true, T_true, coal.DistanceRequest(), coal.DistanceResult())
            yield cube, T, d


def _touches(parts, clearance: float, cube, T) -> bool:
    request = coal.CollisionRequest()
    for geometry, security_margin in parts:
        request.security_margin = security_margin
        if coal.collide(cube, T, geometry, coal.Transform3s(), request, coal.CollisionResult()):
            return True
    return False


def test_a_probe_1_75_clearances_from_the_true_noisy_neighbour_is_free(scene):
    parts, clearance = scene
    for cube, T, true in _probes(1.75 * clearance):
        assert true == pytest.approx(1.75 * clearance, abs=1e-4)
        assert not _touches(parts, clearance, cube, T), (
            f"a probe {true * 1e3:.1f} mm from the true neighbour (clearance {clearance * 1e3:.1f} mm) touches the model"
        )


def test_a_probe_half_a_clearance_from_the_true_noisy_neighbour_is_refused(scene):
    parts, clearance = scene
    for cube, T, true in _probes(0.5 * clearance):
        assert _touches(parts, clearance, cube, T), (
            f"a probe {true * 1e3:.1f} mm from the true neighbour (clearance {clearance * 1e3:.1f} mm) is free"
        )


def _footprint(p):
    return np.hypot(p[:, 0] - NEIGHBOUR[0], p[:, 1] - NEIGHBOUR[1]) <= RADIUS


def test_the_margin_from_the_true_side_is_never_less_than_c_minus_n():
    """Small spheres (5 mm, a fingertip) 0.9 (c - n) from the true side, over the gaps between the
    points (1 cm apart) and all around the side that faces away from the grasped bottle: all refused.

    The clearance c is kept from the TRUE surface less the noise margin n (3 sigma, the derived
    clearance): the lead's decision of issue 25 (docs/results.md). Here c = 2 n, so 0.9 (c - n)
    is the 0.9 clearances this test asked of the derived clearance before."""
    parts, clearance = _model(_cylinder_points(NEIGHBOUR), _footprint, 2511, times=2.0)
    clearance /= 2  # c - n
    true = coal.Cylinder(RADIUS, HEIGHT)
    T_true = coal.Transform3s(np.eye(3), np.array([*NEIGHBOUR, TOP + HEIGHT / 2]))
    sphere = coal.Sphere(0.005)
    for angle in np.radians(np.arange(-80, 81, 5)):
        u = np.array([math.cos(angle), math.sin(angle), 0.0])
        for z in np.arange(TOP + 0.03, TOP + HEIGHT - 0.02, 0.005):
            T = coal.Transform3s(
                np.eye(3), np.array([*NEIGHBOUR, z]) + (RADIUS + 0.9 * clearance + 0.005) * u
            )
            d = coal.distance(sphere, T, true, T_true, coal.DistanceRequest(), coal.DistanceResult())
            assert d == pytest.approx(0.9 * clearance, abs=1e-4)
            assert _touches(parts, clearance, sphere, T), (
                f"a sphere {d * 1e3:.1f} mm from the true side is free"
            )


def test_a_noisy_box_keeps_its_corners_within_a_quarter_clearance(box_scene):
    """Spheres (5 mm) 0.75 clearances from a noisy box's true top, edges and corners: all refused.

    Points near an edge are not smoothed onto a plane through both faces (that would cut the corner
    off); between the points 1 cm apart a corner may still let a sphere a little nearer than the clearance.
    """
    parts, clearance = box_scene
    sphere = coal.Sphere(0.005)
    g = np.linspace(-BOX_HALF, BOX_HALF, 9)
    for x in g:
        for y in g:
            q = np.array([NEIGHBOUR[0] + x, NEIGHBOUR[1] + y, TOP + 2 * BOX_HALF])  # on the top face
            outward = np.array([np.sign(x) * (abs(x) == BOX_HALF), np.sign(y) * (abs(y) == BOX_HALF), 1.0])
            for n in {tuple(outward), (outward[0], 0.0, 1.0), (0.0, outward[1], 1.0), (0.0, 0.0, 1.0)}:
                u = np.asarray(n) / np.linalg.norm(n)  # a direction in the normal cone at q
                T = coal.Transform3s(np.eye(3), q + (0.75 * clearance + 0.005) * u)
                assert _touches(parts, clearance, sphere, T), (
                    f"a sphere 0.75 clearances from the box at {np.round(q, 3)} along {np.round(u, 2)} is free"
                )
