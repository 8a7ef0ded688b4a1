"""``eddie run TYPE [--ros-args -p name:=value -r from:=to --params-file F]``: one node.

The simulator on sim time (``eddie run eddiebot.sim.simulator --use-sim-time``) publishes
``/clock``: it refuses to start when a simulator already runs on the same ROS_DOMAIN_ID, as
``eddie sim`` does (`eddiebot.cli._attach.refuse_second_simulator`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from eddiebot.cli._attach import publishes_clock, refuse_second_simulator
from eddiebot.cli._common import connect_transport
from eddiebot.core.context import Context
from eddiebot.core.errors import ParameterError
from eddiebot.core.launch import (
    LaunchDescription,
    LaunchError,
    NodeSpec,
    build_nodes,
    spin_nodes,
)
from eddiebot.registry import NODES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("type", help=f"registered node type, one of: {', '.join(sorted(NODES))}")
    parser.add_argument("--name", help="node name (default: the node's own)")
    parser.add_argument("--namespace", default="", help="node namespace")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE")
    parser.add_argument("-r", "--remap", action="append", default=[], metavar="FROM:=TO")
    parser.add_argument("--params-file", action="append", default=[], type=Path)
    parser.add_argument("--use-sim-time", action="store_true")
    parser.add_argument("--no-transport", action="store_true")


def run(args: argparse.Namespace) -> int:
    import yaml

    spec = NodeSpec(type=args.type, name=args.name, namespace=args.namespace,
                    param_files=list(args.params_file), where="command line")
    try:
        for item in args.param:
            name, sep, value = item.partition(":=")
            if not sep:
                raise LaunchError(f"-p expects NAME:=VALUE, got {item!r}")
            spec.params[name] = yaml.safe_load(value) if value else ""
        for item in args.remap:
            src, sep, dst = item.partition(":=")
            if not sep:
                raise LaunchError(f"-r expects FROM:=TO, got {item!r}")
            spec.remaps[src] = dst
    except LaunchError as exc:
        print(f"eddie run: {exc}", file=sys.stderr)
        return 2
    context = Context(use_sim_time=args.use_sim_time)
    try:
        if not args.no_transport:
            connect_transport(context)
            if publishes_clock([spec.type], args.use_sim_time, NODES):
                refuse_second_simulator(context, f"eddie run {args.type}")
        nodes = build_nodes(LaunchDescription(nodes=[spec]), context, NODES)
    except (LaunchError, ParameterError) as exc:
        context.shutdown()
        print(f"eddie run: {exc}", file=sys.stderr)
        return 2
    except BaseException:
        context.shutdown()
        raise
    return spin_nodes(nodes, context)
