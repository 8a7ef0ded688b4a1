"""Visual registration of two feature sets: descriptor or projection matching, then PnP RANSAC
(`Vis/EstimationType` 1) or RANSAC on 3D point pairs from both frames' depth (0).

Conventions: registration goes *from* an older frame (whose 3D points are used) *to* a newer one
(whose keypoints are used); the result is the pose of the new base frame expressed in the old
base frame (4×4, m). A failed registration returns ``transform=None`` — never a guess.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
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
from eddiebot.vslam.transforms import fit_rigid, from_xyz_yaw, se3_inverse, to_3dof, yaw_of

__all__ = [
    "LOST_VARIANCE",
    "RegistrationResult",
    "estimate_covariance",
    "huge_covariance",
    "match_by_projection",
    "match_descriptors",
    "pnp_jacobian_covariance",
    "refine_pnp",
    "register",
    "reprojection_errors",
    "solve_3d3d",
    "solve_pnp",
]

F64 = NDArray[np.float64]
LOST_VARIANCE = 9999.0
_CONFIDENCE = 0.99
_LINEAR_VARIANCE_FLOOR = 1e-8
_ANGULAR_VARIANCE_FLOOR = 3e-8
_CHI2_FACTOR = 2.1981
_MIN_PIXEL_SIGMA = 0.5  # px: keypoint localisation floor of the Jacobian covariance
_HUBER_PX = 1.0  # px: robust kernel width of the refinement
_REFINE_STEPS = 10  # Gauss-Newton steps per refinement


def huge_covariance() -> F64:
    """The covariance published for a failed registration or lost tracking (6 × 6)."""
    return np.eye(6) * LOST_VARIANCE


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


def solve_pnp(
    object_points: F64,
    image_points: NDArray[np.float32],
    camera: CameraIntrinsics,
    params: RtabmapParameters,
    guess: F64 | None = None,
) -> tuple[F64 | None, NDArray[np.intp]]:
    """PnP RANSAC: pose of the new base frame in the old one, and inlier positions (into the inputs)."""
    n = object_points.shape[0]
    if n < 4:
        return None, np.zeros(0, np.intp)
    lt = camera.local_transform
    rvec = np.zeros((3, 1))
    tvec = np.zeros((3, 1))
    use_guess = guess is not None
    if guess is not None:
        p = se3_inverse(lt) @ se3_inverse(guess)
        rvec = np.asarray(cv2.Rodrigues(p[:3, :3])[0], dtype=np.float64)
        tvec = p[:3, 3].reshape(3, 1).copy()
    ok, rvec_out, tvec_out, inliers = cv2.solvePnPRansac(
        object_points.astype(np.float64),
        image_points.astype(np.float64),
        camera.matrix,
        None,
        rvec,
        tvec,
        useExtrinsicGuess=use_guess,
        iterationsCount=params.vis_iterations,
        reprojectionError=float(params.vis_pnp_reproj_error),
        confidence=_CONFIDENCE,
        flags=cv2.SOLVEPNP_ITERATIVE,
    )
    if not ok or inliers is None or not np.all(np.isfinite(tvec_out)):
        return None, np.zeros(0, np.intp)
    rot, _ = cv2.Rodrigues(rvec_out)
    p = np.eye(4)
    p[:3, :3] = rot
    p[:3, 3] = np.asarray(tvec_out).ravel()
    return se3_inverse(lt @ p), inliers.ravel().astype(np.intp)


def solve_3d3d(
    from_points: F64,
    to_points: F64,
    params: RtabmapParameters,
    origin: F64 | None = None,
) -> tuple[F64 | None, NDArray[np.intp]]:
    """`Vis/EstimationType` 0: RANSAC over pairs of 3D points (old base frame ↔ new base frame,
    both from depth), a pair an inlier when the transformed new point lies within
    `Vis/InlierDistance` of the old one; then `Vis/RefineIterations` re-fits on the inliers and
    re-selections. Returns the pose of the new base frame in the old one and the inlier positions.

    With `Reg/Force3DoF` the samples are two pairs and the fit is planar (x, y, yaw). The re-fits
    weight each pair by the inverse of the depth noise variance (σ ∝ range², as a Kinect's),
    range from `origin` (the old camera, old base frame), so far points (whose depth error
    exceeds their lateral error many times over) do not pull the heading (not upstream: the
    upstream fit is unweighted). Deterministic: the samples come from a fixed-seed generator.
    """
    n = from_points.shape[0]
    three_dof = params.reg_force_3dof
    k = 2 if three_dof else 3
    if n < max(k, 3):
        return None, np.zeros(0, np.intp)
    thr = float(params.vis_inlier_distance)
    rng = np.random.default_rng(n)
    iters = max(1, params.vis_iterations)
    # all hypotheses at once: k distinct pairs per hypothesis
    samples = np.argsort(rng.random((iters, n)), axis=1)[:, :k]
    sp, sq = from_points[samples], to_points[samples]  # (iters, k, 3)
    if three_dof:
        dp, dq = sp[:, 1, :2] - sp[:, 0, :2], sq[:, 1, :2] - sq[:, 0, :2]
        yaw = np.arctan2(dp[:, 1], dp[:, 0]) - np.arctan2(dq[:, 1], dq[:, 0])
        c, s_ = np.cos(yaw), np.sin(yaw)
        rot = np.zeros((iters, 3, 3))
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1], rot[:, 2, 2] = c, -s_, s_, c, 1.0
        valid = np.linalg.norm(dp, axis=1) > 0.05
    else:
        cp, cq = sp.mean(axis=1, keepdims=True), sq.mean(axis=1, keepdims=True)
        h = np.einsum("nki,nkj->nij", sq - cq, sp - cp)
        u, _, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", vt, u)))
        vt[:, -1, :] *= d[:, None]
        rot = np.einsum("nji,nkj->nik", vt, u)
        valid = np.linalg.norm(sp[:, 1] - sp[:, 0], axis=1) > 0.05
    trans = sp.mean(axis=1) - np.einsum("nij,nj->ni", rot, sq.mean(axis=1))
    moved = np.einsum("nij,mj->nmi", rot, to_points) + trans[:, None, :]
    err = np.linalg.norm(from_points[None] - moved, axis=2)  # (iters, n)
    count = np.where(valid, (err <= thr).sum(axis=1), -1)
    score = count - np.minimum(err, thr).sum(axis=1) / (thr * (n + 1))  # ties: smaller error
    h_best = int(np.argmax(score))
    best: NDArray[np.intp] = np.flatnonzero(err[h_best] <= thr).astype(np.intp)
    if best.size < max(k, 3):
        return None, best
    ranges = np.linalg.norm(from_points - (np.zeros(3) if origin is None else origin), axis=1)
    weights = 1.0 / np.maximum(ranges, 0.5) ** 4
    t = fit_rigid(from_points[best], to_points[best], weights[best], three_dof)
    for _ in range(max(0, params.vis_refine_iterations)):
        err = np.linalg.norm(from_points - (to_points @ t[:3, :3].T + t[:3, 3]), axis=1)
        inl = np.flatnonzero(err <= thr).astype(np.intp)
        if inl.size < max(k, 3):
            break
        t_new = fit_rigid(from_points[inl], to_points[inl], weights[inl], three_dof)
        done = np.array_equal(inl, best)
        t, best = t_new, inl
        if done:
            break
    return t, best


def reprojection_errors(
    transform: F64, object_points: F64, image_points: NDArray[np.floating], camera: CameraIntrinsics
) -> NDArray[np.float64]:
    """Pixel distance between each old 3D point (old base frame) projected into the new image
    (`transform` = pose of the new base frame in the old one) and its keypoint; inf behind."""
    m = se3_inverse(camera.local_transform) @ se3_inverse(transform)
    pc = object_points @ m[:3, :3].T + m[:3, 3]
    z = pc[:, 2]
    front = z > 1e-6
    zs = np.where(front, z, 1.0)
    du = camera.fx * pc[:, 0] / zs + camera.cx - image_points[:, 0]
    dv = camera.fy * pc[:, 1] / zs + camera.cy - image_points[:, 1]
    return np.where(front, np.hypot(du, dv), np.inf)


def _refine_3dof(
    transform: F64, object_points: F64, image_points: NDArray[np.floating], camera: CameraIntrinsics
) -> F64:
    """Gauss-Newton (Huber-weighted) on x, y, yaw of `transform` minimising the reprojection
    error: the planar pose the inliers support, instead of a 6-DoF solution projected to 3 DoF
    (whose yaw carries what the free pitch, roll and z absorbed)."""
    x, y, yaw = float(transform[0, 3]), float(transform[1, 3]), yaw_of(transform)
    m = se3_inverse(camera.local_transform)
    a, b = m[:3, :3], m[:3, 3]
    pts = np.asarray(object_points, np.float64)
    uv = np.asarray(image_points, np.float64)
    for _ in range(_REFINE_STEPS):
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = pts[:, 0] - x, pts[:, 1] - y
        q = np.stack([c * dx + s * dy, -s * dx + c * dy, pts[:, 2]], axis=1)  # new base frame
        pc = q @ a.T + b
        z = pc[:, 2]
        if np.any(z <= 1e-6):
            break
        iz = 1.0 / z
        r = np.concatenate([camera.fx * pc[:, 0] * iz + camera.cx - uv[:, 0],
                            camera.fy * pc[:, 1] * iz + camera.cy - uv[:, 1]])
        # d q / d(x, y, yaw), then through the camera rotation and the projection
        dq = np.empty((pts.shape[0], 3, 3))
        dq[:, :, 0] = (-c, s, 0.0)
        dq[:, :, 1] = (-s, -c, 0.0)
        dq[:, 0, 2], dq[:, 1, 2], dq[:, 2, 2] = q[:, 1], -q[:, 0], 0.0
        dpc = np.einsum("ij,njk->nik", a, dq)
        ju = camera.fx * (dpc[:, 0, :] * iz[:, None] - (pc[:, 0] * iz * iz)[:, None] * dpc[:, 2, :])
        jv = camera.fy * (dpc[:, 1, :] * iz[:, None] - (pc[:, 1] * iz * iz)[:, None] * dpc[:, 2, :])
        jac = np.concatenate([ju, jv])
        w = np.minimum(1.0, _HUBER_PX / np.maximum(np.abs(r), 1e-12))
        h = jac.T @ (jac * w[:, None])
        try:
            step = np.linalg.solve(h, -(jac.T @ (w * r)))
        except np.linalg.LinAlgError:
            break
        x, y, yaw = x + float(step[0]), y + float(step[1]), yaw + float(step[2])
        if abs(step[0]) + abs(step[1]) < 1e-7 and abs(step[2]) < 1e-8:
            break
    return from_xyz_yaw(x, y, yaw)


def refine_pnp(
    transform: F64,
    object_points: F64,
    image_points: NDArray[np.floating],
    inliers: NDArray[np.intp],
    camera: CameraIntrinsics,
    params: RtabmapParameters,
) -> tuple[F64, NDArray[np.intp]]:
    """`Vis/PnPRefineIterations` rounds of: re-solve on the inliers (x, y, yaw only with
    `Reg/Force3DoF`, else OpenCV's Levenberg-Marquardt in 6 DoF), then re-select the inliers
    among all matches by `Vis/PnPReprojError`. A round that would leave fewer than
    `Vis/MinInliers` inliers is not taken."""
    lt = camera.local_transform
    for _ in range(params.vis_pnp_refine_iterations):
        if params.reg_force_3dof:
            refined = _refine_3dof(transform, object_points[inliers], image_points[inliers], camera)
        else:
            p = se3_inverse(lt) @ se3_inverse(transform)
            rvec = np.asarray(cv2.Rodrigues(p[:3, :3])[0], dtype=np.float64)
            tvec = p[:3, 3].reshape(3, 1).copy()
            r_out, t_out = cv2.solvePnPRefineLM(
                object_points[inliers].astype(np.float64),
                image_points[inliers].astype(np.float64), camera.matrix, None, rvec, tvec)
            q = np.eye(4)
            q[:3, :3] = cv2.Rodrigues(np.asarray(r_out, np.float64))[0]
            q[:3, 3] = np.asarray(t_out, np.float64).ravel()
            refined = se3_inverse(lt @ q)
        err = reprojection_errors(refined, object_points, image_points, camera)
        selected = np.flatnonzero(err < float(params.vis_pnp_reproj_error)).astype(np.intp)
        if not np.all(np.isfinite(refined)) or selected.size < params.vis_min_inliers:
            break
        transform, inliers = refined, selected
    return transform, inliers


def estimate_covariance(
    transform: F64,
    from_points: F64,
    to_points: F64,
    to_uv: NDArray[np.float32],
    camera: CameraIntrinsics,
    median_ratio: int,
) -> F64:
    """Registration covariance from inlier 3D errors (diagonal, x y z roll pitch yaw).

    Squared distance between each old point and the new point mapped into the old frame (a new
    point without depth is taken along its ray at 1.1 × the old point's depth), and the angle
    between the two as seen from the new camera; variance = 2.1981 × the order statistic at n/ratio.
    """
    n = from_points.shape[0]
    if n == 0:
        return huge_covariance()
    lt = camera.local_transform
    cam_to_old = transform @ lt
    origin = cam_to_old[:3, 3]
    new_in_old = to_points @ transform[:3, :3].T + transform[:3, 3]
    missing = ~np.isfinite(new_in_old[:, 0])
    if missing.any():
        rays = np.stack(
            [(to_uv[missing, 0] - camera.cx) / camera.fx,
             (to_uv[missing, 1] - camera.cy) / camera.fy,
             np.ones(int(missing.sum()))], axis=1,
        )
        old_in_cam = (from_points[missing] - origin) @ cam_to_old[:3, :3]
        depth = np.abs(old_in_cam[:, 2]) * 1.1
        new_in_old[missing] = (rays * depth[:, None]) @ cam_to_old[:3, :3].T + origin
    err2 = np.sum((from_points - new_in_old) ** 2, axis=1)
    a = from_points - origin
    b = new_in_old - origin
    cosang = np.sum(a * b, axis=1) / np.maximum(
        np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-12
    )
    ang = np.arccos(np.clip(cosang, -1.0, 1.0))
    k = min(n - 1, n // max(1, median_ratio))
    lin = max(_CHI2_FACTOR * float(np.sort(err2)[k]), _LINEAR_VARIANCE_FLOOR)
    angv = max(_CHI2_FACTOR * float(np.sort(ang)[k]) ** 2, _ANGULAR_VARIANCE_FLOOR)
    return np.diag([lin, lin, lin, angv, angv, angv])


def pnp_jacobian_covariance(
    link: F64,
    from_points: F64,
    to_uv: NDArray[np.float32],
    camera: CameraIntrinsics,
    three_dof: bool,
    min_pixel_sigma: float = _MIN_PIXEL_SIGMA,
) -> F64:
    """Marginal variances (diagonal 6×6, x y z roll pitch yaw) of a PnP result from the
    geometry of its inliers: σ²(JᵀJ)⁻¹ with J the Jacobian of the inliers' reprojections with
    respect to a perturbation of `link` (pose of the old frame in the new one, perturbed on
    the right as the graph's between factors are) and σ the inliers' RMS reprojection residual
    (at least `min_pixel_sigma` px).

    Unlike the 3D-error rule, this grows along directions the inliers do not constrain, e.g.
    the lateral-shift/yaw ambiguity when all inliers lie at one depth. With `three_dof` only x,
    y and yaw are estimated; the other variances are 0 (left to the caller).
    """
    n = from_points.shape[0]
    axes = [0, 1, 5] if three_dof else [0, 1, 2, 3, 4, 5]
    if n < len(axes):
        return huge_covariance()
    cam_from_base = se3_inverse(camera.local_transform)

    def project(t: F64) -> NDArray[np.float64]:
        m = cam_from_base @ t
        pc = from_points @ m[:3, :3].T + m[:3, 3]
        z = np.maximum(pc[:, 2], 1e-6)
        return np.stack([camera.fx * pc[:, 0] / z + camera.cx,
                         camera.fy * pc[:, 1] / z + camera.cy], axis=1)

    base = project(link)
    resid = base - np.asarray(to_uv, dtype=np.float64)
    dof = max(1, 2 * n - len(axes))
    sigma2 = max(float(np.sum(resid**2)) / dof, min_pixel_sigma**2)
    eps = 1e-6
    cols = []
    for a in axes:
        xi = np.zeros(6)
        xi[a] = eps
        d = np.eye(4)
        if a < 3:
            d[a, 3] = eps
        else:
            d[:3, :3] = cv2.Rodrigues(xi[3:].reshape(3, 1))[0]
        cols.append(((project(link @ d) - base) / eps).ravel())
    jac = np.stack(cols, axis=1)
    h = jac.T @ jac
    try:
        cov_sub = np.linalg.inv(h) * sigma2
    except np.linalg.LinAlgError:
        return huge_covariance()
    var = np.zeros(6)
    var[axes] = np.clip(np.diag(cov_sub), 0.0, LOST_VARIANCE)
    return np.diag(var)


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
