"""Whole-robot collision checks against the environment (seed 000, Algorithm 2).

The obstacles are the occupied voxels without the support voxels: a voxel is support when its
cell belongs to a planar region and its centre lies within ``support_dist`` of that region's plane
(seed 000 V: "remove all voxels ... that belong to a planar region"). The rest go into coal
OcTrees, checked against every collision mesh of the robot, together with self-collision. The
support voxels removed (the floor the base stands on) are checked against the geometries the arms
move only (group :data:`FLOOR`): the base stands on them, the arm and hand must keep off them.

At a grasp only the hand may touch the grasped object (:mod:`baseplace.world.grasped_object`):
its voxels are checked against every other link, and the surface under it stays an obstacle
(:func:`contact_groups`); collisions are reported per robot link and per thing touched. Given the
cloud, the scene within reach of the hand is its points in fine cells and the plane the object
stands on an exact plane (:mod:`baseplace.world.sensor_resolution`), kept at a clearance.

Obstacles given by hand (boxes, cylinders, meshes: :mod:`baseplace.world.obstacles`) are coal
shapes at their world poses beside the voxels, checked against every link and reported by name.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray
from baseplace.robots.collision import SelfCollision, load_collision_model
from baseplace.robots.model import REVOLUTE, Arm, Robot
from baseplace.terrain.segmentation import Segmentation
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.clearance import check_clearance
from baseplace.world.grasped_object import GraspedObject, rows_in
from baseplace.world.obstacles import Obstacle
from baseplace.world.sensor_resolution import (
    EXACT,
    Group,
    Part,
    SupportPlane,
    fine_groups,
    group_parts,
    group_size,
    margin,
    object_contact,
)
from baseplace.world.state_filter import StateFilter
from baseplace.world.support_plane import SUPPORT_PLANE, fit_support_slab

SUPPORT_DIST = 0.1
"""Voxels this close [m] to their region's plane are support: 4 sigma of seed 000's 25 mm noise."""


def obstacle_voxels(
    voxels: VoxelMap,
    seg: Segmentation,
    support_dist: float = SUPPORT_DIST,
    regions: Iterable[int] | None = None,
) -> VoxelMap:
    """The voxels that are obstacles: all but those lying on the plane of their cell's region.

    ``regions``: the ids of the regions that are support (default: all); the voxels of the others
    (e.g. a table top too small for the robot to stand on) stay obstacles.
    """
    centres = voxels.centres
    region = seg.region_at(centres[:, :2])
    support = np.zeros(len(centres), dtype=bool)
    chosen = None if regions is None else set(regions)
    for r in seg.regions:
        if chosen is not None and r.id not in chosen:
            continue
        sel = region == r.id
        support[sel] = np.abs(centres[sel] @ r.normal + r.d) <= support_dist
    return voxels.without(support)


def contact_groups(
    voxels: VoxelMap,
    obstacles: VoxelMap,
    grasped: GraspedObject | None,
    points: ArrayLike | None = None,
    floor: VoxelMap | None = None,
    fit_shapes: bool = True,
) -> tuple[dict[str, Group], Group | None]:
    """Split the scene for :class:`Environment`: ({"support": ..., "obstacle": ...}, the object).

    The object's voxels come from all ``voxels`` (it may stand on a planar region); its support is
    every voxel of ``voxels`` just under and around it (:meth:`GraspedObject.support_mask`), even
    one a planar region removed from ``obstacles``; the other obstacles are ``obstacles`` less
    both. Without an object: ({"obstacle": obstacles}, None).

    ``floor``: the support voxels removed from ``obstacles`` (the surfaces the base stands on), or
    None; given, they are group :data:`FLOOR` (less the object's voxels and its support off the
    floor), which :class:`Environment` checks against the geometries the arms move only; an object
    standing on the floor keeps its exact plane there as :data:`FLOOR_PLANE` (the base stands on it).

    ``points``: the cloud (N, 3) the voxels were made from. Given, the voxels near the object
    become their points in fine cells (those on smooth surfaces put onto their local plane first),
    and the planar surface the object stands on, when the cloud fits a good plane
    (:func:`~baseplace.world.support_plane.fit_support_slab`), an exact plane (group
    "support_plane"): :func:`~baseplace.world.sensor_resolution.fine_groups`, which also fits the
    neighbours standing on it as whole shapes unless ``fit_shapes`` is False.
    """
    floor = None if floor is None or len(floor) == 0 else floor
    if grasped is None:
        return {"obstacle": obstacles, **({} if floor is None else {FLOOR: floor})}, None
    mine = grasped.voxel_mask(voxels)
    support = grasped.support_mask(voxels) & ~mine
    on_floor = (
        np.zeros(len(voxels), dtype=bool) if floor is None else support & rows_in(voxels.keys, floor.keys)
    )
    taken = VoxelMap(voxels.resolution, voxels.keys[mine | support])
    rest = obstacles.without(rows_in(obstacles.keys, taken.keys))
    groups: dict[str, VoxelMap] = {
        "support": VoxelMap(voxels.resolution, voxels.keys[support & ~on_floor]),
        "obstacle": rest,
    }
    if floor is not None:  # the object's support on the floor stays floor: the base stands there
        groups[FLOOR] = floor.without(rows_in(floor.keys, voxels.keys[mine | (support & ~on_floor)]))
    object_voxels = VoxelMap(voxels.resolution, voxels.keys[mine])
    if points is None:
        return dict(groups), object_voxels
    slab = fit_support_slab(points, grasped.footprint_distance, grasped.bottom, voxels.resolution)
    out, grasped_group = fine_groups(groups, object_voxels, points, grasped, slab, fit_shapes=fit_shapes)
    if SUPPORT_PLANE in out and on_floor.sum() > (support & ~on_floor).sum():  # it stands on the floor
        out[FLOOR_PLANE] = out.pop(SUPPORT_PLANE)
    return out, grasped_group


def support_plane(groups: Mapping[str, Group]) -> SupportPlane | None:
    """The exact support plane among the groups (:func:`contact_groups`), or None."""
    for group in groups.values():
        for part in group_parts(group):
            if isinstance(part, SupportPlane):
                return part
    return None


_OCTREE = "_baseplace_octree"


def _octree(part: VoxelMap) -> coal.OcTree:
    """The part's coal OcTree, built once and kept on the part itself.

    The environments of one grasped object (the verification's and the transit's) are built from
    the same groups, so they share the tree, and the state filter the box index it makes of it
    (:class:`~baseplace.world.state_filter.StateFilter`); the tree lives and dies with the part.
    """
    tree = part.__dict__.get(_OCTREE)
    if tree is None:
        tree = coal.makeOctree(np.ascontiguousarray(part.centres), part.resolution)
        object.__setattr__(part, _OCTREE, tree)  # a frozen dataclass: a cache, not a field
    return tree


_SELF_COLLISION = "_baseplace_self_collision"


def _self_collision(robot: Robot) -> SelfCollision:
    """The robot's self-collision checker (collision model and pair tables), built once per robot.

    Kept on the robot itself, so it lives and dies with it: a WeakKeyDictionary would never let
    go, since the checker holds the robot (a long-running service leaked one robot per request).
    """
    checker = getattr(robot, _SELF_COLLISION, None)
    if checker is None:
        checker = SelfCollision(robot)
        setattr(robot, _SELF_COLLISION, checker)
    return checker


GRASPED = "grasped_object"
"""Name of the grasped object's voxels in contact reports (touched by a link that is not the hand)."""
FLOOR = "floor"
"""Name of the group of support voxels the base stands on (removed from the obstacles,
:func:`obstacle_voxels`): checked against the geometries the arms move only (:func:`arm_geometry_ids`)."""
FLOOR_PLANE = "floor_plane"
"""Name of the exact plane a grasped object stands on when that is the floor: as :data:`FLOOR`."""
ARM_ONLY = (FLOOR, FLOOR_PLANE)
"""The groups checked against the geometries the arms move only."""


