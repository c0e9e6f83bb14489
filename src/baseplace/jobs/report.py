"""The one result of every job: a typed, versioned report (docs/results.md).

Every ``baseplace COMMAND --json`` prints exactly one :class:`Report` as JSON, on success and on
failure alike; the service returns the same object. The envelope is the same for every kind:

* ``schema``: :data:`SCHEMA_VERSION`; ``kind``: one of :data:`KINDS`;
* ``robot``: one object (:class:`RobotRef`) or null where no robot takes part;
* ``inputs``: the inputs echoed, as the caller gave them (paths as text, poses as numbers);
* ``timings_ms``: step name -> milliseconds, always with ``total``;
* ``failures``: reason -> count (empty when nothing failed);
* ``outputs``: what -> path of each file written (png, mcap, map, json ...);
* ``error``: null, or the one-line message; ``exit_code``: 0, 2 (bad input) or 3 (nothing found).

Base poses appear in one shape everywhere (:func:`~baseplace.geometry.poses.pose_json`, a
:class:`~baseplace.geometry.poses.BasePose`'s ``to_json``): ``base_pose`` the 4x4
``T_world_base`` and ``x``, ``y``, ``z`` [m], ``yaw`` [rad] wrapped to (-pi, pi].
The fields of each kind follow the envelope at the top level (the subclasses below).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from baseplace.errors import NothingFoundError
from baseplace.geometry.poses import BasePose, matrix_to_rpy, pose_json, wrap_angle

if TYPE_CHECKING:
    from baseplace.navigation.path import Path
    from baseplace.placement.verified import Placement
    from baseplace.robots.model import Robot

SCHEMA_VERSION = "baseplace.result/1"
"""Version of the result contract; bumped when a field changes meaning or goes away."""

KINDS = (
    "place", "candidates", "surface_map", "surface_samples", "navigate", "reach", "segment", "demo",
    "build_map", "robots", "robot_check", "occupancy", "scene", "explain", "point",
)  # fmt: skip
"""Every kind of report."""


def _json(value: Any) -> Any:
    """Plain JSON data from dataclasses, numpy values and containers."""
    if isinstance(value, BasePose | RobotRef):
        return value.to_json()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json(value.tolist())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


@dataclass(frozen=True)
class RobotRef:
    """The robot of a result, the same object in every report.

    Attributes:
        name: robot name.
        urdf: its URDF file.
        base_frame: the base link; base poses are ``T_world_<base_frame>``.
        arm: the arm used (None where the job uses several or none).
        tcp_frames: arm name -> TCP frame, for every arm of the robot.
    """

    name: str
    urdf: str
    base_frame: str
    arm: str | None
    tcp_frames: dict[str, str]

    @classmethod
    def of(cls, robot: Robot, arm: str | None = None) -> RobotRef:
        """The reference of a loaded robot and the arm used."""
        spec = robot.spec
        return cls(robot.name, str(spec.urdf), spec.base_frame, arm,
                   {a: s.tcp_frame for a, s in spec.arms.items()})  # fmt: skip

    def to_json(self) -> dict[str, Any]:
        """``{"name", "urdf", "base_frame", "arm", "tcp_frames"}``."""
        return {"name": self.name, "urdf": self.urdf, "base_frame": self.base_frame, "arm": self.arm,
                "tcp_frames": dict(self.tcp_frames)}  # fmt: skip


def placement_row(p: Placement, motion_cost: float | None = None, path: Path | None = None) -> dict[str, Any]:
    """One verified placement, from any method, as a result row: the pose fields plus its checks.

    A ``place`` placement (no ``approach``): ``roll_pitch_yaw``, ``region``, ``reachability``,
    ``joints`` (one name -> value map per target). A seed-004 one: ``distance``, ``motion_cost``,
    ``method``, ``reachability``, ``grasp`` (its 4x4 TCP target) and ``joints`` (one map). Then
    ``motion`` and ``robustness`` where computed, and ``path`` (the base path to it) when given.
    """
    T = p.T_world_base
    a = p.approach
    if a is None:
        row = {
            **pose_json(T), "roll_pitch_yaw": [round(float(v), 5) for v in matrix_to_rpy(T[:3, :3])],
            "region": p.region, "reachability": round(p.reachability, 5),
            "joints": [dict(zip(p.joint_names, np.round(q, 6).tolist(), strict=True)) for q in p.joints],
        }  # fmt: skip
    else:
        assert p.targets is not None and motion_cost is not None, (
            "a seed-004 row needs its grasp and motion cost"
        )
        row = {
            **pose_json(T), "distance": round(a.distance, 4), "motion_cost": round(float(motion_cost), 4),
            "method": a.method, "reachability": round(p.reachability, 5), "grasp": p.targets[0].round(5).tolist(),
            "joints": dict(zip(p.joint_names, np.round(p.joints[0], 6).tolist(), strict=True)),
        }  # fmt: skip
    if p.motions is not None:
        row["motion"] = [{"path": np.round(m.path, 5).tolist(), "approach": np.round(m.approach, 5).tolist(),
                          "planned": m.planned} for m in p.motions]  # fmt: skip
    if p.robustness is not None:
        row["robustness"] = p.robustness.as_dict()
    if path is not None:
        row["path"] = {"poses": path_json(path.poses), "length": round(path.length, 3), "planner": path.planner,
                       "time_ms": round(path.time_ms, 1)}  # fmt: skip
    return row


def path_json(poses: Any) -> list[list[float]]:
    """A base path as (K, 3) rows x, y [m], yaw [rad, (-pi, pi]]."""
    rows = np.asarray(poses, dtype=float).reshape(len(poses), -1)
    return [[round(float(r[0]), 4), round(float(r[1]), 4), round(float(wrap_angle(r[2])), 4)] for r in rows]


@dataclass
class Report:
    """The envelope every kind shares; subclasses add the kind's own fields."""

    kind: ClassVar[str] = ""
    robot: RobotRef | None = None
    inputs: dict[str, Any] = field(default_factory=dict)
    timings_ms: dict[str, float] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)
    error: str | None = None
    exit_code: int = 0

    ENVELOPE: ClassVar[tuple[str, ...]] = (
        "robot", "inputs", "timings_ms", "failures", "outputs", "error", "exit_code",
    )  # fmt: skip

    def to_json(self) -> dict[str, Any]:
        """The report as one JSON object: ``schema``, ``kind``, the envelope, the kind's fields."""
        obj: dict[str, Any] = {"schema": SCHEMA_VERSION, "kind": self.kind}
        timings = {k: round(float(v), 2) for k, v in self.timings_ms.items()}
        timings.setdefault("total", round(sum(timings.values()), 2))
        obj.update({
            "robot": None if self.robot is None else self.robot.to_json(), "inputs": _json(self.inputs),
            "timings_ms": timings, "failures": {k: int(v) for k, v in self.failures.items()},
            "outputs": {k: str(v) for k, v in self.outputs.items()}, "error": self.error,
            "exit_code": self.exit_code,
        })  # fmt: skip
        for f in dataclasses.fields(self):
            if f.name not in self.ENVELOPE:
                obj[f.name] = _json(getattr(self, f.name))
        return obj

    def dumps(self, indent: int | None = None) -> str:
        """:meth:`to_json` as text."""
        return json.dumps(self.to_json(), indent=indent)

    def failed(self, message: str, exit_code: int) -> Report:
        """This report, marked failed with a one-line ``message`` and an exit code (2 or 3)."""
        self.error, self.exit_code = message, exit_code
        return self


