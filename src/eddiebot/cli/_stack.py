"""Running a launch description in the foreground: executor, /clock, transport, dashboard.

Shared by ``eddie sim``, ``eddie slam`` and ``eddie nav``.
"""

from __future__ import annotations

import argparse
import sys

from eddiebot.core.context import Context
from eddiebot.core.errors import ParameterError
from eddiebot.core.launch import (
    LaunchDescription,
    LaunchError,
    build_nodes,
    connect_transport,
    find_launch_file,
    parse_launch_file,
    spin_nodes,
)
from eddiebot.core.node import Node
from eddiebot.registry import NODES

__all__ = ["add_run_arguments", "run_stack"]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Options every simulated run shares."""
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, default=1.0,
                      help="real-time factor (default 1: real time; 5: five times faster)")
    pace.add_argument("--fast", action="store_true", help="as fast as the CPU allows")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random process")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many simulated seconds")
    parser.add_argument("--dashboard", action="store_true", help="serve the web dashboard")
    parser.add_argument("--dashboard-port", type=int, default=8080)
    parser.add_argument("--no-transport", action="store_true",
                        help="do not open the graph to other processes")


def build_description(launch: str, launch_args: dict[str, str]) -> LaunchDescription:
    return parse_launch_file(find_launch_file(launch), launch_args)


def run_stack(args: argparse.Namespace, launch: str, launch_args: dict[str, str]) -> int:
    """Build ``launch`` on a sim clock this process owns and spin it until interrupted."""
    context = Context(use_sim_time=True)
    try:
        nodes: list[Node] = build_nodes(build_description(launch, launch_args), context, NODES)
    except (LaunchError, ParameterError) as exc:
        print(f"eddie: {exc}", file=sys.stderr)
        return 2
    if not args.no_transport:
        connect_transport(context)
    dashboard = None
    if args.dashboard:
        try:
            from eddiebot.viz.dashboard import start_dashboard  # type: ignore[attr-defined]

            dashboard = start_dashboard(context, "127.0.0.1", args.dashboard_port)
            print(dashboard.url, flush=True)
        except ImportError:
            print("eddie: the dashboard is not installed", file=sys.stderr)
    try:
        return spin_nodes(nodes, context, real_time_factor=None if args.fast else args.rate,
                          duration_s=args.duration, owns_sim_clock=True)
    finally:
        if dashboard is not None:
            dashboard.stop()
