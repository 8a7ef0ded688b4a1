"""Pose graph: loop closure on a drifting square, robust kernel, g2o ½χ²."""

from __future__ import annotations

import math

import numpy as np
import pytest
from slam_world import dataset

from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import EdgeKind, PoseGraph
from eddiebot.slam.io import build_pose_graph, read_g2o, read_pose_graph, read_toro

ODO_COV = np.diag([0.05**2, 0.05**2, 0.02**2])
LOOP_COV = np.diag([0.01**2, 0.01**2, 0.005**2])


def _square() -> np.ndarray:
    """40 poses around a 10 m square (4 sides × 10 steps of 1 m), ending at the start."""
    poses = [np.zeros(3)]
    for side in range(4):
        for step in range(10):
            turn = math.pi / 2 if step == 9 else 0.0
            poses.append(se2_compose(poses[-1], [1.0, 0.0, turn]))
        del side
    return np.array(poses[:-1])


def _drifting_graph(truth: np.ndarray, **kwargs: object) -> PoseGraph:
    graph = PoseGraph(**kwargs)  # type: ignore[arg-type]
    est = truth[0].copy()
    graph.add_node(est)
    for k in range(1, len(truth)):
        z = se2_between(truth[k - 1], truth[k]) + np.array([0.0, 0.0, 0.02])  # heading drift
        est = se2_compose(est, z)
        graph.add_node(est)
        graph.add_edge(k - 1, k, z, ODO_COV, kind=EdgeKind.ODOMETRY)
        graph.optimize()
    return graph


def _error(graph: PoseGraph, truth: np.ndarray) -> float:
    return float(np.max(np.hypot(*(graph.poses[:, :2] - truth[:, :2]).T)))


@pytest.mark.parametrize("optimizer", ["isam2", "levenberg_marquardt"])
def test_loop_closure_removes_square_drift(optimizer: str) -> None:
    truth = _square()
    graph = _drifting_graph(truth, optimizer=optimizer)
    before = _error(graph, truth)
    assert before > 1.5  # 0.02 rad per step over 39 steps
    last = len(truth) - 1
    graph.add_edge(last, 0, se2_between(truth[last], truth[0]), LOOP_COV, kind=EdgeKind.LOOP)
    graph.optimize()
    after = _error(graph, truth)
    assert after < 0.25 * before
    assert after < 0.5
    assert graph.half_chi2() > 0.0


def test_robust_kernel_rejects_false_loop() -> None:
    truth = _square()
    results = {}
    for kernel in ("none", "cauchy"):
        graph = _drifting_graph(truth, robust_kernel=kernel)
        last = len(truth) - 1
        graph.add_edge(
            last, 0, se2_between(truth[last], truth[0]), LOOP_COV, kind=EdgeKind.LOOP, robust=True
        )
        graph.optimize()
        clean = graph.poses.copy()
        # a false closure: node 20 (far corner) "matched" onto node 0
        graph.add_edge(20, 0, np.array([0.3, 0.0, 0.1]), LOOP_COV, kind=EdgeKind.LOOP, robust=True)
        graph.optimize()
        results[kernel] = float(np.max(np.hypot(*(graph.poses[:, :2] - clean[:, :2]).T)))
    assert results["cauchy"] < 0.1
    assert results["none"] > 1.0


def test_edges_and_neighbours() -> None:
    graph = PoseGraph()
    for k in range(3):
        graph.add_node([k, 0.0, 0.0])
    graph.add_edge(0, 1, [1, 0, 0], ODO_COV)
    graph.add_edge(1, 2, [1, 0, 0], ODO_COV)
    assert graph.neighbours(1) == {0, 2}
    with pytest.raises(ValueError, match="distinct existing"):
        graph.add_edge(0, 5, [1, 0, 0], ODO_COV)
    graph.optimize()
    assert graph.half_chi2() == pytest.approx(0.0, abs=1e-12)


def test_intel_g2o_half_chi2_matches_reference() -> None:
    data = read_g2o(dataset("slam2d", "intel", "intel.g2o"))
    assert data.poses.shape == (1728, 3)
    assert data.edge_index.shape == (2512, 2)
    graph = build_pose_graph(data)
    graph.optimize()
    assert graph.half_chi2() == pytest.approx(22.50, rel=0.01)


def test_toro_and_g2o_read_the_same_graph(tmp_path) -> None:
    g2o = tmp_path / "g.g2o"
    toro = tmp_path / "g.graph"
    g2o.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 2 0.1 0\n"
        "EDGE_SE2 0 1 1 0 0 10 1 2 20 3 30\nEDGE_SE2 1 2 1 0.1 0 10 0 0 10 0 10\nEDGE_SE2 0 2 2 0.1 0 5 0 0 5 0 5\n"
    )
    toro.write_text(
        "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nVERTEX2 2 2 0.1 0\n"
        "EDGE2 0 1 1 0 0 10 1 20 30 2 3\nEDGE2 1 2 1 0.1 0 10 0 10 10 0 0\nEDGE2 0 2 2 0.1 0 5 0 5 5 0 0\n"
    )
    a, b = read_g2o(g2o), read_toro(toro)
    assert np.allclose(a.information, b.information)
    assert np.allclose(a.measurements, b.measurements)
    assert read_pose_graph(toro).information[0, 0, 2] == 2
    assert a.information[0].tolist() == [[10, 1, 2], [1, 20, 3], [2, 3, 30]]


def test_bad_g2o_line_names_file_and_line(tmp_path) -> None:
    from eddiebot.slam import PoseGraphFormatError

    path = tmp_path / "bad.g2o"
    path.write_text("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0\n")
    with pytest.raises(PoseGraphFormatError, match=r"bad\.g2o:2"):
        read_g2o(path)
