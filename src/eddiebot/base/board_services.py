"""The original Eddie stack's ten board services, served by the board node.

Each motion service passes the same checks as a velocity command (e-stop, low battery, the
IR/PING veto for forward motion) and goes through the board node's queue; the queries
answer from the counters the node polls, so no service call ever waits on the serial line.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from eddiebot.base.board_modes import Motion, StopKind
from eddiebot.msgs.eddiebot_msgs import (
    Accelerate,
    DriveWithDistance,
    DriveWithPower,
    DriveWithSpeed,
    GetDistance,
    GetHeading,
    GetSpeed,
    ResetEncoder,
    Rotate,
    StopAtDistance,
)
from eddiebot.robot.constants import POSITIONS_PER_REV, POSITIONS_PER_SPIN

if TYPE_CHECKING:
    from eddiebot.base.board_node import BoardNode

__all__ = ["serve_original_services"]


def serve_original_services(node: BoardNode) -> None:
    """The original stack's ten services on ``node``, under the same safety as ``/cmd_vel``:
    no motion while ``/e_stop`` is latched or the battery is low, forward motion only past the
    veto; ``TRVL``/``TURN`` end by themselves (the stale timer leaves them alone), ``GO`` and
    ``GOSPD`` stay under it. The queries answer from the polled counters (no serial traffic).
    """

    def motion_allowed(what: str, forward: bool) -> bool:
        refused = node._motion_refused()
        if refused is None and forward and node.safety.enabled and \
                node.veto.vetoed_at(node.get_clock().now_ns()):
            refused = "an obstacle is ahead (IR/PING veto)"
        if refused is not None:
            node.get_logger().warning(f"{what} refused: {refused}")
            return False
        return True

    def drive_with_distance(req: Any, res: Any) -> Any:
        distance, speed = int(req.distance), int(req.speed)
        if not motion_allowed("drive_with_distance", distance > 0):
            node.request_stop(StopKind.CUT, "refused service motion")
            return res
        node._last_cmd_ns = node.get_clock().now_ns()
        node._send_motion("TRVL", lambda b: b.travel(distance, speed), None,
                          Motion.SERVICE_MOVE, forward=distance > 0)
        return res

    def rotate(req: Any, res: Any) -> Any:
        angle, speed = int(req.angle), int(req.speed)
        if not motion_allowed("rotate", False):
            node.request_stop(StopKind.CUT, "refused service motion")
            return res
        node._last_cmd_ns = node.get_clock().now_ns()
        # the original's angle is degrees, clockwise positive on the wire; ours is REP-103
        node._send_motion("TURN", lambda b: b.turn(math.radians(-angle), speed), None,
                          Motion.SERVICE_MOVE)
        return res

    def drive_with_speed(req: Any, res: Any) -> Any:
        left, right = int(req.left), int(req.right)
        if (left, right) == (0, 0):
            node.request_stop(StopKind.HOLD, "zero speed from drive_with_speed")
            return res
        if not motion_allowed("drive_with_speed", left + right > 0):
            node.request_stop(StopKind.CUT, "refused service motion")
            return res
        node._last_cmd_ns = node.get_clock().now_ns()
        node._send_motion("GOSPD", lambda b: b.go_speed(left, right), (left, right),
                          Motion.SERVICE_SPEED, forward=left + right > 0)
        return res

    def drive_with_power(req: Any, res: Any) -> Any:
        left, right = int(req.left), int(req.right)
        if (left, right) == (0, 0):
            node.request_stop(StopKind.CUT, "zero power from drive_with_power")
            return res
        if not motion_allowed("drive_with_power", left + right > 0):
            node.request_stop(StopKind.CUT, "refused service motion")
            return res
        node._last_cmd_ns = node.get_clock().now_ns()
        node._send_motion("GO", lambda b: b.go_power(left, right), None,
                          Motion.SERVICE_SPEED, forward=left + right > 0)
        return res

    def stop_at_distance(req: Any, res: Any) -> Any:
        distance = int(req.distance)
        if distance == 0:
            node.request_stop(StopKind.CUT, "stop_at_distance 0")
        else:
            node._send_motion("STOPD", lambda b: b.stop(distance), None, Motion.SERVICE_MOVE)
        return res

    def acceleration_rate(req: Any, res: Any) -> Any:
        node._set_acceleration(int(req.rate))
        return res

    def reset_encoder(req: Any, res: Any) -> Any:
        # by an offset: /eddie/encoders_data restarts at 0, /joint_states stays continuous
        node.counters.reset_zero()
        return res

    def get_distance(req: Any, res: Any) -> Any:
        res.left, res.right = node.counters.since_zero()
        return res

    def get_heading(req: Any, res: Any) -> Any:
        # HEAD's own formula on the counts since reset_encoder: degrees, clockwise positive
        left, right = node.counters.since_zero()
        spin = round(POSITIONS_PER_SPIN * node.counts_per_rev / POSITIONS_PER_REV)
        diff = left - right
        rem = int(math.copysign(abs(diff) % spin, diff))
        res.heading = math.trunc(rem * 360 / spin) % 360
        return res

    def get_speed(req: Any, res: Any) -> Any:
        # SPD's meaning: positions/s averaged over the last 0.5 s of DIST polls
        speed = node.counters.average_speed()
        if speed is not None:
            res.left, res.right = speed
        return res

    node.create_service(Accelerate, "acceleration_rate", acceleration_rate)
    node.create_service(DriveWithDistance, "drive_with_distance", drive_with_distance)
    node.create_service(DriveWithPower, "drive_with_power", drive_with_power)
    node.create_service(DriveWithSpeed, "drive_with_speed", drive_with_speed)
    node.create_service(GetDistance, "get_distance", get_distance)
    node.create_service(GetHeading, "get_heading", get_heading)
    node.create_service(GetSpeed, "get_speed", get_speed)
    node.create_service(ResetEncoder, "reset_encoder", reset_encoder)
    node.create_service(Rotate, "rotate", rotate)
    node.create_service(StopAtDistance, "stop_at_distance", stop_at_distance)

