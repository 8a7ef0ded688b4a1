"""AMCL and the map server/saver nodes."""

import math

from eddiebot.core.action import GoalStatus
from eddiebot.maps import load_map
from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
from eddiebot.msgs.nav2_msgs import SaveMap
from eddiebot.nav.nodes._common import pose_from_msg
from eddiebot.nav.nodes.map_server import MAP_QOS, MapSaver, MapServer


def test_amcl_localises_and_the_robot_navigates(make_stack):
    from _support.nav_actions import navigate

    stack = make_stack(start=(1.0, 1.0, 0.0), amcl_pose=(1.25, 0.85, 0.15))
    # set_initial_pose (as Nav2) puts every particle on the given pose; an operator's
    # /initialpose with RViz's covariance spreads them so the scans can pull them in.
    assert stack.nodes["amcl"].amcl.particles[:, :2].std(axis=0).max() < 1e-9
    init = PoseWithCovarianceStamped()
    init.header.frame_id = "map"
    init.pose.pose.position.x, init.pose.pose.position.y = 1.25, 0.85
    init.pose.pose.orientation.z, init.pose.pose.orientation.w = math.sin(0.075), math.cos(0.075)
    cov = [0.0] * 36
    cov[0] = cov[7] = 0.25
    cov[35] = 0.0685
    init.pose.covariance = cov
    stack.nodes["amcl"]._on_initial_pose(init)  # what a /initialpose message does
    assert stack.nodes["amcl"].amcl.particles[:, :2].std(axis=0).min() > 0.3
    poses = []
    stack.probe.create_subscription(PoseWithCovarianceStamped, "/amcl_pose", poses.append, MAP_QOS)
    nav = stack.nodes["bt_navigator"]
    for _ in range(100):  # a goal starts once AMCL gives map -> odom
        if nav._robot_pose_in() is not None:
            break
        stack.spin(0.1)
    _, res = navigate(stack, 4.5, 1.2, 0.0)
    assert res.status == GoalStatus.STATUS_SUCCEEDED, res.result.error_msg
    assert len(poses) > 3
    first = pose_from_msg(poses[0].pose.pose)
    assert math.hypot(first[0] - 1.0, first[1] - 1.0) < 0.35
    est = stack.nodes["amcl"].tf_buffer.lookup_pose2d("map", "base_footprint", 0)
    x, y, th = stack.robot.pose
    assert math.hypot(est[0] - x, est[1] - y) < 0.15
    assert abs(math.remainder(est[2] - th, 2 * math.pi)) < 0.1
    assert math.hypot(x - 4.5, y - 1.2) < 0.45  # goal tolerance 0.25 + localisation error
    mo = stack.nodes["amcl"].tf_buffer.lookup_pose2d("map", "odom", 0)
    assert math.hypot(mo[0] - 1.0, mo[1] - 1.0) < 0.2


def test_map_server_bad_file_fails_configure(tmp_path):
    from eddiebot.core import Context

    ctx = Context(use_sim_time=True)
    node = MapServer(context=ctx, parameter_overrides={"yaml_filename": str(tmp_path / "none.yaml")})
    assert node.trigger_configure() == 98
    assert "map_server" in node.last_error and "yaml_filename" in node.last_error
    ctx.shutdown()


def test_map_saver_writes_the_published_map(make_stack, tmp_path):
    stack = make_stack(servers=("map_server",))
    saver = MapSaver(context=stack.ctx)
    stack.ex.add_node(saver)
    assert saver.trigger_configure() == 97 and saver.trigger_activate() == 97
    client = stack.probe.create_client(SaveMap, "/map_saver/save_map")
    req = SaveMap.Request(map_topic="map", map_url=str(tmp_path / "saved"), image_format="pgm",
                          map_mode="trinary", free_thresh=0.25, occupied_thresh=0.65)
    fut = client.call_async(req)
    stack.spin(0.2)
    assert fut.result().result
    saved = load_map(tmp_path / "saved.yaml")
    assert (saved.data == stack.map.data).all()
