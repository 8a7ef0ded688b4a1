"""Correlative scan matcher on synthetic scans: offsets, a Kinect-like scan, corridors."""

from __future__ import annotations

import math

import numpy as np
from slam_world import CORRIDOR, ROOM, raycast

from eddiebot.geometry import se2_transform_points
from eddiebot.slam import MatcherParams, build_correlation_grid, match_scan, score_pose
from eddiebot.slam.scan_matcher import pyramid_levels, refine_icp, refine_icp_with_covariance


def _points(
    pose: np.ndarray, angles: np.ndarray, segments: np.ndarray = ROOM, max_range: float = 30.0
) -> np.ndarray:
    r = raycast(segments, pose, angles, max_range)
    ok = np.isfinite(r)
    return np.stack([r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])], axis=-1)


def _grid_for(ref_world: np.ndarray, pts: np.ndarray, prior: np.ndarray, params: MatcherParams):
    world = se2_transform_points(prior, pts)
    half = 0.5 * params.search_dimension + 0.1
    bounds = (
        world[:, 0].min() - half,
        world[:, 1].min() - half,
        world[:, 0].max() + half,
        world[:, 1].max() + half,
    )
    return build_correlation_grid(
        ref_world, bounds, params.resolution, params.smear_deviation, pyramid_levels(params)
    )


def test_recovers_known_offset() -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 361)
    ref_pose = np.array([4.0, 3.5, 0.2])
    true = np.array([4.3, 3.4, 0.25])
    ref = se2_transform_points(ref_pose, _points(ref_pose, angles))
    pts = _points(true, angles)
    prior = true + np.array([0.15, -0.1, 0.08])  # inside the ±0.25 m / ±20° window
    params = MatcherParams()  # slam_toolbox's sequential defaults
    result = match_scan(pts, _grid_for(ref, pts, prior, params), prior, params)
    err = result.pose - true
    assert abs(err[0]) < 0.01
    assert abs(err[1]) < 0.01
    assert abs(err[2]) < math.radians(0.3)
    assert result.response > 0.8
    assert np.all(np.linalg.eigvalsh(result.covariance) > 0)


def test_kinect_like_scan() -> None:
    # 57° field of view, 4 m range, 320 beams: what depthimage_to_laserscan gives Eddie
    angles = np.linspace(-math.radians(28.5), math.radians(28.5), 320)
    # looking into the room's lower-right corner from 2.5 m, the reference scan taken nearby
    ref_pose = np.array([10.2, 2.0, -0.5])
    true = np.array([10.0, 1.6, -0.45])
    ref_angles = np.linspace(-math.pi, math.pi, 720, endpoint=False)
    ref = se2_transform_points(ref_pose, _points(ref_pose, ref_angles, max_range=4.0))
    pts = _points(true, angles, max_range=4.0)
    assert pts.shape[0] == 320
    prior = true + np.array([-0.12, 0.1, -0.06])
    params = MatcherParams()
    result = match_scan(pts, _grid_for(ref, pts, prior, params), prior, params)
    err = result.pose - true
    assert math.hypot(err[0], err[1]) < 0.02
    assert abs(err[2]) < math.radians(0.5)


def test_wide_window_branch_and_bound_finds_large_offset() -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    true = np.array([8.0, 5.0, 1.9])
    ref = se2_transform_points(
        true, _points(true, np.linspace(-math.pi, math.pi, 720, endpoint=False))
    )
    pts = _points(true, angles)
    prior = true + np.array([1.2, -0.9, 0.25])
    params = MatcherParams(
        search_dimension=6.0, resolution=0.05, smear_deviation=0.03, penalize=False
    )
    grid = _grid_for(ref, pts, prior, params)
    assert len(grid.levels) > 1  # the pyramid is in use
    result = match_scan(pts, grid, prior, params)
    err = result.pose - true
    assert math.hypot(err[0], err[1]) < 0.03
    assert abs(err[2]) < math.radians(1.0)
    assert score_pose(pts, result.pose, grid) > 0.9


