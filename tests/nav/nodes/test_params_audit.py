"""Upstream Nav2 sample parameter files (Jazzy, Kilted) drop in: every section and key is
honoured or named once, and a plugin that cannot be configured stops the bring-up."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from navnodes_stub import room_map

from eddiebot.core import Context, SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.maps import save_map
from eddiebot.nav.config import load_nav2_config
from eddiebot.nav.controllers import DWBController, RegulatedPurePursuitController
from eddiebot.nav.errors import UnsupportedPlugin
from eddiebot.nav.nodes._common import NavServer, nest_nav2_params
from eddiebot.nav.nodes.params_audit import audit_nav2_params
from eddiebot.registry import NODES

DATA = Path(__file__).resolve().parents[2] / "data" / "nav2"
RPP = "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController"
GRACEFUL = "nav2_graceful_controller::GracefulController"


def upstream(distro: str, follow_path: str | None = None) -> dict[str, Any]:
    text = (DATA / f"nav2_params_{distro}.yaml").read_text()
    # Kilted's file holds placeholders its bring-up launch rewrites (filters off by default)
    text = text.replace("KEEPOUT_ZONE_ENABLED", "false").replace("SPEED_ZONE_ENABLED", "false")
    doc = yaml.safe_load(text)
    if follow_path is not None:
        doc["controller_server"]["ros__parameters"]["FollowPath"] = {"plugin": follow_path}
    return doc


@pytest.mark.parametrize("distro", ["jazzy", "kilted"])
def test_unloadable_controller_is_named(distro: str) -> None:
    doc = upstream(distro, GRACEFUL)
    with pytest.raises(UnsupportedPlugin) as exc:
        audit_nav2_params(doc)
    e = exc.value
    assert (e.server, e.key, e.plugin) == ("controller_server", "FollowPath.plugin", GRACEFUL)
    assert GRACEFUL in str(e) and "FollowPath.plugin" in str(e)
    with pytest.raises(UnsupportedPlugin) as exc2:
        load_nav2_config(doc)
    assert exc2.value.plugin == GRACEFUL


def test_jazzy_warnings_name_each_entry_once() -> None:
    audit = audit_nav2_params(upstream("jazzy", RPP))
    w = audit.warnings
    assert len(w) == len(set(w)) == 15
    for section in ("route_server", "docking_server", "loopback_simulator"):
        assert f"not supported: {section} (whole section)" in w
        assert section not in audit.supported
    assert "ignored: local_costmap.voxel_layer.z_voxels" in w
    assert not [x for x in w if "bt_navigator" in x]  # every BT key is honoured
    # honoured keys are kept, ignored ones are gone from what the servers get
    local = audit.supported["local_costmap"]["local_costmap"]["ros__parameters"]
    assert "z_voxels" not in local["voxel_layer"]
    assert local["voxel_layer"]["observation_sources"] == "scan"
    assert audit.supported["amcl"]["ros__parameters"] == upstream("jazzy")["amcl"]["ros__parameters"]


def test_kilted_warnings() -> None:
    w = audit_nav2_params(upstream("kilted", "dwb_core::DWBLocalPlanner")).warnings
    assert len(w) == len(set(w)) == 26
    assert "ignored: bt_navigator.error_code_name_prefixes" not in w
    for section in ("route_server", "docking_server", "loopback_simulator"):
        assert f"not supported: {section} (whole section)" in w
    # the costmap filters and their servers are honoured (tests/nav/test_costmap_filters.py)
    assert not [x for x in w if "filter" in x]
    for beh in ("backup", "drive_on_heading"):  # Kilted's ramp limits are honoured
        for key in ("acceleration_limit", "deceleration_limit", "minimum_speed"):
            assert f"ignored: behavior_server.{beh}.{key}" not in w


def test_unknown_key_in_a_plugin_is_named() -> None:
    doc = upstream("jazzy", RPP)
    doc["controller_server"]["ros__parameters"]["FollowPath"]["foo"] = 1.0
    doc["controller_server"]["ros__parameters"]["FollowPath"]["desired_linear_vel"] = 0.3
    audit = audit_nav2_params(doc)
    assert audit.warnings.count("ignored: controller_server.FollowPath.foo") == 1
    follow = audit.supported["controller_server"]["ros__parameters"]["FollowPath"]
    assert follow == {"plugin": RPP, "desired_linear_vel": 0.3}


@pytest.mark.parametrize(("distro", "plugin", "cls"), [
    ("jazzy", RPP, RegulatedPurePursuitController),
    ("kilted", "dwb_core::DWBLocalPlanner", DWBController),
])
def test_variant_builds_every_core(distro: str, plugin: str, cls: type) -> None:
    c = load_nav2_config(audit_nav2_params(upstream(distro, plugin)).supported)
    assert isinstance(c.controller_server.controller("FollowPath"), cls)
    assert c.local_costmap is not None and c.local_costmap.rolling_window
    assert c.global_costmap is not None and set(c.planners) == {"GridBased"}
    assert set(c.behaviors) >= {"spin", "backup", "drive_on_heading", "wait"}
    assert c.collision_monitor is not None and c.velocity_smoother is not None


def _launch(tmp_path: Path, doc: dict[str, Any]) -> tuple[Context, list[Any]]:
    map_yaml = save_map(room_map(), tmp_path / "room")
    params = tmp_path / "nav2_params.yaml"
    params.write_text(yaml.safe_dump(nest_nav2_params(doc)))
    ctx = Context(use_sim_time=True)
    desc = parse_launch_file(find_launch_file("nav"), {
        "map": str(map_yaml), "params_file": str(params), "use_sim_time": "true"})
    nodes = build_nodes(desc, ctx, NODES)
    ex = SingleThreadedExecutor(context=ctx)
    for n in nodes:
        ex.add_node(n)
    ex.spin_for(1.0)
    return ctx, nodes


def test_jazzy_rpp_variant_brings_up_every_server(tmp_path: Path) -> None:
    ctx, nodes = _launch(tmp_path, audit_nav2_params(upstream("jazzy", RPP)).supported)
    try:
        servers = {n.get_name(): n for n in nodes if isinstance(n, NavServer)}
        assert {"amcl", "map_server", "planner_server", "controller_server", "smoother_server",
                "behavior_server", "bt_navigator", "waypoint_follower", "velocity_smoother",
                "collision_monitor"} <= set(servers)
        for name in ("planner_server", "controller_server", "smoother_server", "behavior_server",
                     "velocity_smoother", "collision_monitor", "bt_navigator", "waypoint_follower"):
            assert servers[name].current_state.label == "active", (name, servers[name].last_error)
    finally:
        ctx.shutdown()


def test_unloadable_controller_fails_the_controller_server_with_its_name(tmp_path: Path) -> None:
    doc = copy.deepcopy(upstream("jazzy", GRACEFUL))
    # what the audit would have removed: sections of servers eddiebot does not run
    for section in ("route_server", "docking_server", "loopback_simulator"):
        del doc[section]
    ctx, nodes = _launch(tmp_path, doc)
    try:
        cs = next(n for n in nodes if n.get_name() == "controller_server")
        assert cs.current_state.label == "unconfigured"
        assert GRACEFUL in cs.last_error and "FollowPath.plugin" in cs.last_error
    finally:
        ctx.shutdown()


def test_behavior_server_reads_jazzy_topic_names() -> None:
    from eddiebot.core import Context
    from eddiebot.nav.nodes.behavior_server import BehaviorServer

    ctx = Context(use_sim_time=True)
    try:
        for over, costmap, footprint in (
                ({}, "/local_costmap/costmap_raw", "/local_costmap/published_footprint"),
                ({"costmap_topic": "humble/costmap_raw"}, "/humble/costmap_raw",
                 "/local_costmap/published_footprint"),
                ({"costmap_topic": "humble/costmap_raw", "local_costmap_topic": "/lc/raw",
                  "local_footprint_topic": "lc/footprint"}, "/lc/raw", "/lc/footprint")):
            node = BehaviorServer(context=ctx, parameter_overrides={
                "behavior_plugins": ["wait"], "wait.plugin": "nav2_behaviors::Wait", **over})
            assert node.trigger_configure() == 97, node.last_error
            assert node.trigger_activate() == 97
            assert [s.topic_name for s in node._subs[:2]] == [costmap, footprint]
            node.trigger_deactivate()
            node.destroy_node()
    finally:
        ctx.shutdown()
    w = audit_nav2_params(upstream("jazzy", RPP)).warnings
    assert "ignored: behavior_server.local_costmap_topic" not in w
    assert "ignored: behavior_server.global_costmap_topic" in w  # no global-costmap behaviour
