from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely

import baseplace.sim
from baseplace.errors import InputError
from baseplace.sim import (
    NONPLANAR,
    OUTSIDE,
    SIZE_CLASSES,
    Scene,
    SceneSettings,
    generate_scene,
    load_scene,
    save_scene,
    truth_grid,
)

SMALL = SceneSettings(size_class="small", n_planes=4, extent=(6.0, 6.0))


def scene_of(settings: SceneSettings = SMALL, seed: int = 0) -> Scene:
    return generate_scene(settings, np.random.default_rng(seed))


@pytest.fixture(scope="module")
def scene() -> Scene:
    return scene_of()


def corners(center, size, yaw):
    """Footprint corners recomputed from the stored centre, size and yaw (not Plane.polygon)."""
    c, s = math.cos(yaw), math.sin(yaw)
    hx, hy = size[0] / 2, size[1] / 2
    return np.array([[center[0] + c * x - s * y, center[1] + s * x + c * y] for x, y in
                     [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]])  # fmt: skip


def hessian_z(plane, xy):
    """Height of a plane from its Hessian form n . p + d = 0 (independent of a, b, c)."""
    n = plane.normal
    return -(plane.d + n[0] * xy[:, 0] + n[1] * xy[:, 1]) / n[2]


def oracle(scene: Scene, xy, tol=1e-9):
    """Top-most height (footprints closed, within tol) and distance to the nearest vertical wall."""
    points = shapely.points(xy)

    def covers(poly):
        return shapely.distance(poly, points) <= tol

    top = np.zeros(len(xy))
    outlines = []
    for plane in scene.planes[1:]:
        poly = shapely.Polygon(corners(plane.center, plane.size, plane.yaw))
        inside = covers(poly)
        top[inside] = np.maximum(top[inside], hessian_z(plane, xy[inside]))
        outlines.append(poly.exterior)
    box = scene.box
    outer = shapely.Polygon(corners(box.center, box.size, box.yaw))
    inner_size = (box.size[0] - 2 * box.wall, box.size[1] - 2 * box.wall)
    inner = shapely.Polygon(corners(box.center, inner_size, box.yaw))
    top[covers(outer)] = box.size[2]
    top[covers(inner) & (shapely.distance(inner.exterior, points) > tol)] = box.wall  # rim owns its inside
    outlines += [outer.exterior, inner.exterior]
    wall_distance = shapely.distance(shapely.MultiLineString(outlines), points)
    for obj in scene.objects:
        if obj.shape == "cube":
            poly = shapely.Polygon(corners(obj.center, obj.size, obj.yaw))
            inside, to_wall = covers(poly), shapely.distance(poly.exterior, points)
        else:
            r = np.hypot(xy[:, 0] - obj.center[0], xy[:, 1] - obj.center[1])
            inside, to_wall = r <= obj.size[0] / 2 + tol, np.abs(r - obj.size[0] / 2)
        top[inside] = obj.center[2] + obj.size[2] / 2
        wall_distance = np.minimum(wall_distance, to_wall)
    return top, wall_distance


def test_public_names_import():
    for name in baseplace.sim.__all__:
        assert getattr(baseplace.sim, name) is not None, name


def test_same_seed_same_scene_and_cloud():
    a, b = scene_of(seed=3), scene_of(seed=3)
    assert a == b
    small = SceneSettings(extent=(3.0, 3.0), n_planes=1)
    s = scene_of(small, seed=3)
    np.testing.assert_array_equal(
        s.sample_cloud(np.random.default_rng(1)), s.sample_cloud(np.random.default_rng(1))
    )
    assert scene_of(seed=4) != a


@pytest.mark.parametrize("size_class", sorted(SIZE_CLASSES))
@pytest.mark.parametrize("n_planes", [2, 4])
def test_planes_within_class_inside_scene_and_apart(size_class, n_planes):
    settings = SceneSettings(size_class=size_class, n_planes=n_planes)
    lo, hi = SIZE_CLASSES[size_class]
    for seed in range(3):
        scene = scene_of(settings, seed)
        planes = scene.planes[1:]
        assert [p.id for p in scene.planes] == list(range(n_planes + 1))
        assert scene.planes[0].kind == "floor" and scene.planes[0].normal.tolist() == [0.0, 0.0, 1.0]
        assert sorted(p.kind for p in planes).count("ramp") == n_planes // 2
        footprints = []
        for p in planes:
            assert all(lo <= side <= hi for side in p.size)
            tilt = math.degrees(p.tilt)
            assert settings.tilt_deg[0] - 1e-9 <= tilt <= settings.tilt_deg[1] + 1e-9
            xy = corners(p.center, p.size, p.yaw)
            z = p.a * xy[:, 0] + p.b * xy[:, 1] + p.c
            assert z.max() <= 0.8 + 1e-9 and z.min() >= -1e-9
            assert np.all(np.abs(xy) <= 5.0 - settings.clearance + 1e-9)
            footprints.append(shapely.Polygon(xy))
        footprints.append(shapely.Polygon(corners(scene.box.center, scene.box.size, scene.box.yaw)))
        for i, f in enumerate(footprints):
            for g in footprints[i + 1 :]:
                assert f.distance(g) >= settings.clearance - 1e-9
        inner = shapely.Polygon(scene.box.inner_polygon)
        assert 3 <= len(scene.objects) <= 6
        for obj in scene.objects:
            assert 0.04 <= min(obj.size) <= max(obj.size) <= 0.10
            assert obj.bottom == pytest.approx(scene.box.wall)
            assert inner.contains(shapely.Point(obj.center[:2]).buffer(obj.radius))


