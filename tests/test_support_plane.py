"""The grasped object's support cut down to a thin slab (world/support_plane.py), against ground truth.

Oracle: coal on the true table (a box of known top height) and the cloud's own points (which cell
holds each), never the code's own containment test or fit.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial import cKDTree

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment, contact_groups
from baseplace.world.grasped_object import GraspedObject
from baseplace.world.sensor_resolution import FINE, PLANE_DEPTH, SupportPlane
from baseplace.world.support_plane import RADIUS, SUPPORT_PLANE, fit_support_slab
from conftest import SHARED

RES = 0.025
TARGET = [0.75, -0.15, 0.85, 0.0, 0.0, 0.0]  # side grasp in front of the base (as tests/test_motion.py)
TABLE_XY = ((0.45, 1.25), (-0.6, 0.45))  # the true table top's extent [m]
OBJECT_XY = (0.9, 0.12)
NOISE_REACH = 3.0
"""Fine cells hold points moved onto their neighbours' plane (sensor_resolution.denoised): within this
many sigma of a measured point."""


def _table_box(top: float) -> tuple[coal.Box, coal.Transform3s]:
    (x0, x1), (y0, y1) = TABLE_XY
    box = coal.Box(x1 - x0, y1 - y0, 0.04)
    return box, coal.Transform3s(np.eye(3), np.array([(x0 + x1) / 2, (y0 + y1) / 2, top - 0.02]))


def _robot_distance(robot, env: Environment, q_full, T_world_base, shape, T_shape) -> float:
    """Oracle: the smallest coal distance from any robot geometry to a shape (negative: penetration)."""
    data, gdata = robot.model.createData(), pin.GeometryData(env.geom)
    pin.updateGeometryPlacements(robot.model, data, env.geom, gdata, q_full)
    T_world_root = pin.SE3(np.asarray(T_world_base, dtype=float)) * env._T_root_base.inverse()
    request = coal.DistanceRequest()
    out = np.inf
    for k, obj in enumerate(env.geom.geometryObjects[: env.geom.ngeoms - len(env.env_ids)]):
        M = T_world_root * gdata.oMg[k]
        out = min(out, coal.distance(obj.geometry, coal.Transform3s(M.rotation, M.translation), shape, T_shape,
                                     request, coal.DistanceResult()))  # fmt: skip
    return float(out)


def _scene(
    top: float, rng: np.random.Generator, sigma: float = 0.003
) -> tuple[np.ndarray, np.ndarray, GraspedObject]:
    """A table top at ``top`` (1 cm grid, Gaussian noise per axis) and a cylinder standing on it."""
    (x0, x1), (y0, y1) = TABLE_XY
    X, Y = np.meshgrid(np.arange(x0, x1, 0.01), np.arange(y0, y1, 0.01))
    table = np.c_[X.ravel(), Y.ravel(), np.full(X.size, top)]
    obj = GraspedObject.cylinder([*OBJECT_XY, top + 0.075], 0.03, 0.15)
    a, z = np.meshgrid(
        np.linspace(0, 2 * np.pi, 40, endpoint=False), np.arange(top + 0.005, top + 0.15, 0.01)
    )
    bottle = np.c_[
        OBJECT_XY[0] + 0.03 * np.cos(a).ravel(), OBJECT_XY[1] + 0.03 * np.sin(a).ravel(), z.ravel()
    ]
    table = table + rng.normal(0.0, sigma, table.shape)
    return table, np.concatenate([table, bottle + rng.normal(0.0, sigma, bottle.shape)]), obj


def _models(cloud: np.ndarray, obj: GraspedObject, slab: bool):
    voxels = VoxelMap.from_points(cloud, RES)
    return contact_groups(voxels, voxels, obj, cloud if slab else None)


@pytest.fixture(scope="module")
def hand_over_table(tiago):
    """A side-grasp configuration and the height of the robot's lowest point over the table area."""
    arm = tiago.arm()
    q = DampedLeastSquaresIK(arm).solve(pose_from_xyz_rpy(TARGET), np.random.default_rng(0))
    assert q is not None
    q_full = arm.to_pinocchio(q, tiago.q_reference)
    env = Environment(tiago, VoxelMap(RES, np.zeros((0, 3), dtype=np.int64)))
    assert not env.colliding(q_full, np.eye(4))  # free on its own (self-collision included)
    top = 0.4  # raise a probe table until the robot is 1 cm above it (coal distance, secant steps)
    for _ in range(20):
        d = _robot_distance(tiago, env, q_full, np.eye(4), *_table_box(top))
        if abs(d - 0.01) < 1e-6:
            break
        top += d - 0.01
    assert abs(d - 0.01) < 1e-6
    assert 0.6 < top < 0.85  # under the hand, well above the base
    return q_full, top + 0.01


