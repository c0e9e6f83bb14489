"""Inputs the jobs share: robots, clouds (files, recordings, fused), occupancy grids, progress.

Every input may be given as a path (what a command line has) or as an already-loaded object (what
a service keeps warm between calls).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.files import MAP_FILE, existing_file
from baseplace.reachability.settings import DEFAULT_SAMPLES
from baseplace.status import Progress as Progress  # re-exported: jobs and the CLI take them from here
from baseplace.status import map_step as map_step
from baseplace.status import step_progress as step_progress

if TYPE_CHECKING:
    from pathlib import Path

    from baseplace.io.bag import BagScene
    from baseplace.reachability.cache import MapChoice
    from baseplace.robots.model import Arm, Robot
    from baseplace.terrain.io import Cloud
    from baseplace.world.occupancy import OccupancyGrid


def map_timing(chosen: MapChoice, seconds: float) -> dict[str, float]:
    """The map's step in ``timings_ms``, apart from the query's steps.

    ``map_build`` when the default map was built now (first run), else ``map`` (loading it).
    """
    return {"map_build" if chosen.built else "map": seconds * 1e3}


def map_output(chosen: MapChoice) -> dict[str, str]:
    """``outputs["map"]``: where the cache keeps the default map, when it was built (and stored) now."""
    path = chosen.cached_at
    return {"map": str(path)} if chosen.built and path is not None and path.is_file() else {}


def check_robot_name(robot: object, arm: str | None = None) -> None:
    """A robot given by name or file, and its arm, refused at once when they name none.

    The robot's spec alone is read (:func:`~baseplace.robots.spec.load_spec`: a built-in's, or
    the robot file's text), not its model: checked before the model's imports (pinocchio, coal),
    so that a mistyped ``--robot`` or ``--arm`` costs no seconds. A loaded robot passes, and its
    arm is checked where it is used.
    """
    if isinstance(robot, str):
        from baseplace.robots.spec import load_spec

        spec = load_spec(robot)
        if arm is not None:
            spec.arm(arm)


DEFAULT_MAP = "default"
"""``--map default``: the robot's cached default map (as ``reachability.cache.DEFAULT_MAP``, without numba)."""


def check_map_file(rmap: object) -> None:
    """A reachability map given as a file must exist (:data:`DEFAULT_MAP`, or a loaded map, passes)."""
    if isinstance(rmap, str) and rmap != DEFAULT_MAP:
        existing_file(rmap, MAP_FILE)


def load_robot(robot: Robot | str) -> Robot:
    """A loaded robot, or a built-in name / robot file loaded now."""
    from baseplace.robots.model import Robot

    return robot if isinstance(robot, Robot) else Robot(robot)


def motion_and_robustness(options: Mapping[str, Any]) -> tuple[Any, Any]:
    """The reaching-motion and robustness settings from the front ends' options, by their CLI names.

    ``options``: ``no_motion_check``, ``robustness_samples``, ``error_model``, ``sigma_xy`` [m],
    ``sigma_yaw_deg``, ``xy_tolerance`` [m], ``yaw_tolerance`` [rad; None: the default], ``rank_by_robustness``,
    ``min_robustness``, ``robustness_motion`` and ``seed`` (the CLI's parsed arguments, or a service request).

    Returns:
        (MotionSettings, or None when the check is off; RobustnessSettings).
    """
    import math

    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings

    o = options
    motion = None if o["no_motion_check"] else MotionSettings()
    yaw_tolerance = BaseErrorModel.yaw_tolerance if o["yaw_tolerance"] is None else o["yaw_tolerance"]
    error = BaseErrorModel(o["error_model"], o["sigma_xy"], math.radians(o["sigma_yaw_deg"]),
                           o["xy_tolerance"], yaw_tolerance)  # fmt: skip
    robustness = RobustnessSettings(o["robustness_samples"], error,
                                    "robustness" if o["rank_by_robustness"] else "reachability",
                                    o["min_robustness"], seed=o["seed"], motion=o["robustness_motion"])  # fmt: skip
    if robustness.motion and motion is None:  # before any work; the library checks it again
        raise InputError("--robustness-motion needs the motion check: drop --no-motion-check")
    return motion, robustness


