"""SlamCore's per-scan fast paths give bit-for-bit the values of the general code they replace."""

from __future__ import annotations

import numpy as np
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between, se2_compose, se2_inverse, wrap_angle
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.loop_closure import find_loop_candidates
from eddiebot.slam.mapper import _between1, _compose1, _inverse1, _wrap1


def _poses(rng: np.random.Generator, n: int) -> np.ndarray:
    p = rng.normal(0.0, 20.0, (n, 3))
    p[:, 2] = rng.uniform(-4.0, 4.0, n)
    # headings on the wrap boundary, signed zeros, right angles
    p[:8, 2] = [np.pi, -np.pi, 0.0, -0.0, 0.5 * np.pi, -0.5 * np.pi, 2 * np.pi, -2 * np.pi]
    p[8:12, :2] = [[0.0, -0.0], [-0.0, 0.0], [1e-300, -1e-300], [1e12, -1e12]]
    return p


def test_scalar_se2_fast_paths_are_bit_identical() -> None:
    rng = np.random.default_rng(7)
    a, b = _poses(rng, 3000), _poses(rng, 3000)[::-1].copy()
    for x, y in zip(a, b):
        assert _compose1(x, y).tobytes() == se2_compose(x, y).tobytes()
        assert _inverse1(x).tobytes() == se2_inverse(x).tobytes()
        assert _between1(x, y).tobytes() == se2_between(x, y).tobytes()
    for t in np.concatenate([a[:, 2] + b[:, 2], [np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0]]):
        assert np.float64(_wrap1(t)).tobytes() == wrap_angle(t).tobytes()
    # +π stays +π (the half-open interval), as in wrap_angle
    assert _wrap1(-np.pi) == np.pi


def _candidates_reference(current, positions, linked, max_distance, min_chain_size, active):
    """The plain scan over every earlier node id (the general formulation)."""
    origin = positions[current]
    chains, chain = [], []
    for idx in range(current):
        d = np.hypot(positions[idx, 0] - origin[0], positions[idx, 1] - origin[1])
        ok = d <= max_distance and (active is None or active[idx])
        if ok and idx not in linked:
            chain.append(idx)
            continue
        if len(chain) >= min_chain_size:
            chains.append(tuple(chain))
        chain = []
    if len(chain) >= min_chain_size:
        chains.append(tuple(chain))
    return chains


def test_loop_candidates_match_the_full_scan() -> None:
    rng = np.random.default_rng(3)
    checked = 0
    for trial in range(200):
        n = int(rng.integers(2, 120))
        # a wandering path that comes back near its start
        steps = rng.normal(0.0, 0.6, (n, 2))
        positions = np.cumsum(steps, axis=0)
        current = n - 1
        linked = {int(i) for i in rng.choice(n, size=int(rng.integers(0, n)), replace=False)}
        linked.add(current)
        active = rng.random(n) > 0.1 if trial % 2 else None
        for size in (1, 3, 6):
            want = _candidates_reference(current, positions, linked, 3.0, size, active)
            got = find_loop_candidates(
                current, positions, linked, max_distance=3.0, min_chain_size=size, active=active
            )
            assert got == want
            checked += len(want)
    assert checked > 100  # the cases exercise real chains, not only empty answers


def test_world_points_from_passed_pose_equal_graph_lookup() -> None:
    cfg = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)
    truth = loop_path()[:60]
    odom = drifting_odometry(loop_path())[:60]
    core = SlamCore(cfg, sensor_offset=(0.1, -0.02, 0.03))
    for k, (p, o) in enumerate(zip(truth, odom)):
        scan = Scan(raycast(ROOM, p, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, k * 10**8)
        core.process(scan, o)
    poses = core.graph.poses
    assert poses.shape[0] > 10
    for i in range(poses.shape[0]):
        fresh = SlamCore(cfg, sensor_offset=core.sensor_offset)
        fresh.graph, fresh.nodes = core.graph, core.nodes
        assert core._world_points(i, poses[i]).tobytes() == fresh._world_points(i).tobytes()
