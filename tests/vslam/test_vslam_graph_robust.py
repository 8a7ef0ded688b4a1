"""`Optimizer/Robust`: loop closures as Vertigo switchable constraints, so one false closure
among true ones does not bend the map, where the plain optimiser (with `RGBD/OptimizeMaxError`
0, nothing rejected after it) is bent by it."""

from __future__ import annotations

import numpy as np
import pytest

from eddiebot.vslam.graph import GraphLink, GtsamPoseGraph, IncrementalPose2Graph
from eddiebot.vslam.memory import Link, LinkType
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

SIDE = 10  # nodes per side of a 4 m square, two laps
LAP = 4 * SIDE
ODOM_INFO = np.diag([1e3, 1e3, 1e3, 1e3, 1e3, 1e3])  # RTAB-Map's default odometry variance 0.001
LOOP_INFO = np.diag([1e4, 1e4, 1e4, 1e4, 1e4, 1e4])
FALSE_FROM, FALSE_TO = 2 * LAP - 5, LAP // 2 - 5  # (0, 2) on lap 2 ↔ (4, 2) on lap 1


def _truth(k: int) -> np.ndarray:
    side, step = divmod(k % LAP, SIDE)
    corner = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)][side]
    yaw = side * np.pi / 2
    return from_xyz_yaw(corner[0] + step * 0.4 * np.cos(yaw),
                        corner[1] + step * 0.4 * np.sin(yaw), yaw)


def _graph(rng: np.random.Generator) -> tuple[dict[int, np.ndarray], list[GraphLink]]:
    """Odometry drifting a little per step (dead-reckoned initial poses), true closures of lap
    2 onto lap 1 every other node, and one false closure across the square."""
    n = 2 * LAP
    links: list[GraphLink] = []
    poses = {0: _truth(0)}
    for k in range(n - 1):
        step = se3_inverse(_truth(k)) @ _truth(k + 1)
        noisy = step @ from_xyz_yaw(*rng.normal(0.0, [0.01, 0.01, 0.01]))
        links.append(GraphLink(k, k + 1, noisy, ODOM_INFO))
        poses[k + 1] = poses[k] @ noisy
    for k in range(LAP, n, 2):
        links.append(GraphLink(k, k - LAP, se3_inverse(_truth(k)) @ _truth(k - LAP), LOOP_INFO,
                               switchable=True))
    # the false one: "this is the same place" between nodes 4 m apart
    links.append(GraphLink(FALSE_FROM, FALSE_TO, np.eye(4), LOOP_INFO, switchable=True))
    return poses, links


def _worst_error(poses: dict[int, np.ndarray]) -> float:
    return max(float(np.linalg.norm(poses[k][:2, 3] - _truth(k)[:2, 3])) for k in poses)


@pytest.mark.parametrize(("three_dof", "seed"), [(True, 4), (True, 5), (False, 6)])
def test_a_false_closure_is_switched_off_in_batch(three_dof, seed):
    poses, links = _graph(np.random.default_rng(seed))
    plain = GtsamPoseGraph(three_dof, incremental=False).optimize(poses, links, 0, 100)
    robust_graph = GtsamPoseGraph(three_dof, incremental=False, robust=True)
    robust = robust_graph.optimize(poses, links, 0, 100)
    true_only = GtsamPoseGraph(three_dof, incremental=False).optimize(poses, links[:-1], 0, 100)
    drift = max(float(np.linalg.norm(poses[k][:2, 3] - _truth(k)[:2, 3])) for k in poses)
    # dead reckoning drifts by decimetres; the true closures alone bring the map within
    # centimetres, the false one bends the plain optimum by metres; the robust optimum is the
    # true closures' (the false one switched off, the true ones kept)
    assert drift > 0.2
    assert _worst_error(true_only) < 0.1
    assert _worst_error(plain) > 1.0
    assert abs(_worst_error(robust) - _worst_error(true_only)) < 0.002
    switches = robust_graph.switches
    assert len(switches) == LAP // 2 + 1
    assert switches[(FALSE_FROM, FALSE_TO)] < 0.05
    assert min(s for pair, s in switches.items() if pair != (FALSE_FROM, FALSE_TO)) > 0.9
    # the switched-off closure is left unsatisfied: its ends stay 4 m apart
    gap = np.linalg.norm(robust[FALSE_FROM][:2, 3] - robust[FALSE_TO][:2, 3])
    assert 3.8 < gap < 4.2


@pytest.mark.parametrize("seed", [5, 7])
def test_incremental_graph_switches_off_a_false_closure_as_it_arrives(seed):
    poses, links = _graph(np.random.default_rng(seed))
    graphs = {"plain": IncrementalPose2Graph(), "robust": IncrementalPose2Graph(robust=True),
              "true only": IncrementalPose2Graph()}
    # links in the order a mapping run adds them: each node with its odometry and closures
    by_node: dict[int, list[GraphLink]] = {}
    for lk in links:
        by_node.setdefault(max(lk.from_id, lk.to_id), []).append(lk)
    given: list[GraphLink] = []
    estimate: dict[str, dict[int, np.ndarray]] = {name: {} for name in graphs}
    for k in range(1, 2 * LAP):
        given += by_node.get(k, [])
        for name, graph in graphs.items():
            known = estimate[name]
            start = {i: known.get(i, poses[i]) for i in range(k + 1)}
            if k - 1 in known:  # a new node continues from its neighbour's estimate
                start[k] = known[k - 1] @ se3_inverse(poses[k - 1]) @ poses[k]
            use = [lk for lk in given if name != "true only" or lk is not links[-1]]
            estimate[name] = graph.optimize(start, use, 0, 20)
    assert _worst_error(estimate["true only"]) < 0.15
    assert _worst_error(estimate["plain"]) > 1.0
    assert abs(_worst_error(estimate["robust"]) - _worst_error(estimate["true only"])) < 0.002


def test_optimizer_robust_is_parsed_and_turns_optimize_max_error_off():
    assert RtabmapParameters().optimizer_robust is False  # upstream's default
    params = RtabmapParameters.from_dict({"Optimizer/Robust": "true",
                                          "RGBD/OptimizeMaxError": "3"})
    assert params.optimizer_robust is True
    assert params.to_dict()["Optimizer/Robust"] == "true"
    slam = Rtabmap(params)
    assert slam.optimizer.robust and slam.optimizer.incremental is None
    assert slam._optimize_max_error == 0.0
    assert Rtabmap(RtabmapParameters.from_dict({"Reg/Force3DoF": "true",
                                               "Optimizer/Robust": "true"})
                   ).optimizer.incremental.robust
    assert Rtabmap()._optimize_max_error == 3.0


def test_only_loop_closures_are_switchable():
    eye, info = np.eye(4), np.eye(6)
    kinds = {t: Link(1, 2, t, eye, info).switchable for t in LinkType}
    assert not kinds[LinkType.NEIGHBOR] and not kinds[LinkType.NEIGHBOR_MERGED]
    assert kinds[LinkType.GLOBAL_CLOSURE] and kinds[LinkType.LOCAL_SPACE_CLOSURE]
    assert GraphLink(1, 2, eye, info).switchable is False
