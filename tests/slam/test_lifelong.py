"""Lifelong mapping: slam_toolbox's node scores, node removal by marginalisation, and a
second pass over the same route that does not grow the graph."""

from __future__ import annotations

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between
from eddiebot.slam import ConfigError, Scan, SlamConfig, SlamCore, load_session, save_session
from eddiebot.slam.mapper.lifelong import (
    LifelongParams,
    ScanBox,
    area_overlap_ratio,
    intersect_over_union,
    objective_score,
    reading_overlap_ratio,
    rescore,
    scan_box,
    scan_boxes,
)
from eddiebot.slam.pose_graph import EdgeKind, PoseGraph

SAMPLE = LifelongParams(  # mapper_params_lifelong.yaml
    minimum_score=0.1, iou_match=0.85, node_removal_score=0.04, overlap_score_scale=0.06,
    constraint_multiplier=0.08, nearby_penalty=0.001, candidates_scale=0.03,
)


# -- scores (upstream's formulas on constructed cases) ---------------------------------------
def test_scan_box_holds_points_and_sensor_and_centres_on_the_barycenter() -> None:
    pts = np.array([[1.0, 1.0], [3.0, 1.0], [3.0, 2.0], [1.0, 2.0]])
    box = scan_box(pts, np.array([0.0, 1.5]))
    assert (box.width, box.height) == (3.0, 1.0)
    assert (box.center_x, box.center_y) == (2.0, 1.5)
    assert box.radius == pytest.approx(0.5 * np.hypot(3.0, 1.0))
    empty = scan_box(np.zeros((0, 2)), np.array([4.0, 5.0]))
    assert (empty.area, empty.center_x, empty.center_y) == (0.0, 4.0, 5.0)


def test_intersection_over_union_and_overlap_ratios() -> None:
    a = ScanBox(4.0, 2.0, 0.0, 0.0)
    assert intersect_over_union(a, a) == pytest.approx(1.0)
    b = ScanBox(4.0, 2.0, 2.0, 0.0)  # half of a, shifted along x
    assert intersect_over_union(a, b) == pytest.approx(4.0 / 12.0)
    assert area_overlap_ratio(a, b) == pytest.approx(0.5)
    small = ScanBox(1.0, 1.0, 0.0, 0.0)  # inside a
    assert area_overlap_ratio(a, small) == pytest.approx(1.0)
    assert area_overlap_ratio(small, a) == pytest.approx(1.0 / 8.0)
    # apart in x and in y: no overlap (upstream's product of two negative extents is not)
    far = ScanBox(1.0, 1.0, 10.0, 10.0)
    assert intersect_over_union(a, far) == 0.0
    # readings strictly inside the intersection x ∈ (0, 2), y ∈ (-1, 1)
    pts = np.array([[1.0, 0.0], [1.9, 0.9], [2.5, 0.0], [0.0, 0.0], [-1.0, 0.5]])
    assert reading_overlap_ratio(a, b, pts) == pytest.approx(2.0 / 5.0)


def test_objective_score_as_upstream() -> None:
    # a close fit that no loop closure leans on goes at once
    assert objective_score(SAMPLE, iou=0.9, area_overlap=1.0, reading_overlap=1.0,
                           num_constraints=2, initial_score=1.0) == -1.0
    # with three edges it decays: overlap 0.06·min(0.8, 0.5) = 0.03, boost min(0.08, 0.03)
    s = objective_score(SAMPLE, iou=0.9, area_overlap=0.8, reading_overlap=0.5,
                        num_constraints=3, initial_score=1.0)
    assert s == pytest.approx(1.0 * 1.03 - 0.03 - 0.001)
    # two edges: no boost
    s = objective_score(SAMPLE, iou=0.5, area_overlap=0.8, reading_overlap=0.5,
                        num_constraints=2, initial_score=0.5)
    assert s == pytest.approx(0.5 - 0.03 - 0.001)
    # never above 1
    assert objective_score(SAMPLE, iou=0.5, area_overlap=1.0, reading_overlap=1.0,
                           num_constraints=40, initial_score=1.0) == pytest.approx(1.0 - 0.001)
    # a fully covered chain node reaches the sample removal score after 16 new scans
    score, n = 1.0, 0
    while score >= SAMPLE.node_removal_score:
        score = objective_score(SAMPLE, iou=0.5, area_overlap=1.0, reading_overlap=1.0,
                                num_constraints=2, initial_score=score)
        n += 1
    assert n == 16


