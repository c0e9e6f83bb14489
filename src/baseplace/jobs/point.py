"""The ``point`` job: from an RGB-D frame of a person pointing to the object and where to stand (seed 004).

Seed 004, section 3.1 and Fig. 1b: the operator's hand landmarks give the gesture; on *Point*, the
index finger selects the object (by default the one its 3-D line from depth aims at; the seed's rule,
the first object image box its image line meets, with ``selection="first"``); the object's
position and size come from depth, in the world frame; with an occupancy grid, the ``candidates``
job (seed 004 Algorithm 1, verified) gives where to stand to pick it up.

Outcomes that are not errors (exit 3, the report says why): no hand in the frame, a gesture other
than Point, the line meets no object, or the pixels along the line have no depth (the object may
be there but depth missed it). Bad files, images of different sizes and bad intrinsics are input
errors (exit 2).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from baseplace.errors import InputError, brief
from baseplace.jobs.inputs import CloudInput, Progress, out_path
from baseplace.jobs.report import NoResultError, Report, RobotRef
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.perception.objects import ObjectSettings
    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.robustness import RobustnessSettings
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot
    from baseplace.world.occupancy import OccupancyGrid

MAX_LANDMARKS_BYTES = 1 << 20
MIN_DEPTH_HOLE_PX = 10
"""A line that meets no object but crosses this many pixels in a row without depth: "depth missing"."""


@dataclass
class PointJob:
    """The inputs of :func:`point_job`.

    Attributes:
        rgb: RGB image (PNG or JPEG), or None with ``bag``.
        depth: aligned depth image (16-bit PNG [mm] or float32 .npy [m]), or None with ``bag``.
        intrinsics: "fx fy cx cy" [px] or a ROS CameraInfo YAML, or None with ``bag``.
        transform: world_T_camera (a 4x4 file) or the camera-frame up vector "ux uy uz"; None with
            ``bag`` (tf gives the camera's pose).
        landmarks: JSON file of 21 MediaPipe landmarks (normalised x, y; relative z) instead of the
            hand model; an empty list means no hand.
        occupancy: occupancy grid (map_server YAML or loaded): also the candidates to pick the object up.
        robot, arm, map, robot_pose, seed, motion, robustness: as the candidates job's.
        objects: how objects are cut out of the frame (None: defaults).
        selection: "finger3d" (the object whose centre lies at the smallest angle from the index
            finger's 3-D line from depth, within 16 deg; "nearest", else "first", when the finger
            has no usable depth), "first" (the seed's: the first image box the line enters) or "nearest" (the
            object whose box centre lies at the smallest angle from the image line, within 12 deg).
        png: also write a picture here: the image with the hand, the line and the boxes; with a
            grid, the candidates from above (also on exit 3, what was found).
        bag: a ROS recording to read the frame from instead of image files: the colour image
            (``rgb_topic``), the aligned depth (``depth_topic``, 16UC1 [mm] or 32FC1 [m]) and the
            CameraInfo (``camera_info_topic``) closest in stamp to it, and the camera's pose in
            ``world_frame`` from /tf and /tf_static at the colour image's stamp.
        bag_frame: which colour message: "last" or "first".
    """

    rgb: str | None
    depth: str | None
    intrinsics: str | None
    transform: str | None = None
    landmarks: str | None = None
    occupancy: OccupancyGrid | str | None = None
    robot: Robot | str = DEFAULT_ROBOT
    arm: str | None = None
    map: ReachabilityMap | str | None = None
    robot_pose: str | None = None
    seed: int = 0
    motion: MotionSettings | None = None
    robustness: RobustnessSettings | None = None
    objects: ObjectSettings | None = None
    selection: str = "finger3d"
    png: str | None = None
    bag: str | None = None
    rgb_topic: str | None = None
    depth_topic: str | None = None
    camera_info_topic: str | None = None
    world_frame: str = "map"
    bag_frame: str = "last"

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {"rgb": self.rgb, "depth": self.depth, "intrinsics": self.intrinsics, "transform": self.transform,
                "landmarks": self.landmarks,
                "occupancy": self.occupancy if isinstance(self.occupancy, str | None) else "grid",
                "robot": self.robot if isinstance(self.robot, str) else self.robot.name, "arm": self.arm,
                "map": self.map if isinstance(self.map, str | None) else "loaded", "robot_pose": self.robot_pose,
                "seed": self.seed, "selection": self.selection, "png": self.png,
                "bag": None if self.bag is None else {
                    "path": self.bag, "rgb_topic": self.rgb_topic, "depth_topic": self.depth_topic,
                    "camera_info_topic": self.camera_info_topic, "world_frame": self.world_frame,
                    "frame": self.bag_frame}}  # fmt: skip


@dataclass
class PointReport(Report):
    """``point``: the gesture, the objects, the selected one and where to stand.

    Attributes:
        image_size: [width, height] [px].
        landmarks: (21, 2) hand landmarks [px], or None without a hand.
        gesture: ``{"name": Scan | Point | Stop | none, "fingers": {...}}``, or None without a hand.
        objects: every object found: ``position``, ``size`` [m, world], ``box_world``, ``image_box`` [px] ...
        ray_2d: the index-finger line in the image (origin, direction, end, hit, length [px]).
        ray_3d: the index finger's 3-D line from its front-most depth points, world frame [m], with the
            object it aims at (``finger3d``'s choice), or None without usable depth on the finger.
        selected: index into ``objects`` of the target, or None.
        object: the target: ``position`` and ``size`` [m], world frame, or None.
        candidates: base placements to pick it up, best first (with a grid), or None.
        rejected, path, motion_failures: the candidates job's rejected positions, path and
            reaching-motion reasons (:class:`~baseplace.jobs.report.CandidatesReport`).
    """

    kind: ClassVar[str] = "point"
    image_size: list[int] = field(default_factory=list)
    landmarks: list[list[float]] | None = None
    gesture: dict[str, Any] | None = None
    objects: list[dict[str, Any]] = field(default_factory=list)
    ray_2d: dict[str, Any] | None = None
    ray_3d: dict[str, Any] | None = None
    selected: int | None = None
    object: dict[str, Any] | None = None
    candidates: list[dict[str, Any]] | None = None
    rejected: list[dict[str, Any]] = field(default_factory=list)
    path: list[list[float]] | None = None
    motion_failures: dict[str, int] = field(default_factory=dict)


def read_landmarks(path: str, width: int, height: int) -> np.ndarray | None:
    """Landmarks (21, 3) in pixels (x * width - 0.5, y * height - 0.5, z * width) from a JSON file.

    The file holds 21 MediaPipe landmarks, as ``[{"x":, "y":, "z":}, ...]``, ``[[x, y, z], ...]``
    or ``{"landmarks": [...]}``; ``[]`` means the detector found no hand (returns None).

    Raises:
        InputError: unreadable, over 1 MB, not 21 landmarks of finite numbers, or x, y outside [-1, 2].
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"--landmarks file not found: {brief(path, 200)}")
    if p.stat().st_size > MAX_LANDMARKS_BYTES:
        raise InputError(
            f"--landmarks {path}: {p.stat().st_size} bytes is over the 1 MB limit for 21 landmarks"
        )
    try:
        doc = json.loads(p.read_text())
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"--landmarks {path}: not JSON ({' '.join(str(exc).split())[:100]})") from None
    if isinstance(doc, dict):
        doc = doc.get("landmarks")
    if not isinstance(doc, list):
        raise InputError(f'--landmarks {path}: expected a list of 21 landmarks (or {{"landmarks": [...]}})')
    if not doc:
        return None
    rows = []
    for item in doc:
        row = [item.get(k, 0.0) for k in "xyz"] if isinstance(item, dict) else item
        if not isinstance(row, list | tuple) or len(row) not in (2, 3):
            raise InputError(
                f"--landmarks {path}: a landmark must be {{x, y, z}} or [x, y(, z)], got {brief(item)}"
            )
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in row):
            raise InputError(f"--landmarks {path}: landmark coordinates must be numbers, got {brief(item)}")
        rows.append([float(v) for v in row] + [0.0] * (3 - len(row)))
    L = np.asarray(rows, dtype=float)
    if L.shape != (21, 3):
        raise InputError(f"--landmarks {path}: MediaPipe hands have 21 landmarks, got {len(rows)}")
    if not np.all(np.isfinite(L)) or np.any(L[:, :2] < -1) or np.any(L[:, :2] > 2):
        raise InputError(
            f"--landmarks {path}: x, y must be finite and normalised to the image (0 to 1; -1 to 2 accepted)"
        )
    return np.c_[L[:, 0] * width - 0.5, L[:, 1] * height - 0.5, L[:, 2] * width]


