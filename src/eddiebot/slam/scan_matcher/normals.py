"""Point normals from a PCA of each point's nearest neighbours (line-like neighbourhoods
only), for point-to-line ICP and the scan-geometry covariance."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def _insert_neighbour(
    best_d: FloatArray, best_i: npt.NDArray[np.int64], filled: int, d: float, j: int
) -> int:
    """Insert candidate j at squared distance d into the sorted k-best lists; new fill."""
    k = best_d.size
    if filled == k and d >= best_d[k - 1]:
        return filled
    pos = filled if filled < k else k - 1
    while pos > 0 and best_d[pos - 1] > d:
        if pos < k:
            best_d[pos] = best_d[pos - 1]
            best_i[pos] = best_i[pos - 1]
        pos -= 1
    best_d[pos] = d
    best_i[pos] = j
    return filled + 1 if filled < k else filled


@njit(cache=True)
def _nearest_sweep(
    points: FloatArray, by_x: npt.NDArray[np.int64], k: int
) -> npt.NDArray[np.int64]:
    """Indices (M, k) of each point's k nearest points (itself included), nearest first.

    ``by_x`` orders the points by x; each point's search walks outwards in that order and
    stops on either side once the x gap alone exceeds its k-th best distance (exact).
    """
    m = points.shape[0]
    out = np.empty((m, k), np.int64)
    best_d = np.empty(k)
    best_i = np.empty(k, np.int64)
    for p in range(m):
        i = by_x[p]
        xi = points[i, 0]
        yi = points[i, 1]
        filled = 0
        q = p
        while q >= 0:
            j = by_x[q]
            dx = points[j, 0] - xi
            if filled == k and dx * dx > best_d[k - 1]:
                break
            dy = points[j, 1] - yi
            filled = _insert_neighbour(best_d, best_i, filled, dx * dx + dy * dy, j)
            q -= 1
        q = p + 1
        while q < m:
            j = by_x[q]
            dx = points[j, 0] - xi
            if filled == k and dx * dx > best_d[k - 1]:
                break
            dy = points[j, 1] - yi
            filled = _insert_neighbour(best_d, best_i, filled, dx * dx + dy * dy, j)
            q += 1
        for q in range(k):
            out[i, q] = best_i[q]
    return out


@njit(cache=True)
def _pca_normals(points: FloatArray, nn: npt.NDArray[np.int64]) -> FloatArray:
    """Each point's normal: the eigenvector of the smaller eigenvalue of its neighbourhood's
    scatter matrix (closed form for 2 × 2), NaN unless that eigenvalue is below a tenth of
    the larger one (a line-like neighbourhood)."""
    m, k = nn.shape
    out = np.empty((m, 2))
    for p in range(m):
        m0 = 0.0
        m1 = 0.0
        for q in range(k):
            m0 += points[nn[p, q], 0]
            m1 += points[nn[p, q], 1]
        m0 /= k
        m1 /= k
        c00 = 0.0
        c10 = 0.0
        c11 = 0.0
        for q in range(k):
            d0 = points[nn[p, q], 0] - m0
            d1 = points[nn[p, q], 1] - m1
            c00 += d0 * d0
            c10 += d1 * d0
            c11 += d1 * d1
        half_trace = 0.5 * (c00 + c11)
        radius = math.hypot(0.5 * (c00 - c11), c10)
        w1 = half_trace + radius
        w0 = half_trace - radius
        if w0 < 0.1 * w1 + 1e-12:
            # the larger eigenvalue's direction is at ½·atan2(2 c10, c00 − c11)
            phi = 0.5 * math.atan2(2.0 * c10, c00 - c11)
            out[p, 0] = -math.sin(phi)
            out[p, 1] = math.cos(phi)
        else:
            out[p, 0] = np.nan
            out[p, 1] = np.nan
    return out


def point_normals(points: FloatArray, neighbours: int = 6) -> FloatArray:
    """Unit normals (M, 2) from a PCA of each point's ``neighbours`` nearest points (found by
    a compiled sweep along x: exact, nearest first, as a k-d tree query); NaN where the
    neighbourhood is not line-like (corners, clutter). A normal's sign is arbitrary."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.shape[0] < neighbours:
        return np.full(points.shape, np.nan)
    by_x = np.argsort(points[:, 0], kind="stable").astype(np.int64)
    return _pca_normals(points, _nearest_sweep(points, by_x, neighbours))
