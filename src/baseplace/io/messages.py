"""ROS messages <-> baseplace values, for ROS 1 and ROS 2 typestores of ``rosbags``.

Readers: sensor_msgs/PointCloud2 -> points (N, 3) in the message's frame; nav_msgs/OccupancyGrid
-> :class:`~baseplace.world.occupancy.OccupancyGrid` (map_server's layout: row-major, lower-left
cell first, values -1..100). Builders for the same types, tf2_msgs/TFMessage and the result types
(geometry_msgs/PoseStamped and PoseArray, nav_msgs/Path, visualization_msgs/MarkerArray). Every
builder takes the typestore, so one code path writes ROS 1 bags (headers with ``seq``) and ROS 2.
"""

from __future__ import annotations

import math
from itertools import pairwise
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from baseplace.errors import InputError
from baseplace.geometry.poses import yaw_of
from baseplace.guards import check_alloc
from baseplace.world.occupancy import OccupancyGrid

FloatArray = NDArray[np.float64]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
_FLOAT_TYPES: dict[int, np.dtype[Any]] = {
    7: np.dtype("f4"),
    8: np.dtype("f8"),
}  # sensor_msgs/PointField FLOAT32, FLOAT64
MAX_CLOUD_POINTS = 50_000_000
"""Most points a PointCloud2 may declare (width x height), checked before any allocation."""
CLOUD_BYTES_PER_POINT = 48
"""Memory one cloud point takes once read: float64 x, y, z in the sensor frame and in the world frame."""
GRID_BYTES_PER_CELL = 10
"""Memory one grid cell takes once read: the grid's int8 copy, a float64 distance transform, slack."""


