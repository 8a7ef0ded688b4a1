"""The board node: Eddie's control board on the graph, and the last guard before the motors.

FW 1.1 has no watchdog: once a ``GOSPD`` is on the board the wheels turn until another
command arrives. So this node treats every stop as unfinished until the board confirms it:

- **Stops are confirmed.** A stop counts as done only when its reply arrives. One whose
  reply is missing or garbled is sent again as soon as the reply is overdue
  (``reply_timeout``) and at every poll until a reply arrives; after that the polled ``SPD``
  must reach 0 0 within the ramp time the last speed and ``ACC`` imply plus 0.5 s (SPD is a
  0.5 s average), or ``STOP 0`` goes out again. A zero command, an e-stop, the stale timer,
  the veto and the low-battery cut each re-issue their stop even when the node believes the
  robot is stopped.
- **Which stop.** A zero velocity from any source sends ``GOSPD 0 0`` (a closed-loop hold,
  ramped at ACC: an 11.5 kg robot does not roll down a ramp); stale commands, ``/e_stop``,
  the IR/PING veto, a link that comes back, a low battery and shutdown send ``STOP 0``
  (power cut).
- **Serial work is off the executor.** Requests go through a queue (:mod:`board_io`); a
  stop jumps it and abandons a poll in flight, so a mute board does not delay a stop; the
  abandoned poll runs again right after the stop (odometry is never a stop short).
- ``GOSPD`` is sent only when the wheel targets change (the firmware restarts its ramp from
  a 0.5 s-averaged speed on every GOSPD); the DIST poll keeps FW 1.3's WATCH fed.

Also: polls DIST, PING and ADC back to back at up to ``poll_rate`` → ``/eddie/encoders_data``,
``/eddie/ping_data``, ``/eddie/adc_data``, ``/joint_states`` (wheel angles, continuous across
reconnects, board reboots and ``reset_encoder``, stamped when the board sampled them), ``/eddie/safety_veto`` (std_msgs/Bool, the
one veto state ``emergency_status`` reports), ``/battery_state`` (sensor_msgs/BatteryState)
and ``/diagnostics``; serves the original stack's ten services, which obey the e-stop and
the veto like ``/cmd_vel`` does (``TRVL``/``TURN`` end by themselves, so the stale timer
leaves them alone).

``port`` is a serial device, a pty, a pyserial URL (``socket://host:port``), or
``emulator`` for the in-process firmware emulator the simulator puts in the context
(``emulator:1.1`` / ``emulator:1.3`` make a standalone one). The emulator runs with the real
wire's timing (:mod:`eddiebot.robot.timing`) unless ``emulator_timing`` is false.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from eddiebot.base.board_counters import WheelCounters
from eddiebot.base.board_diagnostics import board_diagnostics
from eddiebot.base.board_health import battery_state_msg
from eddiebot.base.board_io import BoardOp, Priority, ThreadedBoardIO
from eddiebot.base.board_link import BoardConnector, acc_min, open_board, stop_retrying
from eddiebot.base.board_modes import Motion, StopKind
from eddiebot.base.board_services import serve_original_services
from eddiebot.base.board_stops import StopCheck, StopTracker
from eddiebot.base.kinematics import twist_to_wheel_positions
from eddiebot.base.safety import (
    SAFETY_VETO_QOS,
    SAFETY_VETO_TOPIC,
    VetoState,
    declare_safety_parameters,
    limit_twist,
)
from eddiebot.core.node import Node
from eddiebot.core.parameters import Parameter, ParameterDescriptor, SetParametersResult
from eddiebot.core.qos import qos_profile_latched
from eddiebot.core.time import ns_to_stamp
from eddiebot.msgs.diagnostic_msgs import DiagnosticArray
from eddiebot.msgs.eddiebot_msgs import (
    ADC,
    Encoders,
    Ping,
    Velocity,
)
from eddiebot.msgs.sensor_msgs import BatteryState, JointState
from eddiebot.msgs.std_msgs import Bool
from eddiebot.robot.board import Board, BoardEvent
from eddiebot.robot.constants import (
    BATTERY_ADC_INDEX,
    IR_SENSORS,
    PING_MASK,
    PING_SENSORS,
    POSITIONS_PER_REV,
    TRACK_M,
    WHEEL_RADIUS_M,
    FirmwareProfile,
    adc_counts_to_volts,
    battery_volts_from_counts,
    ping_units_to_range_m,
    sharp_voltage_to_distance,
)
from eddiebot.robot.errors import (
    BoardInterrupted,
    BoardTimeout,
    LinkLost,
    ParameterRangeError,
    RobotError,
)
from eddiebot.robot.timing import DEFAULT_TIMING, request_transit_s
from eddiebot.robot.urdf import WHEEL_JOINTS

__all__ = ["BoardNode", "StopKind"]

_READ_ONLY = ("port", "firmware", "counts_per_rev", "wheel_radius", "track", "ping_mask",
              "reply_timeout", "emulator_timing")


class BoardNode(Node):
    default_node_name = "eddie"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        ro = ParameterDescriptor(read_only=True)
        p = self.declare_parameter
        self.port = str(p("port", "/dev/ttyUSB0", ro).value)
        self.firmware = str(p("firmware", "auto", ro).value)
        self.counts_per_rev = int(p("counts_per_rev", POSITIONS_PER_REV, ro).value)
        self.wheel_radius = float(p("wheel_radius", WHEEL_RADIUS_M, ro).value)
        self.track = float(p("track", TRACK_M, ro).value)
        # eddie calibrate's factors, as the odometry reads them (diff_drive_controller's names)
        self.track *= float(p("wheel_separation_multiplier", 1.0, ro).value)
        self.radius_multipliers = (float(p("left_wheel_radius_multiplier", 1.0, ro).value),
                                   float(p("right_wheel_radius_multiplier", 1.0, ro).value))
        self.ping_mask = int(p("ping_mask", PING_MASK, ro).value)
        self.reply_timeout = float(p("reply_timeout", 0.25, ro).value)
        emulator_timing = bool(p("emulator_timing", True, ro).value)
        self.poll_rate = float(p("poll_rate", 12.0).value)
        self.cmd_timeout_ns = round(float(p("cmd_timeout", 0.5).value) * 1e9)
        self.acceleration = int(p("acceleration_rate", 200).value)
        #: cap on wheel speed in positions/s (#27971 motors: ≈ 2.5 rev/s no-load at 12 V)
        self.max_wheel_speed = float(p("max_wheel_speed", 2.5 * self.counts_per_rev).value)
        self.battery_warning_v = float(p("battery_warning_voltage", 11.5).value)
        self.battery_cutoff_v = float(p("battery_cutoff_voltage", 10.5).value)
        self.safety = declare_safety_parameters(self)
        if self.poll_rate <= 0:
            raise ValueError(f"{self.fully_qualified_name}: poll_rate must be positive")
        if self.counts_per_rev <= 0:
            raise ValueError(f"{self.fully_qualified_name}: counts_per_rev must be positive")
        if self.firmware not in ("auto", "1.1", "1.3"):
            raise ValueError(f"{self.fully_qualified_name}: firmware must be auto, 1.1 or 1.3, "
                             f"got {self.firmware!r}")
        self.rad_per_position = 2.0 * math.pi / self.counts_per_rev
        self._dist_transit_ns = round(request_transit_s(DEFAULT_TIMING, len(b"DIST\r")) * 1e9)
        self.metres_per_position = self.rad_per_position * self.wheel_radius
        pins = {p for p in range(16) if self.ping_mask & (1 << p)}
        self.veto = VetoState.from_config(
            self.safety, (*IR_SENSORS, *(s for s in PING_SENSORS if s.index in pins)))
        # command state
        self._last_cmd_ns: int | None = None
        self._twist: tuple[float, float] = (0.0, 0.0)  # last requested (m/s, rad/s)
        self._motion = Motion.NONE
        self._move_forward = False  # a service motion that drives forward (veto applies)
        self._target: tuple[int, int] | None = (0, 0)  # wheel targets on the board (None: unknown)
        self._epoch = 0  # bumped by every stop: motion submitted before it is void
        self._estop = False
        self._battery_low = False
        self.stops = StopTracker()
        self._stops_sent = 0
        self._stop_wire_ns: list[int] = []  # when each stop went out (tests, benchmarks)
        self._sent_wheels: tuple[int, int] = (0, 0)  # the last GOSPD the board confirmed
        self._spd_stamp_ns = 0
        self._silent_since_ns: int | None = None  # first failed query since the last DIST
        # board state
        self.connected = False
        self._link_generation = 0
        self._profile: FirmwareProfile | None = None
        self.counters = WheelCounters(self.max_wheel_speed)
        self._spd: tuple[int, int] = (0, 0)
        self._battery_v = math.nan
        self._stats = {"polls": 0, "timeouts": 0, "link_lost": 0, "stops": 0, "vetoes": 0}
        self._poll_times: list[int] = []
        self._events: list[str] = []

        self.encoders_pub = self.create_publisher(Encoders, "/eddie/encoders_data", 10)
        self.ping_pub = self.create_publisher(Ping, "/eddie/ping_data", 10)
        self.adc_pub = self.create_publisher(ADC, "/eddie/adc_data", 10)
        self.joint_pub = self.create_publisher(JointState, "/joint_states", 10)
        self.veto_pub = self.create_publisher(Bool, SAFETY_VETO_TOPIC, SAFETY_VETO_QOS)
        self.battery_pub = self.create_publisher(BatteryState, "/battery_state", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(Velocity, "/eddie/simple_velocity", self._on_velocity, 1)
        self.create_subscription(Bool, "/e_stop", self._on_estop, qos_profile_latched)
        self._serve_original_services()
        self.board, self.io = open_board(self, emulator_timing)
        self._poll_timer = self.create_timer(1.0 / self.poll_rate, self._poll)
        self.create_timer(1.0, self._publish_diagnostics)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.context.add_safety_stop(self.emergency_stop)
        boot_s = DEFAULT_TIMING.boot_s if emulator_timing or not self.port.startswith(
            "emulator") else 0.0
        self.connector = BoardConnector(self, boot_s, self._on_connected)
        self.connector.connect()

    # -- link ------------------------------------------------------------------------------
    def _call_later(self, delay_ns: int, fn: Any) -> None:
        timer: Any = None

        def fire() -> None:
            self.destroy_timer(timer)
            fn()

        timer = self.create_timer(delay_ns / 1e9, fire, oneshot=True)

    def _on_connected(self, profile: FirmwareProfile) -> None:
        self.connected = True
        self._profile = profile
        self._link_generation = self.board.link.generation
        self.counters.rebase = True
        self._stop_confirmed(StopKind.CUT, self.get_clock().now_ns())
        self.get_logger().info(
            f"board on {self.port}: firmware {profile.name} (VER {self.board.firmware_version:04X})"
            f", {self.counts_per_rev} counts/rev")

    def _on_board_event(self, event: BoardEvent, detail: str) -> None:
        if event == BoardEvent.LINK_LOST:
            self._stats["link_lost"] += 1
        elif event == BoardEvent.TIMEOUT:
            self._stats["timeouts"] += 1
        self._events.append(f"{event.value}: {detail}")
        del self._events[:-10]

    # -- stops -----------------------------------------------------------------------------
    def request_stop(self, kind: StopKind, reason: str) -> None:
        """Stop the wheels (``HOLD``: GOSPD 0 0, ``CUT``: STOP 0) and keep at it until the
        board confirms and its speed reads 0 0. Queued motion is dropped."""
        self._epoch += 1
        self.io.cancel(lambda op: op.priority == Priority.MOTION)
        self._motion = Motion.NONE
        self._move_forward = False
        if not self.stops.request(kind, self.get_clock().now_ns(), self.cmd_timeout_ns // 2):
            return  # the same (or a stronger) stop was confirmed a moment ago
        if reason and self.stops.kind is not None:
            self.get_logger().debug(f"stop ({self.stops.kind.name}): {reason}")
        self._send_stop()

    def _send_stop(self) -> None:
        kind = self.stops.kind
        if kind is None:
            return
        name = "STOP" if kind == StopKind.CUT else "HOLD"
        if self.io.pending(name):
            return

        def run(board: Board) -> None:
            self._stop_wire_ns.append(self.get_clock().now_ns())
            del self._stop_wire_ns[:-100]
            if kind == StopKind.CUT:
                board.stop_now()
            else:
                board.hold_now()

        def done(_: Any, error: BaseException | None) -> None:
            if self.stops.kind is None:
                return  # motion was commanded since: nothing is owed any more
            if error is None:
                self._stop_confirmed(kind, self.get_clock().now_ns())
            elif isinstance(error, (BoardTimeout, RobotError)) and not isinstance(error, LinkLost):
                self._send_stop()  # overdue or garbled: again at once

        self._stops_sent += 1
        self._stats["stops"] += 1
        self.io.submit(BoardOp(name, run, done, Priority.STOP))

    def _stop_confirmed(self, kind: StopKind, now: int) -> None:
        speed = max(abs(v) for v in (*self._spd, *self._sent_wheels))
        if self.stops.confirm(kind, now, speed, self.acceleration, 1.0 / self.poll_rate):
            self._target = (0, 0)

    def _check_stop(self, now: int) -> None:
        check = self.stops.check(now, self._spd, self._spd_stamp_ns)
        if check == StopCheck.RESEND:
            self._send_stop()  # unconfirmed: at every poll until a reply arrives
        elif check == StopCheck.VERIFIED:
            self._sent_wheels = (0, 0)
        elif check == StopCheck.RECUT:
            self.get_logger().warning(
                f"wheels still turning ({self._spd[0]} {self._spd[1]} positions/s) "
                f"after the stop: STOP 0 again")
            self._send_stop()

    @property
    def stopped(self) -> bool:
        """Whether the last stop was confirmed and the wheels read 0 0 since."""
        return self.stops.verified

    # -- polling ---------------------------------------------------------------------------
    def _poll(self) -> None:
        now = self.get_clock().now_ns()
        if not self.connected:
            self.connector.connect()
            if self.stops.owed and self.board.link.generation > 0:
                self._send_stop()  # a port that was open once: the board may still be driving
            return
        if self.board.link.generation != self._link_generation:
            # the link came back (the board may have rebooted): it may still run the last GOSPD
            self._link_generation = self.board.link.generation
            self.counters.rebase = True
            self.request_stop(StopKind.CUT, "link came back")
        self._check_stale(now)
        self._check_stop(now)
        if self.stops.awaiting_speed:
            self._submit_query("SPD", lambda b: b.speed(), self._on_spd)
        if self.io.pending("DIST") or self.io.pending("PING") or self.io.pending("ADC"):
            self._poll_owed = True  # the last cycle is still on the wire: start when it ends
            return
        self._start_cycle()

    _poll_owed = False

    def _start_cycle(self) -> None:
        self._poll_owed = False
        self._stats["polls"] += 1
        self._poll_times.append(self.get_clock().now_ns())
        del self._poll_times[:-50]
        self._submit_query("DIST", self._read_dist, self._on_dist)
        self._submit_query("PING", lambda b: b.ping(), self._on_ping)
        self._submit_query("ADC", lambda b: b.adc(), self._on_adc)
        self.io.submit(BoardOp("cycle end", lambda b: None, self._on_cycle_end, Priority.ROUTINE))

    def _on_cycle_end(self, _: Any, error: BaseException | None) -> None:
        if self._poll_owed and self.connected:
            self._start_cycle()

    def _submit_query(self, name: str, run: Any, on_result: Any) -> None:
        if self.io.pending(name):
            return

        def done(result: Any, error: BaseException | None) -> None:
            if error is None:
                on_result(result)
            elif self._silent_since_ns is None and not isinstance(error, BoardInterrupted):
                self._silent_since_ns = self.get_clock().now_ns()

        self.io.submit(BoardOp(name, run, done, Priority.ROUTINE, rerun_after_stop=True))

    def _read_dist(self, board: Board) -> tuple[int, tuple[int, int]]:
        # The board reads its counters when "DIST\r" arrives, one USB frame and the request's
        # bytes after the write; the reply then waits up to the FTDI latency timer (16 ms) in
        # the chip. Stamping the sample time, not the reply's arrival, keeps that lag out of
        # the odometry (at 1 rad/s, 16 ms is ~1° of heading lag for every scan it meets).
        written = self.get_clock().now_ns()
        counts = board.distance()
        return written + self._dist_transit_ns, counts

    def _on_dist(self, sample: tuple[int, tuple[int, int]]) -> None:
        stamp_ns, raw = sample
        silent_since, self._silent_since_ns = self._silent_since_ns, None
        last = self.counters.raw
        if last is not None and self.counters.restarted(stamp_ns, raw, silent_since):
            # counters jumped back (a reboot: DTR on port open, a brown-out): the board
            # also lost VERB/SPNG/ACC and may have been mid-command
            self.get_logger().warning(
                f"the board's counters restarted ({last[0]} {last[1]} → {raw[0]} {raw[1]}): "
                f"it rebooted; odometry continues from where it was")
            self.counters.rebase = True
            self.board.core.rearm_reconnect()
            self.request_stop(StopKind.CUT, "board rebooted")
        left, right = self.counters.update(stamp_ns, raw)
        since_zero = self.counters.since_zero()
        self.encoders_pub.publish(Encoders(left=since_zero[0], right=since_zero[1]))
        js = JointState()
        js.header.stamp = ns_to_stamp(stamp_ns)
        js.name = list(WHEEL_JOINTS)
        js.position = np.array([left * self.rad_per_position, right * self.rad_per_position])
        self.joint_pub.publish(js)

    def _on_spd(self, spd: tuple[int, int]) -> None:
        self._spd = spd
        self._spd_stamp_ns = self.get_clock().now_ns()
        self._check_stop(self._spd_stamp_ns)

    def _on_ping(self, units: tuple[int, ...]) -> None:
        self.ping_pub.publish(Ping(status="SUCCESS", value=np.asarray(units, dtype=np.uint16)))
        pins = [p for p in range(16) if self.ping_mask & (1 << p)]
        ranges = {}
        for pin, u in zip(pins, units):
            for s in PING_SENSORS:
                if s.index == pin:
                    ranges[s.name] = ping_units_to_range_m(u)
        self.veto.update(ranges, self.get_clock().now_ns())
        self._apply_veto()

    def _on_adc(self, counts: tuple[int, ...]) -> None:
        self.adc_pub.publish(ADC(status="SUCCESS", value=np.asarray(counts, dtype=np.uint16)))
        ranges = {}
        for s in IR_SENSORS:
            if s.index < len(counts):
                ranges[s.name] = sharp_voltage_to_distance(adc_counts_to_volts(counts[s.index]))
        now = self.get_clock().now_ns()
        self.veto.update(ranges, now)
        if len(counts) > BATTERY_ADC_INDEX:
            self._on_battery(battery_volts_from_counts(counts[BATTERY_ADC_INDEX]), now)
        self._apply_veto()

    # -- safety ----------------------------------------------------------------------------
    def _apply_veto(self) -> None:
        now = self.get_clock().now_ns()
        vetoed = self.safety.enabled and self.veto.vetoed_at(now)
        self.veto_pub.publish(Bool(data=bool(vetoed)))
        if self._motion == Motion.VELOCITY:
            self._drive(*self._twist, reason="veto")
        elif self._motion in (Motion.SERVICE_MOVE, Motion.SERVICE_SPEED) and (
                self._move_forward and vetoed):
            self._stats["vetoes"] += 1
            self.get_logger().warning("obstacle ahead: the service motion is stopped")
            self.request_stop(StopKind.CUT, "veto")

    def _on_battery(self, volts: float, now: int) -> None:
        self._battery_v = volts
        msg = battery_state_msg(volts, now, self.battery_cutoff_v)
        self.battery_pub.publish(msg)
        if not msg.present:
            return  # no battery reading (bench supply on the logic side): nothing to judge
        if volts < self.battery_cutoff_v and not self._battery_low:
            self._battery_low = True
            self.get_logger().error(
                f"battery at {volts:.2f} V, below battery_cutoff_voltage "
                f"{self.battery_cutoff_v:.2f} V: motors stopped until it is charged")
            self.request_stop(StopKind.CUT, "low battery")
        elif self._battery_low and volts > self.battery_cutoff_v + 0.3:
            self._battery_low = False
            self.get_logger().info(f"battery at {volts:.2f} V again: motion allowed")
        elif volts < self.battery_warning_v:
            self.get_logger().warning(f"battery low: {volts:.2f} V", once=True)

    def _motion_refused(self) -> str | None:
        """Why no motion may be sent now, or None."""
        if self._estop:
            return "the e-stop is latched (/e_stop)"
        if self._battery_low:
            return f"the battery is below {self.battery_cutoff_v:.2f} V"
        return None

    def _on_estop(self, msg: Any) -> None:
        engaged = bool(msg.data)
        if engaged and not self._estop:
            self.get_logger().warning("e-stop engaged: motors stopped")
        elif self._estop and not engaged:
            self.get_logger().info("e-stop released")
        self._estop = engaged
        if engaged:
            self.request_stop(StopKind.CUT, "e-stop")

    def _check_stale(self, now: int) -> None:
        if self._motion not in (Motion.VELOCITY, Motion.SERVICE_SPEED) or self._last_cmd_ns is None:
            return
        if now - self._last_cmd_ns > self.cmd_timeout_ns:
            self.get_logger().warning(
                f"no velocity command for {self.cmd_timeout_ns / 1e9:.2f} s: stopping the motors")
            self.request_stop(StopKind.CUT, "stale")

    # -- velocity --------------------------------------------------------------------------
    def _on_velocity(self, msg: Any) -> None:
        self._last_cmd_ns = self.get_clock().now_ns()
        self._drive(float(msg.linear), float(msg.angular), reason="command")

    def _wheels(self, linear: float, angular: float) -> tuple[int, int]:
        return twist_to_wheel_positions(linear, angular, max_positions_per_s=self.max_wheel_speed,
                                        track=self.track,
                                        metres_per_position=self.metres_per_position,
                                        radius_multipliers=self.radius_multipliers)

    def _drive(self, linear: float, angular: float, *, reason: str) -> None:
        self._twist = (linear, angular)
        now = self.get_clock().now_ns()
        requested = self._wheels(linear, angular)
        if requested == (0, 0):
            if reason == "command":
                self.request_stop(StopKind.HOLD, "zero command")
            return
        refused = self._motion_refused()
        if refused is not None:
            self.get_logger().warning(f"motion refused: {refused}", once=True)
            self.request_stop(StopKind.CUT, refused)
            return
        limited = limit_twist(linear, angular, self.veto, self.safety, now)
        wheels = self._wheels(*limited)
        if wheels == (0, 0):
            if self._motion != Motion.NONE or reason == "command":
                self._stats["vetoes"] += 1
                self.request_stop(StopKind.CUT, "veto")
            self._motion = Motion.VELOCITY if reason == "veto" else Motion.NONE
            return
        self._motion = Motion.VELOCITY
        if wheels == self._target and self.stops.kind is None:
            return  # the board already runs these targets
        self._send_motion("GOSPD", lambda b, w=wheels: b.go_speed(*w), wheels, Motion.VELOCITY)

    def _send_motion(self, name: str, run: Any, wheels: tuple[int, int] | None,
                     motion: Motion, *, forward: bool = False) -> None:
        self.io.cancel(lambda op: op.priority == Priority.MOTION)
        self.io.cancel(lambda op: op.name in ("HOLD",))
        epoch = self._epoch
        self.stops.clear()
        self._target = wheels
        self._motion = motion
        self._move_forward = forward

        def done(_: Any, error: BaseException | None) -> None:
            if epoch != self._epoch:
                return  # a stop came after it
            if error is not None:
                self._target = None  # unknown: the next command sends again
                self.get_logger().warning(f"{name} failed: {error}", once=True)
            elif wheels is not None:
                self._sent_wheels = wheels

        self.io.submit(BoardOp(name, run, done, Priority.MOTION))

    # -- the original services -------------------------------------------------------------
    def _serve_original_services(self) -> None:
        serve_original_services(self)

    def _set_acceleration(self, rate: int) -> str | None:
        """Send ``ACC``; the reason it was refused, or None."""
        profile = self._profile or self.board.profile
        try:
            from eddiebot.robot import protocol

            protocol.encode_acc(rate, profile)
            if rate < acc_min(profile):
                raise ValueError(f"ACC {rate} is below {acc_min(profile)} on firmware "
                                 f"{profile.name} (ACC 0 freezes GOSPD on FW 1.1)")
        except (ParameterRangeError, ValueError) as exc:
            self.get_logger().error(f"acceleration_rate refused: {exc}")
            return str(exc)
        self.acceleration = rate
        self.io.submit(BoardOp("ACC", lambda b: b.set_acceleration(rate), None, Priority.ROUTINE))
        return None

    # -- parameters and diagnostics --------------------------------------------------------
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for prm in params:
            if prm.name == "acceleration_rate":
                reason = self._set_acceleration(int(prm.value))
                if reason is not None:
                    return SetParametersResult(False, reason)
            elif prm.name == "cmd_timeout":
                self.cmd_timeout_ns = round(float(prm.value) * 1e9)
            elif prm.name == "poll_rate":
                if float(prm.value) <= 0:
                    return SetParametersResult(False, "poll_rate must be positive")
                self.poll_rate = float(prm.value)
                self.destroy_timer(self._poll_timer)
                self._poll_timer = self.create_timer(1.0 / self.poll_rate, self._poll)
            elif prm.name == "max_wheel_speed":
                self.max_wheel_speed = float(prm.value)
                self.counters.max_wheel_speed = self.max_wheel_speed
            elif prm.name in ("battery_warning_voltage", "battery_cutoff_voltage"):
                setattr(self, "battery_warning_v" if "warning" in prm.name else "battery_cutoff_v",
                        float(prm.value))
            elif prm.name in ("veto_distance", "veto_enabled", "stale_after", "slowdown_distance",
                              "max_reverse_speed", "ir_debounce"):
                field = "enabled" if prm.name == "veto_enabled" else prm.name
                try:
                    self.safety = replace(self.safety, **{field: prm.value})
                except ValueError as exc:
                    return SetParametersResult(False, str(exc))
                self.veto.veto_distance = self.safety.veto_distance
                self.veto.ir_debounce = self.safety.ir_debounce
                self.veto.stale_after = self.safety.stale_after
        return SetParametersResult(True)

    def achieved_poll_rate(self) -> float:
        """Polls per second over the last cycles (node clock)."""
        t = self._poll_times
        if len(t) < 2 or t[-1] == t[0]:
            return 0.0
        return (len(t) - 1) / ((t[-1] - t[0]) / 1e9)

    def _publish_diagnostics(self) -> None:
        self.diag_pub.publish(board_diagnostics(self, self.get_clock().now_ns()))

    # -- shutdown --------------------------------------------------------------------------
    def emergency_stop(self, reason: str, from_signal: bool = False) -> None:
        """Put ``STOP 0`` on the wire now, whatever the node is doing (the context's safety
        stop: signals, failing callbacks). Thread-safe on a serial link; on the in-process
        emulator a signal leaves it to shutdown, which runs on the same thread."""
        if isinstance(self.io, ThreadedBoardIO):
            self.io.submit(BoardOp("STOP", lambda b: b.stop_now(), None, Priority.STOP))
            if not from_signal:
                self.request_stop(StopKind.CUT, reason)
        elif not from_signal:
            self.request_stop(StopKind.CUT, reason)

    def destroy_node(self) -> None:
        """Stop the motors (confirmed if the board answers within a second), then go away."""
        if not getattr(self, "_destroying", False):
            self._destroying = True
            self.context.remove_safety_stop(self.emergency_stop)
            self.io.cancel(lambda op: True)
            if self.board.link.generation > 0:  # never opened: nothing to stop
                self.io.submit(BoardOp("STOP", stop_retrying, None, Priority.STOP))
            wait = getattr(self.io, "wait_idle", None)
            if wait is not None:
                wait(1.5)
            self.io.close(1.0)
            try:
                self.board.close()
            except RobotError:
                pass
        super().destroy_node()

