"""``eddie teleop``: keyboard teleoperation in its own process.

Publishes ``/cmd_vel_teleop`` (``--topic`` to change) over the transport as ROS 1
teleop_twist_keyboard does with ``key_timeout``: each key event publishes (hold a key and
the terminal's key repeat keeps the robot moving), and ``--key-timeout`` seconds (default
0.5) after the last key one zero command stops the robot, then teleop stays silent so it
never holds the twist mux. ``--repeat-rate`` (ROS 1 ``repeat_rate``) also repeats a moving
command between keys. Ctrl-C, SIGTERM and SIGHUP (the terminal closing) all send a zero
command, restore the terminal and exit.

If holding a key stutters, the terminal's key-repeat delay is longer than the key timeout:
raise ``--key-timeout`` above it (X11 waits 660 ms by default) or shorten the delay.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import time
from collections.abc import Callable
from typing import Any, TextIO

from eddiebot.base.teleop import USAGE, KeyTeleop, TeleopState
from eddiebot.cli._common import connect_transport
from eddiebot.core.context import Context
from eddiebot.core.node import Node
from eddiebot.msgs.geometry_msgs import Twist

_QUIT_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: time for the transport to send the last zero before the session closes (s)
_FLUSH_S = 0.05


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--topic", default="/cmd_vel_teleop", help="Twist topic")
    parser.add_argument("--key-timeout", type=float, default=0.5,
                        help="s after the last key at which the robot is stopped (0: never)")
    parser.add_argument("--repeat-rate", "--rate", dest="repeat_rate", type=float, default=0.0,
                        help="also repeat a moving command at this rate in Hz between keys (0: off)")
    parser.add_argument("--speed", type=float, default=0.3, help="initial linear speed, m/s")
    parser.add_argument("--turn", type=float, default=1.0, help="initial angular speed, rad/s")


def _twist(v: float, w: float) -> Any:
    t = Twist()
    t.linear.x = v
    t.angular.z = w
    return t


def _say(out: TextIO | None, text: str) -> None:
    if out is None:
        return
    try:
        out.write(text)
        out.flush()
    except (OSError, ValueError):
        pass  # the terminal hung up


def drive(
    fd: int,
    teleop: KeyTeleop,
    publish: Callable[[float, float], None],
    *,
    clock_ns: Callable[[], int] = time.monotonic_ns,
    out: TextIO | None = None,
) -> None:
    """Read keys from ``fd`` and ``publish(linear, angular)`` what ``teleop`` says, until
    end of input, Ctrl-C, SIGINT, SIGTERM or SIGHUP; then publish one zero command and put
    the terminal back as it was. Call from the main thread (it installs signal handlers)."""
    stop: list[int] = []

    def on_signal(signum: int, _frame: Any) -> None:
        stop.append(signum)

    # the wakeup pipe ends select() at once on a signal (PEP 475 would otherwise resume it)
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_r, False)
    os.set_blocking(wake_w, False)
    old_handlers = {sig: signal.signal(sig, on_signal) for sig in _QUIT_SIGNALS}
    old_wakeup = signal.set_wakeup_fd(wake_w)
    tty_state = None
    try:
        if os.isatty(fd):
            import termios
            import tty

            tty_state = termios.tcgetattr(fd)
            tty.setcbreak(fd)
        while not stop:
            wake = teleop.next_wakeup_ns()
            timeout = None if wake is None else max(0.0, (wake - clock_ns()) / 1e9)
            ready, _, _ = select.select([fd, wake_r], [], [], timeout)
            if stop:
                break
            if fd in ready:
                try:
                    data = os.read(fd, 64)
                except OSError:
                    break  # EIO: the terminal is gone
                if not data or b"\x03" in data:  # end of input, or Ctrl-C without ISIG
                    break
                for key in data.decode(errors="ignore"):
                    v, w = teleop.on_key(key, clock_ns())
                    publish(v, w)
                    s = teleop.state
                    _say(out, f"\rspeed {s.speed:.2f} m/s  turn {s.turn:.2f} rad/s  "
                              f"-> linear {v:+.2f}  angular {w:+.2f}   ")
            cmd = teleop.on_idle(clock_ns())
            if cmd is not None:
                publish(*cmd)
    finally:
        publish(0.0, 0.0)
        if tty_state is not None:
            import termios

            try:
                termios.tcsetattr(fd, termios.TCSADRAIN, tty_state)
            except (termios.error, OSError):
                pass  # hung up: there is no terminal left to restore
        _say(out, "\n")
        signal.set_wakeup_fd(old_wakeup)
        for sig, handler in old_handlers.items():
            signal.signal(sig, handler)
        os.close(wake_r)
        os.close(wake_w)


def run(args: argparse.Namespace) -> int:
    context = Context()
    if not connect_transport(context):
        print("eddie teleop: no transport available; nothing would reach the robot", file=sys.stderr)
        return 1
    try:
        node = Node("teleop_twist_keyboard", context=context)
        teleop = KeyTeleop(
            TeleopState(speed=float(node.declare_parameter("speed", args.speed).value),
                        turn=float(node.declare_parameter("turn", args.turn).value)),
            key_timeout=float(node.declare_parameter("key_timeout", args.key_timeout).value),
            repeat_rate=float(node.declare_parameter("repeat_rate", args.repeat_rate).value),
        )
        pub = node.create_publisher(Twist, args.topic, 10)
        print(USAGE.format(topic=args.topic), file=sys.stderr)
        if teleop.key_timeout > 0:
            print(f"Hold a key to keep moving; the robot stops {teleop.key_timeout:g} s after "
                  "the last key.", file=sys.stderr)
        drive(sys.stdin.fileno(), teleop, lambda v, w: pub.publish(_twist(v, w)), out=sys.stderr)
        time.sleep(_FLUSH_S)
    finally:
        context.shutdown()
    return 0