def test_corridor_covariance_is_long_along_the_corridor() -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    true = np.array([15.0, 1.0, 0.0])
    ref = se2_transform_points(true, _points(true, angles, CORRIDOR, max_range=6.0))
    pts = _points(true, angles, CORRIDOR, max_range=6.0)
    params = MatcherParams()
    result = match_scan(pts, _grid_for(ref, pts, true, params), true, params)
    cov = result.covariance
    assert cov[0, 0] > 5 * cov[1, 1]  # along x (the corridor) far less certain
    w, v = np.linalg.eigh(cov[:2, :2])
    assert abs(v[0, -1]) > 0.99  # the weakest direction is the corridor's axis
    assert abs(result.pose[1] - true[1]) < 0.01


def test_empty_inputs_return_prior() -> None:
    prior = np.array([1.0, 2.0, 0.3])
    grid = build_correlation_grid(np.zeros((0, 2)), (0.0, 0.0, 2.0, 2.0), 0.05, 0.05)
    result = match_scan(np.array([[1.0, 0.0]]), grid, prior, MatcherParams())
    assert np.allclose(result.pose, prior)
    assert result.response == 0.0


def test_icp_covariance_long_along_the_corridor_and_tight_across() -> None:
    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    true = np.array([15.0, 1.0, 0.0])
    ref = se2_transform_points(true, _points(true, angles, CORRIDOR, max_range=6.0))
    rng = np.random.default_rng(1)
    pts = _points(true, angles + 0.004, CORRIDOR, max_range=6.0)
    pts = pts + rng.normal(0.0, 0.005, pts.shape)
    pose, share, cov = refine_icp_with_covariance(pts, ref, true + np.array([0.0, 0.03, 0.01]))
    assert share > 0.9
    assert cov is not None
    assert abs(pose[1] - true[1]) < 0.005
    assert abs(pose[2] - true[2]) < math.radians(0.3)
    assert cov[1, 1] < 1e-4  # across the corridor: pinned by the walls
    assert cov[0, 0] > 100 * cov[1, 1]  # along it: nothing to fit
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    # the plain variant returns the same pose
    pose2, share2 = refine_icp(pts, ref, true + np.array([0.0, 0.03, 0.01]))
    assert np.allclose(pose, pose2) and share == share2


def test_icp_covariance_none_without_pairs() -> None:
    pts = np.array([[1.0, float(k)] for k in range(20)])
    ref = pts + 5.0
    pose, share, cov = refine_icp_with_covariance(pts, ref, np.zeros(3))
    assert cov is None and share == 0.0 and np.allclose(pose, 0.0)


def test_solve3_matches_linalg() -> None:
    from eddiebot.slam.scan_matcher.subcell import _solve3

    rng = np.random.default_rng(3)
    for _ in range(20):
        m = rng.normal(size=(3, 3))
        a = m @ m.T + 0.1 * np.eye(3)
        b = rng.normal(size=3)
        x = _solve3(a[0, 0], a[0, 1], a[0, 2], a[1, 1], a[1, 2], a[2, 2], b[0], b[1], b[2])
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)


def _numpy_normals(points: np.ndarray, nn: np.ndarray) -> np.ndarray:
    """Normals by numpy: each neighbourhood's scatter matrix through ``np.linalg.eigh``."""
    nb = points[nn]
    centred = nb - nb.mean(axis=1, keepdims=True)
    vals, vecs = np.linalg.eigh(np.einsum("mki,mkj->mij", centred, centred))
    normals = vecs[:, :, 0].copy()
    normals[~(vals[:, 0] < 0.1 * vals[:, 1] + 1e-12)] = np.nan
    return normals


def _assert_same_normals(got: np.ndarray, want: np.ndarray) -> None:
    """Equal up to each normal's sign (a line's normal has no preferred side), NaN alike."""
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    ok = np.isfinite(want[:, 0])
    sign = np.sign(np.sum(got[ok] * want[ok], axis=1))[:, None]
    np.testing.assert_allclose(got[ok] * sign, want[ok], rtol=0, atol=1e-9)


