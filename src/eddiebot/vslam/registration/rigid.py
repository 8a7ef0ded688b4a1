"""3D-3D registration (`Vis/EstimationType` 0): RANSAC over point pairs from both frames' depth,
with numba kernels and cached sample sets."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from numba import njit
from numpy.typing import NDArray

from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.common import F64
from eddiebot.vslam.transforms import fit_rigid


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
