"""``eddie dashboard [--host H] [--port P] [--read-only]`` — the web dashboard.

Joins the graph through the transport (as every ``eddie`` process) and serves the page;
the first line of stdout is the URL to open (with the token when one is needed).
"""

from __future__ import annotations

import argparse
import sys
import time

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to bind (default 127.0.0.1; any other needs the token)")
    parser.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free)")
    parser.add_argument("--token", default=None,
                        help="access token (default: random when the bind is not loopback)")
    parser.add_argument("--read-only", action="store_true", help="hide and refuse every control")


def run(args: argparse.Namespace) -> int:
    from eddiebot.core import Context
    from eddiebot.viz.dashboard import start_dashboard

    context = Context()
    try:
        from eddiebot.transport import connect

        if connect(context) is None:
            print("eddie dashboard: no transport: only this process is visible", file=sys.stderr)
    except Exception as exc:  # the dashboard still serves an empty graph
        print(f"eddie dashboard: transport unavailable ({exc})", file=sys.stderr)
    try:
        handle = start_dashboard(context, args.host, args.port, args.token, args.read_only)
    except BaseException:  # a busy port (DashboardBindError): eddie's main says so in one line
        context.shutdown()
        raise
    try:
        while handle.is_alive():
            time.sleep(0.5)
        return 1
    except KeyboardInterrupt:
        return 0
    finally:
        handle.stop()
        context.shutdown()
