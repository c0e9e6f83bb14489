"""Region labels where the surface is continuous: the demo's ramp meets the floor and the platform.

The oracle is the demo scene's generator (its true heights and surfaces), never the segmentation.
Before the fix the cleanup gave cells cut off from the ramp at its corner by the platform to the
floor, 0.29 m below them, and noise frayed the ramp's borders with the floor and the platform into
one-cell notches, so the demo's path entered the floor twice: regions [0, 2, 0, 2, 1].
"""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.jobs.demo import DEMO_START, demo_scene
from baseplace.navigation.navmap import navigation_map
from baseplace.navigation.planners import plan_path
from baseplace.robots.model import Robot
from baseplace.terrain.graph import GraphSettings
from baseplace.terrain.pipeline import terrain_from_points
from baseplace.terrain.segmentation import RobustSettings
from baseplace_experiments.navigation_experiment import path_violations

TOLERANCE = RobustSettings().extend_dist
"""The segmentation's tolerance: a cell joins a region only this close to its plane [m]."""
MAX_STEP = GraphSettings().max_step
"""The largest height step the robot drives over [m]."""
GOALS = [(x, y, 0.0) for x in (0.8, 1.6, 2.4) for y in (-0.6, -0.3, 0.0, 0.3, 0.6)]
"""Base poses on the platform (true: x 0.3..2.9, y -1.3..1.3), clear of its rim for TIAGo."""


@pytest.fixture(scope="module")
def demo():
    """The demo's scene and its terrain, as ``baseplace demo`` builds them (seed 0)."""
    scene = demo_scene()
    return scene, terrain_from_points(scene.sample_cloud(np.random.default_rng(0)))


@pytest.fixture(scope="module")
def navmap(demo):
    _, terrain = demo
    return navigation_map(terrain, Robot("tiago").spec.footprint_bounding_radius)


def true_height_range(scene, hmap, samples: int = 6, slack: float = 1e-3):
    """(low, high) (H, W) of the true surface under each cell, its edges and ``slack`` [m] included.

    A cell on a plane's edge holds points of both sides (the voxels of a wall land in the cell
    beside it), so either side's plane may claim it; one that matches neither is wrong.
    """
    X, Y = hmap.cell_centres()
    offsets = np.linspace(-hmap.resolution / 2 - slack, hmap.resolution / 2 + slack, samples)
    z = np.stack([scene.height(np.c_[(X + dx).ravel(), (Y + dy).ravel()]).reshape(X.shape)
                  for dx in offsets for dy in offsets])  # fmt: skip
    return np.nanmin(z, axis=0), np.nanmax(z, axis=0)


def test_every_cell_lies_on_its_regions_plane(demo):
    scene, terrain = demo
    seg = terrain.segmentation
    low, high = true_height_range(scene, seg.hmap)
    X, Y = seg.hmap.cell_centres()
    misfits = []
    for region in seg.regions:
        cells = seg.labels == region.id
        z = region.height_at(np.c_[X[cells], Y[cells]])
        miss = np.maximum(low[cells] - z, z - high[cells])
        for x, y, m in zip(
            X[cells][miss > TOLERANCE], Y[cells][miss > TOLERANCE], miss[miss > TOLERANCE], strict=True
        ):
            misfits.append(f"region {region.id} at ({x:.3f}, {y:.3f}) is {m:.3f} m off the surface")
    assert not misfits, f"{len(misfits)} cells: " + "; ".join(misfits[:8])


def test_each_region_is_one_true_surface(demo):
    """Floor, ramp and platform: one region each, under which the generator has that surface."""
    scene, terrain = demo
    seg = terrain.segmentation
    X, Y = seg.hmap.cell_centres()
    truth = scene.surface_id(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
    surfaces = [int(np.bincount(truth[seg.labels == r.id]).argmax()) for r in seg.regions]
    assert sorted(surfaces) == [p.id for p in scene.planes]


@pytest.mark.parametrize("goal", GOALS, ids=[f"x{x}_y{y}" for x, y, _ in GOALS])
def test_demo_path_enters_each_region_once_and_never_steps(demo, navmap, goal):
    scene, terrain = demo
    seg = terrain.segmentation
    start = np.array([float(v) for v in DEMO_START.split()])
    path = plan_path(navmap, start, np.array(goal), "rrt", seed=0)  # as the demo plans it
    assert len(set(path.regions)) == len(path.regions), f"regions {list(path.regions)}"
    X, Y = seg.hmap.cell_centres()
    truth = scene.surface_id(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
    surface = {r: int(np.bincount(truth[seg.labels == r]).argmax()) for r in path.regions}
    assert [scene.planes[surface[r]].kind for r in path.regions] == ["floor", "ramp", "platform"]
    steps, off_surface = path_violations(scene, path, MAX_STEP)  # true heights every 1 cm
    assert (steps, off_surface) == (0, 0)
