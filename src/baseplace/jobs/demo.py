"""The ``demo`` job: the main job on built-in defaults (`make demo` / `baseplace demo`).

TIAGo in a generated scene: a ramp leads from the floor up to a raised platform, and the grasp
target stands above the middle of the platform, beyond the arm's reach from the floor or the ramp.
The demo samples the scene's cloud (25 mm noise), segments it into planar regions, builds the
OSRM, finds a verified placement on the platform (IK + collision, seed 000 Algorithm 2), plans
the base path from the start on the floor up the ramp (seed 000 V), and writes ``demo.json``,
``demo.png`` and the viewer's ``demo_view.npz``. The default TIAGo map is built on the first run
and cached.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from baseplace.geometry.poses import BasePose, pose_json
from baseplace.jobs.inputs import DEFAULT_MAP_SAMPLES, Progress
from baseplace.jobs.report import DemoReport, NoResultError, RobotRef, path_json
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.sim.scenes import Scene

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


@dataclass
class DemoJob:
    """The inputs of :func:`demo_job`.

    Attributes:
        out: output directory (demo.json, demo.png, demo_view.npz).
        samples: samples of the cached default map.
        seed: random seed (scene noise, search, planner).
    """

    out: str = "out"
    samples: int = DEFAULT_MAP_SAMPLES
    seed: int = 0


def demo_job(job: DemoJob, progress: Progress | None = None) -> DemoReport:
    """Run the demo and write its JSON, PNG and viewer data into ``job.out``.

    Raises:
        InputError: an output directory that cannot be written.
        NoResultError: no verified placement, or no path to it (a regression: the scene is built
            so that both exist).
    """
    from baseplace.guards import check_output_dir, check_output_path

    out_dir = check_output_dir(job.out, "--out")  # outputs first: before the imports and any work
    json_path = check_output_path(out_dir / "demo.json", "--out", (".json",))
    from baseplace.files import atomic_write
    from baseplace.geometry.poses import parse_pose6
    from baseplace.navigation.navmap import navigation_map
    from baseplace.navigation.planners import plan_path
    from baseplace.placement.pipeline import PlaceSettings, place
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.cache import resolve_map
    from baseplace.robots.model import Robot
    from baseplace.terrain.pipeline import terrain_from_points
    from baseplace.terrain.polygons import footprint_outline
    from baseplace.viz.placement import plot_placement
    from baseplace.viz.view_data import save_view_data, view_data_from

    t0 = time.perf_counter()
    robot = Robot(DEFAULT_ROBOT)
    settings = BuildSettings(samples=job.samples, seed=job.seed)
    chosen = resolve_map(robot, None, None, progress, settings)
    rmap, map_path, built = chosen.rmap, chosen.cached_at, chosen.built
    t_map = time.perf_counter()
    rng = np.random.default_rng(job.seed)
    points = demo_scene().sample_cloud(rng)
    terrain = terrain_from_points(points)
    result = place(
        robot, rmap, points, parse_pose6(DEMO_TARGET), PlaceSettings(strategy="MR"), rng, terrain=terrain
    )
    report = DemoReport(
        robot=RobotRef.of(robot, rmap.info.arm), inputs={"out": job.out, "samples": job.samples, "seed": job.seed,
                                                         "target": DEMO_TARGET, "start": DEMO_START},
        failures=dict(result.failures), targets=[DEMO_TARGET],
        start=BasePose.from_xyyaw(*[float(v) for v in DEMO_START.split()]),
        map={"path": str(map_path), "built_now": built, "samples": rmap.info.samples,
             "cells_reached": rmap.n_reached, "build_time_s": round(rmap.info.build_time_s, 2)},
        regions=len(terrain.segmentation.regions),
    )  # fmt: skip
    if not result.placements:
        raise NoResultError(
            f"the demo found no verified placement (failures: {dict(result.failures)})", report
        )
    placement = result.placements[0]
    T = placement.T_world_base
    navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
    start = np.array([float(v) for v in DEMO_START.split()])
    path = plan_path(navmap, start, np.array([T[0, 3], T[1, 3], placement.yaw]), "rrt", seed=job.seed)
    png = out_dir / "demo.png"
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    plot_placement(result.osrm, [placement], outline, png,
                   f"TIAGo: placement on the platform (region {placement.region}) and the path up the ramp",
                   [path.poses])  # fmt: skip
    region = terrain.segmentation.regions[placement.region]
    report.placement = {
        **pose_json(T), "region": placement.region,
        "region_tilt_deg": round(float(np.degrees(region.tilt)), 2),
        "reachability": round(placement.reachability, 5),
        "joints": dict(zip(placement.joint_names, np.round(placement.joints[0], 6).tolist(), strict=True)),
    }  # fmt: skip
    report.path = {"planner": path.planner, "poses": path_json(path.poses), "length": round(path.length, 3),
                   "regions": [int(r) for r in path.regions]}  # fmt: skip
    save_view_data(out_dir / "demo_view.npz", view_data_from(terrain, result.osrm, points, robot.name))
    report.view_data = "demo_view.npz"  # for `baseplace view`, relative to the JSON
    report.outputs = {"png": str(png), "json": str(json_path), "view_data": str(out_dir / "demo_view.npz")}
    place_ms = {k: v for k, v in result.timings_ms.items() if k != "total"}
    report.timings_ms = {"map": (t_map - t0) * 1e3, **place_ms, "segmentation": terrain.timings_ms["total"],
                         "path": path.time_ms, "total": (time.perf_counter() - t0) * 1e3}  # fmt: skip
    with atomic_write(json_path, "demo result") as tmp:
        tmp.write_text(report.dumps(indent=2))
    return report
