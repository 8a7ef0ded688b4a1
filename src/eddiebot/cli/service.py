"""``eddie service list|call|type|find`` — as ``ros2 service``."""

from __future__ import annotations

import argparse
import sys
import time

from eddiebot.cli._common import cli_session, discovery_wait_s, fill_from_yaml, message_to_yaml

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    p = sub.add_parser("list", help="services in the graph")
    p.add_argument("-t", "--show-types", action="store_true")
    p.add_argument("-c", "--count-services", action="store_true")
    p.add_argument("-a", "--include-hidden-services", action="store_true")
    p = sub.add_parser("type", help="the type of a service")
    p.add_argument("service_name")
    p = sub.add_parser("find", help="the services of a type")
    p.add_argument("service_type")
    p.add_argument("-c", "--count-services", action="store_true")
    p.add_argument("-a", "--include-hidden-services", action="store_true")
    p = sub.add_parser("call", help="call a service with YAML request values")
    p.add_argument("service_name")
    p.add_argument("service_type")
    p.add_argument("values", nargs="?", default="{}", help='YAML, e.g. "{data: true}"')
    p.add_argument("--timeout", type=float, default=10.0,
                   help="seconds to wait for the service and its answer (default 10)")
    parser.set_defaults(_parser=parser)


def _hidden(name: str) -> bool:
    return any(tok.startswith("_") for tok in name.split("/"))


def run(args: argparse.Namespace) -> int:
    verb = getattr(args, "verb", None)
    if verb is None:
        args._parser.print_help()
        return 0
    with cli_session("service") as s:
        if verb == "call":
            return _call(s, args)
        s.wait(discovery_wait_s())
        services = s.service_types()
        if verb == "type":
            name = args.service_name if args.service_name.startswith("/") else "/" + args.service_name
            if name not in services:
                print(f"Unknown service '{name}'", file=sys.stderr)
                return 1
            print("\n".join(sorted(services[name])))
            return 0
        shown = {k: v for k, v in services.items()
                 if args.include_hidden_services or not _hidden(k)}
        if verb == "find":
            pkg, _, name = args.service_type.partition("/")
            wanted = f"{pkg}/srv/{name.rpartition('/')[2]}"  # std_srvs/SetBool or …/srv/SetBool
            shown = {k: v for k, v in shown.items() if wanted in v}
        if args.count_services:
            print(len(shown))
            return 0
        for name in sorted(shown):
            show_types = getattr(args, "show_types", False)
            print(f"{name} [{', '.join(sorted(shown[name]))}]" if show_types else name)
    return 0


def _call(s: object, args: argparse.Namespace) -> int:

    from eddiebot.core.errors import ServiceCallTimeoutError, ServiceUnavailableError
    from eddiebot.msgs import get_service
    from eddiebot.transport.errors import RemoteServiceError

    srv_type = get_service(args.service_type)
    name = args.service_name if args.service_name.startswith("/") else "/" + args.service_name
    request = srv_type.Request()
    try:
        fill_from_yaml(request, args.values)
    except ValueError as exc:
        print(f"eddie service call: {exc}", file=sys.stderr)
        return 2
    node = s.node  # type: ignore[attr-defined]
    client = node.create_client(srv_type, name)
    if not client.wait_for_service(timeout_sec=args.timeout):
        print(f"eddie service call: service {name} is not available", file=sys.stderr)
        return 1
    print(f"requester: making request: {request}", flush=True)
    t0 = time.monotonic()
    try:
        response = client.call(request, timeout_sec=args.timeout)
    except (ServiceCallTimeoutError, ServiceUnavailableError, RemoteServiceError,
            TypeError) as exc:
        print(f"eddie service call: {exc}", file=sys.stderr)
        return 1
    print()
    print("response:")
    print(message_to_yaml(response))
    print(f"({(time.monotonic() - t0) * 1e3:.1f} ms)", file=sys.stderr)
    return 0
