"""A scripted operator: drives the simulated robot along a route of world-frame waypoints.

It steers on the simulator's ground truth (``/ground_truth/odom``), as a person with a
remote control watching the robot would, and publishes ``/cmd_vel_teleop`` — the same topic
``eddie teleop`` uses — so the whole base stack (mux, controller, board driver, emulator)
carries every command. A waypoint may ask for a spin in place, which is how a 57° Kinect
sees a room.

When a forward command moves the robot less than ``stuck_distance`` within ``stuck_after_s``
(the base's range veto or its slowdown band holds it), the operator does what one with a
remote control does: turns in place until the robot faces its carrot within
``align_tolerance`` and drives on from there. The veto judges the straight corridor ahead of
the robot, so an arc whose heading still points at a door leaf is refused while the same
path started square to the doorway is not.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

from eddiebot.core.node import Node
from eddiebot.geometry import quaternion_to_yaw, wrap_angle
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.msgs.nav_msgs import Odometry

__all__ = [
    "OFFICE_10MIN_ROUTE",
    "OFFICE_LONG_ROUTE",
    "OFFICE_ROUTE",
    "WAREHOUSE_10MIN_ROUTE",
    "WAREHOUSE_ROUTE",
    "RouteDriver",
    "Waypoint",
]


@dataclass(frozen=True)
class Waypoint:
    """Reach (x, y) in the world frame; then turn ``spin`` radians in place (0: none)."""

    x: float
    y: float
    spin: float = 0.0



def _room_visit(x: float, y: float, corridor_y: float = 7.5) -> tuple[Waypoint, ...]:
    """From the office corridor at ``x`` into a room to (x, y), one full turn there, and back."""
    return (Waypoint(x, corridor_y), Waypoint(x, y, spin=2 * math.pi), Waypoint(x, corridor_y))


#: Down the office corridor and back, into a room on each side through open doors (the
#: doors at x 10.0–10.9 north and 12.0–12.9 south are closed), closing the loop at the start:
#: about 45 m and five spins.
OFFICE_ROUTE: tuple[Waypoint, ...] = (
    Waypoint(3.4, 7.5, spin=2 * math.pi),
    *_room_visit(7.45, 5.0),
    *_room_visit(16.45, 10.3),
    Waypoint(18.5, 7.5, spin=2 * math.pi),
    Waypoint(12.5, 7.6),
    Waypoint(3.0, 7.5),
    Waypoint(1.5, 7.5, spin=math.pi),
)

#: The benchmark's office route (about 6.5 simulated minutes): `OFFICE_ROUTE`, then the three
#: other open rooms (south-west, north-west with the meeting table, south-east) from the
#: corridor, revisiting the corridor and the start twice more: about 89 m and nine spins.
OFFICE_LONG_ROUTE: tuple[Waypoint, ...] = (
    *OFFICE_ROUTE,
    *_room_visit(2.45, 5.0),
    *_room_visit(3.45, 9.7),
    *_room_visit(17.45, 5.0),
    Waypoint(3.0, 7.5),
    Waypoint(1.5, 7.5, spin=math.pi),
)

#: The benchmark's warehouse route (30 × 20 m; about 6.5 simulated minutes): along the south
#: wall, up the middle cross aisle, east down the central aisle to the far wall, back west to
#: the pallet by the west wall, down the west side to the start, and round again through the
#: aisle between the first two shelf rows (its pillars passed on the south side), closing
#: the loop twice at the start.
WAREHOUSE_ROUTE: tuple[Waypoint, ...] = (
    Waypoint(2.5, 2.0, spin=2 * math.pi),
    Waypoint(15.2, 2.0),
    Waypoint(15.2, 11.0, spin=2 * math.pi),
    Waypoint(27.5, 11.0, spin=2 * math.pi),
    Waypoint(15.2, 11.0),
    Waypoint(5.6, 11.0, spin=2 * math.pi),
    Waypoint(4.8, 12.0),
    Waypoint(2.0, 12.0),
    Waypoint(2.0, 3.0),
    Waypoint(2.5, 2.0, spin=2 * math.pi),
    Waypoint(15.2, 2.0),
    Waypoint(15.2, 6.3),
    Waypoint(5.8, 6.3, spin=2 * math.pi),
    Waypoint(2.0, 6.3),
    Waypoint(2.0, 3.0),
    Waypoint(2.5, 2.0, spin=math.pi),
)


#: The benchmark's ten-minute office route (about 10.5 simulated minutes, 140 m):
#: `OFFICE_LONG_ROUTE`, then a third pass revisiting the corridor end to end and five of the
#: rooms seen before (south-west, north-west, the room by the start, north-east and the
#: corridor's east end), closing the loop at the start a third time.
OFFICE_10MIN_ROUTE: tuple[Waypoint, ...] = (
    *OFFICE_LONG_ROUTE,
    *_room_visit(2.45, 5.0),
    *_room_visit(3.45, 9.7),
    *_room_visit(7.45, 5.0),
    *_room_visit(16.45, 10.3),
    Waypoint(18.5, 7.5, spin=2 * math.pi),
    Waypoint(3.0, 7.5),
    Waypoint(1.5, 7.5, spin=math.pi),
)

#: The benchmark's ten-minute warehouse route (about 10.5 simulated minutes, 175 m):
#: `WAREHOUSE_ROUTE`, then a third loop up the west side to the aisle between the third and
#: fourth shelf rows (its pillars passed on the south side), east along it past the cross
#: aisle and back, down the cross aisle, west along the central aisle and down the west side
#: to the start, revisiting the places of the first two loops.
WAREHOUSE_10MIN_ROUTE: tuple[Waypoint, ...] = (
    *WAREHOUSE_ROUTE,
    Waypoint(2.0, 3.0),
    Waypoint(2.0, 14.3, spin=2 * math.pi),
    Waypoint(24.0, 14.3, spin=2 * math.pi),
    Waypoint(15.2, 14.3),
    Waypoint(15.2, 11.0),
    Waypoint(5.6, 11.0, spin=2 * math.pi),
    Waypoint(4.8, 12.0),
    Waypoint(2.0, 12.0),
    Waypoint(2.0, 3.0),
    Waypoint(2.5, 2.0, spin=math.pi),
)


class RouteDriver(Node):
    """Follows ``route``; ``done`` is set at the end (or ``failed`` after ``timeout_s``)."""

    def __init__(self, route: tuple[Waypoint, ...], *, speed: float = 0.35, turn_speed: float = 0.7,
                 lookahead: float = 0.4, timeout_s: float = 1200.0, stuck_after_s: float = 1.0,
                 stuck_distance: float = 0.02, align_tolerance: float = math.radians(2.0),
                 **kwargs: Any) -> None:
        super().__init__("route_driver", **kwargs)
        if not stuck_after_s > 0.0:
            raise ValueError(f"RouteDriver: stuck_after_s must be > 0 s, got {stuck_after_s}")
        if not 0.0 < align_tolerance < math.radians(35):
            raise ValueError(f"RouteDriver: align_tolerance must be in (0, 35°) rad, got {align_tolerance}")
        self.route = route
        self.speed, self.turn_speed, self.lookahead = speed, turn_speed, lookahead
        self.stuck_ns = round(stuck_after_s * 1e9)
        self.stuck_distance, self.align_tolerance = stuck_distance, align_tolerance
        #: Times a forward command did not move the robot and it turned to face its carrot.
        self.realignments = 0
        #: Where each realignment started (world x, y), for reports.
        self.stuck_at: list[tuple[float, float]] = []
        self._aligning = False
        self._progress: tuple[int, float, float] | None = None
        self.timeout_ns = round(timeout_s * 1e9)
        self.index = 0
        self.spin_left = 0.0
        self._segment_start: tuple[float, float] | None = None
        self.pose: tuple[float, float, float] | None = None
        self._last_yaw: float | None = None
        self.done = threading.Event()
        self.failed = False
        self.started_ns: int | None = None
        self.distance = 0.0
        self.pub = self.create_publisher(Twist, "/cmd_vel_teleop", 10)
        self.create_subscription(Odometry, "/ground_truth/odom", self._on_truth, 10)
        self.create_timer(0.05, self._tick)

    def _on_truth(self, msg: Any) -> None:
        p = msg.pose.pose
        q = p.orientation
        pose = (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))
        if self.pose is not None:
            self.distance += math.hypot(pose[0] - self.pose[0], pose[1] - self.pose[1])
        self.pose = pose

    def _send(self, v: float, w: float) -> None:
        t = Twist()
        t.linear.x, t.angular.z = v, w
        self.pub.publish(t)

    def _tick(self) -> None:
        if self.done.is_set() or self.pose is None:
            return
        now = self.get_clock().now_ns()
        if self.started_ns is None:
            self.started_ns = now
        if now - self.started_ns > self.timeout_ns:
            self.failed = True
            self._send(0.0, 0.0)
            self.done.set()
            return
        x, y, th = self.pose
        if self.spin_left > 0:
            self._progress = None
            if self._last_yaw is not None:
                self.spin_left -= abs(float(wrap_angle(th - self._last_yaw)))
            self._last_yaw = th
            self._send(0.0, self.turn_speed if self.spin_left > 0 else 0.0)
            if self.spin_left <= 0:
                self._advance()
            return
        if self.index >= len(self.route):
            self._send(0.0, 0.0)
            self.done.set()
            return
        wp = self.route[self.index]
        dx, dy = wp.x - x, wp.y - y
        dist = math.hypot(dx, dy)
        if dist < 0.12:
            if wp.spin > 0:
                self.spin_left, self._last_yaw = wp.spin, th
                self._send(0.0, 0.0)
            else:
                self._advance()
            return
        # Pure pursuit on the segment from the previous waypoint: a carrot `lookahead` beyond
        # the robot's projection on the line, so a lateral offset (after a spin, say) is
        # removed within a metre instead of being carried into the next doorway.
        tx, ty = wp.x, wp.y
        if self._segment_start is not None:
            sx, sy = self._segment_start
            lx, ly = wp.x - sx, wp.y - sy
            length = math.hypot(lx, ly)
            if length > 1e-6:
                ux, uy = lx / length, ly / length
                along = (x - sx) * ux + (y - sy) * uy
                carrot = min(length, max(0.0, along) + max(self.lookahead, 0.5))
                tx, ty = sx + carrot * ux, sy + carrot * uy
        err = float(wrap_angle(math.atan2(ty - y, tx - x) - th))
        if self._aligning:
            if abs(err) > self.align_tolerance:
                # slowing near the heading so the turn ends inside the tolerance
                self._send(0.0, math.copysign(min(self.turn_speed, max(0.15, 1.5 * abs(err))), err))
                return
            self._aligning = False
        if abs(err) > math.radians(35):
            self._progress = None
            self._send(0.0, math.copysign(self.turn_speed, err))
            return
        if self._progress is None or math.hypot(x - self._progress[1], y - self._progress[2]) > self.stuck_distance:
            self._progress = (now, x, y)
        elif now - self._progress[0] > self.stuck_ns:
            self._progress = None
            self._aligning = True
            self.realignments += 1
            self.stuck_at.append((x, y))
            self._send(0.0, 0.0)
            return
        curvature = 2.0 * math.sin(err) / max(self.lookahead, min(math.hypot(tx - x, ty - y), 1.0))
        v = min(self.speed, 0.6 * dist + 0.05)
        self._send(v, max(-self.turn_speed, min(self.turn_speed, v * curvature)))

    def _advance(self) -> None:
        self.spin_left = 0.0
        self._last_yaw = None
        if self.index < len(self.route):
            wp = self.route[self.index]
            self._segment_start = (wp.x, wp.y)
        self.index += 1
