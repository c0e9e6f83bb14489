"""A conservative pre-filter in front of coal for one arm's state checks: coal's verdicts, faster.

:meth:`Environment.colliding_arm <baseplace.world.environment.Environment.colliding_arm>` asks coal
about every (robot geometry, scene part) pair and every arm-pruned self-collision pair: about
1.2 ms per state on TIAGo, most of it on pairs far apart. Here each robot collision geometry gets
one sphere that truly contains it (:func:`bounding_sphere`), placed by the arm's compiled chain
(:func:`~baseplace.robots.spheres._joint_frames`, the kernel of the sphere model). A pair is
*certified free* when the sphere is farther from the other side than the pair's security margin:

* an OcTree part: no occupied box centre (coal's own boxes, :meth:`coal.OcTree.toBoxes`) within
  the sphere's radius + the margin + the box's half diagonal (:class:`~baseplace.world.point_index.PointIndex`);
* a convex part (the exact support plane's prism): the largest signed distance to the planes of
  its hull faces, a lower bound of the distance to it, above radius + margin;
* any other part (an obstacle given by hand) and another robot geometry: sphere against sphere.

Only the pairs not certified go to coal (``pinocchio.computeCollision``, the same call, request
and margin as the full check), so the verdict is coal's. Geometries no arm joint moves are
checked against the scene once per base pose and the answer kept.
"""

from __future__ import annotations

import math

import coal
import numba as nb
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull

from baseplace.geometry.poses import FloatArray
from baseplace.robots.model import Arm, Robot
from baseplace.robots.spheres import _joint_frames, _place
from baseplace.world.point_index import PointIndex, _clear

SLACK = 1e-6
"""Added [m] to every certified distance: rounding in coal's and this module's arithmetic."""
HASH_CELL = 0.05
"""Cell edge [m] of the box-centre hashes (about a link sphere's radius)."""


def bounding_sphere(geometry: coal.CollisionGeometry) -> tuple[FloatArray, float]:
    """A sphere (centre (3,), radius [m]) in the geometry's frame that contains the whole geometry.

    A mesh or convex lies in the hull of its vertices: their bounding box's centre and the
    farthest vertex from it. A sphere, box or cylinder from its exact extents; any other shape
    from its local bounding box.
    """
    if isinstance(geometry, coal.Sphere):
        return np.zeros(3), float(geometry.radius)
    if isinstance(geometry, coal.Box):
        return np.zeros(3), float(np.linalg.norm(geometry.halfSide))
    if isinstance(geometry, coal.Cylinder):
        return np.zeros(3), math.hypot(float(geometry.radius), float(geometry.halfLength))
    points = hull_points(geometry)  # for a bounding box's corners: its centre and half diagonal
    centre = (points.min(axis=0) + points.max(axis=0)) / 2
    return centre, float(np.max(np.linalg.norm(points - centre, axis=1)))


def hull_points(geometry: coal.CollisionGeometry) -> FloatArray:
    """(k, 3) points whose convex hull holds the geometry, in its own frame.

    A mesh's or convex's vertices, else the corners of its local bounding box.
    """
    vertices = _vertices(geometry)
    if vertices is not None:
        return vertices
    geometry.computeLocalAABB()
    box = geometry.aabb_local
    lo, hi = np.asarray(box.min_, dtype=float), np.asarray(box.max_, dtype=float)
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _vertices(geometry: coal.CollisionGeometry) -> FloatArray | None:
    """(k, 3) the vertices of a mesh or convex in its frame, or None for other shapes."""
    if isinstance(geometry, coal.BVHModelBase) and geometry.num_vertices:
        return np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)
    if isinstance(geometry, coal.ConvexBase) and geometry.num_points:
        return np.asarray(geometry.points(), dtype=float).reshape(-1, 3)
    return None


