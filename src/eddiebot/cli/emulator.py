"""``eddie emulator``: serve an emulated Eddie control board on a pseudo-terminal.

The first line on stdout is the pty's device path (flushed at once), so scripts can read it
and point the driver at it: ``eddie board --port "$(eddie emulator | head -1)" VER``.  The
emulator runs in real time until SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import signal
import sys
from types import FrameType

from eddiebot.robot.constants import FIRMWARE_PROFILES
from eddiebot.robot.emulator import FirmwareEmulator, FixedSensors
from eddiebot.robot.pty_server import PtyServer
from eddiebot.robot.timing import NO_TIMING

__all__ = ["add_arguments", "main", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``eddie emulator``."""
    parser.add_argument("--firmware", choices=sorted(FIRMWARE_PROFILES), default="1.1",
                        help="firmware to emulate (default 1.1: Position Controllers)")
    parser.add_argument("--no-timing", action="store_true",
                        help="answer at once and do not reboot on open (the real board takes "
                             "115,200 baud, the FTDI latency and PING's 25 ms, and reboots "
                             "when the port is opened)")
    parser.add_argument("--counts-per-rev", type=int, default=36,
                        help="encoder positions per wheel revolution (default 36)")
    parser.add_argument("--battery", type=float, default=12.6,
                        help="battery voltage reported on ADC index 7 (V, default 12.6)")
    parser.add_argument("--ping", type=float, nargs=2, default=(1.5, 2.0),
                        metavar=("LEFT_M", "RIGHT_M"),
                        help="fixed PING))) ranges left/right in metres (default 1.5 2.0)")


def run(args: argparse.Namespace) -> int:
    """Open the pty, print its path, serve until SIGINT/SIGTERM."""
    sensors = FixedSensors(ping_left_m=args.ping[0], ping_right_m=args.ping[1],
                           battery_v=args.battery)
    emulator = FirmwareEmulator(FIRMWARE_PROFILES[args.firmware],
                                counts_per_rev=args.counts_per_rev, sensors=sensors)
    server = (PtyServer(emulator, timing=NO_TIMING, reboot_on_open=False) if args.no_timing
              else PtyServer(emulator))

    def _stop(signum: int, frame: FrameType | None) -> None:
        server.stop()

    previous = {sig: signal.signal(sig, _stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        sys.stdout.write(server.device_path + "\n")
        sys.stdout.flush()
        print(f"emulating Eddie firmware {args.firmware} "
              f"({args.counts_per_rev} positions/rev); Ctrl-C to stop", file=sys.stderr)
        server.serve_forever()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Stand-alone entry point (``python -m eddiebot.cli.emulator``)."""
    parser = argparse.ArgumentParser(prog="eddie emulator", description=__doc__)
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