def _hand_landmarks(job: PointJob, rgb: np.ndarray) -> np.ndarray | None:
    """The hand's landmarks [px]: from ``--landmarks``, else MediaPipe's hand landmarker."""
    height, width = rgb.shape[:2]
    if job.landmarks is not None:
        return read_landmarks(job.landmarks, width, height)
    from baseplace.perception.hands import detect_hand

    return detect_hand(rgb)


def point_job(job: PointJob, progress: Progress | None = None) -> PointReport:
    """The gesture, the objects and the object pointed at in one RGB-D frame; with a grid, where to stand.

    Raises:
        InputError: bad files, images of different sizes, bad intrinsics or transform.
        NoResultError: no hand, not pointing, the line meets no object, or no depth along it (exit 3).
    """
    from baseplace.perception.rgbd import load_frame
    from baseplace.perception.selection import SELECTION_RULES
    from baseplace.terrain.io import load_transform

    t0 = time.perf_counter()
    png = out_path(job.png, "--png", (".png",))  # before any work
    if job.selection not in SELECTION_RULES:
        raise InputError(f"unknown selection rule {job.selection!r}; valid: {', '.join(SELECTION_RULES)}")
    if job.bag is not None:
        frame, T_world_camera = _bag_frame(job)
    else:
        if job.rgb is None or job.depth is None or job.intrinsics is None:
            raise InputError("give --rgb, --depth and --intrinsics, or --bag with --rgb-topic, --depth-topic and "
                             "--camera-info-topic")  # fmt: skip
        if job.transform is None:
            raise InputError(
                'give --transform: the camera\'s world_T_camera (a 4x4 file) or its up vector (e.g. "0 -1 0")'
            )
        T_world_camera = load_transform(job.transform)
        frame = load_frame(job.rgb, job.depth, job.intrinsics)
    report = PointReport(inputs=job.echo(), image_size=[frame.width, frame.height])
    try:
        _find(job, frame, T_world_camera, report, t0, progress)
    except NoResultError:  # what was found is worth a picture too; bad input writes nothing
        _picture(png, frame.rgb, report)
        raise
    _picture(png, frame.rgb, report)
    return report


