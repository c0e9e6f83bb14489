"""A tf2 buffer without ROS: transforms from /tf and /tf_static, looked up at a time stamp.

``TfTree.lookup(target, source, stamp)`` returns ``T_target_source`` (maps points from the source
frame to the target frame, as ``tf2_ros.Buffer.lookup_transform(target, source, time)``): the
chain of edges between the two frames, each static edge as stored and each dynamic edge linearly
interpolated between the two recorded transforms around ``stamp`` (slerp for the rotation), as
tf2 does. A stamp outside a dynamic edge's recorded range by more than ``tolerance_ns`` raises.
"""

from __future__ import annotations

from array import array
from collections import deque
from collections.abc import Sequence
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


MAX_TRANSFORMS = 1_000_000
"""Most stamped transforms one tree (one recording's /tf and /tf_static) may record."""


@dataclass
class _Edge:
    """One parent -> child edge: its transforms appended as they come, sorted once when looked up.

    A stamp recorded twice keeps its first transform.
    """

    static: bool = False
    _stamps: array[int] = field(default_factory=lambda: array("q"))
    _poses: array[float] = field(default_factory=lambda: array("d"))  # tx ty tz qx qy qz qw per stamp
    _in_order: bool = True
    _sorted: tuple[NDArray[np.int64], FloatArray] | None = None

    def extend(self, stamps: NDArray[np.int64], poses: FloatArray) -> None:
        """Append transforms (n,) stamps and (n, 7) poses, dropping stamps equal to the one before."""
        keep = np.r_[True, stamps[1:] != stamps[:-1]]
        if self._stamps and stamps[0] == self._stamps[-1]:
            keep[0] = False
        stamps, poses = stamps[keep], poses[keep]
        if not len(stamps):
            return
        ascending = (not self._stamps or stamps[0] > self._stamps[-1]) and bool(
            np.all(stamps[1:] > stamps[:-1])
        )
        self._in_order = self._in_order and ascending
        self._stamps.frombytes(stamps.astype(np.int64).tobytes())
        self._poses.frombytes(np.ascontiguousarray(poses, dtype=np.float64).tobytes())
        self._sorted = None

    def replace(self, stamp_ns: int, pose: FloatArray) -> None:
        self._stamps, self._poses = array("q", [stamp_ns]), array("d", pose.tolist())
        self._in_order, self._sorted = True, None

    def arrays(self) -> tuple[NDArray[np.int64], FloatArray]:
        """Stamps (n,) ascending and unique, and poses (n, 7) (translation, quaternion x y z w)."""
        if self._sorted is None:
            stamps = np.array(self._stamps, dtype=np.int64)
            poses = np.array(self._poses, dtype=np.float64).reshape(-1, 7)
            if not self._in_order:
                order = np.argsort(stamps, kind="stable")
                stamps, poses = stamps[order], poses[order]
                first = np.r_[True, stamps[1:] != stamps[:-1]]
                stamps, poses = stamps[first], poses[first]
            self._sorted = (stamps, poses)
        return self._sorted


def _fmt_stamp(ns: int) -> str:
    return f"{ns / 1e9:.3f} s"


