"""Occupancy grid ray casting against hand-computed cells."""

from __future__ import annotations

import math

import numpy as np

from eddiebot.slam import OccupancyGridBuilder


def _counts(builder: OccupancyGridBuilder, x: float, y: float) -> tuple[int, int]:
    c = math.floor(x / builder.resolution) - round(builder.origin[0] / builder.resolution)
    r = math.floor(y / builder.resolution) - round(builder.origin[1] / builder.resolution)
    return int(builder.hits[r, c]), int(builder.passes[r, c])


def test_axis_beam_cells() -> None:
    b = OccupancyGridBuilder(0.1, 10.0, occupancy_threshold=0.1, min_pass_through=1)
    # sensor in cell (0, 0); a beam along +x of 0.42 m ends in cell (4, 0)
    b.add_scan([0.05, 0.05, 0.0], [0.42], [0.0])
    for k in range(5):
        hits, passes = _counts(b, 0.05 + 0.1 * k, 0.05)
        assert passes == 1
        assert hits == (1 if k == 4 else 0)
    assert _counts(b, 0.55, 0.05) == (0, 0)
    assert _counts(b, 0.05, 0.15) == (0, 0)
    grid = b.to_map(crop=True)
    row = grid.data[1, 1:6].tolist()  # one cell of margin around the known cells
    assert row == [0, 0, 0, 0, 100]


def test_diagonal_beam_is_bresenham() -> None:
    b = OccupancyGridBuilder(1.0, 100.0, min_pass_through=1)
    # from cell (0, 0) to cell (5, 2): y = 0.4 x rounds to 0, 0, 1, 1, 2, 2
    b.add_scan([0.5, 0.5, 0.0], [math.hypot(5.0, 2.0)], [math.atan2(2.0, 5.0)])
    visited = {(c, r) for c in range(7) for r in range(4) if _counts(b, c + 0.5, r + 0.5)[1]}
    assert visited == {(0, 0), (1, 0), (2, 1), (3, 1), (4, 2), (5, 2)}
    assert _counts(b, 5.5, 2.5) == (1, 1)


def test_long_beam_is_cut_without_hit_and_invalid_beams_ignored() -> None:
    b = OccupancyGridBuilder(0.5, 2.0, min_pass_through=1)
    b.add_scan([0.25, 0.25, 0.0], [5.0, np.nan, np.inf, 0.0], [0.0, 0.5, 1.0, 1.5])
    assert int(b.hits.sum()) == 0
    assert int(b.passes.sum()) == 5  # cells 0..4 along x up to 2.0 m (+ the end cell)


def test_remove_restores_counts_and_threshold_rule() -> None:
    b = OccupancyGridBuilder(0.1, 10.0, occupancy_threshold=0.1, min_pass_through=2)
    angles = np.linspace(-0.4, 0.4, 5)  # end points 0.2 m apart: one beam per end cell
    ranges = np.full(5, 1.0)
    b.add_scan([0.0, 0.0, 0.0], ranges, angles)
    one = b.to_map(crop=False).data.copy()
    assert (one == 100).sum() == 0  # one pass is not enough (min_pass_through 2)
    b.add_scan([0.0, 0.0, 0.0], ranges, angles)
    assert (b.to_map(crop=False).data == 100).sum() > 0
    b.add_scan([0.0, 0.0, 0.0], ranges, angles, weight=-1)
    b.add_scan([3.0, 2.0, 1.0], ranges, angles)  # growth keeps the cell lattice
    b.add_scan([3.0, 2.0, 1.0], ranges, angles, weight=-1)
    b.add_scan([0.0, 0.0, 0.0], ranges, angles, weight=-1)
    assert int(np.abs(b.hits).sum()) == 0
    assert int(np.abs(b.passes).sum()) == 0