@nb.njit(cache=True)
def _arm_centres(q, placements, axes, kinds, joint, local, out):
    """Sphere centres (G, 3) in the arm's base frame: ``local`` in the frame of arm joint ``joint`` (-1: fixed)."""
    F = np.empty((q.shape[0], 3, 4))
    R, t = np.empty((3, 3)), np.empty(3)
    _joint_frames(q, placements, axes, kinds, F, R, t)
    _place(joint, local, F, out)


@nb.njit(cache=True)
def _transformed(C, T, out):
    """Points C (G, 3) moved by the rigid transform T (4, 4), into ``out``."""
    for k in range(C.shape[0]):
        for a in range(3):
            out[k, a] = T[a, 0] * C[k, 0] + T[a, 1] * C[k, 1] + T[a, 2] * C[k, 2] + T[a, 3]


@nb.njit(cache=True)
def _uncertified_pairs(C, radius, pairs, reach):
    """Indices of the sphere pairs (P, 2) of centres C whose distance is not above ``reach`` (P,) + radii."""
    out = np.empty(pairs.shape[0], dtype=np.int64)
    n = 0
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        dx, dy, dz = C[a, 0] - C[b, 0], C[a, 1] - C[b, 1], C[a, 2] - C[b, 2]
        r = radius[a] + radius[b] + reach[p]
        if dx * dx + dy * dy + dz * dz <= r * r:
            out[n] = p
            n += 1
    return out[:n]


class _Part:
    """One scene geometry and the robot geometries paired with it: which pairs a state leaves to coal."""

    def __init__(self, geometry: coal.CollisionGeometry, T_world_part: FloatArray) -> None:
        self.robot: list[int] = []  # robot geometry ids paired with this part
        self.pair: list[int] = []  # their collision pair index
        self.margin: list[float] = []  # and security margin [m]
        self.indexes: list[tuple[PointIndex, float]] = []  # OcTree: (box centres, half diagonal)
        self.planes: FloatArray | None = None  # convex: (H, 4) unit normal, offset (inside: <= 0)
        self.sphere: tuple[FloatArray, float] | None = None  # anything else: its bounding sphere
        if isinstance(geometry, coal.OcTree):
            boxes = np.array(geometry.toBoxes(), dtype=float).reshape(-1, 6)
            for size in np.unique(boxes[:, 3]):
                centres = boxes[boxes[:, 3] == size, :3]
                self.indexes.append((PointIndex(centres, HASH_CELL), float(size) * math.sqrt(3) / 2))
            return
        vertices = _vertices(geometry) if isinstance(geometry, coal.ConvexBase) else None
        if vertices is not None and len(vertices) >= 4:
            world = vertices @ T_world_part[:3, :3].T + T_world_part[:3, 3]
            self.planes = ConvexHull(world).equations  # unit normals
            return
        c, r = bounding_sphere(geometry)
        self.sphere = (T_world_part[:3, :3] @ c + T_world_part[:3, 3], r)

    def subset(self, keep: list[int], radius: FloatArray) -> _Part:
        """This part with only its pairs ``keep`` (indices into its pairs), finished (:meth:`finish`)."""
        out = _Part.__new__(_Part)
        out.indexes, out.planes, out.sphere = self.indexes, self.planes, self.sphere
        out.robot = [self.robot[n] for n in keep]
        out.pair = [self.pair[n] for n in keep]
        out.margin = [self.margin[n] for n in keep]
        out.finish(radius)
        return out

    def finish(self, radius: FloatArray) -> None:
        """Fix the pairs; ``radius`` (G,): the robot geometries' bounding radii [m]."""
        self.robot_a = np.array(self.robot, dtype=np.int64)
        self.pair_a = np.array(self.pair, dtype=np.int64)
        self.reach = radius[self.robot_a] + np.array(self.margin, dtype=float) + SLACK
        """(P,) how far [m] each pair's sphere centre must stay from the part."""
        self._arrays = [
            (index._arrays(), self.reach + half_diagonal) for index, half_diagonal in self.indexes
        ]
        self._free = np.empty(len(self.robot_a), dtype=np.bool_)

    def uncertified(self, C_world: FloatArray) -> NDArray[np.int64]:
        """The pair indices of this part that the bounding spheres (centres (G, 3), world frame) do not clear."""
        if len(self.robot_a) == 0:
            return self.pair_a
        C = C_world[self.robot_a]
        if self._arrays:
            free = np.ones(len(C), dtype=bool)
            for arrays, reach in self._arrays:
                _clear(self._free, C, reach, *arrays)
                free &= self._free
        elif self.planes is not None:
            free = np.max(C @ self.planes[:, :3].T + self.planes[:, 3], axis=1) > self.reach
        else:
            assert self.sphere is not None
            centre, r = self.sphere
            free = np.linalg.norm(C - centre, axis=1) > self.reach + r
        return self.pair_a[~free]


