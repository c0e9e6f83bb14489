"""Whole-robot collision checks against the environment (seed 000, Algorithm 2).

The obstacles are the occupied voxels without the support voxels: a voxel is support when its
cell belongs to a planar region and its centre lies within ``support_dist`` of that region's plane
(seed 000 V: "remove all voxels ... that belong to a planar region"). The rest go into a coal
OcTree, checked against every collision mesh of the robot, together with self-collision.
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.robots.collision import SelfCollision, load_collision_model
from baseplace.robots.model import Arm, Robot
from baseplace.terrain.segmentation import Segmentation
from baseplace.terrain.voxels import VoxelMap

SUPPORT_DIST = 0.1
"""Voxels this close [m] to their region's plane are support: 4 sigma of seed 000's 25 mm noise."""


def obstacle_voxels(voxels: VoxelMap, seg: Segmentation, support_dist: float = SUPPORT_DIST) -> VoxelMap:
    """The voxels that are obstacles: all but those lying on the plane of their cell's region."""
    centres = voxels.centres
    region = seg.region_at(centres[:, :2])
    support = np.zeros(len(centres), dtype=bool)
    for r in seg.regions:
        sel = region == r.id
        support[sel] = np.abs(centres[sel] @ r.normal + r.d) <= support_dist
    return voxels.without(support)


class Environment:
    """Collision checks of the whole robot, placed in the world, against obstacle voxels.

    Args:
        robot: the robot.
        obstacles: obstacle voxels in the world frame (see :func:`obstacle_voxels`).
        self_collision: also check self-collision (default True).
    """

    def __init__(self, robot: Robot, obstacles: VoxelMap, self_collision: bool = True) -> None:
        self.robot = robot
        self.model = robot.model
        self._self = SelfCollision(robot) if self_collision else None
        base_geom = self._self.geom if self._self is not None else None
        if base_geom is None:
            base_geom = load_collision_model(robot)
        self.geom = base_geom.copy()
        self.geom.removeAllCollisionPairs()
        n_robot = self.geom.ngeoms
        if len(obstacles) == 0:
            self.env_id = None
        else:
            tree = coal.makeOctree(np.ascontiguousarray(obstacles.centres), obstacles.resolution)
            self.env_id = self.geom.addGeometryObject(
                pin.GeometryObject("environment", 0, pin.SE3.Identity(), tree)
            )
            for k in range(n_robot):
                self.geom.addCollisionPair(pin.CollisionPair(k, self.env_id))
        self.data = self.model.createData()
        self.geom_data = pin.GeometryData(self.geom)
        if self._self is not None:  # build the arm-pruned pair tables now, not in the first query
            for arm_name in robot.spec.arms:
                self._self.colliding_arm(robot.arm(arm_name), robot.arm(arm_name).lower)
        ref = self.model.createData()
        pin.framesForwardKinematics(self.model, ref, robot.q_reference)
        self._T_root_base = ref.oMf[self.model.getFrameId(robot.spec.base_frame)]

    @property
    def obstacle_tree(self) -> coal.OcTree | None:
        """The obstacle voxels as a coal OcTree in the world frame, or None when there are none."""
        if self.env_id is None:
            return None
        tree: coal.OcTree = self.geom.geometryObjects[self.env_id].geometry
        return tree

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

    def _touches_obstacles(self, q: NDArray[np.float64], T_world_base: ArrayLike) -> bool:
        if self.env_id is None:
            return False
        T = np.asarray(T_world_base, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise InputError("base pose must be a finite (4, 4) matrix")
        T_root_world = self._T_root_base * pin.SE3(T).inverse()
        self.geom.geometryObjects[self.env_id].placement = T_root_world
        return bool(pin.computeCollisions(self.model, self.data, self.geom, self.geom_data, q, True))

    def colliding_arm(self, arm: Arm, q_arm: ArrayLike, T_world_base: ArrayLike) -> bool:
        """:meth:`colliding` for arm joint values (n,), other joints at their reference values.

        Self-collision uses only the pairs the arm can move relative to each other (exact here,
        since every other joint stays at its reference value).
        """
        if self._self is not None and self._self.colliding_arm(arm, q_arm)[0]:
            return True
        return self._touches_obstacles(arm.to_pinocchio(q_arm, self.robot.q_reference), T_world_base)


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
        arm = robot.arm(arm_name)
        geom = geom if geom is not None else load_collision_model(robot)
        model, data = robot.model, robot.model.createData()
        q = robot.q_reference
        pin.framesForwardKinematics(model, data, q)
        gdata = pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, data, geom, gdata, q)
        last = model.getJointId(arm.joint_names[-1])
        T_tcp_world = data.oMf[model.getFrameId(arm.tcp_frame)].inverse()
        self.parts = [
            (obj.geometry, (T_tcp_world * gdata.oMg[k]).homogeneous)
            for k, obj in enumerate(geom.geometryObjects)
            if last in set(model.supports[obj.parentJoint])
        ]

    def clear(self, T_world_tcp: ArrayLike, obstacles: coal.OcTree) -> bool:
        """True if no hand geometry at ``T_world_tcp`` (4, 4) touches ``obstacles``."""
        T_tcp = np.asarray(T_world_tcp, dtype=float)
        request, identity = coal.CollisionRequest(), coal.Transform3s()
        for geometry, T_tcp_geom in self.parts:
            T = T_tcp @ T_tcp_geom
            result = coal.CollisionResult()
            if coal.collide(
                geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), obstacles, identity, request, result
            ):
                return False
        return True
