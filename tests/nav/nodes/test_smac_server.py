"""The planner server runs SmacPlannerHybrid from a Nav2 parameters file, with the global
costmap's (rectangular) footprint."""

from __future__ import annotations

import math

from eddiebot.core.action import ActionClient
from eddiebot.msgs.nav2_msgs import ComputePathToPose
from eddiebot.nav.nodes._common import pose_stamped
from eddiebot.nav.planners.smac import SmacPlannerHybrid


def test_planner_server_plans_with_smac_hybrid_and_the_footprint(make_stack, nav_stub_params):
    doc = nav_stub_params()
    ps = doc["planner_server"]["ros__parameters"]
    ps.pop("ThetaStar")
    ps["planner_plugins"] = ["GridBased"]
    ps["GridBased"] = {"plugin": "nav2_smac_planner::SmacPlannerHybrid",
                       "motion_model_for_search": "REEDS_SHEPP", "minimum_turning_radius": 0.3,
                       "smoother": {"max_iterations": 500}}
    gc = ps["global_costmap"]
    del gc["robot_radius"]
    gc["footprint"] = "[[0.25, 0.15], [0.25, -0.15], [-0.25, -0.15], [-0.25, 0.15]]"
    stack = make_stack(servers=("map_server", "planner_server"), params=doc)
    planner = stack.nodes["planner_server"].planners["GridBased"]
    assert isinstance(planner, SmacPlannerHybrid)
    assert planner.config.smoother.max_iterations == 500
    client = ActionClient(stack.probe, ComputePathToPose, "/compute_path_to_pose")
    fut = client.send_goal_async(ComputePathToPose.Goal(goal=pose_stamped(4.5, 1.0, 0.0, "map")))
    stack.spin(0.5)
    res = fut.result().get_result_async()
    stack.spin(3.0)
    result = res.result().result
    assert result.error_code == 0, result.error_msg
    poses = result.path.poses
    assert len(poses) > 10
    end = poses[-1].pose.position
    assert math.hypot(end.x - 4.5, end.y - 1.0) < 1e-6
    # the planner checked the rectangle (padded by footprint_padding), not a circle
    assert not planner.use_radius and planner.footprint is not None
    assert planner.footprint.shape == (4, 2)
    assert planner.footprint[:, 0].max() > 0.25
