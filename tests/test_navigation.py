from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from baseplace.errors import InputError, NothingFoundError
from baseplace.navigation.navmap import navigation_map
from baseplace.navigation.planners import PLANNERS, plan_path
from baseplace.sim.scenes import Plane, Scene, SceneObject, SceneSettings
from baseplace.terrain.pipeline import terrain_from_points
from baseplace_experiments.navigation_experiment import path_violations, run_navigation_experiment

RADIUS = 0.3
SLOPE = math.tan(math.radians(8))


def _ramp_scene(with_object: bool) -> Scene:
    """A 6 m floor; a 3 x 2.4 m ramp rising along +x from x = -1 (8 deg); a raised platform at y = -1.9;
    optionally a 0.4 m cube lying on the ramp's middle (as seed 000 Fig. 4)."""
    floor = Plane(0, "floor", (0.0, 0.0), (6.0, 6.0), 0.0, 0.0, 0.0, 0.0)
    ramp = Plane(1, "ramp", (0.5, 0.6), (3.0, 2.4), 0.0, SLOPE, 0.0, SLOPE * 1.0)  # z = 0 at x = -1
    platform = Plane(2, "platform", (0.5, -1.9), (2.0, 1.2), 0.0, 0.0, 0.0, 0.3)
    objects = ()
    if with_object:
        z = SLOPE * (0.7 + 1.0)
        objects = (SceneObject("cube", (0.7, 0.6, z + 0.2), 0.0, (0.4, 0.4, 0.4)),)
    return Scene(
        SceneSettings(n_planes=2, extent=(6.0, 6.0), with_box=False), (floor, ramp, platform), None, objects
    )


@pytest.fixture(scope="module")
def ramp_world():
    scene = _ramp_scene(with_object=True)
    terrain = terrain_from_points(scene.sample_cloud(np.random.default_rng(0)))
    return scene, navigation_map(terrain, RADIUS)


@pytest.mark.parametrize("planner", PLANNERS)
def test_path_up_the_ramp_goes_around_the_object(ramp_world, planner):
    scene, navmap = ramp_world
    obj = scene.objects[0]
    ramp_id = int(navmap.seg.region_at(np.array([[1.6, 0.6]]))[0])
    assert ramp_id >= 0
    assert (
        navmap.seg.region_at(np.array([obj.center[:2]]))[0] != ramp_id
    )  # the object is not part of the ramp
    start, goal = np.array([-2.0, 0.6, 0.0]), np.array([1.7, 0.6, 0.0])
    path = plan_path(navmap, start, goal, planner)
    footprint = shapely.Polygon(_square(obj))
    line = shapely.LineString(path.dense(0.01))
    assert line.distance(footprint) >= RADIUS - navmap.seg.hmap.resolution  # around it, footprint clear
    assert path_violations(scene, path, 0.04) == (0, 0)  # up the low edge, never over a ledge


def _square(obj: SceneObject) -> np.ndarray:
    h = obj.size[0] / 2
    return np.array(obj.center[:2]) + np.array([[-h, -h], [h, -h], [h, h], [-h, h]])


@pytest.mark.parametrize("planner", PLANNERS)
def test_no_path_onto_a_raised_platform(ramp_world, planner):
    _, navmap = ramp_world
    with pytest.raises(NothingFoundError, match="no path"):
        plan_path(navmap, np.array([-2.0, -1.9, 0.0]), np.array([0.5, -1.9, 0.0]), planner, time_limit=0.5)


def test_bad_start_and_goal(ramp_world):
    _, navmap = ramp_world
    with pytest.raises(InputError, match="outside the scanned area"):
        plan_path(navmap, np.array([9.0, 0.0, 0.0]), np.array([-2.0, 0.6, 0.0]))
    with pytest.raises(InputError, match="in collision"):
        plan_path(navmap, np.array([-2.0, 0.6, 0.0]), np.array([-0.7, -1.9, 0.0]))  # beside the platform
    with pytest.raises(InputError, match="off every surface"):
        plan_path(navmap, np.array([0.7, 0.6, 0.0]), np.array([-2.0, 0.6, 0.0]))  # on the object
    with pytest.raises(InputError, match="valid: regions, rrt"):
        plan_path(navmap, np.array([-2.0, 0.6, 0.0]), np.array([-2.0, 1.6, 0.0]), planner="astar")


def test_navigation_experiment_smoke():
    result = run_navigation_experiment(
        scenes_per_class=1, pairs_per_scene=3, classes=(("medium", 2),), time_limit=0.5
    )
    rows = {r["planner"]: r for r in result["rows"]}
    assert set(rows) == set(PLANNERS)
    for r in rows.values():
        assert r["pairs"] == 3 and r["paths_crossing_a_step"] == 0 and r["paths_to_unreachable_goals"] == 0


def test_true_traversability_on_the_demo_scene():
    """The ground-truth oracle: the platform is reached up the ramp only; its rim is off limits."""
    from baseplace.jobs.demo import demo_scene
    from baseplace_experiments.navigation_experiment import TrueTraversability

    truth = TrueTraversability(demo_scene(), radius=0.3, max_step=0.04)
    floor, platform = (-3.5, 0.0), (1.6, 0.0)
    assert truth.connected(floor, platform)  # up the 6 deg ramp: 2.7 mm per 2.5 cm cell
    assert truth.connected((-3.5, -2.5), (1.6, 0.8))
    assert not truth.connected(floor, (2.75, 1.15))  # 0.15 m from the platform's edge: the disc hangs over
    assert not truth.connected(floor, (10.0, 0.0))  # off the scene
    steep = TrueTraversability(demo_scene(), radius=0.3, max_step=0.002)  # the ramp's 2.7 mm step is too much
    assert not steep.connected(floor, platform)
    assert steep.connected(floor, (-3.5, -2.5))


@pytest.mark.parametrize("yaw", [np.pi, -np.pi])
def test_headings_of_pi_at_start_and_goal(ramp_world, yaw):
    # OMPL's SO(2) holds [-pi, pi); a heading of exactly pi (or -pi, which wraps to pi) is a valid
    # pose and must plan like any other, ending at the goal's heading
    _, navmap = ramp_world
    start, goal = np.array([-2.0, 0.6, yaw]), np.array([1.7, 0.6, yaw])
    path = plan_path(navmap, start, goal, "rrt")
    assert np.allclose(path.poses[-1, :2], goal[:2], atol=1e-6)
    assert abs(np.angle(np.exp(1j * (path.poses[-1, 2] - yaw)))) < 1e-6
    assert np.all((path.poses[:, 2] > -np.pi) & (path.poses[:, 2] <= np.pi))
