"""Correlative scan-to-map matching, multi-resolution (Olson 2009), with sub-cell refinement.

A reference point set (the local map) is rasterised into a *correlation grid* whose cells hold
``exp(-½ (d/σ)²)`` for the distance d to the nearest reference point (Karto's smear kernel,
computed with a Euclidean distance transform; 0 beyond 2σ). A scan's response at a pose is the
mean grid value under its end points (0..1, Karto's response scaled from 0..100).

The search covers a translation window around the prior at the grid's resolution and
headings ``prior ± coarse_search_angle_offset`` in ``coarse_angle_resolution`` steps.
Translations are searched by branch and bound over precomputed max-pooled grids
(Olson's multi-resolution idea in Cartographer's form: level h holds the maximum of the
2^h × 2^h cells it covers, an upper bound on every finer candidate beneath it), so wide
windows cost little. The best coarse candidate is refined on a fine angular step
(``fine_search_angle_offset``) over ±½ coarse step and ±2 cells, then to sub-cell accuracy by
Gauss–Newton on the bilinearly interpolated grid. Karto's distance/angle penalties are
applied to candidate responses when ``penalize`` is set (sequential matching).

The covariance follows Karto's recipe: the response-weighted spread of every translation
candidate at the best heading whose response is within 0.1 of the best, floored and scaled by
1/response; the heading variance likewise over the fine headings.

Modules: `grid` (the correlation grid and its pyramid), `lookup` (rotated point cells,
thinning, window offsets), `search` (`match_scan`), `branch_and_bound`, `subcell` (the
Gauss–Newton refinement), `covariance`, `normals` and `icp` (point-to-line polish).
"""

from __future__ import annotations

from eddiebot.slam.scan_matcher.grid import CorrelationGrid, build_correlation_grid, pyramid_levels
from eddiebot.slam.scan_matcher.icp import refine_icp, refine_icp_with_covariance
from eddiebot.slam.scan_matcher.normals import point_normals
from eddiebot.slam.scan_matcher.search import MatcherParams, MatchResult, match_scan, score_pose

__all__ = [
    "CorrelationGrid",
    "MatchResult",
    "MatcherParams",
    "build_correlation_grid",
    "match_scan",
    "point_normals",
    "pyramid_levels",
    "refine_icp",
    "refine_icp_with_covariance",
    "score_pose",
]
