"""``eddie param list|get|set|describe|delete|dump|load`` — as ``ros2 param``, through
rcl_interfaces services."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from eddiebot.cli._common import CliSession, cli_session, discovery_wait_s

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("list", help="parameter names of one node (or of every node)")
    p.add_argument("node_name", nargs="?", default=None)
    p.add_argument("--param-prefixes", nargs="*", default=[])
    p = sub.add_parser("get", help="a parameter's value")
    p.add_argument("node_name")
    p.add_argument("parameter_name")
    p.add_argument("--hide-type", action="store_true", help="print only the value")
    p = sub.add_parser("set", help="set a parameter (the value is YAML: 1, 0.5, true, [1, 2])")
    p.add_argument("node_name")
    p.add_argument("parameter_name")
    p.add_argument("value")
    p = sub.add_parser("describe", help="type, description and constraints of parameters")
    p.add_argument("node_name")
    p.add_argument("parameter_names", nargs="+")
    p = sub.add_parser("delete", help="undeclare a parameter (the node may refuse)")
    p.add_argument("node_name")
    p.add_argument("parameter_name")
    p = sub.add_parser("dump", help="a node's parameters as a ROS 2 parameter file")
    p.add_argument("node_name")
    p = sub.add_parser("load", help="set a node's parameters from a ROS 2 parameter file")
    p.add_argument("node_name")
    p.add_argument("parameter_file")
    for sp in sub.choices.values():
        sp.add_argument("--timeout", type=float, default=5.0,
                        help="seconds to wait for the node's parameter services (default 5)")
    parser.set_defaults(_parser=parser)


def _fq(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def _client(s: CliSession, node_name: str, timeout: float) -> Any:
    from eddiebot.core.param_services import ParameterClient

    client = ParameterClient(s.node, _fq(node_name), timeout_sec=timeout)
    if not client.wait_for_services(timeout_sec=timeout):
        return None
    return client


_TYPE_WORDS = {
    bool: "Boolean value is", int: "Integer value is", float: "Double value is",
    str: "String value is", bytes: "Byte values are",
}


def _describe(value: Any) -> str:
    if value is None:
        return "Parameter not set."
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        word = {bool: "Boolean", int: "Integer", float: "Double", str: "String"}.get(
            kinds.pop() if len(kinds) == 1 else str, "String")
        return f"{word} values are: {value}"
    return f"{_TYPE_WORDS.get(type(value), 'Value is')}: {value}"


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    with cli_session("param") as s:
        if verb == "list" and args.node_name is None:
            s.wait(discovery_wait_s())
            status = 0
            for node in s.node_names():
                client = _client(s, node, args.timeout)
                if client is None:
                    continue
                print(f"{node}:")
                for name in sorted(client.list_parameters(args.param_prefixes)):
                    print(f"  {name}")
            return status
        client = _client(s, args.node_name, args.timeout)
        if client is None:
            print(f"Node not found: {_fq(args.node_name)} (no parameter services within "
                  f"{args.timeout} s)", file=sys.stderr)
            return 1
        if verb == "list":
            for name in sorted(client.list_parameters(args.param_prefixes)):
                print(f"  {name}")
            return 0
        if verb == "get":
            value = client.get_parameter(args.parameter_name)
            if value is None:
                print("Parameter not set.")
                return 1
            print(value if args.hide_type else _describe(value))
            return 0
        if verb == "set":
            import yaml

            try:
                value = yaml.safe_load(args.value)
            except yaml.YAMLError:
                value = args.value
            result = client.set_parameters({args.parameter_name: value})[0]
            if result.successful:
                print("Set parameter successful")
                return 0
            print(f"Setting parameter failed: {result.reason}", file=sys.stderr)
            return 1
        if verb == "describe":
            return _describe_params(client, args.parameter_names)
        if verb == "delete":
            result = client.set_parameters({args.parameter_name: None})[0]
            if result.successful:
                print("Deleted parameter successfully")
                return 0
            print(f"Deleting parameter failed: {result.reason}", file=sys.stderr)
            return 1
        if verb == "load":
            return _load(client, _fq(args.node_name), args.parameter_file)
        # dump
        import yaml

        names = sorted(client.list_parameters())
        values = client.get_parameters(names)
        params = {n: v for n, v in zip(names, values) if v is not None}
        print(yaml.safe_dump({_fq(args.node_name): {"ros__parameters": params}},
                             sort_keys=True).rstrip("\n"))
    return 0


_TYPE_NAMES = {0: "not set", 1: "boolean", 2: "integer", 3: "double", 4: "string",
               5: "byte array", 6: "boolean array", 7: "integer array", 8: "double array",
               9: "string array"}


def _describe_params(client: Any, names: list[str]) -> int:
    status = 0
    found = {str(d.name): d for d in client.describe_parameters(names)}
    for name in names:
        desc = found.get(name)
        ptype = int(getattr(desc, "type", 0))
        if desc is None or ptype == 0:
            print(f"Parameter not set: {name}", file=sys.stderr)
            status = 1
            continue
        print(f"Parameter name: {name}")
        print(f"  Type: {_TYPE_NAMES.get(ptype, str(ptype))}")
        if desc.description:
            print(f"  Description: {desc.description}")
        constraints = []
        if desc.read_only:
            constraints.append("    Read only: true")
        if desc.dynamic_typing:
            constraints.append("    Dynamic typing: true")
        for r in list(desc.floating_point_range) + list(desc.integer_range):
            constraints.append(f"    Min value: {r.from_value}")
            constraints.append(f"    Max value: {r.to_value}")
        if desc.additional_constraints:
            constraints.append(f"    {desc.additional_constraints}")
        if constraints:
            print("  Constraints:")
            print("\n".join(constraints))
    return status


def _load(client: Any, node: str, path: str) -> int:
    """Set the parameters a ROS 2 parameter file gives ``node`` (its own section and ``/**``)."""
    from pathlib import Path

    from eddiebot.core.parameters import load_parameter_file, node_matches

    pf = load_parameter_file(Path(path))
    values = {o.name: o.value for o in pf.overrides if node_matches(o.node_pattern, node)}
    if not values:
        print(f"eddie param load: {path} sets nothing for {node}", file=sys.stderr)
        return 1
    status = 0
    for (name, _), result in zip(values.items(), client.set_parameters(values)):
        if result.successful:
            print(f"Set parameter {name} successful")
        else:
            print(f"Set parameter {name} failed: {result.reason}", file=sys.stderr)
            status = 1
    return status
