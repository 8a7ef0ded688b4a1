"""``eddie lifecycle nodes|get|list|set`` — as ``ros2 lifecycle``: the managed nodes of the
graph, a node's state, its available transitions, and triggering one by label or id."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from eddiebot.cli._common import CliSession, cli_session, discovery_wait_s

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.add_parser("nodes", help="the lifecycle nodes of the graph")
    p = sub.add_parser("get", help="the current state of a lifecycle node")
    p.add_argument("node_name")
    p = sub.add_parser("list", help="the transitions a lifecycle node offers now")
    p.add_argument("node_name")
    p = sub.add_parser("set", help="trigger a transition (label such as configure, or id)")
    p.add_argument("node_name")
    p.add_argument("transition")
    for p in sub.choices.values():
        p.add_argument("--timeout", type=float, default=5.0,
                       help="seconds to wait for the node's services (default 5)")
    parser.set_defaults(_parser=parser)


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    with cli_session("lifecycle") as s:
        s.wait(discovery_wait_s())
        if verb == "nodes":
            for name in sorted(n[: -len("/get_state")] for n, types in s.service_types().items()
                               if n.endswith("/get_state")
                               and "lifecycle_msgs/srv/GetState" in types):
                print(name)
            return 0
        node = args.node_name if args.node_name.startswith("/") else "/" + args.node_name
        if verb == "get":
            from eddiebot.msgs.lifecycle_msgs import GetState

            response = _call(s, GetState, f"{node}/get_state", GetState.Request(), args.timeout)
            if response is None:
                return 1
            state = response.current_state
            print(f"{state.label} [{state.id}]")
            return 0
        from eddiebot.msgs.lifecycle_msgs import GetAvailableTransitions

        response = _call(s, GetAvailableTransitions, f"{node}/get_available_transitions",
                         GetAvailableTransitions.Request(), args.timeout)
        if response is None:
            return 1
        transitions = list(response.available_transitions)
        if verb == "list":
            for t in transitions:
                print(f"- {t.transition.label} [{t.transition.id}]")
                print(f"\tStart: {t.start_state.label}")
                print(f"\tGoal: {t.goal_state.label}")
            return 0
        return _set(s, node, args.transition, transitions, args.timeout)


def _set(s: CliSession, node: str, wanted: str, transitions: list[Any], timeout: float) -> int:
    from eddiebot.msgs.lifecycle_msgs import ChangeState, Transition

    match = [t.transition for t in transitions
             if t.transition.label == wanted or str(t.transition.id) == wanted]
    if not match:
        offered = ", ".join(f"{t.transition.label} [{t.transition.id}]" for t in transitions)
        print(f"eddie lifecycle set: {node} cannot take transition {wanted!r} now "
              f"(available: {offered or 'none'})", file=sys.stderr)
        return 1
    request = ChangeState.Request(transition=Transition(id=match[0].id, label=match[0].label))
    response = _call(s, ChangeState, f"{node}/change_state", request, timeout)
    if response is None:
        return 1
    if not response.success:
        print(f"eddie lifecycle set: {node} refused {match[0].label}", file=sys.stderr)
        return 1
    print("Transitioning successful")
    return 0


def _call(s: CliSession, srv_type: Any, name: str, request: Any, timeout: float) -> Any:
    from eddiebot.core.errors import ServiceCallTimeoutError, ServiceUnavailableError

    client = s.node.create_client(srv_type, name)
    if not client.wait_for_service(timeout_sec=timeout):
        print(f"eddie lifecycle: {name} is not available (not a lifecycle node?)",
              file=sys.stderr)
        return None
    try:
        return client.call(request, timeout_sec=timeout)
    except (ServiceCallTimeoutError, ServiceUnavailableError) as exc:
        print(f"eddie lifecycle: {exc}", file=sys.stderr)
        return None
