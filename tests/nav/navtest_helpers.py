"""Helpers for the navigation tests: small synthetic costmaps and a kinematic simulation."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.maps import OccupancyMap
from eddiebot.nav.costmap import LayeredCostmap, build_costmap
from eddiebot.nav.types import Twist2D

#: The nav2.yaml that ships with eddiebot.
EDDIE_NAV2 = Path(__file__).resolve().parents[2] / "src" / "eddiebot" / "config" / "nav2.yaml"


def eddie_collision_monitor() -> tuple[Any, dict[str, np.ndarray]]:
    """The collision monitor the shipped nav2.yaml builds, and its sources with no points
    (to be overridden with the points of a case)."""
    from eddiebot.nav.config import load_nav2_config

    monitor = load_nav2_config(EDDIE_NAV2).collision_monitor
    assert monitor is not None
    return monitor, {n: np.zeros((0, 2)) for n in monitor.config.observation_sources}


def make_costmap(occ: np.ndarray, resolution: float = 0.05, robot_radius: float = 0.2,
                 inflation_radius: float = 0.55, cost_scaling_factor: float = 3.0,
                 track_unknown_space: bool = False) -> LayeredCostmap:
    cm = build_costmap({
        "resolution": resolution, "robot_radius": robot_radius, "footprint_padding": 0.0,
        "track_unknown_space": track_unknown_space,
        "plugins": ["static_layer", "inflation_layer"],
        "inflation_layer": {"inflation_radius": inflation_radius,
                            "cost_scaling_factor": cost_scaling_factor},
    }, "test_costmap")
    cm.set_static_map(OccupancyMap(occ.astype(np.int8), resolution))
    cm.update_map((0.0, 0.0, 0.0))
    return cm


def simulate(controller, path, costmap, start, goal_checker, steps=2000, dt=0.05):
    """Unicycle integration of the controller's commands; returns (final pose, reached, log)."""
    pose = np.asarray(start, dtype=float).copy()
    vel = Twist2D()
    log = []
    for _ in range(steps):
        if goal_checker.is_goal_reached(pose, path[-1], vel):
            return pose, True, np.array(log)
        cmd = controller.compute_velocity_commands(pose, vel, path, costmap, dt)
        th = pose[2] + 0.5 * cmd.wz * dt
        pose[0] += cmd.vx * math.cos(th) * dt
        pose[1] += cmd.vx * math.sin(th) * dt
        pose[2] = (pose[2] + cmd.wz * dt + math.pi) % (2 * math.pi) - math.pi
        vel = cmd
        log.append([pose[0], pose[1], pose[2], cmd.vx, cmd.wz])
    return pose, False, np.array(log)
