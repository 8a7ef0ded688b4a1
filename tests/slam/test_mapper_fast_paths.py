"""SlamCore's per-scan fast paths give bit-for-bit the values of the general code they replace.

Batched per-scan paths of SlamCore give bit for bit what the per-node code gives."""

from __future__ import annotations

import math

import numpy as np
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between, se2_compose, se2_inverse, wrap_angle
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.loop_closure import find_loop_candidates
from eddiebot.slam.mapper.se2_rows import _between1, _compose1, _compose_rows, _inverse1, _wrap1


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


def test_row_compose_is_the_scalar_compose_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    a = _poses(rng, 4000)
    offsets = [np.array([0.1, -0.02, 0.03]), np.zeros(3), np.array([-0.0, 0.0, np.pi]),
               np.array([1e-3, 2.5, -np.pi])]
    # headings whose sum with the offset lands on the ±π boundary
    a[12:16, 2] = [np.pi - 0.03, -np.pi - 0.03, 0.0, -2 * np.pi]
    for off in offsets:
        rows = _compose_rows(a, off)
        want = np.array([_compose1(x, off) for x in a])
        assert rows.tobytes() == want.tobytes()
        assert rows.tobytes() == se2_compose(a, np.broadcast_to(off, a.shape)).tobytes()


def _core_after_loop(n: int = 70) -> SlamCore:
    cfg = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)
    truth = loop_path()[:n]
    odom = drifting_odometry(loop_path())[:n]
    core = SlamCore(cfg, sensor_offset=(0.1, -0.02, 0.03))
    for k, (p, o) in enumerate(zip(truth, odom)):
        scan = Scan(raycast(ROOM, p, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, k * 10**8)
        core.process(scan, o)
    return core


def _world_normals(core: SlamCore, idx: int, pose: np.ndarray) -> np.ndarray:
    """A node's normals in the map frame, one node at a time (the per-node code the batched
    path replaced, operation for operation)."""
    local = core._local_normals(idx)
    th = float(_compose1(pose, core.sensor_offset)[2])
    c, s = math.cos(th), math.sin(th)
    return np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]],
                    axis=-1)


def test_batched_reference_equals_per_node_points_and_normals() -> None:
    core = _core_after_loop()
    poses = core.graph.poses
    n = poses.shape[0]
    assert n > 20
    rng = np.random.default_rng(5)
    # the pose rows may also be any estimate (e.g. mid-update), not only the graph's
    moved = poses + rng.normal(0.0, 0.3, poses.shape)
    for rows in (poses, moved):
        for nodes in ([0], list(range(n)), list(range(n - 10, n)), [5, 3, 9, 9, 1],
                      [int(i) for i in rng.choice(n, 17, replace=False)]):
            ref, normals = core._reference(nodes, rows, normals=True)
            fresh = SlamCore(core.config, sensor_offset=core.sensor_offset)
            fresh.graph, fresh.nodes = core.graph, core.nodes
            want = np.concatenate([fresh._world_points(i, rows[i]) for i in nodes])
            want_n = np.concatenate([_world_normals(fresh, i, rows[i]) for i in nodes])
            assert ref.tobytes() == want.tobytes()
            assert normals is not None and normals.tobytes() == want_n.tobytes()
            only, none = core._reference(nodes, rows)
            assert none is None and only.tobytes() == want.tobytes()


def test_kept_active_mask_follows_retirement(tmp_path) -> None:
    from eddiebot.slam.session import load_session, save_session

    core = _core_after_loop(40)
    assert core._active_nodes().tobytes() == core.active_mask().tobytes()
    path = save_session(core, tmp_path / "room.eslam")
    life = load_session(path, mode="lifelong")
    truth = loop_path()
    life.set_initial_pose(truth[0])
    retired_seen = False
    for k in range(0, 24, 2):
        d = truth[k] - truth[0]
        c, s = np.cos(-truth[0, 2]), np.sin(-truth[0, 2])
        odom = np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])
        scan = Scan(raycast(ROOM, truth[k], SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0,
                    10**9 + k * 10**8)
        life.process(scan, odom)
        want = life.active_mask()
        assert life._active_nodes().tobytes() == want.tobytes()
        retired_seen |= not want.all()
    assert retired_seen  # the revisited stretch's old scans retired on the way


def test_batched_reference_keeps_float32_points_float32() -> None:
    import dataclasses

    core = _core_after_loop(30)
    poses = core.graph.poses
    core.nodes = [dataclasses.replace(n, points=n.points.astype(np.float32)) for n in core.nodes]
    core._ref_cache.clear()  # the float64 points of the run
    nodes = list(range(3, poses.shape[0]))
    ref, _ = core._reference(nodes, poses)
    want = np.concatenate([core._world_points(i, poses[i]) for i in nodes])
    assert want.dtype == ref.dtype == np.float32
    assert ref.tobytes() == want.tobytes()


def test_place_rows_kernel_is_numpy_bit_for_bit() -> None:
    from eddiebot.slam.mapper.se2_rows import _place_rows

    rng = np.random.default_rng(17)
    counts = rng.integers(0, 400, 60).astype(np.int64)
    n = int(counts.sum())
    local = rng.normal(0.0, 1.0, (n, 2)) * 10.0 ** rng.uniform(-3, 3, (n, 1))
    th = rng.uniform(-4.0, 4.0, counts.size)
    c, s = np.cos(th), np.sin(th)
    tx, ty = rng.normal(0.0, 50.0, counts.size), rng.normal(0.0, 50.0, counts.size)
    pick = np.repeat(np.arange(counts.size), counts)
    lx, ly = local[:, 0], local[:, 1]
    want = np.stack([tx[pick] + c[pick] * lx - s[pick] * ly,
                     ty[pick] + s[pick] * lx + c[pick] * ly], axis=-1)
    want_rot = np.stack([c[pick] * lx - s[pick] * ly, s[pick] * lx + c[pick] * ly], axis=-1)
    got = np.empty_like(local)
    _place_rows(local, counts, tx, ty, c, s, True, got)
    assert got.tobytes() == want.tobytes()
    _place_rows(local, counts, tx, ty, c, s, False, got)
    assert got.tobytes() == want_rot.tobytes()
    # a fused multiply-add would round differently on a good share of these values
    fused = np.array([np.float64(np.longdouble(a) * np.longdouble(b) + np.longdouble(t))
                      for a, b, t in zip(c[pick][:2000], lx[:2000], tx[pick][:2000])])
    assert np.any(fused != tx[pick][:2000] + c[pick][:2000] * lx[:2000])
