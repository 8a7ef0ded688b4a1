"""The Zenoh router every process meets at (``eddie daemon``), run here or detached.

``python -m eddiebot.transport.router [--endpoint E] [--lan]`` runs one in the foreground.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from eddiebot.transport.config import ZenohConfig, normalize_endpoint
from eddiebot.transport.errors import RouterError

__all__ = [
    "pid_file",
    "router_reachable",
    "run_router",
    "start_detached",
    "stop_detached",
    "wait_reachable",
]


def router_reachable(config: ZenohConfig, timeout_s: float = 0.3) -> bool:
    """True when something accepts TCP connections at the router endpoint."""
    hp = config.router_host_port()
    if hp is None:
        return True  # not a tcp endpoint: assume the user knows
    host, port = hp
    if host in ("0.0.0.0", "::"):
        host = "127.0.0.1"
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


def wait_reachable(config: ZenohConfig, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if router_reachable(config):
            return True
        time.sleep(0.05)
    return router_reachable(config)


def pid_file(config: ZenohConfig) -> Path:
    hp = config.router_host_port()
    port = hp[1] if hp else 7447
    return Path(tempfile.gettempdir()) / f"eddie-router-{os.getuid()}-{port}.pid"


def run_router(config: ZenohConfig, stop: threading.Event | None = None) -> int:
    """Run the router until SIGINT/SIGTERM (or ``stop`` is set); returns an exit code."""
    import zenoh

    try:
        session = zenoh.open(config.router_config())
    except Exception as exc:
        print(f"eddie daemon: cannot start the Zenoh router at {config.router}: {exc}",
              file=sys.stderr)
        return 1
    pf = pid_file(config)
    with contextlib.suppress(OSError):
        pf.write_text(str(os.getpid()))
    stop = stop or threading.Event()

    def _stop(*_: object) -> None:
        stop.set()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _stop)
        signal.signal(signal.SIGINT, _stop)
    print(f"eddie daemon: Zenoh router {session.zid()} listening at {config.router}"
          f" ({config.network})", file=sys.stderr, flush=True)
    try:
        while not stop.wait(0.5):
            pass
    finally:
        with contextlib.suppress(Exception):
            session.close()
        with contextlib.suppress(OSError):
            if pf.read_text().strip() == str(os.getpid()):
                pf.unlink()
    return 0


def start_detached(config: ZenohConfig, timeout_s: float = 10.0) -> int:
    """Start a router in its own session (it outlives this process); returns its pid."""
    args = [sys.executable, "-m", "eddiebot.transport.router", "--endpoint", config.router]
    if config.lan:
        args.append("--lan")
    log = Path(tempfile.gettempdir()) / f"{pid_file(config).stem}.log"
    with open(log, "ab") as out:
        proc = subprocess.Popen(
            args, stdin=subprocess.DEVNULL, stdout=out, stderr=out, start_new_session=True,
            env={**os.environ, "EDDIE_ROUTER_AUTOSTART": "0"},
        )
    if not wait_reachable(config, timeout_s):
        if proc.poll() is None and not router_reachable(config):
            proc.terminate()
        raise RouterError(f"the Zenoh router at {config.router} did not come up "
                          f"within {timeout_s} s (log: {log})")
    return proc.pid


def stop_detached(config: ZenohConfig, timeout_s: float = 5.0) -> bool:
    """Stop the router this user started detached on that port; True if one was stopped."""
    pf = pid_file(config)
    try:
        pid = int(pf.read_text().strip())
    except (OSError, ValueError):
        return False
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        with contextlib.suppress(OSError):
            pf.unlink()
        return False
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="run the eddiebot Zenoh router")
    parser.add_argument("--endpoint", default=None, help="e.g. tcp/127.0.0.1:7447 or a port")
    parser.add_argument("--lan", action="store_true", help="listen on every interface")
    args = parser.parse_args(argv)
    config = ZenohConfig.from_env()
    if args.endpoint:
        config.router = normalize_endpoint(args.endpoint)
    if args.lan:
        config.network = "lan"
    return run_router(config)


if __name__ == "__main__":
    sys.exit(main())
