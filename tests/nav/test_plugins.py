"""Plugins from another package: an installed distribution's entry points (groups
``eddiebot.nav.<kind>``) and explicit ``register`` calls load by name through the same
builders as the built-in types; unknown and broken ones are named."""

from __future__ import annotations

import math
import sys
import textwrap
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from eddiebot.nav import plugins
from eddiebot.nav.behaviors import build_behaviors
from eddiebot.nav.bt import BehaviorTreeFactory, TreeError
from eddiebot.nav.controllers import SimpleGoalChecker, build_controller_server
from eddiebot.nav.cost_values import FREE_SPACE, LETHAL_OBSTACLE
from eddiebot.nav.costmap import build_costmap
from eddiebot.nav.errors import NoValidPath, ParameterError, UnsupportedPlugin
from eddiebot.nav.nodes.params_audit import audit_nav2_params
from eddiebot.nav.planners import build_planners
from eddiebot.nav.smoother import build_smoother
from eddiebot.nav.types import Twist2D

PLUGIN_SOURCE = '''
"""A user's navigation plugins, as another package would ship them."""
import math
from dataclasses import dataclass, replace

import numpy as np

from eddiebot.nav.behaviors import Spin
from eddiebot.nav.cost_values import LETHAL_OBSTACLE
from eddiebot.nav.costmap.layers import Layer, touch
from eddiebot.nav.errors import NoValidPath, ParameterError
from eddiebot.nav.smoother import SmoothResult
from eddiebot.nav.types import Twist2D


class StraightController:
    """Turns towards the plan's last pose at k_theta * heading error (at most max_wz); drives
    at speed unless the cell lookahead m ahead is lethal; within goal_radius of the last pose
    it only turns to that pose's yaw."""

    def __init__(self, name, speed, k_theta, lookahead, period, goal_radius, max_wz):
        self.name, self.speed, self.k_theta = name, speed, k_theta
        self.lookahead, self.period = lookahead, period
        self.goal_radius, self.max_wz = goal_radius, max_wz
        self.plan = np.zeros((1, 3))

    @classmethod
    def from_params(cls, params, name, context):
        speed = float(params.get("speed", 0.2))
        if speed <= 0.0:
            raise ParameterError(context.server, f"{name}.speed", speed, "must be > 0")
        return cls(name, speed, float(params.get("k_theta", 1.0)),
                   float(params.get("lookahead", 0.5)),
                   1.0 / context.server_config.controller_frequency,
                   float(params.get("goal_radius", 0.1)), float(params.get("max_wz", 10.0)))

    def set_plan(self, path):
        self.plan = np.asarray(path, dtype=float)

    def set_speed_limit(self, speed_limit, percentage):
        pass

    def set_goal_tolerance(self, xy_tolerance):
        pass

    def compute_velocity_commands(self, pose, velocity, path, costmap, dt=None):
        if path is not None:
            self.set_plan(path)
        x, y, th = (float(v) for v in pose)
        gx, gy, gyaw = self.plan[-1]
        if math.hypot(gx - x, gy - y) <= self.goal_radius:
            err = math.remainder(gyaw - th, 2.0 * math.pi)
            vx = 0.0
        else:
            err = math.remainder(math.atan2(gy - y, gx - x) - th, 2.0 * math.pi)
            ahead = costmap.master.cost_at_world(x + self.lookahead * math.cos(th),
                                                 y + self.lookahead * math.sin(th))
            vx = 0.0 if ahead >= LETHAL_OBSTACLE else self.speed
        wz = max(-self.max_wz, min(self.max_wz, self.k_theta * err))
        return Twist2D(vx, 0.0, wz)


class StraightLinePlanner:
    """Poses every step m on the segment start-goal, facing the goal; fails on a lethal cell."""

    def __init__(self, name, step):
        self.name, self.step = name, step

    @classmethod
    def from_params(cls, params, name, context):
        return cls(name, float(params.get("step", 0.1)))

    def create_plan(self, start, goal, costmap):
        s, g = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
        n = int(math.ceil(math.hypot(*(g[:2] - s[:2])) / self.step)) + 1
        t = np.linspace(0.0, 1.0, n)
        path = np.zeros((n, 3))
        path[:, :2] = s[:2] + t[:, None] * (g[:2] - s[:2])
        path[:, 2] = math.atan2(g[1] - s[1], g[0] - s[0])
        for x, y, _ in path:
            if costmap.cost_at_world(x, y) >= LETHAL_OBSTACLE:
                raise NoValidPath(f"{self.name}: the line crosses an obstacle at ({x:.2f}, {y:.2f})")
        return path


class BoxLayer(Layer):
    """Writes cost into the cells whose centres lie in box [x0, y0, x1, y1] (m)."""

    def __init__(self, name, box, cost):
        super().__init__(name)
        self.box, self.cost = box, cost

    @classmethod
    def from_params(cls, params, name, context):
        box = [float(v) for v in params.get("box", [])]
        if len(box) != 4:
            raise ParameterError(context.server, f"{name}.box", params.get("box"),
                                 "expected [x0, y0, x1, y1]")
        return cls(name, box, int(params.get("cost", LETHAL_OBSTACLE)))

    def update_bounds(self, robot_x, robot_y, robot_yaw, bounds):
        touch(bounds, self.box[0], self.box[1])
        touch(bounds, self.box[2], self.box[3])

    def update_costs(self, master, i0, j0, i1, j1):
        res = master.resolution
        xs = master.origin_x + (np.arange(i0, i1) + 0.5) * res
        ys = master.origin_y + (np.arange(j0, j1) + 0.5) * res
        inx = (xs >= self.box[0]) & (xs <= self.box[2])
        iny = (ys >= self.box[1]) & (ys <= self.box[3])
        win = master.data[j0:j1, i0:i1]
        win[np.ix_(iny, inx)] = np.maximum(win[np.ix_(iny, inx)], self.cost)


class DecimatingSmoother:
    """Keeps every n-th pose and the last one."""

    def __init__(self, name, n):
        self.name, self.n = name, n

    @classmethod
    def from_params(cls, params, name, context):
        return cls(name, int(params.get("n", 2)))

    def smooth(self, path, costmap=None):
        p = np.asarray(path, dtype=float)
        keep = sorted(set(range(0, len(p), self.n)) | {len(p) - 1})
        return SmoothResult(p[keep], True)


class GentleSpin(Spin):
    """Spin capped at its own max_rotational_vel."""

    @classmethod
    def from_params(cls, params, name, context):
        cap = float(params.get("max_rotational_vel", 0.3))
        return cls(replace(context.server_config, max_rotational_vel=cap,
                           min_rotational_vel=min(cap, context.server_config.min_rotational_vel)))


class Fragile:
    """A plugin whose configure fails with an error no parameter check foresaw."""

    @classmethod
    def from_params(cls, params, name, context):
        return params.get("mode").upper()


def make_progress_checker(params, name, context):
    """A plain factory function (no class): a checker that never times out."""
    class Patient:
        def reset(self):
            pass

        def check(self, pose, now_ns):
            return True
    return Patient()
'''

