"""Small jobs about inputs: the built-in robots, a robot file's check, an occupancy grid, a test scene."""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.jobs.inputs import PLOT_SUFFIXES, check_robot_name, out_path
from baseplace.jobs.report import OccupancyReport, RobotCheckReport, RobotRef, RobotsReport, SceneReport


def robots_job() -> RobotsReport:
    """The built-in robots: URDF, base frame, arms (joints, TCP frame, approach axis), footprint."""
    from baseplace.robots.spec import BUILTIN_ROBOTS, builtin_spec

    rows: list[dict[str, Any]] = []
    for name in BUILTIN_ROBOTS:
        spec = builtin_spec(name)
        rows.append({
            "name": name, "urdf": str(spec.urdf), "base_frame": spec.base_frame, "default_arm": spec.default_arm,
            "arms": {a: {"joints": list(s.joints), "tcp_frame": s.tcp_frame, "approach": s.approach}
                     for a, s in spec.arms.items()},
            "footprint": {"radius": spec.footprint_radius} if spec.footprint_radius is not None
            else {"polygon": [list(p) for p in spec.footprint_polygon or ()]},
        })  # fmt: skip
    return RobotsReport(robots=rows)


@dataclass
class RobotCheckJob:
    """The inputs of :func:`robot_check_job`.

    Attributes:
        robot: robot file (.toml/.yaml) or built-in name.
        png: the picture of the robot (None: NAME_check.png in the current folder).
        pairs: list the active self-collision pairs in the text form.
    """

    robot: str
    png: str | None = None
    pairs: bool = False


def robot_check_job(job: RobotCheckJob) -> RobotCheckReport:
    """Load a robot file, describe it, render its collision geometry and warn where it looks wrong."""
    png = out_path(job.png, "--png", PLOT_SUFFIXES)  # checked before the robot loads
    check_robot_name(job.robot)
    from baseplace.robots.check import check_robot, collision_meshes
    from baseplace.robots.collision import load_collision_model
    from baseplace.robots.model import Robot
    from baseplace.viz.robot import plot_robot

    t0 = time.perf_counter()
    robot = Robot(job.robot)
    if png is None:  # the robot's name as a plain file name in this folder
        png = Path(re.sub(r"[^A-Za-z0-9_.-]", "_", robot.name).lstrip(".") + "_check.png")
    check = check_robot(robot)
    plot_robot(robot, collision_meshes(robot, load_collision_model(robot)), png)
    return RobotCheckReport(robot=RobotRef.of(robot), inputs={"robot": job.robot, "png": job.png, "pairs": job.pairs},
                            outputs={"png": str(png)}, check=check.to_dict(),
                            timings_ms={"total": (time.perf_counter() - t0) * 1e3})  # fmt: skip


def occupancy_job(path: str) -> OccupancyReport:
    """An occupancy grid in map_server format, as map_server reads it."""
    from baseplace.world.occupancy import load_occupancy

    t0 = time.perf_counter()
    grid = load_occupancy(path)
    return OccupancyReport(inputs={"map": path}, grid=grid.to_json(),
                           timings_ms={"total": (time.perf_counter() - t0) * 1e3})  # fmt: skip


@dataclass
class SceneJob:
    """The inputs of :func:`scene_job`: a generated scene (seed 000 VI) with ground truth.

    Attributes:
        out: the cloud file (.ply, .pcd or .npy).
        truth: the ground-truth JSON (None: next to ``out``).
        size_class: plane sides small 1-1.5, medium 1.5-2 or large 2-2.5 m.
        planes: number of inclined planes.
        sigma: height noise std [m].
        extent: scene side [m].
        box: add the box with objects.
        seed: random seed.
    """

    out: str
    truth: str | None = None
    size_class: str = "small"
    planes: int = 2
    sigma: float = 0.025
    extent: float = 10.0
    box: bool = True
    seed: int = 0


def scene_job(job: SceneJob) -> SceneReport:
    """Write a random scene's cloud and its ground truth."""
    out_path(job.out, "--out", (".ply", ".pcd", ".npy"))  # outputs first: before the imports and any work
    truth = job.truth or str(Path(job.out).with_suffix(".json"))
    out_path(truth, "--truth", (".json",))
    from baseplace.sim.scenes import SceneSettings, generate_scene, save_scene
    from baseplace.terrain.io import Cloud, save_cloud

    t0 = time.perf_counter()
    settings = SceneSettings(size_class=job.size_class, n_planes=job.planes, sigma=job.sigma,
                             extent=(job.extent, job.extent), with_box=job.box)  # fmt: skip
    rng = np.random.default_rng(job.seed)
    scene = generate_scene(settings, rng)
    points = scene.sample_cloud(rng)
    save_cloud(Cloud(points, source="baseplace scene generate"), job.out)
    save_scene(scene, truth)
    return SceneReport(
        inputs={"out": job.out, "truth": job.truth, "size_class": job.size_class, "planes": job.planes,
                "sigma": job.sigma, "extent": job.extent, "box": job.box, "seed": job.seed},
        outputs={"cloud": job.out, "truth": truth}, points=len(points), planes=len(scene.planes) - 1,
        seed=job.seed, size_class=job.size_class, timings_ms={"total": (time.perf_counter() - t0) * 1e3},
    )  # fmt: skip
