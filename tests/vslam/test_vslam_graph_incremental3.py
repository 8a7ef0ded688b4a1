"""The Pose3 graph in iSAM2 (`GTSAM/Incremental`), fed one node and one closure per call,
stays on the Levenberg–Marquardt optimum, answers the `RGBD/OptimizeMaxError` residuals as
`link_errors` does, and rebuilds when a link it holds is taken away."""

import numpy as np

from eddiebot.vslam.graph import (
    GraphLink,
    GtsamPoseGraph,
    IncrementalPose3Graph,
    link_errors,
    optimized_link_errors,
)
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

INFO = np.diag([1e3, 1e3, 1e3, 1e2, 1e2, 1e3])


def _truth(k: int, lap: int) -> np.ndarray:
    a = 2 * np.pi * (k % lap) / lap
    t = from_xyz_yaw(4 * np.cos(a), 4 * np.sin(a), a + np.pi / 2)
    t[2, 3] = 0.2 * np.sin(a)  # up and down a ramp: a real 6DoF graph
    return t


def _run(graph, steps: int = 150, lap: int = 50):
    rng = np.random.default_rng(3)
    poses = {1: _truth(0, lap)}
    links: list[GraphLink] = []
    out: dict[int, np.ndarray] = {}
    worst = []
    for k in range(1, steps):
        step = se3_inverse(_truth(k - 1, lap)) @ _truth(k, lap)
        step[0, 3] *= 1.02  # odometry scale drift
        links.append(GraphLink(k, k + 1, step, INFO))
        poses[k + 1] = poses[k] @ step
        if k > lap:
            noise = from_xyz_yaw(*rng.normal(0.0, [0.005, 0.005, 0.002]))
            links.append(GraphLink(k + 1, k + 1 - lap, se3_inverse(_truth(k, lap))
                                   @ _truth(k - lap, lap) @ noise, INFO, switchable=True))
        out = graph.optimize(poses, links, 1, 20)
        _, lin, ang = optimized_link_errors(graph, out, links)
        worst.append(max(lin.max(initial=0.0), ang.max(initial=0.0)))
        poses.update(out)
    return poses, links, out, worst


def test_pose3_incremental_with_a_closure_every_call_matches_batch():
    graph = GtsamPoseGraph(False)
    assert isinstance(graph.incremental3, IncrementalPose3Graph)
    poses, links, out, worst = _run(graph)
    inc = graph.incremental3
    assert inc.rebuilds == 0 and inc.recoveries == 0 and inc.node_count == 150
    ref = GtsamPoseGraph(False, incremental=False).optimize_batch(poses, links, 1, 100)
    assert ref.keys() == out.keys()
    dxyz = max(float(np.linalg.norm(out[i][:3, 3] - ref[i][:3, 3])) for i in ref)
    drot = max(float(np.linalg.norm(out[i][:3, :3] - ref[i][:3, :3])) for i in ref)
    assert dxyz < 0.005 and drot < 0.003
    assert max(worst) < 1.5  # consistent closures stay far inside 3 σ


def test_pose3_incremental_residuals_are_link_errors():
    graph = GtsamPoseGraph(False)
    _, links, out, _ = _run(graph, steps=80)
    ids, lin, ang = optimized_link_errors(graph, out, links)
    ref = {(e.from_id, e.to_id): (e.linear_ratio, e.angular_ratio)
           for e in link_errors(out, links)}
    assert len(ids) == len(ref) == len(links)
    for (a, b), x, y in zip(ids.tolist(), lin.tolist(), ang.tolist()):
        assert abs(x - ref[(a, b)][0]) < 1e-6 and abs(y - ref[(a, b)][1]) < 1e-6


def test_pose3_incremental_rebuilds_without_a_removed_closure():
    graph = IncrementalPose3Graph()
    poses, links, _, _ = _run(graph, steps=80)
    wrong = GraphLink(80, 40, from_xyz_yaw(1.0, 0.0, 0.5), INFO, switchable=True)
    strained = graph.optimize(poses, [*links, wrong], 1, 20)
    _, lin, _ = graph.link_error_ratios()
    assert lin.max() > 3.0  # RGBD/OptimizeMaxError would reject it
    kept = graph.optimize(poses, links, 1, 20)  # the closure left the memory graph
    assert graph.rebuilds == 1
    ref = GtsamPoseGraph(False, incremental=False).optimize_batch(poses, links, 1, 100)
    assert max(float(np.linalg.norm(kept[i][:3, 3] - ref[i][:3, 3])) for i in ref) < 0.005
    assert max(float(np.linalg.norm(strained[i][:3, 3] - ref[i][:3, 3])) for i in ref) > 0.05
