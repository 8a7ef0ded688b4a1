"""Pose graphs of a 10 m square for the pose-graph tests: two drifting laps with true and false
closures, built chained from odometry (batch) or node by node as the SLAM front end does."""

from __future__ import annotations

import math

import numpy as np

from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import EdgeKind, PoseGraph

ODO_COV = np.diag([0.05**2, 0.05**2, 0.02**2])
LOOP_COV = np.diag([0.01**2, 0.01**2, 0.005**2])


def square() -> np.ndarray:
    """40 poses around a 10 m square (4 sides × 10 steps of 1 m), ending at the start."""
    poses = [np.zeros(3)]
    for side in range(4):
        for step in range(10):
            turn = math.pi / 2 if step == 9 else 0.0
            poses.append(se2_compose(poses[-1], [1.0, 0.0, turn]))
        del side
    return np.array(poses[:-1])



def two_laps(seed: int) -> tuple[np.ndarray, list[tuple[int, int, np.ndarray, np.ndarray, bool]]]:
    """Two drifting laps of the square; each second-lap node closes onto the first lap, plus
    8 false closures between random nodes (random relative poses)."""
    rng = np.random.default_rng(seed)
    lap = square()
    truth = np.concatenate([lap, lap])
    n = len(truth)
    edges = []
    for k in range(1, n):
        z = se2_between(truth[k - 1], truth[k]) + rng.normal(0.0, [0.02, 0.02, 0.01])
        edges.append((k - 1, k, z, ODO_COV, False))
    for k in range(len(lap), n):
        edges.append((k - len(lap), k, se2_between(truth[k - len(lap)], truth[k]), LOOP_COV, True))
    for _ in range(8):
        i, j = sorted(rng.choice(n, size=2, replace=False))
        z = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)])
        edges.append((int(i), int(j), z, LOOP_COV, True))
    edges.sort(key=lambda e: max(e[0], e[1]))
    return truth, edges


def chained(truth: np.ndarray, edges: list, **kwargs: object) -> PoseGraph:
    graph = PoseGraph(**kwargs)  # type: ignore[arg-type]
    graph.add_node(truth[0])
    for k in range(1, len(truth)):
        graph.add_node(
            se2_compose(graph.pose(k - 1), edges[[e[:2] for e in edges].index((k - 1, k))][2])
        )
    for i, j, z, cov, robust in edges:
        graph.add_edge(
            i, j, z, cov, kind=EdgeKind.LOOP if robust else EdgeKind.ODOMETRY, robust=robust
        )
    return graph


def incremental(edges: list, truth: np.ndarray, **kwargs: object) -> PoseGraph:
    """Feed the graph node by node, optimising after each, as the SLAM front end does."""
    graph = PoseGraph(**kwargs)  # type: ignore[arg-type]
    by_last: dict[int, list] = {}
    for e in edges:
        by_last.setdefault(max(e[0], e[1]), []).append(e)
    graph.add_node(truth[0])
    for k in range(1, len(truth)):
        odo = next(e for e in by_last[k] if not e[4] and e[0] == k - 1)
        graph.add_node(se2_compose(graph.pose(k - 1), odo[2]))
        for i, j, z, cov, robust in by_last[k]:
            kind = EdgeKind.LOOP if robust else EdgeKind.ODOMETRY
            graph.add_edge(i, j, z, cov, kind=kind, robust=robust)
        graph.optimize()
    return graph
