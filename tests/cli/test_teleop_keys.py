"""``eddie teleop``'s key loop: end of input, SIGHUP and SIGTERM all stop the robot and
restore the terminal."""

from __future__ import annotations

import os
import signal
import termios

import pytest

from eddiebot.base.teleop import KeyTeleop, TeleopState
from eddiebot.cli.teleop import drive


class FakeClock:
    def __init__(self) -> None:
        self.ns = 0

    def __call__(self) -> int:
        self.ns += 10_000_000  # 10 ms per reading
        return self.ns


def test_keys_then_end_of_input_ends_with_a_zero():
    r, w = os.pipe()
    os.write(w, b"iik")
    os.close(w)
    sent: list[tuple[float, float]] = []
    try:
        drive(r, KeyTeleop(TeleopState(speed=0.3)), lambda v, a: sent.append((v, a)),
              clock_ns=FakeClock())
    finally:
        os.close(r)
    assert sent == [(0.3, 0.0), (0.3, 0.0), (0.0, 0.0), (0.0, 0.0)]


@pytest.mark.parametrize("signum", [signal.SIGHUP, signal.SIGTERM, signal.SIGINT])
def test_quit_signal_mid_drive_sends_one_zero_and_exits(signum):
    r, w = os.pipe()
    os.write(w, b"i")  # the write end stays open: only the signal can end the loop
    sent: list[tuple[float, float]] = []

    def publish(v: float, a: float) -> None:
        sent.append((v, a))
        if len(sent) == 1:
            os.kill(os.getpid(), signum)

    previous = signal.getsignal(signum)
    try:
        drive(r, KeyTeleop(TeleopState(speed=0.3)), publish, clock_ns=FakeClock())
    finally:
        os.close(r)
        os.close(w)
    assert sent == [(0.3, 0.0), (0.0, 0.0)]
    assert signal.getsignal(signum) == previous  # handler put back


def test_sighup_on_a_terminal_restores_it():
    master, slave = os.openpty()
    before = termios.tcgetattr(slave)
    teleop = KeyTeleop(TeleopState(speed=0.3))
    teleop.on_key("i", 0)  # moving when the loop starts: it asks the clock for the timeout
    lflags: list[int] = []

    def clock_ns() -> int:
        if not lflags:
            lflags.append(termios.tcgetattr(slave)[3])
            os.kill(os.getpid(), signal.SIGHUP)  # the terminal window is closed
        return 0

    sent: list[tuple[float, float]] = []
    try:
        drive(slave, teleop, lambda v, a: sent.append((v, a)), clock_ns=clock_ns)
        after = termios.tcgetattr(slave)
    finally:
        os.close(master)
        os.close(slave)
    assert lflags[0] & termios.ICANON == 0  # cbreak while driving
    assert after == before
    assert sent == [(0.0, 0.0)]