def test_hessian_form_matches_slopes(scene):
    xy = np.random.default_rng(0).uniform(-3, 3, (50, 2))
    for p in scene.planes:
        assert np.linalg.norm(p.normal) == pytest.approx(1.0) and p.normal[2] > 0
        np.testing.assert_allclose(hessian_z(p, xy), p.a * xy[:, 0] + p.b * xy[:, 1] + p.c, atol=1e-12)
        np.testing.assert_allclose(p.polygon, corners(p.center, p.size, p.yaw), atol=1e-12)


def test_ramps_touch_the_floor_along_an_edge_and_platforms_are_raised():
    settings = SceneSettings(size_class="medium", n_planes=4)
    for seed in range(4):
        for p in scene_of(settings, seed).planes[1:]:
            z = p.z(p.polygon)
            if p.kind == "ramp":
                low = np.flatnonzero(np.abs(z) < 1e-9)
                assert len(low) == 2 and (low[1] - low[0]) in (1, 3)  # two adjacent corners: an edge
                assert z.min() > -1e-9
            else:
                assert settings.platform_height[0] - 1e-9 <= z.min() <= settings.platform_height[1] + 1e-9


def test_exact_cloud_lies_on_the_surfaces_or_walls(scene):
    spacing = 0.025
    points = scene.sample_cloud(np.random.default_rng(5), spacing=spacing, sigma=0.0)
    assert points.dtype == np.float64 and points.shape[1] == 3
    top, wall_distance = oracle(scene, points[:, :2])
    on_top = np.abs(points[:, 2] - top) < 1e-9
    np.testing.assert_allclose(points[on_top, 2], scene.height(points[on_top, :2]), atol=1e-12)
    # Everything else is on a vertical wall, below the top.
    assert np.all(wall_distance[~on_top] < 1e-6)
    assert np.all(points[~on_top, 2] <= top[~on_top] + 1e-9)
    # Every plane and every wall is sampled.
    ids = scene.surface_id(points[on_top, :2])
    assert set(ids.tolist()) == {NONPLANAR, *range(len(scene.planes))}
    assert (~on_top).sum() > 1000
    # Jittered grid: about one top point per spacing^2.
    assert on_top.sum() == pytest.approx(36.0 / spacing**2, rel=0.01)


def test_noise_on_floor_has_sigma():
    scene = scene_of(SceneSettings(n_planes=1, extent=(4.0, 4.0), with_box=False), seed=2)
    points = scene.sample_cloud(np.random.default_rng(0), sigma=0.025)
    near_plane = shapely.Polygon(scene.planes[1].polygon).buffer(0.01)  # its walls lie on the outline
    on_floor = ~shapely.contains_xy(near_plane, points[:, 0], points[:, 1])
    residual = points[on_floor, 2] - 0.0
    assert len(residual) > 50_000
    assert residual.std() == pytest.approx(0.025, rel=0.02)
    assert abs(residual.mean()) < 0.001


def test_surface_id_resolves_to_the_top_piece(scene):
    for p in scene.planes[1:]:
        assert scene.surface_id([p.center]).tolist() == [p.id]
        assert scene.height([p.center])[0] == pytest.approx(p.a * p.center[0] + p.b * p.center[1] + p.c)
    box = scene.box
    assert scene.surface_id([box.center]).tolist() == [NONPLANAR]
    for obj in scene.objects:
        assert scene.surface_id([obj.center[:2]]).tolist() == [NONPLANAR]
        assert scene.height([obj.center[:2]])[0] == pytest.approx(obj.top)
    outside = np.array([[3.5, 0.0], [0.0, -3.01]])
    assert scene.surface_id(outside).tolist() == [OUTSIDE, OUTSIDE]
    assert np.isnan(scene.height(outside)).all()
    # Far from every footprint the floor is on top.
    xy = np.random.default_rng(1).uniform(-3, 3, (2000, 2))
    top, _ = oracle(scene, xy)
    covered = np.zeros(len(xy), dtype=bool)
    for p in scene.planes[1:]:
        covered |= p.contains(xy)
    covered |= box.contains(xy)
    assert np.all(scene.surface_id(xy)[~covered] == 0)
    np.testing.assert_allclose(scene.height(xy), top, atol=1e-12)


