"""The explicit registry of node types: launch files name nodes by these keys.

Values are ``module:Class``; modules are imported only when a launch uses them. A node
class takes keyword arguments ``node_name`` (optional, it has a default), ``namespace``,
``context``, ``parameter_overrides`` and ``remappings``, and passes them to ``Node``.
"""

from __future__ import annotations

NODES: dict[str, str] = {
    # foundation
    "eddiebot.demo.talker": "eddiebot.core.demo_nodes:Talker",
    "eddiebot.demo.listener": "eddiebot.core.demo_nodes:Listener",
    "eddiebot.core.lifecycle_manager": "eddiebot.core.lifecycle:LifecycleManager",
    # the base (robot/ and base/)
    "eddiebot.base.board": "eddiebot.base.board_node:BoardNode",
    "eddiebot.base.vel_controller": "eddiebot.base.vel_controller:VelocityControllerNode",
    "eddiebot.base.odometry": "eddiebot.base.odometry_node:OdometryNode",
    "eddiebot.base.range": "eddiebot.base.range_node:RangeNode",
    "eddiebot.base.safety": "eddiebot.base.safety:SafetyNode",
    "eddiebot.base.twist_mux": "eddiebot.base.twist_mux:TwistMuxNode",
    "eddiebot.base.robot_state_publisher": "eddiebot.base.robot_state_publisher:RobotStatePublisher",
    # simulator and perception
    "eddiebot.sim.simulator": "eddiebot.sim.node:SimulatorNode",
    "eddiebot.perception.depth_to_scan": "eddiebot.perception.node:DepthToScanNode",
    "eddiebot.perception.depth_to_cloud": "eddiebot.perception.node:DepthToCloudNode",
    "eddiebot.perception.image_compressor": "eddiebot.perception.compress:ImageCompressorNode",
    "eddiebot.robot.kinect": "eddiebot.robot.kinect:KinectNode",
    # mapping and navigation
    "eddiebot.slam.slam_toolbox": "eddiebot.slam.node:SlamNode",
    "eddiebot.vslam.rtabmap": "eddiebot.vslam.node:RtabmapNode",
    "eddiebot.nav.map_server": "eddiebot.nav.nodes.map_server:MapServer",
    "eddiebot.nav.map_saver": "eddiebot.nav.nodes.map_server:MapSaver",
    "eddiebot.nav.filter_mask_server": "eddiebot.nav.nodes.costmap_filters:FilterMaskServer",
    "eddiebot.nav.costmap_filter_info_server":
        "eddiebot.nav.nodes.costmap_filters:CostmapFilterInfoServer",
    "eddiebot.nav.amcl": "eddiebot.nav.nodes.amcl:AmclNode",
    "eddiebot.nav.planner_server": "eddiebot.nav.nodes.planner_server:PlannerServer",
    "eddiebot.nav.controller_server": "eddiebot.nav.nodes.controller_server:ControllerServer",
    "eddiebot.nav.smoother_server": "eddiebot.nav.nodes.smoother_server:SmootherServer",
    "eddiebot.nav.velocity_smoother": "eddiebot.nav.nodes.velocity_smoother:VelocitySmootherNode",
    "eddiebot.nav.collision_monitor": "eddiebot.nav.nodes.collision_monitor:CollisionMonitorNode",
    "eddiebot.nav.behavior_server": "eddiebot.nav.nodes.behavior_server:BehaviorServer",
    "eddiebot.nav.bt_navigator": "eddiebot.nav.nodes.bt_navigator:BtNavigator",
    "eddiebot.nav.waypoint_follower": "eddiebot.nav.nodes.waypoint_follower:WaypointFollower",
    "eddiebot.explore.explore": "eddiebot.explore.node:ExploreNode",
    # tools
    "eddiebot.bag.recorder": "eddiebot.bag.recorder:RecorderNode",
    "eddiebot.viz.recorder": "eddiebot.bag.recorder:RecorderNode",  # its name before bag/
}

__all__ = ["NODES"]
