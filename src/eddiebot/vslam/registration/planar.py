"""2-point planar PnP (`Vis/PnPMinimal3DoF`): a numba RANSAC over (x, y, yaw) hypotheses and its
refinement."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.common import _CONFIDENCE, _HUBER_PX, _REFINE_STEPS, F64
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, yaw_of

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
