"""Sub-cell refinement of a discrete match: Gauss–Newton on the bilinearly interpolated
correlation grid (Hector-style)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit


@njit(cache=True)
def _bilinear(grid: npt.NDArray[np.float32], u: float, v: float) -> tuple[float, float, float]:
    """Value and gradient (d/du, d/dv) at continuous cell coordinates (cell centres at k+0.5)."""
    h, w = grid.shape
    fu = u - 0.5
    fv = v - 0.5
    c0 = math.floor(fu)
    r0 = math.floor(fv)
    if c0 < 0 or r0 < 0 or c0 + 1 >= w or r0 + 1 >= h:
        return 0.0, 0.0, 0.0
    tu = fu - c0
    tv = fv - r0
    v00 = grid[r0, c0]
    v01 = grid[r0, c0 + 1]
    v10 = grid[r0 + 1, c0]
    v11 = grid[r0 + 1, c0 + 1]
    val = (1 - tv) * ((1 - tu) * v00 + tu * v01) + tv * ((1 - tu) * v10 + tu * v11)
    du = (1 - tv) * (v01 - v00) + tv * (v11 - v10)
    dv = (1 - tu) * (v10 - v00) + tu * (v11 - v01)
    return val, du, dv


@njit(cache=True)
def _solve3(
    a00: float,
    a01: float,
    a02: float,
    a11: float,
    a12: float,
    a22: float,
    b0: float,
    b1: float,
    b2: float,
) -> tuple[float, float, float]:
    """Solve the symmetric 3×3 system A x = b by Cramer's rule (A positive definite).

    Written out rather than ``np.linalg.solve``: LAPACK's binding costs seconds of JIT
    compilation in every fresh process without a numba cache.
    """
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    det = a00 * c00 + a01 * c01 + a02 * c02
    if abs(det) < 1e-300:
        return 0.0, 0.0, 0.0
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    inv = 1.0 / det
    return (
        (c00 * b0 + c01 * b1 + c02 * b2) * inv,
        (c01 * b0 + c11 * b1 + c12 * b2) * inv,
        (c02 * b0 + c12 * b1 + c22 * b2) * inv,
    )


@njit(cache=True)
def _refine(
    grid: npt.NDArray[np.float32],
    pts: npt.NDArray[np.float64],
    x: float,
    y: float,
    th: float,
    ox: float,
    oy: float,
    res: float,
    iterations: int,
) -> tuple[float, float, float, float]:
    """Gauss–Newton on Σ (1 - f(T p))² (Hector-style); returns pose and mean f."""
    n = pts.shape[0]
    for _ in range(iterations):
        c = math.cos(th)
        s = math.sin(th)
        h00 = h01 = h02 = h11 = h12 = h22 = 0.0
        g0 = g1 = g2 = 0.0
        for i in range(n):
            px = pts[i, 0]
            py = pts[i, 1]
            wx = c * px - s * py + x
            wy = s * px + c * py + y
            val, du, dv = _bilinear(grid, (wx - ox) / res, (wy - oy) / res)
            if val <= 0.0:
                continue
            gx = du / res
            gy = dv / res
            gth = gx * (-s * px - c * py) + gy * (c * px - s * py)
            r = 1.0 - val
            g0 += gx * r
            g1 += gy * r
            g2 += gth * r
            h00 += gx * gx
            h01 += gx * gy
            h02 += gx * gth
            h11 += gy * gy
            h12 += gy * gth
            h22 += gth * gth
        h00 += 1e-9 + 1e-3 * h00
        h11 += 1e-9 + 1e-3 * h11
        h22 += 1e-9 + 1e-3 * h22
        d0, d1, d2 = _solve3(h00, h01, h02, h11, h12, h22, g0, g1, g2)
        x += d0
        y += d1
        th += d2
        if abs(d0) < 1e-5 and abs(d1) < 1e-5 and abs(d2) < 1e-6:
            break
    c = math.cos(th)
    s = math.sin(th)
    total = 0.0
    for i in range(n):
        wx = c * pts[i, 0] - s * pts[i, 1] + x
        wy = s * pts[i, 0] + c * pts[i, 1] + y
        val, _, _ = _bilinear(grid, (wx - ox) / res, (wy - oy) / res)
        total += val
    return x, y, th, total / max(n, 1)
