"""PnP RANSAC on OpenCV (`Vis/EstimationType` 1), reprojection errors and the Gauss-Newton
refinement of a PnP pose (6-DoF, or 3-DoF on the ground plane)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.common import _CONFIDENCE, _HUBER_PX, _REFINE_STEPS, F64
from eddiebot.vslam.registration.planar import _planar_camera, _planar_refine
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, yaw_of


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
    `Reg/Force3DoF`, compiled with `Vis/PnPMinimal3DoF`, else OpenCV's Levenberg-Marquardt in
    6 DoF), then re-select the inliers among all matches by `Vis/PnPReprojError`. A round that would leave fewer than
    `Vis/MinInliers` inliers is not taken."""
    lt = camera.local_transform
    for _ in range(params.vis_pnp_refine_iterations):
        if params.reg_force_3dof and params.vis_pnp_minimal_3dof:
            a, b, cam = _planar_camera(camera)
            rx, ry, ryaw = _planar_refine(
                float(transform[0, 3]), float(transform[1, 3]), yaw_of(transform),
                np.ascontiguousarray(object_points[inliers], np.float64),
                np.ascontiguousarray(image_points[inliers], np.float64), a, b, cam,
                _REFINE_STEPS, _HUBER_PX)
            refined = from_xyz_yaw(rx, ry, ryaw)
        elif params.reg_force_3dof:
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