def _icp_oracle(
    points: np.ndarray, reference: np.ndarray, pose: np.ndarray, max_distance: float = 0.2
) -> tuple[np.ndarray, float, np.ndarray | None]:
    """Plain numpy / k-d tree point-to-line ICP (the compiled kernel must reproduce it)."""
    from scipy.spatial import cKDTree

    pose = pose.astype(np.float64).copy()
    tree = cKDTree(reference)
    normals = _numpy_normals(reference, tree.query(reference, k=6)[1])
    planar = np.isfinite(normals[:, 0])
    normals = np.where(planar[:, None], normals, 0.0)
    share, cov = 0.0, None
    for it in range(11):
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = np.stack(
            [pose[0] + c * points[:, 0] - s * points[:, 1],
             pose[1] + s * points[:, 0] + c * points[:, 1]], axis=-1,
        )
        dist, idx = tree.query(world, k=1, distance_upper_bound=max_distance)
        ok = np.isfinite(dist)
        ok[ok] &= planar[idx[ok]]
        share = float(np.count_nonzero(ok)) / points.shape[0]
        if np.count_nonzero(ok) < 10:
            cov = None
            break
        n, q, p = normals[idx[ok]], reference[idx[ok]], points[ok]
        r = np.einsum("ij,ij->i", n, world[ok] - q)
        dth = np.stack([-s * p[:, 0] - c * p[:, 1], c * p[:, 0] - s * p[:, 1]], axis=-1)
        jac = np.column_stack([n[:, 0], n[:, 1], np.einsum("ij,ij->i", n, dth)])
        w = np.minimum(1.0, 0.05 / np.maximum(np.abs(r), 1e-9))
        h = jac.T @ (jac * w[:, None]) + 1e-9 * np.eye(3)
        cov = float(np.sum(w * r * r)) / max(float(w.sum()) - 3.0, 1.0) * np.linalg.inv(h)
        if it == 10:
            break
        delta = -np.linalg.solve(h, jac.T @ (w * r))
        pose += delta
        if abs(delta[0]) < 1e-5 and abs(delta[1]) < 1e-5 and abs(delta[2]) < 1e-6:
            break
    pose[2] = math.remainder(pose[2], 2 * math.pi)
    return pose, share, None if cov is None else 0.5 * (cov + cov.T)


def test_icp_kernel_matches_kd_tree_oracle() -> None:
    rng = np.random.default_rng(3)
    angles = np.linspace(-0.5, 0.5, 300)
    truth = np.array([1.5, 1.2, 0.4])
    pts = _points(truth, angles)
    ref = se2_transform_points(truth, _points(truth, angles + 0.0007)) + rng.normal(
        0, 0.004, (pts.shape[0], 2)
    )
    ref = np.concatenate([ref, rng.uniform(-1.0, 5.0, (40, 2))])  # clutter: non-planar normals
    for k in range(12):
        start = truth + np.array([rng.normal(0, 0.06), rng.normal(0, 0.06), rng.normal(0, 0.03)])
        if k == 0:
            start = truth + np.array([3.0, 3.0, 0.0])  # nothing within reach: no pairs
        pose, share, cov = refine_icp_with_covariance(pts, ref, start)
        opose, oshare, ocov = _icp_oracle(pts, ref, start)
        np.testing.assert_allclose(pose, opose, rtol=0, atol=1e-12)  # same pairs, same sums
        assert share == oshare
        if ocov is None:
            assert cov is None
        else:
            assert cov is not None
            np.testing.assert_allclose(cov, ocov, rtol=1e-9, atol=1e-18)
        if k > 0:
            assert np.hypot(*(pose[:2] - truth[:2])) < 0.02


def _naive_block(
    grid: np.ndarray, px: np.ndarray, py: np.ndarray, x0: int, y0: int, n: int, step: int
) -> np.ndarray:
    """Candidate-major reference for `_response_block`: points added in scan order."""
    h, w = grid.shape
    out = np.zeros((n, n))
    for ix in range(n):
        for iy in range(n):
            total = 0.0
            for c, r in zip(px + x0 + step * ix, py + y0 + step * iy, strict=True):
                if 0 <= c < w and 0 <= r < h:
                    total += float(grid[r, c])
            out[ix, iy] = total
    return out * (1.0 / max(px.size, 1))


