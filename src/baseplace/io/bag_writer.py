"""Write recordings of clouds, grids, images, camera infos and tf (ROS 2 sqlite3 or MCAP, ROS 1), without ROS.

For converting files into the recordings robots make, and for tests of :func:`~baseplace.io.bag.read_bag`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.files import staged_directory
from baseplace.io.messages import OCCUPANCY_GRID, POINTCLOUD2, TF_MESSAGE, cloud_msg, grid_msg, tf_msg
from baseplace.world.occupancy import OccupancyGrid

FORMATS = ("mcap", "sqlite3", "ros1")


@dataclass(frozen=True)
class CloudRecord:
    """A PointCloud2 to write: points (N, 3) [m] in ``frame`` at ``stamp_ns``, ``width`` per row."""

    topic: str
    frame: str
    stamp_ns: int
    points: ArrayLike
    width: int | None = None


@dataclass(frozen=True)
class TfRecord:
    """``T_parent_child`` (4, 4) at ``stamp_ns``, on /tf_static when ``static`` else /tf."""

    parent: str
    child: str
    stamp_ns: int
    T: ArrayLike
    static: bool = False


@dataclass(frozen=True)
class GridRecord:
    """An OccupancyGrid to write on ``topic`` in ``frame``."""

    topic: str
    frame: str
    stamp_ns: int
    grid: OccupancyGrid


@dataclass(frozen=True)
class ImageRecord:
    """A sensor_msgs/Image to write: ``image`` in ``encoding``, in ``frame`` at ``stamp_ns``.

    ``image`` is (H, W, 3) uint8 for rgb8 and bgr8, (H, W) depth for 16UC1 [mm] and 32FC1 [m].
    """

    topic: str
    frame: str
    stamp_ns: int
    image: ArrayLike
    encoding: str


@dataclass(frozen=True)
class CameraInfoRecord:
    """A sensor_msgs/CameraInfo to write: ``intrinsics`` for ``width`` x ``height`` images, no distortion."""

    topic: str
    frame: str
    stamp_ns: int
    intrinsics: Any
    width: int
    height: int


def write_input_bag(
    path: str | Path,
    fmt: str,
    clouds: Sequence[CloudRecord] = (),
    tf: Sequence[TfRecord] = (),
    grids: Sequence[GridRecord] = (),
    images: Sequence[ImageRecord] = (),
    camera_infos: Sequence[CameraInfoRecord] = (),
) -> None:
    """Write a recording: ``fmt`` "mcap" or "sqlite3" (a rosbag2 directory at ``path``) or "ros1" (a ``.bag``)."""
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if fmt not in FORMATS:
        raise InputError(f"unknown bag format {fmt!r}; valid: {', '.join(FORMATS)}")
    ts = get_typestore(Stores.ROS1_NOETIC if fmt == "ros1" else Stores.ROS2_HUMBLE)
    if TF_MESSAGE not in ts.types:  # ROS 1 Noetic has tf2_msgs too; rosbags' store leaves it out
        from rosbags.typesys import get_types_from_msg

        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF_MESSAGE))
    messages: list[tuple[str, str, int, Any]] = []
    for c in clouds:
        messages.append(
            (c.topic, POINTCLOUD2, c.stamp_ns, cloud_msg(ts, c.points, c.frame, c.stamp_ns, c.width))
        )
    for g in grids:
        messages.append((g.topic, OCCUPANCY_GRID, g.stamp_ns, grid_msg(ts, g.grid, g.frame, g.stamp_ns)))
    if images or camera_infos:
        from baseplace.io.image_messages import CAMERA_INFO, IMAGE, camera_info_msg, image_msg

        for im in images:
            messages.append(
                (
                    im.topic,
                    IMAGE,
                    im.stamp_ns,
                    image_msg(ts, np.asarray(im.image), im.encoding, im.frame, im.stamp_ns),
                )
            )
        for ci in camera_infos:
            msg = camera_info_msg(ts, ci.intrinsics, ci.width, ci.height, ci.frame, ci.stamp_ns)
            messages.append((ci.topic, CAMERA_INFO, ci.stamp_ns, msg))
    for t in tf:
        topic = "/tf_static" if t.static else "/tf"
        messages.append(
            (topic, TF_MESSAGE, t.stamp_ns, tf_msg(ts, [(t.parent, t.child, np.asarray(t.T))], t.stamp_ns))
        )
    messages.sort(key=lambda m: m[2])
    if path.exists():  # as rosbags' writers: a recording is never overwritten
        raise InputError(f"recording {path} exists already; not overwriting it")
    with staged_directory(path, "recording") as staged:  # a full disk leaves nothing at path
        _write(staged / path.name, fmt, ts, messages)
        os.replace(staged / path.name, path)


def _write(path: Path, fmt: str, ts: Any, messages: list[tuple[str, str, int, Any]]) -> None:
    if fmt == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        with Writer1(path) as w1:
            conns1: dict[tuple[str, str], Any] = {}
            for topic, msgtype, ns, msg in messages:
                if (topic, msgtype) not in conns1:
                    conns1[(topic, msgtype)] = w1.add_connection(topic, msgtype, typestore=ts)
                w1.write(conns1[(topic, msgtype)], ns, ts.serialize_ros1(msg, msgtype))
        return
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if fmt == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w2:
        conns2: dict[tuple[str, str], Any] = {}
        for topic, msgtype, ns, msg in messages:
            if (topic, msgtype) not in conns2:
                conns2[(topic, msgtype)] = w2.add_connection(topic, msgtype, typestore=ts)
            w2.write(conns2[(topic, msgtype)], ns, ts.serialize_cdr(msg, msgtype))
