"""What the 3D viewer draws, read from any result JSON of baseplace.

:func:`read_result` turns the ``--json`` object of ``place``, ``candidates``, ``surface-map``,
``surface-sample``, ``navigate``, ``segment``, ``point`` or ``demo`` into a :class:`ResultView`: the robot
poses to draw (with their joint values and reaching motions), candidates and rejected positions,
base paths, targets, regions, a ``point`` result's frame (hand, line, objects), and the input files the result names (cloud, occupancy grid,
surface map, view data). It reads the one result schema (``"schema"`` and ``"kind"``, poses as
4x4 plus x, y, z, yaw, inputs echoed under ``"inputs"``) and the per-command objects written
before it; nothing here draws or imports the viewer's libraries.

Every error is one line naming the file, the command that wrote it and what is missing.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose

FloatArray = NDArray[np.float64]

KINDS = ("place", "candidates", "surface_map", "surface_samples", "navigate", "segment", "point", "demo")
"""The result kinds the viewer draws."""
COMMANDS = {
    "place": "baseplace place",
    "candidates": "baseplace candidates",
    "surface_map": "baseplace surface-map",
    "surface_samples": "baseplace surface-sample",
    "navigate": "baseplace navigate",
    "segment": "baseplace segment",
    "point": "baseplace point",
    "demo": "baseplace demo",
}
"""The command that writes each kind."""
_ALIASES = {
    "surface_sample": "surface_samples",
    "surface_sampling": "surface_samples",
    "samples": "surface_samples",
    "navigation": "navigate",
    "path": "navigate",
    "segmentation": "segment",
    "placement": "place",
    "pointing": "point",
}
_NOT_SHOWN = ("reach", "build_map", "robots", "robot_check", "occupancy", "scene", "experiment")


@dataclass(frozen=True)
class Motion:
    """A reaching motion: the arm's joint waypoints from the start configuration to the grasp.

    Attributes:
        joint_names: (n,) the arm's joints, in the waypoints' column order.
        waypoints: (P, n) joint values [rad or m] from the start configuration through the
            pre-grasp to the grasp.
        pregrasp: index of the pre-grasp waypoint (where the straight approach begins).
    """

    joint_names: tuple[str, ...]
    waypoints: FloatArray
    pregrasp: int


@dataclass(frozen=True)
class RobotPose:
    """A robot to draw: its base pose, joint values and reaching motion.

    Attributes:
        T_world_base: (4, 4) pose of the robot's base frame in the world [m].
        joints: joint name -> value of its (final) configuration; other joints keep the robot's
            reference values.
        motion: its reaching motion, if the result has one.
        label: what it is ("placement 1", "candidate 2", ...).
    """

    T_world_base: FloatArray
    joints: dict[str, float]
    motion: Motion | None
    label: str


@dataclass(frozen=True)
class Region:
    """A planar region of a segmentation.

    Attributes:
        id: region id.
        plane: (4,) ``(nx, ny, nz, d)`` with ``n . p + d = 0`` [m].
        polygons: list of (exterior (N, 2), holes [(M, 2), ...]) outlines in the world xy [m].
    """

    id: int
    plane: FloatArray
    polygons: list[tuple[FloatArray, list[FloatArray]]]


@dataclass(frozen=True)
class Pointing:
    """A ``point`` result's frame: the hand, the finger's line and the objects, in the image and the world.

    Attributes:
        image: the RGB image the command read (``--rgb``), or None when it read a recording (``bag``).
        intrinsics: "fx fy cx cy" [px] or the CameraInfo YAML, as the command got them.
        transform: world_T_camera file or the camera-frame up vector, as the command got it.
        gesture: Scan, Point, Stop, none, or "no hand".
        landmarks: (21, 2) hand landmarks [px], or None without a hand.
        ray_2d: (2, 2) the finger's line from the fingertip to where it stops [px], or None.
        ray_3d: (2, 3) the same from the finger's depth [m, world], or None.
        image_boxes: (K, 2, 2) each object's image box ``[[u0, v0], [u1, v1]]`` [px].
        world_boxes: (K, 2, 3) each object's box ``[min, max]`` [m, world].
        selected: index of the object pointed at, or None.
        bag: the recording the command read the frame from (``--bag``), else None.
        bag_topics: its colour, depth and CameraInfo topics, world frame and frame selection
            (``read_rgbd``'s arguments after the path).
    """

    image: Path | None
    intrinsics: str | None
    transform: str | None
    gesture: str
    landmarks: FloatArray | None
    ray_2d: FloatArray | None
    ray_3d: FloatArray | None
    image_boxes: FloatArray
    world_boxes: FloatArray
    selected: int | None
    bag: Path | None = None
    bag_topics: tuple[str, ...] = ()


@dataclass(frozen=True)
class Inputs:
    """The input files a result names, resolved to paths that exist.

    Attributes:
        clouds: point clouds with their ``T_world_sensor`` transform spec (file or up vector) or None.
        occupancy: the occupancy grid's map_server YAML, if any.
        surface_map: the surface map file (``surface-map``'s output), if any.
        view_data: the demo's view data ``.npz``, if any.
        floor: height [m] of the floor plane added under a cloud that shows none (``--floor``).
    """

    clouds: list[tuple[Path, str | None]] = field(default_factory=list)
    occupancy: Path | None = None
    surface_map: Path | None = None
    view_data: Path | None = None
    floor: float | None = None


@dataclass(frozen=True)
class ResultView:
    """Everything the viewer draws from one result JSON.

    Attributes:
        kind: one of :data:`KINDS`.
        source: the JSON file.
        robot: robot name or robot-file path (what ``Robot()`` takes), if the result names one.
        arm: the arm that reaches, if named.
        inputs: the input files it names.
        robots: robot poses (placements, candidates best first, ...): the viewer draws the robot and
            its motion at one of them, the first unless picked.
        candidates: (K, 3) ranked base poses (x, y, yaw) drawn as arrows, best first.
        rejected: (R, 2) rejected base positions (x, y) [m].
        paths: base paths, each (N, 3) (x, y, yaw) [m, rad].
        targets: (4, 4) TCP target poses in the world.
        object_xyz: (3,) the object's position [m] (candidates), if any.
        regions: planar regions (segment).
        traversable: (E, 2, 3) region borders the base can cross, and ``blocked`` those it cannot.
        pointing: a ``point`` result's frame, else None.
        summary: one line about the result for the viewer's panel.
    """

    kind: str
    source: Path
    robot: str | None
    arm: str | None
    inputs: Inputs
    robots: list[RobotPose]
    candidates: FloatArray
    rejected: FloatArray
    paths: list[FloatArray]
    targets: list[FloatArray]
    object_xyz: FloatArray | None = None
    regions: list[Region] = field(default_factory=list)
    traversable: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    blocked: FloatArray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    pointing: Pointing | None = None
    summary: str = ""

    @property
    def command(self) -> str:
        """The command that wrote this kind of result."""
        return COMMANDS[self.kind]


class _Reader:
    """Field access with one-line errors that name the file and the command that wrote it."""

    def __init__(self, source: Path, kind: str) -> None:
        self.source = source
        self.kind = kind

    def fail(self, what: str) -> InputError:
        return InputError(f"{self.source} ({COMMANDS[self.kind]} result): {what}")

    def array(self, value: Any, shape: tuple[int, ...], what: str) -> FloatArray:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise self.fail(f"{what} is not numeric") from None
        if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape, strict=True)):
            raise self.fail(f"{what} must have shape {shape}, got {arr.shape}")
        if not np.isfinite(arr).all():
            raise self.fail(f"{what} has non-finite values")
        return arr

    def pose(self, obj: Any, what: str) -> FloatArray:
        """A (4, 4) pose: a 4x4 under a known key, else x, y, (z), yaw/theta."""
        if not isinstance(obj, dict):
            raise self.fail(f"{what} is not an object")
        for key in ("T_world_base", "base_pose", "pose", "matrix"):
            value = obj.get(key)
            if isinstance(value, dict):
                return self.pose(value, what)
            if value is not None:
                return self.array(value, (4, 4), f"{what} {key}")
        if "x" in obj and "y" in obj:
            yaw = obj.get("yaw", obj.get("theta", 0.0))
            x, y, z, yaw = self.array([obj["x"], obj["y"], obj.get("z", 0.0), yaw], (4,), what)
            return _planar(x, y, z, yaw)
        raise self.fail(f"{what} has no pose (base_pose as 4x4, or x, y, yaw)")

    def xyyaw(self, value: Any, what: str) -> FloatArray:
        """(N, 3) base poses from rows [x, y(, yaw)] or objects {x, y, yaw}."""
        if isinstance(value, dict):
            value = value.get("poses", value.get("waypoints"))
        if not isinstance(value, list):
            raise self.fail(f"{what} must be a list of poses")
        rows = []
        for i, p in enumerate(value):
            if isinstance(p, dict):
                T = self.pose(p, f"{what} pose {i}")
                rows.append(BasePose.batch_from_matrix(T)[0])
            else:
                row = self.array(p, (-1,), f"{what} pose {i}")
                if len(row) not in (2, 3):
                    raise self.fail(f"{what} pose {i} must be [x, y] or [x, y, yaw], got {len(row)} numbers")
                rows.append([row[0], row[1], row[2] if len(row) == 3 else 0.0])
        return np.array(rows, dtype=np.float64).reshape(-1, 3)

    def joints(self, value: Any, what: str) -> dict[str, float]:
        """Joint name -> value from {name: value}, {"names", "values"}, or a list of those (first)."""
        if isinstance(value, list):
            value = value[0] if value else {}
        if isinstance(value, dict) and isinstance(value.get("names"), list):
            names, values = value["names"], self.array(value.get("values"), (-1,), f"{what} values")
            if len(names) != len(values) or not all(isinstance(n, str) for n in names):
                raise self.fail(f"{what}: names and values must be as many")
            return dict(zip(names, values.tolist(), strict=True))
        if not isinstance(value, dict) or not all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
            for k, v in value.items()
        ):
            raise self.fail(f"{what} must be an object of joint name -> number")
        return {k: float(v) for k, v in value.items()}

    def motion(self, value: Any, names: Iterable[str], what: str) -> Motion | None:
        """The first target's reaching motion: {"path", "approach"} or {"waypoints"} joint rows."""
        if isinstance(value, list):
            value = value[0] if value else None
        if value is None:
            return None
        if not isinstance(value, dict):
            raise self.fail(f"{what} must be an object with joint waypoints")
        names = tuple(value.get("joint_names") or names)
        if "waypoints" in value:
            rows = self.array(value["waypoints"], (-1, -1), f"{what} waypoints")
            pregrasp = int(value.get("pregrasp", len(rows) - 1))
        else:
            path = self.array(value.get("path"), (-1, -1), f"{what} path")
            approach = (
                self.array(value.get("approach", []), (-1, path.shape[1]), f"{what} approach")
                if (value.get("approach"))
                else np.zeros((0, path.shape[1]))
            )
            rows = np.concatenate([path, approach[1:]]) if len(approach) else path
            pregrasp = len(path) - 1
        if not len(rows):
            return None
        if len(names) != rows.shape[1]:
            raise self.fail(f"{what}: {rows.shape[1]} joint columns but {len(names)} joint names")
        return Motion(names, rows, max(0, min(pregrasp, len(rows) - 1)))


def _planar(x: float, y: float, z: float, yaw: float) -> FloatArray:
    T = BasePose.batch_matrix([x, y, yaw])[0]
    T[2, 3] = z
    return T


def _kind(obj: dict[str, Any], path: Path) -> str:
    raw = obj.get("kind", obj.get("command"))
    if isinstance(raw, str):
        kind = raw.strip().lower().replace("-", "_").replace(" ", "_").removeprefix("baseplace_")
        kind = _ALIASES.get(kind, kind)
        if kind in KINDS:
            return kind
        if kind in _NOT_SHOWN:
            raise InputError(
                f"{path} is a `baseplace {kind.replace('_', '-')}` result, which has nothing to show in 3D; "
                f"the viewer shows the --json of: {', '.join(COMMANDS.values())}"
            )
        raise InputError(f"{path}: unknown result kind {raw!r}; the viewer shows: {', '.join(KINDS)}")
    # the per-command objects written before the one schema
    if "placement" in obj and "view_data" in obj:
        return "demo"
    if "placements" in obj:
        return "place"
    if "candidates" in obj:
        return "candidates"
    if "poses" in obj and "planner" in obj:
        return "navigate"
    if "poses" in obj and "map" in obj:
        return "surface_samples"
    if "nonzero_poses" in obj and "out" in obj:
        return "surface_map"
    if isinstance(obj.get("regions"), list) and "edges" in obj:
        return "segment"
    raise InputError(
        f"{path} is not a baseplace result (no 'kind'); write one with the --json of: "
        f"{', '.join(COMMANDS.values())} (e.g. `baseplace place ... --json > result.json`)"
    )


def _inputs(obj: dict[str, Any]) -> dict[str, Any]:
    """The echoed inputs, and the per-command top-level keys that named them before."""
    merged: dict[str, Any] = {}
    for key in ("cloud", "clouds", "transform", "transforms", "occupancy", "grid", "map", "surface_map",
                "view_data", "floor", "bag"):  # fmt: skip
        if key in obj:
            merged[key] = obj[key]
    echoed = obj.get("inputs")
    if isinstance(echoed, dict):
        merged.update({k: v for k, v in echoed.items() if v is not None})
    return merged


def _paths_of(value: Any) -> list[str]:
    """File names from a string, {"path": ...}, or a list of those; non-strings are dropped."""
    if isinstance(value, dict):
        value = value.get("path", value.get("paths", value.get("file")))
    if isinstance(value, str):
        return [value]
    if isinstance(value, list):
        return [p for v in value for p in _paths_of(v)]
    return []


_VIEWER_OPTION = {"cloud": "--cloud", "transform": "--transform", "occupancy grid": "--occupancy",
                  "surface map": "--surface-map", "robot file": "--robot"}  # fmt: skip


class _Resolver:
    """Input files: as written (relative to the working directory), else next to the JSON."""

    def __init__(self, source: Path, kind: str, given_here: Iterable[str] = ()) -> None:
        self.source = source
        self.kind = kind
        self.given_here = set(given_here)

    def __call__(self, name: str, what: str, option: str) -> Path:
        p = Path(name)
        for candidate in (p, self.source.parent / p) if not p.is_absolute() else (p,):
            if candidate.exists():
                return candidate
        mine = _VIEWER_OPTION.get(what)
        if name in self.given_here:
            raise InputError(f"the {what} {name} given to the viewer ({mine}) does not exist")
        hint = f"give it to the viewer with {mine} FILE" if mine else "rerun that command"
        raise InputError(
            f"{self.source} was written by `{COMMANDS[self.kind]}` from the {what} {name} ({option}), "
            f"which does not exist here; {hint}"
        )


def _is_vector(text: str, n: int = 3) -> bool:
    """``n`` numbers (an up vector "ux uy uz", intrinsics "fx fy cx cy") rather than a file's name."""
    try:
        return len([float(v) for v in text.replace(",", " ").split()]) == n
    except ValueError:
        return False


def _is_recording(name: str) -> bool:
    """A ROS recording: a bag or MCAP file, or a rosbag2 directory."""
    return name.endswith((".bag", ".mcap", ".db3")) or Path(name).is_dir()


def _resolve_inputs(obj: dict[str, Any], source: Path, kind: str, given_here: dict[str, Any]) -> Inputs:
    here = {k: v for k, v in given_here.items() if v is not None}
    echoed = _inputs(obj)
    for one, many in (("cloud", "clouds"), ("transform", "transforms")):
        if one in here:  # the viewer's --cloud/--transform replace the result's, in either spelling
            echoed.pop(many, None)
    given = {**echoed, **here}
    resolve = _Resolver(source, kind, [p for v in given_here.values() for p in _paths_of(v)])
    clouds_named = _paths_of(given.get("clouds", given.get("cloud")))
    recordings = [c for c in [*clouds_named, *_paths_of(given.get("bag"))] if _is_recording(c)]
    if recordings and kind != "point":  # point's frame is read back from its recording (_pointing)
        raise InputError(
            f"{source} was written by `{COMMANDS[kind]}` from the ROS recording {recordings[0]} (--bag); the "
            f"viewer reads clouds and grids from files: export them (.pcd, map_server .yaml) and rerun with --cloud"
        )
    transforms = given.get("transforms", given.get("transform"))
    transforms = transforms if isinstance(transforms, list) else [transforms] * len(clouds_named)
    clouds = []
    for name, spec in zip(clouds_named, transforms + [None] * len(clouds_named), strict=False):
        spec = spec if isinstance(spec, str) else None
        if spec is not None and not _is_vector(spec):
            spec = str(resolve(spec, "transform", "--transform"))
        clouds.append((resolve(name, "cloud", "--cloud"), spec))
    occupancy = _paths_of(given.get("occupancy", given.get("grid")))
    occupancy = [o for o in occupancy if o.endswith((".yaml", ".yml"))]
    smap = _paths_of(given.get("surface_map"))
    if kind == "surface_samples" and not smap:
        smap = _paths_of(given.get("map"))
    if kind == "surface_map" and not smap:  # the file it wrote: outputs.surface_map (schema 1), else out
        outputs: dict[str, Any] = obj["outputs"] if isinstance(obj.get("outputs"), dict) else {}
        smap = _paths_of(outputs.get("surface_map", obj.get("out")))
    view_data = _paths_of(given.get("view_data"))
    return Inputs(
        clouds=clouds,
        occupancy=resolve(occupancy[0], "occupancy grid", "--occupancy") if occupancy else None,
        surface_map=resolve(smap[0], "surface map", "--map" if kind == "surface_samples" else "--out")
        if smap else None,
        view_data=resolve(view_data[0], "view data", "view_data") if view_data else None,
        floor=float(given["floor"]) if isinstance(given.get("floor"), (int, float)) else None,
    )  # fmt: skip


def _robot(obj: dict[str, Any]) -> tuple[str | None, str | None]:
    """(robot name or robot file, arm): the robot file the command read (``--robot FILE``), else the name."""
    robot = obj.get("robot")
    arm = obj.get("arm")
    echoed = obj.get("inputs", {}).get("robot") if isinstance(obj.get("inputs"), dict) else None
    if isinstance(robot, dict):
        arm = robot.get("arm", arm)
        robot = next(
            (robot[k] for k in ("file", "path", "source", "name") if isinstance(robot.get(k), str)), None
        )
    if isinstance(echoed, str) and echoed:
        robot = echoed
    return (robot if isinstance(robot, str) and robot else None), (arm if isinstance(arm, str) else None)


def _targets(obj: dict[str, Any], r: _Reader) -> list[FloatArray]:
    from baseplace.geometry.poses import parse_pose6

    given = obj.get("targets", [obj["target"]] if "target" in obj else [])
    out = []
    for i, t in enumerate(given if isinstance(given, list) else []):
        if isinstance(t, str):
            try:
                out.append(parse_pose6(t))
            except InputError:
                raise r.fail(f"target {i} {t!r} is not 'x y z roll pitch yaw'") from None
        elif isinstance(t, (dict, list)):
            out.append(r.pose(t, f"target {i}") if isinstance(t, dict) else r.array(t, (4, 4), f"target {i}"))
    return out


def _robot_pose(p: dict[str, Any], r: _Reader, what: str, arm_joints: tuple[str, ...]) -> RobotPose:
    T = r.pose(p, what)
    joints = r.joints(p.get("joints", {}), f"{what} joints")
    names = tuple(joints) or arm_joints
    motion = r.motion(p.get("motion"), names, f"{what} motion")
    return RobotPose(T, joints, motion, what)


DEFAULT_RESULT = Path("out") / "demo.json"
"""The result the viewer shows when given none: the demo's."""


def result_file(path: str | Path | None) -> Path:
    """The result file to view (:data:`DEFAULT_RESULT` for None), which must exist.

    Checked before the viewer's libraries are imported, so that a mistyped name is refused at once.

    Raises:
        InputError: the file does not exist, with how to write one.
    """
    if path is None:
        if not DEFAULT_RESULT.is_file():
            raise InputError(
                f"result {DEFAULT_RESULT} does not exist; run `baseplace demo` first, or give a result JSON"
            )
        return DEFAULT_RESULT
    path = Path(path)
    if not path.is_file():
        raise InputError(f"result {path} does not exist; write one with a command's --json (e.g. `baseplace "
                         f"place ... --json > {path.name}`) or run `baseplace demo`")  # fmt: skip
    return path


def read_result(
    path: str | Path, arm_joints: tuple[str, ...] = (), given: dict[str, Any] | None = None
) -> ResultView:
    """Parse what the viewer draws from a result JSON and resolve the inputs it names.

    Args:
        path: the result JSON (the ``--json`` object of a command, or the demo's ``out/demo.json``).
        arm_joints: the arm's joint names, for motions whose joints the result does not name.
        given: input files given to the viewer, in place of those the result names (keys
            ``cloud`` (list of paths), ``transform`` (list), ``floor``, ``occupancy``, ``surface_map``,
            ``robot``; None values are ignored): for a result that names none, or whose files moved.

    Raises:
        InputError: the file is missing, not a result, of a kind with nothing to draw, malformed,
            or names an input file that does not exist.
    """
    path = result_file(path)
    try:
        obj = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read result {path}: {exc}") from None
    if not isinstance(obj, dict):
        raise InputError(
            f"{path} is not a baseplace result: expected a JSON object, got {type(obj).__name__}"
        )
    kind = _kind(obj, path)
    r = _Reader(path, kind)
    error = obj.get("error")
    if isinstance(error, dict):
        error = error.get("message")
    note = f"{COMMANDS[kind]} failed: {error}" if isinstance(error, str) and error else ""
    robot, arm = _robot(obj)
    if given and isinstance(given.get("robot"), str):
        robot = given["robot"]
    if robot is not None and (Path(robot).suffix or "/" in robot):  # a robot file, not a built-in name
        robot = str(_Resolver(path, kind)(robot, "robot file", "--robot"))
    inputs = _resolve_inputs(obj, path, kind, {k: v for k, v in (given or {}).items() if k != "robot"})
    robots: list[RobotPose] = []
    candidates = np.zeros((0, 3))
    rejected = np.zeros((0, 2))
    paths: list[FloatArray] = []
    targets = _targets(obj, r)
    object_xyz = None
    regions: list[Region] = []
    traversable = blocked = np.zeros((0, 2, 3))
    pointing = None

    if kind in ("place", "demo"):
        placements = obj.get(
            "placements", [obj["placement"]] if isinstance(obj.get("placement"), dict) else []
        )
        if not isinstance(placements, list) or not all(isinstance(p, dict) for p in placements):
            raise r.fail("placements must be a list of objects")
        for i, p in enumerate(placements):
            robots.append(_robot_pose(p, r, f"placement {i + 1}", arm_joints))
            if p.get("path") is not None:
                paths.append(r.xyyaw(p["path"], f"placement {i + 1} path"))
        if obj.get("path") is not None:
            paths.append(r.xyyaw(obj["path"], "path"))
        if inputs.view_data is None and not inputs.clouds and not inputs.occupancy:
            raise r.fail(
                "names no cloud or occupancy grid; give the cloud with --cloud FILE (and --transform, --floor as the command got them)"
            )
        note = note or f"{len(robots)} placement(s)"
    elif kind in ("candidates", "point"):
        rows = obj.get("candidates") or []
        if not isinstance(rows, list) or not all(isinstance(c, dict) for c in rows):
            raise r.fail("candidates must be a list of objects")
        robots += [_robot_pose(c, r, f"candidate {i + 1}", arm_joints) for i, c in enumerate(rows)]
        poses = [r.pose(c, f"candidate {i + 1}") for i, c in enumerate(rows)]
        candidates = BasePose.batch_from_matrix(poses)
        rej = obj.get("rejected", [])
        if isinstance(rej, list) and rej:
            rejected = np.array(
                [[q.get("x"), q.get("y")] if isinstance(q, dict) else q[:2] for q in rej], dtype=float
            )
            rejected = r.array(rejected, (-1, 2), "rejected")
        if obj.get("path") is not None:
            paths.append(r.xyyaw(obj["path"], "path"))
        o = obj.get("object")
        if isinstance(o, dict):
            o = o.get("position", o.get("xyz"))
        if o is not None:
            object_xyz = r.array(o, (3,), "object")
        start = obj.get("robot_pose", obj.get("start"))
        if start is not None:
            s = r.xyyaw([start], "robot_pose")[0]
            if not paths:
                paths.append(s[None])
        if inputs.occupancy is None and (kind == "candidates" or rows):
            raise r.fail("names no occupancy grid; give it with --occupancy MAP.yaml")
        note = note or f"{len(rows)} candidate(s), {len(rejected)} rejected"
        if kind == "point":
            pointing = _pointing(obj, r, path)
            note = (
                f"gesture {pointing.gesture}, {len(pointing.world_boxes)} object(s), "
                + (
                    "none selected"
                    if pointing.selected is None
                    else f"object {pointing.selected + 1} selected"
                )
                + (f"; {note}" if rows or error else "")
            )
    elif kind == "navigate":
        paths.append(r.xyyaw(obj.get("poses", obj.get("path")), "path"))
        if len(paths[0]):
            x, y, yaw = paths[0][-1]
            robots.append(RobotPose(_planar(x, y, 0.0, yaw), {}, None, "goal"))
        if not inputs.clouds and inputs.occupancy is None:
            raise r.fail("names no cloud; give it with --cloud FILE (and --transform as the command got it)")
        length = obj.get("length")
        if isinstance(obj.get("path"), dict):
            length = obj["path"].get("length", length)
        note = note or (f"path of {length:.2f} m" if isinstance(length, (int, float)) else "path")
    elif kind in ("surface_samples", "surface_map"):
        if inputs.surface_map is None:
            raise r.fail("names no surface map file; give it with --surface-map FILE")
        rows = obj.get("poses", obj.get("samples", []))
        if kind == "surface_samples":
            if not isinstance(rows, list) or not all(isinstance(c, dict) for c in rows):
                raise r.fail("poses must be a list of objects")
            poses = [r.pose(c, f"sample {i + 1}") for i, c in enumerate(rows)]
            candidates = BasePose.batch_from_matrix(poses)
            if poses:
                best = int(np.argmax([float(c.get("score", 0.0)) for c in rows]))
                robots.append(RobotPose(poses[best], {}, None, f"sample {best + 1}"))
            note = note or f"{len(rows)} sampled base pose(s)"
        else:
            note = note or "surface map"
    elif kind == "segment":
        regions, traversable, blocked = _regions(obj, r)
        if not inputs.clouds:
            raise r.fail("names no cloud; give it with --cloud FILE")
        note = note or f"{len(regions)} planar region(s)"
    return ResultView(
        kind=kind, source=path, robot=robot, arm=arm, inputs=inputs, robots=robots, candidates=candidates,
        rejected=rejected, paths=paths, targets=targets, object_xyz=object_xyz, regions=regions,
        traversable=traversable, blocked=blocked, pointing=pointing, summary=note,
    )  # fmt: skip


def _pointing(obj: dict[str, Any], r: _Reader, source: Path) -> Pointing:
    """A ``point`` result's frame: its image (found as written or next to the JSON) and what was found in it."""
    echoed: dict[str, Any] = obj["inputs"] if isinstance(obj.get("inputs"), dict) else {}
    rgb, intrinsics = echoed.get("rgb"), echoed.get("intrinsics")
    bag, topics = None, ()
    recording = echoed.get("bag")
    if isinstance(recording, dict) and isinstance(recording.get("path"), str):
        keys = ("rgb_topic", "depth_topic", "camera_info_topic", "world_frame", "frame")
        if not all(isinstance(recording.get(k), str) for k in keys):
            raise r.fail(f"inputs.bag must name its {', '.join(keys)}")
        bag = _Resolver(source, "point")(recording["path"], "recording", "--bag")
        topics = tuple(recording[k] for k in keys)
    elif not isinstance(rgb, str) or not isinstance(intrinsics, str):
        raise r.fail(
            "names no image and intrinsics (inputs.rgb, inputs.intrinsics); rerun it with this version"
        )
    transform = echoed.get("transform")
    if isinstance(transform, str) and not _is_vector(transform):
        transform = str(_Resolver(source, "point")(transform, "transform", "--transform"))
    if isinstance(intrinsics, str) and not _is_vector(intrinsics, 4):
        intrinsics = str(_Resolver(source, "point")(intrinsics, "intrinsics", "--intrinsics"))
    objects = obj.get("objects") or []
    if not isinstance(objects, list) or not all(isinstance(o, dict) for o in objects):
        raise r.fail("objects must be a list of objects")
    gesture = obj.get("gesture")
    selected = obj.get("selected")
    if selected is not None and not (isinstance(selected, int) and 0 <= selected < len(objects)):
        raise r.fail(f"selected must be an index into the {len(objects)} objects, got {selected!r}")

    def ray(value: Any, dim: int, what: str) -> FloatArray | None:
        if not isinstance(value, dict):
            return None
        ends = r.array([value.get("origin"), value.get("end")], (2, dim), what)
        if value.get("length") is None and value.get("direction") is not None:  # met no box: 1 m of it
            ends[1] = ends[0] + r.array(value["direction"], (dim,), f"{what} direction")
        return ends

    landmarks = obj.get("landmarks")
    return Pointing(
        image=_Resolver(source, "point")(rgb, "image", "--rgb") if bag is None and isinstance(rgb, str) else None,
        intrinsics=intrinsics if bag is None and isinstance(intrinsics, str) else None,
        transform=transform if isinstance(transform, str) else None,
        gesture=str(gesture.get("name")) if isinstance(gesture, dict) else "no hand",
        landmarks=None if landmarks is None else r.array(landmarks, (21, 2), "landmarks"),
        ray_2d=ray(obj.get("ray_2d"), 2, "ray_2d"),
        ray_3d=ray(obj.get("ray_3d"), 3, "ray_3d"),
        image_boxes=r.array([o.get("image_box") for o in objects], (len(objects), 2, 2), "objects' image_box")
        if objects else np.zeros((0, 2, 2)),
        world_boxes=r.array([o.get("box_world") for o in objects], (len(objects), 2, 3), "objects' box_world")
        if objects else np.zeros((0, 2, 3)),
        selected=selected,
        bag=bag,
        bag_topics=topics,
    )  # fmt: skip


def _regions(obj: dict[str, Any], r: _Reader) -> tuple[list[Region], FloatArray, FloatArray]:
    segmentation: dict[str, Any] = obj["segmentation"] if isinstance(obj.get("segmentation"), dict) else obj
    rows = segmentation.get("regions", [])
    if not isinstance(rows, list) or not all(isinstance(g, dict) for g in rows):
        raise r.fail("regions must be a list of objects")
    regions = []
    for g in rows:
        rid = g.get("id")
        if not isinstance(rid, int):
            raise r.fail("a region has no integer id")
        plane = r.array([*g.get("normal", []), g.get("d")], (4,), f"region {rid} plane")
        if abs(plane[2]) < 1e-6:
            raise r.fail(f"region {rid} is vertical (normal {plane[:3].tolist()})")
        polys = []
        for k, poly in enumerate(g.get("polygon", [])):
            if not isinstance(poly, dict):
                raise r.fail(f"region {rid} polygon {k} must be an object with exterior and holes")
            ext = r.array(poly.get("exterior"), (-1, 2), f"region {rid} polygon {k} exterior")
            holes = [r.array(h, (-1, 2), f"region {rid} polygon {k} hole") for h in poly.get("holes", [])]
            polys.append((ext, holes))
        regions.append(Region(rid, plane, polys))
    planes = {g.id: g.plane for g in regions}
    edges = segmentation.get("edges", [])
    good: list[FloatArray] = []
    bad: list[FloatArray] = []
    for e in edges if isinstance(edges, list) else []:
        if isinstance(e, dict) and "p_s" in e and "p_e" in e:
            seg = r.array([e["p_s"], e["p_e"]], (2, -1), "edge")[:, :2]
            # a border lies between its two regions: drawn on the higher one
            z = np.full(2, -np.inf)
            for rid in (e.get("a"), e.get("b")):
                if rid in planes:
                    n = planes[rid]
                    z = np.maximum(z, -(n[3] + n[0] * seg[:, 0] + n[1] * seg[:, 1]) / n[2])
            (good if e.get("traversable") else bad).append(np.c_[seg, np.where(np.isfinite(z), z, 0.0)])
    return (
        regions,
        np.array(good, dtype=np.float64).reshape(-1, 2, 3),
        np.array(bad, dtype=np.float64).reshape(-1, 2, 3),
    )
