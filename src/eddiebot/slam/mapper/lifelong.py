"""Lifelong mapping's node scores: slam_toolbox's ``LifelongSlamToolbox`` (``computeScores``,
``computeObjectiveScore``, ``computeIntersectOverUnion`` and friends) as pure functions.

Every node starts with score 1. Each new node re-scores the older nodes near it (linked to
it through the graph within half its bounding box's diagonal, or with
``lifelong_search_use_tree`` every node that near): a candidate whose box overlaps the new
one's by IoU ≥ ``lifelong_minimum_score`` and that has at least two edges gets

    score' = score · (1 + min(overlap, clamp(multiplier · (edges − 2), 0, 1)))
             − overlap − lifelong_nearby_penalty,
    overlap = lifelong_overlap_score_scale · min(area overlap, reading overlap),

or −1 outright when IoU > ``lifelong_iou_match`` and it has fewer than three edges (a close
fit, no loop closure leans on it). Nodes fewer than ``scan_buffer_size`` ids older than the
new one, and nodes 0 and 1, keep their score. A node whose score drops below
``lifelong_node_removal_score`` is removed. (``lifelong_candidates_scale`` enters upstream's
formula only in a commented-out line, so it changes nothing there or here.)

Boxes are axis-aligned in the map frame around a scan's points and its sensor position; as
upstream, the intersection is taken between boxes of those sizes centred on each scan's
barycenter. Deviation: upstream multiplies the two extents of the intersection and clamps
the product at 0, so two boxes apart in both x and y "overlap" by a positive area; here
either extent ≤ 0 means no overlap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.slam.config import SlamConfig
from eddiebot.slam.mapper.results import FloatArray

__all__ = [
    "LifelongParams",
    "ScanBox",
    "area_overlap_ratio",
    "intersect_over_union",
    "objective_score",
    "reading_overlap_ratio",
    "rescore",
    "scan_box",
    "scan_boxes",
]


@dataclass(frozen=True)
class LifelongParams:
    """The ``lifelong_*`` parameters (upstream's names without the prefix)."""

    minimum_score: float = 0.1
    iou_match: float = 0.85
    node_removal_score: float = 0.1
    overlap_score_scale: float = 0.5
    constraint_multiplier: float = 0.05
    nearby_penalty: float = 0.001
    candidates_scale: float = 0.03
    search_use_tree: bool = False

    @classmethod
    def from_config(cls, cfg: SlamConfig) -> LifelongParams:
        return cls(
            cfg.lifelong_minimum_score,
            cfg.lifelong_iou_match,
            cfg.lifelong_node_removal_score,
            cfg.lifelong_overlap_score_scale,
            cfg.lifelong_constraint_multiplier,
            cfg.lifelong_nearby_penalty,
            cfg.lifelong_candidates_scale,
            cfg.lifelong_search_use_tree,
        )


@dataclass(frozen=True)
class ScanBox:
    """A scan's axis-aligned bounding box size (m) and barycenter (map frame, m)."""

    width: float
    height: float
    center_x: float
    center_y: float

    @property
    def area(self) -> float:
        return self.width * self.height

    @property
    def radius(self) -> float:
        """Half the diagonal: upstream's search radius around a new scan."""
        return 0.5 * float(np.hypot(self.width, self.height))


def scan_box(world_points: FloatArray, sensor_xy: FloatArray) -> ScanBox:
    """Karto's bounding box (the points and the sensor position) and barycenter (the points'
    mean; the sensor position when there are none) of one scan, map frame."""
    sensor = np.asarray(sensor_xy, dtype=np.float64)[:2]
    if world_points.shape[0] == 0:
        return ScanBox(0.0, 0.0, float(sensor[0]), float(sensor[1]))
    lo = np.minimum(world_points.min(axis=0), sensor)
    hi = np.maximum(world_points.max(axis=0), sensor)
    center = world_points.mean(axis=0)
    return ScanBox(float(hi[0] - lo[0]), float(hi[1] - lo[1]), float(center[0]), float(center[1]))


def scan_boxes(
    world_points: FloatArray, counts: npt.NDArray[np.int64], sensors_xy: FloatArray
) -> FloatArray:
    """`scan_box` of several scans at once, as rows (width, height, center x, center y):
    ``world_points`` their points concatenated, ``counts`` how many each has (at least one),
    ``sensors_xy`` (N, 2) their sensor positions."""
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    lo = np.minimum(np.minimum.reduceat(world_points, starts, axis=0), sensors_xy)
    hi = np.maximum(np.maximum.reduceat(world_points, starts, axis=0), sensors_xy)
    center = np.add.reduceat(world_points, starts, axis=0) / counts[:, None]
    return np.column_stack([hi - lo, center])


def rescore(
    params: LifelongParams,
    new: ScanBox,
    boxes: FloatArray,
    world_points: FloatArray,
    counts: npt.NDArray[np.int64],
    num_constraints: npt.NDArray[np.int64],
    initial_scores: FloatArray,
) -> tuple[npt.NDArray[np.bool_], FloatArray]:
    """Upstream's ``computeScores`` for N candidates at once: which are re-scored (IoU with
    the new scan's box at least ``minimum_score``) and their new scores (`objective_score`
    with `intersect_over_union`, `area_overlap_ratio` and `reading_overlap_ratio`).
    ``boxes`` are `scan_boxes` rows, ``world_points`` / ``counts`` the candidates' points."""
    w, h, cx, cy = boxes[:, 0], boxes[:, 1], boxes[:, 2], boxes[:, 3]
    x_u = np.minimum(new.center_x + new.width / 2.0, cx + w / 2.0)
    y_u = np.minimum(new.center_y + new.height / 2.0, cy + h / 2.0)
    x_l = np.maximum(new.center_x - new.width / 2.0, cx - w / 2.0)
    y_l = np.maximum(new.center_y - new.height / 2.0, cy - h / 2.0)
    inter = np.where((x_u > x_l) & (y_u > y_l), (x_u - x_l) * (y_u - y_l), 0.0)
    area = w * h
    union = new.area + area - inter
    iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0.0)
    area_overlap = np.divide(inter, area, out=np.zeros_like(inter), where=area > 0.0)
    pick = np.repeat(np.arange(counts.size), counts)
    x, y = world_points[:, 0], world_points[:, 1]
    inside = (x < x_u[pick]) & (x > x_l[pick]) & (y < y_u[pick]) & (y > y_l[pick])
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    reading = np.add.reduceat(inside.astype(np.float64), starts) / counts
    overlap = params.overlap_score_scale * np.minimum(area_overlap, reading)
    boost = np.clip(params.constraint_multiplier * (num_constraints - 2.0), 0.0, 1.0)
    boost = np.minimum(boost, overlap)
    score = np.minimum(initial_scores * (1.0 + boost) - overlap - params.nearby_penalty, 1.0)
    score = np.where((iou > params.iou_match) & (num_constraints < 3), -1.0, score)
    return iou >= params.minimum_score, score


