"""`register`: match two frames (descriptors or projection), estimate the motion with the
configured estimator, refine it and attach its covariance."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.matching import (
    as_words64,
    knn2_hamming,
    knn2_hamming_window,
    nndr_one_to_one,
)
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.common import F64, huge_covariance
from eddiebot.vslam.registration.covariance import estimate_covariance, pnp_jacobian_covariance
from eddiebot.vslam.registration.planar import solve_pnp_planar
from eddiebot.vslam.registration.pnp import refine_pnp, solve_pnp
from eddiebot.vslam.registration.rigid import solve_3d3d
from eddiebot.vslam.transforms import se3_inverse, to_3dof


@dataclass(frozen=True)
class RegistrationResult:
    """Outcome of a registration; `transform` is None on failure (see `reason`)."""

    transform: F64 | None
    covariance: F64 = field(default_factory=huge_covariance)
    inliers: int = 0
    matches: int = 0
    from_index: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    to_index: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    reason: str = ""
    #: every match the transform was estimated from (inliers or not): old / new indices
    match_from_index: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    match_to_index: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))

    @property
    def ok(self) -> bool:
        """True when a transform was found."""
        return self.transform is not None


def match_descriptors(
    from_desc: NDArray[np.uint8],
    to_desc: NDArray[np.uint8],
    nndr: float,
    from_mask: NDArray[np.bool_] | None = None,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """One-to-one NNDR matches without a guess: (from indices, to indices)."""
    if from_desc.shape[0] < 2 or to_desc.shape[0] == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    idx, dist = knn2_hamming(as_words64(to_desc), as_words64(from_desc), from_mask)
    to_i, from_i = nndr_one_to_one(idx, dist, nndr)
    return from_i, to_i


def match_by_projection(
    from_points_in_to: F64,
    from_desc: NDArray[np.uint8],
    to_uv: NDArray[np.float32],
    to_desc: NDArray[np.uint8],
    camera: CameraIntrinsics,
    window_px: float,
    nndr: float,
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Matches searched within `window_px` of where each 3D point projects in the new image.

    `from_points_in_to`: old 3D points expressed in the new *base* frame (NaN rows skipped).
    """
    lt_inv = se3_inverse(camera.local_transform)
    cam = from_points_in_to @ lt_inv[:3, :3].T + lt_inv[:3, 3]
    valid = np.isfinite(cam[:, 2]) & (cam[:, 2] > 1e-3)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = camera.fx * cam[:, 0] / cam[:, 2] + camera.cx
        v = camera.fy * cam[:, 1] / cam[:, 2] + camera.cy
    margin = window_px
    valid &= (u > -margin) & (u < camera.width + margin) & (v > -margin) & (v < camera.height + margin)
    proj_index = np.flatnonzero(valid)
    if proj_index.size < 2 or to_uv.shape[0] == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    idx, dist = knn2_hamming_window(
        as_words64(to_desc), as_words64(from_desc), to_uv,
        np.stack([u[proj_index], v[proj_index]], axis=1), proj_index, window_px)
    # A window with a single candidate has no second neighbour; such a match passes when it is
    # clearly close (a quarter of the descriptor bits), as the projection already disambiguates.
    single = (idx[:, 0] >= 0) & (idx[:, 1] < 0) & (dist[:, 0] <= 64)
    dist2 = dist.copy()
    idx2 = idx.copy()
    dist2[single, 1] = 256
    idx2[single, 1] = idx2[single, 0]
    to_i, from_i = nndr_one_to_one(idx2, dist2, nndr)
    return from_i, to_i


