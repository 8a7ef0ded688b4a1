"""How fast each path puts a stop on the wire: the real board node over a real pty.

The firmware emulator is served on a pty with the wire's timing on (115,200 baud, 16 ms FTDI
latency, PING's 25 ms); every line that reaches the pty's master is logged with its wall
time, and faults are injected there (a lost STOP, a mute board). For each path it measures
the time from the trigger (the last velocity command, the e-stop, the signal) to the first
stopping command on the wire, over ``--repeats`` runs, and the poll rate the node achieves.

Prints a table and writes ``results/board_stops.json``.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.base.board_node import BoardNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.qos import qos_profile_latched
from eddiebot.msgs.eddiebot_msgs import Velocity
from eddiebot.msgs.std_msgs import Bool
from eddiebot.robot.constants import FIRMWARE_1_1
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.pty_server import PtyServer

STOPS = (b"STOP 0", b"GOSPD 0 0")


class Wire:
    """The emulated board on a pty; logs what arrives and can lose or swallow it."""

    def __init__(self) -> None:
        self.emulator = FirmwareEmulator(FIRMWARE_1_1)
        self.lines: list[tuple[float, bytes]] = []
        self.lose: set[bytes] = set()
        self.mute = False
        feed = self.emulator.feed

        def logging_feed(data: bytes) -> bytes:
            now = time.monotonic()
            parts = [p.strip() for p in data.split(b"\r") if p.strip()]
            self.lines.extend((now, p) for p in parts)
            if self.mute or any(p in self.lose for p in parts):
                self.lose.difference_update(parts)
                return b""
            return feed(data)

        self.emulator.feed = logging_feed  # type: ignore[method-assign]
        self.server = PtyServer(self.emulator)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def first(self, words: tuple[bytes, ...], after: float, timeout_s: float = 5.0) -> float:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for t, line in list(self.lines):
                if t >= after and line in words:
                    return t
            time.sleep(0.002)
        return float("nan")

    def close(self) -> None:
        self.server.stop()
        self.thread.join(2.0)


def in_process(path: str, repeats: int) -> tuple[list[dict[str, Any]], float]:
    wire = Wire()
    ctx = Context()
    node = BoardNode(context=ctx, parameter_overrides={"port": wire.server.device_path})
    probe = Node("probe", context=ctx)
    vel = probe.create_publisher(Velocity, "/eddie/simple_velocity", 10)
    estop = probe.create_publisher(Bool, "/e_stop", qos_profile_latched)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    results: dict[str, list[float]] = {k: [] for k in (
        "stale (STOP 0)", "zero command (GOSPD 0 0)", "e-stop (STOP 0)",
        "lost STOP (resent STOP 0 reaches the board)", "mute board (STOP 0 written)")}
    try:
        wire.first((b"DIST",), 0.0, 30.0)
        time.sleep(5.0)  # idle polling: the rate the link allows
        rate = node.achieved_poll_rate()

        def drive(seconds: float) -> float:
            last = time.monotonic()
            end = last + seconds
            while time.monotonic() < end:
                last = time.monotonic()
                vel.publish(Velocity(linear=0.2, angular=0.0))
                time.sleep(0.1)
            return last

        for _ in range(repeats):
            last = drive(0.6)
            results["stale (STOP 0)"].append(wire.first((b"STOP 0",), last) - last)
            time.sleep(1.0)
            drive(0.6)
            t0 = time.monotonic()
            vel.publish(Velocity(linear=0.0, angular=0.0))
            results["zero command (GOSPD 0 0)"].append(wire.first((b"GOSPD 0 0",), t0) - t0)
            time.sleep(1.0)
            drive(0.6)
            t0 = time.monotonic()
            estop.publish(Bool(data=True))
            results["e-stop (STOP 0)"].append(wire.first((b"STOP 0",), t0) - t0)
            time.sleep(0.5)
            estop.publish(Bool(data=False))
            time.sleep(0.5)
            wire.lose.add(b"STOP 0")
            last = drive(0.6)
            first = wire.first((b"STOP 0",), last)
            results["lost STOP (resent STOP 0 reaches the board)"].append(
                wire.first((b"STOP 0",), first + 1e-6) - last)
            time.sleep(1.0)
            last = drive(0.6)
            wire.mute = True
            results["mute board (STOP 0 written)"].append(wire.first((b"STOP 0",), last) - last)
            time.sleep(0.5)
            wire.mute = False
            time.sleep(1.0)
    finally:
        ex.shutdown()
        ctx.shutdown()
        wire.close()
    rows = [_row(name, values) for name, values in results.items()]
    return rows, rate


def by_signal(sig: int, repeats: int) -> dict[str, Any]:
    values = []
    for _ in range(repeats):
        wire = Wire()
        proc = subprocess.Popen(
            [sys.executable, "-m", "eddiebot.cli.main", "launch", "bringup",
             f"port:={wire.server.device_path}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            env=dict(os.environ, EDDIE_TRANSPORT="none"))
        try:
            wire.first((b"DIST",), 0.0, 60.0)
            time.sleep(0.5)
            wire.emulator.plant.set_velocity(40, 40)
            t0 = time.monotonic()
            proc.send_signal(sig)
            values.append(wire.first((b"STOP 0",), t0) - t0)
            proc.wait(20)
        finally:
            if proc.poll() is None:
                proc.kill()
            wire.close()
    return _row(f"{signal.Signals(sig).name} to `eddie launch bringup` (STOP 0)", values)


def _row(name: str, values: list[float]) -> dict[str, Any]:
    ms = [v * 1000 for v in values]
    return {"path": name, "median_ms": round(statistics.median(ms), 1),
            "max_ms": round(max(ms), 1), "runs": len(ms)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    rows, rate = in_process("", args.repeats)
    for sig in (signal.SIGHUP, signal.SIGQUIT, signal.SIGINT, signal.SIGTERM):
        rows.append(by_signal(sig, max(1, args.repeats // 2)))
    rows.append({"path": "poll rate achieved (Hz, DIST+PING+ADC)", "median_ms": round(rate, 1),
                 "max_ms": None, "runs": 1})
    print_table(rows, ["path", "median_ms", "max_ms", "runs"])
    write_results("board_stops", rows)


if __name__ == "__main__":
    main()
