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
* any other part (an obstacle given by hand) and another robot geometry: sphere against sphere;
* failing those, by the robot geometry's convex hull (:func:`convex_hull`, placed with its joint):
  every box centre near it, or every sphere of the other geometry's cover, farther than the reach
  outside one of its face planes, or else every point of the other's hull
  (:func:`~baseplace.world.state_kernel._hull_points_clear`); against the convex part, all its
  hull's points outside one of the part's planes. On the 72 table-grid dev motion checks about
  10 k states went to coal where the spheres alone sent 60 k (their times:
  bench/results/motion_verdicts_speed_dev.json); the hull points against the other's face
  planes took the self pairs' share of the states left to coal from 71 to 21 per check (the
  arm tucked beside the torso's column: ``bench/profile_motion_stages.py``, session 33).

Only the pairs not certified go to coal (``pinocchio.computeCollision``, the same call, request
and margin as the full check), so the verdict is coal's. Before that, a state whose scene pairs
are left is proven touching without coal where a witness ball inside a robot geometry
(:func:`contact_balls`: a mesh's vertices, balls inside a box, cylinder or sphere) lies closer to
an OcTree's box, or deeper inside a convex part, than the pair's margin less
:data:`CONTACT_DEPTH` (:func:`~baseplace.world.state_kernel._touch_proven`): coal's verdict
there is True. On the 72 table-grid dev motion checks, 40 of the 44 states a check sent to coal
with a scene pair touching (session 35). Geometries no arm joint moves are
checked against the scene once per base pose and the answer kept.

This module builds what the certificates read (spheres, covers, hulls, distance tables, anchor
fields, the scene parts packed) and hands coal what they leave; the compiled kernels that read
them are :mod:`~baseplace.world.state_kernel`.
"""

from __future__ import annotations

import functools
import math
import weakref
from collections.abc import Iterable, Iterator

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from baseplace.geometry.poses import FloatArray
from baseplace.robots.model import PRISMATIC, Arm, Robot
from baseplace.world.array_cache import cached_array
from baseplace.world.point_index import PointIndex, _clear
from baseplace.world.state_kernel import (
    _anchor_field,
    _arm_centres,
    _touch_proven,
    _transformed,
    _transformed_poses,
    _uncertified_line,
    _uncertified_poses,
    _uncertified_states,
)

LINE_ENTRIES = 4_000_000
"""A line's check (:meth:`StateFilter.first_colliding_line`) keeps a gap per pair and state: for
lines of more states times pairs than this (32 MB) the states are checked one by one instead."""
SLACK = 1e-6
"""Added [m] to every certified distance: rounding in coal's and this module's arithmetic."""
HASH_CELL = 0.05
"""Cell edge [m] of the box-centre hashes (about a link sphere's radius)."""
COVER_SPHERES = 16
"""At most this many spheres cover one robot geometry (:func:`sphere_cover`)."""
TABLE_SLACK = 0.003
"""Self pairs' distance tables: a grid step per joint such that no point moves more than this [m]
between a configuration and its nearest node (:func:`_distance_table`)."""
TABLE_NODES = 4000
"""At most this many nodes in one self pair's distance table (the steps are widened to fit)."""
TABLE_HARD = 0.1
"""A self pair gets a distance table when its spheres leave it to coal in this share of random
configurations."""
STOWED_SPREAD = 0.15
"""Standard deviation [rad or m] per joint of the configurations near the stowed one that choose
the self pairs' distance tables (:meth:`StateFilter._self_tables`)."""
COVER_RADIUS = 0.03
"""A cover's pieces are cut no further once their sphere's radius is within this [m]."""
ANCHOR_JOINTS = (-1, 0)
"""The frames of the anchor fields (:func:`_anchor_field`): the arm's base (the geometries no arm
joint moves) and arm joint 0's (those it moves with no other arm joint between)."""
ANCHOR_STEP = 0.01
"""Node spacing [m] of an anchor field (widened to stay within :data:`ANCHOR_NODES`)."""
ANCHOR_BAND = 0.3
"""An anchor field's grid reaches this far [m] beyond its geometries' bounding box."""
ANCHOR_NODES = 4_000_000
"""At most this many nodes in one anchor field."""
ANCHOR_CAP = 0.5
"""An anchor field's values are cut at this [m] (a lower bound still)."""
CONTACT_DEPTH = 1e-4
"""A contact is proven without coal (:func:`contact_balls`) only this much [m] inside the pair's
margin: coal's GJK decides within its tolerance (1e-6) and both sides round."""
CONTACT_BALLS = 64
"""At most this many witness balls per robot geometry (:func:`contact_balls`)."""


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


def sphere_cover(geometry: coal.CollisionGeometry) -> tuple[FloatArray, FloatArray]:
    """Spheres (centres (K, 3), radii (K,)) in the geometry's frame whose union holds the whole geometry.

    The convex hull of :func:`hull_points`, cut in halves by planes across its longest principal
    axis, the piece with the largest sphere first, until :data:`COVER_SPHERES` pieces or every
    sphere within :data:`COVER_RADIUS`. A piece of a convex polytope cut by a plane is the hull
    of its vertices on that side and the points where its edges cross the plane, so the sphere
    around those points holds the piece. One sphere (the :func:`bounding_sphere`) for a flat
    geometry.
    """
    centre, radius = bounding_sphere(geometry)
    one = (centre[None], np.array([radius]))
    pieces = [_ball(hull_points(geometry))]
    while len(pieces) < COVER_SPHERES:
        k = max(range(len(pieces)), key=lambda i: pieces[i][2])
        V, _, r = pieces[k]
        halves = _halves(V) if r > COVER_RADIUS else None
        if halves is None:
            break
        pieces[k : k + 1] = [_ball(h) for h in halves]
    if len(pieces) == 1:
        return one
    return np.array([c for _, c, _ in pieces]), np.array([r for _, _, r in pieces])


def contact_balls(geometry: coal.CollisionGeometry) -> tuple[FloatArray, FloatArray]:
    """Balls (centres (K, 3), radii (K,)) in the geometry's frame, each wholly within the geometry (radius 0: a point of it).

    The witnesses of :func:`~baseplace.world.state_kernel._touch_proven`: where one lies closer
    to an obstacle than a pair's margin (less :data:`CONTACT_DEPTH`) plus its radius, coal finds
    the pair touching. A mesh (coal's meshes are triangle surfaces, not solids): vertices of its
    triangles, radius 0; a convex: its points; a box: the 27 points of a 3 x 3 x 3 lattice over
    it, each with the largest ball around it inside the box (the centre's: the smallest half
    side); a cylinder: 5 points on its axis (balls up to its radius) and 8 on each rim; a sphere:
    its centre and radius. At most :data:`CONTACT_BALLS`, spread by farthest-point order (the
    largest balls first). Any other shape: none (its pairs go to coal).
    """
    if isinstance(geometry, coal.Sphere):
        return np.zeros((1, 3)), np.array([float(geometry.radius)])
    if isinstance(geometry, coal.Box):
        h = np.asarray(geometry.halfSide, dtype=float)
        C = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)], dtype=float) * h
        return _spread(C, np.min(h - np.abs(C), axis=1))
    if isinstance(geometry, coal.Cylinder):
        r, L = float(geometry.radius), float(geometry.halfLength)
        axis = np.array([[0.0, 0.0, z] for z in np.linspace(-L, L, 5)])
        angles = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
        rims = np.array([[r * np.cos(a), r * np.sin(a), z] for z in (-L, L) for a in angles])
        return _spread(
            np.concatenate([axis, rims]),
            np.concatenate([np.minimum(r, L - np.abs(axis[:, 2])), np.zeros(16)]),
        )
    if isinstance(geometry, coal.BVHModelBase) and geometry.num_tris:
        triangles = [geometry.tri_indices(t) for t in range(geometry.num_tris)]
        used = np.unique(np.array([[t[0], t[1], t[2]] for t in triangles], dtype=np.int64))
        V = np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)[used]
        return _spread(V, np.zeros(len(V)))
    if isinstance(geometry, coal.ConvexBase) and geometry.num_points:
        V = np.asarray(geometry.points(), dtype=float).reshape(-1, 3)
        return _spread(V, np.zeros(len(V)))
    return np.zeros((0, 3)), np.zeros(0)