@dataclass
class ErrorReport(Report):
    """A failure before a job could start (bad arguments); ``kind`` names the command's kind (None: no such command)."""

    kind_name: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The envelope with ``kind`` set to the command's kind."""
        obj = super().to_json()
        obj["kind"] = obj.pop("kind_name")
        return obj


class NoResultError(NothingFoundError):
    """A job ran and found nothing; ``report`` holds what it did find (failure counts, rejects)."""

    def __init__(self, message: str, report: Report) -> None:
        super().__init__(message)
        self.report = report.failed(message, self.exit_code)


@dataclass
class PlaceReport(Report):
    """``place``: verified base placements for TCP targets (seed 000 Algorithm 2).

    Attributes:
        targets: the TCP targets "x y z roll pitch yaw" [m, rad], world frame.
        strategy: candidate strategy (MR, TO, MRTO, orm, grid, random).
        seed: random seed.
        placements: best first; each a pose (:func:`~baseplace.geometry.poses.pose_json` fields) plus ``roll_pitch_yaw``,
            ``region``, ``reachability``, ``joints`` (one name -> value map per target), and
            optionally ``motion``, ``robustness`` and ``path`` (the base path from the start).
        tries: candidates checked.
        collisions: contact counts per robot link and obstacle.
        object: the grasped object: requested, found, allowed.
        floor: the added floor height [m] or None.
        regions: number of planar regions.
        clearance: the clearance kept from the scene near the grasped object: ``metres`` and how
            it was ``derived`` ("given", "3 sigma of the support plane's residuals (...)", "default: ...").
        motion_failures: of the candidates ``failures`` counts under "motion", how many per reason
            the reaching-motion check gave (:data:`~baseplace.placement.motion.MOTION_FAILURES`).
    """

    kind: ClassVar[str] = "place"
    targets: list[str] = field(default_factory=list)
    strategy: str = "MR"
    seed: int = 0
    placements: list[dict[str, Any]] = field(default_factory=list)
    tries: int = 0
    collisions: Any = None
    object: dict[str, Any] = field(default_factory=dict)
    floor: float | None = None
    regions: int = 0
    clearance: dict[str, Any] | None = None
    motion_failures: dict[str, int] = field(default_factory=dict)


