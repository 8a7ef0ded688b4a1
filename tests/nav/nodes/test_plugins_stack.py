"""A controller from another installed package drives the navigation stack to a goal."""

from __future__ import annotations

import copy
import math
import sys
from pathlib import Path
from typing import Any

import pytest
from test_plugins import install_package

from _support.nav_actions import navigate
from eddiebot.core.action import GoalStatus
from eddiebot.nav import plugins


def test_stack_reaches_a_goal_with_an_installed_controller(
        make_stack: Any, nav_stub_params: Any, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    site = tmp_path / "site-packages"
    mod = install_package(site)
    monkeypatch.syspath_prepend(str(site))
    plugins.clear_entry_point_cache()
    try:
        doc = copy.deepcopy(nav_stub_params())
        cs = doc["controller_server"]["ros__parameters"]
        cs["FollowPath"] = {"plugin": "my_pkg::StraightController", "speed": 0.2,
                            "k_theta": 1.5, "lookahead": 0.3, "goal_radius": 0.08,
                            "max_wz": 1.0}
        stack = make_stack(params=doc)
        assert stack.manager.system_active
        ctrl = stack.nodes["controller_server"].plugins.controller("FollowPath")
        assert type(ctrl).__module__ == mod and ctrl.period == pytest.approx(1.0 / 20.0)
        _, res = navigate(stack, 2.2, 1.0, math.pi / 2)
        assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
        x, y, th = stack.robot.pose
        assert math.hypot(x - 2.2, y - 1.0) < 0.15
        assert abs(math.remainder(th - math.pi / 2, 2 * math.pi)) < 0.25
    finally:
        plugins.clear_entry_point_cache()
        sys.modules.pop(mod, None)
