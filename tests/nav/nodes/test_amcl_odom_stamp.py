"""AMCL pairs each scan with odometry at the scan's stamp (Nav2's tf2 MessageFilter).

When a scan arrives before the ``odom → base`` transform at its stamp (the camera and the
odometry tick together; the scan callback runs first), the scan waits for that transform
instead of using an older one, so ``map → odom`` carries no lag error.
"""

import math

import numpy as np
from navnodes_stub import room_map

from eddiebot.core import Context
from eddiebot.core.tf import make_transform_2d
from eddiebot.maps import map_to_msg
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.nav.nodes.amcl import AmclNode

MS = 1_000_000


def _scan(stamp_ns: int) -> LaserScan:
    msg = LaserScan()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.header.frame_id = "laser"
    msg.angle_min, msg.angle_increment = -0.5, 0.01
    msg.range_min, msg.range_max = 0.1, 8.0
    msg.ranges = np.full(101, np.nan, dtype=np.float32)  # no information: odometry decides
    return msg


def _odom(node: AmclNode, stamp_ns: int, x: float) -> None:
    node.tf_buffer.set_transform(make_transform_2d("odom", "base_footprint", stamp_ns, x, 0.0, 0.0))


def test_scan_waits_for_odometry_at_its_stamp() -> None:
    ctx = Context(use_sim_time=True)
    node = AmclNode(context=ctx, parameter_overrides={
        "set_initial_pose": True, "initial_pose.x": 1.0, "initial_pose.y": 1.0,
        "random_seed": 3, "max_particles": 200, "min_particles": 100,
        "alpha1": 0.0, "alpha2": 0.0, "alpha3": 0.0, "alpha4": 0.0,
        "update_min_d": 0.1, "tf_broadcast": False})
    try:
        assert node.trigger_configure() == 97 and node.trigger_activate() == 97
        node.tf_buffer.set_transform_static(make_transform_2d("base_footprint", "laser", 0, 0.0, 0.0, 0.0))
        node._on_map(map_to_msg(room_map(box=None)))
        assert node.amcl is not None
        node.amcl.initialize((1.0, 1.0, 0.0), np.diag([1e-6, 1e-6, 1e-8]))
        _odom(node, 0, 0.0)
        _odom(node, 50 * MS, 0.2)
        node._on_scan(_scan(50 * MS))
        # robot drives at 4 m/s in odom: x(t) = 4 t; the scan at 100 ms comes before its odometry
        node._on_scan(_scan(100 * MS))
        assert len(node._pending) == 1  # waits rather than pairing with odometry at 50 ms
        _odom(node, 100 * MS, 0.4)
        node._drain()
        assert not node._pending
        odom_last = node.amcl._odom_last
        assert odom_last is not None and math.isclose(float(odom_last[0]), 0.4)
        mo = node._map_to_odom
        assert mo is not None
        est, _ = node.amcl.estimate
        # map → odom composed with odom → base at the scan's stamp gives the estimate
        assert math.isclose(mo[0] + 0.4, est[0], abs_tol=1e-9)
        assert abs(est[0] - 1.2) < 0.02 and abs(est[1] - 1.0) < 0.02
        # a scan whose odometry never comes is dropped after transform_tolerance
        node._on_scan(_scan(150 * MS))
        assert len(node._pending) == 1
        ctx.sim_clock.set_ns(1300 * MS)
        node._drain()
        assert not node._pending
        assert math.isclose(float(node.amcl._odom_last[0]), 0.4)
    finally:
        ctx.shutdown()
