import numpy as np
import pytest

from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.occupancy import local_grid_from_points, ray_cells
from eddiebot.vslam.parameters import RtabmapParameters


def _wall_cloud(x=2.0, half_width=0.5, height=0.5):
    """A wall of points at x (m), y in ±half_width, z 0.2..height, no floor points."""
    ys = np.arange(-half_width, half_width + 1e-9, 0.02)
    zs = np.arange(0.2, height + 1e-9, 0.05)
    yy, zz = np.meshgrid(ys, zs)
    return np.stack([np.full(yy.size, x), yy.ravel(), zz.ravel()], axis=1)


def test_without_ray_tracing_only_ground_is_free():
    g = local_grid_from_points(_wall_cloud(), np.zeros(3), RtabmapParameters())
    assert g.empty.shape[0] == 0 and g.ground.shape[0] == 0
    assert g.obstacles.shape[0] == 21  # 1.0 m of wall in 0.05 m cells (cell edges inclusive)


def test_ray_tracing_frees_the_cells_between_view_point_and_obstacles():
    params = RtabmapParameters(grid_ray_tracing=True)
    g = local_grid_from_points(_wall_cloud(), np.zeros(3), params)
    # the empty cells fill the triangle from the origin to the wall, never past or on it
    assert np.all(g.empty[:, 0] < 2.0)  # the wall cells are centred at x 2.025
    assert np.all(g.empty[:, 0] > -0.05)
    occupied = {tuple(np.floor(c / 0.05).astype(int)) for c in g.obstacles}
    keys = {tuple(np.floor(c / 0.05).astype(int)) for c in g.empty}
    assert not occupied & keys
    # triangle of base 1 m and height 2 m: 1 m² = 400 cells of 0.05 m, and the ray edges
    assert 300 <= g.empty.shape[0] <= 560
    # a cell half-way on the central ray is free, one beside the triangle is not
    assert (20, 0) in keys and (20, 15) not in keys


def test_ray_cells_exclude_the_end_cells():
    cells = ray_cells(np.zeros(2), np.array([[1.0, 0.0]]), 0.1)
    xs = np.sort(cells[:, 0])
    np.testing.assert_allclose(xs, np.arange(10) * 0.1 + 0.05, atol=1e-6)


def test_grid_3d_is_refused_with_its_name():
    with pytest.raises(ParameterError, match="Grid/3D"):
        RtabmapParameters.from_dict({"Grid/3D": "true"})
    assert RtabmapParameters.from_dict({"Grid/RayTracing": "true"}).grid_ray_tracing