def _bag_frame(job: PointJob) -> tuple[Any, np.ndarray]:
    """The frame and world_T_camera from ``job.bag``'s image, depth, CameraInfo and tf topics."""
    from baseplace.io.bag import read_rgbd
    from baseplace.perception.rgbd import RgbdFrame

    given = [o for o, v in (("--rgb", job.rgb), ("--depth", job.depth), ("--intrinsics", job.intrinsics),
                            ("--transform", job.transform)) if v is not None]  # fmt: skip
    if given:
        raise InputError(f"--bag gives the frame and tf the camera's pose: drop {', '.join(given)}")
    missing = [o for o, v in (("--rgb-topic", job.rgb_topic), ("--depth-topic", job.depth_topic),
                              ("--camera-info-topic", job.camera_info_topic)) if v is None]  # fmt: skip
    if missing:
        raise InputError(f"with --bag, give {', '.join(missing)} (sensor_msgs/Image, sensor_msgs/CameraInfo)")
    assert job.bag and job.rgb_topic and job.depth_topic and job.camera_info_topic
    got = read_rgbd(
        job.bag, job.rgb_topic, job.depth_topic, job.camera_info_topic, job.world_frame, job.bag_frame
    )
    return RgbdFrame(got.rgb, got.depth, got.intrinsics), got.T_world_camera


def _picture(png: Path | None, rgb: np.ndarray, report: PointReport) -> None:
    if png is not None:
        from baseplace.viz.pointing import plot_point

        plot_point(rgb, report.to_json(), png)
        report.outputs["png"] = str(png)


