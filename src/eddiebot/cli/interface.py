"""``eddie interface show|list|packages|package`` — as ``ros2 interface``."""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["add_arguments", "render_definition", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("show", help="the definition of a message, service or action")
    p.add_argument("type_name", help="e.g. geometry_msgs/msg/Twist or std_srvs/srv/Trigger")
    p.add_argument("--no-expand", action="store_true", help="do not expand nested types")
    p = sub.add_parser("list", help="every known interface")
    p.add_argument("-m", "--only-msgs", action="store_true")
    p.add_argument("-s", "--only-srvs", action="store_true")
    p.add_argument("-a", "--only-actions", action="store_true")
    sub.add_parser("packages", help="packages with interfaces")
    p = sub.add_parser("package", help="the interfaces of one package")
    p.add_argument("package_name")
    parser.set_defaults(_parser=parser)


def _messages() -> list[str]:
    from eddiebot.msgs import TYPESTORE

    return sorted(n for n in TYPESTORE.types if n.split("/")[1] == "msg")


def _all() -> tuple[list[str], list[str], list[str]]:
    from eddiebot.msgs import ACTIONS, SERVICES

    return _messages(), sorted(SERVICES), sorted(ACTIONS)


def _type_str(desc: Any, parent_pkg: str) -> str:
    from rosbags.interfaces import Nodetype

    kind, detail = desc
    if kind == Nodetype.BASE:
        typ, bound = detail
        return f"{typ}<={bound}" if bound else typ
    if kind == Nodetype.NAME:
        pkg, _, name = detail.split("/", 2)
        return name if pkg == parent_pkg else f"{pkg}/{name}"
    inner, size = detail
    base = _type_str(inner, parent_pkg)
    if kind == Nodetype.ARRAY:
        return f"{base}[{size}]"
    return f"{base}[<={size}]" if size else f"{base}[]"


def _nested_name(desc: Any) -> str | None:
    from rosbags.interfaces import Nodetype

    kind, detail = desc
    if kind == Nodetype.NAME:
        return str(detail)
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return _nested_name(detail[0])
    return None


def render_definition(type_name: str, *, expand: bool = True, indent: str = "") -> str:
    """A message's fields (and constants) in .msg syntax, nested types expanded by a tab."""
    from eddiebot.msgs import TYPESTORE, normalize_type_name

    full = normalize_type_name(type_name)
    consts, fields = TYPESTORE.fielddefs[full]
    pkg = full.split("/", 1)[0]
    lines = []
    for cname, ctype, value in consts:
        v = f'"{value}"' if ctype == "string" else value
        lines.append(f"{indent}{ctype} {cname}={v}")
    for fname, desc in fields:
        lines.append(f"{indent}{_type_str(desc, pkg)} {fname}")
        nested = _nested_name(desc)
        if expand and nested is not None:
            inner = render_definition(nested, expand=True, indent=indent + "\t")
            if inner:
                lines.append(inner)
    return "\n".join(lines)


def _show(type_name: str, expand: bool) -> int:
    from eddiebot.msgs import (
        ACTIONS,
        SERVICES,
        TYPESTORE,
        UnknownTypeError,
        load_type,
        normalize_type_name,
    )

    name = normalize_type_name(type_name)
    srv = name if "/srv/" in name else name.replace("/msg/", "/srv/", 1)
    act = name if "/action/" in name else name.replace("/msg/", "/action/", 1)
    missing = ""
    for candidate in dict.fromkeys((name, srv, act)):  # from the interface search path
        try:
            load_type(candidate, "interface")
            break
        except UnknownTypeError as exc:
            missing = missing or exc.detail
    if name in TYPESTORE.fielddefs and "/msg/" in name:
        print(render_definition(name, expand=expand))
        return 0
    if srv in SERVICES:
        print(render_definition(f"{srv}_Request", expand=expand))
        print("---")
        print(render_definition(f"{srv}_Response", expand=expand))
        return 0
    if act in ACTIONS:
        print(render_definition(f"{act}_Goal", expand=expand))
        print("---")
        print(render_definition(f"{act}_Result", expand=expand))
        print("---")
        print(render_definition(f"{act}_Feedback", expand=expand))
        return 0
    print(f"Unknown interface '{type_name}'" + (f": {missing}" if missing else ""),
          file=sys.stderr)
    return 1


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    if verb == "show":
        return _show(args.type_name, not args.no_expand)
    msgs, srvs, acts = _all()
    if verb == "packages":
        for p in sorted({n.split("/", 1)[0] for n in (*msgs, *srvs, *acts)}):
            print(p)
        return 0
    if verb == "package":
        found = [n for n in (*msgs, *srvs, *acts) if n.split("/", 1)[0] == args.package_name]
        if not found:
            print(f"Unknown package '{args.package_name}'", file=sys.stderr)
            return 1
        print("\n".join(found))
        return 0
    only = args.only_msgs or args.only_srvs or args.only_actions
    for title, names, flag in (("Messages", msgs, args.only_msgs),
                               ("Services", srvs, args.only_srvs),
                               ("Actions", acts, args.only_actions)):
        if only and not flag:
            continue
        print(f"{title}:")
        for n in names:
            print(f"    {n}")
    return 0
