"""Nav2's sample parameter files with MPPI as FollowPath: the section is honoured key by
key, what it cannot honour is named, and the whole stack drives to a goal with it."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import pytest
import yaml
from navnodes_stub import room_map

from _support.nav_actions import navigate
from eddiebot.core import Context, SingleThreadedExecutor
from eddiebot.core.action import GoalStatus
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.maps import save_map
from eddiebot.nav.config import load_nav2_config
from eddiebot.nav.controllers import MPPIController
from eddiebot.nav.errors import UnsupportedPlugin
from eddiebot.nav.nodes._common import nest_nav2_params
from eddiebot.nav.nodes.params_audit import audit_nav2_params
from eddiebot.registry import NODES

DATA = Path(__file__).resolve().parents[2] / "data" / "nav2"


def upstream(distro: str) -> dict[str, Any]:
    text = (DATA / f"nav2_params_{distro}.yaml").read_text()
    text = text.replace("KEEPOUT_ZONE_ENABLED", "false").replace("SPEED_ZONE_ENABLED", "false")
    return yaml.safe_load(text)


def follow_path(doc: dict[str, Any]) -> dict[str, Any]:
    return doc["controller_server"]["ros__parameters"]["FollowPath"]


@pytest.mark.parametrize(("distro", "named"), [
    ("jazzy", []),
    ("kilted", ["ignored: controller_server.FollowPath.publish_optimal_trajectory"]),
])
def test_sample_mppi_section_is_honoured(distro: str, named: list[str]) -> None:
    doc = upstream(distro)
    audit = audit_nav2_params(doc)
    assert [w for w in audit.warnings if ".FollowPath" in w] == named
    kept = follow_path(audit.supported)
    for key in named:
        assert key.rsplit(".", 1)[1] not in kept
    expected = {k: v for k, v in follow_path(doc).items() if f"FollowPath.{k}" not in str(named)}
    assert kept == expected  # everything else reaches the controller as written
    ctrl = load_nav2_config(audit.supported).controller_server.controller("FollowPath")
    assert isinstance(ctrl, MPPIController)
    assert (ctrl.config.batch_size, ctrl.config.time_steps) == (2000, 56)
    assert [c.name for c in ctrl.critics] == follow_path(doc)["critics"]


def test_unknown_mppi_entries_are_named_once() -> None:
    doc = upstream("jazzy")
    fp = follow_path(doc)
    fp["foo"] = 1.0
    fp["CostCritic"]["bar"] = 2
    fp["TwirlingCritic"] = {"enabled": True, "cost_weight": 10.0}  # not in critics: unread
    fp["TrajectoryVisualizer"]["colour"] = "red"
    audit = audit_nav2_params(doc)
    w = [x for x in audit.warnings if ".FollowPath" in x]
    assert sorted(w) == sorted([
        "ignored: controller_server.FollowPath.foo",
        "ignored: controller_server.FollowPath.CostCritic.bar",
        "ignored: controller_server.FollowPath.TwirlingCritic",
        "ignored: controller_server.FollowPath.TrajectoryVisualizer.colour",
    ])
    kept = follow_path(audit.supported)
    assert "foo" not in kept and "TwirlingCritic" not in kept and "bar" not in kept["CostCritic"]


def test_unknown_critic_stops_the_audit_with_its_name() -> None:
    doc = upstream("jazzy")
    follow_path(doc)["critics"].append("WaypointCritic")
    with pytest.raises(UnsupportedPlugin) as exc:
        audit_nav2_params(doc)
    assert (exc.value.server, exc.value.key, exc.value.plugin) == (
        "controller_server", "FollowPath.critics", "WaypointCritic")


def _controller_after_bring_up(doc: dict[str, Any], tmp_path: Path) -> Any:
    """``launch nav`` with the supported part of ``doc`` on a room map, spun 1 s: the
    controller server's FollowPath (the server active)."""
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
    try:
        ex.spin_for(1.0)
        cs = next(n for n in nodes if n.get_name() == "controller_server")
        assert cs.current_state.label == "active", cs.last_error
        return cs.plugins.controller("FollowPath")
    finally:
        ctx.shutdown()


def test_jazzy_file_brings_the_controller_server_up_with_mppi(tmp_path: Path) -> None:
    ctrl = _controller_after_bring_up(audit_nav2_params(upstream("jazzy")).supported, tmp_path)
    assert isinstance(ctrl, MPPIController) and ctrl.config.prune_distance == 1.7


def test_stack_reaches_a_goal_with_the_jazzy_mppi_section(make_stack, nav_stub_params) -> None:
    doc = copy.deepcopy(nav_stub_params())
    cs = doc["controller_server"]["ros__parameters"]
    cs["controller_frequency"] = 20.0
    cs["FollowPath"] = copy.deepcopy(follow_path(upstream("jazzy")))
    stack = make_stack(params=doc)
    assert stack.manager.system_active
    ctrl = stack.nodes["controller_server"].plugins.controller("FollowPath")
    assert isinstance(ctrl, MPPIController)
    _, res = navigate(stack, 4.5, 4.5, math.pi / 2)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    x, y, th = stack.robot.pose
    assert math.hypot(x - 4.5, y - 4.5) < 0.25
    assert abs(math.remainder(th - math.pi / 2, 2 * math.pi)) < 0.3


def test_the_shipped_jazzy_example_names_14_entries_and_brings_mppi_up(tmp_path: Path) -> None:
    # config/examples: Jazzy's sample with Eddie's frames, radius, command topic and the
    # sample's own local static layer listed; what it does not use is named, the rest runs
    import eddiebot

    example = Path(eddiebot.__file__).parent / "config" / "examples" / "nav2_params_jazzy_eddie.yaml"
    audit = audit_nav2_params(yaml.safe_load(example.read_text()))
    w = audit.warnings
    assert len(w) == len(set(w)) == 14, w
    assert "not supported: docking_server (whole section)" in w
    assert not [x for x in w if "static_layer" in x]
    local = audit.supported["local_costmap"]["local_costmap"]["ros__parameters"]
    assert local["plugins"][0] == "static_layer" and local["robot_base_frame"] == "base_footprint"
    ctrl = _controller_after_bring_up(audit.supported, tmp_path)
    assert isinstance(ctrl, MPPIController)