def _spread(C: FloatArray, radii: FloatArray) -> tuple[FloatArray, FloatArray]:
    """At most :data:`CONTACT_BALLS` of the balls (C (K, 3), radii (K,)): the largest first, then each the farthest from those taken."""
    order = [int(np.argmax(radii))]
    d = np.linalg.norm(C - C[order[0]], axis=1)
    while len(order) < min(len(C), CONTACT_BALLS):
        k = int(np.argmax(d))
        if not d[k] > 0.0:  # the rest repeat a ball taken
            break
        order.append(k)
        d = np.minimum(d, np.linalg.norm(C - C[k], axis=1))
    return np.ascontiguousarray(C[order]), np.ascontiguousarray(radii[order])


def _sphere_covers(geometries: list[coal.CollisionGeometry]) -> list[tuple[FloatArray, FloatArray]]:
    """:func:`sphere_cover` of each geometry, kept on disk (0.2 s for TIAGo's 64, in every process).

    Packed as (G, :data:`COVER_SPHERES`, 4) centres and radii, NaN past a cover's last sphere
    (:func:`~baseplace.world.array_cache.cached_array`), keyed by what a cover is made of: each
    geometry's kind, :func:`bounding_sphere` and :func:`hull_points`.
    """
    inputs: list[FloatArray | float | str] = []
    for g in geometries:
        centre, radius = bounding_sphere(g)
        inputs += [type(g).__name__, centre, radius, hull_points(g)]
    packed = cached_array(
        "sphere_covers", inputs, (len(geometries), COVER_SPHERES, 4), np.float64,
        functools.partial(_packed_covers, geometries),
    )  # fmt: skip
    return [(P[~np.isnan(P[:, 3]), :3], P[~np.isnan(P[:, 3]), 3]) for P in packed]


def _packed_covers(geometries: list[coal.CollisionGeometry]) -> FloatArray:
    """:func:`_sphere_covers`, computed."""
    out = np.full((len(geometries), COVER_SPHERES, 4), np.nan)
    for k, g in enumerate(geometries):
        centres, radii = sphere_cover(g)
        out[k, : len(radii), :3], out[k, : len(radii), 3] = centres, radii
    return out


def _ball(V: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """The points (k, 3), the centre of their bounding box and the farthest point's distance from it (+ SLACK)."""
    c = (V.min(axis=0) + V.max(axis=0)) / 2
    return V, c, float(np.max(np.linalg.norm(V - c, axis=1))) + SLACK


def _halves(V: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """The vertex sets of the hull of V (k, 3) cut in two across its longest principal axis, or None if flat."""
    try:
        hull = ConvexHull(V)
    except (QhullError, ValueError):  # flat or too few points: no 3-D hull to cut
        return None
    _, _, axes = np.linalg.svd(V - V.mean(axis=0), full_matrices=False)
    t = V @ axes[0]
    cut = (t.min() + t.max()) / 2
    tri = hull.simplices
    edges = np.unique(
        np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]), axis=1), axis=0
    )
    ta, tb = t[edges[:, 0]], t[edges[:, 1]]
    cross = (np.minimum(ta, tb) < cut) & (np.maximum(ta, tb) > cut)
    w = ((cut - ta[cross]) / (tb[cross] - ta[cross]))[:, None]
    on_cut = V[edges[cross, 0]] * (1 - w) + V[edges[cross, 1]] * w
    vertices = V[hull.vertices]
    tv = t[hull.vertices]
    return np.concatenate([vertices[tv <= cut], on_cut]), np.concatenate([vertices[tv >= cut], on_cut])


def _vertices(geometry: coal.CollisionGeometry) -> FloatArray | None:
    """(k, 3) the vertices of a mesh or convex in its frame, or None for other shapes."""
    if isinstance(geometry, coal.BVHModelBase) and geometry.num_vertices:
        return np.asarray(geometry.vertices(), dtype=float).reshape(-1, 3)
    if isinstance(geometry, coal.ConvexBase) and geometry.num_points:
        return np.asarray(geometry.points(), dtype=float).reshape(-1, 3)
    return None


class _Part:
    """One scene geometry and the robot geometries paired with it: which pairs a state leaves to coal."""

    def __init__(self, geometry: coal.CollisionGeometry, T_world_part: FloatArray) -> None:
        self.robot: list[int] = []  # robot geometry ids paired with this part
        self.pair: list[int] = []  # their collision pair index
        self.margin: list[float] = []  # and security margin [m]
        self.indexes: list[tuple[PointIndex, float]] = []  # OcTree: (box centres, half diagonal)
        self.planes: FloatArray | None = None  # convex: (H, 4) unit normal, offset (inside: <= 0)
        self.edges = np.zeros((0, 4))  # convex: a supporting plane at each edge (:func:`_edge_planes`)
        self.sphere: tuple[FloatArray, float] | None = None  # anything else: its bounding sphere
        if isinstance(geometry, coal.OcTree):
            self.indexes = _box_indexes(geometry)
            return
        vertices = _vertices(geometry) if isinstance(geometry, coal.ConvexBase) else None
        if vertices is not None and len(vertices) >= 4:
            world = vertices @ T_world_part[:3, :3].T + T_world_part[:3, 3]
            self.planes = _distinct_planes(ConvexHull(world).equations)  # unit normals
            self.edges = _edge_planes(world, self.planes)
            return
        c, r = bounding_sphere(geometry)
        self.sphere = (T_world_part[:3, :3] @ c + T_world_part[:3, 3], r)

    def subset(self, keep: list[int], radius: FloatArray) -> _Part:
        """This part with only its pairs ``keep`` (indices into its pairs), finished (:meth:`finish`)."""
        out = _Part.__new__(_Part)
        out.indexes, out.planes, out.edges, out.sphere = self.indexes, self.planes, self.edges, self.sphere
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
        return self.pair_a[~self.clear(C_world[self.robot_a])]

    def clear(self, C: FloatArray, copies: int = 1) -> NDArray[np.bool_]:
        """Whether each of this part's pairs' spheres, centred at C (copies * P, 3) [m], clears the part.

        C holds the P pairs' centres ``copies`` times over (one block per base pose,
        :meth:`StateFilter.colliding_poses`), in the order of the pairs.
        """

        def tiled(reach: FloatArray) -> FloatArray:  # each pair's reach, once per block of C
            return reach if copies == 1 else np.tile(reach, copies)

        if self._arrays:
            free = np.ones(len(C), dtype=bool)
            buf = self._free if copies == 1 else np.empty(len(C), dtype=np.bool_)
            for arrays, reach in self._arrays:
                _clear(buf, C, tiled(reach), *arrays)
                free &= buf
            return free
        if self.planes is not None:
            return np.max(C @ self.planes[:, :3].T + self.planes[:, 3], axis=1) > tiled(self.reach)
        assert self.sphere is not None
        centre, r = self.sphere
        return np.linalg.norm(C - centre, axis=1) > tiled(self.reach) + r


_TABLES: weakref.WeakKeyDictionary[Robot, dict[tuple[str, bytes, bytes], tuple[NDArray[np.generic], ...]]] = (
    weakref.WeakKeyDictionary()
)
"""Per robot, the packed self pair tables of :meth:`StateFilter._self_tables` (they hold no reference to it)."""


def _box_indexes(tree: coal.OcTree) -> list[tuple[PointIndex, float]]:
    """Per box size of the OcTree's occupied boxes (:meth:`coal.OcTree.toBoxes`): their centres' index and half diagonal.

    Kept per tree (:data:`_BOX_INDEXES`): every environment built on the same tree shares them.
    """
    kept = _BOX_INDEXES.get(tree)
    if kept is None:
        boxes = np.array(tree.toBoxes(), dtype=float).reshape(-1, 6)
        kept = []
        for size in np.unique(boxes[:, 3]):
            centres = boxes[boxes[:, 3] == size, :3]
            kept.append((PointIndex(centres, HASH_CELL), float(size) * math.sqrt(3) / 2))
        _BOX_INDEXES[tree] = kept
    return kept


_BOX_INDEXES: weakref.WeakKeyDictionary[coal.OcTree, list[tuple[PointIndex, float]]] = (
    weakref.WeakKeyDictionary()
)
"""Per OcTree, the box indexes of :func:`_box_indexes` (they hold no reference to it)."""


_PACKED_ANCHORS: weakref.WeakKeyDictionary[
    Robot, dict[tuple[str, bytes, bytes, bytes, bytes], tuple[NDArray[np.generic], ...]]
] = weakref.WeakKeyDictionary()
"""Per robot, :meth:`StateFilter._anchor_fields`' packed arrays by arm, geometries' joints, self pairs, reaches and tables
(the kernel only reads them: every environment of the robot shares them)."""