def _find(job: PointJob, frame: Any, T_world_camera: np.ndarray, report: PointReport, t0: float,
          progress: Progress | None) -> None:  # fmt: skip
    """The hand, the gesture, the objects, the selection and the candidates, into ``report``."""
    from baseplace.perception.gestures import classify
    from baseplace.perception.objects import NoSupportPlaneError, detect_objects
    from baseplace.perception.selection import FINGER3D_MAX_ANGLE_DEG, depth_hole, select

    t_load = time.perf_counter()
    hand = _hand_landmarks(job, frame.rgb)
    t_hand = time.perf_counter()
    report.timings_ms = {"load": (t_load - t0) * 1e3, "landmarks": (t_hand - t_load) * 1e3}
    if hand is None:
        raise NoResultError("no hand in the image", report)
    report.landmarks = np.round(hand[:, :2], 2).tolist()
    gesture = classify(hand)
    report.gesture = gesture.to_json()
    t_gesture = time.perf_counter()
    points = frame.points_camera() @ T_world_camera[:3, :3].T + T_world_camera[:3, 3]
    try:
        detections = detect_objects(points, job.objects, hand[:, :2])
    except NoSupportPlaneError as exc:
        raise NoResultError(str(exc), report) from None
    objects = detections.objects
    t_objects = time.perf_counter()
    report.objects = [o.to_json() for o in objects]
    report.timings_ms.update(
        {"gesture": (t_gesture - t_hand) * 1e3, "objects": (t_objects - t_gesture) * 1e3}
    )
    if gesture.name != "Point":
        raise NoResultError(f"the gesture is {gesture.name}, not Point: nothing is selected", report)
    boxes = np.array([o.image_box for o in objects]).reshape(-1, 2, 2)
    K = frame.intrinsics
    ray, ray3 = select(job.selection, hand[:, :2], boxes, np.array([o.box_world for o in objects]).reshape(-1, 2, 3),
                       points, T_world_camera, (K.fx, K.fy, K.cx, K.cy), frame.width, frame.height)  # fmt: skip
    report.ray_2d, report.ray_3d = ray.to_json(), None if ray3 is None else ray3.to_json()
    t_select = time.perf_counter()
    report.timings_ms["selection"] = (t_select - t_objects) * 1e3
    if ray.hit is None:
        hole, at = depth_hole(ray, frame.depth, start=10.0)
        if hole >= MIN_DEPTH_HOLE_PX and at is not None:
            raise NoResultError(
                f"depth is missing on {hole} pixels in a row along the pointing line from pixel "
                f"({at[0]:.0f}, {at[1]:.0f}): an object there would be unseen by the depth camera (too close, dark or shiny)",
                report,
            )
        if job.selection == "finger3d" and ray3 is not None:
            raise NoResultError(f"the finger's 3-D line passes more than {FINGER3D_MAX_ANGLE_DEG:g} deg from "
                                f"each of the {len(objects)} objects' centres", report)  # fmt: skip
        raise NoResultError(
            f"the pointing line meets none of the {len(objects)} objects before the image border", report
        )
    target = objects[ray.hit]
    report.selected = ray.hit
    report.object = {
        "position": np.round(target.position, 4).tolist(),
        "size": np.round(target.size, 4).tolist(),
    }
    if job.occupancy is not None:
        _candidates(job, report, points[~detections.hand], target.position, progress)
    report.timings_ms["total"] = (time.perf_counter() - t0) * 1e3


def _candidates(job: PointJob, report: PointReport, points: np.ndarray, position: np.ndarray,
                progress: Progress | None) -> None:  # fmt: skip
    """The candidates job's placements for picking up the target, into ``report``.

    ``points`` (N, 3) are the frame's world points without the hand's: the operator steps away.
    """
    from baseplace.jobs.candidates import CandidatesJob, candidates_job

    cloud = points[np.all(np.isfinite(points), axis=1)]
    sub = CandidatesJob(position.tolist(), job.occupancy, CloudInput(points=cloud), job.robot_pose, "radial",
                        job.robot, job.arm, job.map, None, job.seed, "auto", job.motion, job.robustness)  # fmt: skip
    t = time.perf_counter()
    try:
        found = candidates_job(sub, progress)
    except NoResultError as exc:
        report.failures, report.robot = dict(exc.report.failures), exc.report.robot
        report.rejected = list(getattr(exc.report, "rejected", []))
        report.motion_failures = dict(getattr(exc.report, "motion_failures", {}))
        raise NoResultError(f"the object is at {np.round(position, 3).tolist()}: {exc}", report) from None
    report.robot = found.robot if isinstance(found.robot, RobotRef) else None
    report.candidates, report.rejected, report.path = found.candidates, found.rejected, found.path
    report.motion_failures = dict(found.motion_failures)
    report.failures = dict(found.failures)
    report.outputs.update(found.outputs)
    report.timings_ms["candidates"] = (time.perf_counter() - t) * 1e3


__all__ = ["PointJob", "PointReport", "point_job", "read_landmarks"]