def test_response_block_matches_candidate_major_sums() -> None:
    # the compiled kernel reorders the loops, reads column phases and skips out-of-grid
    # runs; every candidate still adds its points in scan order: the candidate-major sums,
    # also for points partly or wholly outside the grid
    from eddiebot.slam.scan_matcher.search import _planes, _response_block

    rng = np.random.default_rng(7)
    grid = rng.random((37, 53)).astype(np.float32)
    for step, n in ((1, 9), (4, 7), (3, 5), (2, 11)):
        px = rng.integers(-30, 80, 40)
        py = rng.integers(-25, 60, 40)
        for x0, y0 in ((-12, -12), (0, 5), (-40, 30)):
            got = _response_block(_planes(grid, step), 53, px, py, x0, y0, n, step)
            np.testing.assert_array_equal(got, _naive_block(grid, px, py, x0, y0, n, step))
    assert _response_block(_planes(grid, 1), 53, px[:0], py[:0], 0, 0, 3, 1).sum() == 0.0
    for _ in range(40):  # grids of every shape, steps 2-4
        h, w = (int(v) for v in rng.integers(5, 90, 2))
        grid = rng.random((h, w)).astype(np.float32)
        step = int(rng.integers(2, 5))
        n = int(rng.integers(1, 14))
        px = rng.integers(-60, 150, 30)
        py = rng.integers(-60, 150, 30)
        x0, y0 = (int(v) for v in rng.integers(-40, 40, 2))
        np.testing.assert_array_equal(
            _response_block(_planes(grid, step), w, px, py, x0, y0, n, step),
            _naive_block(grid, px, py, x0, y0, n, step),
        )