def out_path(path: str | Path | None, what: str, suffixes: Sequence[str] | None) -> Path | None:
    """An output path checked before any work (:func:`baseplace.guards.check_output_path`), or None."""
    from baseplace.guards import check_output_path

    return None if path is None else check_output_path(path, what, suffixes)


PLOT_SUFFIXES = (".png", ".pdf", ".svg")
NO_CLOUD = "give --cloud FILE or --bag FILE --cloud-topic TOPIC"
"""The error for a job that needs a cloud and was given none."""
NO_BAG_TOPIC = "with --bag, give the cloud topic: --cloud-topic /camera/points"
"""The error for a recording given without the topic of its clouds."""
TARGET_AND_GRASP_POINT = (
    "give --target (the TCP pose) or --grasp-point (the point between the fingertips), not both"
)
"""The error for a job given both a TCP target and a grasp point."""
DEFAULT_MAP_SAMPLES = DEFAULT_SAMPLES
"""``BuildSettings().samples``, from the settings' module: ``--help`` and the jobs' inputs import no numba."""


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

    def check_given(self) -> None:
        """A cloud is given: files, points, or a recording with its cloud topic (nothing is read)."""
        if self.bag is not None and not self.bag.cloud_topics:
            raise InputError(NO_BAG_TOPIC)
        if not self.given:
            raise InputError(NO_CLOUD)

    def check_paths(self) -> None:
        """Each cloud file has a suffix a reader knows and exists (nothing is read)."""
        from baseplace.guards import check_input_file
        from baseplace.terrain.io import CLOUD_SUFFIXES

        for path in self.paths:
            check_input_file(path, "cloud", CLOUD_SUFFIXES)

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
            raise InputError(NO_BAG_TOPIC)
        scene = read_bag_input(cloud.bag, cloud)
        source = f"{cloud.bag.path} {' '.join(cloud.bag.cloud_topics)}"
        if cloud.fuse:
            posed = [(c.world_points, c.T_world_sensor[:3, 3]) for c in scene.clouds]
            return _fused(posed, cloud.fuse_miss, fused_out, source)
        return Cloud(scene.world_points(), source=source)
    if not cloud.paths:
        raise InputError(NO_CLOUD)
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
    if grid is None and (bag is None or bag.map_topic is None):
        return None  # before the import: a query on a cloud alone never loads the grid reader
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
    """A base pose "x y yaw" [m, rad] (text or numbers) as (3,), the heading wrapped to (-pi, pi].

    Raises:
        InputError: not 3 finite numbers, or a heading beyond +-2 pi (degrees, most likely).
    """
    from baseplace.geometry.poses import parse_base_pose

    text = pose if isinstance(pose, str) else " ".join(repr(float(v)) for v in pose)
    try:
        p = parse_base_pose(text)
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from None
    return np.array([p.x, p.y, p.yaw])


def target_pose(target: str | Sequence[float], what: str) -> np.ndarray:
    """A TCP pose "x y z roll pitch yaw" [m, rad] (text or 6 numbers) as (4, 4).

    Raises:
        InputError: not 6 finite numbers, or an angle out of range (degrees, most likely).
    """
    from baseplace.geometry.poses import RPY_LIMITS, check_angles, parse_pose6, pose_from_xyz_rpy

    try:
        if isinstance(target, str):
            return parse_pose6(target)
        values = np.asarray(target, dtype=float)
        if values.shape != (6,) or not np.isfinite(values).all():
            raise InputError(f"a target needs 6 finite numbers x y z roll pitch yaw, got {list(values)}")
        check_angles(values[3:], RPY_LIMITS)
    except InputError as exc:
        raise InputError(f"{what}: {exc}") from None
    return np.asarray(pose_from_xyz_rpy(values))


