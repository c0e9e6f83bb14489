"""Ground truth for surface maps: the share of a surface's grid points IK reaches from a base pose.

The oracle behind seed 002's R_S ("the percentage of surface area that the robot can reach from
each pose"), computed without the reachability map: for every grid point of the polygon, IK is
solved for a few TCP orientations approaching from above (within the map's cone), and the point
counts as reached when a solution exists whose arm keeps clear of the surface's furniture.

Run on a pose the map keeps, this is seed 002 III-A's validation ("the robot must be able to assume
the pose without colliding with the surface polygon; also a collision free inverse kinematic
solution to reach the sampled point must exist"): :func:`validate` times it per pose, and
:class:`PointMapCalibration` scales R_P so that the map agrees with it on development poses.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, FloatArray, invert_transforms, pose_from_xyz_rpy
from baseplace.placement.surface_map import SurfaceMap, surface_grid
from baseplace.placement.surface_sampling import furniture_voxels
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.world.environment import Environment
from baseplace_experiments.results import SeedSplit


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


SEEDS = SeedSplit(dev=(0,), held_out=(1,))
"""Pose seeds: development poses fit the calibration and time the validation; held-out poses report."""


def poses_near_surface(smap: SurfaceMap, n: int, rng: np.random.Generator, margin: float = 0.7) -> FloatArray:
    """``n`` random base poses (n, 3) [m, m, rad] within ``margin`` of the map's surface, about half with R_S > 0.

    Each draw is uniform in the surface's bounding box grown by ``margin``; a draw with R_S = 0 is
    kept with probability 1/2, so that poses the map keeps and poses it drops are both represented.
    """
    x0, y0 = smap.polygon.min(axis=0) - margin
    x1, y1 = smap.polygon.max(axis=0) + margin
    poses: list[FloatArray] = []
    while len(poses) < n:
        p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(0, 2 * math.pi)])
        if smap.reachability(p)[0] > 0 or rng.uniform() < 0.5:
            poses.append(p)
    return np.array(poses).reshape(-1, 3)


def kept_poses(smap: SurfaceMap, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` of the poses the map keeps (R_S > 0), uniformly without replacement: (n, 3) [m, m, rad]."""
    poses, values = smap.cell_poses()
    kept = poses[values > 0]
    return kept[rng.choice(len(kept), size=min(n, len(kept)), replace=False)]


def validate(
    truth: SurfaceTruth, poses: ArrayLike, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray]:
    """Seed 002 III-A's per-pose validation: the IK share (n,) of :meth:`SurfaceTruth.share` and its time (n,) [s]."""
    P = np.asarray(poses, dtype=float).reshape(-1, 3)
    shares, seconds = np.empty(len(P)), np.empty(len(P))
    for k, p in enumerate(P):
        t = time.perf_counter()
        shares[k] = truth.share(p, rng)
        seconds[k] = time.perf_counter() - t
    return shares, seconds


@dataclass(frozen=True)
class PointMapCalibration:
    """R_P scaled to agree with the IK validation: R_P' = scale * R_P, hence R_S' = scale * R_S.

    R_S (seed 002 eq. 2) is linear in R_P, so one factor on the point map is one factor on the
    surface map. The factor is the least-squares fit of the validated share against R_S over the
    development poses with R_S > 0 (no intercept: a pose the map drops stays dropped).

    Attributes:
        scale: the factor (1: the uncalibrated map).
        poses: development poses it was fit on.
    """

    scale: float
    poses: int

    @classmethod
    def fit(cls, rs: ArrayLike, validated: ArrayLike) -> PointMapCalibration:
        """Fit on R_S (n,) and the validated shares (n,) of the same poses."""
        r, v = np.asarray(rs, dtype=float), np.asarray(validated, dtype=float)
        nz = r > 0
        if not nz.any():
            raise InputError("cannot calibrate R_P: no development pose has R_S > 0")
        return cls(float((r[nz] @ v[nz]) / (r[nz] @ r[nz])), int(nz.sum()))

    def __call__(self, rs: ArrayLike) -> FloatArray:
        """Calibrated R_S (n,) in [0, 1]."""
        return np.clip(self.scale * np.asarray(rs, dtype=float), 0.0, 1.0)


def agreement(rs: ArrayLike, truth: ArrayLike) -> dict[str, Any]:
    """Map against truth over poses (n,): MAE, and on the non-zero poses MAE and bias (signed mean, map - truth)."""
    r, t = np.asarray(rs, dtype=float), np.asarray(truth, dtype=float)
    err = r - t
    nz = r > 0

    def rounded(v: float) -> float:
        return round(float(v), 4)

    return {
        "poses": len(r),
        "nonzero_rs": int(nz.sum()),
        "mae": rounded(np.abs(err).mean()),
        "max_abs_error": rounded(np.abs(err).max()),
        "mae_nonzero_rs": rounded(np.abs(err[nz]).mean()) if nz.any() else None,
        "bias_nonzero_rs": rounded(err[nz].mean()) if nz.any() else None,
        "mean_truth_nonzero_rs": rounded(t[nz].mean()) if nz.any() else None,
        "overestimated_nonzero_rs": int((err[nz] > 0).sum()),
        "mae_zero_rs": rounded(np.abs(err[~nz]).mean()) if (~nz).any() else None,
        "zero_rs_but_ik_reaches": int(((~nz) & (t > 0)).sum()),
    }
