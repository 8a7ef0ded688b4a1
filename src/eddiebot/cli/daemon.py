"""``eddie daemon [start|stop|status]`` — the Zenoh router processes meet at.

With no verb the router runs in the foreground (Ctrl-C stops it); ``start`` runs it
detached, ``stop`` stops a detached one, ``status`` says whether one answers.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("verb", nargs="?", choices=["run", "start", "stop", "status"],
                        default="run", help="run (foreground, default), start, stop or status")
    parser.add_argument("--endpoint", default=None,
                        help="router endpoint or port (default EDDIE_ZENOH_ROUTER or "
                        "tcp/127.0.0.1:7447)")
    parser.add_argument("--lan", action="store_true",
                        help="listen on every interface, multicast scouting on (EDDIE_NETWORK=lan)")


def run(args: argparse.Namespace) -> int:
    from eddiebot.transport.config import ZenohConfig, normalize_endpoint
    from eddiebot.transport.errors import RouterError
    from eddiebot.transport.router import (
        router_reachable,
        run_router,
        start_detached,
        stop_detached,
    )

    config = ZenohConfig.from_env()
    if args.endpoint:
        config.router = normalize_endpoint(args.endpoint)
    if args.lan:
        config.network = "lan"
    if args.verb == "status":
        up = router_reachable(config)
        print(f"the Zenoh router at {config.router} is {'running' if up else 'not running'}")
        return 0 if up else 1
    if args.verb == "stop":
        if stop_detached(config):
            print(f"stopped the Zenoh router at {config.router}")
            return 0
        print(f"no detached Zenoh router of this user at {config.router}", file=sys.stderr)
        return 1
    if router_reachable(config):
        print(f"a Zenoh router is already running at {config.router}", file=sys.stderr)
        return 0 if args.verb == "start" else 1
    if args.verb == "start":
        try:
            pid = start_detached(config)
        except RouterError as exc:
            print(f"eddie daemon: {exc}", file=sys.stderr)
            return 1
        print(f"started the Zenoh router at {config.router} (pid {pid})")
        return 0
    return run_router(config)
