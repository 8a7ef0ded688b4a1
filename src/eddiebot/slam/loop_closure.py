"""Loop-closure candidates and their two-stage verification (Karto's recipe).

Candidates: earlier nodes within ``loop_search_maximum_distance`` of the current node that are
*not* reachable from it through graph edges while staying within that distance (the recent
chain and anything already linked to it), grouped into runs of consecutive node ids; a run
counts if it holds at least ``loop_match_minimum_chain_size`` nodes — or, where nodes lie
further apart than ``minimum_travel_distance`` (scans sparser than the travel gate, as in logs
recorded at one scan a metre), if its path is as long as that many nodes would span at the
travel gate, ``(loop_match_minimum_chain_size - 1) * minimum_travel_distance``. Karto counts
nodes only, so on sparse scans no run of its default 10 fits in the 3 m search circle.

Verification: a coarse match over the loop search window (``loop_search_space_*``, no
penalty) must give a response > ``loop_match_minimum_response_coarse`` with x and y variances
< ``loop_match_maximum_variance_coarse``; a fine match (sequential parameters, no penalty)
started from the coarse pose must reach ``loop_match_minimum_response_fine`` and, when
``max_variance_fine`` is set (eddiebot's addition), have a position variance below it along
every direction.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.slam.scan_matcher import (
    MatcherParams,
    MatchResult,
    build_correlation_grid,
    match_scan,
)

__all__ = ["LoopClosure", "find_loop_candidates", "near_linked_nodes", "verify_loop"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LoopClosure:
    """An accepted loop: link ``candidate`` (a node of ``chain``) to the current node."""

    candidate: int
    chain: tuple[int, ...]
    match: MatchResult
    coarse_response: float


def near_linked_nodes(
    start: int,
    positions: FloatArray,
    neighbours: Callable[[int], AbstractSet[int]],
    max_distance: float,
) -> set[int]:
    """Nodes reachable from ``start`` through edges, every hop staying within ``max_distance``."""
    diff = positions - positions[start]
    # every node's distance once, as a list of flags (the walk visits a few hundred nodes)
    near = (diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1] <= max_distance * max_distance).tolist()
    seen = {start}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for nb in neighbours(node):
            if near[nb] and nb not in seen:
                seen.add(nb)
                queue.append(nb)
    return seen


def find_loop_candidates(
    current: int,
    positions: FloatArray,
    linked: set[int],
    *,
    max_distance: float,
    min_chain_size: int,
    min_chain_length: float | None = None,
    active: npt.NDArray[np.bool_] | None = None,
) -> list[tuple[int, ...]]:
    """Runs of consecutive earlier node ids near ``current`` and not in ``linked``.

    A run counts with ``min_chain_size`` nodes, or with fewer whose path (through their
    ``positions``) is at least ``min_chain_length`` metres long.
    """
    origin = positions[current]
    d = np.hypot(positions[:current, 0] - origin[0], positions[:current, 1] - origin[1])
    near = d <= max_distance
    if active is not None:
        near &= active[:current]

    def counts(run: list[int]) -> bool:
        if len(run) >= min_chain_size:
            return True
        if min_chain_length is None or len(run) < 2:
            return False
        steps = np.diff(positions[run[0] : run[-1] + 1], axis=0)
        return float(np.hypot(steps[:, 0], steps[:, 1]).sum()) >= min_chain_length

    chains: list[tuple[int, ...]] = []
    chain: list[int] = []
    # only the near ids are visited (a run breaks at any gap in them)
    for idx in np.flatnonzero(near).tolist():
        if idx in linked:
            continue
        if chain and idx != chain[-1] + 1:
            if counts(chain):
                chains.append(tuple(chain))
            chain = []
        chain.append(idx)
    if chain and counts(chain):
        chains.append(tuple(chain))
    return chains


def verify_loop(
    points: FloatArray,
    prior: FloatArray,
    chain: Sequence[int],
    chain_points_world: FloatArray,
    chain_positions: FloatArray,
    *,
    coarse: MatcherParams,
    fine: MatcherParams,
    min_response_coarse: float,
    max_variance_coarse: float,
    min_response_fine: float,
    max_variance_fine: float = 0.0,
) -> LoopClosure | None:
    """Match scan ``points`` (sensor frame) against a chain's points; None if rejected.

    ``prior`` is the current sensor pose (map frame); ``chain_positions`` (len(chain), 2) pick
    the chain node nearest to the matched pose as the candidate to link.
    """
    if chain_points_world.shape[0] == 0 or points.shape[0] == 0:
        return None
    world = _transform(prior, points)
    half = 0.5 * coarse.search_dimension + 0.1
    bounds = (
        float(world[:, 0].min()) - half,
        float(world[:, 1].min()) - half,
        float(world[:, 0].max()) + half,
        float(world[:, 1].max()) + half,
    )
    levels = _levels_for(coarse)
    grid = build_correlation_grid(
        chain_points_world, bounds, coarse.resolution, coarse.smear_deviation, levels
    )
    coarse_match = match_scan(points, grid, prior, coarse)
    cov = coarse_match.covariance
    if not (
        coarse_match.response > min_response_coarse
        and cov[0, 0] < max_variance_coarse
        and cov[1, 1] < max_variance_coarse
    ):
        return None
    world = _transform(coarse_match.pose, points)
    half = 0.5 * fine.search_dimension + 0.1
    bounds = (
        float(world[:, 0].min()) - half,
        float(world[:, 1].min()) - half,
        float(world[:, 0].max()) + half,
        float(world[:, 1].max()) + half,
    )
    grid = build_correlation_grid(
        chain_points_world, bounds, fine.resolution, fine.smear_deviation, _levels_for(fine)
    )
    fine_match = match_scan(points, grid, coarse_match.pose, fine, reject_below=min_response_fine)
    if fine_match.response < min_response_fine:
        return None
    if max_variance_fine > 0.0:
        # well constrained in every direction: a corridor match aliases along its length
        xy = fine_match.covariance[:2, :2]
        if float(np.linalg.eigvalsh(0.5 * (xy + xy.T))[-1]) > max_variance_fine:
            return None
    d = np.hypot(
        chain_positions[:, 0] - fine_match.pose[0], chain_positions[:, 1] - fine_match.pose[1]
    )
    candidate = int(chain[int(np.argmin(d))])
    return LoopClosure(candidate, tuple(int(c) for c in chain), fine_match, coarse_match.response)


def _transform(pose: FloatArray, pts: FloatArray) -> FloatArray:
    c, s = math.cos(float(pose[2])), math.sin(float(pose[2]))
    out = np.empty_like(pts)
    out[:, 0] = pose[0] + c * pts[:, 0] - s * pts[:, 1]
    out[:, 1] = pose[1] + s * pts[:, 0] + c * pts[:, 1]
    return out


def _levels_for(params: MatcherParams) -> int:
    half = max(1, round(0.5 * params.search_dimension / params.resolution))
    if half <= 40:
        return 1
    return max(1, min(6, int(math.log2(2 * half + 1))))
