"""Merging a second session (slam_toolbox's add_submap / merge_submaps): placement by scan
matching or by hand, the merged graph against the truth, refusals; and the node's services."""

from __future__ import annotations

import logging
import pickle
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from slam_world import CORRIDOR, ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast
from test_node import MOUNT, _map_odom_count, rig_factory  # noqa: F401  (the fixture)

from eddiebot.geometry import se2_compose, se2_inverse
from eddiebot.msgs.slam_toolbox import AddSubmap, MergeMaps, SerializePoseGraph
from eddiebot.msgs.visualization_msgs import InteractiveMarkerFeedback
from eddiebot.slam import Scan, SlamConfig, SlamCore, load_session, save_session
from eddiebot.slam.errors import MergeError
from eddiebot.slam.merge import (
    map_snapshot,
    merge_session,
    place_copy,
    place_session,
    rebase_placement,
)
from eddiebot.slam.node_editing import _load_and_place
from eddiebot.slam.placement_process import PlacementProcess

CONFIG = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)
#: the second session's map frame in the first one's (where its odometry started)
SECOND_FRAME = np.array([-3.0, 2.0, 0.7])


def _scan(world: np.ndarray, pose: np.ndarray, stamp: int) -> Scan:
    return Scan(raycast(world, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp)


def _halves() -> tuple[SlamCore, SlamCore, np.ndarray, np.ndarray]:
    """One drive around the room mapped as two sessions: the first half, and the second half
    with its odometry in another frame. Returns both, the truth, and the second session's
    map frame in the first's (its first pose is where its odometry put it)."""
    truth = loop_path()
    odom = drifting_odometry(truth)
    half = len(truth) // 2
    first = SlamCore(CONFIG)
    for k in range(half):
        first.process(_scan(ROOM, truth[k], k * 100_000_000), odom[k])
    second = SlamCore(CONFIG)
    to_second = se2_inverse(SECOND_FRAME)
    for k in range(half, len(truth)):
        second.process(_scan(ROOM, truth[k], k * 100_000_000), se2_compose(to_second, odom[k]))
    expected = se2_compose(truth[half], se2_inverse(se2_compose(to_second, odom[half])))
    return first, second, truth, expected


def _truth_of(core: SlamCore, truth: np.ndarray) -> np.ndarray:
    return truth[[n.scan.stamp_ns // 100_000_000 for n in core.nodes]]


@pytest.fixture(scope="module")
def halves(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    """Both halves saved as sessions."""
    first, second, truth, expected = _halves()
    folder = tmp_path_factory.mktemp("halves")
    return (save_session(first, folder / "first.eslam"),
            save_session(second, folder / "second.eslam"), truth, expected)


def test_a_second_session_of_the_same_place_is_placed_by_scan_matching(halves: Any) -> None:
    first_path, second_path, truth, expected = halves
    core = load_session(first_path, CONFIG)
    other = load_session(second_path, CONFIG)
    placement = place_session(core, other)
    assert placement.by_scan_matching
    assert placement.relocalized == 3  # the search stops at three that agree
    assert len(placement.links) >= 6
    assert np.hypot(*(placement.transform[:2] - expected[:2])) < 0.03
    assert abs(placement.transform[2] - expected[2]) < 0.005
    n, m = len(core.nodes), len(other.nodes)
    ids = merge_session(core, other, placement)
    assert list(ids) == list(range(n, n + m))
    err = np.hypot(*(core.node_poses()[:, :2] - _truth_of(core, truth)[:, :2]).T)
    assert err.max() < 0.03  # both halves line up in one frame
    # the merged map is one room: its walls where the room's are
    grid = core.occupancy_map()
    assert grid.width * grid.resolution == pytest.approx(12.0 + 2 * grid.resolution, abs=0.5)


def test_a_rough_hand_placement_is_refined_by_the_links(halves: Any) -> None:
    first_path, second_path, truth, expected = halves
    core = load_session(first_path, CONFIG)
    other = load_session(second_path, CONFIG)
    rough = expected + np.array([0.4, -0.3, 0.06])
    placement = place_session(core, other, transform=rough)
    assert not placement.by_scan_matching
    assert len(placement.links) >= 6
    assert np.hypot(*(placement.transform[:2] - expected[:2])) < 0.03
    merge_session(core, other, placement)
    err = np.hypot(*(core.node_poses()[:, :2] - _truth_of(core, truth)[:, :2]).T)
    assert err.max() < 0.03


def test_another_place_is_not_merged(halves: Any) -> None:
    first_path, _, _, _ = halves
    core = load_session(first_path, CONFIG)
    corridor = SlamCore(CONFIG)
    for k in range(12):
        pose = np.array([2.0 + 0.6 * k, 1.0, 0.0])
        corridor.process(_scan(CORRIDOR, pose, k * 100_000_000), pose)
    with pytest.raises(MergeError, match="12 sampled nodes of the session relocalised"):
        place_session(core, corridor)


def test_refusals_name_the_reason(halves: Any) -> None:
    first_path, second_path, _, _ = halves
    core = load_session(first_path, CONFIG)
    other = load_session(second_path, CONFIG)
    with pytest.raises(MergeError, match="the current graph is empty"):
        place_session(SlamCore(CONFIG), other)
    with pytest.raises(MergeError, match="the session to merge holds no nodes"):
        place_session(core, SlamCore(CONFIG))
    moved = load_session(second_path, CONFIG)
    moved.sensor_offset = np.array([0.2, 0.0, 0.0])
    with pytest.raises(MergeError, match=r"laser was mounted at \(0.200, 0.000, 0.000\)"):
        place_session(core, moved)
    with pytest.raises(MergeError, match=r"placement .* is not a finite"):
        place_session(core, other, transform=(0.0, np.inf, 0.0))


def test_a_placement_found_on_a_snapshot_follows_its_anchors(halves: Any) -> None:
    first_path, second_path, truth, expected = halves
    core = load_session(first_path, CONFIG)
    other = load_session(second_path, CONFIG)
    snapshot = map_snapshot(core)
    copy = pickle.loads(pickle.dumps(snapshot))  # sent to the placement process
    assert len(copy.nodes) == len(core.nodes) and copy.core().graph.edges == []
    assert np.array_equal(copy.core().graph.poses, core.node_poses())
    searched = copy.poses.copy()
    placement = place_copy(copy, map_snapshot(other))
    assert np.hypot(*(placement.transform[:2] - expected[:2])) < 0.03
    # meanwhile the live map moved as a whole (as after a loop closure far away): the links,
    # kept relative to their anchor nodes, move with it
    shift = np.array([0.5, -0.2, 0.1])
    core.graph.set_poses(se2_compose(np.broadcast_to(shift, searched.shape), searched))
    moved = rebase_placement(placement, other, searched, core)
    assert len(moved.links) == len(placement.links)
    assert np.allclose(moved.transform, se2_compose(shift, placement.transform), atol=1e-6)
    # a retired anchor's link is dropped
    gone = moved.links[0].anchor
    core.nodes[gone].retired = True
    fewer = rebase_placement(placement, other, searched, core)
    assert all(lk.anchor != gone for lk in fewer.links)
    assert len(fewer.links) == len(placement.links) - sum(
        lk.anchor == gone for lk in placement.links)


def test_a_session_is_placed_in_a_process_of_its_own(halves: Any) -> None:
    first_path, second_path, _, expected = halves
    core = load_session(first_path, CONFIG)
    poses = core.node_poses().copy()
    placer = PlacementProcess()
    placed = _load_and_place(str(second_path), map_snapshot(core), placer.run)
    assert placed.placement is not None and placed.unplaced == ""
    assert np.hypot(*(placed.placement.transform[:2] - expected[:2])) < 0.03
    assert len(placed.placement.links) >= 6
    assert np.array_equal(core.node_poses(), poses)
    assert core._global is None and core.relocalizations == []
    # a refusal comes back as the MergeError the search raised
    empty = map_snapshot(SlamCore(CONFIG))
    with pytest.raises(MergeError, match="the current graph is empty"):
        _load_and_place(str(second_path), empty, placer.run)


# -- the node's services ---------------------------------------------------------------------
def _spin_until(rig: Any, done: Any, wall_s: float = 120.0) -> None:
    """Spin the rig until ``done()``; the bound only stops a broken run from hanging."""
    stop = time.monotonic() + wall_s
    while not done():
        assert time.monotonic() < stop, "no answer"
        rig.ex.spin_once(timeout_sec=0.01)


def _add_submap(rig: Any, path: Path) -> list[Any]:
    """Call ~/add_submap as a client does; returns the answers (filled once it answers)."""
    (service,) = [s for s in rig.node.services if s.service_name == "/slam_toolbox/add_submap"]
    answers: list[Any] = []
    service.handle_async(AddSubmap.Request(filename=str(path)), lambda r, e: answers.append((r, e)))
    return answers


def _added(rig: Any, path: Path) -> None:
    answers = _add_submap(rig, path)
    _spin_until(rig, lambda: answers)
    assert answers[0][1] is None


def _map_room(rig: Any, xs: Any, y: float, odom_frame: np.ndarray | None = None) -> None:
    """Drive along ``y`` through ``xs``; the odometry is exact, in ``odom_frame`` (its origin
    in the room; the room's own frame by default)."""
    to_odom = se2_inverse(odom_frame) if odom_frame is not None else np.zeros(3)
    for x in xs:
        truth = np.array([x, y, 0.0])
        rig.publish(rig.now, truth, se2_compose(to_odom, truth))
        rig.ex.spin_for(0.5)


def test_add_submap_and_merge_submaps(
    rig_factory: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture  # noqa: F811
) -> None:
    # a session driven along y = 5.5 from x = 7 to 10, its odometry in another frame, saved
    other = rig_factory()
    _map_room(other, np.arange(7.0, 10.01, 0.25), 5.5, odom_frame=SECOND_FRAME)
    path = tmp_path / "other.eslam"
    other.call(SerializePoseGraph, "serialize_map", filename=str(path))
    m = len(other.node.core.nodes)
    # the running map: along y = 4 from x = 2 to 6
    rig = rig_factory()
    rig.drive(17)
    n = len(rig.node.core.nodes)
    caplog.set_level(logging.INFO)
    _added(rig, path)
    (sub,) = rig.node.editing.submaps
    assert sub.placement is not None
    # the other session's map frame is its odometry's
    assert np.hypot(*(sub.transform[:2] - SECOND_FRAME[:2])) < 0.05
    assert abs(sub.transform[2] - SECOND_FRAME[2]) < 0.01
    rig.call(MergeMaps, "merge_submaps")
    assert rig.node.editing.submaps == []
    poses = rig.node.core.node_poses()
    assert len(poses) == n + m
    assert np.abs(poses[n:, 1] - 5.5).max() < 0.05
    assert np.abs(poses[n:, 0] - np.linspace(7.0, 10.0, m)).max() < 0.05
    rig.ex.spin_for(rig.node.config.map_update_interval + 0.1)
    assert rig.node.map_pub.sequence >= 1
    # the next live scan still maps, tied to the nodes near it
    _map_room(rig, [6.3], 4.0)
    assert len(rig.node.core.nodes) == n + m + 1
    assert np.hypot(*(rig.node.core.node_poses()[-1, :2] - [6.3, 4.0])) < 0.05
    assert any("merged " in r.getMessage() for r in caplog.records)


def _other_session(rig_factory: Any, tmp_path: Path) -> tuple[Path, int]:  # noqa: F811
    """A session driven along y = 5.5 from x = 7 to 10, its odometry in another frame."""
    other = rig_factory()
    _map_room(other, np.arange(7.0, 10.01, 0.25), 5.5, odom_frame=SECOND_FRAME)
    path = tmp_path / "other.eslam"
    other.call(SerializePoseGraph, "serialize_map", filename=str(path))
    return path, len(other.node.core.nodes)


def test_scans_are_processed_while_a_submap_is_placed(
    rig_factory: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch  # noqa: F811
) -> None:
    path, m = _other_session(rig_factory, tmp_path)
    rig = rig_factory()
    rig.drive(17)  # along y = 4 from x = 2 to 6
    n = len(rig.node.core.nodes)
    # the placement is held (then run in its process) until the robot has driven on: however
    # fast the machine, the scans below arrive while it is pending
    started, release = threading.Event(), threading.Event()
    searched_on: list[str] = []
    real_place = rig.node.editing.place_copies  # the placement process

    def held(map_copy: Any, session: Any) -> Any:
        searched_on.append(threading.current_thread().name)
        started.set()
        assert release.wait(120)
        return real_place(map_copy, session)

    monkeypatch.setattr(rig.node.editing, "place_copies", held)
    answers = _add_submap(rig, path)
    _spin_until(rig, started.is_set)
    tf_before, processed = _map_odom_count(rig), rig.node.scans_processed
    _map_room(rig, np.arange(6.25, 7.51, 0.25), 4.0)  # 3 s of driving, 6 scans
    assert not answers and rig.node.editing.submaps == []
    assert rig.node.scans_processed == processed + 6
    assert len(rig.node.core.nodes) == n + 6
    # map → odom kept publishing every transform_publish_period (0.05 s) of those 3 s
    assert _map_odom_count(rig) - tf_before >= 59
    release.set()
    _spin_until(rig, lambda: answers)
    assert answers[0][1] is None
    assert searched_on == ["slam-add-submap"]
    (sub,) = rig.node.editing.submaps
    assert np.hypot(*(sub.transform[:2] - SECOND_FRAME[:2])) < 0.05
    # merged into the graph as it is now, the six nodes added meanwhile included
    rig.call(MergeMaps, "merge_submaps")
    poses = rig.node.core.node_poses()
    assert len(poses) == n + 6 + m
    assert np.abs(poses[n : n + 6, 0] - np.arange(6.25, 7.51, 0.25)).max() < 0.05
    assert np.abs(poses[n + 6 :, 1] - 5.5).max() < 0.05
    assert np.abs(poses[n + 6 :, 0] - np.linspace(7.0, 10.0, m)).max() < 0.05


def test_merge_submaps_leaves_a_submap_still_being_placed(
    rig_factory: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,  # noqa: F811
    caplog: pytest.LogCaptureFixture,
) -> None:
    path, m = _other_session(rig_factory, tmp_path)
    rig = rig_factory()
    rig.drive(17)
    n = len(rig.node.core.nodes)
    started, release = threading.Event(), threading.Event()
    real_place = rig.node.editing.place_copies

    def held(map_copy: Any, session: Any) -> Any:
        started.set()
        assert release.wait(120)
        return real_place(map_copy, session)

    monkeypatch.setattr(rig.node.editing, "place_copies", held)
    answers = _add_submap(rig, path)
    _spin_until(rig, started.is_set)
    caplog.set_level(logging.WARNING)
    rig.call(MergeMaps, "merge_submaps")
    assert len(rig.node.core.nodes) == n
    assert any("1 submaps are still being placed" in r.getMessage() for r in caplog.records)
    release.set()
    _spin_until(rig, lambda: answers)
    rig.call(MergeMaps, "merge_submaps")
    assert len(rig.node.core.nodes) == n + m


def test_a_submap_placed_by_hand(
    rig_factory: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture  # noqa: F811
) -> None:
    rig = rig_factory()
    rig.drive(5)
    n = len(rig.node.core.nodes)
    # a corridor mapped with the same laser mount: nothing in the room matches it
    corridor = SlamCore(CONFIG, sensor_offset=MOUNT)
    for k in range(12):
        pose = np.array([2.0 + 0.6 * k, 1.0, 0.0])
        corridor.process(_scan(CORRIDOR, se2_compose(pose, MOUNT), k * 100_000_000), pose)
    path = save_session(corridor, tmp_path / "corridor.eslam")
    caplog.set_level(logging.WARNING)
    _added(rig, path)
    assert len(rig.node.editing.submaps) == 1
    assert any("it waits at its own origin" in r.getMessage() for r in caplog.records)
    pub = rig.probe.create_publisher(InteractiveMarkerFeedback, "/merge_maps_tool/feedback", 10)
    msg = InteractiveMarkerFeedback()
    msg.marker_name = "1"
    msg.event_type = InteractiveMarkerFeedback.MOUSE_UP
    msg.pose.position.x, msg.pose.position.y = 20.0, 30.0
    msg.pose.orientation.w = 1.0
    pub.publish(msg)
    rig.ex.spin_for(0.05)
    sub = rig.node.editing.submaps[0]
    assert sub.placement is None
    assert np.allclose(sub.transform, [20.0, 30.0, 0.0])
    m = len(sub.core.nodes)
    first = sub.core.node_poses()[0].copy()
    rig.call(MergeMaps, "merge_submaps")
    poses = rig.node.core.node_poses()
    assert len(poses) == n + m
    # nothing of this map near it: placed where the user put it
    assert np.hypot(*(poses[n, :2] - (first[:2] + np.array([20.0, 30.0])))) < 0.05


def test_add_submap_refuses_a_bad_file(
    rig_factory: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture  # noqa: F811
) -> None:
    rig = rig_factory()
    rig.drive(3)
    bad = tmp_path / "notes.txt"
    bad.write_text("not a session")
    caplog.set_level(logging.ERROR)
    _added(rig, bad)
    _added(rig, tmp_path / "missing.eslam")
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 2
    assert f"add_submap: {bad}: not a readable SLAM session" in errors[0]
    assert errors[0].endswith("; not added")
    assert "no such session file" in errors[1]
    assert rig.node.editing.submaps == []




def test_nodes_marginalised_out_stay_behind(halves: Any) -> None:
    first_path, second_path, truth, _ = halves
    core = load_session(first_path, CONFIG)
    other = load_session(second_path, CONFIG)
    # as lifelong mode removes a node: retired, and marginalised out of the graph
    other.nodes[7].retired = True
    other.graph.marginalize([7])
    n, m = len(core.nodes), len(other.nodes)
    ids = merge_session(core, other, place_session(core, other))
    assert len(ids) == m - 1 and len(core.nodes) == n + m - 1
    stamps = {node.scan.stamp_ns for node in core.nodes}
    assert other.nodes[7].scan.stamp_ns not in stamps
    err = np.hypot(*(core.node_poses()[:, :2] - _truth_of(core, truth)[:, :2]).T)
    assert err.max() < 0.03