def check_object_yaw(spec: str, what: str) -> None:
    """Refuse a grasped-object spec ``"box CX CY CZ SX SY SZ YAW"`` whose yaw [rad] is beyond +-2 pi."""
    from baseplace.geometry.poses import YAW_LIMIT, check_angles

    words = spec.replace(",", " ").split()
    if len(words) == 8 and words[0].lower() == "box":
        try:
            yaw = float(words[7])
        except ValueError:
            return  # the spec's own parser names the problem
        try:
            check_angles([yaw], (YAW_LIMIT,))
        except InputError as exc:
            raise InputError(f"{what}: box {exc}") from None


CHECK_MARGIN = 0.25
"""Slack [m] of the scene checks below: a support's fitted height or a height-map cell may lie a
little beyond the points it came from."""


@dataclass(frozen=True)
class ReachBound:
    """Upper bounds on where an arm's TCP can be in its base frame, from the robot model alone [m].

    The chain is split at its first revolute joint, the mount (shoulder): the prismatic joints
    before it (a torso lift) move the mount along straight lines within their limits; after it,
    each joint offset can at most add its length (rotations keep lengths). True bounds by the
    triangle inequality, however loose; tests check them against pinocchio FK.

    Attributes:
        arm: the arm's name ("any arm" for the largest of several).
        mount_top: highest z of the mount over the lift joints' limits.
        mount_far: farthest the mount gets from the base origin.
        length: sum of |translation| of the joint placements from the mount to the TCP, plus the
            strokes of the prismatic joints after it.
    """

    arm: str
    mount_top: float
    mount_far: float
    length: float

    @property
    def height(self) -> float:
        """Highest the TCP gets above the base frame's origin."""
        return self.mount_top + self.length

    @property
    def radius(self) -> float:
        """Farthest the TCP gets from the base frame's origin."""
        return self.mount_far + self.length

    @staticmethod
    def of_arm(arm: Arm) -> ReachBound:
        """The bound of one arm's chain (:class:`~baseplace.robots.model.Arm`)."""
        import itertools

        from baseplace.robots.model import REVOLUTE

        n = arm.n_joints
        k = next((i for i in range(n) if arm.kinds[i] == REVOLUTE), n)
        T = np.eye(4)
        strokes = []  # each lift joint moves the mount by q * direction, q within its limits
        for i in range(k):
            T = T @ arm.placements[i]
            strokes.append((T[:3, :3] @ arm.axes[i], arm.lower[i], arm.upper[i]))
        mount = (T @ (arm.placements[k] if k < n else arm.T_last_tcp))[:3, 3]
        corners = np.array([mount + sum((q * d for (d, _, _), q in zip(strokes, qs, strict=True)), np.zeros(3))
                            for qs in itertools.product(*[(lo, hi) for _, lo, hi in strokes])])  # fmt: skip
        length = 0.0
        if k < n:
            length = float(np.linalg.norm(arm.placements[k + 1 :, :3, 3], axis=1).sum())
            length += float(np.linalg.norm(arm.T_last_tcp[:3, 3]))
            after = np.arange(n) > k
            prismatic = after & (arm.kinds != REVOLUTE)
            length += float(np.maximum(np.abs(arm.lower), np.abs(arm.upper))[prismatic].sum())
        # an affine map of a box: its largest height and norm lie at corners
        return ReachBound(
            arm.name, float(corners[:, 2].max()), float(np.linalg.norm(corners, axis=1).max()), length
        )

    @staticmethod
    def of_robot(robot: Robot, arm: str | None = None) -> ReachBound:
        """The bound of ``arm``, or the largest over every arm (None: the map's arm is not known yet)."""
        if arm is not None:
            return ReachBound.of_arm(robot.arm(arm))
        bounds = [ReachBound.of_arm(robot.arm(a)) for a in robot.spec.arms]
        if len(bounds) == 1:
            return bounds[0]
        return ReachBound("any arm", max(b.height for b in bounds), max(b.radius for b in bounds), 0.0)


def _box_text(lo: np.ndarray, hi: np.ndarray) -> str:
    axes = zip("xyz", lo, hi, strict=False)
    return ", ".join(f"{name} {a:.2f}..{b:.2f}" for name, a, b in axes)