@dataclass
class TfTree:
    """Recorded transforms, keyed by (parent frame, child frame).

    Recording is linear in the number of transforms (appended, sorted once per edge at the first
    lookup); at most :data:`MAX_TRANSFORMS` may be recorded.

    Attributes:
        tolerance_ns: how far a stamp may lie outside a dynamic edge's recorded range [ns].
        count: transforms recorded so far (duplicates included).
    """

    tolerance_ns: int = 100_000_000
    count: int = 0
    _edges: dict[tuple[str, str], _Edge] = field(default_factory=dict)

    def add(
        self,
        parent: str,
        child: str,
        stamp_ns: int,
        translation: Sequence[float] | FloatArray,
        quaternion_xyzw: Sequence[float] | FloatArray,
        static: bool,
    ) -> None:
        """Record ``T_parent_child`` at ``stamp_ns`` (static: valid at every time).

        Raises:
            InputError: as :meth:`add_many`.
        """
        pose = np.concatenate(
            [np.asarray(translation, dtype=float), np.asarray(quaternion_xyzw, dtype=float)]
        )
        self.add_many([parent], [child], [stamp_ns], pose.reshape(1, -1), static)

    def add_many(
        self,
        parents: Sequence[str],
        children: Sequence[str],
        stamps_ns: Sequence[int],
        poses: FloatArray | Sequence[Sequence[float]],
        static: bool,
    ) -> None:
        """Record n transforms ``T_parent_child``: poses (n, 7) are translation [m] and quaternion (x, y, z, w).

        Raises:
            InputError: a translation or quaternion that is not finite, a quaternion of zero
                norm, or more than :data:`MAX_TRANSFORMS` transforms in all.
        """
        n = len(stamps_ns)
        if self.count + n > MAX_TRANSFORMS:
            raise InputError(
                f"more than {MAX_TRANSFORMS} transforms on /tf and /tf_static; the limit is {MAX_TRANSFORMS}"
            )
        self.count += n
        if not n:
            return
        pose = np.asarray(poses, dtype=float)
        if pose.shape != (n, 7):
            raise InputError(f"need {n} transforms of 3 + 4 numbers, got an array of shape {pose.shape}")
        bad = ~np.isfinite(pose).all(axis=1) | ~(np.einsum("ij,ij->i", pose[:, 3:], pose[:, 3:]) >= 1e-18)
        if bad.any():
            i = int(np.argmax(bad))
            raise InputError(
                f"transform {parents[i]} -> {children[i]} has an invalid translation or quaternion "
                f"{pose[i].tolist()}"
            )
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        groups: dict[tuple[str, str], list[int]] = {}
        for i, key in enumerate(zip(parents, children, strict=True)):
            groups.setdefault(key, []).append(i)
        for (parent, child), rows in groups.items():
            key = (parent.lstrip("/"), child.lstrip("/"))
            edge = self._edges.get(key)
            if edge is None:
                edge = self._edges[key] = _Edge(static=static)
            if static:
                edge.static = True
                edge.replace(int(stamps[rows[-1]]), pose[rows[-1]])
            elif len(rows) == n:
                edge.extend(stamps, pose)
            else:
                edge.extend(stamps[rows], pose[rows])

    @property
    def frames(self) -> set[str]:
        """Every frame named in the tree."""
        return {f for pair in self._edges for f in pair}

    def _edge_at(self, parent: str, child: str, stamp_ns: int, target: str, source: str) -> FloatArray:
        edge = self._edges[(parent, child)]
        stamps, poses = edge.arrays()
        if edge.static or (len(stamps) == 1 and abs(int(stamps[0]) - stamp_ns) <= self.tolerance_ns):
            return transform_matrix(poses[0, :3], poses[0, 3:])
        k = int(np.searchsorted(stamps, stamp_ns, side="left"))
        if k < len(stamps) and stamps[k] == stamp_ns:
            return transform_matrix(poses[k, :3], poses[k, 3:])
        if 0 < k < len(stamps):
            t0, t1 = int(stamps[k - 1]), int(stamps[k])
            a = (stamp_ns - t0) / (t1 - t0)
            rot = Slerp([0.0, 1.0], Rotation.from_quat(poses[k - 1 : k + 1, 3:]))([a])
            T = np.eye(4)
            T[:3, :3] = rot.as_matrix()[0]
            T[:3, 3] = (1 - a) * poses[k - 1, :3] + a * poses[k, :3]
            return T
        j = 0 if k == 0 else len(stamps) - 1
        nearest = int(stamps[j])
        if abs(nearest - stamp_ns) <= self.tolerance_ns:
            return transform_matrix(poses[j, :3], poses[j, 3:])
        raise InputError(
            f"no transform from {source!r} to {target!r} at {_fmt_stamp(stamp_ns)}: the edge {parent} -> "
            f"{child} is recorded from {_fmt_stamp(int(stamps[0]))} to {_fmt_stamp(int(stamps[-1]))} "
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