def _naive_profile(
    grid: np.ndarray, px: np.ndarray, py: np.ndarray, dth: np.ndarray, window: int, step: int,
    res: float, penalize: bool,
) -> np.ndarray:
    """Each heading's best (penalised) response over the window, every ``step`` cells."""
    from eddiebot.slam.scan_matcher.branch_and_bound import _penalty

    n = 2 * (window // step) + 1
    x0 = -(window // step) * step
    out = np.zeros(dth.size)
    for a in range(dth.size):
        block = _naive_block(grid, px[a], py[a], x0, x0, n, step)
        for ix in range(n):
            for iy in range(n):
                v = block[ix, iy]
                if penalize:
                    v *= _penalty((x0 + step * ix) * res, (x0 + step * iy) * res, dth[a],
                                  0.5, 1.0, 0.5, 0.9)
                out[a] = max(out[a], v)
    return out


def test_coarse_pass_profile_is_the_heading_profile() -> None:
    # the coarse pass's per-heading best is the heading variance's input
    from eddiebot.slam.scan_matcher.search import _coarse_grid_search

    rng = np.random.default_rng(11)
    grid = rng.random((120, 140)).astype(np.float32)
    px = rng.integers(10, 130, (9, 60))
    py = rng.integers(10, 110, (9, 60))
    dth = 0.0349 * np.arange(-4, 5, dtype=np.float64)
    for penalize in (True, False):
        args = (grid, px, py, dth, 25, 4, 0.01, penalize, 0.5, 1.0, 0.5, 0.9)
        profile = np.zeros(dth.size)
        a, x, y, s = _coarse_grid_search(*args, profile)
        np.testing.assert_array_equal(
            profile, _naive_profile(grid, px, py, dth, 25, 4, 0.01, penalize)
        )
        assert s == profile.max() and profile[a] == s
        assert -25 <= x <= 25 and -25 <= y <= 25


def test_normals_neighbour_sweep_matches_kd_tree() -> None:
    from scipy.spatial import cKDTree

    from eddiebot.slam.scan_matcher.normals import _nearest_sweep, point_normals

    rng = np.random.default_rng(5)
    angles = np.linspace(-0.5, 0.5, 300)
    pts = _points(np.array([1.5, 1.2, 0.4]), angles) + rng.normal(0, 0.003, (300, 2))
    pts = np.concatenate([pts, rng.uniform(-1.0, 5.0, (40, 2))])  # clutter
    tree = cKDTree(pts)
    _, want = tree.query(pts, k=6)
    got = _nearest_sweep(pts, np.argsort(pts[:, 0], kind="stable").astype(np.int64), 6)
    np.testing.assert_array_equal(got, want)
    # same neighbours in the same order: numpy's PCA normals through a k-d tree
    with_tree = _numpy_normals(pts, want)
    _assert_same_normals(point_normals(pts), with_tree)
    planar = np.isfinite(with_tree[:, 0])
    assert planar[:300].mean() > 0.9 and planar[300:].mean() < 0.5
    assert np.isnan(point_normals(pts[:5])).all()


def test_rotated_cells_match_numpy_formula() -> None:
    from eddiebot.slam.scan_matcher import CorrelationGrid
    from eddiebot.slam.scan_matcher.lookup import _cells_for_angles

    rng = np.random.default_rng(2)
    pts = rng.uniform(-4.0, 4.0, (200, 2))
    grid = CorrelationGrid((np.zeros((4, 4), np.float32),), (-3.217, 1.093), 0.01)
    prior = np.array([0.731, -2.113, 0.4])
    thetas = prior[2] + 0.0349 * np.arange(-10, 11)
    px, py = _cells_for_angles(pts, prior, thetas, grid)
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    wx = c * pts[None, :, 0] - s * pts[None, :, 1] + prior[0]
    wy = s * pts[None, :, 0] + c * pts[None, :, 1] + prior[1]
    np.testing.assert_array_equal(px, np.floor((wx - grid.origin[0]) / 0.01).astype(np.int64))
    np.testing.assert_array_equal(py, np.floor((wy - grid.origin[1]) / 0.01).astype(np.int64))


def _numpy_weighted_covariance(
    values: np.ndarray, coords: np.ndarray, best: float, floor: np.ndarray
) -> np.ndarray:
    keep = values >= best - 0.1
    w = values[keep]
    c = coords[keep]
    norm = float(w.sum())
    if norm <= 1e-12:
        return np.diag(floor)
    mean = (w[:, None] * c).sum(axis=0) / norm
    d = c - mean
    cov = (w[:, None, None] * d[:, :, None] * d[:, None, :]).sum(axis=0) / norm
    return cov + np.diag(floor)


def test_weighted_covariance_kernel_matches_numpy() -> None:
    # the covariance feeds the graph's edges: numpy's expressions, to rounding
    from eddiebot.slam.scan_matcher.covariance import _weighted_covariance
    from eddiebot.slam.scan_matcher.lookup import _window_offsets

    rng = np.random.default_rng(13)
    for window in (1, 3, 25, 40):
        coords = _window_offsets(window, 0.01)
        for power in (1.0, 3.0, 8.0):
            values = rng.random(coords.shape[0]) ** power
            for best in (float(values.max()), float(values.max()) - 0.05):
                floor = np.full(2, 1e-5)
                got = _weighted_covariance(values, coords, best, floor)
                np.testing.assert_allclose(
                    got, _numpy_weighted_covariance(values, coords, best, floor),
                    rtol=1e-10, atol=1e-18,
                )
    for n in (3, 8, 11, 21, 61, 200):
        resp = rng.random((n, 5, 5))
        thetas = 0.0349 * np.arange(n, dtype=np.float64) - 0.3
        vals = resp[:, 2, 3]  # strided, as match_scan passes it
        floor = np.array([1e-6])
        got = _weighted_covariance(vals, thetas[:, None], float(vals.max()), floor)
        want = _numpy_weighted_covariance(vals, thetas[:, None], float(vals.max()), floor)
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-18)
    # nothing kept above the floor: the floor alone
    zero = np.zeros(9)
    np.testing.assert_array_equal(
        _weighted_covariance(zero, _window_offsets(1, 0.01), 0.0, np.full(2, 2e-5)),
        np.diag([2e-5, 2e-5]),
    )


def test_closed_form_pca_normals_match_lapack() -> None:
    # the 2 × 2 eigenproblem in closed form against np.linalg.eigh: general, degenerate
    # (axis-aligned lines, exact duplicates, a tiny off-diagonal) and widely scaled
    from eddiebot.slam.scan_matcher.normals import _pca_normals

    rng = np.random.default_rng(17)
    k = 6
    hoods = [rng.normal(size=(k, 2)) * 10.0 ** rng.uniform(-6, 2) for _ in range(2000)]
    line = np.stack([np.linspace(0.0, 1.0, k), np.zeros(k)], axis=-1)
    hoods += [line, line[:, ::-1], line + 1e-20 * rng.normal(size=(k, 2))]
    hoods += [line @ np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
              + rng.normal(0.0, 0.003, (k, 2)) for a in rng.uniform(-math.pi, math.pi, 200)]
    pts = np.concatenate(hoods)
    nn = np.arange(pts.shape[0]).reshape(-1, k)
    nn = np.repeat(nn, k, axis=0)  # each point's neighbourhood: its own group
    got = _pca_normals(pts, nn)
    want = _numpy_normals(pts, nn)
    _assert_same_normals(got, want)
    assert np.isfinite(want[:, 0]).sum() > 1000  # line-like ones among them
    first_line = 2000 * k
    np.testing.assert_allclose(np.abs(got[first_line]), [0.0, 1.0], atol=1e-15)  # y = 0
    np.testing.assert_allclose(np.abs(got[first_line + k]), [1.0, 0.0], atol=1e-15)  # x = 0


def test_compiled_normals_match_numpy_pca() -> None:
    from eddiebot.slam.scan_matcher.normals import _nearest_sweep, point_normals

    rng = np.random.default_rng(19)
    for trial in range(24):
        k = (3, 4, 6, 8, 10, 16)[trial % 6]
        n = int(rng.integers(k, 400))
        if trial % 2:
            th = rng.uniform(-0.5, 0.5, n)
            r = rng.uniform(0.5, 5.0, n)
            pts = np.stack([r * np.cos(th), r * np.sin(th)], axis=-1)
        else:
            pts = rng.normal(size=(n, 2)) * 10.0 ** rng.uniform(-4, 2)
        nn = _nearest_sweep(pts, np.argsort(pts[:, 0], kind="stable").astype(np.int64), k)
        _assert_same_normals(point_normals(pts, neighbours=k), _numpy_normals(pts, nn))


def test_pyramid_levels_are_the_anchored_dilation() -> None:
    # level h = max over the 2^h × 2^h cells from (r, c), zero past the edges: what
    # cv2.dilate anchored at (0, 0) with a constant 0 border gives
    import cv2

    rng = np.random.default_rng(23)
    for trial in range(6):
        pts = rng.uniform(-3.0, 3.0, (int(rng.integers(1, 300)), 2))
        grid = build_correlation_grid(pts, (-3.0, -3.0, 3.0 + trial, 3.0), 0.05, 0.03, 6)
        assert len(grid.levels) == 6
        for h in range(1, 6):
            k = 1 << h
            want = cv2.dilate(
                grid.levels[0],
                np.ones((k, k), np.uint8),
                anchor=(0, 0),
                borderType=cv2.BORDER_CONSTANT,
                borderValue=0,
            )
            np.testing.assert_array_equal(grid.levels[h], want)


def test_window_near_best_keeps_every_candidate_the_covariance_uses() -> None:
    from eddiebot.slam.scan_matcher.branch_and_bound import _window_near_best
    from eddiebot.slam.scan_matcher.covariance import _weighted_covariance
    from eddiebot.slam.scan_matcher.lookup import _cells_for_angles, _window_offsets
    from eddiebot.slam.scan_matcher.search import _exhaustive

    rng = np.random.default_rng(31)
    pruned = 0
    for trial in range(24):
        ref = rng.uniform(-4.0, 4.0, (int(rng.integers(20, 300)), 2))
        grid = build_correlation_grid(ref, (-4.0, -4.0, 4.0, 4.0), 0.05, 0.03, 6)
        scan = ref[rng.choice(ref.shape[0], 60)] + rng.normal(0.0, 0.02, (1, 2))
        if trial % 4 == 0:
            scan = rng.uniform(-7.0, 7.0, (50, 2))  # partly off the grid
        window = int(rng.integers(20, 90))
        penalize = bool(trial % 2)
        pen = (penalize, 0.5, 1.0, 0.5, 0.9)
        px, py = _cells_for_angles(scan, np.array([0.1, -0.2, 0.05]), np.array([0.05]), grid)
        want = _exhaustive(grid.levels[0], px, py, np.array([0.05]), 0, 0, window, 0.05, *pen)[0]
        sx, sy = (int(v) for v in rng.integers(-window - 1, window + 2, 2))
        got = _window_near_best(
            *grid.levels, 6, px[0], py[0], 0.05, window, sx, sy, 0.05, *pen
        )
        best = want.max()
        keep = want >= best - 0.1
        assert got.max() == best
        np.testing.assert_array_equal(got[keep], want[keep])
        assert np.all((got[~keep] == want[~keep]) | (got[~keep] == -1.0))
        pruned += int(np.count_nonzero(got == -1.0))
        coords = _window_offsets(window, 0.05)
        np.testing.assert_array_equal(
            _weighted_covariance(got.ravel(), coords, float(got.max()), np.full(2, 1e-5)),
            _weighted_covariance(want.ravel(), coords, float(want.max()), np.full(2, 1e-5)),
        )
    assert pruned > 0
