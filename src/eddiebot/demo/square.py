"""Demo stage 1: the real base stack drives a 1 m square against the firmware emulator
through a pseudo-terminal — exactly the bytes it would exchange with the robot.

The square is closed-loop on wheel odometry (straight until 1 m travelled, turn until
90° turned), as a user would script it; at each corner the odometry pose is printed beside
the emulator's true pose.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.node import Node
from eddiebot.geometry import quaternion_to_yaw, wrap_angle
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.registry import NODES
from eddiebot.robot.emulator import FirmwareEmulator, FixedSensors
from eddiebot.robot.pty_server import PtyServer

__all__ = ["Corner", "SquareDriver", "SquareResult", "run_square"]


@dataclass(frozen=True)
class Corner:
    index: int
    odom: tuple[float, float, float]
    truth: tuple[float, float, float]

    @property
    def position_error(self) -> float:
        return math.hypot(self.odom[0] - self.truth[0], self.odom[1] - self.truth[1])

    @property
    def heading_error(self) -> float:
        return abs(float(wrap_angle(self.odom[2] - self.truth[2])))


@dataclass
class SquareResult:
    corners: list[Corner] = field(default_factory=list)
    device: str = ""
    bag: Path | None = None


class SquareDriver(Node):
    """Publishes ``/cmd_vel`` to drive a square of ``side`` metres, closed-loop on ``/odom``:
    counter-clockwise for ``direction`` +1, clockwise for −1. ``truth`` (optional) gives the
    true pose recorded at each corner (the emulator's, in simulation)."""

    def __init__(self, truth: Callable[[], tuple[float, float, float]] | None = None, *,
                 side: float = 1.0, speed: float = 0.2, turn_speed: float = 0.6,
                 direction: int = 1, **kwargs: Any) -> None:
        super().__init__("square_driver", **kwargs)
        self.truth = truth
        self.direction = 1 if direction >= 0 else -1
        self.side, self.speed, self.turn_speed = side, speed, turn_speed
        self.velocity = (0.0, 0.0)
        self._still_since: int | None = None
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.pose: tuple[float, float, float] | None = None
        self.create_subscription(Odometry, "/odom", self._on_odom, 10)
        self.corners: list[Corner] = []
        self.leg = 0
        self.phase = "straight"
        self.start: tuple[float, float, float] | None = None
        self.done = threading.Event()
        self.create_timer(0.05, self._tick)

    def _on_odom(self, msg: Any) -> None:
        p = msg.pose.pose
        q = p.orientation
        self.pose = (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))
        self.velocity = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)

    def _settled(self) -> bool:
        """Standing still (odometry twist ≈ 0) for 0.3 s."""
        now = self.get_clock().now_ns()
        if abs(self.velocity[0]) > 0.003 or abs(self.velocity[1]) > 0.01:
            self._still_since = None
            return False
        if self._still_since is None:
            self._still_since = now
        return now - self._still_since >= 300_000_000

    def _send(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = v, w
        self.pub.publish(t)

    def _tick(self) -> None:
        if self.done.is_set() or self.pose is None:
            return
        if self.start is None:
            self.start = self.pose
        x, y, th = self.pose
        if self.phase == "straight":
            remaining = self.side - math.hypot(x - self.start[0], y - self.start[1])
            if remaining > 0.005:
                self._send(min(self.speed, max(0.05, 1.5 * remaining)), 0.0)
                return
            self._send(0.0, 0.0)
            self.phase, self.start = "settle_corner", self.pose
        elif self.phase == "settle_corner":
            self._send(0.0, 0.0)
            if self._settled():
                truth = self.truth() if self.truth is not None else self.pose
                self.corners.append(Corner(len(self.corners) + 1, self.pose, truth))
                self.leg += 1
                if self.leg == 4:
                    self.done.set()
                    return
                self.phase, self.start = "turn", self.pose
        elif self.phase == "turn":
            turned = abs(float(wrap_angle(th - self.start[2])))
            remaining = math.pi / 2 - turned
            if remaining > math.radians(1.0):
                self._send(0.0, self.direction * min(self.turn_speed, max(0.15, 2.0 * remaining)))
                return
            self._send(0.0, 0.0)
            self.phase, self.start = "settle_turn", self.pose
        elif self.phase == "settle_turn":
            self._send(0.0, 0.0)
            if self._settled():
                self.phase, self.start = "straight", self.pose


def run_square(out_dir: Path, *, side: float = 1.0, firmware: str = "1.1",
               timeout_s: float = 120.0, record: bool = True) -> SquareResult:
    """Serve the emulator on a pty, bring the base up on it, drive the square."""
    from eddiebot.robot.constants import FIRMWARE_PROFILES

    emulator = FirmwareEmulator(FIRMWARE_PROFILES[firmware], sensors=FixedSensors())
    server = PtyServer(emulator)
    serve = threading.Thread(target=server.serve_forever, name="emulator-pty", daemon=True)
    serve.start()
    result = SquareResult(device=server.device_path)
    context = Context()
    nodes: list[Node] = []
    try:
        desc = parse_launch_file(find_launch_file("bringup"), {"port": server.device_path})
        nodes = build_nodes(desc, context, NODES)
        driver = SquareDriver(lambda: emulator.plant.true_pose, side=side, context=context)
        nodes.append(driver)
        recorder = None
        if record:
            recorder = _recorder(context, out_dir / "square_bag")
            if recorder is not None:
                nodes.append(recorder)
                result.bag = out_dir / "square_bag"
        executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            executor.add_node(n)
        import time

        deadline = time.monotonic() + timeout_s
        while not driver.done.is_set() and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        result.corners = list(driver.corners)
    finally:
        for n in reversed(nodes):
            n.destroy_node()
        context.shutdown()
        server.stop()
        serve.join(2.0)
    return result


def _recorder(context: Context, path: Path) -> Node | None:
    """A recorder of every topic, if the bag module is installed."""
    try:
        from eddiebot.bag import RecorderNode
    except ImportError:
        return None
    if path.exists():
        import shutil

        shutil.rmtree(path)
    node: Node = RecorderNode(context=context, parameter_overrides={"output": str(path), "all": True})
    return node
