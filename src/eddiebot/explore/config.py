"""Exploration parameters: explore_lite's names and defaults, plus eddiebot's few additions."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from eddiebot.explore.errors import ExploreConfigError

__all__ = ["EDDIE_EXPLORE_PARAMS", "ExploreConfig"]


@dataclass(frozen=True)
class ExploreConfig:
    """One exploration's settings (lengths m, angles rad, times s).

    The first block carries explore_lite's parameter names with the defaults of its code
    (``explore.cpp``); the second is eddiebot's: the Kinect's usable cone for the
    information gain, the robot's radius for the reachable space, and the rules that merge
    and abandon frontiers.
    """

    planner_frequency: float = 1.0
    progress_timeout: float = 30.0
    potential_scale: float = 1e-3
    orientation_scale: float = 0.0
    gain_scale: float = 1.0
    min_frontier_size: float = 0.5
    visualize: bool = False
    return_to_init: bool = False
    robot_base_frame: str = "base_footprint"
    transform_tolerance: float = 0.3

    # eddiebot additions
    costmap_topic: str = ""
    """An OccupancyGrid costmap in the map's frame (``/global_costmap/costmap``) whose lethal
    cells goals keep ``goal_clearance`` from, as from the map's obstacles: what the costmap
    marks from the depth cloud below the scan (chairs). explore_lite searches frontiers on
    its ``costmap_topic``; here frontiers come from ``/map`` and this grid only places
    goals. "": none."""
    robot_radius: float = 0.23
    """Cells closer than this to an occupied cell are not reachable (Nav2's inscribed radius)."""
    goal_clearance: float = 0.35
    """Goals (viewpoints, entries) keep this far from known obstacles, m."""
    preferred_clearance: float = 0.5
    """Viewpoints keep this far from known obstacles when the frontier has such a spot, m:
    out of a 0.9 m door's gap and off the walls, where the controller and the base's range
    veto stall the robot."""
    free_threshold: int = 19
    """A map cell with 0 ≤ value ≤ this is free (map_server's free_thresh 0.196)."""
    occupied_threshold: int = 65
    """A map cell with value ≥ this is occupied (map_server's occupied_thresh 0.65)."""
    sensor_min_range: float = 0.5
    sensor_max_range: float = 4.5
    sensor_fov: float = math.radians(57.0)
    """The Kinect's usable depth range and horizontal field of view."""
    standoff: float = 0.9
    """How far back from a frontier the robot stops to look at it (beyond sensor_min_range)."""
    frontier_match_tolerance: float = 0.75
    """Frontiers whose centroids are this close across searches are the same frontier."""
    blacklist_radius: float = 0.6
    """A frontier whose centroid lies this close to an abandoned one is abandoned too."""
    max_visits: int = 2
    """Arrivals at a frontier that leave it in place before it is abandoned as unproductive."""
    min_gain: float = 0.05
    """Frontiers whose viewpoint would show less unknown area than this (m²) are skipped."""
    stuck_strikes: int = 2
    """``progress_timeout`` expiries before a frontier is abandoned; before that, the goal spot
    the robot could not get closer to is avoided and the frontier gets another viewpoint."""
    avoid_radius: float = 0.5
    """Goals (viewpoints, entries) keep this far from the spots avoided after no progress, m."""
    retry_rounds: int = 1
    """Times the frontiers abandoned for no progress or a failed goal are tried again when
    nothing else is left (the map around them has grown since)."""
    look_around: bool = True
    """Spin 360° in place before the first frontier (the Kinect sees 57°)."""
    time_limit: float = 0.0
    """Exploration time (s, node clock) after which the robot stops exploring; 0: none."""

    def __post_init__(self) -> None:
        positive = ("planner_frequency", "progress_timeout", "sensor_max_range", "sensor_fov",
                    "frontier_match_tolerance", "transform_tolerance")
        for name in positive:
            if not float(getattr(self, name)) > 0.0:
                raise ExploreConfigError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("potential_scale", "orientation_scale", "gain_scale", "min_frontier_size",
                     "robot_radius", "sensor_min_range", "min_gain", "goal_clearance", "preferred_clearance", "standoff", "blacklist_radius",
                     "time_limit"):
            if float(getattr(self, name)) < 0.0:
                raise ExploreConfigError(f"{name} must be ≥ 0, got {getattr(self, name)!r}")
        if self.sensor_min_range >= self.sensor_max_range:
            raise ExploreConfigError("sensor_min_range must be below sensor_max_range")
        if not 0 <= self.free_threshold < self.occupied_threshold <= 100:
            raise ExploreConfigError("need 0 ≤ free_threshold < occupied_threshold ≤ 100")
        if self.stuck_strikes < 1:
            raise ExploreConfigError(f"stuck_strikes must be ≥ 1, got {self.stuck_strikes}")
        if self.retry_rounds < 0 or self.avoid_radius < 0.0:
            raise ExploreConfigError("retry_rounds and avoid_radius must be ≥ 0")
        if self.max_visits < 1:
            raise ExploreConfigError(f"max_visits must be ≥ 1, got {self.max_visits}")

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> ExploreConfig:
        """Build from parameter values; unknown keys are an error naming them."""
        names = {f.name: f for f in fields(cls)}
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise ExploreConfigError(f"unknown explore parameters {unknown}; known: {sorted(names)}")
        typed: dict[str, Any] = {}
        for key, value in values.items():
            default = getattr(cls, key)
            typed[key] = type(default)(value)
        return cls(**typed)


#: Eddie's tuning (what `eddie explore` runs with): cost in metres of path against square
#: metres of unknown floor the Kinect would see, and turning counted, since a turn in place
#: is slow and blind with a 57° scan.
EDDIE_EXPLORE_PARAMS: dict[str, Any] = {
    "planner_frequency": 1.0,
    "progress_timeout": 20.0,
    "potential_scale": 1.0,
    "orientation_scale": 0.5,
    "gain_scale": 0.3,
    "min_frontier_size": 0.4,
    "visualize": True,
    "return_to_init": True,
    "costmap_topic": "/global_costmap/costmap",
}
