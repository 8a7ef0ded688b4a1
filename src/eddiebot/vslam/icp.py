"""Point-to-point 2D ICP for refining neighbour links with laser scans."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

__all__ = ["IcpResult", "icp_2d"]

F64 = NDArray[np.float64]


class IcpResult(NamedTuple):
    """Pose of the new scan's frame in the reference frame (m, rad) and variances."""

    x: float
    y: float
    theta: float
    linear_variance: float
    angular_variance: float
    correspondence_ratio: float


def icp_2d(
    reference: F64,
    scan: F64,
    guess: F64,
    *,
    max_iterations: int = 30,
    max_correspondence: float = 0.2,
    max_translation: float = 0.2,
    max_rotation: float = 0.78,
    min_correspondence_ratio: float = 0.1,
) -> IcpResult | None:
    """Align `scan` (N, 2) onto `reference` (M, 2) starting at `guess` (x, y, θ); None on failure.

    Rejections as RTAB-Map's ICP: a correction beyond `max_translation`/`max_rotation` of the
    guess or a correspondence ratio ≤ `min_correspondence_ratio`. Variances: 2.1981 × median
    squared correspondence distance / 10 (linear) and / 100 (angular).
    """
    tree = cKDTree(reference)
    x, y, th = (float(v) for v in guess)
    ratio = 0.0
    d2 = np.zeros(0)
    for _ in range(max_iterations):
        c, s = np.cos(th), np.sin(th)
        moved = scan @ np.array([[c, s], [-s, c]]) + (x, y)
        dist, idx = tree.query(moved, distance_upper_bound=max_correspondence)
        ok = np.isfinite(dist)
        ratio = float(ok.mean()) if ok.size else 0.0
        if ok.sum() < 3:
            return None
        a = moved[ok]
        b = reference[idx[ok]]
        ca, cb = a.mean(axis=0), b.mean(axis=0)
        h = (a - ca).T @ (b - cb)
        dth = float(np.arctan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1]))
        cd, sd = np.cos(dth), np.sin(dth)
        r = np.array([[cd, -sd], [sd, cd]])
        dt = cb - r @ ca
        x, y = (r @ np.array([x, y]) + dt).tolist()
        th = float(np.arctan2(np.sin(th + dth), np.cos(th + dth)))
        d2 = dist[ok] ** 2
        if abs(dth) < 1e-6 and float(np.linalg.norm(dt)) < 1e-6:
            break
    if ratio <= min_correspondence_ratio:
        return None
    if np.hypot(x - guess[0], y - guess[1]) > max_translation:
        return None
    if abs(np.arctan2(np.sin(th - guess[2]), np.cos(th - guess[2]))) > max_rotation:
        return None
    med = float(np.median(d2)) if d2.size else 0.0
    var = max(2.1981 * med, 1e-6)
    return IcpResult(x, y, th, var / 10.0, var / 100.0, ratio)
