"""The board node: Eddie's control board on the graph.

- polls DIST, PING and ADC at ``poll_rate`` (default 20 Hz) → ``/eddie/encoders_data``,
  ``/eddie/ping_data``, ``/eddie/adc_data`` and ``/joint_states`` (wheel angles in rad,
  stamped with the time the DIST reply arrived); a failed read publishes nothing;
- ``/eddie/simple_velocity`` (m/s, rad/s, REP-103) → per-wheel positions/s saturated
  together (curvature kept) → ``GOSPD`` (``STOP 0`` for zero), after the IR/PING veto on
  forward motion, which sits here, last before the motors, so every command source is covered;
- stops the motors when commands go stale (``cmd_timeout``, default 0.5 s), on shutdown,
  and when the link comes back after a drop (the FW 1.1 board keeps driving otherwise);
- serves the original stack's ten services with its srv types.

``port`` is a serial device, a pty, a pyserial URL (``socket://host:port``), or
``emulator`` for the in-process firmware emulator the simulator puts in the context
(``emulator:1.1`` / ``emulator:1.3`` make a standalone one).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from eddiebot.base.kinematics import twist_to_wheel_positions
from eddiebot.base.safety import SafetyConfig, VetoState, forward_veto
from eddiebot.core.node import Node
from eddiebot.core.time import ns_to_stamp
from eddiebot.msgs.eddiebot_msgs import (
    ADC,
    Accelerate,
    DriveWithDistance,
    DriveWithPower,
    DriveWithSpeed,
    Encoders,
    GetDistance,
    GetHeading,
    GetSpeed,
    Ping,
    ResetEncoder,
    Rotate,
    StopAtDistance,
    Velocity,
)
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.robot.board import Board, BoardEvent
from eddiebot.robot.constants import (
    IR_SENSORS,
    PING_MASK,
    PING_SENSORS,
    POSITIONS_PER_REV,
    adc_counts_to_volts,
    ping_units_to_range_m,
    profile_for_name,
    sharp_voltage_to_distance,
)
from eddiebot.robot.errors import RobotError
from eddiebot.robot.urdf import WHEEL_JOINTS

__all__ = ["BoardNode"]

_RAD_PER_POSITION = 2.0 * math.pi / POSITIONS_PER_REV


class BoardNode(Node):
    default_node_name = "eddie"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.port = str(self.declare_parameter("port", "/dev/ttyUSB0").value)
        poll_rate = float(self.declare_parameter("poll_rate", 20.0).value)
        self.cmd_timeout_ns = round(float(self.declare_parameter("cmd_timeout", 0.5).value) * 1e9)
        self.reply_timeout = float(self.declare_parameter("reply_timeout", 0.25).value)
        self.ping_mask = int(self.declare_parameter("ping_mask", PING_MASK).value)
        self.acceleration = int(self.declare_parameter("acceleration_rate", 200).value)
        #: cap on wheel speed in positions/s (≈ 90 no-load on the #27971 motors ≈ 1.2 m/s)
        self.max_wheel_speed = float(self.declare_parameter("max_wheel_speed", 90.0).value)
        self.safety = SafetyConfig(
            veto_distance=float(self.declare_parameter("veto_distance", 0.25).value),
            enabled=bool(self.declare_parameter("veto_enabled", True).value),
        )
        if poll_rate <= 0:
            raise ValueError(f"{self.fully_qualified_name}: poll_rate must be positive")
        self.board = self._make_board()
        self.veto = VetoState(
            veto_distance=self.safety.veto_distance,
            mounts={s.name: (s.x_m, s.y_m, s.yaw_rad) for s in (*IR_SENSORS, *PING_SENSORS)},
        )
        self._last_cmd_ns: int | None = None
        self._moving = False
        self._last_wheels: tuple[int, int] = (0, 0)
        self._link_generation = 0
        self.encoders_pub = self.create_publisher(Encoders, "/eddie/encoders_data", 10)
        self.ping_pub = self.create_publisher(Ping, "/eddie/ping_data", 10)
        self.adc_pub = self.create_publisher(ADC, "/eddie/adc_data", 10)
        self.joint_pub = self.create_publisher(JointState, "/joint_states", 10)
        self.create_subscription(Velocity, "/eddie/simple_velocity", self._on_velocity, 1)
        self._serve_original_services()
        self.connected = self._start_board()
        self.create_timer(1.0 / poll_rate, self._poll)

    # -- link ------------------------------------------------------------------------------
    def _make_board(self) -> Board:
        from eddiebot.robot.links import EmulatorLink, SerialLink

        port = self.port
        if port.startswith("emulator"):
            emulator = self.context.resources.get("emulator")
            if emulator is None or ":" in port:
                from eddiebot.robot.emulator import FirmwareEmulator

                profile = profile_for_name(port.partition(":")[2] or "1.1")
                emulator = FirmwareEmulator(profile, start_ns=self.get_clock().now_ns())
                self.context.resources["emulator"] = emulator
            clock = self.get_clock()
            link: Any = EmulatorLink(emulator, clock_ns=clock.now_ns)
            return Board(link, clock=clock.now_ns, timeout_s=self.reply_timeout,
                         on_event=self._on_board_event)
        return Board(SerialLink(port), clock=time.monotonic_ns, timeout_s=self.reply_timeout,
                     on_event=self._on_board_event)

    def _start_board(self) -> bool:
        try:
            profile = self.board.start(ping_mask=self.ping_mask)
            self.board.stop(0)
            self.board.set_acceleration(min(max(self.acceleration, profile.acc_min), profile.acc_max))
            self.board.reset()
            self._link_generation = self.board.link.generation
        except RobotError as exc:
            self.get_logger().error(f"board on {self.port} not answering yet: {exc}; will keep trying")
            return False
        self.get_logger().info(
            f"board on {self.port}: firmware {profile.name} (VER {self.board.firmware_version:04X})"
        )
        return True

    def _on_board_event(self, event: BoardEvent, detail: str) -> None:
        if event == BoardEvent.LINK_LOST:
            self._moving = False  # whatever it does now, we must command it again after STOP

    # -- polling ---------------------------------------------------------------------------
    def _poll(self) -> None:
        if not self.connected:
            self.connected = self._start_board()
            if not self.connected:
                return
        if self.board.link.generation != self._link_generation:
            # the link came back: the board may still be executing the last GOSPD
            self._link_generation = self.board.link.generation
            self._safe(lambda: self.board.stop(0))
            self._moving = False
        self._check_stale()
        dist = self._safe(self.board.distance)
        stamp_ns = self.get_clock().now_ns()
        if dist is not None:
            left, right = dist
            self.encoders_pub.publish(Encoders(left=left, right=right))
            js = JointState()
            js.header.stamp = ns_to_stamp(stamp_ns)
            js.name = list(WHEEL_JOINTS)
            js.position = np.array([left * _RAD_PER_POSITION, right * _RAD_PER_POSITION])
            self.joint_pub.publish(js)
        ping = self._safe(self.board.ping)
        if ping is not None:
            self.ping_pub.publish(Ping(status="SUCCESS", value=np.asarray(ping, dtype=np.uint16)))
            self._update_ping(ping)
        adc = self._safe(self.board.adc)
        if adc is not None:
            self.adc_pub.publish(ADC(status="SUCCESS", value=np.asarray(adc, dtype=np.uint16)))
            self._update_ir(adc)
        if self.veto.vetoed and self._moving and self._last_wheels[0] + self._last_wheels[1] > 0:
            # an obstacle appeared while driving forward: re-apply the veto now
            self._drive(*self._last_twist)

    def _update_ping(self, units: tuple[int, ...]) -> None:
        pins = [p for p in range(16) if self.ping_mask & (1 << p)]
        ranges = {}
        for pin, u in zip(pins, units):
            for s in PING_SENSORS:
                if s.index == pin:
                    ranges[s.name] = ping_units_to_range_m(u)
        self.veto.update(ranges)

    def _update_ir(self, counts: tuple[int, ...]) -> None:
        ranges = {}
        for s in IR_SENSORS:
            if s.index < len(counts):
                ranges[s.name] = sharp_voltage_to_distance(adc_counts_to_volts(counts[s.index]))
        self.veto.update(ranges)

    def _safe(self, fn: Any) -> Any:
        try:
            return fn()
        except RobotError:
            return None  # the board logs each fault once per episode

    # -- velocity --------------------------------------------------------------------------
    _last_twist: tuple[float, float] = (0.0, 0.0)

    def _on_velocity(self, msg: Any) -> None:
        self._last_cmd_ns = self.get_clock().now_ns()
        self._drive(float(msg.linear), float(msg.angular))

    def _drive(self, linear: float, angular: float) -> None:
        self._last_twist = (linear, angular)
        linear = forward_veto(linear, self.veto, self.safety)
        left, right = twist_to_wheel_positions(linear, angular, max_positions_per_s=self.max_wheel_speed)
        if left == 0 and right == 0:
            if self._moving or self._last_wheels != (0, 0):
                self._safe(lambda: self.board.stop(0))
                self._moving = False
            self._last_wheels = (0, 0)
            return
        try:
            self.board.go_speed(left, right)
        except RobotError as exc:
            self.get_logger().warning(f"GOSPD {left} {right} failed: {exc}", once=True)
            return
        self._moving = True
        self._last_wheels = (left, right)

    def _check_stale(self) -> None:
        if not self._moving or self._last_cmd_ns is None:
            return
        if self.get_clock().now_ns() - self._last_cmd_ns > self.cmd_timeout_ns:
            self.get_logger().warning(
                f"no velocity command for {self.cmd_timeout_ns / 1e9:.2f} s: stopping the motors"
            )
            self._safe(lambda: self.board.stop(0))
            self._moving = False
            self._last_wheels = (0, 0)

    # -- the original services -------------------------------------------------------------
    def _serve_original_services(self) -> None:
        b = self

        def action(fn: Any) -> Any:
            def cb(req: Any, res: Any) -> Any:
                try:
                    fn(req)
                    b._last_cmd_ns = b.get_clock().now_ns()
                except (RobotError, ValueError) as exc:
                    b.get_logger().error(f"service call failed: {exc}")
                return res

            return cb

        def drive_speed(req: Any) -> None:
            self.board.go_speed(int(req.left), int(req.right))
            self._moving = True

        def drive_power(req: Any) -> None:
            self.board.go_power(int(req.left), int(req.right))
            self._moving = True

        def get_distance(req: Any, res: Any) -> Any:
            d = self._safe(self.board.distance)
            if d is not None:
                res.left, res.right = d
            return res

        def get_heading(req: Any, res: Any) -> Any:
            h = self._safe(self.board.heading_degrees_cw)
            if h is not None:
                res.heading = int(h) % 360
            return res

        def get_speed(req: Any, res: Any) -> Any:
            s = self._safe(self.board.speed)
            if s is not None:
                res.left, res.right = s
            return res

        self.create_service(Accelerate, "acceleration_rate",
                            action(lambda r: self.board.set_acceleration(int(r.rate))))
        self.create_service(DriveWithDistance, "drive_with_distance",
                            action(lambda r: self.board.travel(int(r.distance), int(r.speed))))
        self.create_service(DriveWithPower, "drive_with_power", action(drive_power))
        self.create_service(DriveWithSpeed, "drive_with_speed", action(drive_speed))
        self.create_service(GetDistance, "get_distance", get_distance)
        self.create_service(GetHeading, "get_heading", get_heading)
        self.create_service(GetSpeed, "get_speed", get_speed)
        self.create_service(ResetEncoder, "reset_encoder", action(lambda r: self.board.reset()))
        # the original's angle is degrees, clockwise positive on the wire; ours is REP-103
        self.create_service(Rotate, "rotate",
                            action(lambda r: self.board.turn(math.radians(-int(r.angle)), int(r.speed))))
        self.create_service(StopAtDistance, "stop_at_distance",
                            action(lambda r: self.board.stop(int(r.distance))))

    def destroy_node(self) -> None:
        """Stop the motors before going away."""
        self._safe(lambda: self.board.stop(0))
        self._safe(self.board.close)
        super().destroy_node()
