"""Inputs the jobs share: robots, clouds (files, recordings, fused), occupancy grids, progress.

Every input may be given as a path (what a command line has) or as an already-loaded object (what
a service keeps warm between calls).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError

if TYPE_CHECKING:
    from pathlib import Path

    from baseplace.io.bag import BagScene
    from baseplace.robots.model import Robot
    from baseplace.terrain.io import Cloud
    from baseplace.world.occupancy import OccupancyGrid

Progress = Callable[[str, int, int], None]
"""A job's progress callback: ``progress(step, done, total)``; ``step`` names a long step."""


def step_progress(progress: Progress | None, step: str, total: int) -> Callable[[int], None] | None:
    """The one-argument callback (samples done) of one step, or None without ``progress``."""
    if progress is None:
        return None
    return lambda done: progress(step, done, total)


def load_robot(robot: Robot | str) -> Robot:
    """A loaded robot, or a built-in name / robot file loaded now."""
    from baseplace.robots.model import Robot

    return robot if isinstance(robot, Robot) else Robot(robot)


def motion_and_robustness(options: Mapping[str, Any]) -> tuple[Any, Any]:
    """The reaching-motion and robustness settings from the front ends' options, by their CLI names.

    ``options``: ``no_motion_check``, ``robustness_samples``, ``error_model``, ``sigma_xy`` [m],
    ``sigma_yaw_deg``, ``xy_tolerance`` [m], ``yaw_tolerance`` [rad], ``rank_by_robustness``,
    ``min_robustness`` and ``seed`` (the CLI's parsed arguments, or a service request).

    Returns:
        (MotionSettings, or None when the check is off; RobustnessSettings).
    """
    import math

    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings

    o = options
    motion = None if o["no_motion_check"] else MotionSettings()
    error = BaseErrorModel(o["error_model"], o["sigma_xy"], math.radians(o["sigma_yaw_deg"]),
                           o["xy_tolerance"], o["yaw_tolerance"])  # fmt: skip
    robustness = RobustnessSettings(o["robustness_samples"], error,
                                    "robustness" if o["rank_by_robustness"] else "reachability",
                                    o["min_robustness"], seed=o["seed"])  # fmt: skip
    return motion, robustness


def out_path(path: str | Path | None, what: str, suffixes: Sequence[str] | None) -> Path | None:
    """An output path checked before any work (:func:`baseplace.guards.check_output_path`), or None."""
    from baseplace.guards import check_output_path

    return None if path is None else check_output_path(path, what, suffixes)


PLOT_SUFFIXES = (".png", ".pdf", ".svg")
DEFAULT_MAP_SAMPLES = 200_000_000
"""``BuildSettings().samples`` (``reachability/build.py``), here so that ``--help`` and the jobs' inputs
do not import numba (a test keeps the two equal)."""


@dataclass(frozen=True)
class BagInput:
    """Inputs read from a ROS recording (rosbag2 directory, .db3, .mcap or ROS 1 .bag).

    Attributes:
        path: the recording.
        cloud_topics: sensor_msgs/PointCloud2 topics, posed by /tf at their stamps.
        map_topic: nav_msgs/OccupancyGrid topic (its last message), or None.
        world_frame: frame of the results.
        which: which messages of each cloud topic: last, first or all.
    """

    path: str
    cloud_topics: tuple[str, ...] = ()
    map_topic: str | None = None
    world_frame: str = "map"
    which: str = "last"


