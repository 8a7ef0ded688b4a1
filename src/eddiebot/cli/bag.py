"""``eddie bag info BAG``: what a rosbag2 holds (``ros2 bag info``), and where it is damaged."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bag_command", metavar="VERB", required=True)
    info = sub.add_parser("info", help="summary of a bag: duration, topics, counts, damage")
    info.add_argument("bag", type=Path, help="bag directory, .mcap or .db3 file")


def run(args: argparse.Namespace) -> int:
    from eddiebot.bag import BagError, bag_info, format_bag_info

    if args.bag_command != "info":  # pragma: no cover - argparse enforces the choice
        return 2
    try:
        info = bag_info(args.bag)
    except BagError as exc:
        print(f"eddie bag info: {exc}", file=sys.stderr)
        return 2
    print(format_bag_info(info))
    return 1 if info.problems else 0