def test_hand_1cm_above_true_top_is_free_2mm_into_it_collides(tiago, hand_over_table):
    q_full, low = hand_over_table
    # lift the robot so that the true top lies 4 mm into a voxel layer: a voxel's cube then
    # reaches 21 mm above the top, and the hand 1 cm above the top is inside the old layer
    top = np.floor((low - 0.01) / RES) * RES + RES + 0.004
    lift = top + 0.01 - low
    # 1 mm sensor noise: the slab holds every point of the plane (up to 4 sigma above it)
    _, cloud, obj = _scene(top, np.random.default_rng(3), sigma=0.001)
    box, T_box = _table_box(top)
    old = Environment(tiago, _models(cloud, obj, slab=False)[0])
    groups, object_voxels = _models(cloud, obj, slab=True)
    assert len(groups[SUPPORT_PLANE]) > 0
    new = Environment(tiago, groups, grasped=object_voxels)
    for dz, gap in ((lift, 0.01), (lift - 0.012, -0.002)):
        T = np.eye(4)
        T[2, 3] = dz
        truth = _robot_distance(tiago, old, q_full, T, box, T_box)  # oracle on the true table
        if gap > 0:
            assert truth == pytest.approx(gap, abs=2e-4)
            assert old.colliding(q_full, T)  # the voxel layer: a false collision
            assert not new.colliding(q_full, T)  # cut down to the slab: free, as on the true table
        else:  # 12 mm lower than a 10 mm gap; coal's penetration depth of a mesh is not exact
            assert truth < 0
            assert new.colliding(q_full, T)  # 2 mm into the true table: still a collision


def _cells(group) -> list[VoxelMap]:
    return [p for p in (group if isinstance(group, tuple) else (group,)) if isinstance(p, VoxelMap)]


def _key_sets(cells: list[VoxelMap]) -> dict[float, set[tuple[int, ...]]]:
    """The cells' keys, per resolution."""
    out: dict[float, set[tuple[int, ...]]] = {}
    for c in cells:
        out.setdefault(c.resolution, set()).update(tuple(k) for k in c.keys)
    return out


def _in_cells(points: np.ndarray, cells: list[VoxelMap], sigma: float) -> np.ndarray:
    """Oracle: (N,) True for the points (N, 3) in a voxel, or moved onto their neighbours' plane (within
    3 sigma, 15 % for the measured noise) in a fine cell."""
    sets = _key_sets(cells)
    voxel = np.array([any(tuple(np.floor(p / r).astype(np.int64)) in keys for r, keys in sets.items() if r > FINE)
                      for p in points])  # fmt: skip
    fine = cKDTree(np.concatenate([c.centres for c in cells if c.resolution <= FINE]))
    return voxel | (fine.query(points)[0] <= NOISE_REACH * 1.15 * sigma + FINE * np.sqrt(3) / 2)


