"""A tf2 buffer without ROS: transforms from /tf and /tf_static, looked up at a time stamp.

``TfTree.lookup(target, source, stamp)`` returns ``T_target_source`` (maps points from the source
frame to the target frame, as ``tf2_ros.Buffer.lookup_transform(target, source, time)``): the
chain of edges between the two frames, each static edge as stored and each dynamic edge linearly
interpolated between the two recorded transforms around ``stamp`` (slerp for the rotation), as
tf2 does. A stamp outside a dynamic edge's recorded range by more than ``tolerance_ns`` raises.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation, Slerp

from baseplace.errors import InputError, choices

FloatArray = NDArray[np.float64]


def transform_matrix(translation: FloatArray, quaternion_xyzw: FloatArray) -> FloatArray:
    """(4, 4) homogeneous transform from a translation (3,) [m] and a quaternion (x, y, z, w)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(np.asarray(quaternion_xyzw, dtype=float)).as_matrix()
    T[:3, 3] = translation
    return T


@dataclass
class _Edge:
    stamps: list[int] = field(default_factory=list)
    translations: list[FloatArray] = field(default_factory=list)
    quaternions: list[FloatArray] = field(default_factory=list)
    static: bool = False


def _fmt_stamp(ns: int) -> str:
    return f"{ns / 1e9:.3f} s"


@dataclass
class TfTree:
    """Recorded transforms, keyed by (parent frame, child frame).

    Attributes:
        tolerance_ns: how far a stamp may lie outside a dynamic edge's recorded range [ns].
    """

    tolerance_ns: int = 100_000_000
    _edges: dict[tuple[str, str], _Edge] = field(default_factory=dict)

    def add(
        self,
        parent: str,
        child: str,
        stamp_ns: int,
        translation: FloatArray,
        quaternion_xyzw: FloatArray,
        static: bool,
    ) -> None:
        """Record ``T_parent_child`` at ``stamp_ns`` (static: valid at every time)."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        edge = self._edges.setdefault((parent, child), _Edge(static=static))
        q = np.asarray(quaternion_xyzw, dtype=float)
        if not np.all(np.isfinite(q)) or np.linalg.norm(q) < 1e-9:
            raise InputError(f"transform {parent} -> {child} has an invalid quaternion {q.tolist()}")
        if static:
            edge.static = True
            edge.stamps, edge.translations, edge.quaternions = (
                [stamp_ns],
                [np.asarray(translation, float)],
                [q],
            )
            return
        k = bisect.bisect_left(edge.stamps, stamp_ns)
        edge.stamps.insert(k, stamp_ns)
        edge.translations.insert(k, np.asarray(translation, dtype=float))
        edge.quaternions.insert(k, q)

    @property
    def frames(self) -> set[str]:
        """Every frame named in the tree."""
        return {f for pair in self._edges for f in pair}

    def _edge_at(self, parent: str, child: str, stamp_ns: int, target: str, source: str) -> FloatArray:
        edge = self._edges[(parent, child)]
        if edge.static or (len(edge.stamps) == 1 and abs(edge.stamps[0] - stamp_ns) <= self.tolerance_ns):
            return transform_matrix(edge.translations[0], edge.quaternions[0])
        stamps = edge.stamps
        k = bisect.bisect_left(stamps, stamp_ns)
        if k < len(stamps) and stamps[k] == stamp_ns:
            return transform_matrix(edge.translations[k], edge.quaternions[k])
        if 0 < k < len(stamps):
            t0, t1 = stamps[k - 1], stamps[k]
            a = (stamp_ns - t0) / (t1 - t0)
            rot = Slerp([0.0, 1.0], Rotation.from_quat([edge.quaternions[k - 1], edge.quaternions[k]]))([a])
            T = np.eye(4)
            T[:3, :3] = rot.as_matrix()[0]
            T[:3, 3] = (1 - a) * edge.translations[k - 1] + a * edge.translations[k]
            return T
        nearest = stamps[0] if k == 0 else stamps[-1]
        if abs(nearest - stamp_ns) <= self.tolerance_ns:
            j = 0 if k == 0 else len(stamps) - 1
            return transform_matrix(edge.translations[j], edge.quaternions[j])
        raise InputError(
            f"no transform from {source!r} to {target!r} at {_fmt_stamp(stamp_ns)}: the edge {parent} -> "
            f"{child} is recorded from {_fmt_stamp(stamps[0])} to {_fmt_stamp(stamps[-1])} "
            f"({len(stamps)} stamps; nearest {_fmt_stamp(nearest)})"
        )

    def lookup(self, target: str, source: str, stamp_ns: int) -> FloatArray:
        """``T_target_source`` (4, 4) at ``stamp_ns``: ``p_target = T @ p_source``.

        Raises:
            InputError: a frame the tree does not know, frames not connected, or a stamp outside
                the recorded range of a dynamic edge on the way (naming the nearest stamps).
        """
        target, source = target.lstrip("/"), source.lstrip("/")
        if target == source:
            return np.eye(4)
        for frame in (target, source):
            if frame not in self.frames:
                raise InputError(
                    f"no transform from {source!r} to {target!r}: frame {frame!r} is not in /tf or "
                    f"/tf_static; frames: {choices(self.frames) or 'none'}"
                )
        path = self._path(source, target)
        if path is None:
            raise InputError(
                f"no transform from {source!r} to {target!r}: the frames are not connected in /tf and "
                f"/tf_static; frames: {choices(self.frames)}"
            )
        T = np.eye(4)  # T_target_current, walking from target towards source
        for a, b in zip(path[::-1][:-1], path[::-1][1:], strict=True):  # a -> b from the target side
            if (a, b) in self._edges:
                T = T @ self._edge_at(a, b, stamp_ns, target, source)
            else:
                T = T @ np.linalg.inv(self._edge_at(b, a, stamp_ns, target, source))
        return T

    def _path(self, source: str, target: str) -> list[str] | None:
        neighbours: dict[str, list[str]] = {}
        for parent, child in self._edges:
            neighbours.setdefault(parent, []).append(child)
            neighbours.setdefault(child, []).append(parent)
        previous: dict[str, str | None] = {source: None}
        queue = deque([source])
        while queue:
            frame = queue.popleft()
            if frame == target:
                path = [frame]
                while (prev := previous[path[-1]]) is not None:
                    path.append(prev)
                return path[::-1]  # source ... target
            for other in neighbours.get(frame, []):
                if other not in previous:
                    previous[other] = frame
                    queue.append(other)
        return None
