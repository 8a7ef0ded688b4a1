"""Fixtures: the navigation servers around a kinematic robot, one process, sim time."""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from navnodes_stub import StubRobot, room_map

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.lifecycle import LifecycleManager
from eddiebot.maps import save_map
from eddiebot.nav.nodes._common import flatten_params, nest_nav2_params

REPO = Path(__file__).resolve().parents[3]


def stub_params() -> dict[str, Any]:
    """config/nav2.yaml, folded, with the sources the stub robot has (a scan only)."""
    doc = nest_nav2_params(yaml.safe_load((REPO / "config" / "nav2.yaml").read_text()))
    local = doc["controller_server"]["ros__parameters"]["local_costmap"]
    local["plugins"] = ["voxel_layer", "inflation_layer"]
    local["voxel_layer"]["observation_sources"] = "scan"
    cm = doc["collision_monitor"]["ros__parameters"]
    cm["observation_sources"] = ["scan"]
    return doc


def server_params(doc: dict[str, Any], name: str, **extra: Any) -> dict[str, Any]:
    out = flatten_params(copy.deepcopy(doc.get(name, {}).get("ros__parameters", {}) or {}))
    out.update(extra)
    return out


class NavStack:
    def __init__(self, tmp_path: Path, *, start=(1.0, 1.0, 0.0), box=(2.6, 2.0, 3.4, 4.0),
                 servers: tuple[str, ...] = ("map_server", "planner_server", "controller_server",
                                              "smoother_server", "velocity_smoother",
                                              "collision_monitor", "behavior_server",
                                              "bt_navigator", "waypoint_follower"),
                 params: dict[str, Any] | None = None, amcl_pose: tuple | None = None) -> None:
        from eddiebot.nav.nodes import SERVER_CLASSES

        self.ctx = Context(use_sim_time=True)
        self.map = room_map(box=box)
        map_yaml = save_map(self.map, tmp_path / "room")
        doc = params or stub_params()
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.robot = StubRobot(self.map, start, context=self.ctx,
                               static_map_odom=amcl_pose is None)
        self.nodes: dict[str, Any] = {}
        remaps = {"controller_server": {"/cmd_vel": "/cmd_vel_nav"},
                  "velocity_smoother": {"/cmd_vel": "/cmd_vel_nav"},
                  "behavior_server": {"/cmd_vel": "/cmd_vel_nav"}}
        extra = {"map_server": {"yaml_filename": str(map_yaml)},
                 "bt_navigator": {"robot_base_frame": "base_footprint"}}
        if amcl_pose is not None:
            servers = (*servers, "amcl")
            extra["amcl"] = {"set_initial_pose": True, "initial_pose.x": amcl_pose[0],
                             "initial_pose.y": amcl_pose[1], "initial_pose.yaw": amcl_pose[2],
                             "random_seed": 1, "max_particles": 500, "min_particles": 200}
        for name in servers:
            cls = SERVER_CLASSES[name]
            self.nodes[name] = cls(context=self.ctx, remappings=remaps.get(name, {}),
                                   parameter_overrides=server_params(doc, name, **extra.get(name, {})))
        self.manager = LifecycleManager("lifecycle_manager_navigation", context=self.ctx,
                                        parameter_overrides={"node_names": list(servers),
                                                             "autostart": True})
        self.probe = Node("probe", context=self.ctx)
        for n in (self.robot, *self.nodes.values(), self.manager, self.probe):
            self.ex.add_node(n)
        self.ex.spin_for(0.5)

    def spin(self, seconds: float) -> None:
        self.ex.spin_for(seconds)

    def close(self) -> None:
        self.ctx.shutdown()


@pytest.fixture
def make_stack(tmp_path):
    stacks: list[NavStack] = []

    def make(**kwargs: Any) -> NavStack:
        s = NavStack(tmp_path, **kwargs)
        stacks.append(s)
        return s
    yield make
    for s in stacks:
        s.close()


@pytest.fixture
def nav_stub_params() -> Callable[[], dict[str, Any]]:
    """The stub robot's folded parameters, for tests that edit them before making a stack."""
    return stub_params