_HULLS: weakref.WeakKeyDictionary[Robot, dict[int, list[tuple[FloatArray, FloatArray]]]] = (
    weakref.WeakKeyDictionary()
)
"""Per robot, the :func:`convex_hull` of each of its first n collision geometries (by n)."""


_COVERS: weakref.WeakKeyDictionary[Robot, dict[int, list[tuple[FloatArray, FloatArray]]]] = (
    weakref.WeakKeyDictionary()
)
"""Per robot, the :func:`sphere_cover` of each of its first n collision geometries (by n)."""


_CONTACTS: weakref.WeakKeyDictionary[Robot, dict[int, tuple[FloatArray, FloatArray]]] = (
    weakref.WeakKeyDictionary()
)
"""Per robot, the :func:`contact_balls` of its collision geometries that an arm moves, by geometry id
(the robot's geometries come first in every scene model, with the same ids)."""


_Table = tuple[list[int], FloatArray, FloatArray, list[int], FloatArray, FloatArray]
"""A self pair's distance table: joints, lower, step, nodes per joint, lever arms, values (:func:`_distance_table`)."""


def _reference_pose(
    robot: Robot, self_check: tuple[pin.Model, pin.Data, pin.GeometryModel, pin.GeometryData]
) -> tuple[pin.Data, pin.GeometryData, tuple[NDArray[np.generic] | str, ...]]:
    """The self model at the robot's reference configuration, for all of a filter's :func:`_distance_table` calls.

    Its joint and geometry placements, and the kinematic tree as part of a table's cache key: the
    joints' placements, axes (motion subspaces), parents and kinds, and the reference values.
    """
    model, _, geom, _ = self_check
    ref = model.createData()
    pin.forwardKinematics(model, ref, robot.q_reference)
    gref = pin.GeometryData(geom)
    pin.updateGeometryPlacements(model, ref, geom, gref)
    tree = (
        np.array([M.homogeneous for M in model.jointPlacements]),
        np.concatenate([np.asarray(ref.joints[i].S).ravel() for i in range(1, model.njoints)]),
        np.array(model.parents),
        " ".join(joint.shortname() for joint in model.joints),
        np.asarray(robot.q_reference),
    )
    return ref, gref, tree


def _distance_table(
    robot: Robot,
    arm: Arm,
    self_check: tuple[pin.Model, pin.Data, pin.GeometryModel, pin.GeometryData],
    reference: tuple[pin.Data, pin.GeometryData, tuple[NDArray[np.generic] | str, ...]],
    pair: int,
    reach: float,
) -> _Table | None:
    """Coal's distance between one self pair's convex hulls on a grid over the arm joints that move them apart.

    The hulls hold the geometries, so their distance is a lower bound of the geometries'.

    Only for a pair whose relative pose one or two revolute arm joints change (every other joint
    stays at its reference value, or moves both geometries alike). Per joint i, ``rho[i]`` bounds
    how far a point of the geometry it moves travels per radian relative to the other: its
    farthest hull point from the joint's origin, plus, for the upstream of two joints moving the
    same geometry, the distance between their origins (both invariant under the joints). At a
    configuration q the distance is at least the nearest node's less ``sum(rho * |q - node|)``.
    Returns (joints, lower, step, nodes per joint, rho, distance - ``reach`` per node (row-major)),
    or None. The values (:func:`_table_values`) are kept on disk
    (:func:`~baseplace.world.array_cache.cached_array`, keyed by the hulls, the kinematic tree and
    the grid): computing TIAGo's took 0.35 s of every process.
    """
    model, data, geom, _ = self_check
    objects = geom.geometryObjects
    first, second = int(geom.collisionPairs[pair].first), int(geom.collisionPairs[pair].second)
    ids = [model.getJointId(name) for name in arm.joint_names]
    supports = {k: set(model.supports[objects[k].parentJoint]) for k in (first, second)}
    joints = [i for i, j in enumerate(ids) if (j in supports[first]) != (j in supports[second])]
    if not 1 <= len(joints) <= 2 or any(arm.kinds[i] != 0 for i in joints):
        return None
    ref, gref, tree = reference  # :func:`_reference_pose`
    rho = []
    for i in joints:
        moved = first if ids[i] in supports[first] else second
        M = gref.oMg[moved]
        P = hull_points(objects[moved].geometry) @ M.rotation.T + M.translation
        below = [k for k in joints if k > i and ids[k] in supports[moved]]  # the other joint, downstream
        pivot = ids[below[0]] if below else ids[i]
        o, o_i = ref.oMi[pivot].translation, ref.oMi[ids[i]].translation
        rho.append(float(np.max(np.linalg.norm(P - o, axis=1)) + np.linalg.norm(o - o_i)))
    lo, hi = arm.lower[joints], arm.upper[joints]
    nodes = np.maximum(np.ceil((hi - lo) * np.array(rho) / (2 * TABLE_SLACK)), 1).astype(int) + 1
    while np.prod(nodes) > TABLE_NODES:
        nodes = np.maximum(np.ceil(nodes / 1.25), 2).astype(int)
    step = (hi - lo) / (nodes - 1)
    points = [hull_points(objects[k].geometry) for k in (first, second)]
    try:
        hulls = [_convex(P) for P in points]
    except Exception:  # qhull refuses a flat geometry: no table, coal decides
        return None
    parents = [(objects[k].parentJoint, objects[k].placement) for k in (first, second)]
    # everything the values depend on: the two hulls where their joints carry them, the kinematic
    # tree, the other joints' values and the grid (about 6 ms a table to compute: kept on disk)
    inputs = (
        *points,
        np.array([M.homogeneous for _, M in parents]),
        np.array([j for j, _ in parents]),
        *tree,
        np.array(ids),
        np.array(joints),
        lo,
        step,
        nodes,
        reach,
    )
    cert = cached_array(
        "self_table", inputs, (int(np.prod(nodes)),), np.float64,
        functools.partial(_table_values, robot, arm, (model, data), hulls, parents, joints, lo, step, nodes, reach),
    )  # fmt: skip
    return joints, lo, step, list(nodes), np.array(rho), np.asarray(cert)


def _table_values(
    robot: Robot,
    arm: Arm,
    kinematics: tuple[pin.Model, pin.Data],
    hulls: list[coal.ConvexBase],
    parents: list[tuple[int, pin.SE3]],
    joints: list[int],
    lo: FloatArray,
    step: FloatArray,
    nodes: NDArray[np.int64],
    reach: float,
) -> FloatArray:
    """:func:`_distance_table`'s values: per grid node (row-major), coal's distance between the hulls less ``reach``."""
    model, data = kinematics
    q = np.clip(arm.from_pinocchio(robot.q_reference), arm.lower, arm.upper)
    request, result, identity = coal.DistanceRequest(), coal.DistanceResult(), coal.Transform3s()
    (j1, M1), (j2, M2) = parents
    cert = []
    for u in np.ndindex(*nodes):
        q[joints] = lo + np.array(u) * step
        pin.forwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
        M = (data.oMi[j1] * M1).actInv(data.oMi[j2] * M2)  # the second geometry in the first's frame
        result.clear()
        d = coal.distance(
            hulls[0], identity, hulls[1], coal.Transform3s(M.rotation, M.translation), request, result
        )
        cert.append(d - reach)
    return np.array(cert)


def _convex(points: FloatArray) -> coal.ConvexBase:
    """Coal's convex hull of points (k, 3): it holds the geometry they are the :func:`hull_points` of."""
    vertices = coal.StdVec_Vec3s()
    for v in points:
        vertices.append(np.asarray(v, dtype=float))
    return coal.Convex.convexHull(vertices, False, "")


def convex_hull(geometry: coal.CollisionGeometry) -> tuple[FloatArray, FloatArray]:
    """The convex hull of :func:`hull_points` in the geometry's frame: its face planes (H, 4) and vertices (V, 3).

    Planes as unit normal and offset, inside <= 0, each offset raised by :data:`SLACK` (the hull
    holds the geometry up to rounding). A flat geometry has no 3-D hull: no planes (0, 4), and
    :func:`hull_points` as its vertices.
    """
    P = hull_points(geometry)
    try:
        hull = ConvexHull(P)
    except (QhullError, ValueError):  # flat or too few points: no 3-D hull, no certificate
        return np.zeros((0, 4)), P
    planes = _distinct_planes(hull.equations)
    planes[:, 3] -= SLACK
    return planes, P[hull.vertices]