def test_vectorised_rescore_matches_the_scalar_formulas() -> None:
    rng = np.random.default_rng(3)
    new_pts = rng.uniform([0.0, 0.0], [6.0, 4.0], (50, 2))
    new = scan_box(new_pts, np.array([3.0, 2.0]))
    counts = rng.integers(1, 40, 25)
    offsets = rng.uniform(-5.0, 5.0, (25, 2))
    pts = np.concatenate([rng.uniform([0.0, 0.0], [5.0, 3.0], (c, 2)) + o
                          for c, o in zip(counts, offsets)])
    sensors = offsets + 1.0
    edges = rng.integers(1, 6, 25)
    initial = rng.uniform(0.2, 1.0, 25)
    boxes = scan_boxes(pts, counts, sensors)
    scored, scores = rescore(SAMPLE, new, boxes, pts, counts, edges, initial)
    assert 0 < scored.sum() < 25
    ends = np.cumsum(counts)
    for k in range(25):
        own = pts[ends[k] - counts[k] : ends[k]]
        box = scan_box(own, sensors[k])
        assert np.allclose(boxes[k], [box.width, box.height, box.center_x, box.center_y])
        iou = intersect_over_union(new, box)
        assert scored[k] == (iou >= SAMPLE.minimum_score)
        expect = objective_score(
            SAMPLE, iou=iou, area_overlap=area_overlap_ratio(new, box),
            reading_overlap=reading_overlap_ratio(new, box, own),
            num_constraints=int(edges[k]), initial_score=float(initial[k]),
        )
        assert scores[k] == pytest.approx(expect, abs=1e-12)


def test_lifelong_keys_are_range_checked() -> None:
    with pytest.raises(ConfigError, match="lifelong_overlap_score_scale"):
        SlamConfig(lifelong_overlap_score_scale=1.5).validated()
    cfg = SlamConfig(lifelong_node_removal_score=0.04, lifelong_search_use_tree=True)
    assert LifelongParams.from_config(cfg).node_removal_score == 0.04
    assert LifelongParams.from_config(cfg).search_use_tree


# -- marginalisation ---------------------------------------------------------------------------
COV = np.diag([0.01, 0.01, 0.001])


def _loop_graph(optimizer: str = "levenberg_marquardt") -> tuple[PoseGraph, list[np.ndarray]]:
    """30 poses on a spiral, noisy odometry and four exact loop edges."""
    rng = np.random.default_rng(0)
    truth = [np.zeros(3)]
    for _ in range(29):
        x, y, th = truth[-1]
        truth.append(np.array([x + np.cos(th), y + np.sin(th), th + 0.2]))
    g = PoseGraph(optimizer=optimizer)
    for p in truth:
        g.add_node(p + rng.normal(0.0, 0.05, 3))
    for k in range(1, 30):
        z = se2_between(truth[k - 1], truth[k]) + rng.normal(0.0, 0.05, 3) * [1.0, 1.0, 0.1]
        g.add_edge(k - 1, k, z, COV, kind=EdgeKind.ODOMETRY)
    for a, b in ((0, 25), (3, 20), (10, 28), (5, 15)):
        g.add_edge(a, b, se2_between(truth[a], truth[b]), COV, kind=EdgeKind.SCAN_MATCH)
    g.optimize(full=True)
    return g, truth


def _after_removal(g: PoseGraph, nodes: list[int]) -> np.ndarray:
    g.marginalize(nodes)
    # a new node makes the solver run again over what is left
    g.add_node(g.pose(29))
    g.add_edge(29, 30, np.zeros(3), COV)
    g.optimize(full=True)
    return g.poses


@pytest.mark.parametrize("optimizer", ["levenberg_marquardt", "isam2"])
def test_chain_node_becomes_one_composed_edge(optimizer: str) -> None:
    g, _ = _loop_graph(optimizer)
    full = g.poses
    edges_before = len(g.edges) - len(g.removed_edges)
    poses = _after_removal(g, [7, 8])
    assert g.removed_nodes == [7, 8]
    assert g.live_nodes == 29  # 31 - 2
    assert g.neighbours(6) == {5, 9} and g.neighbours(9) == {6, 10}
    new = g.edges[-2]  # 6 → 9, composed from the two odometry chains' edges
    assert (new.i, new.j, new.kind) == (6, 9, EdgeKind.ODOMETRY)
    assert len(g.edges) - len(g.removed_edges) == edges_before - 3 + 1 + 1
    keep = [k for k in range(30) if k not in (7, 8)]
    assert np.abs(poses[keep] - full[keep]).max() < 1e-3
    # the composed covariance is at least the sum of the three steps' (it accumulates)
    assert new.covariance[0, 0] > 2.5 * COV[0, 0]


def test_marginalised_loop_nodes_keep_the_solution_within_tolerance() -> None:
    g, truth = _loop_graph()
    full = g.poses
    poses = _after_removal(g, [15, 20, 22])
    keep = [k for k in range(30) if k not in (15, 20, 22)]
    assert np.abs(poses[keep] - full[keep]).max() < 0.03
    # dropping the nodes and their edges instead (upstream) loses the loops they carried
    h, _ = _loop_graph()
    cut = PoseGraph(optimizer="levenberg_marquardt")
    for p in h.poses:
        cut.add_node(p)
    for e in h.edges:
        if not {e.i, e.j} & {15, 20}:
            cut.add_edge(e.i, e.j, e.measurement, e.covariance, kind=e.kind)
    for a, b in ((14, 16), (19, 21)):  # keep it connected with the odometry alone
        z = se2_between(truth[a], truth[b])
        cut.add_edge(a, b, z, 4 * COV, kind=EdgeKind.ODOMETRY)
    cut.optimize(full=True)
    keep = [k for k in range(30) if k not in (15, 20)]
    assert np.abs(cut.poses[keep] - full[keep]).max() > 0.03