def xyz_text(p: np.ndarray) -> str:
    """A point as "(x, y, z)" for messages."""
    return "(" + ", ".join(f"{v:.4g}" for v in p) + ")"


def points_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners (3,) of the finite points (N, 3) [m]."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if not len(p):
        raise InputError("the cloud holds no finite points")
    return p.min(axis=0), p.max(axis=0)


def grid_bounds(grid: OccupancyGrid) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners (3,) of an occupancy grid's area [m], floor at z = 0."""
    w, h = grid.width * grid.resolution, grid.height * grid.resolution
    c, s = np.cos(grid.origin[2]), np.sin(grid.origin[2])
    corners = (
        np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]]) @ np.array([[c, s], [-s, c]]) + grid.origin[:2]
    )
    return np.r_[corners.min(axis=0), 0.0], np.r_[corners.max(axis=0), 0.0]


def check_in_reach(
    points: np.ndarray,
    labels: Sequence[str],
    bounds: tuple[np.ndarray, np.ndarray],
    scene: str,
    bound: ReachBound,
    robot_name: str,
    extra: float = 0.0,
) -> None:
    """Refuse points the arm cannot reach from any support within ``bounds``, before any search.

    A base stands on a support of the scene, inside its bounding box ``bounds`` (lower, upper
    corners (3,) [m]); its TCP is then at most ``bound.radius`` from the box and ``bound.height``
    above its top (plus ``extra`` [m]: a grasp point ahead of the TCP).

    Args:
        points: (K, 3) targets [m], world frame.
        labels: a name per point for the message ("target 0", "--object").
        bounds: the scene's (lower, upper) corners.
        scene: the scene's name for the message ("the cloud's bounds").
        bound: the arm's :class:`ReachBound`.
        robot_name: the robot's name for the message.
        extra: how far [m] a point may lie beyond the TCP.

    Raises:
        InputError: the first point out of reach, with its distance.
    """
    lo, hi = bounds
    arm = f"{robot_name}'s {bound.arm if bound.arm == 'any arm' else repr(bound.arm) + ' arm'}"
    P = np.asarray(points, dtype=float).reshape(-1, 3)
    outside = np.linalg.norm(P - np.clip(P, lo, hi), axis=1)
    aside = np.linalg.norm(P[:, :2] - np.clip(P[:, :2], lo[:2], hi[:2]), axis=1)
    above = P[:, 2] - hi[2]
    radius, height = bound.radius + extra, bound.height + extra
    too_high = (aside <= radius + CHECK_MARGIN) & (above > height + CHECK_MARGIN)  # else: say how far aside
    bad = too_high | (outside > radius + CHECK_MARGIN)
    if not bad.any():
        return
    k = int(np.argmax(bad))
    if too_high[k]:
        raise InputError(
            f"{labels[k]} at {xyz_text(P[k])} m is {above[k] - height:.2f} m higher than {arm} reaches: "
            f"{height:.2f} m above its base, which stands at most at z {hi[2]:.2f} m (the top of {scene}); "
            "coordinates are in metres"
        )
    raise InputError(
        f"{labels[k]} at {xyz_text(P[k])} m is {outside[k]:.1f} m outside {scene} ({_box_text(lo, hi)}), "
        f"farther than {arm} reaches ({radius:.2f} m); coordinates are in metres"
    )


def check_on_scene(
    xy: np.ndarray, what: str, bounds: tuple[np.ndarray, np.ndarray], scene: str, margin: float
) -> None:
    """Refuse a base position (2,) [m] farther than ``margin`` [m] outside the scene's ``bounds``."""
    lo, hi = bounds[0][:2], bounds[1][:2]
    p = np.asarray(xy, dtype=float)[:2]
    outside = float(np.linalg.norm(p - np.clip(p, lo, hi)))
    if outside > margin:
        raise InputError(
            f"{what} {xyz_text(p)} m is {outside:.1f} m outside the scanned area ({scene} "
            f"{_box_text(lo, hi)}); coordinates are in metres"
        )


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