def register(
    old: FrameFeatures,
    new: FrameFeatures,
    camera: CameraIntrinsics,
    params: RtabmapParameters,
    guess: F64 | None = None,
    *,
    nndr: float | None = None,
) -> RegistrationResult:
    """Register `new` against `old` (old 3D points ↔ new keypoints); pose of new in old.

    Without a guess, descriptors are matched globally (NNDR `Vis/CorNNDR`); with a guess, by
    projection within `Vis/CorGuessWinSize` px. `Reg/RepeatOnce` re-matches by projection using
    the first result. `Reg/Force3DoF` projects the guess and the result to x, y, yaw.
    `Vis/EstimationType` 0 estimates from the matches with depth in both frames (`solve_3d3d`)
    instead of PnP; the covariance is the 3D-error rule either way.
    """
    ratio = params.vis_cor_nndr if nndr is None else nndr
    force = params.reg_force_3dof
    if guess is not None and force:
        guess = to_3dof(guess)
    old_valid = old.has_depth
    if int(old_valid.sum()) < params.vis_min_inliers or len(new) < params.vis_min_inliers:
        return RegistrationResult(None, reason="too few features")

    def _once(g: F64 | None) -> RegistrationResult:
        if g is None:
            fi, ti = match_descriptors(old.descriptors, new.descriptors, ratio, old_valid)
        else:
            pts = old.points.copy()
            pts[~old_valid] = np.nan
            inv = se3_inverse(g)
            fi, ti = match_by_projection(
                pts @ inv[:3, :3].T + inv[:3, 3], old.descriptors, new.uv, new.descriptors,
                camera, float(params.vis_cor_guess_win_size), ratio,
            )
        if fi.size < params.vis_min_inliers:
            return RegistrationResult(None, matches=int(fi.size), reason="too few matches")
        if params.vis_estimation_type == 0:
            return _estimate_3d3d(fi, ti)
        if force and params.vis_pnp_minimal_3dof:
            transform, inl = solve_pnp_planar(old.points[fi], new.uv[ti], camera, params, g)
        else:
            transform, inl = solve_pnp(old.points[fi], new.uv[ti], camera, params, g)
        if transform is None or inl.size < params.vis_min_inliers:
            return RegistrationResult(
                None, matches=int(fi.size), inliers=int(inl.size), reason="too few inliers"
            )
        if force:
            transform = to_3dof(transform)
        if params.vis_pnp_refine_iterations > 0:
            transform, inl = refine_pnp(transform, old.points[fi], new.uv[ti], inl, camera, params)
        fi_in, ti_in = fi[inl], ti[inl]
        cov = estimate_covariance(
            transform, old.points[fi_in], new.points[ti_in], new.uv[ti_in], camera,
            params.vis_pnp_variance_median_ratio,
        )
        if params.vis_pnp_jacobian_covariance:
            jac = pnp_jacobian_covariance(se3_inverse(transform), old.points[fi_in],
                                          new.uv[ti_in], camera, force)
            cov = np.maximum(cov, jac)
        return RegistrationResult(transform, cov, int(inl.size), int(fi.size), fi_in, ti_in,
                                  match_from_index=fi, match_to_index=ti)

    def _estimate_3d3d(fi: NDArray[np.intp], ti: NDArray[np.intp]) -> RegistrationResult:
        both = np.flatnonzero(np.isfinite(new.points[ti, 0]) & np.isfinite(old.points[fi, 0]))
        if both.size < params.vis_min_inliers:
            return RegistrationResult(None, matches=int(fi.size), inliers=0,
                                      reason="too few matches with depth")
        transform, inl = solve_3d3d(old.points[fi[both]], new.points[ti[both]], params,
                                    camera.local_transform[:3, 3])
        if transform is None or inl.size < params.vis_min_inliers:
            return RegistrationResult(
                None, matches=int(fi.size), inliers=int(inl.size), reason="too few inliers")
        fi_in, ti_in = fi[both[inl]], ti[both[inl]]
        cov = estimate_covariance(transform, old.points[fi_in], new.points[ti_in], new.uv[ti_in],
                                  camera, params.vis_pnp_variance_median_ratio)
        return RegistrationResult(transform, cov, int(inl.size), int(fi.size), fi_in, ti_in,
                                  match_from_index=fi, match_to_index=ti)

    result = _once(guess)
    if guess is not None and not result.ok:
        result = _once(None)
    if result.ok and params.reg_repeat_once and guess is None:
        second = _once(result.transform)
        if second.ok and second.inliers >= result.inliers:
            result = second
    return result
