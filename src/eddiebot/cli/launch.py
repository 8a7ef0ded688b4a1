"""``eddie launch FILE [name:=value ...]``: run a YAML launch file in this process.

A launch that runs the simulator on sim time (``eddie launch sim``) publishes ``/clock``: it
refuses to start when a simulator already runs on the same ROS_DOMAIN_ID, as ``eddie sim``
does (`eddiebot.cli._attach.refuse_second_simulator`).
"""

from __future__ import annotations

import argparse
import sys

from eddiebot.cli._attach import publishes_clock, refuse_second_simulator
from eddiebot.cli._common import connect_transport
from eddiebot.core.context import Context
from eddiebot.core.errors import ParameterError
from eddiebot.core.launch import (
    LaunchError,
    build_nodes,
    find_launch_file,
    parse_cli_args,
    parse_launch_file,
    spin_nodes,
)
from eddiebot.registry import NODES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", help="a launch file, or the name of one of the package's (bringup)")
    parser.add_argument("launch_args", nargs="*", metavar="name:=value", help="launch arguments")
    parser.add_argument("--show-args", action="store_true", help="print the file's arguments and exit")
    parser.add_argument("--rate", type=float, default=None,
                        help="real-time factor on a sim clock (default: as fast as possible)")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many seconds of node-clock time")
    parser.add_argument("--no-transport", action="store_true",
                        help="do not connect to other processes (Zenoh)")


def run(args: argparse.Namespace) -> int:
    try:
        path = find_launch_file(args.file)
        desc = parse_launch_file(path, parse_cli_args(args.launch_args))
        if args.show_args:
            for name, value in desc.args.items():
                print(f"{name}:={value}")
            return 0
        use_sim_time = str(desc.args.get("use_sim_time", "false")).lower() == "true"
    except (LaunchError, ParameterError) as exc:
        print(f"eddie launch: {exc}", file=sys.stderr)
        return 2
    context = Context(use_sim_time=use_sim_time)
    try:
        if not args.no_transport:
            connect_transport(context)
            if publishes_clock((spec.type for spec in desc.nodes), use_sim_time, NODES):
                refuse_second_simulator(context, f"eddie launch {args.file}")
        nodes = build_nodes(desc, context, NODES)
    except (LaunchError, ParameterError) as exc:
        context.shutdown()
        print(f"eddie launch: {exc}", file=sys.stderr)
        return 2
    except BaseException:
        context.shutdown()
        raise
    print(f"launched {len(nodes)} nodes from {path}: "
          + ", ".join(n.fully_qualified_name for n in nodes), file=sys.stderr)
    return spin_nodes(nodes, context, real_time_factor=args.rate, duration_s=args.duration)
