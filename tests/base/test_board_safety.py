"""The board node's stop guarantees, on the emulator's sim clock with the wire's timing on.

Each test drives the real node against the firmware emulator through the timed in-process
link (115,200 baud, 16 ms FTDI latency, PING's 25 ms) and reads what reached the board from
the link's write log, so the times asserted are sim times at which a stop was on the wire.
"""

from __future__ import annotations

import pytest

from eddiebot.base.board_node import BoardNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.qos import qos_profile_latched
from eddiebot.msgs.eddiebot_msgs import DriveWithDistance, DriveWithSpeed, Rotate, Velocity
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.msgs.std_msgs import Bool

S = 1_000_000_000


class Rig:
    def __init__(self, **params: object) -> None:
        self.ctx = Context(use_sim_time=True)
        self.board = BoardNode(context=self.ctx,
                               parameter_overrides={"port": "emulator:1.1", **params})
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.board)
        self.probe = Node("probe", context=self.ctx)
        self.ex.add_node(self.probe)
        self.vel = self.probe.create_publisher(Velocity, "/eddie/simple_velocity", 10)
        self.estop = self.probe.create_publisher(Bool, "/e_stop", qos_profile_latched)
        self.emulator = self.ctx.resources["emulator"]
        self.link = self.ctx.resources["board_link"]
        # opening the port reboots the board (1.5 s), then the handshake and the first polls
        self.ex.spin_for(2.2)
        assert self.board.connected

    @property
    def now(self) -> int:
        return self.ctx.sim_clock.now_ns()

    def drive(self, v: float, w: float, seconds: float, rate: float = 10.0) -> int:
        """Publish (v, w) at ``rate`` for ``seconds``; the time of the last command."""
        last = self.now
        for _ in range(round(seconds * rate)):
            last = self.now
            self.vel.publish(Velocity(linear=v, angular=w))
            self.ex.spin_for(1.0 / rate)
        return last

    def stops_after(self, t_ns: int, words: tuple[bytes, ...] = (b"STOP 0", b"GOSPD 0 0")) -> list[int]:
        return [t for t, line in self.link.writes if t >= t_ns and line in words]

    def speed(self) -> float:
        return max(abs(v) for v in self.emulator.plant.wheel_velocities)

    def call(self, srv_type: object, name: str, **fields: object) -> None:
        req = srv_type.Request()  # type: ignore[attr-defined]
        for k, v in fields.items():
            setattr(req, k, v)
        self.probe.create_client(srv_type, name).call(req)  # type: ignore[arg-type]


@pytest.fixture
def rig():
    r = Rig()
    yield r
    r.ctx.shutdown()


def test_poll_rate_with_the_wire_timing(rig):
    rig.ex.spin_for(3.0)
    rate = rig.board.achieved_poll_rate()
    # DIST + PING + ADC back to back: 3 × 16 ms latency + 25 ms PING + bytes ≈ 78 ms
    assert 11.0 < rate < 14.0


def test_stale_commands_cut_power_within_the_timeout(rig):
    last = rig.drive(0.3, 0.0, 1.0)
    assert rig.speed() > 10
    rig.ex.spin_for(1.5)
    cuts = rig.stops_after(last, (b"STOP 0",))
    assert cuts, "no STOP 0 after the commands went stale"
    assert (cuts[0] - last) / S < 0.5 + 1 / 13 + 0.05
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)


def test_a_lost_stop_is_sent_again_and_confirmed(rig):
    last = rig.drive(0.3, 0.0, 1.0)
    rig.link.lose("STOP")
    rig.ex.spin_for(1.5)
    arrived = rig.stops_after(last, (b"STOP 0",))
    assert arrived, "the lost STOP was never sent again"
    assert (arrived[0] - last) / S < 1.0
    rig.ex.spin_for(2.0)
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)
    assert rig.board.stopped


def test_zero_command_holds_and_repeats_reissue(rig):
    rig.drive(0.3, 0.0, 1.0)
    t0 = rig.now
    rig.drive(0.0, 0.0, 0.1)
    holds = rig.stops_after(t0, (b"GOSPD 0 0",))
    assert holds and (holds[0] - t0) / S < 0.1
    rig.ex.spin_for(2.0)
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)
    assert rig.board.stopped
    # believed stopped: another zero command still reaches the board
    t1 = rig.now
    rig.drive(0.0, 0.0, 0.1)
    assert rig.stops_after(t1, (b"GOSPD 0 0",))


