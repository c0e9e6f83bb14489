"""Clouds, an occupancy grid and tf from a ROS recording, without ROS (``rosbags``).

Reads ROS 2 bags (a rosbag2 directory, or a single ``.db3`` (sqlite3) or ``.mcap`` file) and ROS 1
``.bag`` files. :func:`read_bag` picks the cloud topic(s) (sensor_msgs/PointCloud2), the map topic
(nav_msgs/OccupancyGrid), reads every tf2_msgs/TFMessage on ``/tf`` and ``/tf_static`` into a
:class:`~baseplace.io.tf.TfTree`, and looks up ``T_world_sensor`` at each cloud's stamp.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError, brief
from baseplace.geometry.poses import yaw_of
from baseplace.io.bag_limits import (
    bound_mcap_decompression,
    bound_rosbag2_decompression,
    check_chunks,
    check_tf_message,
)
from baseplace.io.messages import (
    OCCUPANCY_GRID,
    POINTCLOUD2,
    TF_MESSAGE,
    cloud_points,
    grid_from_msg,
    stamp_ns,
)
from baseplace.io.tf import MAX_TRANSFORMS, TfTree
from baseplace.world.occupancy import OccupancyGrid

FloatArray = NDArray[np.float64]
TF_TOPICS = ("/tf", "/tf_static")
TF_TYPES = (TF_MESSAGE, "tf/msg/tfMessage")  # tf2 and ROS 1's older tf
CLOUD_CHOICES = ("last", "first", "all")


@dataclass(frozen=True)
class BagCloud:
    """One PointCloud2 message with its pose.

    Attributes:
        topic: the topic it came from.
        frame: its header's frame_id (the sensor frame).
        stamp_ns: its header's stamp [ns].
        points: (N, 3) finite points in the sensor frame [m].
        T_world_sensor: (4, 4) pose of the sensor in the world frame at ``stamp_ns``.
        organized: the message was an image-shaped cloud (height > 1): an optical camera frame.
    """

    topic: str
    frame: str
    stamp_ns: int
    points: FloatArray
    T_world_sensor: FloatArray
    organized: bool

    @property
    def world_points(self) -> FloatArray:
        """(N, 3) points in the world frame [m]."""
        T = self.T_world_sensor
        return np.asarray(self.points @ T[:3, :3].T + T[:3, 3], dtype=np.float64)


@dataclass(frozen=True)
class BagScene:
    """What a job needs from a recording, in one world frame.

    Attributes:
        source: the bag's path.
        world_frame: the frame everything is expressed in.
        clouds: the selected clouds with their poses.
        grid: the occupancy grid moved into the world frame, or None without a map topic.
        tf: every recorded transform.
    """

    source: str
    world_frame: str
    clouds: list[BagCloud]
    grid: OccupancyGrid | None
    tf: TfTree

    def world_points(self) -> FloatArray:
        """(N, 3) all selected clouds in the world frame [m] (empty without clouds)."""
        if not self.clouds:
            return np.zeros((0, 3))
        return np.vstack([c.world_points for c in self.clouds])


def _open(path: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    if not path.exists():
        raise InputError(f"bag {path} does not exist")
    bound_mcap_decompression()  # an MCAP file without a summary is inflated while it is opened
    bound_rosbag2_decompression()  # a file-compressed rosbag2 directory too
    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except InputError as exc:
        raise InputError(f"bag {path}: {exc}") from None
    except Exception as exc:  # rosbags raises its own errors, and OSError/ValueError on odd files
        raise InputError(
            f"cannot read bag {path}: {type(exc).__name__}: {brief(str(exc), 120)} (need a rosbag2 "
            "directory, a .db3 or .mcap file, or a ROS 1 .bag)"
        ) from None
    try:
        check_chunks(reader, path)
    except InputError:
        reader.close()
        raise
    except Exception as exc:
        reader.close()
        raise InputError(f"cannot read bag {path}: its chunks are damaged: {brief(str(exc), 120)}") from None
    return reader


def _topics(reader: Any) -> dict[str, str]:
    return {c.topic: c.msgtype for c in reader.connections}


def _describe(topics: dict[str, str]) -> str:
    return ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"


def _connections(reader: Any, topic: str, msgtype: str, path: Path, option: str) -> list[Any]:
    topics = _topics(reader)
    if topic not in topics:
        raise InputError(f"bag {path} has no topic {topic!r} ({option}); topics: {_describe(topics)}")
    conns = [c for c in reader.connections if c.topic == topic]
    bad = [c.msgtype for c in conns if c.msgtype != msgtype]
    if bad:
        raise InputError(
            f"bag {path}: topic {topic!r} carries unknown message type {bad[0]} for {option}; expected {msgtype}"
        )
    return conns


def _raw_messages(reader: Any, conns: list[Any], path: Path) -> Iterator[tuple[Any, bytes]]:
    """(connection, serialized message) of ``conns`` in time order, one at a time."""
    messages = reader.messages(connections=conns)
    while True:
        try:
            conn, _, raw = next(messages)
        except StopIteration:
            return
        except InputError as exc:
            raise InputError(f"bag {path}: {exc}") from None
        except Exception as exc:
            raise InputError(
                f"cannot decode {conns[0].topic} in bag {path}: {brief(str(exc), 120)}"
            ) from None
        yield conn, raw


def _decode(reader: Any, conn: Any, raw: bytes, path: Path) -> Any:
    try:
        return reader.deserialize(raw, conn.msgtype)
    except Exception as exc:
        raise InputError(f"cannot decode {conn.topic} in bag {path}: {brief(str(exc), 120)}") from None


def _chosen(reader: Any, conns: list[Any], path: Path, which: str) -> Iterator[Any]:
    """The decoded messages of ``conns`` that ``which`` selects ("first", "last", "all"), one at a time.

    Only the selected messages are decoded, and only one is held at a time.
    """
    last = None
    for conn, raw in _raw_messages(reader, conns, path):
        if which == "all":
            yield _decode(reader, conn, raw, path)
        elif which == "first":
            yield _decode(reader, conn, raw, path)
            return
        last = (conn, raw)
    if which == "last" and last is not None:
        yield _decode(reader, *last, path)


TF_BATCH = 4096
"""Transforms gathered from /tf messages before they are recorded together (one sort per batch)."""


class _TfBatch:
    """Transforms of /tf (or /tf_static) messages not recorded yet, as plain names and numbers.

    A decoded message's objects are dropped as soon as its numbers are read: held in a batch they
    would outlive the garbage collector's young generations, and its full collections, which walk
    every object the process holds, took half of a large recording's tf read.
    """

    def __init__(self) -> None:
        self.parents: list[str] = []
        self.children: list[str] = []
        self.stamps: list[int] = []
        self.poses: list[tuple[float, ...]] = []

    def clear(self) -> None:
        for values in (self.parents, self.children, self.stamps, self.poses):
            values.clear()

    def extend(self, transforms: Sequence[Any]) -> None:
        for t in transforms:
            r, q = t.transform.translation, t.transform.rotation
            self.parents.append(t.header.frame_id)
            self.children.append(t.child_frame_id)
            self.stamps.append(stamp_ns(t.header))
            self.poses.append((r.x, r.y, r.z, q.x, q.y, q.z, q.w))

    def __len__(self) -> int:
        return len(self.stamps)

    def record(self, tree: TfTree, static: bool) -> None:
        """Record the batch in ``tree``, and empty it."""
        tree.add_many(self.parents, self.children, self.stamps, self.poses or np.zeros((0, 7)), static)
        self.clear()


def _read_tf(reader: Any, path: Path, tolerance_ns: int) -> TfTree:
    tree = TfTree(tolerance_ns)
    conns = [c for c in reader.connections if c.topic in TF_TOPICS]
    for c in conns:
        if c.msgtype != TF_MESSAGE:
            raise InputError(
                f"bag {path}: topic {c.topic!r} carries unknown message type {c.msgtype}; expected {TF_MESSAGE}"
            )
    batches = {False: _TfBatch(), True: _TfBatch()}  # the transforms of /tf, /tf_static
    seen = 0  # transforms read, recorded or in a batch
    for conn, raw in _raw_messages(reader, conns, path) if conns else ():
        seen += check_tf_message(raw, reader.is2, seen, MAX_TRANSFORMS, f"bag {path}")
        static = conn.topic == "/tf_static"
        batches[static].extend(_decode(reader, conn, raw, path).transforms)
        if len(batches[static]) >= TF_BATCH:
            batches[static].record(tree, static)
    for static, batch in batches.items():
        batch.record(tree, static)
    return tree


def read_bag(
    path: str | Path,
    cloud_topics: Sequence[str] = (),
    map_topic: str | None = None,
    world_frame: str = "map",
    clouds: str = "last",
    tf_tolerance: float = 0.1,
) -> BagScene:
    """Read clouds, a grid and tf from a recording, and put them in ``world_frame``.

    Args:
        path: rosbag2 directory, ``.db3`` or ``.mcap`` file, or ROS 1 ``.bag``.
        cloud_topics: PointCloud2 topics to read (any number).
        map_topic: an OccupancyGrid topic (its last message is used), or None.
        world_frame: the frame of the result (e.g. ``map``).
        clouds: which messages of each cloud topic: "last", "first" or "all".
        tf_tolerance: how far [s] a cloud's stamp may lie outside a dynamic tf edge's range.

    Raises:
        InputError: a missing or unreadable bag, a missing topic (listing the topics), a topic of
            another message type, a transform that cannot be looked up (naming the frames and
            the nearest stamps), or a map that is not level in the world frame.
    """
    path = Path(path)
    if clouds not in CLOUD_CHOICES:
        raise InputError(f"unknown cloud selection {clouds!r}; valid: {', '.join(CLOUD_CHOICES)}")
    if not cloud_topics and map_topic is None:
        raise InputError(
            "give a cloud topic (--cloud-topic) or a map topic (--map-topic) to read from the bag"
        )
    reader = _open(path)
    try:
        cloud_conns = {t: _connections(reader, t, POINTCLOUD2, path, "--cloud-topic") for t in cloud_topics}
        map_conns = _connections(reader, map_topic, OCCUPANCY_GRID, path, "--map-topic") if map_topic else []
        tree = _read_tf(reader, path, int(tf_tolerance * 1e9))
        out: list[BagCloud] = []
        n_points = 0  # of the clouds read so far, bounded together
        for topic, conns in cloud_conns.items():
            where, before = f"{topic} in {path}", len(out)
            for msg in _chosen(reader, conns, path, clouds):
                points, organized = cloud_points(msg, where, n_points)
                n_points += len(points)
                frame, ns = msg.header.frame_id.lstrip("/"), stamp_ns(msg.header)
                T = tree.lookup(world_frame, frame, ns)
                out.append(BagCloud(topic, frame, ns, points, T, organized))
            if len(out) == before:
                raise InputError(f"bag {path}: topic {topic!r} has no messages")
        grid = None
        if map_conns:
            maps = list(_chosen(reader, map_conns, path, "last"))
            if not maps:
                raise InputError(f"bag {path}: topic {map_topic!r} has no messages")
            msg = maps[-1]
            grid = grid_from_msg(msg, f"{map_topic} in {path}")
            frame = msg.header.frame_id.lstrip("/") or world_frame
            if frame != world_frame:
                grid = _grid_in_world(
                    grid, tree.lookup(world_frame, frame, stamp_ns(msg.header)), frame, world_frame
                )
    finally:
        reader.close()
    return BagScene(str(path), world_frame, out, grid, tree)


def _grid_in_world(grid: OccupancyGrid, T_world_map: FloatArray, frame: str, world: str) -> OccupancyGrid:
    """The grid re-anchored in the world frame (the transform must be level, at floor height)."""
    R = T_world_map[:3, :3]
    if R[2, 2] < math.cos(math.radians(1.0)) or abs(T_world_map[2, 3]) > 0.01:
        raise InputError(
            f"the map's frame {frame!r} is not level at floor height in {world!r} "
            f"(z offset {T_world_map[2, 3]:.3f} m); only level maps are supported"
        )
    x, y, yaw = grid.origin
    p = T_world_map @ np.array([x, y, 0.0, 1.0])
    yaw_w = yaw + float(yaw_of(R))
    return OccupancyGrid(grid.data, grid.resolution, (float(p[0]), float(p[1]), yaw_w), grid.source)


@dataclass(frozen=True)
class BagRgbd:
    """An aligned RGB-D frame from a recording, with its camera's pose.

    Attributes:
        source: the bag's path.
        rgb: (H, W, 3) uint8 RGB of the colour topic's message.
        depth: (H, W) float32 depth [m] of the depth topic's message, NaN where there is no return.
        intrinsics: the CameraInfo topic's camera, for H x W images.
        camera_frame: the colour image's frame_id (an optical frame: x right, y down, z forward).
        stamp_ns: the colour image's stamp [ns].
        T_world_camera: (4, 4) pose of ``camera_frame`` in the world frame at ``stamp_ns``.
    """

    source: str
    rgb: NDArray[np.uint8]
    depth: NDArray[np.float32]
    intrinsics: Any
    camera_frame: str
    stamp_ns: int
    T_world_camera: FloatArray


def read_rgbd(
    path: str | Path,
    rgb_topic: str,
    depth_topic: str,
    info_topic: str,
    world_frame: str = "map",
    which: str = "last",
    tf_tolerance: float = 0.1,
) -> BagRgbd:
    """Read one RGB-D frame (image, aligned depth, CameraInfo) and the camera's pose from a recording.

    The colour message is the ``which`` ("first" or "last") of its topic; the depth and CameraInfo
    messages are those of their topics closest in stamp to it. The camera's pose is looked up in
    tf at the colour image's stamp, from its frame_id.

    Raises:
        InputError: a missing or unreadable bag or topic, a topic of another message type, an
            image encoding not read, images or CameraInfo of different sizes, or a pose tf cannot give.
    """
    from baseplace.io.image_messages import (
        CAMERA_INFO,
        IMAGE,
        depth_from_msg,
        intrinsics_from_msg,
        rgb_from_msg,
    )

    path = Path(path)
    if which not in ("first", "last"):
        raise InputError(f"unknown frame selection {which!r}; valid: first, last")
    reader = _open(path)
    try:
        rgb_conns = _connections(reader, rgb_topic, IMAGE, path, "--rgb-topic")
        depth_conns = _connections(reader, depth_topic, IMAGE, path, "--depth-topic")
        info_conns = _connections(reader, info_topic, CAMERA_INFO, path, "--camera-info-topic")
        colour = next(iter(_chosen(reader, rgb_conns, path, which)), None)
        if colour is None:
            raise InputError(f"bag {path}: topic {rgb_topic!r} has no messages")
        ns, frame = stamp_ns(colour.header), colour.header.frame_id.lstrip("/")
        rgb = rgb_from_msg(colour, f"{rgb_topic} in {path}")
        del colour
        depth = depth_from_msg(
            _closest(reader, depth_conns, path, depth_topic, ns), f"{depth_topic} in {path}"
        )
        K = intrinsics_from_msg(_closest(reader, info_conns, path, info_topic, ns), f"{info_topic} in {path}")
        if rgb.shape[:2] != depth.shape:
            raise InputError(
                f"bag {path}: the image on {rgb_topic} is {rgb.shape[1]}x{rgb.shape[0]} and the depth on "
                f"{depth_topic} {depth.shape[1]}x{depth.shape[0]}; they must be aligned (the same size)"
            )
        K.check_image(rgb.shape[1], rgb.shape[0])
        T = _read_tf(reader, path, int(tf_tolerance * 1e9)).lookup(world_frame, frame, ns)
    finally:
        reader.close()
    return BagRgbd(str(path), rgb, depth, K, frame, ns, T)


def _closest(reader: Any, conns: list[Any], path: Path, topic: str, ns: int) -> Any:
    """The message of ``conns`` whose header stamp is closest to ``ns`` (one decoded message held at a time)."""
    best: tuple[int, Any, bytes] | None = None
    for conn, raw in _raw_messages(reader, conns, path):
        msg = _decode(reader, conn, raw, path)
        gap = abs(stamp_ns(msg.header) - ns)
        del msg
        if best is None or gap < best[0]:
            best = (gap, conn, raw)
    if best is None:
        raise InputError(f"bag {path}: topic {topic!r} has no messages")
    return _decode(reader, best[1], best[2], path)
