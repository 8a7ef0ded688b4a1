"""``eddie topic list|echo|hz|bw|delay|info|pub`` — as ``ros2 topic``.

``hz``, ``bw`` take samples raw (CDR bytes), so they work on any type, described here or
not; ``echo`` and ``delay`` decode, so they need the type's definition (shipped, or an
interface file on ``EDDIE_INTERFACE_PATH``/``AMENT_PREFIX_PATH``; ``echo`` also asks the
publishers' ``~/get_type_description``) and say so in one line when there is none.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

from eddiebot.cli._common import (
    cli_session,
    discovery_wait_s,
    get_field,
    message_from_yaml,
    message_to_yaml,
    parse_type,
)
from eddiebot.cli._topic_publishers import _publisher_qos_hint, _type_from_publishers
from eddiebot.cli.topic_stats import DELAY_WINDOW, DelayStats, _bw, _delay, _hz
from eddiebot.msgs.errors import UnknownTypeError

__all__ = ["DelayStats", "add_arguments", "run"]


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value <= 0:
        raise argparse.ArgumentTypeError(f"wants a positive integer, got {text!r}")
    return value


def _qos_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--qos-depth", type=int, default=None, help="queue depth (default 10)")
    p.add_argument("--qos-reliability", choices=["reliable", "best_effort"], default=None)
    p.add_argument("--qos-durability", choices=["volatile", "transient_local"], default=None)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("list", help="topics in the graph")
    p.add_argument("-t", "--show-types", action="store_true", help="show each topic's type")
    p.add_argument("-c", "--count-topics", action="store_true", help="only print the number")
    p.add_argument("-a", "--include-hidden-topics", action="store_true")

    p = sub.add_parser("echo", help="print the messages of a topic")
    p.add_argument("topic_name")
    p.add_argument("message_type", nargs="?", default=None,
                   help="type (default: discovered from the graph)")
    p.add_argument("--once", action="store_true", help="print one message and exit")
    p.add_argument("--field", default=None, help="print only this field, e.g. linear.x")
    p.add_argument("--truncate-length", type=int, default=128,
                   help="truncate arrays and strings longer than this (default 128)")
    p.add_argument("--full-length", "-f", action="store_true", help="never truncate")
    p.add_argument("--no-arr", action="store_true", help="do not print arrays")
    p.add_argument("--flow-style", action="store_true", help="YAML flow style")
    p.add_argument("--timeout", type=float, default=None,
                   help="give up after this many seconds without a message (exit 1)")
    _qos_args(p)

    p = sub.add_parser("hz", help="print the average publishing rate")
    p.add_argument("topic_name")
    p.add_argument("--window", "-w", type=int, default=10000, help="samples in the window")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")

    p = sub.add_parser("bw", help="print the bandwidth a topic uses")
    p.add_argument("topic_name")
    p.add_argument("--window", "-w", type=int, default=100, help="samples in the window")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")

    p = sub.add_parser("delay", help="print the delay between header stamps and receipt")
    p.add_argument("topic_name")
    p.add_argument("--window", "-w", type=_positive_int, default=DELAY_WINDOW,
                   help=f"samples in the window (default {DELAY_WINDOW})")
    p.add_argument("--use-sim-time", action="store_true",
                   help="measure against /clock instead of the system clock")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")

    p = sub.add_parser("type", help="the type of a topic")
    p.add_argument("topic_name")
    p = sub.add_parser("find", help="the topics of a type")
    p.add_argument("topic_type")
    p.add_argument("-c", "--count-topics", action="store_true")
    p.add_argument("-a", "--include-hidden-topics", action="store_true")
    p = sub.add_parser("info", help="type, publishers and subscribers of a topic")
    p.add_argument("topic_name")
    p.add_argument("-v", "--verbose", action="store_true", help="every endpoint with its QoS")

    p = sub.add_parser("pub", help="publish a message (YAML values) to a topic")
    p.add_argument("topic_name")
    p.add_argument("message_type")
    p.add_argument("values", nargs="?", default="{}", help='YAML, e.g. "{data: hi}"')
    g = p.add_mutually_exclusive_group()
    g.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    g.add_argument("-t", "--times", type=int, default=None, help="publish N messages and exit")
    p.add_argument("-r", "--rate", type=float, default=1.0, help="publishing rate in Hz (default 1)")
    p.add_argument("-w", "--wait-matching-subscriptions", type=int, default=None,
                   help="wait for N matching subscriptions first (default 1 with --once/--times)")
    p.add_argument("--max-wait-time-secs", type=float, default=None,
                   help="give up waiting for subscriptions after this many seconds")
    p.add_argument("--keep-alive", type=float, default=0.1,
                   help="seconds to stay up after the last message (default 0.1)")
    p.add_argument("-p", "--print", dest="print_nth", type=int, default=1,
                   help="print every N-th message (0: never)")
    _qos_args(p)
    parser.set_defaults(_parser=parser)


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    try:
        return int({"list": _list, "echo": _echo, "hz": _hz, "bw": _bw, "delay": _delay,
                    "info": _info, "pub": _pub, "type": _type, "find": _find}[verb](args))
    except (ValueError, UnknownTypeError) as exc:
        print(f"eddie topic {verb}: {exc}", file=sys.stderr)
        return 2


def _hidden(name: str) -> bool:
    return any(tok.startswith("_") for tok in name.split("/"))


def _qos(args: argparse.Namespace, default_tl: bool = False, default_be: bool = False) -> Any:
    from eddiebot.core.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    dur = args.qos_durability or ("transient_local" if default_tl else "volatile")
    rel = args.qos_reliability or ("best_effort" if default_be else "reliable")
    return QoSProfile(
        depth=args.qos_depth or 10,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if dur == "transient_local"
        else DurabilityPolicy.VOLATILE,
        reliability=ReliabilityPolicy.BEST_EFFORT if rel == "best_effort"
        else ReliabilityPolicy.RELIABLE,
    )


# -- list -----------------------------------------------------------------------------
def _list(args: argparse.Namespace) -> int:
    with cli_session("topic") as s:
        s.wait(discovery_wait_s())
        topics = {k: v for k, v in s.topic_types().items()
                  if args.include_hidden_topics or not _hidden(k)}
        if args.count_topics:
            print(len(topics))
            return 0
        for name in sorted(topics):
            if args.show_types:
                print(f"{name} [{', '.join(sorted(topics[name]))}]")
            else:
                print(name)
    return 0


# -- echo -----------------------------------------------------------------------------
def _echo(args: argparse.Namespace) -> int:
    from eddiebot.core import SingleThreadedExecutor
    from eddiebot.msgs import get_message

    topic = args.topic_name if args.topic_name.startswith("/") else "/" + args.topic_name
    with cli_session("topic") as s:
        type_name = parse_type(args.message_type) if args.message_type else None
        if type_name is None:
            type_name = s.wait_for_topic_type(topic, args.timeout)
            if type_name is None:
                print(f"eddie topic echo: topic {topic} did not appear within {args.timeout} s",
                      file=sys.stderr)
                return 1
        tl, be = _publisher_qos_hint(s, topic)
        truncate = None if args.full_length else args.truncate_length
        received = [0]

        def on_msg(msg: Any) -> None:
            try:
                value = get_field(msg, args.field)
            except ValueError as exc:
                print(f"eddie topic echo: {exc}", file=sys.stderr)
                received[0] = -1
                return
            print(message_to_yaml(value, truncate=truncate, no_arr=args.no_arr,
                                  flow_style=args.flow_style))
            print("---", flush=True)
            received[0] += 1

        try:
            msg_type = get_message(type_name)
        except UnknownTypeError as exc:
            asked = _type_from_publishers(s, topic, type_name)
            if isinstance(asked, str):
                print(f"eddie topic echo: cannot decode {topic}: {exc}{asked}", file=sys.stderr)
                return 2
            msg_type = asked
        s.node.create_subscription(msg_type, topic, on_msg,
                                   _qos(args, default_tl=tl, default_be=be))
        ex = SingleThreadedExecutor(context=s.context)
        ex.add_node(s.node)
        last = time.monotonic()
        seen = 0
        while s.context.ok():
            ex.spin_once(timeout_sec=0.1)
            if received[0] < 0:
                return 2
            if received[0] != seen:
                seen, last = received[0], time.monotonic()
            if args.once and received[0] >= 1:
                return 0
            if args.timeout is not None and time.monotonic() - last > args.timeout:
                print(f"eddie topic echo: no message on {topic} within {args.timeout} s",
                      file=sys.stderr)
                return 1
    return 0


# -- type / find ----------------------------------------------------------------------
def _type(args: argparse.Namespace) -> int:
    topic = args.topic_name if args.topic_name.startswith("/") else "/" + args.topic_name
    with cli_session("topic") as s:
        s.wait(discovery_wait_s())
        types = s.topic_types().get(topic)
    if not types:
        print(f"Unknown topic '{topic}'", file=sys.stderr)
        return 1
    print("\n".join(sorted(types)))
    return 0


def _find(args: argparse.Namespace) -> int:
    wanted = parse_type(args.topic_type)
    with cli_session("topic") as s:
        s.wait(discovery_wait_s())
        found = sorted(name for name, types in s.topic_types().items()
                       if wanted in types and (args.include_hidden_topics or not _hidden(name)))
    if args.count_topics:
        print(len(found))
    else:
        for name in found:
            print(name)
    return 0


# -- info -----------------------------------------------------------------------------
def _info(args: argparse.Namespace) -> int:
    topic = args.topic_name if args.topic_name.startswith("/") else "/" + args.topic_name
    with cli_session("topic") as s:
        s.wait(discovery_wait_s())
        types = s.topic_types().get(topic)
        if not types:
            print(f"Unknown topic '{topic}'", file=sys.stderr)
            return 1
        cache = s.remote()
        pubs = list(cache.publishers(topic)) if cache is not None else []
        subs = list(cache.subscriptions(topic)) if cache is not None else []
        entry = s.context.topics.get(topic)
        local_pubs = [p for p in entry.publishers if p.node is not s.node] if entry else []
        local_subs = [q for q in entry.subscriptions if q.node is not s.node] if entry else []
        print(f"Type: {', '.join(sorted(types))}")
        print()
        print(f"Publisher count: {len(pubs) + len(local_pubs)}")
        if args.verbose:
            print()
            for e in pubs:
                _print_endpoint(e, "PUBLISHER")
        print(f"Subscription count: {len(subs) + len(local_subs)}")
        if args.verbose:
            print()
            for e in subs:
                _print_endpoint(e, "SUBSCRIPTION")
    return 0


def _print_endpoint(e: Any, kind: str) -> None:
    from eddiebot.transport.keys import qos_from_keyexpr

    q = qos_from_keyexpr(e.qos)
    gid = ".".join(f"{b:02x}" for b in e.gid)
    print(f"Node name: {e.node_name}")
    print(f"Node namespace: {e.namespace}")
    print(f"Topic type: {e.type_name}")
    print(f"Topic type hash: {e.type_hash}")
    print(f"Endpoint type: {kind}")
    print(f"GID: {gid}")
    print("QoS profile:")
    print(f"  Reliability: {q.reliability.name}")
    print(f"  History (Depth): {q.history.name} ({q.depth})")
    print(f"  Durability: {q.durability.name}")
    print()


# -- pub ------------------------------------------------------------------------------
def _pub(args: argparse.Namespace) -> int:
    from eddiebot.msgs import get_message

    topic = args.topic_name if args.topic_name.startswith("/") else "/" + args.topic_name
    type_name = parse_type(args.message_type)
    msg = message_from_yaml(type_name, args.values)
    times = 1 if args.once else args.times
    wait_n = args.wait_matching_subscriptions
    if wait_n is None:
        wait_n = 1 if times is not None else 0
    with cli_session("topic") as s:
        pub = s.node.create_publisher(get_message(type_name), topic, _qos(args))
        if wait_n > 0:
            print(f"Waiting for at least {wait_n} matching subscription(s)...", flush=True)
            deadline = (None if args.max_wait_time_secs is None
                        else time.monotonic() + args.max_wait_time_secs)
            while pub.get_subscription_count() < wait_n:
                if deadline is not None and time.monotonic() >= deadline:
                    print(f"eddie topic pub: no {wait_n} matching subscription(s) on {topic} "
                          f"within {args.max_wait_time_secs} s", file=sys.stderr)
                    return 1
                time.sleep(0.01)
        print("publisher: beginning loop", flush=True)
        period = 1.0 / args.rate if args.rate > 0 else 1.0
        count = 0
        next_t = time.monotonic()
        while s.context.ok():
            count += 1
            pub.publish(msg)
            if args.print_nth and count % args.print_nth == 0:
                print(f"publishing #{count}: {msg}", flush=True)
            if times is not None and count >= times:
                break
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
        time.sleep(max(0.0, args.keep_alive))
    return 0