def test_gospd_only_when_the_targets_change(rig):
    t0 = rig.now
    rig.drive(0.3, 0.0, 2.0, rate=20.0)
    gospd = [line for t, line in rig.link.writes if t >= t0 and line.startswith(b"GOSPD")]
    assert len(gospd) == 1


def test_estop_cuts_power_and_services_obey_it(rig):
    rig.drive(0.3, 0.0, 1.0)
    t0 = rig.now
    rig.estop.publish(Bool(data=True))
    rig.ex.spin_for(0.3)
    cuts = rig.stops_after(t0, (b"STOP 0",))
    assert cuts and (cuts[0] - t0) / S < 0.3
    x0 = rig.emulator.plant.true_pose[0]
    rig.ex.spin_for(1.0)
    t1 = rig.now
    rig.call(DriveWithDistance, "/drive_with_distance", distance=300, speed=30)
    rig.call(Rotate, "/rotate", angle=90, speed=30)
    rig.call(DriveWithSpeed, "/drive_with_speed", left=30, right=30)
    rig.drive(0.3, 0.0, 1.0)
    motion = [line for t, line in rig.link.writes if t >= t1 and (
        line.split()[0] in (b"TRVL", b"TURN", b"GO")
        or (line.startswith(b"GOSPD") and line != b"GOSPD 0 0"))]
    assert motion == []
    assert rig.emulator.plant.true_pose[0] == pytest.approx(x0, abs=0.01)


@pytest.mark.parametrize("how", ["zero", "estop"])
def test_travel_is_stopped_by_a_zero_command_or_estop(rig, how):
    rig.call(DriveWithDistance, "/drive_with_distance", distance=300, speed=40)
    rig.ex.spin_for(1.0)  # longer than the stale timeout: TRVL is not cut by it
    assert rig.speed() > 10
    t0 = rig.now
    if how == "zero":
        rig.vel.publish(Velocity(linear=0.0, angular=0.0))
    else:
        rig.estop.publish(Bool(data=True))
    rig.ex.spin_for(0.3)
    stops = rig.stops_after(t0)
    assert stops and (stops[0] - t0) / S < 0.3
    rig.ex.spin_for(1.5)
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)


class _Wall:
    """Something 0.15 m in front of every sensor."""

    def ping_range_m(self, pin: int, time_s: float) -> float:
        return 0.15

    def adc_volts(self, channel: int, time_s: float) -> float:
        return 1.9 if channel < 3 else 12.0 / 3.21


def test_service_motion_passes_the_veto(rig):
    rig.emulator.sensors = _Wall()
    rig.ex.spin_for(0.5)
    t0 = rig.now
    rig.call(DriveWithSpeed, "/drive_with_speed", left=40, right=40)
    rig.call(DriveWithDistance, "/drive_with_distance", distance=200, speed=40)
    rig.ex.spin_for(1.0)
    assert not [line for t, line in rig.link.writes
                if t >= t0 and (line.startswith(b"TRVL") or line == b"GOSPD 28 28")]
    assert rig.emulator.plant.true_pose[0] == pytest.approx(0.0, abs=0.005)
    # turning away is still allowed
    rig.call(Rotate, "/rotate", angle=90, speed=30)
    rig.ex.spin_for(2.0)
    assert abs(rig.emulator.plant.true_pose[2]) > 0.5


def test_a_mute_board_does_not_delay_the_stale_stop(rig):
    last = rig.drive(0.3, 0.0, 1.0)
    rig.link.mute = True  # every poll from now on times out
    rig.ex.spin_for(1.0)
    written = [t for t in rig.board._stop_wire_ns if t >= last]
    assert written and (written[0] - last) / S < 0.7
    rig.link.mute = False
    rig.ex.spin_for(2.0)
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)


def test_joint_states_stay_continuous_across_a_board_reboot(rig):
    joints: list[JointState] = []
    rig.probe.create_subscription(JointState, "/joint_states", joints.append, 50)
    rig.drive(0.3, 0.0, 2.0)
    rig.drive(0.0, 0.0, 0.1)
    rig.ex.spin_for(1.0)
    before = joints[-1].position.copy()
    rig.emulator.reboot(rig.now)  # counters zeroed, deaf while it boots
    rig.ex.spin_for(3.0)
    after = joints[-1].position
    assert before[0] > 5.0
    assert after[0] == pytest.approx(before[0], abs=0.2)
    assert after[1] == pytest.approx(before[1], abs=0.2)