def _intersect_bounds(a: ScanBox, b: ScanBox) -> tuple[float, float, float, float]:
    """(x_lower, x_upper, y_lower, y_upper) of the two boxes' intersection (upstream's
    ``computeIntersectBounds``: boxes centred on the barycenters)."""
    x_u = min(a.center_x + a.width / 2.0, b.center_x + b.width / 2.0)
    y_u = min(a.center_y + a.height / 2.0, b.center_y + b.height / 2.0)
    x_l = max(a.center_x - a.width / 2.0, b.center_x - b.width / 2.0)
    y_l = max(a.center_y - a.height / 2.0, b.center_y - b.height / 2.0)
    return x_l, x_u, y_l, y_u


def _intersect(a: ScanBox, b: ScanBox) -> float:
    x_l, x_u, y_l, y_u = _intersect_bounds(a, b)
    if x_u <= x_l or y_u <= y_l:
        return 0.0
    return (x_u - x_l) * (y_u - y_l)


def intersect_over_union(a: ScanBox, b: ScanBox) -> float:
    """Intersection over union of two scans' boxes (0 when both are empty)."""
    inter = _intersect(a, b)
    union = a.area + b.area - inter
    return inter / union if union > 0.0 else 0.0


def area_overlap_ratio(new: ScanBox, candidate: ScanBox) -> float:
    """Share of the candidate's box the new scan's box covers."""
    area = candidate.area
    return _intersect(new, candidate) / area if area > 0.0 else 0.0


def reading_overlap_ratio(new: ScanBox, candidate: ScanBox, candidate_points: FloatArray) -> float:
    """Share of the candidate's points (map frame) strictly inside the boxes' intersection."""
    n = candidate_points.shape[0]
    if n == 0:
        return 0.0
    x_l, x_u, y_l, y_u = _intersect_bounds(new, candidate)
    x, y = candidate_points[:, 0], candidate_points[:, 1]
    inside = (x < x_u) & (x > x_l) & (y < y_u) & (y > y_l)
    return float(np.count_nonzero(inside)) / n


def objective_score(
    params: LifelongParams,
    *,
    iou: float,
    area_overlap: float,
    reading_overlap: float,
    num_constraints: int,
    initial_score: float,
) -> float:
    """A candidate's new score (upstream's ``computeObjectiveScore``), at most 1."""
    if iou > params.iou_match and num_constraints < 3:
        return -1.0
    overlap = params.overlap_score_scale * min(area_overlap, reading_overlap)
    boost = min(1.0, max(0.0, params.constraint_multiplier * (num_constraints - 2)))
    boost = min(boost, overlap)
    score = initial_score * (1.0 + boost) - overlap - params.nearby_penalty
    return min(score, 1.0)
