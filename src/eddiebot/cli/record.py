"""``eddie record -o DIR (-a | TOPIC...)``: record topics to a rosbag2 MCAP bag.

Joins the graph through the transport (when installed) so topics of other processes are
recorded too; Ctrl-C closes the bag cleanly (a killed recorder leaves a truncated MCAP that
``eddie bag info`` and ``eddie play`` still read up to the cut).
"""

from __future__ import annotations

import argparse
import sys


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("topics", nargs="*", metavar="TOPIC", help="topics to record")
    parser.add_argument("-a", "--all", action="store_true",
                        help="record every topic, including topics that appear later")
    parser.add_argument("-o", "--output", default="",
                        help="bag directory (default: rosbag2_<date>-<time>)")
    parser.add_argument("-e", "--exclude", action="append", default=[], metavar="REGEX",
                        help="do not record topics matching REGEX (repeatable)")
    parser.add_argument("-d", "--max-bag-duration", type=float, default=0.0, metavar="S",
                        help="split the bag every S seconds (0: never)")
    parser.add_argument("-b", "--max-bag-size", type=int, default=0, metavar="BYTES",
                        help="split the bag when a file reaches BYTES (0: never)")
    parser.add_argument("--polling-interval", type=float, default=0.1, metavar="S",
                        help="how often to look for new topics (s)")
    parser.add_argument("--use-sim-time", action="store_true",
                        help="stamp messages with /clock time instead of wall time")
    parser.add_argument("--no-transport", action="store_true",
                        help="do not connect to other processes")


def run(args: argparse.Namespace) -> int:
    from eddiebot.bag import BagError, RecorderNode
    from eddiebot.core.context import Context
    from eddiebot.core.errors import ParameterError
    from eddiebot.core.launch import spin_nodes

    if not args.all and not args.topics:
        print("eddie record: give topics or -a/--all", file=sys.stderr)
        return 2
    context = Context(use_sim_time=args.use_sim_time)
    if not args.no_transport:
        try:
            from eddiebot.transport import connect

            connect(context)
        except ImportError:
            pass
    overrides = {
        "output": args.output,
        "all": bool(args.all),
        "topics": list(args.topics),
        "exclude": list(args.exclude),
        "max_bag_duration": float(args.max_bag_duration),
        "max_bag_size": int(args.max_bag_size),
        "polling_interval": float(args.polling_interval),
    }
    try:
        recorder = RecorderNode(context=context, parameter_overrides=overrides)
    except (BagError, ParameterError) as exc:
        print(f"eddie record: {exc}", file=sys.stderr)
        context.shutdown()
        return 2
    try:
        spin_nodes([recorder], context)
    finally:
        recorder.destroy_node()  # idempotent: the bag is closed whatever stopped us
        context.shutdown()
    print(f"recorded {recorder.writer.message_count} messages to {recorder.output}")
    return 0