def test_diagnostics_battery_and_a_low_battery_stop(rig):
    from eddiebot.msgs.diagnostic_msgs import DiagnosticArray
    from eddiebot.msgs.sensor_msgs import BatteryState

    diags: list[DiagnosticArray] = []
    batteries: list[BatteryState] = []
    rig.probe.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    rig.probe.create_subscription(BatteryState, "/battery_state", batteries.append, 10)
    rig.drive(0.3, 0.0, 1.5)
    status = diags[-1].status[0]
    values = {kv.key: kv.value for kv in status.values}
    assert status.level == status.OK
    assert values["link"] == "connected" and values["firmware"] == "1.1"
    assert 11.0 < float(values["poll rate achieved (Hz)"]) < 14.0
    assert batteries[-1].voltage == pytest.approx(12.6, abs=0.05)
    # the battery sags below the cut-off while driving: STOP 0, and no motion until it recovers
    rig.emulator.sensors.battery_v = 10.2
    t0 = rig.now
    rig.drive(0.3, 0.0, 1.0)
    assert rig.stops_after(t0, (b"STOP 0",))
    assert rig.speed() == pytest.approx(0.0, abs=1e-6)
    assert diags[-1].status[0].level == status.ERROR
    rig.emulator.sensors.battery_v = 12.4
    rig.ex.spin_for(0.5)
    rig.drive(0.3, 0.0, 1.0)
    assert rig.speed() > 10


def test_param_set_is_honoured_or_refused(rig):
    from eddiebot.core.parameters import Parameter

    ok = rig.board.set_parameters_atomically([Parameter("cmd_timeout", 1.0)])
    assert ok.successful and rig.board.cmd_timeout_ns == 1_000_000_000
    assert rig.board.set_parameters_atomically([Parameter("veto_distance", 0.4)]).successful
    assert rig.board.veto.veto_distance == 0.4
    refused = rig.board.set_parameters_atomically([Parameter("counts_per_rev", 144)])
    assert not refused.successful and "read-only" in refused.reason
    acc0 = rig.board.set_parameters_atomically([Parameter("acceleration_rate", 0)])
    assert not acc0.successful and "ACC 0" in acc0.reason
    t0 = rig.now
    assert rig.board.set_parameters_atomically([Parameter("acceleration_rate", 100)]).successful
    rig.ex.spin_for(0.3)
    assert any(line == b"ACC 64" for t, line in rig.link.writes if t >= t0)


def test_counts_per_rev_reaches_speed_and_odometry():
    rig = Rig(counts_per_rev=144)
    try:
        # a 144-count board: the same 0.3 m/s must be 4x the positions/s of a 36-count one
        rig.emulator.plant.config.counts_per_rev = 144  # the board really has 144 counts
        joints: list[JointState] = []
        rig.probe.create_subscription(JointState, "/joint_states", joints.append, 50)
        t0 = rig.now
        rig.drive(0.3, 0.0, 1.0)
        gospd = [line for t, line in rig.link.writes if t >= t0 and line.startswith(b"GOSPD")]
        # 0.3 m/s / (2π · 0.0762 m / 144) = 90.2 positions/s → capped at 2.5 rev/s = 360
        assert gospd[0] == b"GOSPD 5A 5A"
        assert joints[-1].position[0] > 0
    finally:
        rig.ctx.shutdown()


def test_a_missing_port_is_reported_once(caplog):
    import logging

    ctx = Context()
    caplog.set_level(logging.WARNING)
    node = BoardNode(context=ctx, parameter_overrides={"port": "/dev/ttyUSB_not_here"})
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    import time

    end = time.monotonic() + 2.5
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    ctx.shutdown()
    errors = [r for r in caplog.records if "ttyUSB_not_here" in r.getMessage()]
    assert len(errors) == 1
    assert "dialout" in errors[0].getMessage() and "ls /dev/ttyUSB*" in errors[0].getMessage()


def test_an_obstacle_during_travel_stops_it(rig):
    rig.call(DriveWithDistance, "/drive_with_distance", distance=300, speed=40)
    rig.ex.spin_for(1.0)
    assert rig.speed() > 10
    t0 = rig.now
    rig.emulator.sensors = _Wall()
    rig.ex.spin_for(0.5)
    stops = rig.stops_after(t0, (b"STOP 0",))
    # the wall is seen at the next PING/ADC poll; the IR is debounced over two samples
    assert stops and (stops[0] - t0) / S < 0.3
