"""Loop-closure candidate chains: Karto's node count, and path length on sparse scans."""

from __future__ import annotations

import numpy as np

from eddiebot.slam.loop_closure import find_loop_candidates


def _corridor_revisit(spacing: float, count: int) -> np.ndarray:
    """Nodes along a straight corridor at ``spacing``, then a node back at its middle."""
    out = [(i * spacing, 0.0) for i in range(count)]
    out.append(((count - 1) * spacing / 2.0, 0.3))
    return np.array(out, dtype=float)


def test_dense_nodes_need_the_chain_size_in_nodes() -> None:
    pos = _corridor_revisit(0.5, 30)  # 13 earlier nodes within 3 m
    chains = find_loop_candidates(30, pos, {30}, max_distance=3.0, min_chain_size=10,
                                  min_chain_length=4.5)
    assert len(chains) == 1 and len(chains[0]) >= 10
    none = find_loop_candidates(30, pos, {30}, max_distance=3.0, min_chain_size=14)
    assert none == []


def test_sparse_nodes_count_by_path_length() -> None:
    # one node a metre: at most 6 earlier nodes fit the 3 m circle, never Karto's 10
    pos = _corridor_revisit(1.0, 30)
    karto = find_loop_candidates(30, pos, {30}, max_distance=3.0, min_chain_size=10)
    assert karto == []
    chains = find_loop_candidates(30, pos, {30}, max_distance=3.0, min_chain_size=10,
                                  min_chain_length=(10 - 1) * 0.5)
    assert len(chains) == 1
    run = chains[0]
    assert 5 <= len(run) <= 6
    assert float(np.hypot(*np.diff(pos[list(run)], axis=0).T).sum()) >= 4.5


def test_a_short_glimpse_does_not_count() -> None:
    # a corridor crossed at right angles: three sparse nodes, 2 m of path
    cross = [(6.0, -3.0 + i * 1.0) for i in range(7)]
    far = [(20.0 + i, 0.0) for i in range(10)]
    pos = np.array(far + cross + [(6.0, 0.2)], dtype=float)
    cur = len(pos) - 1
    linked = {cur}
    chains = find_loop_candidates(cur, pos, linked, max_distance=1.5, min_chain_size=10,
                                  min_chain_length=4.5)
    assert chains == []
