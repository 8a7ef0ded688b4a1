"""Visual registration of two feature sets: descriptor or projection matching, then PnP RANSAC
(`Vis/EstimationType` 1) or RANSAC on 3D point pairs from both frames' depth (0).

Conventions: registration goes *from* an older frame (whose 3D points are used) *to* a newer one
(whose keypoints are used); the result is the pose of the new base frame expressed in the old
base frame (4×4, m). A failed registration returns ``transform=None`` — never a guess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
from numba import njit
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
    "planar_two_point",
    "pnp_jacobian_covariance",
    "refine_pnp",
    "register",
    "reprojection_errors",
    "solve_3d3d",
    "solve_pnp",
    "solve_pnp_planar",
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


# -- 2-point planar PnP (`Vis/PnPMinimal3DoF`) ------------------------------------------------
# Pose (x, y, yaw) of the new base frame in the old one. A point P of the old base frame is, in
# the new base frame, q = (c·Px + s·Py − a1, −s·Px + c·Py − a2, Pz) with (c, s) = (cos, sin) yaw
# and (a1, a2) = R(−yaw)·(x, y): linear in θ = (c, s, a1, a2). The camera sees p = A·q + b
# (A, b: the base → optical transform); a keypoint at normalised (xn, yn) gives the two linear
# equations (A₀ − xn·A₂)·q + b₀ − xn·b₂ = 0 and (A₁ − yn·A₂)·q + b₁ − yn·b₂ = 0 (Aᵢ: row i), so
# two correspondences fix θ (4 × 4). The sample is degenerate when that system is singular, when
# its two points are closer than _PLANAR_MIN_SPREAD in the ground plane, or when |(c, s)| is far
# from 1 (no rigid planar motion fits the pair).
_PLANAR_MIN_SPREAD = 0.05  # m
_PLANAR_SCALE_GATE = 0.25  # largest | |(c, s)| − 1 | of a kept hypothesis
_PLANAR_SINGULAR = 1e-9  # |det| / (product of the row norms) below which the sample is singular
_PLANAR_LO_ROUNDS = 5  # re-solve / re-select rounds after the RANSAC


@njit(cache=True)
def _planar_two_point(
    p1: NDArray[np.float64], n1: NDArray[np.float64], p2: NDArray[np.float64],
    n2: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
) -> tuple[bool, float, float, float]:
    """(ok, x, y, yaw) of the planar pose putting old points `p1`, `p2` (old base frame) on the
    normalised image coordinates `n1`, `n2`."""
    m = np.zeros((4, 4))
    rhs = np.zeros(4)
    for k in range(2):
        p = p1 if k == 0 else p2
        nn = n1 if k == 0 else n2
        for e in range(2):
            r0 = a[e, 0] - nn[e] * a[2, 0]
            r1 = a[e, 1] - nn[e] * a[2, 1]
            r2 = a[e, 2] - nn[e] * a[2, 2]
            row = 2 * k + e
            m[row, 0] = r0 * p[0] + r1 * p[1]
            m[row, 1] = r0 * p[1] - r1 * p[0]
            m[row, 2] = -r0
            m[row, 3] = -r1
            rhs[row] = -(r2 * p[2] + b[e] - nn[e] * b[2])
    if math.hypot(p1[0] - p2[0], p1[1] - p2[1]) < _PLANAR_MIN_SPREAD:
        return False, 0.0, 0.0, 0.0
    norms = 1.0
    for row in range(4):
        norms *= math.sqrt(m[row, 0] ** 2 + m[row, 1] ** 2 + m[row, 2] ** 2 + m[row, 3] ** 2)
    if norms <= 0.0:
        return False, 0.0, 0.0, 0.0
    # Gaussian elimination with partial pivoting on a copy (m, rhs are kept for the re-solve)
    w = m.copy()
    z = rhs.copy()
    det = 1.0
    for col in range(4):
        piv = col
        for row in range(col + 1, 4):
            if abs(w[row, col]) > abs(w[piv, col]):
                piv = row
        if piv != col:
            for k in range(4):
                w[col, k], w[piv, k] = w[piv, k], w[col, k]
            z[col], z[piv] = z[piv], z[col]
            det = -det
        det *= w[col, col]
        if w[col, col] == 0.0:
            return False, 0.0, 0.0, 0.0
        for row in range(col + 1, 4):
            f = w[row, col] / w[col, col]
            for k in range(col, 4):
                w[row, k] -= f * w[col, k]
            z[row] -= f * z[col]
    if abs(det) < _PLANAR_SINGULAR * norms:
        return False, 0.0, 0.0, 0.0
    sol = np.zeros(4)
    for row in range(3, -1, -1):
        acc = z[row]
        for k in range(row + 1, 4):
            acc -= w[row, k] * sol[k]
        sol[row] = acc / w[row, row]
    scale = math.hypot(sol[0], sol[1])
    if abs(scale - 1.0) > _PLANAR_SCALE_GATE:
        return False, 0.0, 0.0, 0.0
    c, s = sol[0] / scale, sol[1] / scale
    # with the rotation on the unit circle, (a1, a2) by least squares over the four equations
    h00 = h01 = h11 = g0 = g1 = 0.0
    for row in range(4):
        res = rhs[row] - m[row, 0] * c - m[row, 1] * s
        h00 += m[row, 2] * m[row, 2]
        h01 += m[row, 2] * m[row, 3]
        h11 += m[row, 3] * m[row, 3]
        g0 += m[row, 2] * res
        g1 += m[row, 3] * res
    d = h00 * h11 - h01 * h01
    if abs(d) < 1e-12:
        return False, 0.0, 0.0, 0.0
    a1 = (h11 * g0 - h01 * g1) / d
    a2 = (h00 * g1 - h01 * g0) / d
    return True, c * a1 - s * a2, s * a1 + c * a2, math.atan2(s, c)


@njit(cache=True, inline="always")
def _planar_project(
    c: float, s: float, x: float, y: float, pts: NDArray[np.float64], k: int,
    a: NDArray[np.float64], b: NDArray[np.float64],
) -> tuple[float, float, float, float, float]:
    """Point k (old base frame) in the base frame moved by (x, y, yaw = atan2(s, c)): its
    planar coordinates q0, q1, and in the camera (a · q + b): p0, p1, p2."""
    dx, dy = pts[k, 0] - x, pts[k, 1] - y
    q0, q1, q2 = c * dx + s * dy, -s * dx + c * dy, pts[k, 2]
    p0 = a[0, 0] * q0 + a[0, 1] * q1 + a[0, 2] * q2 + b[0]
    p1 = a[1, 0] * q0 + a[1, 1] * q1 + a[1, 2] * q2 + b[1]
    p2 = a[2, 0] * q0 + a[2, 1] * q1 + a[2, 2] * q2 + b[2]
    return q0, q1, p0, p1, p2


@njit(cache=True)
def _planar_errors(
    x: float, y: float, yaw: float, pts: NDArray[np.float64], uv: NDArray[np.float64],
    a: NDArray[np.float64], b: NDArray[np.float64], cam: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """Reprojection error (px, inf behind the camera) of every point under (x, y, yaw)."""
    c, s = math.cos(yaw), math.sin(yaw)
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    for k in range(pts.shape[0]):
        q0, q1, p0, p1, p2 = _planar_project(c, s, x, y, pts, k, a, b)
        if p2 <= 1e-6:
            out[k] = np.inf
        else:
            out[k] = math.hypot(fx * p0 / p2 + cx - uv[k, 0], fy * p1 / p2 + cy - uv[k, 1])


@njit(cache=True)
def _planar_ransac(
    pts: NDArray[np.float64], uv: NDArray[np.float64], pairs: NDArray[np.int64],
    a: NDArray[np.float64], b: NDArray[np.float64], cam: NDArray[np.float64], thr: float,
    confidence: float, guess: NDArray[np.float64], use_guess: bool,
) -> tuple[float, float, float, int, int]:
    """Best (x, y, yaw) by inlier count (ties: smaller truncated error), its inlier count and
    the hypotheses drawn; stops once `confidence` of an all-inlier sample is reached."""
    n = pts.shape[0]
    norm = np.empty((n, 2))
    for k in range(n):
        norm[k, 0] = (uv[k, 0] - cam[2]) / cam[0]
        norm[k, 1] = (uv[k, 1] - cam[3]) / cam[1]
    err = np.empty(n)
    best = (0.0, 0.0, 0.0)
    best_score, best_count = -1.0, 0
    max_iters = pairs.shape[0]
    need = max_iters
    drawn = 0
    log_fail = math.log(1.0 - confidence)
    if use_guess:
        _planar_errors(guess[0], guess[1], guess[2], pts, uv, a, b, cam, err)
        count, trunc = 0, 0.0
        for k in range(n):
            if err[k] < thr:
                count += 1
            trunc += min(err[k], thr)
        best = (guess[0], guess[1], guess[2])
        best_count = count
        best_score = count - trunc / (thr * (n + 1))
        ratio = count / n
        if ratio >= 1.0:
            need = 0
        elif ratio > 0.0:
            need = min(max_iters, math.ceil(log_fail / math.log(1.0 - ratio * ratio)))
    for h in range(max_iters):
        if drawn >= need:
            break
        drawn += 1
        i, j = pairs[h, 0], pairs[h, 1]
        ok, x, y, yaw = _planar_two_point(pts[i], norm[i], pts[j], norm[j], a, b)
        if not ok:
            continue
        _planar_errors(x, y, yaw, pts, uv, a, b, cam, err)
        count, trunc = 0, 0.0
        for k in range(n):
            if err[k] < thr:
                count += 1
            trunc += min(err[k], thr)
        score = count - trunc / (thr * (n + 1))
        if score > best_score:
            best, best_score, best_count = (x, y, yaw), score, count
            ratio = count / n
            if ratio >= 1.0:
                need = 0
            elif ratio > 0.0:
                need = min(max_iters, math.ceil(log_fail / math.log(1.0 - ratio * ratio)))
    return best[0], best[1], best[2], best_count, drawn


@njit(cache=True)
def _planar_refine(
    x: float, y: float, yaw: float, pts: NDArray[np.float64], uv: NDArray[np.float64],
    a: NDArray[np.float64], b: NDArray[np.float64], cam: NDArray[np.float64], steps: int,
    huber: float,
) -> tuple[float, float, float]:
    """Huber-weighted Gauss-Newton on (x, y, yaw) minimising the reprojection error (the
    compiled form of `_refine_3dof`)."""
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    for _ in range(steps):
        c, s = math.cos(yaw), math.sin(yaw)
        h = np.zeros((3, 3))
        g = np.zeros(3)
        behind = False
        for k in range(pts.shape[0]):
            q0, q1, p0, p1, p2 = _planar_project(c, s, x, y, pts, k, a, b)
            if p2 <= 1e-6:
                behind = True
                break
            iz = 1.0 / p2
            # d q / d(x, y, yaw) columns: (-c, s, 0), (-s, -c, 0), (q1, -q0, 0)
            jq = ((-c, -s, q1), (s, -c, -q0))
            jp = np.empty((3, 3))
            for r in range(3):
                for col in range(3):
                    jp[r, col] = a[r, 0] * jq[0][col] + a[r, 1] * jq[1][col]
            ru = fx * p0 * iz + cx - uv[k, 0]
            rv = fy * p1 * iz + cy - uv[k, 1]
            ju = np.empty(3)
            jv = np.empty(3)
            for col in range(3):
                ju[col] = fx * (jp[0, col] * iz - p0 * iz * iz * jp[2, col])
                jv[col] = fy * (jp[1, col] * iz - p1 * iz * iz * jp[2, col])
            wu = min(1.0, huber / max(abs(ru), 1e-12))
            wv = min(1.0, huber / max(abs(rv), 1e-12))
            for r in range(3):
                g[r] += wu * ju[r] * ru + wv * jv[r] * rv
                for col in range(3):
                    h[r, col] += wu * ju[r] * ju[col] + wv * jv[r] * jv[col]
        if behind:
            break
        det = np.linalg.det(h)
        if not np.isfinite(det) or abs(det) < 1e-30:
            break
        step = np.linalg.solve(h, -g)
        x, y, yaw = x + step[0], y + step[1], yaw + step[2]
        if abs(step[0]) + abs(step[1]) < 1e-7 and abs(step[2]) < 1e-8:
            break
    return x, y, yaw


def _planar_camera(camera: CameraIntrinsics) -> tuple[F64, F64, F64]:
    m = se3_inverse(camera.local_transform)
    return (np.ascontiguousarray(m[:3, :3]), np.ascontiguousarray(m[:3, 3]),
            np.array([camera.fx, camera.fy, camera.cx, camera.cy], np.float64))


def planar_two_point(
    object_points: F64, image_points: NDArray[np.floating], camera: CameraIntrinsics
) -> F64 | None:
    """The planar pose (4×4, new base in old) that puts two old 3D points (old base frame,
    (2, 3)) on their two keypoints ((2, 2) px), or None for a degenerate sample (see above)."""
    a, b, cam = _planar_camera(camera)
    pts = np.asarray(object_points, np.float64)
    uv = np.asarray(image_points, np.float64)
    norm = np.stack([(uv[:, 0] - cam[2]) / cam[0], (uv[:, 1] - cam[3]) / cam[1]], axis=1)
    ok, x, y, yaw = _planar_two_point(pts[0], norm[0], pts[1], norm[1], a, b)
    return from_xyz_yaw(x, y, yaw) if ok else None


def solve_pnp_planar(
    object_points: F64,
    image_points: NDArray[np.floating],
    camera: CameraIntrinsics,
    params: RtabmapParameters,
    guess: F64 | None = None,
) -> tuple[F64 | None, NDArray[np.intp]]:
    """`Vis/PnPMinimal3DoF`: PnP RANSAC in x, y, yaw (same contract as `solve_pnp`).

    Hypotheses from two correspondences (`planar_two_point`), drawn by a generator seeded with
    the number of matches (deterministic), at most `Vis/Iterations`, fewer once an all-inlier
    sample has been drawn with confidence 0.99 at the best inlier ratio so far (2-point
    samples: ≈ 16 draws at 50 % inliers, ≈ 113 at 20 %, where a 5-point 6-DoF sample needs
    ≈ 150 and ≈ 14,000); the guess (projected to 3 DoF) competes as one more hypothesis. An
    inlier reprojects within `Vis/PnPReprojError` px. The best hypothesis is then re-solved on
    its inliers (`_planar_refine`) and the inliers re-selected among all matches, up to
    _PLANAR_LO_ROUNDS times while that keeps at least as many and until they stop changing (a
    2-point hypothesis is noisier than a 5-point one; its first inlier set is a subset)."""
    n = object_points.shape[0]
    if n < 4:
        return None, np.zeros(0, np.intp)
    pts = np.ascontiguousarray(object_points, np.float64)
    uv = np.ascontiguousarray(image_points, np.float64)
    a, b, cam = _planar_camera(camera)
    rng = np.random.default_rng(n)
    iters = max(1, params.vis_iterations)
    first = rng.integers(0, n, iters)
    pairs = np.stack([first, (first + rng.integers(1, n, iters)) % n], axis=1).astype(np.int64)
    g = np.zeros(3)
    if guess is not None:
        g[:] = (guess[0, 3], guess[1, 3], yaw_of(guess))
    thr = float(params.vis_pnp_reproj_error)
    x, y, yaw, count, _ = _planar_ransac(pts, uv, pairs, a, b, cam, thr, _CONFIDENCE, g,
                                         guess is not None)
    if count < 3:
        return None, np.zeros(0, np.intp)
    err = np.empty(n)
    _planar_errors(x, y, yaw, pts, uv, a, b, cam, err)
    inliers = np.flatnonzero(err < thr).astype(np.intp)
    for _ in range(_PLANAR_LO_ROUNDS):
        rx, ry, ryaw = _planar_refine(x, y, yaw, pts[inliers], uv[inliers], a, b, cam,
                                      _REFINE_STEPS, _HUBER_PX)
        if not (np.isfinite(rx) and np.isfinite(ry) and np.isfinite(ryaw)):
            break
        _planar_errors(rx, ry, ryaw, pts, uv, a, b, cam, err)
        refined = np.flatnonzero(err < thr).astype(np.intp)
        if refined.size < inliers.size:
            break
        same = np.array_equal(refined, inliers)
        x, y, yaw, inliers = rx, ry, ryaw, refined
        if same:
            break
    return from_xyz_yaw(x, y, yaw), inliers


@njit(cache=True, inline="always")
def _pair_error(p: F64, q: F64, r: F64, t: F64, m: int) -> float:
    """|p_m − (R q_m + t)|, summed in a fixed order (the RANSAC scores depend on it bit for bit)."""
    d0 = p[m, 0] - (r[0, 0] * q[m, 0] + r[0, 1] * q[m, 1] + r[0, 2] * q[m, 2] + t[0])
    d1 = p[m, 1] - (r[1, 0] * q[m, 0] + r[1, 1] * q[m, 1] + r[1, 2] * q[m, 2] + t[1])
    d2 = p[m, 2] - (r[2, 0] * q[m, 0] + r[2, 1] * q[m, 1] + r[2, 2] * q[m, 2] + t[2])
    return math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@lru_cache(maxsize=2048)
def _ransac_samples(n: int, iters: int, k: int) -> NDArray[np.int64]:
    """The RANSAC samples of `solve_3d3d` for n pairs: k distinct pair positions per
    hypothesis, the k smallest of n random draws in increasing order (argsort(draws)[:, :k]),
    from a generator seeded with n. A function of (n, iters, k) only, so kept (read-only):
    closures verified with as many matched pairs draw the same samples."""
    draws = np.random.default_rng(n).random((iters, n))
    samples = _smallest_sorted(draws, k)
    if samples is None:  # tied draws: leave their order to numpy
        part = np.argpartition(draws, k - 1, axis=1)[:, :k]
        samples = np.take_along_axis(
            part, np.argsort(np.take_along_axis(draws, part, axis=1), axis=1), axis=1)
    samples.flags.writeable = False
    return samples


@njit(cache=True)
def _smallest_k1(draws: F64, k: int) -> tuple[NDArray[np.int64], bool]:
    """Per row, the positions of the k + 1 smallest values in increasing order (first seen
    first among equals), and whether any two of them are equal."""
    rows, n = draws.shape
    m = k + 1
    out = np.empty((rows, m), np.int64)
    tied = False
    val = np.empty(m)
    pos = np.empty(m, np.int64)
    for r in range(rows):
        filled = 0
        for j in range(n):
            x = draws[r, j]
            if filled == m and not x < val[m - 1]:
                if x == val[m - 1]:
                    tied = True
                continue
            # insert after any equal values already kept
            i = filled if filled < m else m - 1
            while i > 0 and x < val[i - 1]:
                if i < m:
                    val[i] = val[i - 1]
                    pos[i] = pos[i - 1]
                i -= 1
            val[i] = x
            pos[i] = j
            if filled < m:
                filled += 1
        for i in range(filled):
            out[r, i] = pos[i]
            if i > 0 and val[i] == val[i - 1]:
                tied = True
    return out, tied


def _smallest_sorted(draws: F64, k: int) -> NDArray[np.int64] | None:
    """`argsort(draws, axis=1)[:, :k]` (the positions of each row's k smallest values, in
    increasing order) in one pass per row; None when a tie among the k + 1 smallest could make
    the order depend on the sorting algorithm (the caller then sorts with numpy)."""
    if draws.shape[1] <= k:
        return None
    idx, tied = _smallest_k1(np.ascontiguousarray(draws, dtype=np.float64), k)
    if tied:
        return None
    return np.ascontiguousarray(idx[:, :k])


@njit(cache=True)
def _best_3d3d(rot: F64, trans: F64, valid: NDArray[np.bool_], p: F64, q: F64,
               thr: float) -> int:
    """The best hypothesis h of a 3D→3D RANSAC: the first argmax of its score, the inliers
    (|p − (R_h q + t_h)| ≤ thr; −1 when the sample is degenerate) less the summed capped error
    / (thr·(n + 1)), so ties go to the smaller error. Hypotheses that cannot win are not
    finished: every 32 pairs, one whose score could at most reach (all remaining pairs inliers
    at zero error) stays below the best so far is dropped; the scores that are finished are
    summed pair by pair as the full score is, so the first best is the same hypothesis."""
    iters, n = rot.shape[0], p.shape[0]
    denom = thr * (n + 1)
    best = -np.inf
    best_h = 0
    for h in range(iters):
        r = rot[h]
        count = 0
        total = 0.0
        dropped = False
        for m in range(n):
            e = _pair_error(p, q, r, trans[h], m)
            if e <= thr:
                count += 1
                total += e
            else:
                total += thr
            if (m & 31) == 31:
                # the total only grows and the count gains at most the pairs left
                bound = ((count + n - 1 - m) if valid[h] else -1) - total / denom
                if bound < best:
                    dropped = True
                    break
        if dropped:
            continue
        score = (count if valid[h] else -1) - total / (thr * (n + 1))
        if score > best:
            best = score
            best_h = h
    return best_h


def _errors_3d3d(rot: F64, trans: F64, p: F64, q: F64) -> F64:
    """|p − (R q + t)| per pair, the distances `_best_3d3d` tests."""
    moved = (q[:, 0:1] * rot[:, 0] + q[:, 1:2] * rot[:, 1]) + q[:, 2:3] * rot[:, 2] + trans
    d = p - moved
    return np.asarray(np.sqrt((d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]))


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
    iters = max(1, params.vis_iterations)
    samples = _ransac_samples(n, iters, k)
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
    h_best = int(_best_3d3d(np.ascontiguousarray(rot), np.ascontiguousarray(trans), valid,
                            np.ascontiguousarray(from_points, dtype=np.float64),
                            np.ascontiguousarray(to_points, dtype=np.float64), thr))
    best_err = _errors_3d3d(rot[h_best], trans[h_best], from_points, to_points)
    best: NDArray[np.intp] = np.flatnonzero(best_err <= thr).astype(np.intp)
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