def stamp_ns(header: Any) -> int:
    """A std_msgs/Header's stamp in nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def cloud_points(msg: Any, where: str, points_before: int = 0) -> tuple[FloatArray, bool]:
    """Finite points (N, 3) [m] of a PointCloud2 in its frame, and whether it is organized (height > 1).

    Every declared size is checked before an array is made: the layout against the message's
    bytes, and the points (:data:`CLOUD_BYTES_PER_POINT` each), alone and with the
    ``points_before`` points of the clouds already read from the same recording, against the
    memory cap (:func:`baseplace.guards.check_alloc`).

    Raises:
        InputError: no float x, y, z fields, fields that overlap or lie outside the point, a data
            size that does not match the layout, or points beyond the cap.
    """
    width, height = int(msg.width), int(msg.height)
    n = width * height
    if n > MAX_CLOUD_POINTS:
        raise InputError(f"{where}: the cloud declares {n} points, more than {MAX_CLOUD_POINTS}")
    fields = {f.name: f for f in msg.fields}
    missing = [c for c in "xyz" if c not in fields or int(fields[c].datatype) not in _FLOAT_TYPES]
    if missing:
        have = ", ".join(f"{f.name}:{int(f.datatype)}" for f in msg.fields) or "none"
        raise InputError(
            f"{where}: PointCloud2 needs float fields x, y, z; missing {missing} (fields: {have})"
        )
    step, row_step = int(msg.point_step), int(msg.row_step)
    data = np.asarray(msg.data, dtype=np.uint8)  # a view of the message's bytes
    if step <= 0 or width < 0 or height < 0 or row_step < step * width or len(data) < row_step * height:
        raise InputError(
            f"{where}: PointCloud2 data of {len(data)} bytes does not fit {msg.width} x {msg.height} points "
            f"of {step} bytes (row_step {row_step})"
        )
    order: Literal[">", "<"] = ">" if msg.is_bigendian else "<"
    spans = []
    for c in "xyz":
        off, size = int(fields[c].offset), _FLOAT_TYPES[int(fields[c].datatype)].itemsize
        if off < 0 or off + size > step:
            raise InputError(f"{where}: field {c} at offset {off} lies outside the {step}-byte point")
        spans.append((off, off + size))
    if any(a[1] > b[0] for a, b in pairwise(sorted(spans))):
        offsets = ", ".join(str(a) for a, _ in spans)
        raise InputError(
            f"{where}: PointCloud2 fields x, y, z overlap (offsets {offsets}); each needs its own bytes"
        )
    check_alloc(n * CLOUD_BYTES_PER_POINT, f"{n} points", where)
    check_alloc(
        (points_before + n) * CLOUD_BYTES_PER_POINT, f"{points_before + n} points of all clouds", where
    )
    rows = data[: row_step * height].reshape(height, row_step)[:, : step * width].reshape(height, width, step)
    pts = np.empty((n, 3))
    grid = pts.reshape(height, width, 3)  # a view: columns written in place, no float copies
    for k, (off, end) in enumerate(spans):
        dt = _FLOAT_TYPES[int(fields["xyz"[k]].datatype)].newbyteorder(order)
        grid[:, :, k] = rows[:, :, off:end].view(dt)[:, :, 0]
    finite = np.isfinite(pts).all(axis=1)
    return (pts if finite.all() else pts[finite]), height > 1


def grid_from_msg(msg: Any, where: str) -> OccupancyGrid:
    """The OccupancyGrid of a nav_msgs/OccupancyGrid message, in the message's frame (yaw-only origin).

    Raises:
        InputError: a data size other than width x height, a grid beyond the memory cap
            (:data:`GRID_BYTES_PER_CELL` per cell), or an origin that is not level.
    """
    info = msg.info
    w, h = int(info.width), int(info.height)
    data = np.asarray(msg.data, dtype=np.int8)  # a view of the message's bytes
    if w <= 0 or h <= 0 or len(data) != w * h:
        raise InputError(f"{where}: OccupancyGrid has {len(data)} cells for {w} x {h}")
    check_alloc(w * h * GRID_BYTES_PER_CELL, f"the occupancy grid of {w} x {h} cells", where)
    o = info.origin
    q = np.array([o.orientation.x, o.orientation.y, o.orientation.z, o.orientation.w], dtype=float)
    if not np.all(np.isfinite(q)):
        raise InputError(f"{where}: the grid's origin has a non-finite orientation {q.tolist()}")
    if np.linalg.norm(q) < 1e-9:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    R = Rotation.from_quat(q).as_matrix()
    if R[2, 2] < math.cos(math.radians(1.0)):
        raise InputError(f"{where}: the grid's origin is tilted; only level maps are supported")
    yaw = float(yaw_of(R))
    return OccupancyGrid(
        data.reshape(h, w), float(info.resolution), (float(o.position.x), float(o.position.y), yaw)
    )


# --- builders ---


def _time(ts: Any, ns: int) -> Any:
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ts: Any, frame: str, ns: int) -> Any:
    """A std_msgs/Header (with ``seq`` in ROS 1 typestores)."""
    cls = ts.types["std_msgs/msg/Header"]
    if "seq" in cls.__dataclass_fields__:
        return cls(seq=0, stamp=_time(ts, ns), frame_id=frame)
    return cls(stamp=_time(ts, ns), frame_id=frame)


def pose_msg(ts: Any, T: ArrayLike) -> Any:
    """A geometry_msgs/Pose from a (4, 4) transform."""
    T = np.asarray(T, dtype=float)
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    g = ts.types
    return g["geometry_msgs/msg/Pose"](
        position=g["geometry_msgs/msg/Point"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
        orientation=g["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def pose_matrix(pose: Any) -> FloatArray:
    """(4, 4) transform of a geometry_msgs/Pose."""
    q = pose.orientation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = [pose.position.x, pose.position.y, pose.position.z]
    return T


def cloud_msg(ts: Any, points: ArrayLike, frame: str, ns: int, width: int | None = None) -> Any:
    """A sensor_msgs/PointCloud2 of float32 x, y, z (organized ``width`` x N/width when given)."""
    pts = np.ascontiguousarray(np.asarray(points, dtype="<f4").reshape(-1, 3))
    width = width or len(pts)
    if len(pts) % width:
        raise InputError(f"{len(pts)} points do not make rows of {width}")
    g = ts.types
    fields = [
        g["sensor_msgs/msg/PointField"](name=c, offset=4 * k, datatype=7, count=1)
        for k, c in enumerate("xyz")
    ]
    return g[POINTCLOUD2](
        header=header(ts, frame, ns), height=len(pts) // width, width=width, fields=fields,
        is_bigendian=False, point_step=12, row_step=12 * width,
        data=np.frombuffer(pts.tobytes(), dtype=np.uint8), is_dense=False,
    )  # fmt: skip


def grid_msg(ts: Any, grid: OccupancyGrid, frame: str, ns: int) -> Any:
    """A nav_msgs/OccupancyGrid of ``grid`` (origin at height 0)."""
    g = ts.types
    x, y, yaw = grid.origin
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    T[:2, 3] = [x, y]
    info = g["nav_msgs/msg/MapMetaData"](
        map_load_time=_time(ts, ns), resolution=float(grid.resolution), width=grid.width, height=grid.height,
        origin=pose_msg(ts, T),
    )  # fmt: skip
    return g[OCCUPANCY_GRID](header=header(ts, frame, ns), info=info, data=grid.data.ravel().astype(np.int8))


def tf_msg(ts: Any, edges: list[tuple[str, str, ArrayLike]], ns: int) -> Any:
    """A tf2_msgs/TFMessage of ``(parent, child, T_parent_child (4, 4))`` edges at ``ns``."""
    g = ts.types
    transforms = []
    for parent, child, T in edges:
        T = np.asarray(T, dtype=float)
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        transforms.append(g["geometry_msgs/msg/TransformStamped"](
            header=header(ts, parent, ns), child_frame_id=child,
            transform=g["geometry_msgs/msg/Transform"](
                translation=g["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
                rotation=g["geometry_msgs/msg/Quaternion"](x=float(x), y=float(y), z=float(z), w=float(w)),
            ),
        ))  # fmt: skip
    return g[TF_MESSAGE](transforms=transforms)