def arm_geometry_ids(robot: Robot, geom: pin.GeometryModel) -> list[int]:
    """Indices of the collision geometries that an arm's first joint moves, of every arm of the robot.

    The base, its wheels and the torso stand on the floor by design; the arm and hand must keep off it.
    """
    model = robot.model
    firsts = set()
    for name in robot.spec.arms:  # an arm's chain may start with a prismatic torso: its first revolute joint
        arm = robot.arm(name)
        revolute = [j for j, kind in zip(arm.joint_names, arm.kinds, strict=True) if kind == REVOLUTE]
        if revolute:
            firsts.add(model.getJointId(revolute[0]))
    return [k for k, obj in enumerate(geom.geometryObjects) if firsts & set(model.supports[obj.parentJoint])]


def hand_geometry_ids(robot: Robot, geom: pin.GeometryModel, arm_name: str | None = None) -> list[int]:
    """Indices of the collision geometries of the arm's hand: those its last joint moves."""
    model = robot.model
    last = model.getJointId(robot.arm(arm_name).joint_names[-1])
    return [k for k, obj in enumerate(geom.geometryObjects) if last in set(model.supports[obj.parentJoint])]


class Environment:
    """Collision checks of the whole robot, placed in the world, against obstacle voxels.

    Obstacles come in named groups (e.g. "support", "obstacle"), each checked against every robot
    link but the groups of :data:`ARM_ONLY` (the floor the base stands on), checked against the
    geometries the arms move only (:func:`arm_geometry_ids`); collision reports name the group. The grasped object's voxels, if given, are checked
    against every link but the hand's (:func:`hand_geometry_ids`): only the hand may touch them,
    to any depth (coal handles no negative security margin for meshes and OcTrees, so a limit on
    how deep is not checked).

    A link closer than ``clearance`` to a part of a group at sensor resolution (cells of at most
    :data:`~baseplace.world.sensor_resolution.MAX_FINE`, the exact support plane) touches it (coal's
    security margin; from the point cells the clearance plus an allowance for how far inside the true
    surface they may lie: :func:`~baseplace.world.sensor_resolution.margin`). Coarser voxels (25 mm)
    keep no margin: a voxel's cube already reaches up to a whole edge beyond its points, more than
    any clearance; obstacles given by hand are exact and keep none either.

    Args:
        robot: the robot.
        obstacles: obstacle voxels in the world frame (see :func:`obstacle_voxels`), or a mapping
            name -> group (voxels, cells, the exact support plane: :func:`contact_groups`).
        self_collision: also check self-collision (default True).
        grasped: the grasped object's voxels or cells (world frame), or None.
        hand_arm: the arm whose hand holds the object (default: the robot's first arm).
        shapes: obstacles given by hand (world frame), each checked against every link and
            reported as its :attr:`~baseplace.world.obstacles.Obstacle.label` (``obstacle box#0``).
        clearance: the distance [m] to the parts at sensor resolution below which a link touches
            them (>= 0).
        plane_clearance: the distance [m] to the exact support plane below which a link touches
            it (:func:`~baseplace.world.sensor_resolution.derived_plane_clearance`); None: ``clearance``.
    """

    def __init__(
        self,
        robot: Robot,
        obstacles: VoxelMap | Mapping[str, Group],
        self_collision: bool = True,
        grasped: Group | None = None,
        hand_arm: str | None = None,
        shapes: Sequence[Obstacle] = (),
        clearance: float = 0.0,
        plane_clearance: float | None = None,
    ) -> None:
        check_clearance(clearance)
        check_clearance(plane_clearance)
        self.clearance = float(clearance)
        self.plane_clearance = plane_clearance
        self.robot = robot
        self.model = robot.model
        self._self = _self_collision(robot) if self_collision else None
        base_geom = self._self.geom if self._self is not None else None
        if base_geom is None:
            base_geom = load_collision_model(robot)
        self.geom = base_geom.copy()
        self.geom.removeAllCollisionPairs()
        n_robot = self.geom.ngeoms
        groups = dict(obstacles) if isinstance(obstacles, Mapping) else {"obstacle": obstacles}
        self.hand_ids = set(hand_geometry_ids(robot, self.geom, hand_arm)) if grasped is not None else set()
        arm_ids = set(arm_geometry_ids(robot, self.geom)) if set(ARM_ONLY) & set(groups) else set()
        self.env_ids: list[int] = []
        self._margin: dict[int, float] = {}  # per scene geometry: the security margin of its pairs
        self.parts: dict[int, Part] = {}
        """Per geometry id of a group's part: the part it was built from (its kind: the smoothed or raw
        point cells of :mod:`~baseplace.world.sensor_resolution`, coarse voxels, the exact plane, a
        fitted neighbour)."""
        margins: list[float] = []  # per collision pair
        contact = None if grasped is None else object_contact(grasped)  # cells: what the hand touches
        for name, group in [*groups.items(), (GRASPED, contact)]:
            for part in () if group is None else group_parts(group):
                if len(part) == 0:
                    continue
                if isinstance(part, EXACT):  # the support plane, a fitted neighbour: exact convexes
                    geometry: coal.CollisionGeometry = part.geometry()
                else:
                    geometry = _octree(part)
                gid = self.geom.addGeometryObject(pin.GeometryObject(name, 0, pin.SE3.Identity(), geometry))
                self.env_ids.append(gid)
                self.parts[gid] = part
                self._margin[gid] = margin(part, self.clearance, plane_clearance)
                for k in range(n_robot):  # the hand may touch the object; only the arms, the floor
                    if (name != GRASPED or k not in self.hand_ids) and (name not in ARM_ONLY or k in arm_ids):
                        self.geom.addCollisionPair(pin.CollisionPair(k, gid))
                        margins.append(self._margin[gid])
        self.shapes = tuple(shapes)
        self._T_world_env: dict[int, pin.SE3] = {}  # the shapes' poses; voxels are in the world frame
        for shape in self.shapes:
            obj = pin.GeometryObject(shape.label, 0, pin.SE3.Identity(), shape.geometry)
            gid = self.geom.addGeometryObject(obj)
            self.env_ids.append(gid)
            self._T_world_env[gid] = pin.SE3(np.asarray(shape.T_world_obstacle, dtype=float))
            self._margin[gid] = 0.0  # exact shapes keep no margin
            for k in range(n_robot):
                self.geom.addCollisionPair(pin.CollisionPair(k, gid))
                margins.append(0.0)
        self.obstacle_names = [n for n, v in groups.items() if group_size(v)] + [o.label for o in self.shapes]
        self.data = self.model.createData()
        self.geom_data = pin.GeometryData(self.geom)
        for request, metres in zip(self.geom_data.collisionRequests, margins, strict=True):
            request.security_margin = metres
        if self._self is not None:  # build the arm-pruned pair tables now, not in the first query
            for arm_name in robot.spec.arms:
                self._self.colliding_arm(robot.arm(arm_name), robot.arm(arm_name).lower)
        ref = self.model.createData()
        pin.framesForwardKinematics(self.model, ref, robot.q_reference)
        self._T_root_base = ref.oMf[self.model.getFrameId(robot.spec.base_frame)]
        self._n_robot = n_robot
        self._placed: bytes | None = None  # the base pose the scene geometries were last placed for
        # the scene geometries (references into self.geom: no geometry is added after this) and
        # their world poses (None: the world frame), placed for each new base pose
        objects = self.geom.geometryObjects
        self._scene_objects = [(objects[gid], self._T_world_env.get(gid)) for gid in self.env_ids]
        self._filters: dict[str, StateFilter] = {}

    @property
    def env_id(self) -> int | None:
        """Index of the first obstacle geometry, or None when there are none."""
        return self.env_ids[0] if self.env_ids else None

    @property
    def obstacle_trees(self) -> list[coal.OcTree]:
        """The obstacle voxels (every group, not the grasped object) as coal OcTrees in the world frame."""
        return [
            self.geom.geometryObjects[g].geometry
            for g in self.env_ids
            if self.geom.geometryObjects[g].name != GRASPED
            and g not in self._T_world_env
            and isinstance(self.geom.geometryObjects[g].geometry, coal.OcTree)
        ]

    @property
    def obstacle_geometries(self) -> list[tuple[coal.CollisionGeometry, FloatArray]]:
        """Every obstacle (voxel groups and shapes, not the grasped object) with its world pose (4, 4)."""
        out = []
        for g in self.env_ids:
            obj = self.geom.geometryObjects[g]
            if obj.name != GRASPED:
                out.append((obj.geometry, self._T_world_env.get(g, pin.SE3.Identity()).homogeneous))
        return out

    @property
    def obstacle_margins(self) -> list[float]:
        """Per obstacle of :attr:`obstacle_geometries`, the distance [m] below which a link touches it."""
        return [self._margin[g] for g in self.env_ids if self.geom.geometryObjects[g].name != GRASPED]

    @property
    def obstacle_tree(self) -> coal.OcTree | None:
        """The first obstacle OcTree in the world frame, or None when there are none."""
        trees = self.obstacle_trees
        return trees[0] if trees else None

    def colliding(self, q_full: ArrayLike, T_world_base: ArrayLike) -> bool:
        """True if the robot touches an obstacle voxel or itself.

        Args:
            q_full: full pinocchio configuration.
            T_world_base: (4, 4) base pose in the world.
        """
        q = np.asarray(q_full, dtype=float)
        if self._self is not None and self._self.colliding(q):
            return True
        return self._touches_obstacles(q, T_world_base)

    def _place_obstacles(self, T_world_base: ArrayLike) -> None:
        """Place the scene geometries in the robot's root frame for a base pose (4, 4), unless they are already.

        Once per new base pose (every candidate, every robustness draw that reaches coal): the
        geometry objects are looked up once, at construction (about 30 -> 8 us a call, 8 parts).
        """
        T = _base_pose(T_world_base)
        key = T.tobytes()
        if key == self._placed:
            return
        self._placed = key
        T_root_world = self._T_root_base * pin.SE3(T).inverse()
        for obj, T_world_env in self._scene_objects:
            obj.placement = T_root_world if T_world_env is None else T_root_world * T_world_env

    def _touches_obstacles(self, q: NDArray[np.float64], T_world_base: ArrayLike) -> bool:
        if not self.env_ids:
            return False
        self._place_obstacles(T_world_base)
        return bool(pin.computeCollisions(self.model, self.data, self.geom, self.geom_data, q, True))

    def colliding_arm(self, arm: Arm, q_arm: ArrayLike, T_world_base: ArrayLike) -> bool:
        """:meth:`colliding` for arm joint values (n,), other joints at their reference values.

        Coal's verdict (:meth:`colliding_arm_exact`), with the pairs whose bounding spheres are
        clear of each other left out (:class:`~baseplace.world.state_filter.StateFilter`): about
        1.2 ms per state on TIAGo with every pair, mostly spent on pairs far apart.
        """
        return self.state_filter(arm).colliding(q_arm, _base_pose(T_world_base))

    def first_colliding_arm(self, arm: Arm, Q_arm: ArrayLike, T_world_base: ArrayLike) -> int:
        """The index of the first of the arm states Q_arm (m, n) for which :meth:`colliding_arm` is True, or -1.

        Every state's spheres in one compiled call (:meth:`StateFilter.first_colliding`).
        """
        return self.state_filter(arm).first_colliding(Q_arm, _base_pose(T_world_base))

    def first_colliding_arm_line(
        self, arm: Arm, a: ArrayLike, b: ArrayLike, n: int, travel: float, T_world_base: ArrayLike
    ) -> tuple[int, int]:
        """The first k (1..n) for which :meth:`colliding_arm` is True at ``a + k / n (b - a)``, or -1; and the states asked.

        The same verdict as :meth:`first_colliding_arm` on those n states (taken far end first,
        then by bisection), asking fewer pairs: ``travel`` [m] must bound how far any point of the
        robot moves along the line (:meth:`StateFilter.first_colliding_line`).
        """
        return self.state_filter(arm).first_colliding_line(
            np.asarray(a, dtype=float), np.asarray(b, dtype=float), n, travel, _base_pose(T_world_base)
        )

    def colliding_arm_poses(self, arm: Arm, Q_arm: ArrayLike, T_world_base: ArrayLike) -> NDArray[np.bool_]:
        """(S,) :meth:`colliding_arm` for each pair of arm joint values Q_arm[s] (n,) and base pose T_world_base[s] (4, 4).

        The geometries no arm joint moves are checked for all poses together
        (:meth:`StateFilter.colliding_poses`); the verdicts are coal's.

        Raises:
            InputError: the poses are not finite (S, 4, 4) matrices, or not one per state.
        """
        T = np.asarray(T_world_base, dtype=float)
        Q = np.asarray(Q_arm, dtype=float)
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise InputError(f"base poses must be (S, 4, 4) matrices, got shape {T.shape}")
        bad = np.flatnonzero(~np.isfinite(T).all(axis=(1, 2)))
        if len(bad):
            raise InputError(f"base poses must be finite: {len(bad)} of {len(T)} are not, first at {bad[0]}")
        if Q.ndim != 2 or len(Q) != len(T) or Q.shape[1] != arm.n_joints:
            raise InputError(
                f"need one arm state ({arm.n_joints},) per base pose, got {Q.shape} for {len(T)} poses"
            )
        return self.state_filter(arm).colliding_poses(Q, T)

    def state_filter(self, arm: Arm) -> StateFilter:
        """The pre-filtered state check of ``arm`` (built on first use, kept)."""
        if arm.name not in self._filters:
            own = None
            if self._self is not None:
                own = (self._self.model, self._self.data, self._self.geom, self._self._arm_geometry_data(arm))
            self._filters[arm.name] = StateFilter(
                self.robot, arm, (self.model, self.data, self.geom, self.geom_data), self._n_robot,
                {gid: T.homogeneous for gid, T in self._T_world_env.items()}, self._place_obstacles,
                self._T_root_base, own,
            )  # fmt: skip
        return self._filters[arm.name]

    def colliding_arm_exact(self, arm: Arm, q_arm: ArrayLike, T_world_base: ArrayLike) -> bool:
        """:meth:`colliding_arm` with coal on every pair: the oracle of the pre-filtered check.

        Self-collision uses only the pairs the arm can move relative to each other (exact here,
        since every other joint stays at its reference value).
        """
        if self._touches_obstacles(arm.to_pinocchio(q_arm, self.robot.q_reference), T_world_base):
            return True
        return self._self is not None and bool(self._self.colliding_arm(arm, q_arm)[0])

    def contacts_arm(self, arm: Arm, q_arm: ArrayLike, T_world_base: ArrayLike) -> list[tuple[str, str]]:
        """Every (robot link, what it touches) at arm joint values (n,), other joints at reference.

        What is an obstacle group's name, :data:`GRASPED` (a link other than the hand touching the
        grasped object) or "self: <link>" (self-collision). Empty when :meth:`colliding_arm` is False.
        Coal's contacts, asked only for the pairs the state filter's spheres do not certify free
        (:meth:`StateFilter.touching`).
        """
        scene, own = self.state_filter(arm).touching(q_arm, _base_pose(T_world_base))
        out: list[tuple[str, str]] = []
        if self._self is not None:
            for i in own:
                first, second = self._self.pair_links(i)
                out.append((first, f"self: {second}"))
        objects = self.geom.geometryObjects
        for i in scene:
            pair = self.geom.collisionPairs[i]
            out.append((self._link(pair.first), objects[pair.second].name))
        return sorted(set(out))

    def _link(self, geometry_id: int) -> str:
        return str(self.model.frames[self.geom.geometryObjects[geometry_id].parentFrame].name)


