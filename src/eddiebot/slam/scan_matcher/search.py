"""The correlative search (`match_scan`) and its set-up.

Headings ``prior ± coarse_search_angle_offset`` in ``coarse_angle_resolution`` steps; for each,
translations over the window: every second to fourth cell on a single-level grid (Karto's
coarse pass), or every cell by branch and bound on a pyramid. The best coarse candidate is
refined on fine headings over ±½ coarse step and ±2 cells, then to sub-cell accuracy; the
covariance follows Karto's recipe (`eddiebot.slam.scan_matcher.covariance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.geometry import wrap_angle
from eddiebot.slam.scan_matcher.branch_and_bound import (
    _branch_and_bound,
    _penalty,
    _top_level_scores,
    _window_near_best,
)
from eddiebot.slam.scan_matcher.covariance import _weighted_covariance
from eddiebot.slam.scan_matcher.grid import _MAX_LEVELS, CorrelationGrid, _score
from eddiebot.slam.scan_matcher.lookup import _cells_for_angles, _thin, _window_offsets
from eddiebot.slam.scan_matcher.subcell import _refine

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class MatcherParams:
    """One search set-up (slam_toolbox names in brackets)."""

    search_dimension: float = 0.5
    """Side of the square translation window, m [correlation_search_space_dimension]."""
    resolution: float = 0.01
    """Correlation grid cell, m [correlation_search_space_resolution]."""
    smear_deviation: float = 0.1
    """σ of the smear kernel, m [correlation_search_space_smear_deviation]."""
    coarse_angle_offset: float = 0.349
    """± heading range, rad [coarse_search_angle_offset]."""
    coarse_angle_resolution: float = 0.0349
    """Coarse heading step, rad [coarse_angle_resolution]."""
    fine_angle_step: float = 0.00349
    """Fine heading step, rad [fine_search_angle_offset]."""
    penalize: bool = True
    distance_variance_penalty: float = 0.5
    angle_variance_penalty: float = 1.0
    minimum_distance_penalty: float = 0.05
    minimum_angle_penalty: float = 0.9
    use_response_expansion: bool = True
    refine: bool = True
    """Sub-cell Gauss–Newton refinement after the discrete search."""
    coarse_heading_variance: bool = False
    """Heading variance from every coarse heading's best response over the whole window
    (headings within 0.1 of the best count), not only the fine headings next to the best:
    a narrow scan can fit nearly as well several degrees off."""


@dataclass(frozen=True)
class MatchResult:
    """Best pose (map frame, m/rad), its response (0..1) and covariance (3×3, m², rad²)."""

    pose: FloatArray
    response: float
    covariance: FloatArray


@njit(cache=True)
def _column_phases(grid: npt.NDArray[np.float32], step: int) -> npt.NDArray[np.float32]:
    """The grid's columns split by phase: ``out[p, r, j] = grid[r, step·j + p]`` (zero past
    the last column), so a run of every ``step``-th column is contiguous in one phase."""
    h, w = grid.shape
    wq = (w + step - 1) // step
    out = np.empty((step, h, wq), np.float32)
    for p in range(step):
        n = (w - p + step - 1) // step
        for r in range(h):
            src = grid[r, p:]
            dst = out[p, r]
            for j in range(n):
                dst[j] = src[step * j]
            for j in range(n, wq):
                dst[j] = 0.0
    return out


@njit(cache=True)
def _planes(grid: npt.NDArray[np.float32], step: int) -> npt.NDArray[np.float32]:
    """The grid as `_response_block` reads it for ``step``: its `_column_phases`, or for
    step 1 the grid itself as one plane (a view)."""
    if step == 1:
        h, w = grid.shape
        return grid.reshape((1, h, w))
    return _column_phases(grid, step)


@njit(cache=True)
def _response_block(
    phases: npt.NDArray[np.float32],
    w: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    x0: int,
    y0: int,
    n: int,
    step: int,
) -> npt.NDArray[np.float64]:
    """Mean grid value under the points for translations x0 + step·ix, y0 + step·iy,
    [ix, iy] (n × n), read from `_planes` of the grid (``w`` columns wide).

    Loops run point → row → column so that each point reads one contiguous run of a plane's
    row per candidate row (cache-friendly; the candidate-major order is several times
    slower); each point's in-grid column range is found once, so the innermost loop is a
    branch-free contiguous add. Every candidate adds the points in scan order.
    """
    h = phases.shape[1]
    acc = np.zeros((n, n))
    for i in range(px.size):
        c0 = px[i] + x0
        lo = 0 if c0 >= 0 else (step - 1 - c0) // step
        hi = min(n, (w - 1 - c0) // step + 1) if c0 <= w - 1 else 0
        if lo >= hi:
            continue
        c = c0 + step * lo
        plane = phases[c % step]
        j0 = c // step
        r0 = py[i] + y0
        m = hi - lo
        for iy in range(n):
            r = r0 + step * iy
            if r < 0 or r >= h:
                continue
            run = plane[r, j0:]
            out_run = acc[iy, lo:hi]
            for k in range(m):
                out_run[k] += run[k]
    inv = 1.0 / max(px.size, 1)
    out = np.empty((n, n))
    for ix in range(n):
        for iy in range(n):
            out[ix, iy] = acc[iy, ix] * inv
    return out


@njit(cache=True)
def _coarse_grid_search(
    g0: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    window: int,
    step: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
    profile: npt.NDArray[np.float64],
) -> tuple[int, int, int, float]:
    """Karto's coarse pass: every heading, translations every ``step`` cells.

    Also writes each heading's best (penalised) response into ``profile`` (the coarse
    heading variance's input).
    """
    best_a, best_x, best_y, best_s = -1, 0, 0, 0.0
    n = 2 * (window // step) + 1
    x0 = -(window // step) * step
    phases = _planes(g0, step)
    for a in range(px.shape[0]):
        block = _response_block(phases, g0.shape[1], px[a], py[a], x0, x0, n, step)
        best_h = 0.0
        for ix in range(n):
            for iy in range(n):
                s = block[ix, iy]
                # the penalty is at most 1: a raw response at or below both bests cannot win
                if s <= best_s and s <= best_h:
                    continue
                dx = x0 + step * ix
                dy = x0 + step * iy
                if penalize:
                    s *= _penalty(dx * res, dy * res, dth[a], dvp, avp, mdp, map_)
                if s > best_h:
                    best_h = s
                if s > best_s:
                    best_a, best_x, best_y, best_s = a, dx, dy, s
        profile[a] = best_h
    return best_a, best_x, best_y, best_s


@njit(cache=True)
def _exhaustive(
    g0: npt.NDArray[np.float32],
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    dth: npt.NDArray[np.float64],
    cx: int,
    cy: int,
    radius: int,
    res: float,
    penalize: bool,
    dvp: float,
    avp: float,
    mdp: float,
    map_: float,
) -> npt.NDArray[np.float64]:
    """Penalised responses (n_angles, 2r+1, 2r+1) around cell offset (cx, cy); [a, ix, iy]."""
    n_ang = px.shape[0]
    side = 2 * radius + 1
    out = np.zeros((n_ang, side, side))
    plane = _planes(g0, 1)
    w = g0.shape[1]
    for a in range(n_ang):
        block = _response_block(plane, w, px[a], py[a], cx - radius, cy - radius, side, 1)
        for ix in range(side):
            for iy in range(side):
                s = block[ix, iy]
                if penalize and s > 0.0:
                    s *= _penalty(
                        (cx - radius + ix) * res,
                        (cy - radius + iy) * res,
                        dth[a],
                        dvp,
                        avp,
                        mdp,
                        map_,
                    )
                out[a, ix, iy] = s
    return out


def score_pose(points: FloatArray, pose: FloatArray, grid: CorrelationGrid) -> float:
    """Response (0..1) of scan points (sensor frame) at ``pose`` (map frame) on ``grid``."""
    px, py = _cells_for_angles(points, np.asarray(pose, float), np.array([pose[2]], float), grid)
    return float(_score(grid.likelihood, px[0], py[0], 0, 0))


def match_scan(
    points: FloatArray,
    grid: CorrelationGrid,
    prior: FloatArray,
    params: MatcherParams,
    *,
    reject_below: float | None = None,
) -> MatchResult:
    """Match scan end points (M, 2, sensor frame) to ``grid`` around ``prior`` (sensor pose).

    With a single-level grid the translations are searched as Karto does (every second to
    fourth cell, then every cell around the best); with a pyramid (`build_correlation_grid(levels=n)`,
    n ≈ log2 of the window in cells) by branch and bound, exactly, at every cell.

    ``reject_below``: for a caller that discards a match whose response is below it, such a
    match returns as soon as its response is known, with the fine search's discrete pose and
    no covariance (``diag(1e3)``); the response is the one the full match would return.
    """
    prior = np.asarray(prior, dtype=np.float64)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    res = grid.resolution
    if pts.shape[0] == 0:
        return MatchResult(prior.copy(), 0.0, np.diag([1e3, 1e3, 1e3]))
    window = max(1, round(0.5 * params.search_dimension / res))
    levels = list(grid.levels[:_MAX_LEVELS])
    while len(levels) < _MAX_LEVELS:
        levels.append(levels[-1])
    n_levels = min(len(grid.levels), _MAX_LEVELS)
    offset = params.coarse_angle_offset
    step = max(params.coarse_angle_resolution, 1e-6)
    best = (-1, 0, 0, 0.0)
    dth = np.zeros(1)
    # The coarse pass scores a thinned point set (one point per half-σ cell): the smear
    # makes nearby points nearly redundant there; fine pass, covariance and refinement use all.
    coarse_pts = _thin(pts, max(0.5 * params.smear_deviation, 2.0 * res))
    # Karto steps 2 cells; a wide smear (σ >= 10 cells) is smooth enough for up to 4, and the
    # fine pass below covers ±(step/2 + 1) cells around the coarse best.
    coarse_step = int(max(2, min(4, math.floor(params.smear_deviation / (2.5 * res)))))
    # per-heading best of the plain coarse pass (None after branch and bound)
    profile: FloatArray | None = None
    for attempt in range(4 if params.use_response_expansion else 1):
        n_half = math.floor(offset / step + 1e-9)
        dth = step * np.arange(-n_half, n_half + 1, dtype=np.float64)
        px, py = _cells_for_angles(coarse_pts, prior, prior[2] + dth, grid)
        penalties = (
            params.penalize,
            params.distance_variance_penalty,
            params.angle_variance_penalty,
            params.minimum_distance_penalty,
            params.minimum_angle_penalty,
        )
        if n_levels > 1:
            top_step = 1 << (n_levels - 1)
            top_scores = _top_level_scores(levels[n_levels - 1], px, py, window, top_step)
            order = np.argsort(top_scores, kind="stable").astype(np.int64)
            best = _branch_and_bound(
                levels[0],
                levels[1],
                levels[2],
                levels[3],
                levels[4],
                levels[5],
                n_levels,
                px,
                py,
                dth,
                window,
                res,
                *penalties,
                top_scores,
                order,
            )
        else:
            profile = np.zeros(dth.size)
            best = _coarse_grid_search(
                grid.likelihood, px, py, dth, window, coarse_step, res, *penalties, profile
            )
        if best[3] > 0.0 or attempt == 3:
            break
        offset += 0.349  # slam_toolbox widens by 20° per retry
    a_idx, bx, by, coarse_score = best
    if a_idx < 0:
        return MatchResult(prior.copy(), 0.0, np.diag([1e3, 1e3, 1e3]))
    # fine headings around the coarse best
    fine = max(params.fine_angle_step, 1e-6)
    n_fine = math.floor(0.5 * step / fine + 1e-9)
    fdth = dth[a_idx] + fine * np.arange(-n_fine, n_fine + 1, dtype=np.float64)
    fpx, fpy = _cells_for_angles(pts, prior, prior[2] + fdth, grid)
    radius = coarse_step // 2 + 1 if n_levels == 1 else 1
    penalties = (
        params.penalize,
        params.distance_variance_penalty,
        params.angle_variance_penalty,
        params.minimum_distance_penalty,
        params.minimum_angle_penalty,
    )
    resp = _exhaustive(grid.likelihood, fpx, fpy, fdth, bx, by, radius, res, *penalties)
    fa, fix, fiy = np.unravel_index(int(np.argmax(resp)), resp.shape)
    best_resp = float(resp[fa, fix, fiy])
    dx = bx - radius + int(fix)
    dy = by - radius + int(fiy)
    pose = np.array([prior[0] + dx * res, prior[1] + dy * res, prior[2] + fdth[fa]])
    if reject_below is not None and best_resp < reject_below:
        return MatchResult(pose, best_resp, np.diag([1e3, 1e3, 1e3]))
    # covariance: translation spread over the whole window at the best heading (thinned
    # points: the spread, not the exact values, matters here)
    cpx, cpy = _cells_for_angles(coarse_pts, prior, prior[2] + fdth[fa : fa + 1], grid)
    if n_levels > 1:
        # wide window: only the candidates that can come within 0.1 of the best (the ones
        # the covariance keeps) are scored, found through the pyramid's bounds
        full = _window_near_best(
            levels[0],
            levels[1],
            levels[2],
            levels[3],
            levels[4],
            levels[5],
            n_levels,
            cpx[0],
            cpy[0],
            float(fdth[fa]),
            window,
            dx,
            dy,
            res,
            *penalties,
        )
    else:
        full = _exhaustive(
            grid.likelihood,
            cpx,
            cpy,
            fdth[fa : fa + 1],
            0,
            0,
            window,
            res,
            *penalties,
        )[0]
    coords = _window_offsets(window, res)
    ref = float(full.max())
    xy_cov = _weighted_covariance(full.ravel(), coords, ref, np.full(2, 0.1 * res * res))
    ang_vals = resp[:, fix, fiy]
    th_cov = _weighted_covariance(ang_vals, fdth[:, None], best_resp, np.array([0.1 * fine * fine]))
    cov = np.zeros((3, 3))
    cov[:2, :2] = xy_cov
    cov[2, 2] = th_cov[0, 0]
    if params.coarse_heading_variance and dth.size > 1:
        if profile is None:
            # branch and bound scores only part of the window: one full pass per heading
            profile = np.zeros(dth.size)
            _coarse_grid_search(
                grid.likelihood, px, py, dth, window, coarse_step, res, *penalties, profile
            )
        coarse_th = _weighted_covariance(
            profile, dth[:, None], float(profile.max()), np.array([0.1 * fine * fine])
        )
        cov[2, 2] = max(cov[2, 2], float(coarse_th[0, 0]))
    cov /= max(best_resp, 1e-3)
    if params.refine and best_resp > 0.0:
        rx, ry, rth, rscore = _refine(
            grid.likelihood, pts, pose[0], pose[1], pose[2], grid.origin[0], grid.origin[1], res, 10
        )
        # Trust the refinement near the discrete optimum (within one smear σ: the penalty can
        # hold the discrete pose that far from the best fit) and only when its mean response
        # is at least the discrete pose's: on sparse reference points (beams centimetres apart
        # on a far wall) the smeared grid is bumpy along walls and Σ(1 - f)² can pull the
        # heading off while the mean response drops.
        raw = score_pose(pts, pose, grid)
        if (
            math.hypot(rx - pose[0], ry - pose[1]) <= max(2.0 * res, params.smear_deviation)
            and abs(rth - pose[2]) <= 0.5 * step
            and rscore >= raw
        ):
            pose = np.array([rx, ry, rth])
    pose[2] = float(wrap_angle(pose[2]))
    del coarse_score
    return MatchResult(pose, best_resp, cov)