def test_truth_grid_uses_cell_centres(scene):
    origin, res, shape = (-3.0, -2.5), 0.05, (100, 120)
    ids, normals = truth_grid(scene, origin, res, shape)
    assert ids.shape == shape and normals.shape == (*shape, 3)
    i, j = 37, 91
    centre = [origin[0] + (j + 0.5) * res, origin[1] + (i + 0.5) * res]
    assert ids[i, j] == scene.surface_id([centre])[0]
    for k, p in enumerate(scene.planes):
        np.testing.assert_allclose(normals[ids == k], np.broadcast_to(p.normal, normals[ids == k].shape))
    assert np.isnan(normals[ids < 0]).all()
    assert (ids == NONPLANAR).any()
    plane = scene.planes[1]
    col, row = (np.asarray(plane.center) - origin) // res
    if 0 <= row < shape[0] and 0 <= col < shape[1]:
        assert ids[int(row), int(col)] == plane.id
    with pytest.raises(InputError):
        truth_grid(scene, origin, 0.0, shape)


def test_json_round_trip(scene, tmp_path):
    path = tmp_path / "truth.json"
    save_scene(scene, path)
    loaded = load_scene(path)
    assert loaded == scene
    np.testing.assert_array_equal(
        loaded.sample_cloud(np.random.default_rng(0)), scene.sample_cloud(np.random.default_rng(0))
    )
    doc = json.loads(path.read_text())
    for key in ("id", "normal", "d", "polygon", "a", "b", "c"):
        assert key in doc["planes"][1]
    assert doc["extent"] == [6.0, 6.0]
    assert len(doc["objects"]) == len(scene.objects)
    no_box = scene_of(SceneSettings(n_planes=0, extent=(3.0, 3.0), with_box=False))
    save_scene(no_box, path)
    assert load_scene(path) == no_box


def _drop(key):
    def edit(doc):
        del doc[key]

    return edit


@pytest.mark.parametrize(
    "edit",
    [
        _drop("planes"),
        _drop("settings"),
        lambda doc: doc.update(planes={"0": {}}),
        lambda doc: doc["planes"][1].pop("a"),
        lambda doc: doc["planes"][1].update(kind="cliff"),
        lambda doc: doc["planes"][1].update(center=[1.0]),
        lambda doc: doc["planes"][2].update(id=7),
        lambda doc: doc["settings"].update(size_class="huge"),
        lambda doc: doc["settings"].update(colour="red"),
        lambda doc: doc["box"].pop("size"),
        lambda doc: doc["objects"][0].update(shape="sphere"),
        lambda doc: doc.update(version=99),
    ],
)
def test_bad_truth_files_are_input_errors(scene, tmp_path, edit):
    path = tmp_path / "truth.json"
    save_scene(scene, path)
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError):
        load_scene(path)


def test_unreadable_truth_files(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        load_scene(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputError, match="JSON"):
        load_scene(tmp_path / "bad.json")


@pytest.mark.parametrize(
    "kwargs",
    [
        {"size_class": "huge"},
        {"n_planes": -1},
        {"extent": (10.0, 0.0)},
        {"extent": (10.0,)},
        {"tilt_deg": (15.0, 5.0)},
        {"sigma": -0.1},
        {"spacing": 0.0},
        {"object_height": (0.2, 0.1)},
        {"box_near": 0.05},
    ],
)
def test_bad_settings(kwargs):
    with pytest.raises(InputError):
        SceneSettings(**kwargs)


def test_bad_size_class_lists_the_choices():
    with pytest.raises(InputError, match="valid: large, medium, small"):
        SceneSettings(size_class="huge")


def test_impossible_requests():
    with pytest.raises(InputError, match="too small for 4 large planes"):
        scene_of(SceneSettings(size_class="large", n_planes=4, extent=(3.0, 3.0)))
    with pytest.raises(InputError, match="box"):
        scene_of(SceneSettings(n_planes=0, extent=(0.5, 0.5)))
    with pytest.raises(InputError, match="too steep"):
        scene_of(SceneSettings(size_class="large", tilt_deg=(40.0, 50.0)))


def test_object_heights_and_a_box_beside_the_planes():
    settings = SceneSettings(size_class="medium", n_planes=2, extent=(7.0, 7.0), box_near=0.3,
                             object_height=(0.15, 0.25))  # fmt: skip
    for k in range(5):
        scene = scene_of(settings, seed=k)
        assert all(0.15 <= o.size[2] <= 0.25 for o in scene.objects)
        box = shapely.Polygon(scene.box.polygon)
        gaps = [box.distance(shapely.Polygon(p.polygon)) for p in scene.planes[1:]]
        assert settings.clearance <= min(gaps) <= 0.3 + 1e-9
