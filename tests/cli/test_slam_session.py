"""``eddie slam --session``: where the continued session starts, and that it says why."""

from __future__ import annotations

import argparse
import math
from types import SimpleNamespace

import pytest

from eddiebot.cli.errors import CliError
from eddiebot.cli.slam import _session_anchor, _start_pose
from eddiebot.core.launch import find_launch_file, parse_launch_file
from eddiebot.maps import MapAnchor, save_anchor


def _args(session, start=None):
    return argparse.Namespace(live_session=session, start_pose=start)


@pytest.fixture
def session(tmp_path):
    path = tmp_path / "session.eslam"
    path.write_bytes(b"")
    save_anchor(path.with_name("session.eslam.anchor.yaml"),
                MapAnchor((1.0, 0.0, math.pi / 2), "abc/eddie_odom"))
    return path


def test_same_odometry_continues_where_the_robot_is(session):
    anchor = _session_anchor(session)
    pose, why = _start_pose(_args(session), anchor, SimpleNamespace(odom_session="abc/eddie_odom"),
                            lambda: (1.0, 0.0, 0.0))
    assert pose == pytest.approx((1.0, 1.0, math.pi / 2))
    assert "same running odometry" in why


def test_otherwise_start_pose_or_an_error_naming_it(session, tmp_path):
    anchor = _session_anchor(session)
    other = SimpleNamespace(odom_session="zzz/eddie_odom")
    pose, why = _start_pose(_args(session, [0.5, 0.5, 0.0]), anchor, other, lambda: None)
    assert pose == (0.5, 0.5, 0.0) and why == "--start-pose"
    with pytest.raises(CliError, match="give --start-pose X Y YAW"):
        _start_pose(_args(session), anchor, other, lambda: None)
    with pytest.raises(CliError, match="no such file"):
        _session_anchor(tmp_path / "missing.eslam")


def test_slam_launch_is_the_simulator_plus_mapping():
    full = parse_launch_file(find_launch_file("slam"), {})
    alone = parse_launch_file(find_launch_file("mapping"), {"use_sim_time": "false"})
    assert [n.type for n in alone.nodes] == ["eddiebot.slam.slam_toolbox"]
    assert full.nodes[-1].type == "eddiebot.slam.slam_toolbox"
    assert "eddiebot.sim.simulator" in [n.type for n in full.nodes]
