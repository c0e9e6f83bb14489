"""Warm queries do only per-query work (issue 25): what depends on the scene alone is made once.

Counted, not timed: the calls of the per-scene functions over two ``place`` queries that share a
scene's cache, as the service runs them (:func:`baseplace.jobs.place.place_job` with the scene's
:class:`~baseplace.placement.scene_cache.SceneCache`).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest

from baseplace.geometry.poses import matrix_to_rpy
from baseplace.jobs import inputs
from baseplace.jobs.place import PlaceJob, place_job
from baseplace.jobs.report import NoResultError
from baseplace.placement.pipeline import PlaceSettings
from baseplace.placement.robustness import RobustnessSettings
from baseplace.placement.scene_cache import SceneCache
from baseplace.world import grasped_object
from test_grasped_object import THROUGH_B, A, cloud, tray_scene


def _counted(monkeypatch: pytest.MonkeyPatch, module: Any, name: str, calls: Counter[str]) -> None:
    real = getattr(module, name)

    def counting(*args: Any, **kwargs: Any) -> Any:
        calls[name] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, counting)


def _query(tiago: Any, tiago_map: Any, points: np.ndarray, cache: SceneCache, seed: int) -> dict[str, Any]:
    target = " ".join(f"{v:.6f}" for v in (*THROUGH_B[:3, 3], *matrix_to_rpy(THROUGH_B[:3, :3])))
    settings = PlaceSettings(tries=5, motion=None, robustness=RobustnessSettings(samples=0))
    job = PlaceJob([target], tiago, cloud=inputs.CloudInput(points=points), map=tiago_map, settings=settings,
                   seed=seed, cache=cache)  # fmt: skip
    try:
        return place_job(job).to_json()
    except NoResultError as exc:  # found or not, the scene's work is the same
        return exc.report.to_json()


def test_two_queries_in_one_scene_find_the_grasped_object_and_the_bounds_once(tiago, tiago_map, monkeypatch):
    points = cloud(tray_scene(A))
    cache = SceneCache(points)
    calls: Counter[str] = Counter()
    _counted(monkeypatch, grasped_object, "find_grasped_object", calls)
    _counted(monkeypatch, inputs, "points_bounds", calls)
    first = _query(tiago, tiago_map, points, cache, 0)
    second = _query(tiago, tiago_map, points, cache, 1)
    assert first["object"]["allowed"] is not None  # the object was found, and is the same the second time
    assert second["object"] == first["object"]
    assert calls["find_grasped_object"] == 1, calls  # main: once per query (2)
    assert calls["points_bounds"] == 0, calls  # main: once per query (2); the cache holds the bounds
    lo, hi = cache.bounds  # oracle: the bounds of the points themselves
    assert np.array_equal(lo, points.min(axis=0)) and np.array_equal(hi, points.max(axis=0))


def test_a_grasp_point_elsewhere_seeks_its_own_object(tiago, monkeypatch):
    points = cloud(tray_scene(A))
    cache = SceneCache(points)
    calls: Counter[str] = Counter()
    _counted(monkeypatch, grasped_object, "find_grasped_object", calls)
    at_a = (THROUGH_B @ tiago.T_tcp_grasp(None))[:3, 3]
    found = cache.grasped_object(at_a)
    assert found is not None and cache.grasped_object(at_a) is found
    assert (
        cache.grasped_object(at_a + np.array([0.0, 0.0, 2.0])) is None
    )  # nothing up there, and not the kept object
    assert calls["find_grasped_object"] == 2


def test_a_cloud_without_finite_points_is_refused_as_before():
    from baseplace.errors import InputError

    cache = SceneCache(np.full((4, 3), np.nan))
    cache.prepare()  # nothing to prepare: the query says what is wrong
    with pytest.raises(InputError, match="the cloud holds no finite points"):
        cache.bounds  # noqa: B018
    with pytest.raises(InputError, match="the cloud holds no finite points"):
        inputs.points_bounds(np.full((4, 3), np.nan))


def test_a_navigate_query_in_a_cached_scene_reads_the_bounds_from_the_cache(tiago, monkeypatch):
    from baseplace.errors import InputError
    from baseplace.jobs import navigate
    from baseplace.jobs.navigate import NavigateJob, navigate_job

    points = cloud(tray_scene(A))
    cache = SceneCache(points)
    calls: Counter[str] = Counter()
    _counted(monkeypatch, navigate, "points_bounds", calls)
    far = f"{points[:, 0].max() + 5.0:.3f} 0 0"  # off the scene: refused on the bounds, before any planning
    for cached in (cache, None):
        job = NavigateJob("0 0 0", far, inputs.CloudInput(points=points), tiago, cache=cached)
        with pytest.raises(InputError, match="--goal"):
            navigate_job(job)
    assert calls["points_bounds"] == 1, calls  # main: 2 (once per query, cache or not)


def test_the_same_targets_again_find_their_osrm_made_and_the_same_placements(tiago, tiago_map, monkeypatch):
    from baseplace.placement import pipeline

    points = cloud(tray_scene(A))
    cache = SceneCache(points)
    calls: Counter[str] = Counter()
    _counted(monkeypatch, pipeline, "build_osrm", calls)
    first = _query(tiago, tiago_map, points, cache, 0)
    second = _query(tiago, tiago_map, points, cache, 1)
    assert calls["build_osrm"] == 1, calls  # main: once per query (2)
    # oracle: the same query without a scene cache builds its own OSRM and finds the same
    alone = _query(tiago, tiago_map, points, SceneCache(points), 1)
    for key in ("placements", "failures", "tries"):
        assert second[key] == alone[key], key
    assert first["targets"] == second["targets"]
    moved = THROUGH_B.copy()
    moved[0, 3] += 0.05  # other targets: an OSRM of their own
    target = " ".join(f"{v:.6f}" for v in (*moved[:3, 3], *matrix_to_rpy(moved[:3, :3])))
    settings = PlaceSettings(tries=5, motion=None, robustness=RobustnessSettings(samples=0))
    job = PlaceJob([target], tiago, cloud=inputs.CloudInput(points=points), map=tiago_map, settings=settings,
                   seed=0, cache=cache)  # fmt: skip
    try:
        place_job(job)
    except NoResultError:
        pass
    assert calls["build_osrm"] == 3, calls  # the oracle's own, and the moved targets'
