"""Where a wheeled base may stand: the ground and what it can drive onto, not a table top (issue 25).

Oracle: the generated scenes' true surfaces (which true plane lies under each region's centroid,
the true table's footprint and height), never the segmentation's own labels.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from baseplace.errors import InputError
from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings, ground_regions, place
from baseplace.sim.scenes import Plane, Scene, SceneSettings
from baseplace.terrain.pipeline import terrain_from_points
from baseplace.terrain.polygons import footprint_outline

FLOOR = Plane(0, "floor", (0.0, 0.0), (8.0, 8.0), 0.0, 0.0, 0.0, 0.0)
RAMP = Plane(
    1, "ramp", (2.0, -2.0), (2.4, 1.4), 0.0, 0.08, 0.0, -0.08 * 0.8
)  # z = 0 at x = 0.8, 0.19 m at x = 3.2
TABLE = Plane(2, "platform", (0.0, 1.5), (1.6, 1.0), 0.0, 0.0, 0.0, 0.72)  # a table top, no way up
LEDGE = Plane(3, "platform", (-2.2, -2.0), (1.6, 1.6), 0.0, 0.0, 0.0, 0.25)  # a raised platform, no ramp


def _scene(*planes: Plane) -> Scene:
    return Scene(SceneSettings(n_planes=len(planes), extent=(8.0, 8.0), with_box=False), (FLOOR, *planes))


def _true_plane(scene: Scene, xyz: np.ndarray) -> int:
    """The id of the true surface under a point: the highest plane containing its xy (the scene's solids)."""
    under = [p for p in scene.planes if p.contains(xyz[None, :2])[0]]
    return max(under, key=lambda p: float(p.z(xyz[None, :2])[0])).id


@pytest.fixture(scope="module")
def terrain_and_scene():
    scene = _scene(RAMP, TABLE, LEDGE)
    points = scene.sample_cloud(np.random.default_rng(4), sigma=0.005)
    return terrain_from_points(points), scene


def test_the_ground_and_the_ramp_are_standable_a_table_top_and_a_ledged_platform_are_not(
    tiago, terrain_and_scene
):
    terrain, scene = terrain_and_scene
    outline = footprint_outline(tiago.spec.footprint_radius, tiago.spec.footprint_polygon)
    allowed = set(ground_regions(terrain, outline))
    truth = {r.id: _true_plane(scene, r.centroid) for r in terrain.segmentation.regions}
    on = {plane: {i for i, p in truth.items() if p == plane} for plane in range(4)}
    assert on[0] and on[1] and on[2] and on[3], truth  # each true surface has a region
    assert on[0] <= allowed and on[1] <= allowed  # the floor and the ramp from it
    assert not (on[2] | on[3]) & allowed  # neither the table top nor the platform behind its ledge


def test_a_target_over_the_middle_of_a_table_gets_no_placement_on_the_table(tiago, tiago_map_10m):
    """Top-down over the table's centre, 0.8 m from its long edges: on main the base stood on the top."""
    scene = _scene(TABLE)
    points = scene.sample_cloud(np.random.default_rng(5), sigma=0.005)
    terrain = terrain_from_points(points)
    target = pose_from_xyz_rpy([0.0, 1.5, 0.72 + 0.35, 0.0, math.pi / 2, 0.0])
    table = Polygon(TABLE.polygon)

    def run(**kw):
        settings = PlaceSettings(placements=5, tries=300, **POSE_ONLY_CHECKS, **kw)
        return place(
            tiago, tiago_map_10m, points, target, settings, np.random.default_rng(0), terrain=terrain
        )

    anywhere = run(stand_on="any")  # seed 000's experiments: every planar region
    assert any(table.contains(Point(p.T_world_base[:2, 3])) for p in anywhere.placements)
    try:
        found = run().placements
    except InputError as exc:  # nothing within reach from the floor: said so, with the way out
        assert "--stand-on any" in str(exc)
        found = []
    for p in found:
        assert not table.buffer(0.05).contains(Point(p.T_world_base[:2, 3]))
        assert abs(p.T_world_base[2, 3]) < 0.03  # on the true floor


def test_stand_on_must_be_ground_or_any():
    with pytest.raises(InputError, match="stand_on must be one of ground, any"):
        PlaceSettings(stand_on="table")
