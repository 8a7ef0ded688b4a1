"""`eddie nav`'s launch (nav_sim: simulator + base + AMCL + Nav2 servers) in one process."""

import math
import time

import pytest
from navnodes_stub import room_map

from eddiebot.cli.nav import resolve_params
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.action import ActionClient, GoalStatus
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.maps import save_map
from eddiebot.msgs.nav2_msgs import NavigateToPose
from eddiebot.nav.nodes._common import pose_stamped
from eddiebot.registry import NODES


@pytest.fixture
def sim_stack(tmp_path):
    from eddiebot.sim.worlds import load_world

    map_yaml = save_map(room_map(), tmp_path / "room")
    start = load_world(map_yaml).start
    params = resolve_params(find_launch_file("nav").parents[1] / "config" / "nav2.yaml", tmp_path,
                            tuple(start))
    ctx = Context(use_sim_time=True)
    desc = parse_launch_file(find_launch_file("nav_sim"), {
        "world": str(map_yaml), "map": str(map_yaml), "params_file": str(params),
        "camera_rate": "5.0", "camera_width": "160", "camera_height": "120"})
    nodes = build_nodes(desc, ctx, NODES)
    ex = SingleThreadedExecutor(context=ctx)
    probe = Node("probe", context=ctx)
    for n in (*nodes, probe):
        ex.add_node(n)
    yield ctx, ex, probe, start
    ctx.shutdown()


def test_simulated_robot_reaches_a_goal(sim_stack):
    ctx, ex, probe, start = sim_stack
    tf = Buffer(node=probe)
    TransformListener(tf, probe)
    ex.spin_for(2.0)
    for _ in range(60):  # a goal starts once the robot is localised (map -> base_footprint)
        try:
            tf.lookup_pose2d("map", "base_footprint", 0)
            break
        except TransformException:
            ex.spin_for(0.5)
    client = ActionClient(probe, NavigateToPose, "/navigate_to_pose")
    gx, gy = (1.4, 4.2) if start[1] < 3.0 else (1.4, 1.6)
    fb = []
    future = client.send_goal_async(NavigateToPose.Goal(pose=pose_stamped(gx, gy, 0.0, "map")),
                                    feedback_callback=fb.append)
    ex.spin_for(0.5)
    handle = future.result()
    assert handle.accepted
    result = handle.get_result_async()
    wall = time.monotonic()
    t = 0.0
    while not result.done() and t < 90.0:
        ex.spin_for(0.5)
        t += 0.5
    sim = ctx.resources["simulator"]
    print(f"start {start}, goal ({gx}, {gy}), {t:.1f} s sim, {time.monotonic() - wall:.1f} s wall, "
          f"truth ({sim.state.x:.2f}, {sim.state.y:.2f})")
    for f in fb[::40]:
        print(f.feedback.navigation_time.sec, f.feedback.distance_remaining,
              f.feedback.number_of_recoveries)
    assert result.done()
    assert result.result().status == GoalStatus.STATUS_SUCCEEDED, result.result().result.error_msg
    assert math.hypot(sim.state.x - gx, sim.state.y - gy) < 0.4
