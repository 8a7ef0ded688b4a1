"""Interactive editing (slam_toolbox's toggle_interactive_mode, manual_loop_closure,
clear_changes) and set_localization_mode: the pure edit and the node's services."""

from __future__ import annotations

import json
import logging
import math
from typing import Any

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast
from test_node import START, rig_factory  # noqa: F401  (the fixture)

from eddiebot.geometry import se2_compose, se2_inverse, yaw_to_quaternion
from eddiebot.msgs.slam_toolbox import Clear, LoopClosure, ToggleInteractive
from eddiebot.msgs.std_srvs import SetBool
from eddiebot.msgs.visualization_msgs import (
    GetInteractiveMarkers,
    InteractiveMarkerControl,
    InteractiveMarkerFeedback,
    InteractiveMarkerUpdate,
)
from eddiebot.slam import Scan, SlamConfig, SlamCore
from eddiebot.slam.editing import apply_node_moves, check_node_move
from eddiebot.slam.errors import GraphEditError

CONFIG = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)


def _mapped_core() -> SlamCore:
    """The first half of a drive around the room: 20 nodes, no loop closed."""
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(CONFIG)
    for k in range(len(truth) // 2):
        scan = Scan(raycast(ROOM, truth[k], SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0,
                    k * 100_000_000)
        core.process(scan, odom[k])
    assert len(core.nodes) == 20
    return core


# -- the pure edit ---------------------------------------------------------------------------
def test_a_moved_node_lands_where_put_and_its_neighbours_follow() -> None:
    core = _mapped_core()
    before = core.node_poses().copy()
    target = before[10] + np.array([0.0, 0.5, 0.1])
    assert apply_node_moves(core, {10: target}) == 1
    after = core.node_poses()
    assert np.hypot(*(after[10, :2] - target[:2])) < 0.02
    assert abs(after[10, 2] - target[2]) < 0.01
    moved = np.hypot(*(after[:, :2] - before[:, :2]).T)
    assert moved[0] < 1e-3  # the anchor
    assert 0.3 < moved[9] < 0.5 and 0.4 < moved[11] < 0.7  # the neighbours follow
    assert moved[1] < 0.05  # far back along the chain, little changes
    # the constraint stays: a later optimisation keeps the node there
    core.graph.optimize(full=True)
    assert np.hypot(*(core.node_poses()[10, :2] - target[:2])) < 0.02


def test_a_bad_move_leaves_the_graph_untouched() -> None:
    core = _mapped_core()
    edges = len(core.graph.edges)
    before = core.node_poses().copy()
    good = before[5] + np.array([0.2, 0.0, 0.0])
    with pytest.raises(GraphEditError, match=r"node 57: no such node \(the graph has 20 nodes"):
        apply_node_moves(core, {5: good, 57: good})
    with pytest.raises(GraphEditError, match="node 0: it anchors the map frame"):
        check_node_move(core, 0, good)
    with pytest.raises(GraphEditError, match=r"node 3: pose .* is not a finite"):
        check_node_move(core, 3, (1.0, math.nan, 0.0))
    assert len(core.graph.edges) == edges
    assert np.array_equal(core.node_poses(), before)


# -- the node's services ---------------------------------------------------------------------
def _feedback(node_id: Any, x: float, y: float, turn: float = 0.0,
              event: int = InteractiveMarkerFeedback.MOUSE_UP) -> Any:
    msg = InteractiveMarkerFeedback()
    msg.header.frame_id = "map"
    msg.marker_name = str(node_id)
    msg.event_type = event
    msg.mouse_point.x, msg.mouse_point.y = x, y
    msg.mouse_point_valid = True
    q = yaw_to_quaternion(turn)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = q
    msg.pose.position.x, msg.pose.position.y = x, y
    return msg


class _Editor:
    def __init__(self, rig: Any) -> None:
        self.rig = rig
        self.pub = rig.probe.create_publisher(InteractiveMarkerFeedback, "/slam_toolbox/feedback", 10)

    def drag(self, node_id: Any, x: float, y: float, turn: float = 0.0) -> None:
        self.pub.publish(_feedback(node_id, x, y, turn))
        self.rig.ex.spin_for(0.05)


def test_drag_then_manual_loop_closure_moves_the_node(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(12)
    node = rig.node
    before = node.core.node_poses().copy()
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    assert node.editing.interactive_mode
    assert node.get_parameter("interactive_mode").value is True
    assert node.get_parameter("paused_processing").value is True
    # scans wait while the user edits: the graph does not grow
    n = len(node.core.nodes)
    rig.drive(2, t0=0)
    assert len(node.core.nodes) == n
    editor = _Editor(rig)
    target = before[6] + np.array([0.1, 0.4, 0.0])
    editor.drag(6, target[0], target[1], turn=0.05)
    assert sorted(node.editing.staged) == [6]
    assert np.allclose(node.editing.staged[6], [target[0], target[1], before[6, 2] + 0.05])
    assert np.array_equal(node.core.node_poses(), before)  # staged only
    rig.call(LoopClosure, "manual_loop_closure")
    after = node.core.node_poses()
    # the move's 0.01 m σ against the neighbours' scan-match edges: within a few centimetres
    assert np.hypot(*(after[6, :2] - target[:2])) < 0.03
    assert abs(after[6, 2] - (before[6, 2] + 0.05)) < 0.01
    assert np.hypot(*(after[5, :2] - before[5, :2])) > 0.25
    assert np.hypot(*(after[7, :2] - before[7, :2])) > 0.25
    assert node.editing.staged == {}
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    assert node.get_parameter("interactive_mode").value is False


def test_clear_changes_drops_the_staged_moves(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(8)
    before = rig.node.core.node_poses().copy()
    edges = len(rig.node.core.graph.edges)
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    editor = _Editor(rig)
    editor.drag(3, before[3, 0], before[3, 1] + 1.0)
    editor.drag(5, before[5, 0] + 0.5, before[5, 1])
    assert sorted(rig.node.editing.staged) == [3, 5]
    rig.call(Clear, "clear_changes")
    assert rig.node.editing.staged == {}
    rig.call(LoopClosure, "manual_loop_closure")  # nothing staged: nothing changes
    assert len(rig.node.core.graph.edges) == edges
    assert np.array_equal(rig.node.core.node_poses(), before)


def _positions(markers: Any) -> dict[str, tuple[float, float]]:
    return {m.name: (m.pose.position.x, m.pose.position.y) for m in markers}


def test_the_marker_server_serves_a_marker_per_node(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(12)
    node = rig.node
    updates: list[Any] = []
    rig.probe.create_subscription(InteractiveMarkerUpdate, "/slam_toolbox/update", updates.append, 100)
    # interactive mode off: the server holds nothing
    empty = rig.call(GetInteractiveMarkers, "get_interactive_markers")
    assert empty.markers == [] and empty.sequence_number == 0
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    rig.ex.spin_for(0.05)
    poses = node.core.node_poses().copy()
    n = len(poses)
    res = rig.call(GetInteractiveMarkers, "get_interactive_markers")
    assert res.sequence_number == 1
    assert [m.name for m in res.markers] == [str(i) for i in range(n)]
    got = _positions(res.markers)
    assert max(math.hypot(got[str(i)][0] - p[0], got[str(i)][1] - p[1])
               for i, p in enumerate(poses)) < 1e-9
    marker = res.markers[4]
    assert marker.header.frame_id == "map" and marker.pose.orientation.w == 1.0
    assert [c.interaction_mode for c in marker.controls] == [
        InteractiveMarkerControl.MOVE_PLANE, InteractiveMarkerControl.ROTATE_AXIS]
    assert marker.controls[0].markers[0].id == 4
    # the same set went out as update 1
    assert [u.seq_num for u in updates] == [1]
    assert updates[0].type == InteractiveMarkerUpdate.UPDATE
    assert [m.name for m in updates[0].markers] == [str(i) for i in range(n)]
    # a drag moves the marker on the server; the loop closure's update puts every marker on
    # its node's new pose
    editor = _Editor(rig)
    target = poses[6] + np.array([0.1, 0.4, 0.0])
    editor.pub.publish(_feedback(6, target[0], target[1],
                                 event=InteractiveMarkerFeedback.POSE_UPDATE))
    rig.ex.spin_for(0.05)
    drag = _positions(rig.call(GetInteractiveMarkers, "get_interactive_markers").markers)
    assert drag["6"] == pytest.approx((target[0], target[1]))
    editor.drag(6, target[0], target[1])
    rig.call(LoopClosure, "manual_loop_closure")
    rig.ex.spin_for(0.05)
    after = node.core.node_poses()
    assert [u.seq_num for u in updates] == [1, 2]
    closed = _positions(updates[-1].markers)
    assert len(closed) == n and updates[-1].erases == []
    assert max(math.hypot(closed[str(i)][0] - p[0], closed[str(i)][1] - p[1])
               for i, p in enumerate(after)) < 1e-9
    assert math.hypot(closed["6"][0] - poses[6, 0], closed["6"][1] - poses[6, 1]) > 0.35
    assert rig.call(GetInteractiveMarkers, "get_interactive_markers").sequence_number == 2
    # the map republished with the graph unchanged: no further update
    rig.ex.spin_for(node.config.map_update_interval + 0.1)
    assert [u.seq_num for u in updates] == [1, 2]
    # interactive mode off: every marker erased
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    rig.ex.spin_for(0.05)
    assert updates[-1].seq_num == 3 and updates[-1].markers == []
    assert sorted(updates[-1].erases, key=int) == [str(i) for i in range(n)]
    assert rig.call(GetInteractiveMarkers, "get_interactive_markers").markers == []


def test_clear_changes_puts_the_markers_back_on_their_nodes(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(8)
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    poses = rig.node.core.node_poses().copy()
    editor = _Editor(rig)
    editor.pub.publish(_feedback(3, poses[3, 0], poses[3, 1] + 1.0,
                                 event=InteractiveMarkerFeedback.POSE_UPDATE))
    editor.drag(3, poses[3, 0], poses[3, 1] + 1.0)
    assert _positions(rig.node.editing.markers.markers.values())["3"][1] == pytest.approx(
        poses[3, 1] + 1.0)
    seq = rig.node.editing.markers.sequence_number
    rig.call(Clear, "clear_changes")
    res = rig.call(GetInteractiveMarkers, "get_interactive_markers")
    assert res.sequence_number == seq + 1
    assert _positions(res.markers)["3"] == pytest.approx((poses[3, 0], poses[3, 1]))


def _warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


def test_refusals_name_the_reason(
    rig_factory: Any, caplog: pytest.LogCaptureFixture  # noqa: F811
) -> None:
    caplog.set_level(logging.WARNING)
    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(6)
    editor = _Editor(rig)
    poses = rig.node.core.node_poses()
    n = len(poses)
    caplog.clear()
    editor.drag(2, 1.0, 1.0)  # not in interactive mode
    assert rig.node.editing.staged == {}
    assert any("move of node 2: interactive mode is off" in w for w in _warnings(caplog))
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    caplog.clear()
    editor.drag(99, 1.0, 1.0)
    editor.drag("corner", 1.0, 1.0)
    editor.drag(0, 1.0, 1.0)
    logged = _warnings(caplog)
    assert any(f"node 99: no such node (the graph has {n} nodes" in w for w in logged)
    assert any("marker 'corner': not a node id" in w for w in logged)
    assert any("node 0: it anchors the map frame" in w for w in logged)
    assert rig.node.editing.staged == {}
    # a press or a drag in progress stages nothing; only the release does
    rig.node.editing._on_feedback(
        _feedback(2, 1.0, 1.0, event=InteractiveMarkerFeedback.POSE_UPDATE)
    )
    assert rig.node.editing.staged == {}
    caplog.clear()
    rig.call(LoopClosure, "manual_loop_closure")
    assert _warnings(caplog) == ["manual_loop_closure: no moved nodes to close loops with"]


@pytest.mark.parametrize(("params", "why"), [
    ({}, "toggle_interactive_mode: enable_interactive_mode is false; ignored"),
    ({"enable_interactive_mode": True, "mode": "lifelong"},
     "toggle_interactive_mode: interactive mode works in mapping mode only (mode is lifelong)"),
])
def test_toggle_refused_without_enable_or_outside_mapping(
    rig_factory: Any, caplog: pytest.LogCaptureFixture, params: dict, why: str  # noqa: F811
) -> None:
    caplog.set_level(logging.WARNING)
    rig = rig_factory(**params)
    caplog.clear()
    rig.call(ToggleInteractive, "toggle_interactive_mode")
    assert not rig.node.editing.interactive_mode
    assert any(w.startswith(why) for w in _warnings(caplog))


# -- set_localization_mode -------------------------------------------------------------------
def test_set_localization_mode_switches_a_mapping_node_and_back(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory()
    node = rig.node
    res = rig.call(SetBool, "set_localization_mode", data=True)
    assert not res.success
    assert res.message == "no map to localize on: the graph is empty"
    rig.drive(12)  # x 2 → 4.75
    n = len(node.core.nodes)
    res = rig.call(SetBool, "set_localization_mode", data=True)
    assert res.success, res.message
    assert node.config.mode == "localization" and node.core.mode == "localization"
    names = {s.service_name for s in node.services}
    assert "/slam_toolbox/clear_localization_buffer" in names
    # driving back over the map localises without adding nodes
    for k in range(6):
        truth = START + np.array([2.5 - 0.3 * k, 0.0, 0.0])
        rig.publish(rig.now, truth, truth.copy())
        rig.ex.spin_for(0.5)
        assert np.hypot(*(rig.robot_in_map()[:2] - truth[:2])) < 0.05
    assert len(node.core.nodes) == n
    res = rig.call(SetBool, "set_localization_mode", data=True)
    assert res.success and res.message == "already in localization mode"
    res = rig.call(SetBool, "set_localization_mode", data=False)
    assert res.success, res.message
    assert node.config.mode == "mapping"
    names = {s.service_name for s in node.services}
    assert "/slam_toolbox/clear_localization_buffer" not in names
    # mapping again: new scans extend the graph, tied to the nodes near the robot
    for k in range(4):
        truth = START + np.array([1.0 - 0.3 * k, 0.3, 0.0])
        rig.publish(rig.now, truth, truth.copy())
        rig.ex.spin_for(0.5)
    assert len(node.core.nodes) == n + 4
    new = node.core.node_poses()[n:]
    expected = START + np.array([[1.0 - 0.3 * k, 0.3, 0.0] for k in range(4)])
    assert np.hypot(*(new[:, :2] - expected[:, :2]).T).max() < 0.05
    # the first new node is tied to a node near it, not by odometry to the last node mapped
    (link,) = [e.i for e in node.core.graph.edges if e.j == n and e.i < n]
    assert link < n - 3


def test_set_localization_mode_cannot_leave_a_localization_launch(rig_factory: Any) -> None:  # noqa: F811
    rig = rig_factory(mode="localization")
    res = rig.call(SetBool, "set_localization_mode", data=False)
    assert not res.success
    assert "launched in localization mode" in res.message


# -- from the dashboard ----------------------------------------------------------------------
def test_the_dashboard_edits_a_running_slam_node(rig_factory: Any) -> None:  # noqa: F811
    """The dashboard's slam commands through the bus to the node: interactive mode, a node
    dragged in the display frame, close loop; its graph frame lists the nodes by id."""
    from eddiebot.viz.dashboard.hub import Hub
    from eddiebot.viz.dashboard.node import DashboardNode

    rig = rig_factory(enable_interactive_mode=True)
    rig.drive(12)
    dash = DashboardNode(Hub(), context=rig.ctx)
    rig.ex.add_node(dash)
    answers: list[tuple[bool, str]] = []
    try:
        node = rig.node
        node.mark_map_dirty()
        rig.ex.spin_for(node.config.map_update_interval + 0.5)
        frame = json.loads(dash._slam_graph_frame(dash._slam_graph[1]))
        poses = node.core.node_poses()
        assert frame["count"] == len(poses)
        assert np.allclose(np.reshape(frame["nodes"], (-1, 2)), poses[:, :2], atol=2e-3)
        dash.slam_command("interactive", lambda ok, text: answers.append((ok, text)))
        rig.ex.spin_for(0.1)
        assert answers[-1][0] and node.editing.interactive_mode
        before = node.core.node_poses().copy()
        target = before[6, :2] + np.array([0.0, 0.3])
        # the display frame is odom; the map frame sits on it as map → odom says
        shown = se2_compose(se2_inverse(node.core.map_to_odom), np.array([*target, 0.0]))
        dash.slam_command("move", lambda ok, text: answers.append((ok, text)),
                          node=6, x=float(shown[0]), y=float(shown[1]))
        rig.ex.spin_for(0.1)
        assert answers[-1][0], answers[-1][1]
        assert np.allclose(node.editing.staged[6][:2], target, atol=1e-6)
        dash.slam_command("close_loop", lambda ok, text: answers.append((ok, text)))
        rig.ex.spin_for(0.1)
        assert np.hypot(*(node.core.node_poses()[6, :2] - target)) < 0.02
    finally:
        dash.destroy_node()
