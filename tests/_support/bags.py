"""A talker and a recording of it, for the rosbag2 tests (tests/bag) and their neighbours."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eddiebot.bag import BagReader, RecorderNode
from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import OccupancyGrid, Odometry
from eddiebot.msgs.sensor_msgs import LaserScan

NS = 1_000_000_000
T0 = 5 * NS  # sim clock start: recordings do not begin at zero
#: Every node offers /parameter_events; these tests record only the talker's topics.
EXCLUDE = ["^/parameter_events$", "^/rosout$"]


class Talker(Node):
    """Publishes /odom at 10 Hz and /scan at 5 Hz, latches /map once, and starts /cmd_vel
    (a topic that appears later) at t0 + 1 s."""

    def __init__(self, context: Context) -> None:
        super().__init__("talker", context=context)
        self.odom = self.create_publisher(Odometry, "/odom", 10)
        self.scan = self.create_publisher(LaserScan, "/scan", 5)
        self.map = self.create_publisher(OccupancyGrid, "/map", qos_profile_latched)
        self.cmd = None
        self.n = 0
        grid = OccupancyGrid()
        grid.info.width, grid.info.height, grid.info.resolution = 4, 3, 0.05
        grid.data = np.array([0, 100, -1, 0] * 3, dtype=np.int8)
        self.map.publish(grid)
        self.create_timer(0.1, self._tick)

    def _tick(self) -> None:
        self.n += 1
        odom = Odometry(child_frame_id="base_footprint")
        odom.header.frame_id = "odom"
        odom.header.stamp = self.get_clock().now().to_msg()
        odom.pose.pose.position.x = 0.01 * self.n
        self.odom.publish(odom)
        if self.n % 2 == 0:
            self.scan.publish(LaserScan(ranges=np.full(8, 1.0 + self.n, np.float32)))
        if self.n == 10:
            self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        if self.cmd is not None and self.n > 11:
            self.cmd.publish(Twist())


def record_talker(bag: Path, seconds: float = 2.0) -> None:
    """Record the talker's topics to ``bag`` for ``seconds`` of sim time from ``T0``."""
    ctx = Context(use_sim_time=True)
    ctx.sim_clock.set_ns(T0)
    talker = Talker(ctx)
    rec = RecorderNode(context=ctx, parameter_overrides={"output": str(bag), "all": True,
                                                         "exclude": EXCLUDE,
                                                         "polling_interval": 0.05})
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(talker)
    ex.add_node(rec)
    ex.spin_for(seconds)
    rec.destroy_node()
    ctx.shutdown()


def read_bag(bag: Path) -> list[tuple[str, int, bytes]]:
    """Every message of ``bag`` as (topic, receive time in ns, CDR bytes), in order."""
    with BagReader(bag) as reader:
        return [(m.topic, m.timestamp, m.data) for m in reader.messages()]