class StateFilter:
    """Whether the robot, its arm at joint values, touches the scene or itself: coal's verdict, pre-filtered.

    Args:
        robot: the robot.
        arm: the arm whose joints move (every other joint at its reference value).
        scene: (model, data, geometry model, geometry data) of the scene check; robot geometries
            first, then the scene's, placed in the robot's root frame by ``place_scene``.
        n_robot: how many of the scene model's geometries are the robot's.
        T_world_part: per scene geometry id, its world pose (4, 4); absent: the world frame.
        place_scene: places the scene geometries for a base pose (4, 4) (before coal is asked).
        T_root_base: the base frame in the robot's root frame at the reference configuration.
        self_check: (model, data, geometry model, geometry data) of self-collision, or None;
            its active pairs are the ones checked.
    """

    def __init__(
        self,
        robot: Robot,
        arm: Arm,
        scene: tuple[pin.Model, pin.Data, pin.GeometryModel, pin.GeometryData],
        n_robot: int,
        T_world_part: dict[int, FloatArray],
        place_scene: object,
        T_root_base: pin.SE3,
        self_check: tuple[pin.Model, pin.Data, pin.GeometryModel, pin.GeometryData] | None,
    ) -> None:
        self.robot, self.arm = robot, arm
        self.scene, self.self_check, self._place_scene = scene, self_check, place_scene
        model, _, geom, gdata = scene
        ref = model.createData()
        pin.forwardKinematics(model, ref, robot.q_reference)
        pin.updateFramePlacements(model, ref)
        T_root_armbase = ref.oMf[model.getFrameId(arm.base_frame)]
        self._T_base_armbase = (T_root_base.inverse() * T_root_armbase).homogeneous
        armbase_inv = T_root_armbase.inverse()
        arm_ids = [model.getJointId(j) for j in arm.joint_names]
        joint, local, radius = [], [], []
        gref = pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, ref, geom, gref)
        for k in range(n_robot):
            obj = geom.geometryObjects[k]
            supports = set(model.supports[obj.parentJoint])
            j = max((i for i, a in enumerate(arm_ids) if a in supports), default=-1)
            frame = armbase_inv * ref.oMi[arm_ids[j]] if j >= 0 else pin.SE3.Identity()
            T = frame.inverse() * armbase_inv * gref.oMg[k]  # the geometry in its moving frame
            c, r = bounding_sphere(obj.geometry)
            joint.append(j)
            local.append(T.rotation @ c + T.translation)
            radius.append(r)
        self.joint = np.array(joint, dtype=np.int64)
        """(G,) per robot geometry the arm joint that moves it, -1 for none."""
        self.local = np.array(local, dtype=float).reshape(-1, 3)
        """(G, 3) its bounding sphere's centre in that joint's frame (or the arm's base frame) [m]."""
        self.radius = np.array(radius, dtype=float)
        """(G,) the bounding sphere's radius [m]."""
        moving = self.joint >= 0
        by_gid: dict[int, _Part] = {}
        for i, pair in enumerate(geom.collisionPairs):
            if not gdata.activeCollisionPairs[i]:
                continue
            k, gid = int(pair.first), int(pair.second)
            if gid not in by_gid:
                T = T_world_part.get(gid, np.eye(4))
                by_gid[gid] = _Part(geom.geometryObjects[gid].geometry, np.asarray(T, dtype=float))
            part = by_gid[gid]
            part.robot.append(k)
            part.pair.append(i)
            part.margin.append(float(gdata.collisionRequests[i].security_margin))
        self.parts: list[_Part] = []  # per scene part: its pairs with geometries the arm moves
        self._static_parts: list[_Part] = []  # and with those it does not (checked once per base pose)
        for part in by_gid.values():
            arm_moves = [bool(moving[k]) for k in part.robot]
            self.parts.append(part.subset([n for n, m in enumerate(arm_moves) if m], self.radius))
            self._static_parts.append(part.subset([n for n, m in enumerate(arm_moves) if not m], self.radius))
        self._self_pairs = np.zeros((0, 2), dtype=np.int64)
        self._self_index = np.zeros(0, dtype=np.int64)
        self._self_reach = np.zeros(0)
        if self_check is not None:
            _, _, sgeom, sdata = self_check
            active = [i for i in range(len(sgeom.collisionPairs)) if sdata.activeCollisionPairs[i]]
            pairs = sgeom.collisionPairs
            self._self_pairs = np.array(
                [(pairs[i].first, pairs[i].second) for i in active], dtype=np.int64
            ).reshape(-1, 2)
            self._self_index = np.array(active, dtype=np.int64)
            self._self_reach = np.array(
                [sdata.collisionRequests[i].security_margin + SLACK for i in active], dtype=float
            )
        self._static_key: bytes | None = None
        self._static_hit = False
        self._centres = np.empty((n_robot, 3))
        self._world = np.empty((n_robot, 3))
        self.coal_pairs = 0
        """Pairs handed to coal so far (scene and self), for measurements."""

    def centres(self, q_arm: ArrayLike) -> FloatArray:
        """(G, 3) the bounding spheres' centres in the arm's base frame at arm joint values (n,) [m]."""
        q = np.ascontiguousarray(q_arm, dtype=float)
        a = self.arm
        _arm_centres(q, a.placements, a.axes, a.kinds, self.joint, self.local, self._centres)
        return self._centres

    def colliding(self, q_arm: ArrayLike, T_world_base: ArrayLike) -> bool:
        """Coal's verdict for arm joint values (n,) at base pose (4, 4): the robot touches the scene or itself."""
        q_arm = np.asarray(q_arm, dtype=float)
        T = np.asarray(T_world_base, dtype=float)
        q_full = self.arm.to_pinocchio(q_arm, self.robot.q_reference)
        C = self.centres(q_arm)
        key = T.tobytes()
        new_pose = key != self._static_key
        if new_pose:
            self._static_key = key
            self._T_world_armbase = T @ self._T_base_armbase
        _transformed(C, self._T_world_armbase, self._world)
        if new_pose:
            todo = [p for part in self._static_parts for p in part.uncertified(self._world)]
            self._static_hit = self._scene_coal(todo, q_full, T)
        if self._static_hit:
            return True
        todo = [p for part in self.parts for p in part.uncertified(self._world)]
        if todo and self._scene_coal(todo, q_full, T):
            return True
        if self.self_check is None:
            return False
        near = _uncertified_pairs(C, self.radius, self._self_pairs, self._self_reach)
        if len(near) == 0:
            return False
        model, data, geom, gdata = self.self_check
        pin.forwardKinematics(model, data, q_full)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        self.coal_pairs += len(near)
        return any(pin.computeCollision(geom, gdata, int(i)) for i in self._self_index[near])

    def _scene_coal(self, pairs: list[int], q_full: FloatArray, T_world_base: FloatArray) -> bool:
        if not pairs:
            return False
        model, data, geom, gdata = self.scene
        self._place_scene(T_world_base)  # type: ignore[operator]
        pin.forwardKinematics(model, data, q_full)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        self.coal_pairs += len(pairs)
        return any(pin.computeCollision(geom, gdata, int(i)) for i in pairs)


__all__ = ["SLACK", "StateFilter", "bounding_sphere", "hull_points"]
