"""``eddie board CMD...``: send one raw firmware command to the control board, print the reply.

Examples: ``eddie board VER``, ``eddie board --port /dev/pts/3 GOSPD 10 10``,
``eddie board -v DIST`` (``VERB 1`` first, so an ``ERROR`` carries its reason).
Exit status: 0 on a normal reply, 1 on an ``ERROR`` reply, 2 on a timeout or a link failure.
"""

from __future__ import annotations

import argparse
import sys
import time

from eddiebot.robot.board import ProtocolCore
from eddiebot.robot.errors import BoardTimeout, LinkLost
from eddiebot.robot.links import SerialLink

__all__ = ["add_arguments", "main", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``eddie board``."""
    parser.add_argument("command", nargs="+", metavar="CMD",
                        help="firmware command and parameters, e.g. VER or GOSPD 10 10")
    parser.add_argument("--port", default="/dev/ttyUSB0",
                        help="serial device, pty or pyserial URL such as socket://host:port "
                             "(default /dev/ttyUSB0)")
    parser.add_argument("--timeout", type=float, default=0.5,
                        help="reply timeout in seconds (default 0.5)")
    parser.add_argument("--boot-wait", type=float, default=3.0,
                        help="opening the port reboots the board (DTR): wait up to this long "
                             "for it to answer before sending (default 3 s)")
    parser.add_argument("-v", "--verbose-errors", action="store_true",
                        help="send VERB 1 first so ERROR replies carry a reason")


def run(args: argparse.Namespace) -> int:
    """Send the command and print the reply (an empty reply prints an empty line)."""
    line = " ".join(args.command)
    link = SerialLink(args.port)
    try:
        link.open()
    except LinkLost as exc:
        print(f"eddie board: {exc}", file=sys.stderr)
        return 2
    core = ProtocolCore(link, timeout_s=args.timeout)
    try:
        _wait_for_boot(core, args.boot_wait)
        if args.verbose_errors:
            core.raw("VERB 1")
        reply = core.raw(line)
    except (BoardTimeout, LinkLost) as exc:
        print(f"eddie board: {exc}", file=sys.stderr)
        return 2
    finally:
        link.close()
    print(reply)
    return 1 if reply.startswith("ERROR") else 0


def _wait_for_boot(core: ProtocolCore, wait_s: float) -> None:
    """Ask ``VER`` until the board answers: the Propeller is deaf for ~1.5 s after the DTR
    reset that opening the port causes."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            core.raw("VER", timeout_s=0.2)
            return
        except BoardTimeout:
            if time.monotonic() >= deadline:
                raise


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry point (``python -m eddiebot.cli.board``)."""
    parser = argparse.ArgumentParser(prog="eddie board", description=__doc__)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
