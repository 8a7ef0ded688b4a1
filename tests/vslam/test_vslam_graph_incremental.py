"""The incremental graph, fed one node and one closure per call as at 1,000 WM nodes, stays on
the batch optimum (its relinearisation threshold trades time, not accuracy)."""

import numpy as np

from eddiebot.vslam.graph import (
    GraphLink,
    GtsamPoseGraph,
    IncrementalPose2Graph,
    optimized_link_errors,
)
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, yaw_of

INFO = np.diag([1e3, 1e3, 1e-6, 1e-6, 1e-6, 1e3])


def test_incremental_graph_with_a_closure_every_call_matches_batch():
    lap = 60
    rng = np.random.default_rng(1)

    def truth(k):
        a = 2 * np.pi * (k % lap) / lap
        return from_xyz_yaw(4 * np.cos(a), 4 * np.sin(a), a + np.pi / 2)

    poses = {1: truth(0)}
    links: list[GraphLink] = []
    inc = IncrementalPose2Graph()
    worst = []
    for k in range(1, 200):
        step = se3_inverse(truth(k - 1)) @ truth(k)
        step[0, 3] *= 1.02  # odometry scale drift
        links.append(GraphLink(k, k + 1, step, INFO))
        poses[k + 1] = poses[k] @ step
        if k > lap:  # a slightly noisy closure to the same place one lap back, every call
            noise = from_xyz_yaw(*rng.normal(0.0, [0.005, 0.005, 0.002]))
            links.append(GraphLink(k + 1, k + 1 - lap,
                                   se3_inverse(truth(k)) @ truth(k - lap) @ noise, INFO))
        out = inc.optimize(poses, links, 1, 20)
        _, lin, ang = optimized_link_errors(inc, out, links)
        worst.append(max(lin.max(initial=0.0), ang.max(initial=0.0)))
        poses.update(out)
    assert inc.rebuilds == 0 and inc.recoveries == 0
    ref = GtsamPoseGraph(True, incremental=False).optimize_batch(poses, links, 1, 100)
    dxy = max(float(np.linalg.norm(out[i][:2, 3] - ref[i][:2, 3])) for i in ref)
    dyaw = max(abs(float(np.arctan2(np.sin(yaw_of(out[i]) - yaw_of(ref[i])),
                                    np.cos(yaw_of(out[i]) - yaw_of(ref[i]))))) for i in ref)
    assert dxy < 0.005 and dyaw < 0.002
    # every consistent closure stays far inside RGBD/OptimizeMaxError (3 σ)
    assert max(worst) < 1.5
