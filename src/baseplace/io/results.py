"""Results out as an MCAP file (ROS 2 messages) that Foxglove and RViz open.

Topics (all in the world frame, stamped with the input's stamp):

* ``/baseplace/placements`` geometry_msgs/PoseStamped, one message per verified placement (the base
  pose, z on its support plane), best first;
* ``/baseplace/candidates`` geometry_msgs/PoseArray of the candidates (one message);
* ``/baseplace/path`` nav_msgs/Path, one message per path;
* ``/baseplace/regions`` visualization_msgs/MarkerArray: each planar region's polygon outline as a
  LINE_STRIP on its plane (one marker per ring), namespace ``region``, id = region id x 100 + ring;
* ``/baseplace/targets`` geometry_msgs/PoseArray of the TCP targets.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.files import atomic_write, staged_directory
from baseplace.io.messages import header, pose_msg

FloatArray = NDArray[np.float64]

PLACEMENTS_TOPIC = "/baseplace/placements"
CANDIDATES_TOPIC = "/baseplace/candidates"
PATH_TOPIC = "/baseplace/path"
REGIONS_TOPIC = "/baseplace/regions"
TARGETS_TOPIC = "/baseplace/targets"


@dataclass
class ResultMessages:
    """What to write.

    Attributes:
        world_frame: frame_id of every message.
        stamp_ns: header stamp and log time [ns].
        placements: (4, 4) world_T_base of each placement.
        candidates: (4, 4) world_T_base of each candidate.
        paths: base paths, each (K, 3) x [m], y [m], yaw [rad], or (K, 2) x, y (yaw along the path); z = 0.
        regions: (region id, rings) with rings (M, 3) world points of each polygon ring.
        targets: (4, 4) world TCP targets.
    """

    world_frame: str
    stamp_ns: int
    placements: list[FloatArray] = field(default_factory=list)
    candidates: list[FloatArray] = field(default_factory=list)
    paths: list[FloatArray] = field(default_factory=list)
    regions: list[tuple[int, list[FloatArray]]] = field(default_factory=list)
    targets: list[FloatArray] = field(default_factory=list)


def _base_T(x: float, y: float, yaw: float, z: float = 0.0) -> FloatArray:
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = [x, y, z]
    return T


def _with_yaw(poses: Any) -> FloatArray:
    """(K, 3) x, y, yaw of a path given as (K, 3), or as (K, 2) points (yaw: the direction of travel)."""
    p = np.asarray(poses, dtype=float).reshape(len(poses), -1)
    if p.shape[1] >= 3:
        return p[:, :3]
    step = np.diff(p[:, :2], axis=0)
    yaw = np.arctan2(step[:, 1], step[:, 0]) if len(step) else np.zeros(0)
    return np.c_[p[:, :2], np.r_[yaw, yaw[-1:] if len(yaw) else [0.0]]]


def _marker_array(ts: Any, res: ResultMessages) -> Any:
    g = ts.types
    markers = []
    for rid, rings in res.regions:
        hue = (rid * 0.61803) % 1.0
        rgb = np.clip(np.abs((hue * 6 + np.array([0, 4, 2])) % 6 - 3) - 1, 0, 1)
        for k, ring in enumerate(rings):
            markers.append(g["visualization_msgs/msg/Marker"](
                header=header(ts, res.world_frame, res.stamp_ns), ns="region", id=int(rid) * 100 + k,
                type=4, action=0, pose=pose_msg(ts, np.eye(4)),
                scale=g["geometry_msgs/msg/Vector3"](x=0.02, y=0.0, z=0.0),
                color=g["std_msgs/msg/ColorRGBA"](r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=1.0),
                lifetime=g["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
                points=[g["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in ring],
                colors=[], texture_resource="", texture=g["sensor_msgs/msg/CompressedImage"](
                    header=header(ts, "", 0), format="", data=np.zeros(0, dtype=np.uint8)),
                uv_coordinates=[], text="", mesh_resource="",
                mesh_file=g["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
                mesh_use_embedded_materials=False,
            ))  # fmt: skip
    return g["visualization_msgs/msg/MarkerArray"](markers=markers)


def write_result_mcap(path: str | Path, res: ResultMessages) -> None:
    """Write ``res`` to ``path`` (an ``.mcap`` file) atomically; nothing is left behind on failure."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if path.suffix != ".mcap":
        raise InputError(f"the result recording must end in .mcap, got {path.name!r}")
    if not path.parent.is_dir():
        raise InputError(f"cannot write {path}: directory {path.parent} does not exist")
    ts = get_typestore(Stores.ROS2_HUMBLE)
    g = ts.types
    with staged_directory(path, "MCAP result") as tmp:
        bag = tmp / "bag"
        writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        try:

            def put(topic: str, msgtype: str, messages: Sequence[Any]) -> None:
                if not messages:
                    return
                conn = writer.add_connection(topic, msgtype, typestore=ts)
                for m in messages:
                    writer.write(conn, res.stamp_ns, ts.serialize_cdr(m, msgtype))

            h = header(ts, res.world_frame, res.stamp_ns)
            put(PLACEMENTS_TOPIC, "geometry_msgs/msg/PoseStamped",
                [g["geometry_msgs/msg/PoseStamped"](header=h, pose=pose_msg(ts, T)) for T in res.placements])  # fmt: skip
            for topic, poses in ((CANDIDATES_TOPIC, res.candidates), (TARGETS_TOPIC, res.targets)):
                if poses:
                    put(topic, "geometry_msgs/msg/PoseArray",
                        [g["geometry_msgs/msg/PoseArray"](header=h, poses=[pose_msg(ts, T) for T in poses])])  # fmt: skip
            put(PATH_TOPIC, "nav_msgs/msg/Path", [
                g["nav_msgs/msg/Path"](header=h, poses=[
                    g["geometry_msgs/msg/PoseStamped"](header=h, pose=pose_msg(ts, _base_T(*p)))
                    for p in _with_yaw(poses)])
                for poses in res.paths])  # fmt: skip
            if res.regions:
                put(REGIONS_TOPIC, "visualization_msgs/msg/MarkerArray", [_marker_array(ts, res)])
            writer.close()
        except BaseException:
            _abandon(writer)
            raise
        files = list(bag.glob("*.mcap"))
        if len(files) != 1:
            raise InputError(f"the MCAP writer left {len(files)} files in {bag}")
        with atomic_write(path, "MCAP result") as out:
            os.replace(files[0], out)


def _abandon(writer: Any) -> None:
    """Close the file a failed writer holds open.

    rosbags keeps it when a write or its ``close`` fails (a full disk), and a long-running service
    would leak the descriptor.
    """
    bio = getattr(getattr(writer, "storage", None), "bio", None)
    if bio is not None:
        with contextlib.suppress(OSError):
            bio.close()  # closes the file even when its last flush fails


def read_result_mcap(path: str | Path) -> dict[str, list[Any]]:
    """Every message of a result MCAP by topic, deserialized (for checks and round trips)."""
    from rosbags.highlevel import AnyReader

    out: dict[str, list[Any]] = {}
    with AnyReader([Path(path)]) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out