def _in_hull(xy: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """Oracle: inside the convex polygon (H, 2), either orientation (cross products of every edge)."""
    e = np.roll(hull, -1, axis=0) - hull
    cross = e[None, :, 0] * (xy[:, None, 1] - hull[None, :, 1]) - e[None, :, 1] * (
        xy[:, None, 0] - hull[None, :, 0]
    )
    return np.all(cross >= -1e-9, axis=1) | np.all(cross <= 1e-9, axis=1)


@pytest.mark.parametrize("top", [0.7, 0.7125, 0.74])
def test_every_support_point_lies_in_a_cell_or_on_the_exact_plane(top):
    sigma = 0.003
    table, cloud, obj = _scene(top, np.random.default_rng(int(top * 1e4)), sigma=sigma)
    groups, object_group = _models(cloud, obj, slab=True)
    plane = groups.pop(SUPPORT_PLANE)
    assert isinstance(plane, SupportPlane)
    # the exact plane lies on the true top (1 cm grid, 3 mm noise: well within a millimetre)
    corners = np.array([[x, y] for x in TABLE_XY[0] for y in TABLE_XY[1]])
    assert np.all(np.abs(plane.slab.height(corners) - top) < 1e-3)
    assert plane.slab.sigma == pytest.approx(sigma, rel=0.15)  # the noise, measured robustly
    cells = [c for g in [*groups.values(), object_group] for c in _cells(g)]
    on_plane = _in_hull(table[:, :2], plane.hull) & (np.abs(table[:, 2] - top) <= 5 * sigma)
    # each point is on the plane or in a cell (where the surface is uneven, support_plane.uneven_points,
    # its points stay cells)
    assert np.all(on_plane | _in_cells(table, cells, sigma))
    # never more than the cloud was: every voxel is one of the cloud's, every fine cell holds a point
    # moved onto its neighbours' plane, so it lies within 3 sigma (15 % for the measured noise) of one
    original = {tuple(k) for k in VoxelMap.from_points(cloud, RES).keys}
    reach = NOISE_REACH * 1.15 * sigma + FINE * np.sqrt(3) / 2
    for c in cells:
        if c.resolution > FINE:
            assert all(tuple(k) in original for k in np.floor_divide(c.keys, round(RES / c.resolution)))
        else:
            assert cKDTree(cloud).query(c.centres)[0].max() <= reach

    # and around the object (not at it) the table's 25 mm voxels are gone: nothing left above top +
    # 4.5 sigma + a fine cell, where the voxel layer reached 10 mm or more above the top
    def near(c):
        d = np.hypot(*(c[:, :2] - OBJECT_XY).T)
        return (d > 0.1) & (d < RADIUS - RES)

    table_voxels = VoxelMap.from_points(table, RES)
    assert (table_voxels.keys[near(table_voxels.centres), 2].max() + 1) * RES >= top + 0.01
    tops = [((c.keys[near(c.centres), 2] + 1) * c.resolution) for c in cells]
    low_enough = [t[(t > top - 0.05) & (t < top + 0.1)] for t in tops]
    assert max((t.max() for t in low_enough if len(t)), default=top) <= top + 4.5 * sigma + FINE


def test_a_surface_that_is_not_planar_is_no_plane_its_points_stay_cells():
    rng = np.random.default_rng(5)
    table, cloud, obj = _scene(0.7, rng, sigma=0.012)  # 12 mm noise: more than MAX_SIGMA (5 mm)
    groups, object_group = _models(cloud, obj, slab=True)
    plain, _ = _models(cloud, obj, slab=False)
    assert SUPPORT_PLANE not in groups
    assert set(groups) <= set(plain)
    cells = [c for g in [*groups.values(), object_group] for c in _cells(g)]
    assert _in_cells(table, cells, 0.012).all()


@pytest.mark.parametrize("sigma", [0.002, 0.003, 0.004])
def test_a_flat_table_is_a_plane_at_every_noise_the_band_holds(sigma):
    """A flat table top is fitted within 1 mm of its true height at 2-4 mm of noise, ten draws each
    (5 mm is MAX_SIGMA, the band's limit).
    Until session 20 the 99th percentile of the residuals above the plane had to stay under 10 mm,
    whatever the noise: at 4 mm noise it was refused in 28 of 30 dev scenes, at 5 mm in all
    (bench/results/support_plane_ratios_dev.json)."""
    for seed in range(10):
        _, cloud, obj = _scene(0.7, np.random.default_rng(seed), sigma)
        slab = fit_support_slab(cloud, obj.footprint_distance, obj.bottom, RES)
        assert slab is not None, f"{sigma * 1e3:.0f} mm noise, seed {seed}: no plane"
        assert np.all(np.abs(slab.height(slab.hull) - 0.7) < 1e-3)
        assert abs(slab.sigma - sigma) < 0.2 * sigma  # the noise, read back


def _mat(cloud: np.ndarray) -> np.ndarray:
    """(N,) the table points of a 24 x 24 cm mat beside the object in :func:`_scene`'s cloud."""
    return (np.abs(cloud[:, 0] - 0.62) < 0.12) & (np.abs(cloud[:, 1] + 0.3) < 0.12) & (cloud[:, 2] < 0.72)


def test_a_mat_raised_above_the_noise_band_stays_cells_over_an_exact_plane():
    """A mat raised 2 cm (3 mm noise): the table is still its plane, within 1 mm of the true top, and
    the slab (up to about 4 sigma over the plane) takes at most the mat's noise tail, its points
    2.7 sigma or more under the mat's top (0.35 %; at most 1 % here): the rest stay cells, obstacles
    above the plane."""
    for seed in range(5):
        _, cloud, obj = _scene(0.7, np.random.default_rng(seed), 0.003)
        mat = _mat(cloud)
        raised = cloud + np.where(mat[:, None], [0.0, 0.0, 0.02], 0.0)
        slab = fit_support_slab(raised, obj.footprint_distance, obj.bottom, RES)
        assert slab is not None, f"seed {seed}: no plane"
        assert np.all(np.abs(slab.height(slab.hull) - 0.7) < 1e-3)
        assert slab.contains(raised[mat]).sum() <= max(1, 0.01 * mat.sum())


@pytest.mark.parametrize("height", [0.006, 0.009, 0.012])
@pytest.mark.parametrize("sigma", [0.002, 0.003, 0.004])
def test_a_mat_raised_within_the_noise_band_is_never_taken_for_the_plane(height, sigma):
    """A 24 x 24 cm mat (7 % of the fitted points) raised 6-12 mm at 2-4 mm noise, three draws each.
    The fit alone passes such a mat (a 9 mm mat at 3 mm noise moves the 99th percentile above the
    plane to 3.1-3.25 sigma, under P99_SIGMAS), so the plane's points are tested where they are:
    - where the mat lies within the plane's band, every one of its points there is uneven
      (uneven_points, with what stands more than two margins above the plane, as fine_groups
      calls it);
    - in the model the mat's true top (its grid points before the noise) has a cell within a sample
      spacing (1 cm) plus 3 sigma (and the cell's half diagonal) throughout, where the exact plane
      alone would leave up to 12 cm free."""
    from baseplace.world.support_plane import uneven_points

    (x0, _), (y0, _) = TABLE_XY
    for seed in range(3):
        _, cloud, obj = _scene(0.7, np.random.default_rng(seed), sigma)
        mat = _mat(cloud)
        raised = cloud + np.where(mat[:, None], [0.0, 0.0, height], 0.0)
        slab = fit_support_slab(raised, obj.footprint_distance, obj.bottom, RES)
        if slab is None:
            continue
        r = raised[:, 2] - slab.height(raised[:, :2])
        d = obj.footprint_distance(raised[:, :2])
        band = (d > 0) & (d <= RADIUS) & (np.abs(r) <= slab.margin)
        uneven = uneven_points(slab, raised[band], raised[(d <= RADIUS) & (r > 2 * slab.margin)])
        if height <= slab.margin:  # a mat above the band is cells but for its noise tail (checked below)
            assert uneven[mat[band]].all(), f"seed {seed}: {int((~uneven[mat[band]]).sum())} mat points even"
        groups, object_group = _models(raised, obj, slab=True)
        assert SUPPORT_PLANE in groups
        cells = [c for g in [*groups.values(), object_group] for c in _cells(g) if len(c)]
        trees = [(cKDTree(c.centres), c.resolution * np.sqrt(3) / 2) for c in cells]
        reach = 0.01 + NOISE_REACH * 1.15 * sigma
        true = np.c_[
            x0 + 0.01 * np.round((cloud[mat, 0] - x0) / 0.01),
            y0 + 0.01 * np.round((cloud[mat, 1] - y0) / 0.01),
            np.full(mat.sum(), 0.7 + height),
        ]
        true = true[obj.footprint_distance(true[:, :2]) <= RADIUS - RES]  # the rest is voxels
        covered = np.zeros(len(true), dtype=bool)
        for tree, half in trees:
            covered |= tree.query(true)[0] <= reach + half
        assert covered.all(), f"seed {seed}: the mat's top left to the plane at {true[~covered][:3]}"


def test_a_real_table_is_mostly_its_plane():
    """The PCL stereo table (0.7 mm noise; its cells' mean residuals reach 2.4 mm, the table's own
    unevenness): the exact plane stands for at least 95 % of the plane's points (97.3 % measured)."""
    from baseplace.terrain.io import load_cloud, load_transform
    from baseplace.world.support_plane import uneven_points

    mug = SHARED / "pointclouds" / "table_scene_mug_stereo_textured.pcd"
    if not mug.exists():
        pytest.skip("needs the shared PCL data")
    sensor = load_cloud(mug).points
    sensor = sensor[np.all(np.isfinite(sensor), axis=1)]
    T = load_transform("0.0162 -0.8378 -0.5458")
    world = sensor @ T[:3, :3].T + T[:3, 3]

    def distance(xy: np.ndarray) -> np.ndarray:  # the mug's footprint: a 5 cm disc
        return np.maximum(np.hypot(xy[:, 0] - 0.06, xy[:, 1] - 0.605) - 0.05, 0.0)

    slab = fit_support_slab(world, distance, -0.529, RES)
    assert slab is not None and slab.sigma < 0.001
    r = world[:, 2] - slab.height(world[:, :2])
    d = distance(world[:, :2])
    plane = world[(d > 0) & (d <= RADIUS) & (np.abs(r) <= slab.margin)]
    uneven = uneven_points(slab, plane)
    assert uneven.mean() <= 0.05


def _table_with_sides(top: float, rng: np.random.Generator, sigma: float = 0.003):
    """A table top (1 cm grid) with its 3 cm side faces sampled as seed 004's table grid samples them
    (rows 3, 2 and 1 cm under the top), a cylinder 10 cm from two edges, Gaussian noise per axis."""
    (x0, x1), (y0, y1) = TABLE_XY
    xs, ys = np.arange(x0, x1 + 1e-9, 0.01), np.arange(y0, y1 + 1e-9, 0.01)
    X, Y = np.meshgrid(xs, ys)
    parts = [np.c_[X.ravel(), Y.ravel(), np.full(X.size, top)]]
    for z in (top - 0.03, top - 0.02, top - 0.01):
        parts += [np.c_[xs, np.full(len(xs), y), np.full(len(xs), z)] for y in (y0, y1)]
        parts += [np.c_[np.full(len(ys), x), ys, np.full(len(ys), z)] for x in (x0, x1)]
    table = np.concatenate(parts)
    xy = (x1 - 0.1, y1 - 0.1)
    obj = GraspedObject.cylinder([*xy, top + 0.075], 0.03, 0.15)
    a, z = np.meshgrid(
        np.linspace(0, 2 * np.pi, 40, endpoint=False), np.arange(top + 0.005, top + 0.15, 0.01)
    )
    bottle = np.c_[xy[0] + 0.03 * np.cos(a).ravel(), xy[1] + 0.03 * np.sin(a).ravel(), z.ravel()]
    table = table + rng.normal(0.0, sigma, table.shape)
    return table, np.concatenate([table, bottle + rng.normal(0.0, sigma, bottle.shape)]), obj


def test_a_table_seen_with_its_side_faces_keeps_its_exact_plane_on_its_top():
    """The side faces' points within the fit's band lie below the plane: they must not cost the top its
    exact plane (on main 6 of these 10 scenes had none, and the hand met raw noisy cells up to 2 cm
    over the true top: table-grid execution dev seeds)."""
    for seed in range(10):
        _, cloud, obj = _table_with_sides(0.7, np.random.default_rng(seed))
        slab = fit_support_slab(cloud, obj.footprint_distance, obj.bottom, RES)
        assert slab is not None, f"seed {seed}: no plane"
        assert np.all(np.abs(slab.height(slab.hull) - 0.7) < 1e-3), f"seed {seed}: off the true top"


def test_the_plane_kept_beside_side_faces_loses_no_point():
    sigma, top = 0.003, 0.7
    table, cloud, obj = _table_with_sides(top, np.random.default_rng(0), sigma)
    groups, object_group = _models(cloud, obj, slab=True)
    plane = groups.pop(SUPPORT_PLANE, None)
    assert isinstance(plane, SupportPlane)
    # each point of the top and of the side faces is in a cell or inside the plane's prism
    cells = [c for g in [*groups.values(), object_group] for c in _cells(g)]
    in_prism = (
        _in_hull(table[:, :2], plane.hull)
        & (table[:, 2] <= top + 5 * sigma)
        & (table[:, 2] >= top - PLANE_DEPTH + 1e-3)
    )
    assert np.all(in_prism | _in_cells(table, cells, sigma))


def test_the_plane_is_taken_for_the_surface_only_within_half_the_smallest_plane_clearance():
    """uneven_points' allowance (UNEVEN) is half the smallest clearance kept from the exact plane: a
    hand that keeps MIN_CLEARANCE above the plane stays at least UNEVEN above the surface wherever the
    plane stands for it."""
    from baseplace.world.sensor_resolution import MIN_CLEARANCE
    from baseplace.world.support_plane import UNEVEN

    assert 0 < UNEVEN <= MIN_CLEARANCE / 2
