"""Point-to-line ICP from a correlative match, with the fit's covariance."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.geometry import wrap_angle
from eddiebot.geometry.grid import bucket_grid
from eddiebot.slam.scan_matcher.normals import point_normals

FloatArray = npt.NDArray[np.float64]


#: cells per ICP pairing distance in the nearest-neighbour buckets (cell = 5 cm at 0.2 m; any
#: count gives the same pairs, a finer one fewer distance checks per point)
_ICP_CELLS_PER_RANGE = 4


@njit(cache=True)
def _icp_pairs(
    points: FloatArray,
    reference: FloatArray,
    normals: FloatArray,
    planar: npt.NDArray[np.bool_],
    pose: FloatArray,
    max_distance: float,
    x0: float,
    y0: float,
    nx: int,
    ny: int,
    start: npt.NDArray[np.int64],
    order: npt.NDArray[np.int64],
    jac: FloatArray,
    r: FloatArray,
    jac_w: FloatArray,
    w: FloatArray,
) -> int:
    """Point-to-line pairs at ``pose``: each point's nearest reference point closer than
    ``max_distance`` (searched ring by ring over cells of ``max_distance`` /
    `_ICP_CELLS_PER_RANGE`, stopping once no outer cell can hold a nearer one), kept when that
    point's normal is line-like. Writes, in point order, each
    pair's Jacobian row (n, n·R'p) into ``jac``, its residual n·(world − q) into ``r``, its
    Huber weight (5 cm) into ``w`` and the weighted row into ``jac_w`` (the values the numpy
    expressions gave, element by element);
    returns the number of pairs."""
    c = math.cos(pose[2])
    s = math.sin(pose[2])
    md2 = max_distance * max_distance
    cell = max_distance / _ICP_CELLS_PER_RANGE
    rings = _ICP_CELLS_PER_RANGE
    count = 0
    for i in range(points.shape[0]):
        px = points[i, 0]
        py = points[i, 1]
        wx = pose[0] + c * px - s * py
        wy = pose[1] + s * px + c * py
        cx = math.floor((wx - x0) / cell)
        cy = math.floor((wy - y0) / cell)
        best = -1
        best_d2 = md2
        for ring in range(rings + 1):
            for iy in range(max(cy - ring, 0), min(cy + ring + 1, ny)):
                edge = iy == cy - ring or iy == cy + ring
                step = 1 if edge else 2 * ring
                for ix in range(cx - ring, cx + ring + 1, max(step, 1)):
                    if ix < 0 or ix >= nx:
                        continue
                    k = iy * nx + ix
                    for m in range(start[k], start[k + 1]):
                        j = order[m]
                        dx = wx - reference[j, 0]
                        dy = wy - reference[j, 1]
                        d2 = dx * dx + dy * dy
                        if d2 < best_d2 or (d2 == best_d2 and best >= 0 and j < best):
                            best_d2 = d2
                            best = j
            # anything in an outer ring is at least ring·cell away
            if best >= 0 and best_d2 < (ring * cell) ** 2:
                break
            # ... and at least as far as the searched square's nearest side that has cells
            # beyond it (less a margin for the buckets' rounding): most points stop after
            # the cell they fall in
            gap = math.inf
            if cx - ring - 1 >= 0:
                gap = min(gap, wx - (x0 + (cx - ring) * cell))
            if cx + ring + 1 <= nx - 1:
                gap = min(gap, x0 + (cx + ring + 1) * cell - wx)
            if cy - ring - 1 >= 0:
                gap = min(gap, wy - (y0 + (cy - ring) * cell))
            if cy + ring + 1 <= ny - 1:
                gap = min(gap, y0 + (cy + ring + 1) * cell - wy)
            gap -= 1e-9
            if gap > 0.0 and (gap >= max_distance or (best >= 0 and best_d2 < gap * gap)):
                break
        if best < 0 or not planar[best]:
            continue
        n0 = normals[best, 0]
        n1 = normals[best, 1]
        r[count] = n0 * (wx - reference[best, 0]) + n1 * (wy - reference[best, 1])
        jac[count, 0] = n0
        jac[count, 1] = n1
        jac[count, 2] = n0 * (-s * px - c * py) + n1 * (c * px - s * py)
        wk = min(1.0, 0.05 / max(abs(r[count]), 1e-9))
        w[count] = wk
        jac_w[count, 0] = n0 * wk
        jac_w[count, 1] = n1 * wk
        jac_w[count, 2] = jac[count, 2] * wk
        count += 1
    return count


def refine_icp(
    points: FloatArray,
    reference: FloatArray,
    pose: FloatArray,
    *,
    max_distance: float = 0.2,
    iterations: int = 10,
    normal_neighbours: int = 6,
    reference_normals: FloatArray | None = None,
) -> tuple[FloatArray, float]:
    """Point-to-line ICP from ``pose`` (sensor pose, map frame) onto reference points (map).

    Normals come from a PCA of each reference point's nearest neighbours; pairs farther than
    ``max_distance`` are ignored and the rest weighted by a Huber kernel (5 cm). Returns the
    refined pose and the inlier share (0..1). The correlative search finds the basin; this
    polishes the pose below the search grid's and the smear's resolution.
    """
    pose_out, share, _ = refine_icp_with_covariance(
        points,
        reference,
        pose,
        max_distance=max_distance,
        iterations=iterations,
        normal_neighbours=normal_neighbours,
        reference_normals=reference_normals,
    )
    return pose_out, share


def refine_icp_with_covariance(
    points: FloatArray,
    reference: FloatArray,
    pose: FloatArray,
    *,
    max_distance: float = 0.2,
    iterations: int = 10,
    normal_neighbours: int = 6,
    reference_normals: FloatArray | None = None,
) -> tuple[FloatArray, float, FloatArray | None]:
    """`refine_icp`, also returning the fit's covariance (3×3, map frame, m², rad²).

    The covariance is the Gauss–Newton one at the final pose: the inverse of the weighted
    point-to-line Hessian JᵀWJ scaled by the weighted residual variance Σwr²/(Σw − 3). It is
    small along directions the scan's lines pin down and large along those no line observes
    (a corridor's length: the Hessian is nearly singular there). None when fewer than 10
    pairs match.
    """
    pose = np.asarray(pose, dtype=np.float64).copy()
    if points.shape[0] < 10 or reference.shape[0] < normal_neighbours + 1:
        return pose, 0.0, None
    points = np.ascontiguousarray(points, dtype=np.float64)
    reference = np.ascontiguousarray(reference, dtype=np.float64)
    if reference_normals is None:
        normals = point_normals(reference, neighbours=normal_neighbours)
    else:
        normals = reference_normals
    planar = np.isfinite(normals[:, 0])
    normals = np.ascontiguousarray(np.where(planar[:, None], normals, 0.0), dtype=np.float64)
    x0, y0, nx, ny, start, order = bucket_grid(reference, max_distance / _ICP_CELLS_PER_RANGE)
    jac_buf = np.empty((points.shape[0], 3))
    jac_w_buf = np.empty((points.shape[0], 3))
    r_buf = np.empty(points.shape[0])
    w_buf = np.empty(points.shape[0])
    damping = 1e-9 * np.eye(3)
    inlier_share = 0.0
    fit: tuple[FloatArray, float] | None = None
    for it in range(iterations + 1):
        count = _icp_pairs(
            points, reference, normals, planar, pose, max_distance,
            x0, y0, nx, ny, start, order, jac_buf, r_buf, jac_w_buf, w_buf,
        )
        inlier_share = float(count) / points.shape[0]
        if count < 10:
            fit = None
            break
        # normal equations with numpy (BLAS), as the results were established with
        jac = jac_buf[:count]
        r = r_buf[:count]
        w = w_buf[:count]
        wr = w * r
        h = jac.T @ jac_w_buf[:count] + damping
        last = it == iterations
        if not last:
            delta = -np.linalg.solve(h, jac.T @ wr)
            pose += delta
            last = abs(delta[0]) < 1e-5 and abs(delta[1]) < 1e-5 and abs(delta[2]) < 1e-6
        if last:
            # the fit at the final pairs (before the step they gave): only this one is used
            sw = float(w.sum())
            fit = (h, float(np.sum(wr * r)) / max(sw - 3.0, 1.0))
            break
    covariance: FloatArray | None = None
    if fit is not None:
        covariance = np.asarray(fit[1] * np.linalg.inv(fit[0]), dtype=np.float64)
    pose[2] = float(wrap_angle(pose[2]))
    if covariance is not None:
        covariance = 0.5 * (covariance + covariance.T)
    return pose, inlier_share, covariance