@dataclass
class CloudInput:
    """A scene cloud in the world frame (z up), from files, a recording or loaded points.

    Attributes:
        paths: cloud files (.pcd, .ply, .bt, .npy, .xyz).
        transforms: per file, a world_T_sensor file or the sensor-frame up vector "ux uy uz" (None:
            the cloud is z up already, checked).
        points: (N, 3) world points [m] or a :class:`~baseplace.terrain.io.Cloud`, already loaded
            (instead of files).
        bag: read the clouds from a recording.
        fuse: fuse the clouds into one 25 mm OctoMap by ray casting from each sensor origin (seed 000).
        fuse_miss: occupancy probability of a ray passing a voxel.
        fused_out: also write the fused OctoMap (.bt).
    """

    paths: Sequence[str] = ()
    transforms: Sequence[str | None] = ()
    points: Any = None
    bag: BagInput | None = None
    fuse: bool = False
    fuse_miss: float = 0.35
    fused_out: str | None = None
    _bag_scene: Any = field(default=None, repr=False, compare=False)

    @property
    def given(self) -> bool:
        """Whether any cloud was given."""
        return (
            bool(self.paths)
            or self.points is not None
            or (self.bag is not None and bool(self.bag.cloud_topics))
        )

    @property
    def source(self) -> str:
        """What the cloud came from, for results and messages."""
        if self.bag is not None:
            return self.bag.path
        return " ".join(self.paths) if self.paths else "points"

    def echo(self) -> dict[str, Any]:
        """The inputs as given, for a report."""
        out: dict[str, Any] = {"cloud": list(self.paths) or None, "transform": list(self.transforms) or None}
        if self.bag is not None:
            out["bag"] = {"path": self.bag.path, "cloud_topics": list(self.bag.cloud_topics),
                          "map_topic": self.bag.map_topic, "world_frame": self.bag.world_frame}  # fmt: skip
        if self.fuse:
            out["fuse"] = {"miss": self.fuse_miss, "out": self.fused_out}
        return out


def read_bag_input(bag: BagInput, holder: CloudInput | None = None) -> BagScene:
    """The recording's scene (read once per ``holder``)."""
    from baseplace.io.bag import read_bag

    if holder is not None and holder._bag_scene is not None:
        scene: BagScene = holder._bag_scene
        return scene
    scene = read_bag(bag.path, list(bag.cloud_topics), bag.map_topic, bag.world_frame, bag.which)
    if holder is not None:
        holder._bag_scene = scene
    return scene


def world_cloud(cloud: CloudInput) -> Cloud:
    """The cloud in the world frame: through its transform or tf, or checked z-up; fused if asked.

    Raises:
        InputError: no cloud given, one transform per cloud missing, or an unreadable file.
    """
    from baseplace.terrain.cache import check_up_direction_cached
    from baseplace.terrain.io import Cloud, load_cloud, load_transform

    fused_out = out_path(cloud.fused_out, "--fused-out", (".bt",))
    if isinstance(cloud.points, Cloud):  # checked once already (the service's scenes)
        return cloud.points
    if cloud.points is not None:
        return Cloud(np.asarray(cloud.points, dtype=float), source="points")
    if cloud.bag is not None:
        if not cloud.bag.cloud_topics:
            raise InputError("with --bag, give the cloud topic: --cloud-topic /camera/points")
        scene = read_bag_input(cloud.bag, cloud)
        source = f"{cloud.bag.path} {' '.join(cloud.bag.cloud_topics)}"
        if cloud.fuse:
            posed = [(c.world_points, c.T_world_sensor[:3, 3]) for c in scene.clouds]
            return _fused(posed, cloud.fuse_miss, fused_out, source)
        return Cloud(scene.world_points(), source=source)
    if not cloud.paths:
        raise InputError("give --cloud FILE or --bag FILE --cloud-topic TOPIC")
    paths, transforms = list(cloud.paths), list(cloud.transforms)
    if len(transforms) not in (0, len(paths)) and transforms != [None]:
        raise InputError(
            f"give one --transform per --cloud ({len(paths)} clouds, {len(transforms)} transforms)"
        )
    clouds, origins = [], []
    for k, path in enumerate(paths):
        loaded = load_cloud(path)
        spec = transforms[k] if len(transforms) == len(paths) else None  # none given: the cloud is z up
        origins.append(np.zeros(3))
        if spec is not None:
            T = load_transform(spec)
            loaded = loaded.transformed(T)
            origins[-1] = T[:3, 3]
        else:
            check_up_direction_cached(
                loaded.points, optical=loaded.width is not None and loaded.height not in (None, 1)
            )
        clouds.append(loaded)
    if cloud.fuse:
        posed = [(c.points, o) for c, o in zip(clouds, origins, strict=True)]
        return _fused(posed, cloud.fuse_miss, fused_out, " ".join(paths))
    if len(clouds) == 1:
        return clouds[0]
    return Cloud(np.vstack([c.points for c in clouds]), source=" ".join(paths))


