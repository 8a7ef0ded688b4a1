"""A square driven through the whole base stack against the ideal plant closes within the
encoder quantisation bound, and odometry agrees with the emulator's continuous truth."""

import math

from eddiebot.core import Context, SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.demo.square import SquareDriver
from eddiebot.geometry import wrap_angle
from eddiebot.registry import NODES


def test_square_closes_within_quantisation_bound():
    ctx = Context(use_sim_time=True)
    desc = parse_launch_file(find_launch_file("bringup"), {"port": "emulator:1.1", "use_sim_time": "true"})
    nodes = build_nodes(desc, ctx, NODES)
    emulator = ctx.resources["emulator"]
    driver = SquareDriver(lambda: emulator.plant.true_pose, side=1.0, context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    for n in [*nodes, driver]:
        ex.add_node(n)
    for _ in range(120):
        ex.spin_for(1.0)
        if driver.done.is_set():
            break
    assert driver.done.is_set()
    assert len(driver.corners) == 4
    for c in driver.corners:
        # one count of wheel difference is 1.95°; a few counts of position error at most
        assert c.position_error < 0.04
        assert c.heading_error < math.radians(4.0)
    x, y, th = driver.corners[-1].truth
    assert math.hypot(x, y) < 0.05  # back at the start
    assert abs(float(wrap_angle(th + math.pi / 2))) < math.radians(5)  # facing -y after 3 turns
    ctx.shutdown()
