"""Ground truth for surface maps: the share of a surface's grid points IK reaches from a base pose.

The oracle behind seed 002's R_S ("the percentage of surface area that the robot can reach from
each pose"), computed without the reachability map: for every grid point of the polygon, IK is
solved for a few TCP orientations approaching from above (within the map's cone), and the point
counts as reached when a solution exists whose arm keeps clear of the surface's furniture.
"""

from __future__ import annotations

import math

import numpy as np

from baseplace.geometry.poses import BasePose, FloatArray, invert_transforms, pose_from_xyz_rpy
from baseplace.placement.surface_map import SurfaceMap, surface_grid
from baseplace.placement.surface_sampling import furniture_voxels
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.world.environment import Environment


class SurfaceTruth:
    """IK ground truth of R_S for one arm and one surface.

    Args:
        robot: the robot.
        arm_name: the arm.
        smap: the surface map whose polygon, height, resolution and cone are checked.
        orientations: TCP orientations tried per grid point.
        restarts: IK restarts per orientation.
    """

    def __init__(
        self, robot: Robot, arm_name: str, smap: SurfaceMap, orientations: int = 6, restarts: int = 8
    ):
        self.robot = robot
        self.arm = robot.arm(arm_name)
        self.points = surface_grid(smap.polygon, smap.resolution)
        self.height = smap.height + smap.tcp_height
        self.cone = math.pi / 2 if smap.cone is None else smap.cone
        self.orientations = orientations
        self.ik = DampedLeastSquaresIK(self.arm, restarts=restarts)
        self.environment = Environment(robot, furniture_voxels(smap), self_collision=False)

    def share(self, pose: FloatArray, rng: np.random.Generator) -> float:
        """Share of the surface's grid points reached from base pose (x, y, theta)."""
        T_world_base = BasePose(float(pose[0]), float(pose[1]), float(pose[2])).matrix()
        k = self.orientations
        targets = np.empty((len(self.points) * k, 4, 4))
        for i, (x, y) in enumerate(self.points):
            for j in range(k):
                # approach (TCP x) tilted from straight down by up to the cone, random roll and heading
                tilt = self.cone * math.sqrt(
                    rng.uniform()
                )  # uniform over the cone's solid angle (small-angle)
                roll, heading = rng.uniform(-math.pi, math.pi, 2)
                targets[i * k + j] = pose_from_xyz_rpy([x, y, self.height, roll, math.pi / 2 - tilt, heading])
        T_base_tcp = invert_transforms(T_world_base[None])[0] @ targets
        q, ok = self.ik.solve_batch(T_base_tcp, rng)
        reached = np.zeros(len(self.points), dtype=bool)
        for n in np.flatnonzero(ok):
            i = int(n) // k
            if not reached[i] and not self.environment.colliding_arm(self.arm, q[n], T_world_base):
                reached[i] = True
        return float(reached.mean())
