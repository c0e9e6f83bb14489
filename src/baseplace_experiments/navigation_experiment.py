"""Navigation across planar regions on generated scenes: RRTConnect vs the region-graph planner.

For each scene class (seed 000's {small, medium, large} x {2, 4} planes), scenes are generated,
segmented from their noisy cloud, and start/goal pairs are drawn on the true surfaces: starts on
the floor, goals in turn on the floor, on a ramp and on a raised platform. Whether a goal can be
reached is decided on the generator's noise-free height field (:class:`TrueTraversability`), not
assumed from its kind: large planes can wall off part of the floor. Both planners of
:mod:`baseplace.navigation.planners` plan every pair; reported per planner: success rate over
reachable goals, paths found to unreachable goals (should be none), path length, planning time,
and, checked against the same height field, how many paths cross a height step above the
robot's limit or pass over the box or an object.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import ndimage

from baseplace.errors import BaseplaceError
from baseplace.navigation.navmap import NavigationMap, navigation_map
from baseplace.navigation.planners import PLANNERS, Path, plan_path
from baseplace.sim.scenes import Scene, SceneSettings, generate_scene
from baseplace.terrain.graph import GraphSettings
from baseplace.terrain.pipeline import terrain_from_points

CLASSES = tuple((size, n) for size in ("small", "medium", "large") for n in (2, 4))


def path_violations(scene: Scene, path: Path, max_step: float, step: float = 0.01) -> tuple[int, int]:
    """(height steps above ``max_step``, points off every true surface) along the path, every ``step`` m."""
    xy = path.dense(step)
    heights = scene.height(xy)
    ids = scene.surface_id(xy)
    return int((np.abs(np.diff(heights)) > max_step).sum()), int((ids < 0).sum())


class TrueTraversability:
    """Ground truth of where the base can drive, from the scene's noise-free height field.

    On a grid of ``resolution``, a *ledge* cell has a neighbour more than ``max_step`` higher or
    lower (or no surface); the base centre may stand where the nearest ledge cell's centre is more
    than ``radius - resolution`` away (its footprint disc touches no ledge, within the grid's
    tolerance: a step marks the cells on both of its sides, whose centres lie half a cell from it,
    and a pose lies anywhere in its cell). Two poses are connected when they lie in the same
    4-connected component of those cells. No segmentation and no planner is involved.
    """

    def __init__(self, scene: Scene, radius: float, max_step: float, resolution: float = 0.025) -> None:
        x0, y0, x1, y1 = scene.bounds
        self.origin, self.resolution = np.array([x0, y0]), resolution
        X, Y = np.meshgrid(np.arange(x0, x1, resolution), np.arange(y0, y1, resolution), indexing="ij")
        H = scene.height(np.c_[X.ravel(), Y.ravel()] + resolution / 2).reshape(X.shape)
        ledge = ~np.isfinite(H)
        for axis in (0, 1):
            step = np.abs(np.diff(H, axis=axis)) > max_step
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(None, -1), slice(1, None)
            ledge[tuple(lo)] |= step
            ledge[tuple(hi)] |= step
        clear = ndimage.distance_transform_edt(~ledge) * resolution > radius - resolution
        self.labels, _ = ndimage.label(clear)

    def _label(self, xy: ArrayLike) -> int:
        ij = np.floor((np.asarray(xy, dtype=float)[:2] - self.origin) / self.resolution).astype(int)
        if np.any(ij < 0) or np.any(ij >= self.labels.shape):
            return 0
        return int(self.labels[ij[0], ij[1]])

    def connected(self, start: ArrayLike, goal: ArrayLike) -> bool:
        """True if the base can drive from ``start`` to ``goal`` ((x, y, ...) each)."""
        a = self._label(start)
        return a > 0 and a == self._label(goal)


def _endpoint(scene: Scene, navmap: NavigationMap, rng: np.random.Generator, kind: str) -> np.ndarray | None:
    """A free pose on a true surface of ``kind`` (floor, ramp or platform) that the map calls a region."""
    x0, y0, x1, y1 = scene.bounds
    ids_of_kind = [p.id for p in scene.planes if p.kind == kind]
    if not ids_of_kind:
        return None
    for _ in range(200):
        xy = rng.uniform((x0, y0), (x1, y1), (64, 2))
        ok = navmap.free(xy) & (navmap.seg.region_at(xy) >= 0) & np.isin(scene.surface_id(xy), ids_of_kind)
        if ok.any():
            x, y = xy[np.flatnonzero(ok)[0]]
            return np.array([x, y, rng.uniform(-np.pi, np.pi)])
    return None


def run_navigation_experiment(
    scenes_per_class: int = 5,
    pairs_per_scene: int = 10,
    seed: int = 0,
    classes: tuple[tuple[str, int], ...] = CLASSES,
    radius: float = 0.3,
    max_step: float = GraphSettings().max_step,
    time_limit: float = 1.0,
    progress: Any = None,
) -> dict[str, Any]:
    """Per scene class and planner: success, length, time and violations (see module docstring)."""
    rows = []
    for class_index, (size_class, n_planes) in enumerate(classes):
        stats: dict[str, dict[str, Any]] = {
            p: {
                "ok": 0,
                "n": 0,
                "n_reachable": 0,
                "false_paths": 0,
                "length": [],
                "time_ms": [],
                "steps": 0,
                "off_surface": 0,
            }
            for p in PLANNERS
        }
        for k in range(scenes_per_class):
            rng = np.random.default_rng([seed, class_index, k])
            settings = SceneSettings(size_class=size_class, n_planes=n_planes, extent=(8.0, 8.0))
            scene = generate_scene(settings, rng)
            terrain = terrain_from_points(
                scene.sample_cloud(rng), graph_settings=GraphSettings(max_step=max_step)
            )
            navmap = navigation_map(terrain, radius)
            truth = TrueTraversability(scene, radius, max_step)
            for j in range(pairs_per_scene):
                kind = ("floor", "ramp", "platform")[j % 3]
                start, goal = _endpoint(scene, navmap, rng, "floor"), _endpoint(scene, navmap, rng, kind)
                if start is None or goal is None:
                    continue
                reachable = truth.connected(start, goal)
                for planner in PLANNERS:
                    st = stats[planner]
                    st["n"] += 1
                    st["n_reachable"] += reachable
                    try:
                        path = plan_path(navmap, start, goal, planner, time_limit, seed=j)
                    except BaseplaceError:
                        continue
                    if not reachable:  # no true path exists
                        st["false_paths"] += 1
                        continue
                    st["ok"] += 1
                    st["length"].append(path.length)
                    st["time_ms"].append(path.time_ms)
                    steps, off = path_violations(scene, path, max_step)
                    st["steps"] += int(steps > 0)
                    st["off_surface"] += int(off > 0)
            if progress is not None:
                progress(1)
        for planner, st in stats.items():
            rows.append({
                "scene": f"{size_class} {n_planes} planes", "planner": planner, "pairs": st["n"],
                "reachable_pairs": st["n_reachable"],
                "success_rate": round(100 * st["ok"] / st["n_reachable"], 1) if st["n_reachable"] else None,
                "paths_to_unreachable_goals": st["false_paths"],
                "mean_length_m": round(float(np.mean(st["length"])), 2) if st["length"] else None,
                "median_time_ms": round(float(np.median(st["time_ms"])), 1) if st["time_ms"] else None,
                "paths_crossing_a_step": st["steps"], "paths_off_surface": st["off_surface"],
            })  # fmt: skip
    return {
        "rows": rows, "seed": seed, "radius": radius, "max_step": max_step, "time_limit_s": time_limit,
        "settings": dataclasses.asdict(SceneSettings(extent=(8.0, 8.0))),
    }  # fmt: skip