@dataclass
class CandidatesReport(Report):
    """``candidates``: verified placement candidates around an object (seed 004).

    Attributes:
        method: radial or irm.
        object: grasp point (x, y, z) [m], world frame.
        robot_pose: the robot's current pose, or None.
        candidates: best first; each a pose plus ``distance``, ``motion_cost``, ``method``,
            ``reachability``, ``grasp`` (4x4 TCP pose), ``joints`` and optionally ``motion``, ``robustness``.
        rejected: positions rejected: ``x``, ``y``, ``reason``.
        path: the base path (K, 3) to the first reachable candidate, or None.
        object_shape: requested and allowed object shape.
        settings: the radial search's settings.
        clearance: as ``place``'s (:class:`PlaceReport`).
        motion_failures: of the positions rejected for "motion", how many per reason the
            reaching-motion check gave, as ``place``'s.
    """

    kind: ClassVar[str] = "candidates"
    method: str = "radial"
    object: list[float] = field(default_factory=list)
    robot_pose: BasePose | None = None
    candidates: list[dict[str, Any]] = field(default_factory=list)
    rejected: list[dict[str, Any]] = field(default_factory=list)
    path: list[list[float]] | None = None
    object_shape: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    clearance: dict[str, Any] | None = None
    motion_failures: dict[str, int] = field(default_factory=dict)


@dataclass
class SurfaceMapReport(Report):
    """``surface_map``: the inverse surface reachability map of a surface (seed 002).

    Attributes:
        summary: arms, combine, polygon, height, resolution, orientations, shape, origin,
            nonzero_poses, max, cone_rad, tcp_height (fields at the top level of the JSON).
        file_bytes: size of the written map.
    """

    kind: ClassVar[str] = "surface_map"
    summary: dict[str, Any] = field(default_factory=dict)
    file_bytes: int = 0

    def to_json(self) -> dict[str, Any]:
        """The summary's fields at the top level (as before the schema)."""
        obj = super().to_json()
        obj.update(obj.pop("summary"))
        return obj