def test_marginalise_refuses_the_anchor_and_edges_to_removed_nodes() -> None:
    g, _ = _loop_graph()
    with pytest.raises(ValueError, match="node 0"):
        g.marginalize([0])
    g.marginalize([12])
    with pytest.raises(ValueError, match="marginalised"):
        g.add_edge(11, 12, np.zeros(3), COV)
    assert g.marginalize([12]) == 0  # already gone
    assert g.neighbours(12) == set()
    assert 12 not in g.neighbours(11)


# -- a second pass over the same route -----------------------------------------------------
CONFIG = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


@pytest.mark.parametrize("use_tree", [False, True])
def test_second_pass_does_not_double_the_graph(tmp_path, use_tree: bool) -> None:
    truth = loop_path()
    odom = drifting_odometry(truth)
    first = SlamCore(CONFIG)
    for k, (p, o) in enumerate(zip(truth, odom)):
        first.process(_scan(p, k * 100_000_000), o)
    n1 = len(first.nodes)
    path = save_session(first, tmp_path / "room.eslam")
    t0 = (len(truth) + 10) * 100_000_000
    passes = {}
    for mode in ("mapping", "lifelong"):
        config = SlamConfig.from_parameters(
            {**CONFIG.to_parameters(), "mode": mode, "lifelong_search_use_tree": use_tree}
        )
        core = load_session(path, config)
        core.start_at(first.node_poses()[0])
        for k, (p, o) in enumerate(zip(truth, odom)):
            core.process(_scan(p, t0 + k * 100_000_000), o)
        core._remove_depreciated()  # the last, partial batch
        passes[mode] = core
    mapping, life = passes["mapping"], passes["lifelong"]
    assert mapping.graph.live_nodes >= 2 * n1 - 2  # every pass adds its nodes
    assert life.removed_nodes > 0.5 * n1
    assert life.graph.live_nodes < 1.5 * n1
    # the removed nodes' scans left the map, the searches and memory
    removed = life.graph.removed_nodes
    assert all(life.nodes[j].retired and life.nodes[j].scan.ranges.size == 0 for j in removed)
    assert not life.active_mask()[removed].any()
    held = sum(n.scan.ranges.nbytes for n in life.nodes)
    assert held < 0.75 * sum(n.scan.ranges.nbytes for n in mapping.nodes)
    # the second pass's own poses stay on the route
    live = [k for k in range(len(life.nodes)) if k not in set(removed)]
    assert len(live) == life.graph.live_nodes
    poses = life.node_poses()
    last = poses[-1]
    assert np.hypot(*(last[:2] - truth[-1, :2])) < 0.1
    grid = life.occupancy_map()
    from eddiebot.maps import world_to_map

    c, r = world_to_map(grid, [11.99, 5.0])  # the wall is still in the map
    assert grid.data[r - 1 : r + 2, c - 1 : c + 2].max() == 100
    # a saved session holds the live nodes and edges only, renumbered
    again = load_session(save_session(life, tmp_path / "life.eslam"), mode="lifelong")
    assert len(again.nodes) == life.graph.live_nodes
    assert len(again.graph.edges) == len(life.graph.edges) - len(life.graph.removed_edges)
    assert np.allclose(again.node_poses(), poses[live], atol=1e-9)
    # with the nodes' scores, which carry on decaying in the next session (as upstream's)
    kept = [life.lifelong_scores.get(k, 1.0) for k in live]
    assert min(kept) < 1.0
    assert [again.lifelong_scores.get(k, 1.0) for k in range(len(live))] == pytest.approx(kept)


def test_a_loaded_session_keeps_its_rejected_loops_out(tmp_path) -> None:
    """Map, save, load (the start of every lifelong run): a loop the gate rejected stays out,
    and the map comes back where it was saved."""
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(CONFIG)
    for k, (p, o) in enumerate(zip(truth, odom)):
        core.process(_scan(p, k * 100_000_000), o)
    n = len(core.nodes)
    # a false loop: the last node 3 m and 90° away from where node 5 says it is
    core.graph.add_edge(5, n - 1, np.array([3.0, 0.0, 1.57]), np.diag([1e-3, 1e-3, 1e-4]),
                        kind=EdgeKind.LOOP, robust=True)
    core.graph.optimize(full=True)
    false = len(core.graph.edges) - 1
    assert false in core.graph.rejected + core.graph.held
    saved = core.node_poses()
    again = load_session(save_session(core, tmp_path / "room.eslam"), mode="lifelong")
    assert false in again.graph.rejected
    assert np.abs(again.node_poses() - saved).max() < 0.01
