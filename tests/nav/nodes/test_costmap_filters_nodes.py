"""Costmap filters end to end: the info server's message, a keepout mask making the planner
route around a corridor, a speed mask limiting what the controller commands (percent and
m/s), a binary filter flipping as the robot drives through its zone, ``toggle_filter``
switching a keepout zone off and on, Nav2's tutorial
parameters taken without warnings, and unusable masks refused with the file named."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from navnodes_stub import room_map

from _support.nav_actions import navigate, wait_for
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.maps import OccupancyMap, save_map
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav2_msgs import ComputePathToPose, CostmapFilterInfo, SpeedLimit
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.msgs.std_msgs import Bool
from eddiebot.msgs.std_srvs import SetBool
from eddiebot.nav.cost_values import LETHAL_OBSTACLE
from eddiebot.nav.nodes._common import pose_stamped
from eddiebot.nav.nodes.costmap_filters import (
    FILTER_QOS,
    CostmapFilterInfoServer,
    MaskError,
    add_filter_masks,
    build_filter_servers,
    check_mask,
    filter_server_sections,
)
from eddiebot.nav.nodes.params_audit import audit_nav2_params

RES = 0.05


def _mask_file(tmp_path: Path, name: str, value: int, box: tuple[float, float, float, float],
               res: float = RES, origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
               mode: str = "raw") -> Path:
    """A 6 m x 6 m mask (the room's) with ``value`` in box (x0, y0, x1, y1), m; raw mode keeps
    the values exactly, trinary is what a user paints (black: keep out, white: free)."""
    n = round(6.0 / res)
    data = np.zeros((n, n), dtype=np.int8)
    x0, y0, x1, y1 = (round(v / res) for v in box)
    data[y0:y1, x0:x1] = value
    return save_map(OccupancyMap(data, res, origin, "map"), tmp_path / name, mode=mode)


def _with_filters(stack: Any, doc: dict[str, Any]) -> list[Any]:
    nodes = build_filter_servers(filter_server_sections(doc), stack.ctx)
    for n in nodes:
        stack.ex.add_node(n)
    stack.spin(1.5)
    return nodes


# --- the info server -------------------------------------------------------------------------
def test_info_server_publishes_type_base_multiplier_transient_local() -> None:
    ctx = Context(use_sim_time=True)
    try:
        server = CostmapFilterInfoServer(
            "speed_costmap_filter_info_server", context=ctx, parameter_overrides={
                "type": 2, "base": 0.1, "multiplier": 0.005,
                "filter_info_topic": "/speed_info", "mask_topic": "/speed_mask"})
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(server)
        assert server.trigger_configure() is not None and server.last_error == ""
        server.trigger_activate()
        ex.spin_for(0.5)
        # a subscriber that comes later still gets it (transient-local)
        probe = Node("probe", context=ctx)
        got: list[Any] = []
        probe.create_subscription(CostmapFilterInfo, "/speed_info", got.append, FILTER_QOS)
        ex.add_node(probe)
        ex.spin_for(0.5)
        assert len(got) == 1
        msg = got[0]
        assert (msg.type, msg.filter_mask_topic) == (2, "/speed_mask")
        assert msg.base == pytest.approx(0.1) and msg.multiplier == pytest.approx(0.005)
    finally:
        ctx.shutdown()


def test_info_server_refuses_an_unknown_type() -> None:
    ctx = Context(use_sim_time=True)
    try:
        server = CostmapFilterInfoServer(context=ctx, parameter_overrides={"type": 7})
        server.trigger_configure()
        assert server.current_state.label == "unconfigured"
        assert "costmap_filter_info_server" in server.last_error and "type" in server.last_error
        assert "3 (binary)" in server.last_error
    finally:
        ctx.shutdown()


# --- keepout ---------------------------------------------------------------------------------
def _plan(stack: Any, x: float, y: float) -> np.ndarray:
    client = ActionClient(stack.probe, ComputePathToPose, "/compute_path_to_pose")
    handle = wait_for(stack, client.send_goal_async(
        ComputePathToPose.Goal(goal=pose_stamped(x, y, 0.0, "map"))))
    res = wait_for(stack, handle.get_result_async())
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    return np.array([(p.pose.position.x, p.pose.position.y) for p in res.result.path.poses])


@pytest.mark.parametrize("keepout", [False, True])
def test_keepout_mask_blocks_a_corridor_and_the_plan_goes_around(
        make_stack: Any, nav_stub_params: Any, tmp_path: Path, keepout: bool) -> None:
    # the room's box stands at x 2.6..3.4, y 2.0..4.0; the corridor below it (y < 2) is the
    # short way from (1, 1) to (5, 1); the user's mask closes it
    doc = nav_stub_params()
    if keepout:
        mask = _mask_file(tmp_path, "keepout", 100, (2.7, 0.0, 3.3, 2.0), mode="trinary")
        assert mask.with_suffix(".pgm").is_file()
        add_filter_masks(doc, keepout=mask)
    stack = make_stack(servers=("map_server", "planner_server", "controller_server"), params=doc,
                       start=(2.0, 1.0, 0.0))
    _with_filters(stack, doc)
    path = _plan(stack, 5.0, 1.0)
    global_cm = stack.nodes["planner_server"].costmap
    m = global_cm.master
    corridor = m.data[m.world_to_map(3.0, 1.0)[1], m.world_to_map(3.0, 1.0)[0]]
    if not keepout:
        assert corridor < LETHAL_OBSTACLE
        assert path[:, 1].max() < 2.0
        return
    # every mask cell is lethal in the global costmap
    i0, j0 = m.world_to_map(2.725, 0.125)
    i1, j1 = m.world_to_map(3.275, 1.975)
    assert (m.data[j0:j1 + 1, i0:i1 + 1] == LETHAL_OBSTACLE).all()
    # the plan goes over the box instead, and never into the zone
    assert path[:, 1].max() > 4.0
    inside = (path[:, 0] > 2.7) & (path[:, 0] < 3.3) & (path[:, 1] < 2.0)
    assert not inside.any()
    # the local costmap (odom frame, odom = map - (2, 1) here) has the zone in its window:
    # map x 2.7..3.3, y 0..2 -> odom x 0.7..1.3, y -1..1
    lm = stack.nodes["controller_server"].costmap.master
    jj, ii = np.nonzero(lm.data == LETHAL_OBSTACLE)
    ox, oy = lm.origin_x + (ii + 0.5) * RES, lm.origin_y + (jj + 0.5) * RES
    zone = (ox > 0.7) & (ox < 1.3) & (oy > -1.0) & (oy < 1.0)
    assert zone.sum() >= 12 * 39  # the zone's cells inside the 3 m window (walls add others)


def test_toggle_filter_switches_the_keepout_zone_off_and_on(
        make_stack: Any, nav_stub_params: Any, tmp_path: Path) -> None:
    doc = nav_stub_params()
    add_filter_masks(doc, keepout=_mask_file(tmp_path, "keepout", 100, (2.7, 0.0, 3.3, 2.0),
                                             mode="trinary"))
    stack = make_stack(servers=("map_server", "planner_server", "controller_server"), params=doc,
                       start=(2.0, 1.0, 0.0))
    _with_filters(stack, doc)
    m = stack.nodes["planner_server"].costmap.master
    i, j = m.world_to_map(3.0, 1.0)

    def toggle(costmap: str, on: bool) -> Any:
        client = stack.probe.create_client(SetBool, f"/{costmap}/keepout_filter/toggle_filter")
        return wait_for(stack, client.call_async(SetBool.Request(data=on)))

    assert m.data[j, i] == LETHAL_OBSTACLE and _plan(stack, 5.0, 1.0)[:, 1].max() > 4.0
    res = toggle("global_costmap", False)
    assert (res.success, res.message) == (True, "Disabled")
    # the zone is gone from the global costmap at once, and the plan takes the corridor
    assert m.data[j, i] < LETHAL_OBSTACLE
    assert _plan(stack, 5.0, 1.0)[:, 1].max() < 2.0
    lm = stack.nodes["controller_server"].costmap.master

    def local_zone_lethal() -> int:
        """Lethal cells in the zone (odom = map - (2, 1)) clear of the room's walls."""
        jj, ii = np.nonzero(lm.data == LETHAL_OBSTACLE)
        ox, oy = lm.origin_x + (ii + 0.5) * RES, lm.origin_y + (jj + 0.5) * RES
        return int(((ox > 0.7) & (ox < 1.3) & (oy > -0.85) & (oy < 0.95)).sum())

    assert local_zone_lethal() == 12 * 36  # the local costmap's filter is its own
    assert toggle("local_costmap", False).message == "Disabled"
    stack.spin(0.5)
    assert local_zone_lethal() == 0
    res = toggle("global_costmap", True)
    assert (res.success, res.message) == (True, "Enabled")
    assert m.data[j, i] == LETHAL_OBSTACLE and _plan(stack, 5.0, 1.0)[:, 1].max() > 4.0


# --- speed -----------------------------------------------------------------------------------
@pytest.mark.parametrize(("info", "value", "limit"), [
    (None, 0, None),                                             # no mask: RPP's 0.4 m/s
    (None, 50, 0.2),                                             # 100 - 50 = 50 % of 0.4
    ({"type": 2, "base": 0.0, "multiplier": 0.003}, 50, 0.15),   # 0.003 * 50 = 0.15 m/s
])
def test_speed_filter_limits_the_controller(make_stack: Any, nav_stub_params: Any,
                                            tmp_path: Path, info: dict | None, value: int,
                                            limit: float | None) -> None:
    doc = nav_stub_params()
    if info is not None:
        doc["speed_costmap_filter_info_server"] = {"ros__parameters": dict(info)}
    if value:
        add_filter_masks(doc, speed=_mask_file(tmp_path, "speed", value, (0.0, 0.0, 6.0, 6.0)))
    stack = make_stack(params=doc, start=(1.0, 1.0, 0.0))
    limits: list[Any] = []
    stack.probe.create_subscription(SpeedLimit, "/speed_limit", limits.append, 10)
    _with_filters(stack, doc)
    _, res = navigate(stack, 4.5, 1.0, 0.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    top = max(v for _, v, _ in stack.robot.commands)
    if limit is None:
        assert not limits
        assert top > 0.3
        return
    assert [(m.percentage, round(m.speed_limit, 3)) for m in limits] == [
        (info is None, 50.0 if info is None else limit)]
    assert limit * 0.8 < top <= limit + 1e-3


# --- binary ----------------------------------------------------------------------------------
def test_binary_filter_flips_as_the_robot_enters_and_leaves(make_stack: Any, nav_stub_params: Any,
                                                            tmp_path: Path) -> None:
    doc = nav_stub_params()
    gc = doc["planner_server"]["ros__parameters"]["global_costmap"]
    gc["update_frequency"] = 10.0
    gc["filters"] = ["binary_filter"]
    gc["binary_filter"] = {"plugin": "nav2_costmap_2d::BinaryFilter",
                           "filter_info_topic": "/binary_costmap_filter_info",
                           "binary_state_topic": "/camera_enabled", "flip_threshold": 50.0}
    doc["binary_filter_mask_server"] = {"ros__parameters": {
        "yaml_filename": str(_mask_file(tmp_path, "binary", 100, (2.0, 0.5, 3.0, 1.5))),
        "topic_name": "/binary_filter_mask"}}
    doc["binary_costmap_filter_info_server"] = {"ros__parameters": {
        "type": 3, "filter_info_topic": "/binary_costmap_filter_info",
        "mask_topic": "/binary_filter_mask"}}
    stack = make_stack(servers=("map_server", "planner_server"), params=doc, start=(1.0, 1.0, 0.0))
    states: list[tuple[bool, float]] = []
    stack.probe.create_subscription(
        Bool, "/camera_enabled", lambda m: states.append((bool(m.data), stack.robot.pose[0])), 10)
    _with_filters(stack, doc)
    cmd = stack.probe.create_publisher(Twist, "/cmd_vel_safe", 10)
    for _ in range(70):  # 0.5 m/s for 7 s: x 1.0 -> 4.5
        t = Twist()
        t.linear.x = 0.5
        cmd.publish(t)
        stack.spin(0.1)
    flips = [(s, x) for s, x in states]
    assert [s for s, _ in flips][-2:] == [True, False]
    on, off = flips[-2][1], flips[-1][1]
    # entering at x = 2.0, leaving at x = 3.0, seen at the next 10 Hz costmap update
    assert 2.0 <= on < 2.2 and 3.0 <= off < 3.2, flips


# --- parameters ------------------------------------------------------------------------------
# navigation2_tutorials nav2_costmap_filters_demo/params/keepout_params.yaml and
# speed_params.yaml, with the costmap sections the "Navigating with Keepout Zones" and
# "Navigating with Speed Limits" tutorials add to nav2_params.yaml
TUTORIAL_KEEPOUT = """
costmap_filter_info_server:
  ros__parameters:
    use_sim_time: true
    type: 0
    filter_info_topic: "/costmap_filter_info"
    mask_topic: "/keepout_filter_mask"
    base: 0.0
    multiplier: 1.0
filter_mask_server:
  ros__parameters:
    use_sim_time: true
    frame_id: "map"
    topic_name: "/keepout_filter_mask"
    yaml_filename: "keepout_mask.yaml"
"""
TUTORIAL_SPEED = """
costmap_filter_info_server:
  ros__parameters:
    use_sim_time: true
    type: 1
    filter_info_topic: "/costmap_filter_info"
    mask_topic: "/speed_filter_mask"
    base: 100.0
    multiplier: -1.0
filter_mask_server:
  ros__parameters:
    use_sim_time: true
    frame_id: "map"
    topic_name: "/speed_filter_mask"
    yaml_filename: "speed_mask.yaml"
"""
TUTORIAL_COSTMAPS = """
global_costmap:
  global_costmap:
    ros__parameters:
      filters: ["keepout_filter", "speed_filter"]
      keepout_filter:
        plugin: "nav2_costmap_2d::KeepoutFilter"
        enabled: True
        filter_info_topic: "/costmap_filter_info"
      speed_filter:
        plugin: "nav2_costmap_2d::SpeedFilter"
        enabled: True
        filter_info_topic: "/costmap_filter_info"
        speed_limit_topic: "/speed_limit"
local_costmap:
  local_costmap:
    ros__parameters:
      filters: ["keepout_filter"]
      keepout_filter:
        plugin: "nav2_costmap_2d::KeepoutFilter"
        enabled: True
        filter_info_topic: "/costmap_filter_info"
controller_server:
  ros__parameters:
    speed_limit_topic: "/speed_limit"
"""


@pytest.mark.parametrize("servers", [TUTORIAL_KEEPOUT, TUTORIAL_SPEED])
def test_tutorial_params_load_without_warnings(tmp_path: Path, servers: str) -> None:
    doc = {**yaml.safe_load(servers), **yaml.safe_load(TUTORIAL_COSTMAPS)}
    audit = audit_nav2_params(doc)
    assert audit.warnings == ()
    # the mask file is found beside the parameters file
    kind = "keepout" if "keepout" in servers else "speed"
    _mask_file(tmp_path, f"{kind}_mask", 100, (1.0, 1.0, 2.0, 2.0))
    sections = filter_server_sections(audit.supported, base_dir=tmp_path)
    assert [(s.node_name, s.server.__name__) for s in sections] == [
        ("filter_mask_server", "FilterMaskServer"),
        ("costmap_filter_info_server", "CostmapFilterInfoServer")]
    assert sections[0].params["yaml_filename"] == str(tmp_path / f"{kind}_mask.yaml")


def test_kilted_filter_servers_start_only_with_a_mask_file() -> None:
    path = Path(__file__).resolve().parents[2] / "data" / "nav2" / "nav2_params_kilted.yaml"
    doc = yaml.safe_load(path.read_text().replace("KEEPOUT_ZONE_ENABLED", "true")
                         .replace("SPEED_ZONE_ENABLED", "true"))
    assert filter_server_sections(doc) == []  # the sample leaves yaml_filename commented out
    doc["keepout_filter_mask_server"]["ros__parameters"]["yaml_filename"] = "/masks/k.yaml"
    sections = filter_server_sections(doc)
    assert [s.node_name for s in sections] == ["keepout_filter_mask_server",
                                               "keepout_costmap_filter_info_server"]


# --- masks that cannot be used ---------------------------------------------------------------
def _checked(tmp_path: Path, nav_stub_params: Any, mask: Path, **server: Any) -> OccupancyMap:
    doc = nav_stub_params()
    add_filter_masks(doc, keepout=mask)
    section = filter_server_sections(doc)[0]
    section.params.update(server)
    return check_mask(section, doc, room_map())


def test_a_usable_mask_passes(tmp_path: Path, nav_stub_params: Any) -> None:
    mask = _checked(tmp_path, nav_stub_params, _mask_file(tmp_path, "k", 100, (1, 1, 2, 2)))
    assert mask.resolution == pytest.approx(RES)


@pytest.mark.parametrize(("make", "server", "words"), [
    (lambda p: _mask_file(p, "k", 100, (1, 1, 2, 2)), {"frame_id": "camera_link"},
     "frame_id 'camera_link' is neither"),
    (lambda p: _mask_file(p, "k", 100, (1, 1, 2, 2), origin=(50.0, 50.0, 0.0)), {},
     "does not overlap the map"),
    (lambda p: _mask_file(p, "k", 100, (1, 1, 2, 2), res=0.02), {},
     "finer than the global costmap's 0.05 m"),
    (lambda p: p / "absent.yaml", {}, "does not load"),
])
def test_an_unusable_mask_is_refused_naming_the_file(tmp_path: Path, nav_stub_params: Any,
                                                     make: Any, server: dict, words: str) -> None:
    path = make(tmp_path)
    with pytest.raises(MaskError) as exc:
        _checked(tmp_path, nav_stub_params, path, **server)
    text = str(exc.value)
    assert text.startswith(str(path.resolve())) and words in text
    assert "\n" not in text


def test_add_filter_masks_enables_a_disabled_filter(nav_stub_params: Any, tmp_path: Path) -> None:
    doc = nav_stub_params()
    gc = doc["planner_server"]["ros__parameters"]["global_costmap"]
    gc["filters"] = ["my_keepout"]
    gc["my_keepout"] = {"plugin": "nav2_costmap_2d::KeepoutFilter", "enabled": False,
                        "filter_info_topic": "old"}
    add_filter_masks(doc, keepout=tmp_path / "k.yaml")
    assert gc["filters"] == ["my_keepout"]
    assert gc["my_keepout"]["enabled"] is True
    assert gc["my_keepout"]["filter_info_topic"] == "/keepout_costmap_filter_info"
    lc = doc["controller_server"]["ros__parameters"]["local_costmap"]
    assert "keepout_filter" in lc["filters"]
    info = doc["keepout_costmap_filter_info_server"]["ros__parameters"]
    assert (info["type"], info["mask_topic"]) == (0, "/keepout_filter_mask")
    assert math.isclose(info["multiplier"], 1.0)


def test_filter_servers_from_a_launch_file(tmp_path: Path) -> None:
    from eddiebot.core.launch import build_nodes, parse_launch_file
    from eddiebot.registry import NODES

    mask = _mask_file(tmp_path, "zones", 100, (1.0, 1.0, 2.0, 2.0), mode="trinary")
    launch = tmp_path / "filters.yaml"
    launch.write_text(f"""
launch:
  - node:
      type: eddiebot.nav.filter_mask_server
      name: keepout_filter_mask_server
      param:
        - {{name: yaml_filename, value: "{mask}"}}
        - {{name: topic_name, value: /keepout_filter_mask}}
  - node:
      type: eddiebot.nav.costmap_filter_info_server
      name: keepout_costmap_filter_info_server
      param:
        - {{name: filter_info_topic, value: /keepout_costmap_filter_info}}
        - {{name: mask_topic, value: /keepout_filter_mask}}
  - node:
      type: eddiebot.core.lifecycle_manager
      name: lifecycle_manager_costmap_filters
      param:
        - {{name: node_names, value: [keepout_filter_mask_server, keepout_costmap_filter_info_server]}}
        - {{name: autostart, value: true}}
""")
    ctx = Context(use_sim_time=True)
    try:
        ex = SingleThreadedExecutor(context=ctx)
        for n in build_nodes(parse_launch_file(launch, {}), ctx, NODES):
            ex.add_node(n)
        ex.spin_for(1.0)
        probe = Node("probe", context=ctx)
        infos: list[Any] = []
        masks: list[Any] = []
        probe.create_subscription(CostmapFilterInfo, "/keepout_costmap_filter_info", infos.append,
                                  FILTER_QOS)
        probe.create_subscription(OccupancyGrid, "/keepout_filter_mask", masks.append, FILTER_QOS)
        ex.add_node(probe)
        ex.spin_for(0.5)
        assert [(i.type, i.filter_mask_topic) for i in infos] == [(0, "/keepout_filter_mask")]
        assert len(masks) == 1 and masks[0].header.frame_id == "map"
        assert int((np.asarray(masks[0].data) == 100).sum()) == 400  # 1 m x 1 m at 0.05 m
    finally:
        ctx.shutdown()