ENTRY_POINTS = '''
[eddiebot.nav.controllers]
my_pkg::StraightController = {mod}:StraightController

[eddiebot.nav.planners]
my_pkg.StraightLinePlanner = {mod}:StraightLinePlanner

[eddiebot.nav.costmap_layers]
my_pkg::BoxLayer = {mod}:BoxLayer

[eddiebot.nav.smoothers]
my_pkg::DecimatingSmoother = {mod}:DecimatingSmoother
my_pkg::Fragile = {mod}:Fragile

[eddiebot.nav.bt_nodes]
broken_nodes = {mod}_not_installed:register_bt_nodes

[eddiebot.nav.behaviors]
my_pkg::GentleSpin = {mod}:GentleSpin

[eddiebot.nav.progress_checkers]
my_pkg::PatientChecker = {mod}:make_progress_checker

[eddiebot.nav.goal_checkers]
my_pkg::Missing = {mod}_not_installed:GoalChecker
'''


def install_package(site: Path) -> str:
    """Write the plugin module and its ``*.dist-info`` (``METADATA``, ``entry_points.txt``)
    into directory ``site``, as pip leaves an installed package; the module's unique name."""
    mod = f"my_nav_plugins_{uuid.uuid4().hex[:8]}"
    site.mkdir(parents=True, exist_ok=True)
    (site / f"{mod}.py").write_text(PLUGIN_SOURCE)
    dist = site / f"{mod}-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {mod}\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent(ENTRY_POINTS).format(mod=mod))
    return mod