def _fused(posed: list[tuple[np.ndarray, np.ndarray]], miss: float, save: Path | None, source: str) -> Cloud:
    """World clouds with their sensor origins fused into one OctoMap (seed 000); its occupied voxels."""
    from baseplace.terrain.fusion import FusionSettings, PosedCloud, fuse_clouds
    from baseplace.terrain.io import Cloud

    points = fuse_clouds([PosedCloud(p, o) for p, o in posed], FusionSettings(prob_miss=miss), save)
    return Cloud(points, source=f"OctoMap of {source}")


def occupancy_grid(
    grid: OccupancyGrid | str | None, bag: BagInput | None = None, holder: CloudInput | None = None
) -> OccupancyGrid | None:
    """The occupancy grid given (loaded, or a map_server YAML), else the recording's map topic, else None."""
    from baseplace.world.occupancy import OccupancyGrid, load_occupancy

    if isinstance(grid, OccupancyGrid):
        return grid
    if bag is not None and bag.map_topic is not None:
        return read_bag_input(bag, holder).grid
    return None if grid is None else load_occupancy(grid)


def parse_xyz(text: str | Sequence[float], what: str) -> np.ndarray:
    """A point "x y z" [m] (text or numbers), finite."""
    import math

    if isinstance(text, str):
        try:
            values = [float(v) for v in text.replace(",", " ").split()]
        except ValueError:
            raise InputError(f'{what} must be "x y z" in metres, got {text!r}') from None
    else:
        values = [float(v) for v in text]
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise InputError(f'{what} must be 3 finite numbers "x y z" [m], got {text!r}')
    return np.array(values)


def base_xyyaw(pose: str | Sequence[float], what: str) -> np.ndarray:
    """A base pose "x y yaw" [m, rad] (text or numbers) as (3,), the heading wrapped to (-pi, pi]."""
    from baseplace.geometry.poses import parse_base_pose

    text = pose if isinstance(pose, str) else " ".join(repr(float(v)) for v in pose)
    try:
        p = parse_base_pose(text)
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from None
    return np.array([p.x, p.y, p.yaw])


def write_mcap(path: Path, world_frame: str, stamp_ns: int, terrain: Any = None, **poses: Any) -> None:
    """Results as an MCAP recording (io.results): ``poses`` are ResultMessages fields; regions from ``terrain``."""
    from baseplace.io.results import ResultMessages, write_result_mcap

    regions = []
    if terrain is not None:
        for r in terrain.segmentation.regions:
            poly = terrain.polygons[r.id]
            rings = []
            for p in list(poly.geoms) if poly.geom_type == "MultiPolygon" else [poly]:
                for ring in [p.exterior, *p.interiors]:
                    xy = np.asarray(ring.coords)
                    if len(xy):
                        rings.append(np.c_[xy, r.height_at(xy)])
            regions.append((r.id, rings))
    write_result_mcap(path, ResultMessages(world_frame, stamp_ns, regions=regions, **poses))


def bag_stamp(cloud: CloudInput | None) -> int:
    """The latest stamp [ns] of the recording's clouds (0 without a recording)."""
    scene = None if cloud is None else cloud._bag_scene
    return max((c.stamp_ns for c in scene.clouds), default=0) if scene is not None else 0
