"""Theta*'s cost model as ``nav2_theta_star_planner``: unknown space is dear, not free."""

from __future__ import annotations

import numpy as np
import pytest

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import NoValidPath
from eddiebot.nav.planners import ThetaStarPlanner
from eddiebot.nav.planners.theta_star import ThetaStarConfig, _cost_grids, _line_of_sight

RES = 0.05


def _map_with_unknown_block(y_top: int) -> Costmap2D:
    """60 × 40 free cells with unknown (255) in x 20..39, y 0..y_top-1."""
    cm = Costmap2D(60, 40, RES, 0.0, 0.0, 0)
    cm.data[:y_top, 20:40] = 255
    return cm


def _length(path: np.ndarray) -> float:
    return float(np.sum(np.hypot(np.diff(path[:, 0]), np.diff(path[:, 1]))))


def _unknown_cells(path: np.ndarray, cm: Costmap2D) -> int:
    mx = np.floor(path[:, 0] / RES).astype(int)
    my = np.floor(path[:, 1] / RES).astype(int)
    return int(np.count_nonzero(cm.data[my, mx] == 255))


def test_cost_factors() -> None:
    grid = np.array([[0, 100, 252, 253, 254, 255]], dtype=np.uint8)
    step, los = _cost_grids(grid, True)
    np.testing.assert_allclose(step[0], [(26 / 252) ** 2, (116 / 252) ** 2,
                                         (252.8 / 252) ** 2, -1, -1, (255.5 / 252) ** 2])
    # Line checks: the shifted cost must stay <= 252 (cost 252 is blocked), unknown is 253.
    np.testing.assert_allclose(los[0], [(26 / 252) ** 2, (116 / 252) ** 2, -1, -1, -1,
                                        (253 / 252) ** 2])
    step, los = _cost_grids(grid, False)
    assert step[0, 5] == -1 and los[0, 5] == -1


def test_line_of_sight_sums_the_cells_it_visits() -> None:
    _, los = _cost_grids(np.zeros((5, 10), dtype=np.uint8), True)
    # A horizontal line of 6 cells visits each entered cell once (and the row below, only
    # when the first is blocked).
    assert _line_of_sight(los, 0, 2, 6, 2) == pytest.approx(6 * (26 / 252) ** 2)
    _, los = _cost_grids(np.pad(np.full((1, 1), 254, np.uint8), ((2, 2), (3, 6))), True)
    assert _line_of_sight(los, 0, 2, 6, 2) == pytest.approx(6 * (26 / 252) ** 2)  # row 1 used
    grid = np.zeros((5, 10), dtype=np.uint8)
    grid[1:4, 3] = 254
    _, los = _cost_grids(grid, True)
    assert _line_of_sight(los, 0, 2, 6, 2) == -1.0


def test_goes_round_unknown_space_when_cheaper() -> None:
    cm = _map_with_unknown_block(30)  # free band y 30..39 above the block
    path = ThetaStarPlanner().create_plan((0.5, 1.0, 0.0), (2.5, 1.0, 0.0), cm)
    assert _unknown_cells(path, cm) <= 1  # at most a graze of the block's corner
    # Over the block's top corners: about 0.71 + 1.0 + 0.71 m, not the 2.0 m straight line
    # the former cost model (unknown free of charge) took.
    assert 2.35 <= _length(path) <= 2.6


def test_crosses_unknown_when_there_is_no_way_round() -> None:
    cm = _map_with_unknown_block(40)
    path = ThetaStarPlanner().create_plan((0.5, 1.0, 0.0), (2.5, 1.0, 0.0), cm)
    assert _length(path) == pytest.approx(2.0, abs=0.06)
    assert _unknown_cells(path, cm) >= 19
    with pytest.raises(NoValidPath):
        ThetaStarPlanner(ThetaStarConfig(allow_unknown=False)).create_plan(
            (0.5, 1.0, 0.0), (2.5, 1.0, 0.0), cm)


def test_traversal_weight_trades_length_for_cost() -> None:
    """A 1 m band of cost 200 across the direct line: crossed at w_traversal_cost 0 (length
    only), skirted through the gap above it at the default 2.0 (each band cell costs
    2·(206/252)² ≈ 1.34 more, 27 over the band against 8 for the detour)."""
    cm = Costmap2D(60, 40, RES, 0.0, 0.0, 0)
    cm.data[0:20, 20:40] = 200
    straight = ThetaStarPlanner(ThetaStarConfig(w_traversal_cost=0.0)).create_plan(
        (0.5, 0.5, 0.0), (2.5, 0.5, 0.0), cm)
    assert _length(straight) == pytest.approx(2.0, abs=0.06)
    careful = ThetaStarPlanner().create_plan((0.5, 0.5, 0.0), (2.5, 0.5, 0.0), cm)
    mx = np.floor(careful[:, 0] / RES).astype(int)
    my = np.floor(careful[:, 1] / RES).astype(int)
    assert np.count_nonzero(cm.data[my, mx] == 200) <= 1
    assert 2.35 <= _length(careful) <= 2.6