def _distinct_planes(equations: FloatArray) -> FloatArray:
    """Qhull's facet planes (H, 4), each once, the most upward first.

    Qhull gives one plane per triangle, so a face of n triangles comes n times (a support plane's
    prism: 104 planes, 29 distinct); a certificate asks "is any plane clear", which the distinct
    planes answer alike in a fraction of the tries. Upward first: over a table top the top face
    is the one that clears, and the scans stop at the first that does.
    """
    distinct = np.unique(equations, axis=0)
    return np.ascontiguousarray(distinct[np.argsort(-distinct[:, 2], kind="stable")])


def _edge_planes(vertices: FloatArray, planes: FloatArray) -> FloatArray:
    """(E, 4) a supporting plane at each edge of the convex hull of ``vertices`` (k, 3) with face planes ``planes``.

    Its normal halves the angle between the two faces that meet at the edge (two planes that
    share two or more of the vertices), its offset puts every vertex on its inner side
    (``-max(vertices @ n)``): like a face plane it keeps the whole hull at or below 0, so a point
    set beyond one by a margin is that far from the hull. Where the closest points of a link and
    the hull are the hull's edge (an arm beside a table's rim), no face plane separates the two
    and this plane may (:func:`~baseplace.world.state_kernel._vertices_outside`).
    """
    on = np.abs(vertices @ planes[:, :3].T + planes[:, 3]) <= 1e-9 * max(1.0, float(np.abs(vertices).max()))
    shared = on.T.astype(np.int64) @ on.astype(np.int64)
    out = []
    for i, j in zip(*np.nonzero(np.triu(shared >= 2, k=1)), strict=True):
        n = planes[i, :3] + planes[j, :3]
        norm = np.linalg.norm(n)
        if norm > 1e-6:  # not two opposite faces of a flat hull
            n = n / norm
            out.append([*n, -float(np.max(vertices @ n))])
    return np.array(out, dtype=float).reshape(-1, 4)


def _moved_planes(planes: FloatArray, T_frame_geometry: pin.SE3) -> FloatArray:
    """Planes (H, 4) (unit normal, offset) of the geometry frame in another frame (``T_frame_geometry``)."""
    normals = planes[:, :3] @ np.asarray(T_frame_geometry.rotation).T
    offsets = planes[:, 3] - normals @ np.asarray(T_frame_geometry.translation)
    return np.column_stack([normals, offsets])


def _anchor_values(
    starts: NDArray[np.int64],
    hull: FloatArray,
    boxes: FloatArray,
    lo: FloatArray,
    step: float,
    dims: NDArray[np.int64],
) -> NDArray[np.float32]:
    """:func:`_anchor_field` on its grid (``dims`` nodes from ``lo``, ``step`` apart), rounded down to float32."""
    value = np.empty(tuple(dims))
    _anchor_field(starts, hull, boxes, lo, step, dims, ANCHOR_CAP, value)
    low = value.astype(np.float32)
    up = low > value  # rounded up: the next float32 below
    low[up] = np.nextafter(low[up], np.float32(-np.inf))
    return low


def _no_anchors(n_pairs: int, n_geometries: int, n_joints: int) -> tuple[NDArray[np.generic], ...]:
    """The anchor arguments of :func:`_uncertified_states` with no field: no self pair is in one."""
    return (
        np.full(n_pairs, -1, dtype=np.int64),
        np.zeros(0, dtype=np.int64),
        np.zeros((0, 6)),
        np.zeros((0, 3)),
        np.zeros(0),
        np.zeros((0, 3), dtype=np.int64),
        np.zeros(1, dtype=np.int64),
        np.zeros(0, dtype=np.float32),
        np.zeros((0, n_geometries)),
        np.zeros((0, n_joints)),
    )


def _no_tables(n_pairs: int) -> tuple[NDArray[np.generic], ...]:
    return _pack_tables(n_pairs, {})


def _pack_tables(n_pairs: int, tables: dict[int, _Table]) -> tuple[NDArray[np.generic], ...]:
    """Per self pair its table's index or -1, and the tables' (T, 2) joints, lower, step, nodes, rho, offsets, values."""
    which = np.full(n_pairs, -1, dtype=np.int64)
    T = len(tables)
    joint, count = np.full((T, 2), -1, dtype=np.int64), np.ones((T, 2), dtype=np.int64)
    lo, step, rho = np.zeros((T, 2)), np.ones((T, 2)), np.zeros((T, 2))
    offs, values = [0], []
    for t, (p, (joints, lower, steps, nodes, levers, cert)) in enumerate(sorted(tables.items())):
        which[p] = t
        k = len(joints)
        joint[t, :k], lo[t, :k], step[t, :k], count[t, :k], rho[t, :k] = joints, lower, steps, nodes, levers
        offs.append(offs[-1] + len(cert))
        values.append(cert)
    flat = np.concatenate(values) if values else np.zeros(0)
    return which, joint, lo, step, count, rho, np.array(offs, dtype=np.int64), flat


def _group_spheres(
    joint: NDArray[np.int64], local: FloatArray, radius: FloatArray, n: int
) -> tuple[FloatArray, FloatArray]:
    """Per arm joint j < n, a sphere around the spheres (``local``, ``radius``) of the geometries with ``joint == j``."""
    centres, radii = np.zeros((n, 3)), np.zeros(n)
    for j in range(n):
        C, r = local[joint == j], radius[joint == j]
        if len(r):
            centres[j] = ((C - r[:, None]).min(axis=0) + (C + r[:, None]).max(axis=0)) / 2
            radii[j] = float(np.max(np.linalg.norm(C - centres[j], axis=1) + r)) + SLACK
    return centres, radii


