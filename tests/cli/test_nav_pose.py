"""Where ``eddie nav`` starts AMCL: the map's own record, the user's pose, or it says so."""

from __future__ import annotations

import argparse
import math
from types import SimpleNamespace

import numpy as np
import pytest

from eddiebot.cli.errors import CliError
from eddiebot.cli.nav import check_initial_pose, initial_pose
from eddiebot.maps import MapAnchor, OccupancyMap, save_map

SESSION = "0a1b2c3d/eddie_odom"


@pytest.fixture
def slam_map(tmp_path):
    """4 m x 2 m, origin (-1, -1): free where x < 2, unknown beyond, one obstacle cell."""
    data = np.zeros((40, 80), np.int8)
    data[:, 60:] = -1
    data[20, 30] = 100
    anchor = MapAnchor((0.5, 0.2, math.pi / 2), SESSION)
    return save_map(OccupancyMap(data, 0.05, origin=(-1.0, -1.0, 0.0)), tmp_path / "office",
                    anchor=anchor)


def _args(path, pose=None, world=None):
    return argparse.Namespace(map=path, initial_pose=pose, world=world)


def test_same_running_odometry_starts_localised(slam_map):
    robot = SimpleNamespace(odom_session=SESSION)
    pose, line = initial_pose(_args(slam_map), robot, lambda: (0.3, 0.0, 0.1))
    assert pose == pytest.approx((0.5, 0.5, math.pi / 2 + 0.1))  # map_to_odom ∘ odom
    assert line.startswith("starting localised at (0.50, 0.50, 1.67) in office.yaml")
    check_initial_pose(slam_map, pose)


def test_another_odometry_cannot_know_and_says_how_to_help(slam_map):
    robot = SimpleNamespace(odom_session="ffff/eddie_odom")
    pose, line = initial_pose(_args(slam_map), robot, lambda: (0.0, 0.0, 0.0))
    assert pose is None
    assert "cannot know where the robot is in office.yaml" in line
    assert "--initial-pose X Y YAW" in line
    # a fresh simulator of its own: SLAM's map frame is not the world's
    pose, line = initial_pose(_args(slam_map, world="office"), None, None)
    assert pose is None and "cannot know" in line


def test_given_pose_wins(slam_map):
    pose, line = initial_pose(_args(slam_map, pose=[0.0, 0.0, 0.5]),
                              SimpleNamespace(odom_session=SESSION), lambda: (1.0, 1.0, 0.0))
    assert pose == (0.0, 0.0, 0.5)
    assert "--initial-pose" in line


@pytest.mark.parametrize(("pose", "what"), [
    ((5.0, 0.0, 0.0), "is outside"),
    ((2.5, 0.0, 0.0), "unknown space"),
    ((0.52, 0.02, 0.0), "on an obstacle"),
])
def test_a_pose_off_the_free_map_is_an_error(slam_map, pose, what):
    with pytest.raises(CliError, match=what):
        check_initial_pose(slam_map, pose)
