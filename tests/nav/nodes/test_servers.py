"""Single servers: velocity smoother limits, collision monitor, lifecycle errors, lost TF."""


import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav2_msgs import ComputePathToPose, FollowPath
from eddiebot.nav.nodes._common import pose_stamped
from eddiebot.nav.nodes.controller_server import ControllerServer
from eddiebot.nav.nodes.velocity_smoother import VelocitySmootherNode


def _twist(vx, wz=0.0):
    t = Twist()
    t.linear.x, t.angular.z = vx, wz
    return t


def test_velocity_smoother_obeys_accel_limits():
    ctx = Context(use_sim_time=True)
    ex = SingleThreadedExecutor(context=ctx)
    node = VelocitySmootherNode(context=ctx, remappings={"/cmd_vel": "/cmd_vel_nav"},
                                parameter_overrides={"max_accel": [0.8, 0.0, 2.0],
                                                     "max_decel": [-1.0, 0.0, -2.5],
                                                     "max_velocity": [0.5, 0.0, 1.5],
                                                     "min_velocity": [-0.3, 0.0, -1.5]})
    probe = Node("probe", context=ctx)
    out = []
    probe.create_subscription(Twist, "/cmd_vel_smoothed", out.append, 100)
    pub = probe.create_publisher(Twist, "/cmd_vel_nav", 10)
    for n in (node, probe):
        ex.add_node(n)
    assert node.trigger_configure() == 97 and node.trigger_activate() == 97
    for _ in range(40):  # 2 s of a 1 m/s, 3 rad/s request
        pub.publish(_twist(1.0, 3.0))
        ex.spin_for(0.05)
    vx = [m.linear.x for m in out]
    wz = [m.angular.z for m in out]
    assert max(vx) == 0.5 and max(wz) == 1.5  # clamped to max_velocity
    steps = [b - a for a, b in zip(vx, vx[1:])]
    assert max(steps) <= 0.8 / 20 + 1e-9  # accel 0.8 m/s² at 20 Hz
    assert max(b - a for a, b in zip(wz, wz[1:])) <= 2.0 / 20 + 1e-9
    n = len(out)
    for _ in range(20):
        pub.publish(_twist(0.0))
        ex.spin_for(0.05)
    down = [m.linear.x for m in out[n - 1:]]
    assert min(b - a for a, b in zip(down, down[1:])) >= -1.0 / 20 - 1e-9
    assert down[-1] == 0.0
    ctx.shutdown()


def test_velocity_smoother_warns_about_slow_smoothing():
    ctx = Context(use_sim_time=True)
    node = VelocitySmootherNode(context=ctx, parameter_overrides={"smoothing_frequency": 1.0})
    assert node.trigger_configure() == 97
    assert any("stale-command timeout 0.5" in w for w in node.warnings)
    ctx.shutdown()


def test_bad_parameter_fails_configure_naming_server_and_key():
    ctx = Context(use_sim_time=True)
    node = VelocitySmootherNode(context=ctx, parameter_overrides={"max_decel": [2.5, 0.0, -3.2]})
    assert node.trigger_configure() == 98  # FAILURE
    assert node.current_state.label == "unconfigured"
    assert "velocity_smoother" in node.last_error and "max_decel" in node.last_error
    ctrl = ControllerServer(context=ctx, parameter_overrides={
        "controller_plugins": ["FollowPath"], "FollowPath.plugin": "nav2_nope::Nope"})
    assert ctrl.trigger_configure() == 98
    assert "controller_server" in ctrl.last_error and "FollowPath.plugin" in ctrl.last_error
    ctx.shutdown()


def test_collision_monitor_stops_before_obstacle(make_stack):
    # No box: drive straight at the east wall with teleop-like commands into the chain.
    stack = make_stack(servers=("velocity_smoother", "collision_monitor"), start=(3.0, 3.0, 0.0),
                       box=None)
    pub = stack.probe.create_publisher(Twist, "/cmd_vel_nav", 10)
    for _ in range(150):  # 15 s at 0.4 m/s would cross the wall
        pub.publish(_twist(0.4))
        stack.spin(0.1)
    x = stack.robot.pose[0]
    wall = 6.0 - 0.1  # inner face of the east wall
    assert x < wall - 0.23  # the footprint (r 0.23 m) never touched the wall
    assert wall - x < 0.6  # it drove most of the way first
    assert stack.nodes["collision_monitor"].last_action == "StopZone"
    assert stack.robot.cmd == (0.0, 0.0)


def _plan(stack, x: float, y: float):
    """A path from the planner server to (x, y) in the map frame."""
    plan = ActionClient(stack.probe, ComputePathToPose, "/compute_path_to_pose")
    fut = plan.send_goal_async(ComputePathToPose.Goal(goal=pose_stamped(x, y, 0.0, "map")))
    stack.spin(0.5)
    res = fut.result().get_result_async()
    stack.spin(0.5)
    return res.result().result.path


def _following(make_stack, drive_s):
    """A controller server following a planned path for ``drive_s`` s, the stub robot driven
    by it directly: (stack, the goal handle's future, the commands published)."""
    stack = make_stack(servers=("map_server", "planner_server", "controller_server"))
    cmds = []
    stack.probe.create_subscription(Twist, "/cmd_vel_nav", cmds.append, 100)
    follow = ActionClient(stack.probe, FollowPath, "/follow_path")
    path = _plan(stack, 4.5, 1.0)
    stack.robot.destroy_subscription(stack.robot.subscriptions[-1])
    stack.robot.create_subscription(Twist, "/cmd_vel_nav", stack.robot._on_cmd, 10)
    h = follow.send_goal_async(FollowPath.Goal(path=path))
    stack.spin(drive_s)
    assert any(abs(c.linear.x) > 0.1 for c in cmds)
    return stack, h, cmds