def _packed(indexes: list[PointIndex]) -> tuple[NDArray[np.generic], ...]:
    """Point indexes as a few flat arrays for :func:`_uncertified_states`.

    Per index q, ``offs[q]`` .. ``offs[q + 1]`` (Q + 1, 4) are where its points, cell keys, cell
    starts and distance field lie in the concatenated arrays; ``geo`` (Q, 11): lo, hi, cell,
    field_lo, field_h; ``ints`` (Q, 6): dims, the field's shape.
    """
    sizes = [(ix.n_points, len(ix.cell_keys), len(ix.cell_starts), ix.field.size) for ix in indexes]
    offs = np.zeros((len(indexes) + 1, 4), dtype=np.int64)
    offs[1:] = np.cumsum(np.array(sizes, dtype=np.int64).reshape(-1, 4), axis=0)
    cat = lambda arrays, empty: np.ascontiguousarray(np.concatenate([empty, *arrays]))  # noqa: E731
    return (
        offs,
        cat([ix.points for ix in indexes], np.zeros((0, 3))),
        cat([ix.cell_keys for ix in indexes], np.zeros(0, dtype=np.int64)),
        cat([ix.cell_starts for ix in indexes], np.zeros(0, dtype=np.int64)),
        cat([ix.field.ravel() for ix in indexes], np.zeros(0, dtype=np.float32)),
        np.array(
            [[*ix.lo, *ix.hi, ix.cell, *ix.field_lo, ix.field_h] for ix in indexes], dtype=float
        ).reshape(-1, 11),
        np.array([[*ix.dims, *ix.field.shape] for ix in indexes], dtype=np.int64).reshape(-1, 6),
    )


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
        sub_start, sub_joint, sub_local, sub_radius = [0], [], [], []  # the spheres covering each geometry
        hulls: list[FloatArray] = []  # per geometry, its hull's face planes in its joint's frame
        corners: list[FloatArray] = []  # and the points it is the hull of
        kept = _COVERS.setdefault(robot, {})
        if n_robot not in kept:  # the robot's geometries come first in every scene model
            kept[n_robot] = _sphere_covers([geom.geometryObjects[k].geometry for k in range(n_robot)])
        covers = kept[n_robot]
        known = _HULLS.setdefault(robot, {})
        if n_robot not in known:
            known[n_robot] = [convex_hull(geom.geometryObjects[k].geometry) for k in range(n_robot)]
        convex = known[n_robot]
        contacts = _CONTACTS.setdefault(robot, {})  # by geometry id, for the geometries an arm moves
        ball_start, ball_local, ball_radius = [0], [], []  # the witness balls of each geometry
        gref = pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, ref, geom, gref)
        for k in range(n_robot):
            obj = geom.geometryObjects[k]
            supports = set(model.supports[obj.parentJoint])
            j = max((i for i, a in enumerate(arm_ids) if a in supports), default=-1)
            frame = armbase_inv * ref.oMi[arm_ids[j]] if j >= 0 else pin.SE3.Identity()
            T = frame.inverse() * armbase_inv * gref.oMg[k]  # the geometry in its moving frame
            c, r = bounding_sphere(obj.geometry)
            planes, vertices = convex[k]
            hulls.append(_moved_planes(planes, T))
            corners.append(vertices @ T.rotation.T + T.translation)
            joint.append(j)
            local.append(T.rotation @ c + T.translation)
            radius.append(r)
            cover_c, cover_r = covers[k]
            sub_start.append(sub_start[-1] + len(cover_r))
            sub_joint += [j] * len(cover_r)
            sub_local += list(cover_c @ T.rotation.T + T.translation)
            sub_radius += list(cover_r)
            if j >= 0 and k not in contacts:  # only a moving geometry's scene pairs reach a proof
                contacts[k] = contact_balls(obj.geometry)
            ball_c, ball_r = contacts[k] if j >= 0 else (np.zeros((0, 3)), np.zeros(0))
            ball_start.append(ball_start[-1] + len(ball_r))
            ball_local += list(ball_c @ T.rotation.T + T.translation)
            ball_radius += list(ball_r)
        self.joint = np.array(joint, dtype=np.int64)
        """(G,) per robot geometry the arm joint that moves it, -1 for none."""
        self.local = np.array(local, dtype=float).reshape(-1, 3)
        """(G, 3) its bounding sphere's centre in that joint's frame (or the arm's base frame) [m]."""
        self.radius = np.array(radius, dtype=float)
        """(G,) the bounding sphere's radius [m]."""
        self._cover = (
            np.array(sub_start, dtype=np.int64),
            np.array(sub_joint, dtype=np.int64),
            np.array(sub_local, dtype=float).reshape(-1, 3),
            np.array(sub_radius, dtype=float),
        )
        """Per robot geometry g, the spheres of its :func:`sphere_cover` (starts (G + 1,), joints,
        centres in the joint's frame, radii) [m]."""
        self._contact_balls = (
            np.array(ball_start, dtype=np.int64),
            np.array(ball_local, dtype=float).reshape(-1, 3),
            np.array(ball_radius, dtype=float),
        )
        """Per robot geometry g, its :func:`contact_balls` (starts (G + 1,), centres in the frame of
        the arm joint that moves it, radii) [m]; none for a geometry no arm joint moves (its scene
        pairs are checked once per base pose, :meth:`_static_touching`, never proven)."""
        self._hulls = (
            np.cumsum([0] + [len(h) for h in hulls], dtype=np.int64),
            np.ascontiguousarray(np.concatenate([np.zeros((0, 4)), *hulls])),
            np.cumsum([0] + [len(v) for v in corners], dtype=np.int64),
            np.ascontiguousarray(np.concatenate([np.zeros((0, 3)), *corners])),
        )
        """Per robot geometry g, its convex hull's face planes (starts (G + 1,), (H, 4) unit normal and
        offset, inside <= 0) and the points it is the hull of (starts (G + 1,), (V, 3)), in the
        frame of the arm joint that moves it (or the arm's base frame)."""
        self._levers = geometry_levers(arm, self.joint, self.local, self.radius)
        """(G, n) how far a point of each robot geometry moves per unit change of each arm joint, at most [m]."""
        self._groups = _group_spheres(self.joint, self.local, self.radius, arm.n_joints)
        """Per arm joint, a sphere (centres (n, 3) in its frame, radii (n,)) around the bounding
        spheres of every geometry it moves, with no other arm joint between."""
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
            # each pair as (the geometry nearer the arm's base, the other), in runs of (geometry, the other's joint)
            pairs = self._self_pairs
            swap = self.joint[pairs[:, 0]] > self.joint[pairs[:, 1]]
            pairs[swap] = pairs[swap][:, ::-1]
            order = np.lexsort((self.joint[pairs[:, 1]], pairs[:, 0]))
            self._self_pairs, self._self_index = pairs[order], self._self_index[order]
            self._self_reach = self._self_reach[order]
        self._self_runs = self._runs()
        self._kernel_scene()
        self._tables = _no_tables(len(self._self_pairs))
        if self_check is not None and len(self._self_pairs):
            self._tables = self._self_tables()
        self._anchors = self._anchor_fields()
        self._args: tuple[tuple[object, ...], tuple[object, ...]] | None = None
        self._q_reference = np.array(robot.q_reference, dtype=float)
        self._one_value = np.array(arm.q_index, dtype=np.int64) if all(w == 1 for w in arm.q_width) else None
        self._static_key: bytes | None = None
        self._static_hit = False
        self._centres = np.empty((n_robot, 3))
        self._world = np.empty((n_robot, 3))
        self.coal_pairs = 0
        """Pairs handed to coal so far (scene and self), for measurements."""
        self.coal_states = 0
        """States whose spheres left a pair to coal so far, for measurements."""
        self.proven_states = 0
        """Of those, states a witness ball proved touching, coal not asked (:meth:`_touch_proven`)."""

    def _runs(self) -> tuple[NDArray[np.int64], FloatArray]:
        """The self pairs' runs of :func:`_uncertified_states`: (R, 4) geometry, joint, pairs r0..r1; (R,) largest reach.

        A run whose geometries no arm joint moves (joint -1: no group sphere) is never certified
        at once (reach infinite): its pairs are tested one by one.
        """
        g, j = self._self_pairs[:, 0], self.joint[self._self_pairs[:, 1]]
        starts = [p for p in range(len(g)) if p == 0 or (g[p], j[p]) != (g[p - 1], j[p - 1])]
        ends = [*starts[1:], len(g)][: len(starts)]
        runs = np.array(
            [[g[a], max(j[a], 0), a, b] for a, b in zip(starts, ends, strict=True)], dtype=np.int64
        )
        reach = [
            self._self_reach[a:b].max() if j[a] >= 0 else np.inf for a, b in zip(starts, ends, strict=True)
        ]
        return runs.reshape(-1, 4), np.array(reach, dtype=float)

    def _kernel_scene(self) -> None:
        """The moving pairs and scene parts as the arrays of :func:`_uncertified_states`.

        A part's box centres of every size go into one index, the largest box's half diagonal
        taken for all (coal's octrees here hold boxes of one size).
        """
        rows: list[int] = []
        reach: list[float] = []
        pair_ids: list[int] = []
        parts: list[list[int]] = []
        indexes, halves, planes, balls = [], [], [np.zeros((0, 4))], [np.zeros((0, 4))]
        box_half: list[float] = []  # per part, its boxes' half side when they are all one size, else 0
        n_planes = n_balls = 0
        for part in self.parts:
            parts.append([0, 0, 0, len(rows), len(rows) + len(part.robot_a), 0])
            order = np.argsort(self.joint[part.robot_a], kind="stable")  # a joint's geometries together
            rows += list(part.robot_a[order])
            reach += [part.margin[k] + SLACK for k in order]
            pair_ids += list(part.pair_a[order])
            index, half = PointIndex(np.zeros((0, 3)), HASH_CELL, 0.0), 0.0
            box_half.append(part.indexes[0][1] / math.sqrt(3) if len(part.indexes) == 1 else 0.0)
            if part.indexes:
                if len(part.indexes) == 1:
                    index, half = part.indexes[0]
                else:
                    index = PointIndex(np.concatenate([ix.points for ix, _ in part.indexes]), HASH_CELL)
                    half = max(h for _, h in part.indexes)
            elif part.planes is not None:
                parts[-1][:3] = [1, n_planes, n_planes + len(part.planes)]
                planes += [part.planes, part.edges]
                n_planes += len(part.planes) + len(part.edges)
                parts[-1][5] = n_planes
            else:
                assert part.sphere is not None
                parts[-1][:3] = [2, n_balls, n_balls + 1]
                balls.append(np.append(part.sphere[0], part.sphere[1])[None])
                n_balls += 1
            indexes.append(index)
            halves.append(half)
        self._scene_rows = np.array(rows, dtype=np.int64)
        self._scene_row_reach = np.array(reach, dtype=float)
        self._scene_row_pair = np.array(pair_ids, dtype=np.int64)
        self._box_half = np.array(box_half, dtype=float)
        self._contact_limit = self._scene_row_reach - SLACK - CONTACT_DEPTH
        """Per scene row, how close [m] a witness ball's surface must come to the part (its margin less :data:`CONTACT_DEPTH`)."""
        self._scene_parts = (np.array(parts, dtype=np.int64).reshape(-1, 6), *_packed(indexes),
                             np.array([*halves, 0.0], dtype=float), np.concatenate(planes), np.concatenate(balls))  # fmt: skip

    def _self_tables(self) -> tuple[NDArray[np.generic], ...]:
        """Distance tables for the self pairs the spheres leave to coal often, packed for the kernel.

        Hard pairs: left to coal in at least :data:`TABLE_HARD` of 200 random configurations
        (pairs of links that nearly touch near a shared joint: their spheres always overlap), or of
        200 configurations near the arm's stowed one (the spec's ``stowed`` values, each joint
        moved by a normal draw of :data:`STOWED_SPREAD`: every motion starts there, the arm tucked
        against the torso), by the spheres alone: the hull planes are not asked, so the tables do
        not depend on them. Kept per robot and arm (:data:`_TABLES`), each table's values on disk
        (:func:`_distance_table`).
        """
        key = (self.arm.name, self._self_pairs.tobytes(), self._self_reach.tobytes())
        kept = _TABLES.setdefault(self.robot, {})
        if key not in kept:
            a = self.arm
            rng = np.random.default_rng(0)
            Q = a.sample(rng, 200)
            if a.stowed is not None:
                near = a.stowed + rng.normal(0.0, STOWED_SPREAD, (200, a.n_joints))
                Q = np.vstack([Q, np.clip(near, a.lower, a.upper)])
            Q = np.ascontiguousarray(Q)
            none = _no_tables(len(self._self_pairs))
            G = len(self.joint)  # hard for the spheres alone, whatever the hulls certify
            no_hulls = (
                np.zeros(G + 1, dtype=np.int64),
                np.zeros((0, 4)),
                np.zeros(G + 1, dtype=np.int64),
                np.zeros((0, 3)),
            )
            out = np.empty((len(Q), len(self._self_pairs)), dtype=np.bool_)
            i = -1
            while i < len(Q):  # every state's rows (a call stops at each state with any left)
                i = _uncertified_states(  # type: ignore[call-arg]
                    Q, a.placements, a.axes, a.kinds, self.joint, self.local, self.radius, *self._cover,
                    *self._groups, *no_hulls, np.eye(4), self._scene_rows[:0].copy(), self._scene_row_reach[:0].copy(),
                    self._scene_parts[0][:0].copy(), *self._scene_parts[1:], self._self_pairs, self._self_reach, *self._self_runs,
                    *none, *_no_anchors(len(self._self_pairs), G, len(self._groups[1])), i + 1, out,
                )  # fmt: skip
                i = len(Q) if i < 0 else i
            tables = {}
            assert self.self_check is not None
            share = np.maximum(out[:200].mean(axis=0), out[200:].mean(axis=0) if len(Q) > 200 else 0.0)
            reference = _reference_pose(self.robot, self.self_check)
            for p in np.flatnonzero(share >= TABLE_HARD):
                table = _distance_table(self.robot, a, self.self_check, reference, int(self._self_index[p]),
                                        float(self._self_reach[p]))  # fmt: skip
                if table is not None:
                    tables[int(p)] = table
            kept[key] = _pack_tables(len(self._self_pairs), tables)
        return kept[key]

    def _anchor_fields(self) -> tuple[NDArray[np.generic], ...]:
        """The anchor fields of :func:`_uncertified_states`, packed: per self pair its field or -1, then the fields.

        Issue 25 item 3's state check, cheaper where the arm is tucked against the torso. Per frame
        of :data:`ANCHOR_JOINTS` (the arm's base, arm joint 0's), the set of geometries that frame
        carries and that come first in a self pair; their convex hulls (:func:`convex_hull`, in
        that frame) are fixed there whatever the arm's state, so one :func:`_anchor_field` on a
        grid over their bounding box (plus :data:`ANCHOR_BAND`) holds a lower bound of the
        distance to all of them, and one look-up per moved geometry serves all its pairs with the
        set. A pair with a distance table (:meth:`_self_tables`: its geometries nearly touch in
        many states, where the field would serve in vain) is left to the table: ``-2 - a`` where
        anchor a's field covers it (a run's look-up certifies all its pairs), and a run whose
        first pair is such is not looked up at once. Values are rounded down to float32. Per
        geometry h (and per arm joint's group), the largest reach of its pairs with the set. The
        packed arrays are kept per robot, arm, pairs and tables (:data:`_PACKED_ANCHORS`), each
        field on disk (:func:`~baseplace.world.array_cache.cached_array`); an arm with fewer than
        two joints, or a frame with no pairs, gets none.
        """
        pairs, reach = self._self_pairs, self._self_reach
        key = (
            self.arm.name,
            self.joint.tobytes(),
            pairs.tobytes(),
            reach.tobytes(),
            np.asarray(self._tables[0]).tobytes(),
        )
        packed = _PACKED_ANCHORS.setdefault(self.robot, {})
        if key not in packed:  # packing copies the fields (16 MB for TIAGo): 30 ms for every environment
            packed[key] = self._packed_anchor_fields()
        return packed[key]

    def _packed_anchor_fields(self) -> tuple[NDArray[np.generic], ...]:
        """:meth:`_anchor_fields`, computed."""
        G, J, S = len(self.joint), len(self._groups[1]), len(self._self_pairs)
        pairs, reach = self._self_pairs, self._self_reach
        anchor_of = np.full(S, -1, dtype=np.int64)
        frames: list[int] = []
        reaches: list[FloatArray] = []  # per anchor, the largest reach per geometry h, then per joint group
        for f in ANCHOR_JOINTS:
            if f >= self.arm.n_joints - 1:
                continue
            mine = (self.joint[pairs[:, 0]] == f) & (self.joint[pairs[:, 1]] > f)
            asked = mine & (np.asarray(self._tables[0]) < 0)
            mine &= np.isin(pairs[:, 0], pairs[asked, 0])  # the set: the geometries with a pair it serves
            if mine.any():
                anchor_of[mine] = -2 - len(frames)  # covered by the field, left to the pair's table
                anchor_of[mine & asked] = len(frames)
                frames.append(f)
                per = np.full(G + J, -np.inf)
                for p in np.flatnonzero(mine):
                    h = pairs[p, 1]
                    per[h] = max(per[h], reach[p])
                    per[G + self.joint[h]] = max(per[G + self.joint[h]], reach[p])
                reaches.append(per)
        if not frames:
            return _no_anchors(S, G, J)
        plane_start, planes, vert_start, verts = self._hulls
        fields = []
        for a in range(len(frames)):
            members = np.unique(pairs[(anchor_of == a) | (anchor_of == -2 - a), 0])
            boxes = np.array([[*verts[vert_start[g] : vert_start[g + 1]].min(axis=0),
                               *verts[vert_start[g] : vert_start[g + 1]].max(axis=0)] for g in members])  # fmt: skip
            starts = np.cumsum([0] + [plane_start[g + 1] - plane_start[g] for g in members], dtype=np.int64)
            hull = np.ascontiguousarray(
                np.concatenate(
                    [np.zeros((0, 4)), *[planes[plane_start[g] : plane_start[g + 1]] for g in members]]
                )
            )
            box = np.concatenate([boxes[:, :3].min(axis=0), boxes[:, 3:].max(axis=0)])
            lo, hi = box[:3] - ANCHOR_BAND, box[3:] + ANCHOR_BAND
            step = ANCHOR_STEP
            while np.prod(np.floor((hi - lo) / step) + 1) > ANCHOR_NODES:
                step *= 1.25
            dims = (np.floor((hi - lo) / step) + 1).astype(np.int64)
            low = cached_array(  # 1.5 s for TIAGo: kept on disk for the next process
                "anchor_field", (starts, hull, boxes, lo, step, dims, ANCHOR_CAP), tuple(int(n) for n in dims),
                np.float32, functools.partial(_anchor_values, starts, hull, boxes, lo, step, dims),
            )  # fmt: skip
            fields.append((box, lo, step, dims, np.asarray(low, dtype=np.float32).ravel()))
        return (
            anchor_of,
            np.array(frames, dtype=np.int64),
            np.array([box for box, *_ in fields]),
            np.array([lo for _, lo, *_ in fields]),
            np.array([step for _, _, step, *_ in fields]),
            np.array([dims for *_, dims, _ in fields], dtype=np.int64),
            np.cumsum([0] + [len(v) for *_, v in fields], dtype=np.int64),
            np.concatenate([v for *_, v in fields]),
            np.array([per[:G] for per in reaches]),
            np.array([per[G:] for per in reaches]),
        )

    def centres(self, q_arm: ArrayLike) -> FloatArray:
        """(G, 3) the bounding spheres' centres in the arm's base frame at arm joint values (n,) [m]."""
        q = np.ascontiguousarray(q_arm, dtype=float)
        a = self.arm
        _arm_centres(q, a.placements, a.axes, a.kinds, self.joint, self.local, self._centres)
        return self._centres

    def colliding(self, q_arm: ArrayLike, T_world_base: ArrayLike) -> bool:
        """Coal's verdict for arm joint values (n,) at base pose (4, 4): the robot touches the scene or itself."""
        return self.first_colliding(np.asarray(q_arm, dtype=float)[None], T_world_base) == 0

    def first_colliding(self, Q_arm: ArrayLike, T_world_base: ArrayLike) -> int:
        """The index of the first of the states Q_arm (m, n) that touches the scene or itself, or -1.

        Coal's verdict on each state, in order: one compiled call certifies the states' pairs by
        spheres (:func:`_uncertified_states`) up to the first state with pairs left over; only
        that state goes to coal, with only those pairs, and the call goes on after it.
        """
        Q = np.ascontiguousarray(np.atleast_2d(np.asarray(Q_arm, dtype=float)))
        T = np.asarray(T_world_base, dtype=float)
        if self._static_touching(Q[0], T):
            return 0
        out = np.empty((len(Q), len(self._scene_rows) + len(self._self_pairs)), dtype=np.bool_)
        robot, scene_and_self = self._kernel_args
        i = -1
        while True:
            i = _uncertified_states(Q, *robot, self._T_world_armbase, *scene_and_self, i + 1, out)  # type: ignore[call-arg]
            if i < 0 or self._left_touching(Q[i], out[i], T):
                return int(i)

    def first_colliding_line(
        self, a: FloatArray, b: FloatArray, n: int, travel: float, T_world_base: ArrayLike
    ) -> tuple[int, int]:
        """The first state ``a + k / n (b - a)`` (k = 1..n, far end first, then by bisection) that touches, or -1.

        Coal's verdict on every one of the n states, as :meth:`first_colliding` gives it on them
        (the same states, the same answer), with fewer pairs asked: ``travel`` [m] bounds how far
        any point of the robot moves along the whole line (e.g. the lever-arm bound of
        :func:`~baseplace.placement.motion.lever_arms`), so a pair that its spheres clear by a gap
        at two states stays clear between them while the points move less than the gaps add up to
        (:func:`_uncertified_line`). Also returns how many states were asked (a itself included:
        its gaps are used, its verdict is not).
        """
        a = np.ascontiguousarray(a, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        T = np.asarray(T_world_base, dtype=float)
        if not (n >= 1 and math.isfinite(travel) and travel >= 0.0):
            raise ValueError(f"a line needs n >= 1 states and a finite travel >= 0, got {n} and {travel}")
        if self._static_touching(b, T):
            return n, 1
        M = len(self._scene_rows) + len(self._self_pairs)
        if (n + 1) * M > LINE_ENTRIES:  # the gaps' table too large: every state, one by one
            order = bisection_order(n)
            i = self.first_colliding(a + np.outer(np.array(order, dtype=float) / n, b - a), T)
            return (-1, n) if i < 0 else (order[i], i + 1)
        slack = np.empty((n + 1, M))
        queue = np.empty((2 * n + 2, 4), dtype=np.int64)
        pool = np.empty((n + 1) * M, dtype=np.int64)
        ctl = np.zeros(5, dtype=np.int64)
        out = np.empty((1, M), dtype=np.bool_)
        robot, scene_and_self = self._kernel_args
        while True:
            k = _uncertified_line(a, b, n, float(travel), self._levers, *robot, self._T_world_armbase, *scene_and_self, slack,  # type: ignore[call-arg]
                                  queue, pool, ctl, out)  # fmt: skip
            if k < 0 or self._left_touching(a + (b - a) * (k / n), out[0], T):
                return int(k), int(ctl[2])

    def _static_touching(self, q_arm: FloatArray, T: FloatArray) -> bool:
        """Whether the geometries no arm joint moves touch the scene at base pose T (kept per pose)."""
        key = T.tobytes()
        if key != self._static_key:
            self._static_key = key
            self._T_world_armbase = T @ self._T_base_armbase
            _transformed(self.centres(q_arm), self._T_world_armbase, self._world)
            todo = [p for part in self._static_parts for p in part.uncertified(self._world)]
            self._static_hit = self._scene_coal(todo, self._full(q_arm), T)
        return self._static_hit

    def _left_touching(self, q_arm: FloatArray, left: NDArray[np.bool_], T: FloatArray) -> bool:
        """Coal's verdict at arm state q_arm on the pairs the spheres left (``left``: scene rows, then self pairs).

        A scene pair that a witness ball proves touching (:meth:`_touch_proven`) decides it without coal.
        """
        self.coal_states += 1
        P = len(self._scene_rows)
        if self._touch_proven(q_arm, left[:P], self._T_world_armbase):
            return True
        q_full = self._full(q_arm)
        scene = self._scene_row_pair[np.flatnonzero(left[:P])]
        if len(scene) and self._scene_coal(scene.tolist(), q_full, T):
            return True
        own = self._self_index[np.flatnonzero(left[P:])]
        return bool(len(own)) and self._self_coal(own, q_full)

    def touching(self, q_arm: ArrayLike, T_world_base: ArrayLike) -> tuple[list[int], list[int]]:
        """Every pair coal finds touching at arm joint values (n,) and base pose (4, 4).

        The scene model's collision pair indices and the self model's, as coal on every active
        pair finds them: the pairs the spheres certify free (:func:`_uncertified_states`) cannot
        touch, so only the others are asked. For reports (which links touch what).
        """
        q = np.ascontiguousarray(np.asarray(q_arm, dtype=float))
        T = np.asarray(T_world_base, dtype=float)
        T_world_armbase = T @ self._T_base_armbase
        world = np.empty_like(self._world)
        _transformed(self.centres(q), T_world_armbase, world)
        scene = [int(p) for part in self._static_parts for p in part.uncertified(world)]
        P = len(self._scene_rows)
        out = np.empty((1, P + len(self._self_pairs)), dtype=np.bool_)
        robot, scene_and_self = self._kernel_args
        i = _uncertified_states(q[None], *robot, T_world_armbase, *scene_and_self, 0, out)  # type: ignore[call-arg]
        rows = np.flatnonzero(out[0]) if i == 0 else np.zeros(0, dtype=np.int64)
        scene += [int(p) for p in self._scene_row_pair[rows[rows < P]]]
        own = [int(p) for p in self._self_index[rows[rows >= P] - P]]
        q_full = self._full(q)
        touching_scene = list(self._scene_touching(sorted(set(scene)), q_full, T)) if scene else []
        touching_self = list(self._self_touching(own, q_full)) if own else []
        return touching_scene, touching_self

    def _touch_proven(self, q_arm: FloatArray, left: NDArray[np.bool_], T_world_armbase: FloatArray) -> bool:
        """Whether a witness ball proves one of the scene rows ``left`` (P,) touching at arm state q_arm, the arm's base at T_world_armbase (4, 4).

        Coal's verdict on them is then True (:func:`~baseplace.world.state_kernel._touch_proven`);
        False leaves it to coal. Counted in :attr:`proven_states`.
        """
        if not left.any():
            return False
        a = self.arm
        parts, offs, points, keys, starts, _, geo, ints, _, planes, _ = self._scene_parts
        if not _touch_proven(q_arm, a.placements, a.axes, a.kinds, self.joint, T_world_armbase, left, self._scene_rows,
                             self._contact_limit, parts, offs, points, keys, starts, geo, ints, self._box_half, planes,
                             *self._contact_balls):  # fmt: skip
            return False
        self.proven_states += 1
        return True

    @property
    def _kernel_args(self) -> tuple[tuple[object, ...], tuple[object, ...]]:
        """The arguments of :func:`_uncertified_states` before and after the base pose, gathered once."""
        if self._args is None:
            a = self.arm
            self._args = (
                (a.placements, a.axes, a.kinds, self.joint, self.local, self.radius, *self._cover, *self._groups,
                 *self._hulls),
                (self._scene_rows, self._scene_row_reach, *self._scene_parts, self._self_pairs, self._self_reach,
                 *self._self_runs, *self._tables, *self._anchors),
            )  # fmt: skip
        return self._args

    def _full(self, q_arm: FloatArray) -> FloatArray:
        if self._one_value is None:  # every arm joint one pinocchio value: a plain copy and assignment
            return self.arm.to_pinocchio(q_arm, self.robot.q_reference)
        q = self._q_reference.copy()
        q[self._one_value] = q_arm
        return q

    def _self_touching(self, pairs: Iterable[int], q_full: FloatArray) -> Iterator[int]:
        """The self pairs (indices) that coal finds touching at the full configuration, lazily."""
        assert self.self_check is not None
        return _touching(self.self_check, pairs, q_full)

    def _scene_touching(
        self, pairs: Iterable[int], q_full: FloatArray, T_world_base: FloatArray
    ) -> Iterator[int]:
        """The scene pairs (indices) that coal finds touching at the full configuration and base pose, lazily."""
        self._place_scene(T_world_base)  # type: ignore[operator]
        return _touching(self.scene, pairs, q_full)

    def _self_coal(self, pairs: NDArray[np.int64], q_full: FloatArray) -> bool:
        self.coal_pairs += len(pairs)
        return next(self._self_touching(pairs.tolist(), q_full), None) is not None

    def _scene_coal(self, pairs: list[int], q_full: FloatArray, T_world_base: FloatArray) -> bool:
        if not pairs:
            return False
        self.coal_pairs += len(pairs)
        return next(self._scene_touching(pairs, q_full, T_world_base), None) is not None

    def colliding_poses(self, Q_arm: ArrayLike, T_world_base: ArrayLike) -> NDArray[np.bool_]:
        """Per pair (arm joint values Q_arm[s] (n,), base pose T_world_base[s] (4, 4)): :meth:`colliding`'s verdict.

        For many base poses at once: the error draws of the robustness score (Stulp et al. 2012's
        action-related places, seed 000 Alg. 2's check at each drawn pose), each at its own pose.
        The geometries no arm joint moves do not depend on the arm's state, so their spheres are
        placed for every pose and tested against each scene part in one compiled call per part
        (:meth:`_static_uncertified`) instead of one setup per pose; a pose whose leftover pairs
        coal finds touching collides. The others go through the compiled state check, each state
        at its own pose, all in one call (:func:`_uncertified_poses`) up to the next state with
        pairs left, and coal on those pairs, with
        the request and margin of :meth:`first_colliding`: the verdict is coal's. The static answer
        kept for :meth:`first_colliding` is neither used nor changed.

        Returns:
            (S,) bool, True where the robot touches the scene or itself.
        """
        T = np.asarray(T_world_base, dtype=float).reshape(-1, 4, 4)
        Q = np.ascontiguousarray(np.asarray(Q_arm, dtype=float).reshape(len(T), self.arm.n_joints))
        hit = np.zeros(len(T), dtype=bool)
        if len(T) == 0:
            return hit
        T_armbase = np.ascontiguousarray(T @ self._T_base_armbase)
        static = self._static_uncertified(T_armbase)
        for s in range(len(T)):
            if static[s] and self._scene_coal(static[s], self._full(Q[s]), T[s]):
                hit[s] = True
        rest = np.flatnonzero(~hit)
        Q_rest, T_rest = np.ascontiguousarray(Q[rest]), np.ascontiguousarray(T_armbase[rest])
        P = len(self._scene_rows)
        out = np.empty((len(rest), P + len(self._self_pairs)), dtype=np.bool_)
        robot, scene_and_self = self._kernel_args
        i = -1
        while True:
            i = _uncertified_poses(Q_rest, T_rest, *robot, *scene_and_self, i + 1, out)  # type: ignore[call-arg]
            if i < 0:
                return hit
            self.coal_states += 1
            s = rest[i]
            if self._touch_proven(Q[s], out[i, :P], T_armbase[s]):
                hit[s] = True
                continue
            q_full = self._full(Q[s])
            scene = self._scene_row_pair[np.flatnonzero(out[i, :P])]
            if len(scene) and self._scene_coal(scene.tolist(), q_full, T[s]):
                hit[s] = True
                continue
            own = self._self_index[np.flatnonzero(out[i, P:])]
            hit[s] = bool(len(own)) and self._self_coal(own, q_full)

    def _static_uncertified(self, T_world_armbase: FloatArray) -> list[list[int]]:
        """Per arm base pose (S, 4, 4), the scene pairs of the geometries no arm joint moves that their spheres do not clear.

        :meth:`_Part.uncertified` for all poses at once: those geometries' sphere centres (fixed
        in the arm's base frame) placed by every pose (:func:`_transformed_poses`, the arithmetic
        of :func:`_transformed`), then one :meth:`_Part.clear` per scene part over all of them.
        """
        S = len(T_world_armbase)
        left: list[list[int]] = [[] for _ in range(S)]
        W = np.empty((S, len(self.local), 3))
        _transformed_poses(self.local, T_world_armbase, W)
        for part in self._static_parts:
            G = len(part.robot_a)
            if G == 0:
                continue
            free = part.clear(np.ascontiguousarray(W[:, part.robot_a].reshape(-1, 3)), S)
            for s, k in zip(*np.nonzero(~free.reshape(S, G)), strict=True):
                left[s].append(int(part.pair_a[k]))
        return left


def bisection_order(n: int) -> list[int]:
    """The indices 1..n of the states of a line cut in n steps: n first, then by bisection.

    The midpoint first, then the quarter points, and so on: every index once, the far end first
    (as OMPL's discrete motion validator orders them), so a collision anywhere on the line is found
    after few checks.
    """
    order, seen = [n], {0, n}
    queue = [(0, n)]
    while queue:
        nxt = []
        for lo, hi in queue:
            if hi - lo < 2:
                continue
            mid = (lo + hi) // 2
            if mid not in seen:
                seen.add(mid)
                order.append(mid)
            nxt += [(lo, mid), (mid, hi)]
        queue = nxt
    return order


def geometry_levers(arm: Arm, joint: NDArray[np.int64], local: FloatArray, radius: FloatArray) -> FloatArray:
    """(G, n) per robot geometry and arm joint, how far a point of the geometry moves per unit change of the joint, at most [m].

    Each geometry by its bounding sphere: moved by arm joint ``joint[g]`` (-1: by none, a row of
    zeros), centre ``local[g]`` in that joint's frame, ``radius[g]``. A joint after ``joint[g]``
    does not move it; a prismatic joint moves it by its change (1); a revolute joint j by its
    change times the point's distance from j's axis, at most the distances between the joint
    origins from j down to ``joint[g]`` (:attr:`Arm.placements`, a prismatic joint's travel added)
    plus the sphere's centre's distance and radius, at any configuration. Along a joint line the
    moves add up (as :func:`~baseplace.placement.motion.lever_arms` bounds them for the whole robot).
    """
    offset = np.linalg.norm(arm.placements[:, :3, 3], axis=1)
    prismatic = arm.kinds == PRISMATIC
    stroke = np.where(prismatic, np.maximum(np.abs(arm.lower), np.abs(arm.upper)), 0.0)
    out = np.zeros((len(joint), arm.n_joints))
    for g, m in enumerate(joint):
        reach = float(np.linalg.norm(local[g])) + float(radius[g])
        for j in range(m, -1, -1):  # from the geometry's joint up the chain (none when m < 0)
            out[g, j] = 1.0 if prismatic[j] else reach
            reach += offset[j] + stroke[j]
    return out


def _touching(
    check: tuple[pin.Model, pin.Data, pin.GeometryModel, pin.GeometryData],
    pairs: Iterable[int],
    q_full: FloatArray,
) -> Iterator[int]:
    """The collision pairs (indices) of ``check``'s geometry that touch at ``q_full``; posed once, then lazily."""
    model, data, geom, gdata = check
    pin.forwardKinematics(model, data, q_full)
    pin.updateGeometryPlacements(model, data, geom, gdata)
    return (int(i) for i in pairs if pin.computeCollision(geom, gdata, int(i)))


__all__ = [
    "SLACK",
    "StateFilter",
    "bisection_order",
    "bounding_sphere",
    "geometry_levers",
    "hull_points",
    "sphere_cover",
]
