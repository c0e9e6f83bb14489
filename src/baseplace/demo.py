"""The main job on built-in defaults (`make demo` / `baseplace demo`).

TIAGo in a generated scene: a ramp leads from the floor up to a raised platform, and the grasp
target stands above the middle of the platform, beyond the arm's reach from the floor or the ramp.
The demo samples the scene's cloud (25 mm noise), segments it into planar regions, builds the
OSRM, finds a verified placement on the platform (IK + collision, seed 000 Algorithm 2), plans
the base path from the start on the floor up the ramp (seed 000 V), and writes ``out/demo.json``
and ``out/demo.png``. The default TIAGo map is built on the first run and cached.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import NothingFoundError
from baseplace.files import atomic_write
from baseplace.geometry.poses import parse_pose6
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.checkpoint import default_checkpoint_path
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import FORMAT_VERSION, load_map
from baseplace.robots.codegen import cache_dir, private_dir
from baseplace.robots.model import Robot

if TYPE_CHECKING:
    from baseplace.sim.scenes import Scene


def cached_map(
    robot: Robot,
    settings: BuildSettings,
    arm: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[ReachabilityMap, Path, bool]:
    """Load the map for these settings from the cache, building and saving it if absent.

    Returns:
        (map, path, built) where built tells whether it was built now.
    """
    arm_name = arm or robot.spec.default_arm
    key = (
        f"{robot.name}-{arm_name}-{robot.spec.urdf_sha256[:12]}-s{settings.samples}-seed{settings.seed}"
        f"-v{settings.voxel_size}-o{settings.orientation_resolution}-f{FORMAT_VERSION}"
    )
    # the file name is a hash: no name from a robot file ever becomes part of a path
    path = cache_dir().parent / "maps" / f"map-{hashlib.sha256(key.encode()).hexdigest()[:32]}.rmap"
    if path.is_file():
        return load_map(path, robot, arm_name), path, False
    private_dir(path.parent)
    # build_map locks the entry: a second process waits, then reuses the first one's map; and a
    # cache build is resumable too: a killed first run continues from its checkpoint
    rmap = build_map(robot, arm_name, settings, progress, default_checkpoint_path(path), save_to=path)
    return rmap, path, True


DEMO_TARGET = "1.6 0.0 1.05 0 1.5708 0"
"""Top-down grasp above the middle of the platform: 1.3 m from its edges, beyond TIAGo's reach."""
DEMO_START = "-3.5 0.0 0.0"


def demo_scene() -> Scene:
    """Floor; a 2.6 m x 2.6 m platform 0.3 m high; a 1.4 m wide ramp from the floor up to its edge."""
    from baseplace.sim.scenes import Plane, Scene, SceneSettings

    floor = Plane(0, "floor", (0.0, 0.0), (9.0, 6.0), 0.0, 0.0, 0.0, 0.0)
    platform = Plane(1, "platform", (1.6, 0.0), (2.6, 2.6), 0.0, 0.0, 0.0, 0.3)
    slope = 0.3 / 2.8  # 6.1 deg, from x = -2.5 on the floor to the platform's edge at x = 0.3
    ramp = Plane(2, "ramp", (-1.1, 0.0), (2.8, 1.4), 0.0, slope, 0.0, slope * 2.5)
    settings = SceneSettings(n_planes=2, extent=(9.0, 6.0), with_box=False)
    return Scene(settings, (floor, platform, ramp))


def run_demo(
    out_dir: Path,
    samples: int = 50_000_000,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run the demo and write its JSON and PNG into ``out_dir``; returns the JSON object.

    Raises:
        NothingFoundError: no verified placement, or no path to it (a regression: the scene is
            built so that both exist).
    """
    from baseplace.navigation.navmap import navigation_map
    from baseplace.navigation.planners import plan_path
    from baseplace.placement.pipeline import PlaceSettings, place
    from baseplace.terrain.pipeline import terrain_from_points
    from baseplace.terrain.polygons import footprint_outline
    from baseplace.viz.placement import plot_placement

    t0 = time.perf_counter()
    robot = Robot("tiago")
    rmap, map_path, built = cached_map(robot, BuildSettings(samples=samples, seed=seed), progress=progress)
    t_map = time.perf_counter() - t0
    scene = demo_scene()
    rng = np.random.default_rng(seed)
    points = scene.sample_cloud(rng)
    terrain = terrain_from_points(points)
    target = parse_pose6(DEMO_TARGET)
    result = place(robot, rmap, points, target, PlaceSettings(strategy="MR"), rng, terrain=terrain)
    if not result.placements:
        raise NothingFoundError(f"the demo found no verified placement (failures: {dict(result.failures)})")
    placement = result.placements[0]
    T = placement.T_world_base
    navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
    start = np.array([float(v) for v in DEMO_START.split()])
    path = plan_path(navmap, start, np.array([T[0, 3], T[1, 3], placement.yaw]), "rrt", seed=seed)
    out_dir.mkdir(parents=True, exist_ok=True)
    png = out_dir / "demo.png"
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    plot_placement(result.osrm, [placement], outline, png,
                   f"TIAGo: placement on the platform (region {placement.region}) and the path up the ramp",
                   [path.poses])  # fmt: skip
    region = terrain.segmentation.regions[placement.region]
    obj: dict[str, Any] = {
        "robot": robot.name,
        "target": DEMO_TARGET,
        "start": DEMO_START,
        "map": {"path": str(map_path), "built_now": built, "samples": rmap.info.samples,
                "cells_reached": rmap.n_reached, "build_time_s": round(rmap.info.build_time_s, 2)},
        "regions": len(terrain.segmentation.regions),
        "placement": {
            "base_pose": np.round(T, 6).tolist(), "x": round(float(T[0, 3]), 4), "y": round(float(T[1, 3]), 4),
            "z": round(float(T[2, 3]), 4), "yaw": round(placement.yaw, 4), "region": placement.region,
            "region_tilt_deg": round(float(np.degrees(region.tilt)), 2),
            "reachability": round(placement.reachability, 5),
            "joints": dict(zip(placement.joint_names, np.round(placement.joints[0], 6).tolist(), strict=True)),
        },
        "path": {"planner": path.planner, "poses": np.round(path.poses, 4).tolist(),
                 "length": round(path.length, 3), "regions": list(path.regions)},
        "failures": dict(result.failures),
        "timings_ms": {"map": round(t_map * 1e3, 1), **{k: round(v, 1) for k, v in result.timings_ms.items()},
                       "segmentation": round(terrain.timings_ms["total"], 1), "path": round(path.time_ms, 1),
                       "total": round((time.perf_counter() - t0) * 1e3, 1)},
        "png": str(png),
    }  # fmt: skip
    from baseplace.viz.viewer import save_view_data, view_data_from

    save_view_data(out_dir / "demo_view.npz", view_data_from(terrain, result.osrm, points, robot.name))
    obj["view_data"] = "demo_view.npz"  # for `baseplace view`, relative to the JSON
    with atomic_write(out_dir / "demo.json", "demo result") as tmp:
        tmp.write_text(json.dumps(obj, indent=2))
    return obj
