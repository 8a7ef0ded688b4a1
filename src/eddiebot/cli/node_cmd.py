"""``eddie node list|info`` — as ``ros2 node``."""

from __future__ import annotations

import argparse
import sys

from eddiebot.cli._common import cli_session, discovery_wait_s

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("list", help="nodes in the graph")
    p.add_argument("-a", "--all", action="store_true", help="include hidden nodes")
    p.add_argument("-c", "--count-nodes", action="store_true", help="only print the number")
    p = sub.add_parser("info", help="a node's publishers, subscribers and services")
    p.add_argument("node_name")
    parser.set_defaults(_parser=parser)


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    with cli_session("node") as s:
        s.wait(discovery_wait_s())
        if verb == "list":
            names = s.node_names(include_hidden=args.all)
            if args.count_nodes:
                print(len(names))
            else:
                for n in names:
                    print(n)
            return 0
        name = args.node_name if args.node_name.startswith("/") else "/" + args.node_name
        if name not in s.node_names(include_hidden=True):
            print(f"Unable to find node '{name}'", file=sys.stderr)
            return 1
        cache = s.remote()
        ents = [e for e in cache.entities() if e.node == name] if cache is not None else []
        print(name)
        for title, kind in (("Subscribers", "MS"), ("Publishers", "MP"),
                            ("Service Servers", "SS"), ("Service Clients", "SC")):
            print(f"  {title}:")
            rows = sorted({(e.name, e.type_name) for e in ents if e.kind == kind})
            for topic, typ in rows:
                print(f"    {topic}: {typ}")
    return 0
