"""Whole-map search for a view of several scans: the newest scan alone finds the candidate
places, the view decides between them.

Searching the view of the buffered scans itself over the whole map (every heading, every
translation) costs seconds of CPU: the view holds ten times the points, and where the map does
not cover the place the branch and bound prunes little. The newest scan alone costs a tenth
of that, but fits more places of a map whose corridors repeat. So the scan's branch and bound
keeps the `CANDIDATES` best *distinct* places (a leaf within `SEPARATION` of a kept one, at a
heading within two steps, replaces it if better, as non-maximum suppression), and the view is
matched locally around each (±`SEPARATION` and ±2 heading steps, on the same grid). The
candidate where the view fits best is the answer, with the response of the view there.
Where tracking holds the robot is a candidate too: the map supports the newest scan poorly
there (that is why it is searched), yet the view may fit there best, and then the answer is
the tracked pose (which the caller does not take as a relocalisation) or, if another place
fits nearly as well, ambiguous.
Candidates are the places whose scan response comes within 0.1 of the best (Karto's
covariance keeps the candidates within 0.1 of the best alike) and reaches the coarse
acceptance threshold (``loop_match_minimum_response_coarse``, which the view must reach too):
the branch and bound prunes with that bar, so a scan the map does not hold costs little.

Its covariance is what a whole-map search of the view reports (Karto's: the response-weighted
spread of every translation of the whole window, at the answer's heading, whose response
comes within 0.1 of the best; found through the pyramid's bounds) plus the spread of the
candidates whose view response comes within 0.1 of the best (places at other headings): a
view that fits two places of the map nearly equally is refused as ambiguous.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.slam.mapper.results import FloatArray
from eddiebot.slam.scan_matcher import CorrelationGrid, MatcherParams, MatchResult, match_scan
from eddiebot.slam.scan_matcher.branch_and_bound import (
    _push_children,
    _seed_stack,
    _top_level_scores,
    _window_near_best,
)
from eddiebot.slam.scan_matcher.covariance import _weighted_covariance
from eddiebot.slam.scan_matcher.grid import _MAX_LEVELS
from eddiebot.slam.scan_matcher.lookup import _cells_for_angles, _thin, _window_offsets

__all__ = ["CANDIDATES", "MARGIN", "SEPARATION", "scan_candidates", "search_view"]

#: distinct candidate places the newest scan proposes for the view to decide between
CANDIDATES = 8
#: candidates closer than this (m) and within two heading steps are one place
SEPARATION = 0.5
#: candidates more than this below the best scan response are not kept
MARGIN = 0.1


@njit(cache=True)
def _within_reach(da: int, dx: int, dy: int, n_ang: int, sep: int, sep_a: int) -> bool:
    """Two candidates ``da`` heading steps (around the circle of ``n_ang``) and ``dx``, ``dy``
    cells apart are one place."""
    da = abs(da)
    return abs(dx) <= sep and abs(dy) <= sep and min(da, n_ang - da) <= sep_a


@njit(cache=True)
def _top_candidates(
    g0: npt.NDArray[np.float32],
    g1: npt.NDArray[np.float32],
    g2: npt.NDArray[np.float32],
    g3: npt.NDArray[np.float32],
    g4: npt.NDArray[np.float32],
    g5: npt.NDArray[np.float32],
    n_levels: int,
    px: npt.NDArray[np.int64],
    py: npt.NDArray[np.int64],
    window: int,
    top_scores: npt.NDArray[np.float64],
    order: npt.NDArray[np.int64],
    k: int,
    sep: int,
    sep_a: int,
    margin: float,
    floor: float,
) -> tuple[
    npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]
]:
    """The ``k`` best distinct (angle index, dx, dy, response) of the window, depth-first
    branch and bound pruned by the k-th best kept; a leaf within ``sep`` cells and ``sep_a``
    heading steps (around the circle) of a kept one replaces it when better, else is dropped.

    ``top_scores`` are `_top_level_scores` on the coarsest level, ``order`` their ascending
    argsort."""
    grids = (g0, g1, g2, g3, g4, g5)
    n_ang = px.shape[0]
    s_a, s_x, s_y, s_h, s_s, n = _seed_stack(n_levels, window, top_scores, order)
    r_a = np.zeros(k, np.int64)
    r_x = np.zeros(k, np.int64)
    r_y = np.zeros(k, np.int64)
    r_s = np.zeros(k, np.float64)
    m = 0
    # kept and explored: above the k-th best kept (once k are), the best - margin and floor
    bar = floor
    top_s = 0.0
    c_x = np.empty(4, np.int64)
    c_y = np.empty(4, np.int64)
    c_s = np.empty(4, np.float64)
    while n > 0:
        n -= 1
        a, x, y, h, s = s_a[n], s_x[n], s_y[n], s_h[n], s_s[n]
        if s <= bar:
            continue
        if h == 0:
            # the kept ones within reach of the leaf: it replaces them when better than all
            # of them (one entry in their stead, so no two kept ones ever come within reach
            # of each other), else it is dropped
            same = -1
            beaten = False
            for j in range(m):
                if _within_reach(r_a[j] - a, r_x[j] - x, r_y[j] - y, n_ang, sep, sep_a):
                    if r_s[j] >= s:
                        beaten = True
                        break
                    if same < 0:
                        same = j
            if beaten:
                continue
            if same >= 0:
                r_a[same], r_x[same], r_y[same], r_s[same] = a, x, y, s
                kept = same + 1
                for j in range(same + 1, m):
                    if not _within_reach(r_a[j] - a, r_x[j] - x, r_y[j] - y, n_ang, sep, sep_a):
                        r_a[kept], r_x[kept], r_y[kept], r_s[kept] = r_a[j], r_x[j], r_y[j], r_s[j]
                        kept += 1
                m = kept
            elif m < k:
                r_a[m], r_x[m], r_y[m], r_s[m] = a, x, y, s
                m += 1
            else:
                worst = 0
                for j in range(1, m):
                    if r_s[j] < r_s[worst]:
                        worst = j
                r_a[worst], r_x[worst], r_y[worst], r_s[worst] = a, x, y, s
            top_s = max(top_s, s)
            bar = max(floor, top_s - margin)
            if m == k:
                kth = r_s[0]
                for j in range(1, m):
                    kth = min(kth, r_s[j])
                bar = max(bar, kth)
            continue
        n = _push_children(grids[h - 1], px[a], py[a], a, x, y, h, window, bar,
                           s_a, s_x, s_y, s_h, s_s, n, c_x, c_y, c_s)
    return r_a[:m], r_x[:m], r_y[:m], r_s[:m]


def scan_candidates(
    points: FloatArray,
    grid: CorrelationGrid,
    prior: FloatArray,
    params: MatcherParams,
    count: int = CANDIDATES,
    separation: float = SEPARATION,
    margin: float = MARGIN,
    floor: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """The ``count`` best distinct sensor poses (map frame) of scan ``points`` (sensor frame)
    over ``params``' window around ``prior``, best first, and their responses on the coarse
    pass's thinned points: those above ``floor`` and within ``margin`` of the best (one kept
    before the best was found may lie lower)."""
    prior = np.asarray(prior, dtype=np.float64)
    res = grid.resolution
    pts = _thin(np.ascontiguousarray(points, dtype=np.float64),
                max(0.5 * params.smear_deviation, 2.0 * res))
    window = max(1, round(0.5 * params.search_dimension / res))
    levels = list(grid.levels[:_MAX_LEVELS])
    n_levels = len(levels)
    while len(levels) < _MAX_LEVELS:
        levels.append(levels[-1])
    step = max(params.coarse_angle_resolution, 1e-6)
    n_half = math.floor(params.coarse_angle_offset / step + 1e-9)
    dth = step * np.arange(-n_half, n_half + 1, dtype=np.float64)
    px, py = _cells_for_angles(pts, prior, prior[2] + dth, grid)
    top = 1 << (n_levels - 1)
    top_scores = _top_level_scores(levels[n_levels - 1], px, py, window, top)
    order = np.argsort(top_scores, kind="stable").astype(np.int64)
    a, x, y, s = _top_candidates(
        levels[0], levels[1], levels[2], levels[3], levels[4], levels[5],
        n_levels, px, py, window, top_scores, order, count,
        max(1, round(separation / res)), 2, margin, floor,
    )
    best_first = np.argsort(-s, kind="stable")
    poses = np.stack(
        [prior[0] + x * res, prior[1] + y * res, prior[2] + dth[a]], axis=-1
    )[best_first]
    return poses.reshape(-1, 3), s[best_first]


def search_view(
    points: FloatArray,
    view: FloatArray,
    grid: CorrelationGrid,
    prior: FloatArray,
    params: MatcherParams,
    minimum_response: float = 0.0,
    tracked: FloatArray | None = None,
) -> MatchResult:
    """The sensor pose (map frame) of ``view`` — the newest scan ``points`` with the scans
    before it, all in its sensor frame — over ``params``' window around ``prior`` (see the
    module docstring); only places where the scan's response exceeds ``minimum_response``
    are candidates (none: response 0), and ``tracked`` (the sensor pose tracking holds) is
    one too."""
    poses, _ = scan_candidates(points, grid, prior, params, floor=minimum_response)
    if tracked is not None:
        poses = np.concatenate([poses, np.asarray(tracked, float).reshape(1, 3)])
    if poses.shape[0] == 0:
        return MatchResult(np.asarray(prior, float).copy(), 0.0, np.diag([1e3, 1e3, 1e3]))
    step = max(params.coarse_angle_resolution, 1e-6)
    local = dataclasses.replace(
        params,
        search_dimension=2.0 * SEPARATION,
        coarse_angle_offset=2.0 * step,
        use_response_expansion=False,
        penalize=False,
    )
    plain = CorrelationGrid(grid.levels[:1], grid.origin, grid.resolution)
    matches = [match_scan(view, plain, pose, local) for pose in poses]
    responses = np.array([m.response for m in matches])
    best = int(np.argmax(responses))
    chosen = matches[best]
    where = np.array([m.pose[:2] for m in matches])
    spread = _weighted_covariance(responses, where, float(responses[best]), np.zeros(2))
    covariance = chosen.covariance.copy()
    if chosen.response >= minimum_response:
        # (below, the answer is refused on its response whatever its spread)
        covariance[:2, :2] = _window_spread(view, grid, prior, params, chosen.pose)
    covariance[:2, :2] += spread
    covariance[:2, :2] /= max(float(chosen.response), 1e-3)
    return MatchResult(chosen.pose, chosen.response, covariance)


def _window_spread(
    view: FloatArray,
    grid: CorrelationGrid,
    prior: FloatArray,
    params: MatcherParams,
    pose: FloatArray,
) -> FloatArray:
    """Karto's translation spread (2×2, m², before the 1/response scaling) of the view at
    ``pose``'s heading over the whole window: every translation whose response comes within
    0.1 of the best, weighted by it — what a whole-map search of the view would report."""
    res = grid.resolution
    pts = _thin(np.ascontiguousarray(view, dtype=np.float64),
                max(0.5 * params.smear_deviation, 2.0 * res))
    prior = np.asarray(prior, dtype=np.float64)
    window = max(1, round(0.5 * params.search_dimension / res))
    levels = list(grid.levels[:_MAX_LEVELS])
    n_levels = len(levels)
    while len(levels) < _MAX_LEVELS:
        levels.append(levels[-1])
    px, py = _cells_for_angles(pts, prior, np.array([pose[2]]), grid)
    full = _window_near_best(
        levels[0], levels[1], levels[2], levels[3], levels[4], levels[5], n_levels,
        px[0], py[0], 0.0, window,
        round((pose[0] - prior[0]) / res), round((pose[1] - prior[1]) / res), res,
        False, 1.0, 1.0, 0.0, 0.0,
    )
    return _weighted_covariance(
        full.ravel(), _window_offsets(window, res), float(full.max()), np.full(2, 0.1 * res * res)
    )
