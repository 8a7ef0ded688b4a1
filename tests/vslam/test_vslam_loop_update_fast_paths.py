"""The fast paths of the loop-closure update: they must give the reference numbers."""

import numpy as np
from vslam_synthetic import graph_neighbours

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter
from eddiebot.vslam.graph import (
    GraphLink,
    GtsamPoseGraph,
    IncrementalPose2Graph,
    discard_links,
    link_errors,
    optimized_link_errors,
)
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.transforms import from_xyz_rpy, from_xyz_yaw, se3_inverse

INFO = np.diag([1e3, 1e3, 1e-6, 1e-6, 1e-6, 1e3])  # z, roll, pitch ignored


def _circle_graph(n_nodes: int = 90, lap: int = 30):
    def truth(k):
        a = 2 * np.pi * (k % lap) / lap
        return from_xyz_yaw(3 * np.cos(a), 3 * np.sin(a), a + np.pi / 2)

    poses = {1: truth(0)}
    links = []
    for k in range(1, n_nodes):
        step = se3_inverse(truth(k - 1)) @ truth(k)
        step[0, 3] *= 1.03  # odometry overshoots
        links.append(GraphLink(k, k + 1, step, INFO))
        poses[k + 1] = poses[k] @ step
        if k > lap and k % 3 == 0:
            links.append(GraphLink(k + 1, k + 1 - lap, se3_inverse(truth(k)) @ truth(k - lap),
                                   INFO))
    return truth, poses, links


def test_planar_link_residuals_equal_the_general_formula():
    _, poses, links = _circle_graph()
    # a link with roll/pitch/z in its transform and uneven information still matches
    odd = GraphLink(5, 40, from_xyz_rpy(2.3, -1.2, 0.05, 0.01, -0.02, 0.4),
                    np.diag([400.0, 300.0, 1e-6, 30.0, 1e-6, 200.0]))
    links = [*links, odd]
    inc = IncrementalPose2Graph()
    out = inc.optimize(poses, links, 1, 20)
    ids, lin, ang = optimized_link_errors(inc, out, links)
    ref = {(e.from_id, e.to_id): e for e in link_errors(out, links)}
    assert len(ref) == len(lin) == len(links)
    for (a, b), x, y in zip(ids.tolist(), lin, ang):
        assert abs(ref[(a, b)].linear_ratio - x) < 1e-9
        assert abs(ref[(a, b)].angular_ratio - y) < 1e-9
    # the deliberately inconsistent link strains the graph far beyond OptimizeMaxError 3
    assert max(lin.max(), ang.max()) > 10


def test_rejected_closure_is_removed_without_a_rebuild():
    truth, poses, links = _circle_graph()
    batch = GtsamPoseGraph(True, incremental=False)
    ref = batch.optimize(poses, links, 1, 100)
    inc = GtsamPoseGraph(True)
    inc.optimize(poses, links, 1, 20)
    bad = GraphLink(90, 45, from_xyz_yaw(4.0, 0.0, 1.0), INFO)
    with_bad = inc.optimize(poses, [*links, bad], 1, 20)
    moved = max(np.linalg.norm(with_bad[i][:2, 3] - ref[i][:2, 3]) for i in ref)
    assert moved > 0.2  # the bad closure bent the graph
    _, lin, ang = optimized_link_errors(inc, with_bad, [*links, bad])
    assert max(lin.max(), ang.max()) > 3.0  # RGBD/OptimizeMaxError would reject it
    discard_links(inc, [bad])
    again = inc.optimize(poses, links, 1, 20)
    assert inc.incremental is not None
    assert inc.incremental.rebuilds == 0 and inc.incremental.removed_links == 1
    assert max(np.linalg.norm(again[i][:2, 3] - ref[i][:2, 3]) for i in ref) < 0.01
    # chain links are never removed this way (that would cut a node off): rebuild instead
    assert inc.incremental.remove_links([(10, 11)]) == 0


def _dense_reference(lc, vp_stay, prior, likelihood, neighbours, states):
    """posterior ∝ L ⊙ (P · prior) with the prediction matrix P written out."""
    n = len(states)
    index = {s: k for k, s in enumerate(states)}
    p = np.zeros((n, n))
    p[0, 0] = vp_stay
    p[1:, 0] = (1.0 - vp_stay) / (n - 1)
    for k, s in enumerate(states[1:], start=1):
        rows, vals = [s], [lc[1]]
        for j, depth in neighbours(s, len(lc) - 2).items():
            rows.append(j)
            vals.append(lc[depth + 1])
        v = np.array(vals)
        missing = sum(lc) - lc[0] - v.sum()  # missing neighbours' mass to the place (upstream)
        if missing > 1e-9:
            v[0] += missing
        v = (1.0 - lc[0]) * v / v.sum()
        p[0, k] = lc[0]
        for r, x in zip(rows, v):
            if r in index:
                p[index[r], k] += x
    post = np.array([likelihood[s] for s in states]) * (p @ prior)
    return post / post.sum()


def test_bayes_filter_matches_the_dense_prediction_matrix():
    lc = RtabmapParameters().prediction_lc()
    rng = np.random.default_rng(3)
    links: dict[int, set[int]] = {}
    wm: set[int] = set()

    def neighbours(i, depth_max):
        return graph_neighbours(links, wm, i, depth_max)

    bayes = BayesFilter(lc, 0.9)
    prior_post: dict[int, float] = {}
    checked = 0
    for k in range(1, 160):
        if k > 1:
            links.setdefault(k - 1, set()).add(k)
            links.setdefault(k, set()).add(k - 1)
        if k > 60 and rng.random() < 0.4:
            j = int(rng.integers(1, k - 20))
            links[k].add(j)
            links.setdefault(j, set()).add(k)
            bayes.invalidate([k, j])
        if k > 10:
            wm.add(k - 10)
            bayes.node_entered(k - 10, neighbours(k - 10, bayes.max_depth))
        if k > 100 and k % 7 == 0:  # a node leaves WM (memory management)
            gone = int(rng.choice(sorted(wm)))
            near = neighbours(gone, bayes.max_depth)
            wm.discard(gone)
            bayes.node_left(gone, near)
            prior_post.pop(gone, None)
        if not wm:
            continue
        like = {i: float(rng.choice([1.0, 1.0, 2.0 + 6.0 * rng.random()])) for i in wm}
        like[VIRTUAL_PLACE_ID] = 1.0 + rng.random()
        if k % 5:
            prior_post = bayes.update(like, neighbours)
            continue
        states = [VIRTUAL_PLACE_ID, *sorted(wm)]
        if prior_post:
            prior = np.array([prior_post.get(s, 0.0) for s in states])
            prior /= prior.sum()
        else:
            prior = np.eye(1, len(states), 0).ravel()
        expected = _dense_reference(lc, 0.9, prior, like, neighbours, states)
        # columns rebuilt from the graph as it is now (the cached, incrementally updated ones
        # follow new loop links only at their two ends, as in RTAB-Map)
        bayes.invalidate(wm)
        post = bayes.update(like, neighbours)
        got = np.array([post[s] for s in states])
        expected[expected < 1e-12] = 0.0
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-15)
        prior_post = post
        checked += 1
    assert checked >= 29
    assert max(post, key=post.get) != VIRTUAL_PLACE_ID or post[VIRTUAL_PLACE_ID] > 0.0
