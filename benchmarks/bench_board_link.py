"""The board link as slow as the real one: the driver against ``eddie emulator`` over a pty
with the link timing model on (:mod:`eddiebot.robot.timing`: 115,200 baud, the FTDI
latency timer, PING's 25 ms, the Propeller's boot after the DTR reset on open).

Prints and writes ``results/board_link.json``:

* how long after opening the port the board first answers (the reboot on open);
* ``Board.distance()``, ``.ping()`` and ``.adc()`` end to end (median, p90, best), beside
  the model's :func:`~eddiebot.robot.timing.reply_delay_s`;
* the DIST + PING + ADC polling rate back to back, beside the model's ceiling.
"""

from __future__ import annotations

import logging
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import serial

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.robot.board import Board
from eddiebot.robot.errors import BoardTimeout
from eddiebot.robot.links import SerialLink
from eddiebot.robot.timing import DEFAULT_TIMING, reply_delay_s

# Reply lengths after Board.start(): DIST two 8-digit fields, PING two sensors (FW 1.1
# trailing space), ADC eight 3-digit fields; each with its CR.
_MODEL = {
    "DIST": reply_delay_s(DEFAULT_TIMING, b"DIST\r", b"x" * 18, "DIST"),
    "PING": reply_delay_s(DEFAULT_TIMING, b"PING\r", b"x" * 9, "PING"),
    "ADC": reply_delay_s(DEFAULT_TIMING, b"ADC\r", b"x" * 32, "ADC"),
}


def _start_emulator() -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen([sys.executable, "-m", "eddiebot.cli.emulator"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    return proc, proc.stdout.readline().strip()


def first_answer_after_open(path: str, deadline_s: float = 10.0) -> float:
    """Seconds from opening the port until the board first answers ``VER`` (polled 10 ms)."""
    port = serial.serial_for_url(path, baudrate=115200, timeout=0.01)
    try:
        opened = time.perf_counter()
        while time.perf_counter() < opened + deadline_s:
            port.write(b"VER\r")
            if port.read_until(b"\r").endswith(b"\r"):
                return time.perf_counter() - opened
        raise TimeoutError("the emulated board never answered")
    finally:
        port.close()


def _start_board(board: Board, deadline_s: float = 10.0) -> None:
    end = time.monotonic() + deadline_s
    while True:
        try:
            board.start()
            return
        except BoardTimeout:  # still booting after the reset on open
            if time.monotonic() > end:
                raise


def _times(call: Callable[[], object], n: int) -> list[float]:
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        call()
        out.append(time.perf_counter() - t0)
    return sorted(out)


def measure(n: int = 60, cycle_s: float = 5.0) -> dict[str, float]:
    proc, path = _start_emulator()
    try:
        boot = first_answer_after_open(path)
        board = Board(SerialLink(path), timeout_s=0.25)
        try:
            _start_board(board)
            figures = {"boot_s": boot}
            for name, call in (("DIST", board.distance), ("PING", board.ping),
                               ("ADC", board.adc)):
                t = _times(call, n)
                figures[f"{name}_median_ms"] = statistics.median(t) * 1e3
                figures[f"{name}_p90_ms"] = t[int(0.9 * (n - 1))] * 1e3
                figures[f"{name}_min_ms"] = t[0] * 1e3
            cycles = 0
            start = time.perf_counter()
            while time.perf_counter() < start + cycle_s:
                board.distance()
                board.ping()
                board.adc()
                cycles += 1
            figures["cycle_hz"] = cycles / (time.perf_counter() - start)
        finally:
            board.close()
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    return figures


def main() -> int:
    # The requests sent while the board boots time out by design; do not log them.
    logging.getLogger("eddiebot.robot.board").setLevel(logging.ERROR)
    f = measure()
    model_cycle_hz = 1.0 / sum(_MODEL.values())
    rows = [{"benchmark": "open -> first reply (reboot on open, boot model "
                          f"{DEFAULT_TIMING.boot_s:g} s)",
             "value": f["boot_s"], "unit": "s", "model": DEFAULT_TIMING.boot_s}]
    for name in ("DIST", "PING", "ADC"):
        model_ms = _MODEL[name] * 1e3
        rows += [
            {"benchmark": f"Board.{name.lower() if name != 'DIST' else 'distance'}() "
                          "end to end (median)",
             "value": f[f"{name}_median_ms"], "unit": "ms", "model": model_ms},
            {"benchmark": f"{name} end to end (p90)", "value": f[f"{name}_p90_ms"],
             "unit": "ms", "model": model_ms},
            {"benchmark": f"{name} end to end (best)", "value": f[f"{name}_min_ms"],
             "unit": "ms", "model": model_ms},
        ]
    rows.append({"benchmark": "DIST+PING+ADC back to back", "value": f["cycle_hz"], "unit": "Hz",
                 "model": model_cycle_hz})
    rows.append({"benchmark": "machine load (1-min average) at the end",
                 "value": os.getloadavg()[0], "unit": "", "model": f"{os.cpu_count()} CPUs"})
    print_table(rows, ["benchmark", "value", "unit", "model"])
    write_results("board_link", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
