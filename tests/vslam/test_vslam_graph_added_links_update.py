"""The graph update that hands the incremental graph only what was added (memory's link log,
`Rtabmap._optimize_added`) gives what the whole-graph call gives: the same accept/reject
decision and every optimised pose to the last bit, on a graph that grows by a node per call and
gets closures, rejected closures (removed links), replaced links, LTM transfers and
retrievals."""

from __future__ import annotations

import numpy as np
import pytest

from eddiebot.vslam.memory import Link, LinkType, Node
from eddiebot.vslam.rtabmap import ODOM_FRAME_ID_OFFSET, Rtabmap
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse


def _info(sxy: float, syaw: float) -> np.ndarray:
    return np.diag([1 / sxy**2, 1 / sxy**2, 1e-6, 1e-6, 1e-6, 1 / syaw**2])


def _run(fast: bool, sigma: float, seed: int) -> tuple[list[bool], list[dict[int, np.ndarray]], int]:
    params = {"Reg/Force3DoF": "true", "RGBD/OptimizeMaxError": "3.0",
              "RGBD/OdomHeadingSigma": str(sigma)}
    rt = Rtabmap(params)
    if not fast:
        rt._optimize_added = lambda *a, **k: None  # type: ignore[method-assign]
    mem = rt.memory
    rng = np.random.default_rng(seed)
    truth: dict[int, np.ndarray] = {}
    odom = np.eye(4)
    decisions: list[bool] = []
    snapshots: list[dict[int, np.ndarray]] = []
    prev = 0
    for i in range(1, 161):
        # a walk around a 4 m square, odometry with drift
        ang = 2 * np.pi * i / 40
        truth[i] = from_xyz_yaw(2 * np.cos(ang), 2 * np.sin(ang), ang + np.pi / 2)
        if prev:
            step = se3_inverse(truth[prev]) @ truth[i]
            noisy = step @ from_xyz_yaw(rng.normal(0, 0.01), rng.normal(0, 0.01),
                                        rng.normal(0, 0.01))
            odom = odom @ noisy
        mem.add_to_stm(Node(i, 0, i, odom.copy()))
        if prev:
            mem.add_link(Link(prev, i, LinkType.NEIGHBOR, se3_inverse(mem.nodes[prev].odom_pose)
                              @ odom, _info(0.01, 0.01)))
        if i % 23 == 0 and prev - 1 in mem.links.get(prev, {}):
            # a neighbour link already optimised replaced by a closure-type one (which the
            # odometry frames leave between the nodes: another graph link)
            lk = mem.links[prev - 1][prev]
            mem.add_link(Link(prev - 1, prev, LinkType.LOCAL_TIME_CLOSURE, lk.transform,
                              lk.information))
        closures = []
        if i > 45 and rng.random() < 0.4:
            j = int(rng.integers(1, i - 30))
            if j in mem.nodes:
                t = se3_inverse(truth[j]) @ truth[i]
                if rng.random() < 0.15:  # a wrong one: rejected by OptimizeMaxError
                    t = t @ from_xyz_yaw(0.8, -0.5, 0.6)
                closures.append(Link(j, i, LinkType.GLOBAL_CLOSURE, t, _info(0.02, 0.02)))
        for lk in closures:
            mem.add_link(lk)
        rt.optimized_poses[i] = rt.map_to_odom @ odom
        ok = rt._optimize(i, closures)
        if not ok:
            for lk in closures:
                mem.remove_link(lk.from_id, lk.to_id)
            rt.optimized_poses[i] = rt.map_to_odom @ odom
        rt.map_to_odom = rt.optimized_poses[i] @ se3_inverse(odom)
        decisions.append(ok)
        snapshots.append({k: v.copy() for k, v in rt.optimized_poses.items()})
        if i % 37 == 0 and i - 20 in mem.nodes:  # a transfer to LTM and its retrieval
            mem.transfer_to_ltm(i - 20)
            mem.retrieve(i - 20)
        prev = i
    assert all(k < ODOM_FRAME_ID_OFFSET for k in rt.optimized_poses)
    inner = rt._incremental()
    assert inner is not None
    return decisions, snapshots, inner.rebuilds


@pytest.mark.parametrize("sigma", [0.0314, 0.0])
def test_added_only_update_equals_whole_graph_update(sigma, monkeypatch):
    calls = {"n": 0}
    original = Rtabmap._optimize_added

    def counted(self, *args):
        out = original(self, *args)
        calls["n"] += out is not None
        return out

    monkeypatch.setattr(Rtabmap, "_optimize_added", counted)
    fast = _run(True, sigma, 3)
    slow = _run(False, sigma, 3)
    assert fast[0] == slow[0]
    assert sum(fast[0]) >= 140 and 3 <= fast[0].count(False) <= 15  # rejections happened
    assert len(fast[1]) == len(slow[1]) == 160
    for a, b in zip(fast[1], slow[1]):
        assert a.keys() == b.keys()
        for k in a:
            assert np.array_equal(a[k], b[k]), k
    assert fast[2] == slow[2] >= 3  # rebuilds after each rejection, as before
    assert calls["n"] >= 120  # most updates took the added-only path


def test_path_cost_in_scalars_equals_the_matrix_trace():
    from eddiebot.vslam import closure_check

    rng = np.random.default_rng(5)
    for _ in range(300):
        d = rng.choice([1e-14, 0.0, 1e-3, 1.0, 37.5, 1e6], 6) * rng.uniform(0.5, 2.0, 6)
        info = np.diag(d)
        c = closure_check._link_covariance_xyt(info)
        want = 0.25 + float(c[0, 0] + c[1, 1] + c[2, 2])
        got = 0.25 + (1.0 / max(float(info[0, 0]), 1e-12) + 1.0 / max(float(info[1, 1]), 1e-12)
                      + 1.0 / max(float(info[5, 5]), 1e-12))
        assert got == want
    # and the path search over a small graph with a cheaper detour
    links: dict[int, dict[int, Link]] = {i: {} for i in range(1, 7)}

    def add(a, b, s):
        lk = Link(a, b, LinkType.NEIGHBOR, from_xyz_yaw(0.5, 0.0, 0.1), _info(s, s))
        links[a][b], links[b][a] = lk, lk.inverse()

    for a in range(1, 6):
        add(a, a + 1, 0.1)
    add(1, 6, 0.5)  # one link, but σ² 0.25 × 3 > five links of 0.01 × 3
    pose, cov = closure_check.path_covariance(links, 1, 6)
    assert abs(cov[0, 0] - 0.5**2) > 1e-6 and cov[2, 2] == pytest.approx(5 * 0.01)