@dataclass(frozen=True)
class Installed:
    module: str
    site: Path


@pytest.fixture
def installed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Installed]:
    """A distribution installed into a directory on ``sys.path``: its module and its
    ``*.dist-info`` with ``entry_points.txt``, as pip leaves them."""
    site = tmp_path / "site-packages"
    mod = install_package(site)
    monkeypatch.syspath_prepend(str(site))
    plugins.clear_entry_point_cache()
    yield Installed(mod, site)
    plugins.clear_entry_point_cache()
    sys.modules.pop(mod, None)


def _box_costmap() -> Any:
    """4 m x 4 m at 0.05 m, a lethal box [2.0, 1.0]-[2.4, 3.0] from the user's layer."""
    cm = build_costmap({
        "width": 4, "height": 4, "resolution": 0.05, "robot_radius": 0.1,
        "plugins": ["box_layer", "inflation_layer"],
        "box_layer": {"plugin": "my_pkg/BoxLayer", "box": [2.0, 1.0, 2.4, 3.0]},
        "inflation_layer": {"plugin": "nav2_costmap_2d::InflationLayer",
                            "inflation_radius": 0.3, "cost_scaling_factor": 5.0},
    }, "local_costmap")
    cm.update_map((0.5, 2.0, 0.0))
    return cm


def test_installed_layer_builds_into_the_costmap(installed: Installed) -> None:
    cm = _box_costmap()
    assert [type(lay).__name__ for lay in cm.layers] == ["BoxLayer", "InflationLayer"]
    m = cm.master
    assert m.cost_at_world(2.2, 2.0) == LETHAL_OBSTACLE
    assert m.cost_at_world(1.0, 2.0) == FREE_SPACE
    # 0.125 m left of the box edge, beyond the 0.1 m inscribed radius: the inflation decay
    # 252·exp(-5·(d - r_inscribed)) of the distance d to the nearest lethal cell
    cell, edge = m.world_to_map(1.875, 2.0), m.world_to_map(2.0, 2.0)
    assert cell is not None and edge is not None
    d = (edge[0] - cell[0]) * 0.05
    assert d == pytest.approx(0.15)
    assert m.get_cost(*cell) == int(252 * math.exp(-5.0 * (d - cm.inscribed_radius))) == 204


def test_installed_controller_runs_on_a_costmap(installed: Installed) -> None:
    srv = build_controller_server({
        "controller_frequency": 10.0,
        "controller_plugins": ["FollowPath"],
        "FollowPath": {"plugin": "my_pkg::StraightController", "speed": 0.3, "k_theta": 2.0,
                       "lookahead": 0.5},
        "progress_checker_plugins": ["progress_checker"],
        "progress_checker": {"plugin": "my_pkg::PatientChecker"},
    })
    ctrl = srv.controller("FollowPath")
    assert type(ctrl).__name__ == "StraightController" and ctrl.period == pytest.approx(0.1)
    assert srv.progress_checkers["progress_checker"].check((0.0, 0.0, 0.0), 10**12)
    assert isinstance(srv.goal_checkers["goal_checker"], SimpleGoalChecker)
    cm = _box_costmap()
    path = np.array([[0.5, 1.5, 0.0], [1.5, 2.5, 0.0]])
    # free 0.5 m ahead: full speed, turn 2.0 x atan2(1.0, 1.0)
    cmd = ctrl.compute_velocity_commands((0.5, 1.5, 0.0), Twist2D(), path, cm)
    assert (cmd.vx, cmd.vy) == (0.3, 0.0)
    assert cmd.wz == pytest.approx(2.0 * math.pi / 4)
    # 0.5 m ahead of (1.6, 2.0) is inside the box: stop, keep turning towards the goal
    cmd = ctrl.compute_velocity_commands((1.6, 2.0, 0.0), Twist2D(), path, cm)
    assert cmd.vx == 0.0
    assert cmd.wz == pytest.approx(2.0 * math.atan2(0.5, -0.1))


