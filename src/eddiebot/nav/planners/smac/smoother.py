"""The Smac planners' path smoother (``nav2_smac_planner::Smoother``).

Gradient-descent smoothing of the path's interior points toward their neighbours
(``w_smooth``) while held to the original (``w_data``), until the summed change of a sweep
falls below ``tolerance``; the first sweep that would put a point on a cell above
MAX_NON_OBSTACLE (unknown excepted) ends it with the previous sweep's path; a run over
``max_iterations`` sweeps or the time left keeps the last sweep's path. With
``do_refinement`` the result is smoothed again ``refinement_num`` times. Non-holonomic
paths are smoothed per direction of travel (split at cusps); segments of 10 poses or fewer
are left as they are. Headings are then re-derived from the positions (reversed on a
reversing segment). On a non-holonomic path that converged, each segment's ends are then
re-fitted to its original end poses (``enforceStart/EndBoundaryConditions``): of the Dubins
curves from the end pose to the path point one turning radius, one diameter, half a
circumference and a whole circumference along, the shortest that stays off INSCRIBED cells
(and is at most twice the path it replaces) replaces those poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.nav.params import require
from eddiebot.nav.planners.smac.curves import curve_path, curve_sample
from eddiebot.nav.planners.smac.search import _now


@dataclass(frozen=True)
class SmacSmootherConfig:
    """``<planner>.smoother.*`` parameters (Jazzy code defaults)."""

    max_iterations: int = 1000
    w_smooth: float = 0.3
    w_data: float = 0.2
    tolerance: float = 1e-10
    do_refinement: bool = True
    refinement_num: int = 2

    def validate(self, server: str = "planner_server") -> None:
        require(self.max_iterations >= 0, server, "smoother.max_iterations",
                self.max_iterations, "must be >= 0")
        require(self.w_smooth >= 0.0, server, "smoother.w_smooth", self.w_smooth, "must be >= 0")
        require(self.w_data >= 0.0, server, "smoother.w_data", self.w_data, "must be >= 0")
        require(self.tolerance > 0.0, server, "smoother.tolerance", self.tolerance, "must be > 0")
        require(self.refinement_num >= 0, server, "smoother.refinement_num",
                self.refinement_num, "must be >= 0")


@njit(cache=True)
def _smooth_impl(xy: np.ndarray, grid: np.ndarray, ox: float, oy: float, res: float,
                 max_its: int, w_data: float, w_smooth: float, tol: float, deadline: float
                 ) -> tuple[np.ndarray, bool]:
    """``Smoother::smoothImpl`` without its refinement recursion."""
    n = xy.shape[0]
    new = xy.copy()
    last = xy.copy()
    h, w = grid.shape
    its = 0
    change = tol
    while change >= tol:
        its += 1
        change = 0.0
        if its >= max_its or _now() > deadline:
            return last, False
        for i in range(1, n - 1):
            for j in range(2):
                yi = new[i, j]
                org = yi
                yi += w_data * (xy[i, j] - yi) + w_smooth * (new[i + 1, j] + new[i - 1, j]
                                                             - 2.0 * yi)
                new[i, j] = yi
                change += abs(yi - org)
            mx = math.floor((new[i, 0] - ox) / res)
            my = math.floor((new[i, 1] - oy) / res)
            cost = 0
            if 0 <= mx < w and 0 <= my < h:
                cost = grid[my, mx]
            if cost > 252 and cost != 255:
                return last, False
        last[:] = new
    return new, True


def _segments(xy: npt.NDArray[np.float64], yaw: npt.NDArray[np.float64], holonomic: bool
              ) -> list[tuple[int, int]]:
    """``findDirectionalPathSegments``: split at cusps and at turns in place."""
    n = xy.shape[0]
    if holonomic or n < 3:
        return [(0, n - 1)]
    out = []
    start = 0
    for i in range(1, n - 1):
        oa = xy[i] - xy[i - 1]
        ab = xy[i + 1] - xy[i]
        if float(oa @ ab) < 0.0:
            out.append((start, i))
            start = i
        dth = math.remainder(yaw[i + 1] - yaw[i], 2 * math.pi)
        if abs(ab[0]) < 1e-4 and abs(ab[1]) < 1e-4 and abs(dth) > 1e-4:
            out.append((start, i))
            start = i
    out.append((start, n - 1))
    return out


def _orientations(xy: npt.NDArray[np.float64], yaw: npt.NDArray[np.float64], holonomic: bool
                  ) -> bool:
    """``updateApproximatePathOrientations`` (in place); whether the segment reverses."""
    n = xy.shape[0]
    if n < 3:
        return False
    reversing = False
    d = xy[2] - xy[1]
    theta = math.atan2(d[1], d[0])
    if not holonomic and abs(math.remainder(theta - yaw[1], 2 * math.pi)) > math.pi / 2:
        reversing = True
    for i in range(n - 1):
        dx, dy = xy[i + 1] - xy[i]
        if abs(dx) < 1e-4 and abs(dy) < 1e-4:
            continue
        th = math.atan2(dy, dx) + (math.pi if reversing else 0.0)
        yaw[i] = math.remainder(th, 2 * math.pi)
    return reversing


def _expansion(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], n: int,
               original_length: float, grid: npt.NDArray[np.uint8], ox: float, oy: float,
               res: float, radius: float) -> tuple[npt.NDArray[np.float64], float] | None:
    """``findBoundaryExpansion``: the Dubins curve a -> b sampled at n + 1 poses and its
    length; None when longer than twice the original or on an INSCRIBED (or worse) cell."""
    kinds, lengths, d = curve_path(a[0], a[1], a[2], b[0], b[1], b[2], radius, False)
    if d > 2.0 * original_length:
        return None
    pts = np.empty((n + 1, 3))
    h, w = grid.shape
    length = 0.0
    for i in range(n + 1):
        x, y, th, _ = curve_sample(a[0], a[1], a[2], kinds, lengths, radius, i / n)
        mx, my = math.floor((x - ox) / res), math.floor((y - oy) / res)
        if not (0 <= mx < w and 0 <= my < h) or grid[my, mx] >= 253:
            return None
        if i:
            length += math.hypot(x - pts[i - 1, 0], y - pts[i - 1, 1])
        pts[i] = (x, y, math.remainder(th, 2 * math.pi))
    return (pts, length) if length > 0.0 else None


def _enforce_boundary(seg: npt.NDArray[np.float64], pose: npt.NDArray[np.float64],
                      at_start: bool, reversing: bool, grid: npt.NDArray[np.uint8], ox: float,
                      oy: float, res: float, radius: float) -> None:
    """``enforceStartBoundaryConditions`` / ``enforceEndBoundaryConditions`` (in place)."""
    n = seg.shape[0]
    order = np.arange(n) if at_start else np.arange(n - 1, -1, -1)
    targets = [radius, 2.0 * radius, math.pi * radius, 2.0 * math.pi * radius]
    best: tuple[float, int, npt.NDArray[np.float64]] | None = None
    dist = 0.0
    k = 0
    last = seg[order[0], :2]
    for j, idx in enumerate(order):
        dist += float(np.hypot(*(seg[idx, :2] - last)))
        last = seg[idx, :2]
        if dist < targets[k]:
            continue
        if j > 0:
            far = seg[idx]
            outward = at_start != reversing
            a, b = (pose, far) if outward else (far, pose)
            found = _expansion(a, b, j, dist, grid, ox, oy, res, radius)
            if found is not None and (best is None or found[1] < best[0]):
                best = (found[1], j, found[0])
        k += 1
        if k == len(targets):
            break
    if best is None:
        return
    _, j, pts = best
    if reversing:
        pts = pts[::-1]
    if at_start:
        seg[:j + 1] = pts
    else:
        seg[n - 1 - j:] = pts


def smooth_path(path: npt.NDArray[np.float64], grid: npt.NDArray[np.uint8], origin_x: float,
                origin_y: float, resolution: float, config: SmacSmootherConfig, holonomic: bool,
                max_time: float, min_turning_radius: float = 0.0) -> npt.NDArray[np.float64]:
    """Smoothed copy of ``path`` (N, 3) on costmap ``grid`` within ``max_time`` seconds
    (``min_turning_radius`` in metres: the boundary curves of a non-holonomic path)."""
    out = np.array(path, dtype=np.float64, copy=True)
    if config.max_iterations == 0 or out.shape[0] < 3:
        return out
    deadline = float(_now()) + max_time
    for a, b in _segments(out[:, :2], out[:, 2], holonomic):
        if b - a <= 10:
            continue
        seg = np.ascontiguousarray(out[a:b + 1, :2])
        yaw = out[a:b + 1, 2].copy()
        rounds = 1 + (config.refinement_num if config.do_refinement else 0)
        for _ in range(rounds):
            seg, ok = _smooth_impl(seg, grid, origin_x, origin_y, resolution,
                                   config.max_iterations, config.w_data, config.w_smooth,
                                   config.tolerance, deadline)
            if not ok:
                break
        reversing = _orientations(seg, yaw, holonomic)
        piece = np.column_stack([seg, yaw])
        if not holonomic and ok and min_turning_radius > 0.0:
            for at_start, pose in ((True, out[a].copy()), (False, out[b].copy())):
                _enforce_boundary(piece, pose, at_start, reversing, grid, origin_x, origin_y,
                                  resolution, min_turning_radius)
        out[a:b + 1] = piece
    return out


__all__ = ["SmacSmootherConfig", "smooth_path"]
