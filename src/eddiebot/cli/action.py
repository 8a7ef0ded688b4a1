"""``eddie action list|send_goal`` — as ``ros2 action``.

Actions are ROS 2's composition of services and topics under ``<name>/_action/``:
``send_goal``, ``get_result``, ``cancel_goal`` (services), ``feedback`` and ``status``
(topics); this command speaks those directly, so it works with any server that follows them.
"""

from __future__ import annotations

import argparse
import sys
import uuid
from typing import Any

from eddiebot.cli._common import cli_session, discovery_wait_s, fill_from_yaml, message_to_yaml

__all__ = ["add_arguments", "run"]

_STATUS = {0: "UNKNOWN", 1: "ACCEPTED", 2: "EXECUTING", 3: "CANCELING", 4: "SUCCEEDED",
           5: "CANCELED", 6: "ABORTED"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("list", help="actions in the graph")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("-c", "--count-actions", action="store_true")
    p = sub.add_parser("info", help="the servers and clients of an action")
    p.add_argument("action_name")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("-c", "--count", action="store_true")
    p = sub.add_parser("send_goal", help="send a goal (YAML values) and wait for the result")
    p.add_argument("action_name")
    p.add_argument("action_type")
    p.add_argument("goal", nargs="?", default="{}", help='YAML, e.g. "{order: 5}"')
    p.add_argument("-f", "--feedback", action="store_true", help="print the feedback")
    p.add_argument("--timeout", type=float, default=None,
                   help="give up after this many seconds (default: wait for the result)")
    parser.set_defaults(_parser=parser)


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    with cli_session("action") as s:
        if verb == "send_goal":
            return _send_goal(s, args)
        s.wait(discovery_wait_s())
        actions: dict[str, set[str]] = {}
        for name, types in s.service_types().items():
            if name.endswith("/_action/send_goal"):
                actions[name[: -len("/_action/send_goal")]] = {
                    t.removesuffix("_SendGoal") for t in types}
        if verb == "info":
            return _info(s, args, actions)
        if args.count_actions:
            print(len(actions))
            return 0
        for name in sorted(actions):
            print(f"{name} [{', '.join(sorted(actions[name]))}]" if args.show_types else name)
    return 0


def _info(s: Any, args: argparse.Namespace, actions: dict[str, set[str]]) -> int:
    """``ros2 action info``: who serves the action and who uses it (by its send_goal service)."""
    name = args.action_name if args.action_name.startswith("/") else "/" + args.action_name
    if name not in actions:
        print(f"Unknown action '{name}'", file=sys.stderr)
        return 1
    cache = s.remote()
    send_goal = f"{name}/_action/send_goal"
    servers = sorted({e.node for e in cache.services(send_goal)}) if cache is not None else []
    clients = sorted({e.node for e in cache.clients(send_goal)}) if cache is not None else []
    kind = f" [{', '.join(sorted(actions[name]))}]" if args.show_types else ""
    print(f"Action: {name}")
    print(f"Action clients: {len(clients)}")
    if not args.count:
        for node in clients:
            print(f"    {node}{kind}")
    print(f"Action servers: {len(servers)}")
    if not args.count:
        for node in servers:
            print(f"    {node}{kind}")
    return 0


def _send_goal(s: Any, args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from eddiebot.core import SingleThreadedExecutor
    from eddiebot.msgs import get_action

    action = get_action(args.action_type)
    name = args.action_name if args.action_name.startswith("/") else "/" + args.action_name
    goal = action.Goal()
    try:
        fill_from_yaml(goal, args.goal)
    except ValueError as exc:
        print(f"eddie action send_goal: {exc}", file=sys.stderr)
        return 2
    node = s.node
    send = node.create_client(action.SendGoal, f"{name}/_action/send_goal")
    result_client = node.create_client(action.GetResult, f"{name}/_action/get_result")
    goal_id = np.frombuffer(uuid.uuid4().bytes, dtype=np.uint8).copy()
    ex = SingleThreadedExecutor(context=s.context)
    ex.add_node(node)
    if args.feedback:
        def on_feedback(msg: Any) -> None:
            if bytes(bytearray(msg.goal_id.uuid)) == goal_id.tobytes():
                print("Feedback:")
                print(_indent(message_to_yaml(msg.feedback)))
                print(flush=True)

        node.create_subscription(action.FeedbackMessage, f"{name}/_action/feedback",
                                 on_feedback, 10)
    print("Waiting for an action server to become available...", flush=True)
    wait = 10.0 if args.timeout is None else args.timeout
    if not send.wait_for_service(timeout_sec=wait) or not result_client.wait_for_service(
            timeout_sec=wait):
        print(f"eddie action send_goal: action server {name} is not available", file=sys.stderr)
        return 1
    if args.feedback:
        time.sleep(0.2)  # let the server learn of the feedback subscription
    print("Sending goal:")
    print(_indent(message_to_yaml(goal)))
    print(flush=True)
    request = action.SendGoal.Request()
    request.goal_id.uuid = goal_id
    request.goal = goal
    future = send.call_async(request)
    ex.spin_until_future_complete(future, timeout_sec=args.timeout)
    if not future.done():
        print("eddie action send_goal: no answer to the goal", file=sys.stderr)
        return 1
    if not future.result().accepted:
        print("Goal was rejected.")
        return 1
    print(f"Goal accepted with ID: {goal_id.tobytes().hex()}\n", flush=True)
    req = action.GetResult.Request()
    req.goal_id.uuid = goal_id
    rfuture = result_client.call_async(req)
    ex.spin_until_future_complete(rfuture, timeout_sec=args.timeout)
    if not rfuture.done():
        print("eddie action send_goal: no result in time", file=sys.stderr)
        return 1
    res = rfuture.result()
    print("Result:")
    print(_indent(message_to_yaml(res.result)))
    print()
    status = _STATUS.get(int(res.status), str(res.status))
    print(f"Goal finished with status: {status}", flush=True)
    return 0 if status == "SUCCEEDED" else 1


def _indent(text: str) -> str:
    return "\n".join("    " + line for line in text.splitlines())
