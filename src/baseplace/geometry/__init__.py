"""Pose conventions, plane-constrained base poses and the SO(3) grid primitives."""

from baseplace.geometry.poses import (
    BasePose,
    invert_transforms,
    matrix_to_rpy,
    parse_base_pose,
    parse_pose6,
    pose_from_xyz_rpy,
    rpy_to_matrix,
    wrap_angle,
    yaw_of,
)
from baseplace.geometry.surface_poses import plane_base_poses, plane_frame

__all__ = [
    "BasePose",
    "invert_transforms",
    "matrix_to_rpy",
    "parse_base_pose",
    "parse_pose6",
    "plane_base_poses",
    "plane_frame",
    "pose_from_xyz_rpy",
    "rpy_to_matrix",
    "wrap_angle",
    "yaw_of",
]
