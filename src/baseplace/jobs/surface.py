"""The surface jobs: where to stand to work on a whole table or shelf (seed 002).

``surface_map_job`` builds the inverse surface reachability map of a polygonal surface from the
arms' cached reachability maps; ``surface_samples_job`` draws good, spread-out base poses from it
(seed 002 III-B).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.files import SURFACE_MAP_FILE, existing_file
from baseplace.jobs.inputs import (
    DEFAULT_MAP_SAMPLES,
    PLOT_SUFFIXES,
    Progress,
    check_robot_name,
    load_robot,
    occupancy_grid,
    out_path,
)
from baseplace.jobs.report import RobotRef, SurfaceMapReport, SurfaceSamplesReport
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.jobs.inputs import BagInput
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import OccupancyGrid

SURFACE_SUFFIXES = (".smap", ".h5", ".hdf5")


@dataclass
class SurfaceMapJob:
    """The inputs of :func:`surface_map_job`.

    Attributes:
        polygon: the surface outline "x1,y1;x2,y2;..." [m] or (K, 2) points.
        height: surface height above the floor [m].
        out: the surface map file (.smap, sparse HDF5).
        robot: built-in name, robot file or loaded Robot.
        arms: any (either arm), both (both arms) or one arm's name.
        resolution: grid spacing [m].
        orientations: base headings.
        samples: samples of the cached reachability maps, built once per arm.
        png: also plot R_S over the floor here.
        maps: loaded reachability maps, arm -> map, used instead of the cached ones (the service's
            warm maps); every arm of ``arms`` needs one.
    """

    polygon: Any
    height: float
    out: str
    robot: Robot | str = DEFAULT_ROBOT
    arms: str = "any"
    resolution: float = 0.05
    orientations: int = 16
    samples: int = DEFAULT_MAP_SAMPLES
    png: str | None = None
    maps: Mapping[str, ReachabilityMap] | None = field(default=None, repr=False, compare=False)

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {"polygon": self.polygon if isinstance(self.polygon, str) else np.asarray(self.polygon).tolist(),
                "height": self.height, "out": self.out, "robot": self.robot if isinstance(self.robot, str)
                else self.robot.name, "arms": self.arms, "resolution": self.resolution,
                "orientations": self.orientations, "samples": self.samples,
                **({} if self.maps is None else {"maps": "loaded"})}  # fmt: skip


def surface_arms(robot: Robot, arms: str) -> tuple[list[str], str]:
    """The arms of ``arms`` and how they combine: any/both over every arm, or one arm by name."""
    from baseplace.errors import unknown

    names = list(robot.spec.arms)
    if arms in ("any", "both"):
        if arms == "both" and len(names) < 2:
            raise InputError(
                f"--arms both needs two arms; {robot.name} has one ({names[0]}): use any or {names[0]}"
            )
        return names, arms
    if arms not in names:
        raise unknown("arm", arms, ["any", "both", *names], robot.name)
    return [arms], "any"


def surface_map_job(job: SurfaceMapJob, progress: Progress | None = None) -> SurfaceMapReport:
    """Build and save the inverse surface reachability map of ``job.polygon`` at ``job.height``.

    Raises:
        InputError: bad input (a malformed polygon, an unknown arm, an unwritable output, a grid
            over the memory cap).
    """
    out = out_path(job.out, "--out", SURFACE_SUFFIXES)  # outputs first: before the imports and any work
    png = out_path(job.png, "--png", PLOT_SUFFIXES)
    from baseplace.terrain.polygons import parse_polygon

    polygon = parse_polygon(job.polygon)  # before the maps' imports (a second)
    check_robot_name(job.robot)
    from baseplace.placement.surface_map import build_surface_map, check_surface_grid
    from baseplace.placement.surface_storage import save_surface_map
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.cache import resolve_map

    t0 = time.perf_counter()
    assert out is not None
    check_surface_grid(polygon, job.resolution, job.orientations)  # the polygon's box alone, before the maps
    robot = load_robot(job.robot)
    arms, combine = surface_arms(robot, job.arms)
    settings = BuildSettings(samples=job.samples)
    if job.maps is not None:
        missing = [arm for arm in arms if arm not in job.maps]
        if missing:
            raise InputError(f"no loaded map of arm(s) {', '.join(missing)}; loaded: {', '.join(job.maps)}")
        rmaps = {arm: job.maps[arm] for arm in arms}
    else:
        rmaps = {arm: resolve_map(robot, None, arm, progress, settings).rmap for arm in arms}
    for rmap in rmaps.values():
        _ = rmap.tables  # the dense lookup of the reachability map is built once, outside the timing
    t_maps = time.perf_counter()
    smap = build_surface_map(robot, rmaps, polygon, job.height, job.resolution, job.orientations, combine)
    t_build = time.perf_counter()
    size = save_surface_map(smap, out)
    summary = smap.summary()
    summary.pop("robot")  # the robot is the envelope's object
    report = SurfaceMapReport(robot=RobotRef.of(robot, arms[0] if len(arms) == 1 else None), inputs=job.echo(),
                              summary=summary, file_bytes=size, outputs={"surface_map": str(out)})  # fmt: skip
    if png is not None:
        from baseplace.viz.surface import plot_surface_map

        plot_surface_map(smap, png)
        report.outputs["png"] = str(png)
    report.timings_ms = {"maps": (t_maps - t0) * 1e3, "build": (t_build - t_maps) * 1e3,
                         "total": (time.perf_counter() - t0) * 1e3}  # fmt: skip
    return report


@dataclass
class SurfaceSamplesJob:
    """The inputs of :func:`surface_samples_job`.

    Attributes:
        map: the surface map file from :func:`surface_map_job`.
        n: poses to sample.
        occupancy: operational area (map_server YAML or loaded grid; free cells only), or None.
        bag: read the operational area from a recording's map topic instead.
        candidates: N: best of N valid candidates per pose.
        discount: spread consecutive poses (seed 002 eq. 3).
        robot: robot file or loaded Robot for custom robots (None: the map's built-in robot).
        seed: random seed.
    """

    map: str
    n: int = 5
    occupancy: OccupancyGrid | str | None = None
    bag: BagInput | None = None
    candidates: int = 40
    discount: bool = True
    robot: Robot | str | None = None
    seed: int = 0

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {"map": self.map, "n": self.n, "occupancy": self.occupancy if isinstance(self.occupancy, str | None)
                else "grid", "bag": None if self.bag is None else self.bag.path, "candidates": self.candidates,
                "discount": self.discount, "robot": self.robot if isinstance(self.robot, str | None)
                else self.robot.name, "seed": self.seed}  # fmt: skip


def surface_samples_job(job: SurfaceSamplesJob) -> SurfaceSamplesReport:
    """``job.n`` good, spread-out base poses from a surface map (headings in (-pi, pi]).

    Raises:
        InputError: bad input (n or candidates < 1, an unreadable map, a robot that does not match).
    """
    if job.n < 1 or job.candidates < 1:
        raise InputError(f"--n and --candidates must be >= 1, got {job.n} and {job.candidates}")
    existing_file(job.map, SURFACE_MAP_FILE)  # before the sampler's imports
    check_robot_name(job.robot)
    from baseplace.placement.surface_sampling import SurfaceSampler
    from baseplace.placement.surface_storage import load_surface_map

    t0 = time.perf_counter()
    smap = load_surface_map(job.map)
    robot = load_robot(job.robot or smap.robot)
    grid = occupancy_grid(job.occupancy, job.bag)
    t_load = time.perf_counter()
    sampler = SurfaceSampler(smap, robot, grid, job.candidates, discounted=job.discount)
    rng = np.random.default_rng(job.seed)
    samples = [sampler.sample(rng) for _ in range(job.n)]
    poses = [{**s.pose.to_json(), "reachability": round(s.reachability, 4),
              "score": round(s.score, 4)} for s in samples]  # fmt: skip
    occupancy = job.occupancy if isinstance(job.occupancy, str) else (job.bag.path if job.bag else None)
    arm = smap.arms[0] if len(smap.arms) == 1 else None
    return SurfaceSamplesReport(
        robot=RobotRef.of(robot, arm), inputs=job.echo(), map=str(job.map), occupancy=occupancy, poses=poses,
        timings_ms={"load": (t_load - t0) * 1e3, "sample": (time.perf_counter() - t_load) * 1e3},
    )  # fmt: skip
