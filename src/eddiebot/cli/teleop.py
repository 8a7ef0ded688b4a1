"""``eddie teleop``: keyboard teleoperation in its own process.

Publishes ``/cmd_vel_teleop`` (``--topic`` to change) over the transport, repeating the
current command at ``--rate`` Hz so the base's stale-command stop never stutters, and sends
a zero command on exit, Ctrl-C and SIGTERM.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import time
from typing import Any

from eddiebot.base.teleop import USAGE, TeleopState
from eddiebot.core.context import Context
from eddiebot.core.launch import connect_transport
from eddiebot.core.node import Node
from eddiebot.msgs.geometry_msgs import Twist


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--topic", default="/cmd_vel_teleop", help="Twist topic")
    parser.add_argument("--rate", type=float, default=15.0, help="repeat rate in Hz (10-20)")
    parser.add_argument("--speed", type=float, default=0.3, help="initial linear speed, m/s")
    parser.add_argument("--turn", type=float, default=1.0, help="initial angular speed, rad/s")


def _twist(v: float, w: float) -> Any:
    t = Twist()
    t.linear.x = v
    t.angular.z = w
    return t


def run(args: argparse.Namespace) -> int:
    context = Context()
    if not connect_transport(context):
        print("eddie teleop: no transport available; nothing would reach the robot", file=sys.stderr)
        return 1
    node = Node("teleop_twist_keyboard", context=context)
    pub = node.create_publisher(Twist, args.topic, 10)
    state = TeleopState(speed=args.speed, turn=args.turn)
    stop = [False]

    def on_signal(signum: int, _frame: Any) -> None:
        stop[0] = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    fd = sys.stdin.fileno()
    tty_state = None
    if os.isatty(fd):
        import termios
        import tty

        tty_state = termios.tcgetattr(fd)
        tty.setcbreak(fd)
    print(USAGE.format(topic=args.topic), file=sys.stderr)
    period = 1.0 / max(1.0, args.rate)
    try:
        next_send = time.monotonic()
        while not stop[0]:
            timeout = max(0.0, next_send - time.monotonic())
            ready, _, _ = select.select([fd], [], [], timeout)
            if ready:
                ch = os.read(fd, 1)
                if not ch or ch == b"\x03":  # EOF or Ctrl-C in raw mode
                    break
                if state.key(ch.decode(errors="ignore")):
                    v, w = state.command()
                    print(f"\rspeed {state.speed:.2f} m/s  turn {state.turn:.2f} rad/s  "
                          f"-> linear {v:+.2f}  angular {w:+.2f}   ", end="", file=sys.stderr)
                    pub.publish(_twist(v, w))
            if time.monotonic() >= next_send:
                pub.publish(_twist(*state.command()))
                next_send += period
                if next_send < time.monotonic():
                    next_send = time.monotonic() + period
    finally:
        for _ in range(3):
            pub.publish(_twist(0.0, 0.0))
            time.sleep(0.02)
        if tty_state is not None:
            import termios

            termios.tcsetattr(fd, termios.TCSADRAIN, tty_state)
        print("", file=sys.stderr)
        context.shutdown()
    return 0
