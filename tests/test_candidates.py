"""Seed 004: radial candidates (Algorithm 1), pickup loop (Algorithm 2), grid planner, pointing, IRM.

Every geometric property is checked against an independent oracle: brute force over grid cells and
cloud points in the candidate's own frame, scipy's Dijkstra for path lengths, dense sampling for
ray-box hits, pinocchio FK for the IRM joint solutions.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from shapely.geometry import Point, Polygon

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, invert_transforms
from baseplace.navigation.gridnav import GridNavigator
from baseplace.navigation.path import Path
from baseplace.placement.candidates import (
    RadialCandidate,
    RadialSettings,
    collision_risk,
    has_collision_risk,
    motion_cost,
    occupancy_risk,
    pickup,
    radial_candidates,
    radial_search,
)
from baseplace.placement.irm_candidates import (
    IrmSettings,
    grasp_poses,
    hand_feasible,
    irm_candidates,
    verify_candidates,
)
from baseplace.placement.pointing import pointed_object, pointing_ray, ray_box_distances
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from baseplace.world.occupancy import OccupancyGrid, load_occupancy
from conftest import SHARED

RES = 0.05
TABLE = (1.6, 2.4, 1.1, 2.9, 0.74)  # x0, x1, y0, y1, top [m]: the seed's 0.8 m x 1.8 m table


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _grid(mask_fn, n: int = 80, res: float = RES, origin=(0.0, 0.0, 0.0)) -> OccupancyGrid:
    """Grid with cells occupied (100) where ``mask_fn(x, y)`` of their centre holds."""
    centres = (np.arange(n) + 0.5) * res
    X, Y = np.meshgrid(centres + origin[0], centres + origin[1])  # row j = y, column i = x
    return OccupancyGrid(np.where(mask_fn(X, Y), 100, 0).astype(np.int8), res, origin)


def _occupied_squares(grid: OccupancyGrid, threshold: int = 50) -> np.ndarray:
    """Centres (M, 2) of every obstacle cell, for brute force (axis-aligned grids)."""
    rows, cols = np.nonzero(grid.data >= threshold)
    return np.c_[
        grid.origin[0] + (cols + 0.5) * grid.resolution, grid.origin[1] + (rows + 0.5) * grid.resolution
    ]


def _dist_to_squares(p: np.ndarray, centres: np.ndarray, res: float) -> np.ndarray:
    closest = np.clip(p, centres - res / 2, centres + res / 2)
    return np.linalg.norm(closest - p, axis=1)


def _in_base_frame(candidate: RadialCandidate, points: np.ndarray) -> np.ndarray:
    T = invert_transforms(candidate.pose.matrix())
    return points @ T[:3, :3].T + T[:3, 3]


@pytest.fixture(scope="module")
def table_scene():
    x0, x1, y0, y1, top = TABLE
    grid = _grid(lambda X, Y: (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1))
    rng = np.random.default_rng(4)
    table = np.c_[rng.uniform(x0, x1, 20000), rng.uniform(y0, y1, 20000), top + rng.normal(0, 0.004, 20000)]
    floor = np.c_[rng.uniform(0, 4, 30000), rng.uniform(0, 4, 30000), rng.normal(0, 0.004, 30000)]
    p_o = np.array([2.2, 2.5, top + 0.06])  # a cup 0.2 m from the table's +x edge
    a = rng.uniform(0, 2 * np.pi, 2000)
    cup = np.c_[p_o[0] + 0.04 * np.cos(a), p_o[1] + 0.04 * np.sin(a), rng.uniform(top, top + 0.12, 2000)]
    return grid, np.r_[table, floor, cup], p_o


# --- Algorithm 1 ---------------------------------------------------------------------------------


def test_theta_and_ray_count():
    s = RadialSettings(r_r=0.3, d_min=0.5, d_max=1.0)
    theta = 2 * math.asin(0.3 / (2 * 0.5))
    assert s.theta == pytest.approx(theta, abs=1e-15)
    assert s.n_rays == math.ceil(2 * math.pi / theta)
    assert 2 * 0.5 * math.sin(theta / 2) == pytest.approx(0.3)  # the footnote's angle: chord r_r, not 2 r_r
    cands = radial_candidates([1.0, -2.0], s)  # nothing to collide with: one candidate per ray at d_min
    assert len(cands) == s.n_rays
    xy = np.array([c.xy for c in cands])
    assert np.allclose(np.linalg.norm(xy - [1.0, -2.0], axis=1), 0.5)
    chords = np.linalg.norm(np.diff(np.r_[xy, xy[:1]], axis=0), axis=1)
    assert np.all(chords <= 2 * 0.5 * math.sin(theta / 2) + 1e-12)  # rays at most theta apart
    assert np.allclose(chords, chords[0])  # equally spaced


def test_candidates_face_the_object(table_scene):
    grid, points, p_o = table_scene
    cands = radial_candidates(p_o, RadialSettings(), points, grid)
    assert cands
    for c in cands:
        toward = math.atan2(p_o[1] - c.pose.y, p_o[0] - c.pose.x)
        assert abs(_wrap(c.pose.yaw - toward)) < 1e-9
        T = c.pose.matrix()  # the base x axis points at the object
        assert np.dot(T[:2, 0], p_o[:2] - c.xy) == pytest.approx(np.linalg.norm(p_o[:2] - c.xy))


def test_table_scene_candidates_are_clear(table_scene):
    grid, points, p_o = table_scene
    s = RadialSettings()
    search = radial_search(p_o, s, points, grid)
    assert len(search.candidates) >= 3
    centres = _occupied_squares(grid)
    for c in search.candidates:
        assert s.d_min <= c.distance < s.d_max
        assert grid.value_at(c.xy)[0] == 0
        assert np.linalg.norm(centres - c.xy, axis=1).min() >= s.r_r
        assert _dist_to_squares(c.xy, centres, grid.resolution).min() > s.r_r
        # Both cuboids, brute force in the candidate's base frame (x points at the object).
        q = _in_base_frame(c, points)
        body = (
            (np.abs(q[:, 0]) <= s.r_r) & (np.abs(q[:, 1]) <= s.r_r) & (q[:, 2] >= 0.05) & (q[:, 2] <= s.h_r)
        )
        near_face = c.distance - s.w_o / 2 - s.surface_margin
        arm = (q[:, 0] >= 0) & (q[:, 0] <= near_face) & (np.abs(q[:, 1]) <= s.w_o / 2)
        arm &= (q[:, 2] >= p_o[2] - s.h_o / 2 + s.surface_margin) & (q[:, 2] <= p_o[2] + s.h_o / 2)
        assert body.sum() <= s.k_obs and arm.sum() <= s.k_obs
    # Every rejection by a cuboid really holds more than k_obs points there.
    for r in search.rejected:
        if r.reason == "body":
            c = RadialCandidate(BasePose(*r.xy, math.atan2(p_o[1] - r.xy[1], p_o[0] - r.xy[0])), r.distance)
            q = _in_base_frame(c, points)
            inside = (
                (np.abs(q[:, 0]) <= s.r_r)
                & (np.abs(q[:, 1]) <= s.r_r)
                & (q[:, 2] >= 0.05)
                & (q[:, 2] <= s.h_r)
            )
            assert inside.sum() > s.k_obs
    # The cloud alone sees the table and keeps candidates off it, too.
    for c in radial_candidates(p_o, s, points):
        assert _dist_to_squares(c.xy, centres, grid.resolution).min() > s.r_r - 0.03


def test_object_and_its_support_do_not_count(table_scene):
    _, points, p_o = table_scene
    s = RadialSettings()
    free_side = p_o[:2] + np.array([0.75, 0.0])  # beyond the +x table edge, clear of it
    assert not has_collision_risk(free_side, p_o, s, points)


def test_walk_steps_outwards_when_blocked():
    s = RadialSettings(r_r=0.275, d_min=0.45, d_max=0.95, k_obs=10)
    p_o = np.array([0.0, 0.0, 0.8])
    rng = np.random.default_rng(1)

    def cluster(x: float, z: float = 0.5) -> np.ndarray:  # 50 points around (x, 0, z)
        return np.c_[x + rng.normal(0, 0.01, 50), rng.normal(0, 0.01, 50), z + rng.normal(0, 0.01, 50)]

    # A cluster 0.1 m inside d_min fills the body cuboid at d_min, not the one at d_min + r_r.
    search = radial_search(p_o, s, cluster(s.d_min - 0.1))
    ray0 = [c for c in search.candidates if c.ray == 0]
    assert len(ray0) == 1 and ray0[0].distance == pytest.approx(s.d_min + s.r_r)
    assert [(r.distance, r.reason) for r in search.rejected if r.ray == 0] == [(s.d_min, "body")]
    assert len(search.candidates) == s.n_rays

    blocked = radial_search(p_o, s, np.r_[cluster(s.d_min - 0.1), cluster(s.d_min + s.r_r + 0.2)])
    assert not [c for c in blocked.candidates if c.ray == 0]  # d_min + 2 r_r = 1.0 >= d_max
    assert [r.distance for r in blocked.rejected if r.ray == 0] == pytest.approx([s.d_min, s.d_min + s.r_r])

    high = np.array([0.0, 0.0, 1.6])  # above h_r: only the arm cuboid sees points at its height
    arm = radial_search(high, s, cluster(0.3, z=1.6))
    assert {r.reason for r in arm.rejected if r.ray == 0} == {"arm"}
    assert not [c for c in arm.candidates if c.ray == 0]


def test_k_obs_threshold():
    s = RadialSettings(k_obs=7)
    p_o = np.array([0.0, 0.0, 0.8])
    xy = np.array([0.6, 0.0])
    pts = np.c_[np.full(8, 0.6), np.linspace(-0.1, 0.1, 8), np.full(8, 0.5)]
    assert not has_collision_risk(xy, p_o, s, pts[:7])
    assert collision_risk(xy, p_o, s, pts) == "body"


def test_occupancy_disc_rasterisation():
    s = RadialSettings(r_r=0.3)
    grid = _grid(lambda X, Y: (X > 2.0) & (X < 2.05) & (Y > 2.0) & (Y < 2.05))  # one cell [2.0, 2.05]^2
    p_o = [1.0, 1.0]
    assert (
        collision_risk([2.0 - 0.29, 2.02], p_o, s, occupancy=grid) == "occupancy"
    )  # disc overlaps the square
    assert collision_risk([2.0 - 0.32, 2.02], p_o, s, occupancy=grid) is None
    assert collision_risk([0.1, 0.1], p_o, s, occupancy=grid) == "occupancy"  # disc leaves the map
    assert (
        collision_risk([0.1, 0.1], p_o, RadialSettings(r_r=0.3, unknown_is_risk=False), occupancy=grid)
        is None
    )


def test_occupancy_risk_on_a_rotated_grid_against_shapely():
    rng = np.random.default_rng(8)
    data = np.where(rng.random((40, 50)) < 0.03, 100, 0).astype(np.int8)
    grid = OccupancyGrid(data, 0.05, (0.4, -0.3, 0.3))
    radius = 0.12
    rows, cols = np.nonzero(data >= 50)
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
    squares = [
        Polygon(grid.cell_to_world(np.c_[c + corners[:, 0] - 0.5, r + corners[:, 1] - 0.5]))
        for r, c in zip(rows, cols, strict=True)
    ]
    obstacle_centres = grid.cell_to_world(np.c_[cols, rows])
    local = rng.uniform([0.3, 0.3], [2.2, 1.7], (400, 2))  # inside the map, the disc stays on it
    c, s_ = math.cos(0.3), math.sin(0.3)
    pts = local @ np.array([[c, s_], [-s_, c]]) + [0.4, -0.3]
    risk = occupancy_risk(grid, pts, radius)
    checked = 0
    for p, flag in zip(pts, risk, strict=True):
        gap = min(sq.distance(Point(p)) for sq in squares)
        own = grid.cell_to_world(grid.world_to_cell(p))[0]
        centre_gap = np.linalg.norm(obstacle_centres - own, axis=1).min()
        if abs(gap - radius) < 1e-9 or abs(centre_gap - radius) < 1e-9:
            continue
        assert flag == (gap <= radius or centre_gap <= radius)
        checked += 1
    assert checked > 350 and 0 < risk.sum() < len(risk)


@pytest.mark.parametrize("name", ["depot", "tb3_sandbox"])
def test_real_maps_candidates_keep_clearance(name):
    grid = load_occupancy(SHARED / "maps" / f"{name}.yaml")
    s = RadialSettings()
    obstacles = _occupied_squares(grid)
    unknown_rows, unknown_cols = np.nonzero(grid.data < 0)
    unknown = np.c_[grid.origin[0] + (unknown_cols + 0.5) * grid.resolution,
                    grid.origin[1] + (unknown_rows + 0.5) * grid.resolution]  # fmt: skip
    # Objects on free cells 0.1-0.2 m from an obstacle: the edge of a shelf, table or wall.
    rows, cols = np.nonzero(grid.data == 0)
    xy = grid.cell_to_world(np.c_[cols, rows])
    near = (grid.clearance(xy, 50) >= 0.1) & (grid.clearance(xy, 50) <= 0.2)
    rng = np.random.default_rng(0)
    total = 0
    for p_o in rng.permutation(xy[near])[:15]:
        for c in radial_candidates(p_o, s, occupancy=grid):
            total += 1
            assert np.linalg.norm(obstacles - c.xy, axis=1).min() >= s.r_r
            assert _dist_to_squares(c.xy, obstacles, grid.resolution).min() > s.r_r
            if len(unknown):
                assert _dist_to_squares(c.xy, unknown, grid.resolution).min() > s.r_r
    assert total > 0


# --- Algorithm 2 ---------------------------------------------------------------------------------


def _cands(*xys: tuple[float, float]) -> list[RadialCandidate]:
    return [
        RadialCandidate(BasePose(x, y, math.atan2(-y, -x)), math.hypot(x, y), k)
        for k, (x, y) in enumerate(xys)
    ]


def test_motion_cost_is_the_two_distances():
    c = _cands((1.0, 0.0))[0]
    assert motion_cost(c, [0.0, 0.0, 0.7], BasePose(4.0, 4.0, 0.0)) == pytest.approx(5.0 + 1.0)
    assert motion_cost(c, [0.0, 0.0], BasePose(4.0, 4.0, 0.0), travel=2.5) == pytest.approx(3.5)


def test_pickup_reranks_after_a_navigation_failure():
    cands = _cands((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0))
    start = BasePose(2.0, 0.2, 0.0)
    tried: list[int] = []

    def navigate(current: BasePose, goal: BasePose):
        k = next(i for i, c in enumerate(cands) if c.pose == goal)
        tried.append(k)
        return (
            None
            if k == 0
            else Path(np.array([[current.x, current.y, 0.0], [goal.x, goal.y, 0.0]]), "test", 0.0, ())
        )

    def cost(c, pose):  # oracle: the seed's two distances
        return math.dist((pose.x, pose.y), (c.pose.x, c.pose.y)) + math.hypot(c.pose.x, c.pose.y)

    assert min(range(3), key=lambda k: cost(cands[k], start)) == 0
    result = pickup(cands, [0.0, 0.0], start, navigate)
    assert tried == [0, 1] and result.chosen is cands[1] and result.tries == 2
    assert result.failures[0][0] is cands[0] and result.failures[0][1] == "no path"
    # The robot moved while failing: the rest is ranked from where it is now.
    tried.clear()
    moved = BasePose(-2.0, 0.2, 0.0)
    result = pickup(cands, [0.0, 0.0], start, navigate, locate=lambda: moved)
    assert tried == [0, 2] and result.chosen is cands[2]
    assert min((1, 2), key=lambda k: cost(cands[k], moved)) == 2
    tried.clear()
    everything_fails = pickup(cands, [0.0, 0.0], start, lambda a, b: None)
    assert not everything_fails.succeeded and everything_fails.tries == 3 and everything_fails.path is None


def test_pickup_default_navigator_skips_an_enclosed_candidate():
    # A ring of wall around the nearest candidate: a valid goal, but unreachable.
    def walls(X, Y):
        r = np.hypot(X - 3.0, Y - 2.0)
        return (r > 0.45) & (r < 0.55)

    grid = _grid(walls)
    p_o = np.array([2.0, 2.0])
    inside, outside = (
        RadialCandidate(BasePose(3.0, 2.0, math.pi), 1.0, 0),
        RadialCandidate(BasePose(2.0, 3.0, -math.pi / 2), 1.0, 1),
    )
    start = BasePose(3.6, 2.8, 0.0)
    assert motion_cost(inside, p_o, start) < motion_cost(outside, p_o, start)
    result = pickup([inside, outside], p_o, start, occupancy=grid, settings=RadialSettings(r_r=0.2))
    assert result.chosen is outside and result.tries == 2
    assert result.failures == [(inside, "no path")]
    assert result.path is not None and np.allclose(result.path.poses[-1], [2.0, 3.0, -math.pi / 2])
    assert np.allclose(result.path.poses[0], [3.6, 2.8, 0.0])  # from the robot, as it stands


# --- grid planner --------------------------------------------------------------------------------


def _wall(X, Y):
    return (X > 1.5) & (X < 1.6) & (Y < 1.4)


def _oracle_length(free: np.ndarray, s: tuple[int, int], g: tuple[int, int], res: float) -> float:
    """Independent 8-connected Dijkstra (scipy) between the centres of free cells (row, col)."""
    h, w = free.shape
    idx = np.arange(h * w).reshape(h, w)
    r, c = np.nonzero(free)
    src, dst, weights = [], [], []
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr == dc == 0:
                continue
            r2, c2 = r + dr, c + dc
            ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
            ok[ok] &= free[r2[ok], c2[ok]]
            src.append(idx[r[ok], c[ok]])
            dst.append(idx[r2[ok], c2[ok]])
            weights.append(np.full(ok.sum(), res * math.hypot(dr, dc)))
    graph = coo_matrix(
        (np.concatenate(weights), (np.concatenate(src), np.concatenate(dst))), shape=(h * w, h * w)
    )
    return float(dijkstra(graph.tocsr(), indices=idx[s])[idx[g]])


def test_grid_planner_goes_around_a_wall():
    grid = _grid(_wall, n=60)
    radius = 0.15
    start, goal = (0.525, 0.525), (2.525, 0.525)  # cell centres
    route = GridNavigator(grid, radius).plan(start, goal, start_yaw=0.5, goal_yaw=-3.0)
    assert isinstance(route, Path) and route.planner == "grid"  # the one path type (issue 16 item 6)
    path = route.poses[:, :2]
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    assert route.poses[0, 2] == 0.5 and route.poses[-1, 2] == -3.0
    step = np.diff(path, axis=0)  # in between, each pose heads to the next
    np.testing.assert_allclose(route.poses[1:-1, 2], np.arctan2(step[1:, 1], step[1:, 0]))
    assert path[:, 1].max() > 1.4  # over the wall's end
    obstacles = _occupied_squares(grid)
    cells = grid.world_to_cell(path)
    assert np.all(np.abs(np.diff(cells, axis=0)) <= 1)  # 8-connected steps
    for p in grid.cell_to_world(cells):
        assert np.linalg.norm(obstacles - p, axis=1).min() > radius  # never in the inflated wall
    # Oracle for optimality: free cells are those whose centre is > radius from every obstacle centre.
    centres = grid.cell_to_world(np.argwhere(np.ones(grid.data.shape, bool))[:, ::-1])
    d = np.min(np.linalg.norm(centres[:, None] - obstacles[None], axis=2), axis=1)
    free = (d > radius + 1e-9).reshape(grid.data.shape)  # "within radius" includes radius itself
    s, g = tuple(grid.world_to_cell(start)[0][::-1]), tuple(grid.world_to_cell(goal)[0][::-1])
    assert route.length == pytest.approx(_oracle_length(free, s, g, RES), abs=1e-9)


def test_grid_planner_errors_and_no_path():
    grid = _grid(_wall, n=60)
    with pytest.raises(InputError, match=r"^start .*in an obstacle"):
        GridNavigator(grid, 0.15).plan((1.55, 0.5), (2.5, 0.5))
    with pytest.raises(InputError, match=r"^start .*outside the map"):
        GridNavigator(grid, 0.15).plan((-0.5, 0.5), (2.5, 0.5))
    with pytest.raises(InputError, match=r"^goal .*too close to an obstacle"):
        GridNavigator(grid, 0.15).plan((0.5, 0.5), (1.7, 0.5))
    closed = _grid(lambda X, Y: (X > 1.5) & (X < 1.6), n=60)
    assert GridNavigator(closed, 0.15).plan((0.5, 0.5), (2.5, 0.5)) is None
    unknown = OccupancyGrid(np.where(grid.data == 0, -1, grid.data).astype(np.int8), RES)
    with pytest.raises(InputError, match="unknown"):
        GridNavigator(unknown, 0.15).plan((0.5, 0.5), (2.5, 0.5))
    assert GridNavigator(unknown, 0.15, allow_unknown=True).plan((0.5, 0.5), (2.5, 0.5)) is not None


def test_grid_travel_matches_planned_length():
    grid = _grid(_wall, n=60)
    nav = GridNavigator(grid, 0.15)
    goal = (2.525, 0.525)
    path = nav.plan((0.525, 0.525), goal)
    assert path is not None
    assert nav.travel(BasePose(0.525, 0.525, 0.0), np.array([goal]))[0] == pytest.approx(path.length)


# --- pointing ------------------------------------------------------------------------------------


def _hand(direction, tip=(0.0, 0.0, 0.0)) -> np.ndarray:
    rng = np.random.default_rng(5)
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    lm = np.asarray(tip, float) + rng.normal(0, 0.03, (21, len(d)))
    for k, back in zip((5, 6, 7, 8), (0.09, 0.05, 0.025, 0.0), strict=True):
        lm[k] = np.asarray(tip, float) - back * d
    return lm


def _boxes3():
    near = [[1.0, -0.1, -0.1], [1.2, 0.1, 0.1]]
    far = [[2.0, -0.2, -0.2], [2.3, 0.2, 0.3]]
    return np.array([far, near])


def test_pointing_picks_the_nearer_box():
    assert pointed_object(_hand([1.0, 0.0, 0.0]), _boxes3()) == 1
    assert pointed_object(_hand([1.0, 0.0, 0.0]), _boxes3()[::-1]) == 0
    assert pointed_object(_hand([1.0, 0.0, 0.0]), _boxes3(), max_range=0.5) is None
    assert pointed_object(_hand([-1.0, 0.0, 0.0]), _boxes3()) is None  # pointing away
    assert pointed_object(_hand([1.0, 1.0, 0.0]), _boxes3()) is None  # pointing past both
    tilted = _hand([1.0, 0.0, 0.12])  # over the near box (z = 0.12 m at x = 1 m), into the far one
    assert pointed_object(tilted, _boxes3()) == 0
    origin, direction = pointing_ray(tilted)
    assert np.allclose(origin, 0.0, atol=1e-12)
    assert np.allclose(direction, np.array([1.0, 0, 0.12]) / math.hypot(1.0, 0.12))


def test_pointing_in_the_image_plane():
    boxes = np.array([[[300, 180], [360, 260]], [[100, 180], [160, 260]]], float)  # pixels
    assert pointed_object(_hand([1.0, 0.0], tip=(200.0, 220.0)), boxes) == 0
    assert pointed_object(_hand([-1.0, 0.0], tip=(200.0, 220.0)), boxes) == 1
    assert pointed_object(_hand([0.0, 1.0], tip=(200.0, 220.0)), boxes) is None


def test_ray_box_distance_against_sampling():
    rng = np.random.default_rng(6)
    for _ in range(200):
        o, d = rng.uniform(-1, 1, 3), rng.normal(size=3)
        d[rng.integers(3)] = 0.0 if rng.random() < 0.3 else d[0]  # rays parallel to a slab
        lo = rng.uniform(-1, 1, 3)
        box = np.array([lo, lo + rng.uniform(0.05, 0.8, 3)])
        t = ray_box_distances(o, d, box[None])[0]
        u = d / np.linalg.norm(d)
        ts = np.linspace(0, 4, 40001)
        inside = np.all(
            (o + ts[:, None] * u >= box[0] - 1e-12) & (o + ts[:, None] * u <= box[1] + 1e-12), axis=1
        )
        if inside.any():
            assert t == pytest.approx(ts[inside.argmax()], abs=1e-4 + 1e-9)
        else:
            assert t > 4 - 1e-4 or np.isinf(t)
    # Grazing a face while parallel to it still counts: boxes are closed.
    assert ray_box_distances([0, 0, 0], [1, 0, 0], np.array([[[1, 0, -1], [2, 1, 1]]]))[0] == pytest.approx(
        1.0
    )


def test_pointing_rejects_malformed_input():
    with pytest.raises(InputError, match="21"):
        pointed_object(np.zeros((20, 3)), _boxes3())
    bad = _hand([1.0, 0.0, 0.0])
    bad[3, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        pointed_object(bad, _boxes3())
    with pytest.raises(InputError, match="min corner"):
        pointed_object(_hand([1.0, 0.0, 0.0]), _boxes3()[:, ::-1])
    with pytest.raises(InputError, match=r"\(M, 2, 3\)"):
        pointed_object(_hand([1.0, 0.0, 0.0]), np.zeros((2, 3, 3)))
    with pytest.raises(InputError, match="coincide"):
        pointed_object(np.zeros((21, 3)), _boxes3())


def test_settings_reject_bad_values():
    with pytest.raises(InputError, match="d_min < d_max"):
        RadialSettings(d_min=1.0, d_max=0.9)
    with pytest.raises(InputError, match="k_obs"):
        RadialSettings(k_obs=-1)
    with pytest.raises(InputError, match="r_r"):
        RadialSettings(r_r=0.0)
    with pytest.raises(InputError, match="height"):
        radial_candidates([0.0, 0.0], RadialSettings(), points=np.zeros((3, 3)))


# --- IRM candidates (the seed's future work) -----------------------------------------------------


def test_irm_candidates_pass_an_independent_ik_check(tiago, tiago_map, table_scene):
    grid, _, _ = table_scene
    x0, x1, y0, y1, top = TABLE
    p_o = np.array([2.2, 2.5, top + 0.1])  # a bottle: TIAGo's hand spreads +-0.065 m about its axis
    table_top = np.stack(np.meshgrid(np.arange(x0, x1, 0.02), np.arange(y0, y1, 0.02), [top - 0.01]), -1)
    env = Environment(tiago, VoxelMap.from_points(table_top.reshape(-1, 3), 0.025))
    grasps = grasp_poses(p_o, n=8, top_down=True, standoff=0.15)
    settings = IrmSettings(count=3)
    found = irm_candidates(tiago, tiago_map, p_o, grasps, env, grid, settings, np.random.default_rng(0))
    assert len(found) == 3
    arm = tiago.arm()
    model, data = tiago.model, tiago.model.createData()
    obstacles = _occupied_squares(grid)
    for c in found:
        q = c.joints[0]
        assert c.approach is not None and c.approach.method == "irm" and c.reachability > 0
        assert np.all(q >= arm.lower - 1e-9) and np.all(q <= arm.upper + 1e-9)
        pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, tiago.q_reference))
        T_base_tcp = (
            data.oMf[model.getFrameId(arm.base_frame)].inverse() * data.oMf[model.getFrameId(arm.tcp_frame)]
        ).homogeneous
        T_world_tcp = c.pose.matrix() @ T_base_tcp
        G = grasps[c.grasp]
        assert np.linalg.norm(T_world_tcp[:3, 3] - G[:3, 3]) < 1e-4
        assert np.linalg.norm(pin.log3(G[:3, :3].T @ T_world_tcp[:3, :3])) < 1e-3
        assert _dist_to_squares(c.xy, obstacles, grid.resolution).min() > tiago.spec.footprint_bounding_radius
    seps = [math.dist(a.xy, b.xy) for i, a in enumerate(found) for b in found[i + 1 :]]
    assert min(seps) >= settings.separation
    assert [c.reachability for c in found] == sorted((c.reachability for c in found), reverse=True)


def test_hand_pruning_loses_no_placement(tiago, tiago_map, table_scene):
    """A grasp whose hand alone is in the table fails the whole-robot check from every base pose.

    Oracle: IK from many base poses (collision ignored), then ``Environment.colliding`` on the
    whole robot at each solution.
    """
    grid, _, _ = table_scene
    x0, x1, y0, y1, top = TABLE
    table_top = np.stack(np.meshgrid(np.arange(x0, x1, 0.02), np.arange(y0, y1, 0.02), [top - 0.01]), -1)
    env = Environment(tiago, VoxelMap.from_points(table_top.reshape(-1, 3), 0.025))
    # side grasps 2 cm above the top put the fingers into the table; top-down ones 12 cm above clear it
    p_o = np.array([x0 + 0.1, 0.5 * (y0 + y1), top + 0.02])
    side = grasp_poses(p_o, n=8, standoff=0.15)
    top_down = grasp_poses(p_o, n=8, top_down=True, standoff=0.15, top_offset=0.10)[8:]
    grasps = np.concatenate([side, top_down])
    ok = hand_feasible(tiago, None, grasps, env)
    assert not ok[:8].any() and ok[8:].all()  # every side grasp pruned, every top-down one kept

    arm = tiago.arm()
    ik = DampedLeastSquaresIK(arm)
    rng = np.random.default_rng(1)
    solved = 0
    for k in range(8):  # side grasps, approached from the open side of the table
        for d in (0.55, 0.7):
            yaw = 2 * math.pi * k / 8
            base = BasePose(p_o[0] - d * math.cos(yaw), p_o[1] - d * math.sin(yaw), yaw)
            q = ik.solve_world(grasps[k], base.matrix(), rng)
            if q is not None:
                solved += 1
                assert env.colliding_arm(arm, q, base.matrix())
    assert solved >= 2  # the oracle saw some IK solutions to check

    # the IRM search spends its checks on the top-down grasps only
    found = irm_candidates(tiago, tiago_map, p_o, grasps, env, grid, IrmSettings(count=2),
                           np.random.default_rng(0))  # fmt: skip
    assert found and all(c.grasp is not None and c.grasp >= 8 for c in found)
    assert not hand_feasible(tiago, None, grasps[:8], env).any()
    verified, rejected = verify_candidates(tiago, None, found, grasps[:8], env, rng)
    assert not verified and all(reason == "collision" and motion is None for _, reason, motion in rejected)


def test_grasp_poses_top_offset_lifts_only_top_down_grasps():
    p_o = np.array([1.0, 2.0, 0.8])
    G = grasp_poses(p_o, n=4, top_down=True, standoff=0.15, top_offset=0.08)
    # the grasp point is the TCP moved standoff along its approach (x) axis
    grip = G[:, :3, 3] + 0.15 * G[:, :3, 0]
    np.testing.assert_allclose(grip[:4], np.tile(p_o, (4, 1)), atol=1e-12)
    np.testing.assert_allclose(grip[4:], np.tile([1.0, 2.0, 0.88], (4, 1)), atol=1e-12)
    np.testing.assert_allclose(G[4:, :3, 0], np.tile([0.0, 0.0, -1.0], (4, 1)), atol=1e-12)
    with pytest.raises(InputError, match="top_offset"):
        grasp_poses(p_o, top_down=True, top_offset=float("nan"))
