"""Loop verification's early rejection returns the response the full match would."""

from __future__ import annotations

import math

import numpy as np
from slam_world import ROOM, raycast

from eddiebot.geometry import se2_transform_points
from eddiebot.slam import MatcherParams, build_correlation_grid, match_scan
from eddiebot.slam.scan_matcher import pyramid_levels


def _points(pose: np.ndarray, angles: np.ndarray) -> np.ndarray:
    r = raycast(ROOM, pose, angles, 12.0)
    ok = np.isfinite(r)
    return np.stack([r[ok] * np.cos(angles[ok]), r[ok] * np.sin(angles[ok])], axis=-1)


def test_reject_below_keeps_the_response_and_full_matches_unchanged() -> None:
    rng = np.random.default_rng(31)
    angles = np.linspace(-0.5, 0.5, 160)
    params = MatcherParams(
        search_dimension=0.5, resolution=0.01, smear_deviation=0.1, penalize=False
    )
    rejected = kept = strong = 0
    for _trial in range(12):
        ref_pose = np.array([rng.uniform(2.0, 6.0), rng.uniform(2.0, 5.0), rng.uniform(-3, 3)])
        ref = se2_transform_points(ref_pose, _points(ref_pose, angles))
        true = ref_pose + np.array([*rng.normal(0.0, 0.3, 2), rng.normal(0.0, 0.2)])
        pts = _points(true, angles)
        pts = pts + rng.normal(0.0, 0.01, pts.shape)
        prior = true + np.array([*rng.normal(0.0, 0.1, 2), rng.normal(0.0, 0.02)])
        world = se2_transform_points(prior, pts)
        half = 0.5 * params.search_dimension + 0.1
        bounds = (world[:, 0].min() - half, world[:, 1].min() - half,
                  world[:, 0].max() + half, world[:, 1].max() + half)
        grid = build_correlation_grid(
            ref, bounds, params.resolution, params.smear_deviation, pyramid_levels(params)
        )
        full = match_scan(pts, grid, prior, params)
        # a threshold just above the response: rejected early with the same response
        above = math.nextafter(full.response, math.inf)
        early = match_scan(pts, grid, prior, params, reject_below=above)
        assert early.response == full.response and early.response < above
        assert np.array_equal(early.covariance, np.diag([1e3, 1e3, 1e3]))  # it stopped early
        rejected += 1
        strong += full.response > 0.5
        # at or below it: the full match, bit for bit
        for t in (full.response, 0.5 * full.response, 0.0):
            same = match_scan(pts, grid, prior, params, reject_below=t)
            assert same.response == full.response
            assert same.pose.tobytes() == full.pose.tobytes()
            assert same.covariance.tobytes() == full.covariance.tobytes()
            kept += 1
    assert rejected == 12 and kept == 36
    assert strong >= 6  # real matches, not only empty windows


def _near_linked_reference(start, positions, neighbours, max_distance):
    """The breadth-first search without the far-node memo (every encounter tested)."""
    from collections import deque

    origin = positions[start]
    seen = {start}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for nb in set(neighbours(node)):
            if nb in seen:
                continue
            diff = positions[nb] - origin
            if float(diff @ diff) <= max_distance * max_distance:
                seen.add(nb)
                queue.append(nb)
    return seen


def test_near_linked_nodes_matches_the_plain_search() -> None:
    from eddiebot.slam.loop_closure import near_linked_nodes

    rng = np.random.default_rng(41)
    sizes = []
    for _trial in range(60):
        n = int(rng.integers(5, 300))
        positions = np.cumsum(rng.normal(0.0, 0.4, (n, 2)), axis=0)
        adj: list[set[int]] = [set() for _ in range(n)]
        for i in range(1, n):
            adj[i].add(i - 1)
            adj[i - 1].add(i)
        for _ in range(int(rng.integers(0, n))):  # loop edges
            i, j = (int(v) for v in rng.integers(0, n, 2))
            if i != j:
                adj[i].add(j)
                adj[j].add(i)
        start = int(rng.integers(0, n))
        for dist in (0.5, 2.0, 5.0):
            got = near_linked_nodes(start, positions, adj.__getitem__, dist)
            assert got == _near_linked_reference(start, positions, adj.__getitem__, dist)
            sizes.append(len(got))
    assert max(sizes) > 20 and min(sizes) == 1


def _thin_reference(points: np.ndarray, cell: float) -> np.ndarray:
    keys = np.floor(points / cell).astype(np.int64)
    _, first = np.unique(keys[:, 0] * 1_000_003 + keys[:, 1], return_index=True)
    return points[np.sort(first)]


def test_thin_memo_returns_the_thinning_of_the_points_given() -> None:
    from eddiebot.slam.scan_matcher.lookup import _thin

    rng = np.random.default_rng(43)
    pts = rng.uniform(-3.0, 3.0, (300, 2))
    for cell in (0.05, 0.1, 0.05):
        got = _thin(pts, cell)
        assert got.tobytes() == _thin_reference(pts, cell).tobytes()
        assert _thin(pts, cell) is got  # the memo
    # the same array mutated in place, and another of the same shape: thinned afresh
    pts[:10] += 0.2
    assert _thin(pts, 0.05).tobytes() == _thin_reference(pts, 0.05).tobytes()
    other = rng.uniform(-3.0, 3.0, (300, 2))
    assert _thin(other, 0.05).tobytes() == _thin_reference(other, 0.05).tobytes()
    assert _thin(pts, 0.05).tobytes() == _thin_reference(pts, 0.05).tobytes()
    # signed zeros are other points (bytes, not values, decide)
    z = np.array([[0.0, 1.0], [0.5, 0.5], [0.01, 0.01]])
    zn = z.copy()
    zn[0, 0] = -0.0
    assert _thin(z, 0.05).tobytes() == _thin_reference(z, 0.05).tobytes()
    assert _thin(zn, 0.05).tobytes() == _thin_reference(zn, 0.05).tobytes()


def test_smear_kernel_is_shared_read_only() -> None:
    from eddiebot.slam.scan_matcher.grid import _smear_kernel

    k = _smear_kernel(0.01, 0.1)
    assert _smear_kernel(0.01, 0.1) is k and not k.flags.writeable
    half = round(2.0 * 0.1 / 0.01)
    d = np.arange(-half, half + 1, dtype=np.float64) * 0.01
    dist2 = d[None, :] ** 2 + d[:, None] ** 2
    want = np.exp(-0.5 * dist2 / (0.1 * 0.1))
    want[dist2 > (half * 0.01) ** 2 + 1e-12] = 0.0
    assert k.tobytes() == want.astype(np.float32).tobytes()
