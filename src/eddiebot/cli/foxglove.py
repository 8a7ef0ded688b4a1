"""``eddie foxglove [--host H] [--port 8765]`` — the graph in Foxglove (as ROS 2's foxglove_bridge).

Open Foxglove, "Open connection" → Foxglove WebSocket → ``ws://localhost:8765``, and import
the layout ``config/foxglove/eddie_layout.json``.
"""

from __future__ import annotations

import argparse
import sys
import time

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8765, help="port (default 8765)")


def run(args: argparse.Namespace) -> int:
    from eddiebot.core import Context
    from eddiebot.viz.foxglove_bridge import BridgeConfig, FoxgloveBridge

    context = Context()
    try:
        from eddiebot.transport import connect

        if connect(context) is None:
            print("eddie foxglove: no transport: only this process is visible", file=sys.stderr)
    except Exception as exc:
        print(f"eddie foxglove: transport unavailable ({exc})", file=sys.stderr)
    try:
        bridge = FoxgloveBridge(context, BridgeConfig(host=args.host, port=args.port))
    except Exception as exc:
        print(f"eddie foxglove: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        context.shutdown()
        return 1
    print(bridge.url, flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        return 0
    finally:
        bridge.stop()
        context.shutdown()
