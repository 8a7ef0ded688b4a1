"""The three Nav2 parameter files load; errors name server, key and value."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from eddiebot.nav.config import load_nav2_config
from eddiebot.nav.controllers import DWBController, RegulatedPurePursuitController
from eddiebot.nav.errors import ParameterError

CONFIG = Path(__file__).resolve().parents[2] / "config"


def test_defaults_file_matches_upstream_sample() -> None:
    c = load_nav2_config(CONFIG / "nav2_defaults.yaml")
    assert isinstance(c.controller_server.controller("FollowPath"), DWBController)
    assert c.velocity_smoother.max_velocity == (0.26, 0.0, 1.0)
    assert c.planners["GridBased"].config.tolerance == 0.5
    assert c.local_costmap.rolling_window and c.local_costmap.master.size_x == 60
    assert c.warnings == []


def test_eddie_file_is_physically_sane() -> None:
    c = load_nav2_config(CONFIG / "nav2.yaml", stale_command_timeout=0.5)
    assert c.warnings == []
    vs = c.velocity_smoother
    assert vs.smoothing_frequency == 20.0 and max(vs.max_velocity[0], -vs.min_velocity[0]) <= 0.5
    assert c.local_costmap.config.robot_radius == pytest.approx(0.23)
    assert c.local_costmap.inscribed_radius >= 0.2245
    assert isinstance(c.controller_server.controller("FollowPath"), RegulatedPurePursuitController)
    assert set(c.planners) == {"GridBased", "ThetaStar"}
    assert set(c.behaviors) == {"spin", "backup", "drive_on_heading", "assisted_teleop", "wait"}


def test_report_file_warns() -> None:
    c = load_nav2_config(CONFIG / "nav2_report.yaml", stale_command_timeout=0.5)
    vs = c.velocity_smoother
    assert vs.smoothing_frequency == 0.1 and vs.max_velocity == (1.4, 0.0, 0.2)
    assert vs.scale_velocities
    assert len(c.warnings) == 3
    assert c.local_costmap.config.resolution == 0.06


def test_bad_value_named_at_configure() -> None:
    doc = yaml.safe_load((CONFIG / "nav2.yaml").read_text())
    doc["velocity_smoother"]["ros__parameters"]["max_accel"] = [-1.0, 0.0, 1.0]
    with pytest.raises(ParameterError) as exc:
        load_nav2_config(doc)
    assert (exc.value.server, exc.value.key) == ("velocity_smoother", "max_accel")
    assert "max_accel" in str(exc.value) and "-1.0" in str(exc.value)
    doc = yaml.safe_load((CONFIG / "nav2.yaml").read_text())
    doc["controller_server"]["ros__parameters"]["FollowPath"]["desired_linear_vel"] = "fast"
    with pytest.raises(ParameterError) as exc:
        load_nav2_config(doc)
    assert exc.value.server == "controller_server.FollowPath" and exc.value.value == "fast"
