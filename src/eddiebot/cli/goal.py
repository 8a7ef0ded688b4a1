"""``eddie goal X Y YAW [--frame map] [--timeout S]``: one ``navigate_to_pose`` goal.

Sends the goal over the transport to the running navigation (``eddie nav`` or ``eddie launch
nav``), prints the feedback (distance remaining, recoveries, time) and the result, and exits
non-zero on failure with the server's typed reason (e.g. ``GOAL_OCCUPIED (206)``). Ctrl-C
cancels the goal.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

__all__ = ["HELP", "add_arguments", "error_name", "navigate", "run"]

HELP = "send a navigation goal (x y yaw in the map frame) and wait for the result"

_STATUS = {4: "SUCCEEDED", 5: "CANCELED", 6: "ABORTED"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("x", type=float, help="m")
    parser.add_argument("y", type=float, help="m")
    parser.add_argument("yaw", type=float, nargs="?", default=0.0, help="rad (default 0)")
    parser.add_argument("--frame", default="map", help="frame of the goal (default map)")
    parser.add_argument("--timeout", type=float, default=None,
                        help="cancel and fail after this many seconds (wall time)")
    parser.add_argument("--quiet", action="store_true", help="no feedback lines")


def error_name(code: int) -> str:
    """``GOAL_OCCUPIED`` for 206: the nav2_msgs result constant with this value."""
    from eddiebot.msgs import nav2_msgs

    for action in ("ComputePathToPose", "FollowPath", "Spin", "BackUp", "DriveOnHeading",
                   "SmoothPath", "FollowWaypoints", "AssistedTeleop"):
        result = getattr(nav2_msgs, action).Result
        for attr in dir(result):
            if attr.isupper() and attr != "NONE" and getattr(result, attr) == code:
                return attr
    return "UNKNOWN"


def pose_goal(x: float, y: float, yaw: float, frame: str) -> Any:
    from eddiebot.nav.nodes._common import pose_stamped

    return pose_stamped(x, y, yaw, frame)


def _wait(ex: Any, future: Any, deadline: float | None) -> bool:
    while not future.done():
        if deadline is not None and time.monotonic() > deadline:
            return False
        ex.spin_once(timeout_sec=0.05)
    return True


def navigate(session: Any, action_type: Any, name: str, goal: Any, *, timeout: float | None,
             on_feedback: Any = None, server_wait: float = 10.0) -> tuple[int, Any]:
    """Send ``goal`` to action ``name`` and wait; (exit code, X_GetResult response or None)."""
    from eddiebot.core import SingleThreadedExecutor
    from eddiebot.core.action import ActionClient

    ex = SingleThreadedExecutor(context=session.context)
    ex.add_node(session.node)
    client = ActionClient(session.node, action_type, name)
    if not client.wait_for_server(timeout_sec=server_wait):
        print(f"eddie: action server {name} is not available (is `eddie nav` running?)",
              file=sys.stderr)
        return 1, None
    deadline = None if timeout is None else time.monotonic() + timeout
    future = client.send_goal_async(goal, feedback_callback=on_feedback)
    if not _wait(ex, future, deadline):
        print("eddie: no answer to the goal", file=sys.stderr)
        return 1, None
    handle = future.result()
    if not handle.accepted:
        print("eddie: goal rejected", file=sys.stderr)
        return 1, None
    # Ask for the result again whenever a request times out: a get_result call stays open
    # for the whole navigation and can outlive the transport's query timeout.
    from eddiebot.core.errors import ServiceCallTimeoutError

    getter = session.node.create_client(action_type.GetResult, f"{name}/_action/get_result")
    request = action_type.GetResult.Request(goal_id=handle.goal_id)
    result: Any = None
    try:
        while True:
            result = getter.call_async(request)
            done = _wait(ex, result, deadline)
            if not done or not isinstance(result.exception(), ServiceCallTimeoutError):
                break
    except KeyboardInterrupt:
        done = False
        print("\ncanceling the goal", file=sys.stderr)
    if not done:
        cancel = handle.cancel_goal_async()
        _wait(ex, cancel, time.monotonic() + 5.0)
        result = getter.call_async(request)
        _wait(ex, result, time.monotonic() + 5.0)
        if timeout is not None:
            print(f"eddie: timed out after {timeout:g} s; goal canceled", file=sys.stderr)
        return 1, result.result() if result.done() and result.exception() is None else None
    if result.exception() is not None:
        print(f"eddie: {result.exception()}", file=sys.stderr)
        return 1, None
    response = result.result()
    return (0 if int(response.status) == 4 else 1), response


def report(response: Any) -> int:
    status = _STATUS.get(int(response.status), str(response.status))
    code = int(getattr(response.result, "error_code", 0))
    if status == "SUCCEEDED":
        print("Goal reached.")
        return 0
    if code:
        print(f"Navigation {status.lower()}: {error_name(code)} ({code}): {response.result.error_msg}",
              file=sys.stderr)
    else:
        print(f"Navigation {status.lower()}.", file=sys.stderr)
    return 1


def run(args: argparse.Namespace) -> int:
    from eddiebot.cli._common import cli_session
    from eddiebot.msgs.nav2_msgs import NavigateToPose

    last = [0.0]

    def on_feedback(msg: Any) -> None:
        if args.quiet:
            return
        now = time.monotonic()
        if now - last[0] < 1.0:
            return
        last[0] = now
        fb = msg.feedback
        p = fb.current_pose.pose.position
        print(f"at ({p.x:6.2f}, {p.y:6.2f})  remaining {fb.distance_remaining:5.2f} m  "
              f"eta {fb.estimated_time_remaining.sec:3d} s  recoveries {fb.number_of_recoveries}  "
              f"t {fb.navigation_time.sec} s", flush=True)

    goal = NavigateToPose.Goal(pose=pose_goal(args.x, args.y, args.yaw, args.frame))
    print(f"Goal: ({args.x:g}, {args.y:g}, {math.degrees(args.yaw):.0f}°) in {args.frame}", flush=True)
    with cli_session("goal") as s:
        code, response = navigate(s, NavigateToPose, "/navigate_to_pose", goal,
                                  timeout=args.timeout, on_feedback=on_feedback)
        if response is None:
            return 1
        return report(response) or code
