"""Typed, vectorised SE(2)/SE(3) functions and small immutable pose types.

SE(2) poses are arrays (..., 3) of (x, y, theta) in metres and radians (REP-103: x forward,
y left, counter-clockwise positive); quaternions are (x, y, z, w) as in geometry_msgs;
SE(3) transforms are 4×4 homogeneous matrices. Pure functions, no state.
"""

from eddiebot.geometry._se import (
    Pose2D,
    matrix_to_quaternion,
    matrix_to_se2,
    quaternion_multiply,
    quaternion_to_matrix,
    quaternion_to_rpy,
    quaternion_to_yaw,
    rpy_to_quaternion,
    se2_between,
    se2_compose,
    se2_interpolate,
    se2_inverse,
    se2_to_matrix,
    se2_transform_points,
    se3_from_tq,
    se3_interpolate,
    se3_inverse,
    se3_to_tq,
    se3_transform_points,
    slerp,
    wrap_angle,
    yaw_to_quaternion,
)

__all__ = [
    "Pose2D",
    "matrix_to_quaternion",
    "matrix_to_se2",
    "quaternion_multiply",
    "quaternion_to_matrix",
    "quaternion_to_rpy",
    "quaternion_to_yaw",
    "rpy_to_quaternion",
    "se2_between",
    "se2_compose",
    "se2_interpolate",
    "se2_inverse",
    "se2_to_matrix",
    "se2_transform_points",
    "se3_from_tq",
    "se3_interpolate",
    "se3_inverse",
    "se3_to_tq",
    "se3_transform_points",
    "slerp",
    "wrap_angle",
    "yaw_to_quaternion",
]
