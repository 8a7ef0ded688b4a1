"""Covariance of a registration: from 3D-3D residuals (RTAB-Map's estimate) or from the PnP
Jacobian of the reprojection error."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.registration.common import F64, LOST_VARIANCE, huge_covariance
from eddiebot.vslam.transforms import se3_inverse

_LINEAR_VARIANCE_FLOOR = 1e-8
_ANGULAR_VARIANCE_FLOOR = 3e-8
_CHI2_FACTOR = 2.1981
_MIN_PIXEL_SIGMA = 0.5  # px: keypoint localisation floor of the Jacobian covariance


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
    between the two as seen from the new camera; variance = 2.1981 × the order statistic at n/ratio
    of the squared distances (m²) and of the angles (rad, not squared, as upstream's
    util3d::estimateMotion3DTo2D).
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
    # Upstream takes the order statistic of the angles themselves (rad), not of their squares:
    # squaring made links claim a fraction of their real angular error, and
    # RGBD/OptimizeMaxError then rejected true loop closures.
    angv = max(_CHI2_FACTOR * float(np.sort(ang)[k]), _ANGULAR_VARIANCE_FLOOR)
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
