"""Visual registration of two feature sets: descriptor or projection matching, then PnP RANSAC
(`Vis/EstimationType` 1) or RANSAC on 3D point pairs from both frames' depth (0).

Conventions: registration goes *from* an older frame (whose 3D points are used) *to* a newer one
(whose keypoints are used); the result is the pose of the new base frame expressed in the old
base frame (4×4, m). A failed registration returns ``transform=None`` — never a guess.
"""

from __future__ import annotations

from eddiebot.vslam.registration.common import LOST_VARIANCE, huge_covariance
from eddiebot.vslam.registration.covariance import estimate_covariance, pnp_jacobian_covariance
from eddiebot.vslam.registration.pipeline import (
    RegistrationResult,
    match_by_projection,
    match_descriptors,
    register,
)
from eddiebot.vslam.registration.planar import planar_two_point, solve_pnp_planar
from eddiebot.vslam.registration.pnp import refine_pnp, reprojection_errors, solve_pnp
from eddiebot.vslam.registration.rigid import solve_3d3d

__all__ = [
    "LOST_VARIANCE",
    "RegistrationResult",
    "estimate_covariance",
    "huge_covariance",
    "match_by_projection",
    "match_descriptors",
    "planar_two_point",
    "pnp_jacobian_covariance",
    "refine_pnp",
    "register",
    "reprojection_errors",
    "solve_3d3d",
    "solve_pnp",
    "solve_pnp_planar",
]