def _base_pose(T_world_base: ArrayLike) -> NDArray[np.float64]:
    """The base pose as a (4, 4) float array; InputError unless it is one, finite."""
    T = np.asarray(T_world_base, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("base pose must be a finite (4, 4) matrix")
    return T


class HandFilter:
    """Keeps grasps the hand alone can take: its collision geometry at the grasp pose, clear of the scene.

    Seed 000's grasp candidates come from a grasp planner, so the hand fits around the object; random
    grasp poses need this check (the open hand must not sink into the box bottom or the neighbours).
    The hand is every collision geometry that no arm joint moves relative to the TCP, at the
    robot's reference configuration (as :class:`Environment` checks it). A grasp whose hand is not
    clear fails the whole-robot check from every base pose, so dropping it loses no placement.

    Args:
        robot: the robot.
        arm_name: the arm whose hand is checked.
        geom: the robot's collision model, if one is loaded already (e.g. ``Environment.geom``);
            default: loaded from the URDF.
    """

    def __init__(
        self, robot: Robot, arm_name: str | None = None, geom: pin.GeometryModel | None = None
    ) -> None:
        geom = geom if geom is not None else load_collision_model(robot)
        model, data = robot.model, robot.model.createData()
        q = robot.q_reference
        pin.framesForwardKinematics(model, data, q)
        gdata = pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, data, geom, gdata, q)
        T_tcp_world = data.oMf[model.getFrameId(robot.arm(arm_name).tcp_frame)].inverse()
        self.parts = [
            (geom.geometryObjects[k].geometry, (T_tcp_world * gdata.oMg[k]).homogeneous)
            for k in hand_geometry_ids(robot, geom, arm_name)
        ]

    def clear(
        self,
        T_world_tcp: ArrayLike,
        obstacles: coal.CollisionGeometry
        | list[coal.CollisionGeometry | tuple[coal.CollisionGeometry, FloatArray]],
        margins: Sequence[float] | None = None,
    ) -> bool:
        """True if no hand geometry at ``T_world_tcp`` (4, 4) touches ``obstacles``.

        Each obstacle is a geometry in the world frame (an OcTree) or (geometry, its world pose (4, 4)),
        as :attr:`Environment.obstacle_geometries` lists them. ``margins``: per obstacle, the distance
        [m] below which the hand touches it (coal's security margin; default 0).
        """
        T_tcp = np.asarray(T_world_tcp, dtype=float)
        items = obstacles if isinstance(obstacles, list) else [obstacles]
        placed = []
        for item, metres in zip(items, [0.0] * len(items) if margins is None else margins, strict=True):
            geometry, T_world = item if isinstance(item, tuple) else (item, np.eye(4))
            request = coal.CollisionRequest()
            request.security_margin = float(metres)
            placed.append((geometry, coal.Transform3s(T_world[:3, :3], T_world[:3, 3]), request))
        for geometry, T_tcp_geom in self.parts:
            T = T_tcp @ T_tcp_geom
            for other, at, request in placed:
                result = coal.CollisionResult()
                if coal.collide(geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), other, at, request, result):
                    return False
        return True
