"""The board node over a real serial path (pyserial on a pty, the wire's timing on, the
DTR reboot on open) with faults on the wire: the stops still arrive, odometry stays whole.

Wall-clock tests: the bounds are generous (the figures are in docs/benchmarks/robot.md);
the exact times are asserted on the sim clock in test_board_safety.py.
"""

from __future__ import annotations

import threading
import time

import pytest

from eddiebot.base.board_node import BoardNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs.eddiebot_msgs import Velocity
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.robot.fault_pty import FaultyPtyBoard


class PtyRig:
    def __init__(self, tmp_path) -> None:
        self.wire = FaultyPtyBoard(directory=tmp_path)
        self.ctx = Context()
        self.node = BoardNode(context=self.ctx, parameter_overrides={"port": self.wire.port})
        self.probe = Node("probe", context=self.ctx)
        self.vel = self.probe.create_publisher(Velocity, "/eddie/simple_velocity", 10)
        self.joints: list[JointState] = []
        self.probe.create_subscription(JointState, "/joint_states", self.joints.append, 100)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.ex.add_node(self.probe)
        self.thread = threading.Thread(target=self.ex.spin, daemon=True)
        self.thread.start()
        assert self.wire.first((b"DIST",), 0.0, 30.0) is not None, "the driver never polled"
        time.sleep(0.5)

    def drive(self, seconds: float) -> float:
        last = time.monotonic()
        end = last + seconds
        while time.monotonic() < end:
            last = time.monotonic()
            self.vel.publish(Velocity(linear=0.2, angular=0.0))
            time.sleep(0.1)
        return last

    def close(self) -> None:
        self.ex.shutdown()
        self.ctx.shutdown()
        self.thread.join(5.0)
        self.wire.close()


@pytest.fixture
def rig(tmp_path):
    r = PtyRig(tmp_path)
    yield r
    r.close()


def test_a_lost_stop_is_resent_over_the_serial_link(rig):
    rig.wire.lose(b"STOP 0")
    last = rig.drive(1.0)
    first = rig.wire.first((b"STOP 0",), last)
    assert first is not None
    again = rig.wire.first((b"STOP 0",), first + 1e-6)
    assert again is not None, "the lost STOP was never sent again"
    assert again - last < 1.5  # 0.85 s on an idle machine
    time.sleep(1.5)
    assert max(abs(v) for v in rig.wire.emulator.plant.wheel_velocities) < 1e-6


def test_a_mute_board_does_not_hold_up_the_stop(rig):
    last = rig.drive(1.0)
    rig.wire.mute = True
    written = rig.wire.first((b"STOP 0",), last, timeout_s=3.0)
    assert written is not None and written - last < 1.0  # 0.53 s on an idle machine
    rig.wire.mute = False
    time.sleep(1.5)
    assert max(abs(v) for v in rig.wire.emulator.plant.wheel_velocities) < 1e-6


def test_a_vanishing_port_comes_back_stopped_with_odometry_whole(rig):
    rig.drive(1.5)
    rig.vel.publish(Velocity(linear=0.0, angular=0.0))
    time.sleep(1.0)
    before = rig.joints[-1].position.copy()
    assert before[0] > 3.0
    rig.wire.vanish()
    time.sleep(1.0)
    back = time.monotonic()
    rig.wire.restore()  # a new pty: the open reboots the board, its counters read 0
    assert rig.wire.first((b"STOP 0",), back, timeout_s=10.0) is not None
    assert rig.wire.first((b"DIST",), back, timeout_s=10.0) is not None
    time.sleep(1.0)
    after = rig.joints[-1].position
    assert after[0] == pytest.approx(before[0], abs=0.2)
    assert after[1] == pytest.approx(before[1], abs=0.2)