def test_lost_tf_makes_the_controller_publish_zero(make_stack):
    stack, h, cmds = _following(make_stack, 3.0)
    stack.robot.publish_tf = False
    n = len(cmds)
    stack.spin(1.5)
    assert cmds[-1].linear.x == 0.0 and cmds[-1].angular.z == 0.0
    assert len(cmds) > n
    result = h.result().get_result_async()
    stack.spin(0.2)
    assert not result.done()  # held: a stale pose is a TF error after localization_lost_timeout
    stack.spin(1.0)
    assert result.done()
    assert result.result().status == GoalStatus.STATUS_ABORTED
    assert result.result().result.error_code == 102  # TF_ERROR
    assert stack.robot.cmd == (0.0, 0.0)


def test_a_pose_stale_for_a_moment_holds_the_robot_and_the_goal_goes_on(make_stack):
    """The driver's TF late by a few tenths of a second (a loaded machine) holds the robot
    at zero; the goal is not aborted, and the robot drives on once the pose is fresh."""
    stack, h, cmds = _following(make_stack, 2.0)
    stack.robot.publish_tf = False
    stack.spin(0.8)  # past transform_tolerance (0.3 s), within localization_lost_timeout
    assert cmds[-1].linear.x == 0.0 and cmds[-1].angular.z == 0.0
    stack.robot.publish_tf = True
    n = len(cmds)
    stack.spin(1.0)
    result = h.result().get_result_async()
    assert not result.done()
    assert any(abs(c.linear.x) > 0.1 for c in cmds[n:])


def test_lost_localization_holds_then_aborts_the_goal(make_stack, nav_stub_params):
    from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

    doc = nav_stub_params()
    doc["controller_server"]["ros__parameters"]["localization_check"] = True
    stack = make_stack(servers=("map_server", "planner_server", "controller_server"), params=doc)
    cmds = []
    stack.probe.create_subscription(Twist, "/cmd_vel_nav", cmds.append, 100)
    amcl = stack.probe.create_publisher(PoseWithCovarianceStamped, "amcl_pose", 1)
    confident = PoseWithCovarianceStamped()
    confident.pose.covariance[0] = confident.pose.covariance[7] = 0.01
    confident.pose.covariance[35] = 0.01
    amcl.publish(confident)
    follow = ActionClient(stack.probe, FollowPath, "/follow_path")
    h = follow.send_goal_async(FollowPath.Goal(path=_plan(stack, 4.5, 1.0)))
    stack.spin(1.5)
    assert any(abs(c.linear.x) > 0.1 for c in cmds)  # confident: it drives
    lost = PoseWithCovarianceStamped()
    lost.pose.covariance[0] = lost.pose.covariance[7] = 0.8**2  # 0.8 m std > 0.5
    lost.pose.covariance[35] = 0.01
    amcl.publish(lost)
    stack.spin(1.0)
    assert cmds[-1].linear.x == 0.0 and cmds[-1].angular.z == 0.0  # held, not yet aborted
    result = h.result().get_result_async()
    assert not result.done()
    stack.spin(1.5)  # past localization_lost_timeout (2 s)
    assert result.done()
    assert result.result().status == GoalStatus.STATUS_ABORTED
    assert result.result().result.error_code == 102  # TF_ERROR
    assert "localization lost" in result.result().result.error_msg


def test_is_path_valid_finds_the_first_blocked_pose(make_stack):
    """Nav2's is_path_valid: a planned path is valid; a straight line through the box is
    invalid at the first pose in the box's inscribed zone, counted from the robot's pose."""
    from eddiebot.msgs.nav2_msgs import IsPathValid
    from eddiebot.msgs.nav_msgs import Path

    stack = make_stack(servers=("map_server", "planner_server"))
    client = stack.probe.create_client(IsPathValid, "/is_path_valid")

    def check(path):
        fut = client.call_async(IsPathValid.Request(path=path))
        stack.spin(0.3)
        return fut.result()

    planned = _plan(stack, 4.5, 1.0)
    assert len(planned.poses) > 10
    assert check(planned).is_valid
    line = Path()
    line.header.frame_id = "map"
    line.poses = [pose_stamped(1.0 + 0.1 * i, 3.0, 0.0, "map") for i in range(41)]
    answer = check(line)
    assert not answer.is_valid
    (index,) = answer.invalid_pose_indices
    # the box starts at x = 2.6 (index 16); its inscribed zone reaches a robot radius before
    assert 12 <= index <= 16
    # poses behind the robot's closest pose are not checked
    back = Path()
    back.header.frame_id = "map"
    back.poses = [pose_stamped(3.0, 3.0, 0.0, "map"), pose_stamped(1.0, 1.0, 0.0, "map"),
                  pose_stamped(1.5, 1.0, 0.0, "map")]
    assert check(back).is_valid


def test_the_planner_plans_from_the_latest_pose_however_old(make_stack):
    """As Nav2's planner (Costmap2DROS::getRobotPose: the latest transform, the tolerance a
    wait): a robot pose older than transform_tolerance still plans; the controller, which
    drives on it, refuses it (test above)."""
    stack = make_stack(servers=("map_server", "planner_server"))
    stack.spin(0.5)
    stack.robot.publish_tf = False
    stack.spin(1.0)  # the latest robot pose is now 1 s old (transform_tolerance 0.3 s)
    host = stack.nodes["planner_server"].host
    assert host.robot_pose() is None
    path = _plan(stack, 4.5, 1.0)
    assert len(path.poses) > 10
    end = path.poses[-1].pose.position
    assert (end.x, end.y) == pytest.approx((4.5, 1.0), abs=0.05)