def test_installed_planner_and_smoother(installed: Installed) -> None:
    planners = build_planners({"planner_plugins": ["Line"],
                               "Line": {"plugin": "my_pkg::StraightLinePlanner", "step": 0.25}})
    cm = _box_costmap()
    path = planners["Line"].create_plan((0.5, 0.5, 0.0), (1.5, 0.5, 0.0), cm.master)
    np.testing.assert_allclose(path[:, 0], [0.5, 0.75, 1.0, 1.25, 1.5])
    np.testing.assert_allclose(path[:, 1:], 0.5 * np.array([[1.0, 0.0]] * 5))
    with pytest.raises(NoValidPath, match=r"obstacle at \(2\.00, 2\.00\)"):
        planners["Line"].create_plan((0.5, 2.0, 0.0), (3.5, 2.0, 0.0), cm.master)
    sm = build_smoother("decimate", {"plugin": "my_pkg/DecimatingSmoother", "n": 2})
    assert sm.smooth(path).path[:, 0].tolist() == [0.5, 1.0, 1.5]


def test_installed_behaviour(installed: Installed) -> None:
    cfg, behs = build_behaviors({
        "behavior_plugins": ["spin", "wait"],
        "spin": {"plugin": "my_pkg::GentleSpin", "max_rotational_vel": 0.3},
        "wait": {"plugin": "nav2_behaviors::Wait"},
    })
    spin = behs["spin"]
    assert spin.config.max_rotational_vel == 0.3 and cfg.max_rotational_vel == 1.0
    cm = _box_costmap()
    spin.start((1.0, 2.0, 0.0), math.pi / 2, 0)
    step = spin.update((1.0, 2.0, 0.0), 10**8, cm)
    # sqrt(2 · 3.2 · π/2) = 3.17 rad/s, capped at the plugin's 0.3
    assert step.cmd == Twist2D(0.0, 0.0, 0.3)


def test_registered_factory_loads_by_name() -> None:
    def lenient(params: dict[str, Any], name: str, context: plugins.PluginContext) -> Any:
        return SimpleGoalChecker()

    plugins.register("goal_checkers", "my_pkg::Lenient", lenient)
    try:
        srv = build_controller_server({"goal_checker_plugins": ["general_goal_checker"],
                                       "general_goal_checker": {"plugin": "my_pkg/Lenient"}})
        assert isinstance(srv.goal_checkers["general_goal_checker"], SimpleGoalChecker)
    finally:
        plugins.registry("goal_checkers").unregister("my_pkg::Lenient")
    assert "my_pkg::Lenient" not in plugins.registry("goal_checkers")


def test_unknown_type_names_server_key_type_and_known_types(installed: Installed) -> None:
    with pytest.raises(UnsupportedPlugin) as exc:
        build_controller_server({"FollowPath": {"plugin": "my_pkg::Crooked"}})
    e = exc.value
    assert (e.server, e.key, e.plugin) == ("controller_server", "FollowPath.plugin",
                                           "my_pkg::Crooked")
    assert "dwb_core::DWBLocalPlanner" in e.reason and "my_pkg::StraightController" in e.reason
    with pytest.raises(UnsupportedPlugin, match=r"'box\.plugin' = 'my_pkg::Bx'.*my_pkg::BoxLayer"):
        build_costmap({"plugins": ["box"], "box": {"plugin": "my_pkg::Bx"}}, "global_costmap")


def test_plugin_parameter_errors_name_the_key(installed: Installed) -> None:
    with pytest.raises(ParameterError, match=r"controller_server: parameter 'FollowPath\.speed'"):
        build_controller_server({"FollowPath": {"plugin": "my_pkg::StraightController",
                                                "speed": -1.0}})


