"""``eddie play BAG [--rate R] [--loop] [--topics T...] [--clock]``: replay a rosbag2.

Publishes every message with its recorded timing (× ``--rate``); transient-local topics are
latched. A damaged or truncated bag is played up to the damage, and the damage is reported.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bag", type=Path, help="bag directory, .mcap or .db3 file")
    parser.add_argument("-r", "--rate", type=float, default=1.0, help="playback rate")
    parser.add_argument("-l", "--loop", action="store_true", help="play again and again")
    parser.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics")
    parser.add_argument("--start-offset", type=float, default=0.0, metavar="S",
                        help="start S seconds into the bag")
    parser.add_argument("--clock", action="store_true", help="publish /clock with the bag time")
    parser.add_argument("--clock-frequency", type=float, default=40.0, metavar="HZ",
                        help="how often /clock is published between messages (default 40)")
    parser.add_argument("--delay", type=float, default=0.0, metavar="S",
                        help="wait S seconds before the first message (lets others discover)")
    parser.add_argument("--no-transport", action="store_true",
                        help="do not connect to other processes")


def run(args: argparse.Namespace) -> int:
    from eddiebot.bag import BagError, Player
    from eddiebot.core.context import Context
    from eddiebot.core.launch import spin_nodes

    context = Context()
    if not args.no_transport:
        try:
            from eddiebot.transport import connect

            connect(context)
        except ImportError:
            pass
    try:
        player = Player(
            args.bag,
            context=context,
            rate=args.rate,
            loop=args.loop,
            start_offset=args.start_offset,
            topics=args.topics,
            publish_clock=args.clock,
            clock_frequency=args.clock_frequency,
            delay=args.delay,
            shutdown_when_done=True,
        )
    except (BagError, ValueError) as exc:
        print(f"eddie play: {exc}", file=sys.stderr)
        context.shutdown()
        return 2
    for note in player.notes:
        print(f"eddie play: note: {note}", file=sys.stderr)
    try:
        if not player.done:
            spin_nodes([player], context)
        if context.transports:
            import time

            time.sleep(0.3)  # let the transport deliver the last messages before closing
    finally:
        player.destroy_node()
        context.shutdown()
    for problem in player.problems:
        print(f"eddie play: bag damaged at {problem}; played the {player.published} messages "
              "before it", file=sys.stderr)
    print(f"played {player.published} messages from {args.bag}")
    return 1 if player.problems else 0