@dataclass
class SurfaceSamplesReport(Report):
    """``surface_samples``: good, spread-out base poses from a surface map (seed 002 III-B).

    Attributes:
        map: the surface map file.
        occupancy: the operational area's grid, or None.
        poses: each a pose plus ``reachability`` (R_S) and ``score``.
    """

    kind: ClassVar[str] = "surface_samples"
    map: str = ""
    occupancy: str | None = None
    poses: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class NavigateReport(Report):
    """``navigate``: a base path across the planar regions of a scanned scene (seed 000 V).

    Attributes:
        planner: rrt or regions.
        start, goal: the base poses, headings wrapped.
        poses: the path (K, 3): x, y [m], yaw [rad, (-pi, pi]].
        length: path length [m].
        regions: region ids along the path.
        footprint_radius: the robot's footprint radius [m].
    """

    kind: ClassVar[str] = "navigate"
    planner: str = "rrt"
    start: BasePose | None = None
    goal: BasePose | None = None
    poses: list[list[float]] = field(default_factory=list)
    length: float = 0.0
    regions: list[int] = field(default_factory=list)
    footprint_radius: float = 0.0


@dataclass
class ReachReport(Report):
    """``reach``: inverse-reachability values of TCP targets from base poses.

    Attributes:
        values: one value in [0, 1] per (target, base) pair.
    """

    kind: ClassVar[str] = "reach"
    values: list[float] = field(default_factory=list)


@dataclass
class SegmentReport(Report):
    """``segment``: planar regions, polygons and region graph of a cloud (seed 000 IV).

    Attributes:
        regions, edges: :func:`baseplace.terrain.pipeline.terrain_json`'s rows.
        cloud: path and point count.
        algorithm: robust or baseline.
        resolution: height-map cell [m].
        height_map: origin, resolution, shape, known_cells.
        voxels: occupied voxels.
        non_planar_cells: known cells in no region.
    """

    kind: ClassVar[str] = "segment"
    regions: list[dict[str, Any]] = field(default_factory=list)
    edges: list[dict[str, Any]] = field(default_factory=list)
    cloud: dict[str, Any] = field(default_factory=dict)
    algorithm: str = "robust"
    resolution: float = 0.0
    height_map: dict[str, Any] = field(default_factory=dict)
    voxels: int = 0
    non_planar_cells: int = 0


@dataclass
class DemoReport(Report):
    """``demo``: TIAGo's verified placement on a platform and the path up its ramp.

    Attributes:
        targets: the TCP target.
        start: the start base pose.
        map: the cached map used: path, built_now, samples, cells_reached, build_time_s.
        regions: number of planar regions.
        placement: the placement (pose fields, region, region_tilt_deg, reachability, joints).
        path: planner, poses (K, 3), length, regions.
        view_data: the viewer's arrays, relative to the JSON.
    """

    kind: ClassVar[str] = "demo"
    targets: list[str] = field(default_factory=list)
    start: BasePose | None = None
    map: dict[str, Any] = field(default_factory=dict)
    regions: int = 0
    placement: dict[str, Any] = field(default_factory=dict)
    path: dict[str, Any] = field(default_factory=dict)
    view_data: str = ""


@dataclass
class BuildMapReport(Report):
    """``build_map``: a reachability map built by random joint sampling."""

    kind: ClassVar[str] = "build_map"
    samples: int = 0
    seed: int = 0
    cells_reached: int = 0
    build_time_s: float = 0.0
    samples_per_s: float = 0.0
    file_bytes: int = 0
    dropped_self_collision: int = 0
    support: dict[str, Any] | None = None
    quality: dict[str, Any] | None = None
    cached_at: str | None = None
    reused: bool = False


@dataclass
class RobotsReport(Report):
    """``robots``: the built-in robots."""

    kind: ClassVar[str] = "robots"
    robots: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class RobotCheckReport(Report):
    """``robot_check``: what a robot file describes and its warnings (fields at the top level)."""

    kind: ClassVar[str] = "robot_check"
    check: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The check's fields at the top level."""
        obj = super().to_json()
        obj.update({k: v for k, v in obj.pop("check").items() if k not in obj})
        return obj


@dataclass
class OccupancyReport(Report):
    """``occupancy``: an occupancy grid as map_server reads it (fields at the top level)."""

    kind: ClassVar[str] = "occupancy"
    grid: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The grid's fields at the top level."""
        obj = super().to_json()
        obj.update(obj.pop("grid"))
        return obj


@dataclass
class SceneReport(Report):
    """``scene``: a generated scene's cloud and ground truth."""

    kind: ClassVar[str] = "scene"
    points: int = 0
    planes: int = 0
    seed: int = 0
    size_class: str = "small"