def test_entry_point_that_fails_to_import_is_named(installed: Installed) -> None:
    params = {"goal_checker": {"plugin": "my_pkg::Missing"}}
    messages = []
    for _ in range(2):
        with pytest.raises(UnsupportedPlugin) as exc:
            build_controller_server(params)
        messages.append(str(exc.value))
    assert messages[0] == messages[1]
    assert messages[0] == (
        f"controller_server: parameter 'goal_checker.plugin' = 'my_pkg::Missing': entry point "
        f"'my_pkg::Missing' = '{installed.module}_not_installed:GoalChecker' (group "
        f"'eddiebot.nav.goal_checkers') failed to load: ModuleNotFoundError: No module named "
        f"'{installed.module}_not_installed'")


def test_audit_keeps_an_installed_plugins_keys(installed: Installed) -> None:
    doc = {"controller_server": {"ros__parameters": {
        "controller_plugins": ["FollowPath"],
        "FollowPath": {"plugin": "my_pkg::StraightController", "speed": 0.3, "k_theta": 2.0},
    }}, "planner_server": {"ros__parameters": {
        "planner_plugins": ["GridBased"],
        "GridBased": {"plugin": "nav2_navfn_planner::NavfnPlanner", "tolerance": 0.5, "foo": 1},
    }}}
    audit = audit_nav2_params(doc)
    assert audit.warnings == ("ignored: planner_server.GridBased.foo",)
    fp = audit.supported["controller_server"]["ros__parameters"]["FollowPath"]
    assert fp == {"plugin": "my_pkg::StraightController", "speed": 0.3, "k_theta": 2.0}
    doc["controller_server"]["ros__parameters"]["goal_checker_plugins"] = ["goal_checker"]
    doc["controller_server"]["ros__parameters"]["goal_checker"] = {"plugin": "my_pkg::Missing"}
    with pytest.raises(UnsupportedPlugin, match="ModuleNotFoundError"):
        audit_nav2_params(doc)


def test_eddie_nav_exits_non_zero_naming_a_broken_plugin(
        installed: Installed, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from eddiebot.cli.main import main
    from eddiebot.maps import OccupancyMap, save_map

    room = save_map(OccupancyMap(data=np.zeros((40, 60), dtype=np.int8), resolution=0.05),
                    tmp_path / "room")
    params = tmp_path / "nav2.yaml"
    params.write_text("controller_server:\n  ros__parameters:\n"
                      "    controller_plugins: [FollowPath]\n"
                      "    FollowPath:\n      plugin: my_pkg::StraightController\n"
                      "    goal_checker:\n      plugin: my_pkg::Missing\n")
    code = main(["nav", "--map", str(room), "--world", "office", "--params", str(params),
                 "--run-dir", str(tmp_path / "run")])
    err = capsys.readouterr().err.splitlines()
    assert code == 2
    assert err[-1].startswith("eddie: error: controller_server: parameter 'goal_checker.plugin'")
    assert f"No module named '{installed.module}_not_installed'" in err[-1]
    assert sum("my_pkg::Missing" in line for line in err) == 1


def test_installed_plugin_failing_to_configure_is_named(installed: Installed) -> None:
    with pytest.raises(UnsupportedPlugin) as exc:
        build_smoother("fragile", {"plugin": "my_pkg::Fragile"})
    assert str(exc.value) == (
        f"smoother_server: parameter 'fragile.plugin' = 'my_pkg::Fragile': entry point "
        f"'my_pkg::Fragile' = '{installed.module}:Fragile' (group 'eddiebot.nav.smoothers'): "
        f"failed to configure: AttributeError: 'NoneType' object has no attribute 'upper'")


def test_bt_node_entry_point_failing_to_import_is_named(installed: Installed) -> None:
    with pytest.raises(TreeError) as exc:
        BehaviorTreeFactory().load_plugin("broken_nodes")
    assert str(exc.value) == (
        f"plugin_lib_names: entry point 'broken_nodes' = "
        f"'{installed.module}_not_installed:register_bt_nodes' (group 'eddiebot.nav.bt_nodes') "
        f"failed to load: ModuleNotFoundError: No module named '{installed.module}_not_installed'")
