"""Topic, frame, action and service names the dashboard uses."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DashboardTopics"]


@dataclass(frozen=True)
class DashboardTopics:
    """Topic names the dashboard uses (ROS 2 defaults of the stack)."""

    scan: str = "/scan"
    odom: str = "/odom"
    plan: str = "/plan"
    local_plan: str = "/local_plan"
    goal_pose: str = "/goal_pose"
    initial_pose: str = "/initialpose"
    image: str = "/image_raw"
    depth: str = "/depth/image_raw"
    battery: str = "/eddie/battery_level"
    collisions: str = "/sim/collisions"
    rosout: str = "/rosout"
    cmd_vel: str = "/cmd_vel_teleop"
    e_stop: str = "/e_stop"
    base_frame: str = "base_footprint"
    navigate_action: str = "navigate_to_pose"
    map_saver: str = "/map_saver/save_map"
    slam_saver: str = "/slam_toolbox/save_map"
    particle_cloud: str = "/particle_cloud"
    lookahead: str = "/lookahead_point"
    footprint: str = "/local_costmap/published_footprint"
    robot_description: str = "/robot_description"
    vslam_graph: str = "/rtabmap/mapGraph"
    cloud_map: str = "/rtabmap/cloud_map"
    points: str = "/points"
    twist_mux: str = "/twist_mux"
    keepout_mask: str = "/keepout_filter_mask"
    keepout_mask_server: str = "/keepout_filter_mask_server/load_map"
    #: slam_toolbox's node: its graph, editing services and marker feedback live under it
    slam_namespace: str = "/slam_toolbox"
    #: the explore node's progress and its pause/resume (service and topic of one name)
    explore_status: str = "/explore/status"
    explore_resume: str = "/explore/resume"
    explore_frontiers: str = "/explore/frontiers"
