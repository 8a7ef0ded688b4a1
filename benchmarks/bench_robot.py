"""Control-board driver and emulator benchmarks.

* request → reply latency over a pty against ``eddie emulator`` running in its own process;
* DIST + PING + ADC polling cycles per second over that pty and over the in-process link;
* the emulator plant on a simulation clock (simulated seconds per wall second).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.robot.board import Board
from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.links import EmulatorLink, SerialLink

# One polling cycle on the wire: "DIST\r" "PING\r" "ADC\r" (14 bytes) and the replies
# "LLLLLLLL RRRRRRRR\r" (18), "LLL RRR \r" (9, two sensors, FW 1.1 trailing space) and
# eight 3-digit ADC fields (32): 73 bytes of 10 bits (8N1).
BAUD_CYCLE_BYTES = 14 + 18 + 9 + 32


def _start_emulator() -> tuple[subprocess.Popen[str], str]:
    # the driver's own overhead: the wire's timing off (bench_board_link.py measures it on)
    proc = subprocess.Popen([sys.executable, "-m", "eddiebot.cli.emulator", "--no-timing"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    path = proc.stdout.readline().strip()
    return proc, path


def pty_latency(n: int = 3000) -> dict[str, float]:
    proc, path = _start_emulator()
    board = Board(SerialLink(path), timeout_s=1.0)
    try:
        board.start()
        for _ in range(100):
            board.version()
        lat = []
        for _ in range(n):
            t0 = time.perf_counter_ns()
            board.version()
            lat.append(time.perf_counter_ns() - t0)
        lat.sort()
        cycles = 0
        start = time.perf_counter()
        while time.perf_counter() < start + 3.0:
            board.distance()
            board.ping()
            board.adc()
            cycles += 1
        rate = cycles / (time.perf_counter() - start)
    finally:
        board.close()
        proc.terminate()
        proc.wait(timeout=5)
    return {"median_us": statistics.median(lat) / 1e3, "p99_us": lat[int(0.99 * n)] / 1e3,
            "cycle_hz": rate}


def inprocess_cycle_rate(seconds: float = 3.0) -> float:
    """Cycles per CPU second of this process (immune to other processes' load)."""
    clock_ns = [0]
    emu = FirmwareEmulator()
    board = Board(EmulatorLink(emu, lambda: clock_ns[0]), clock=lambda: clock_ns[0])
    board.start()
    board.go_speed(40, 40)
    cycles = 0
    t0 = time.process_time()
    while time.process_time() < t0 + seconds:
        for _ in range(100):
            clock_ns[0] += 1_000_000
            board.distance()
            board.ping()
            board.adc()
        cycles += 100
    return cycles / (time.process_time() - t0)


def plant_realtime_factor(sim_seconds: float = 600.0, step_s: float = 0.01) -> float:
    """Simulated seconds per CPU second of this process."""
    emu = FirmwareEmulator()
    emu.feed(b"ACC C8\rGOSPD 40 30\r")
    steps = round(sim_seconds / step_s)
    t0 = time.process_time()
    for i in range(1, steps + 1):
        emu.advance_to_ns(round(i * step_s * 1e9))
    return sim_seconds / (time.process_time() - t0)


def main() -> int:
    # Best of three runs for the throughputs: the machine is shared, and interference only
    # ever makes a run slower.
    runs = [pty_latency(n=2000) for _ in range(3)]
    pty = min(runs, key=lambda r: r["median_us"])
    pty["cycle_hz"] = max(r["cycle_hz"] for r in runs)
    inproc = max(inprocess_cycle_rate(2.0) for _ in range(3))
    factor = max(plant_realtime_factor(300.0) for _ in range(3))
    wire_ms = BAUD_CYCLE_BYTES * 10 / 115_200 * 1e3
    rows = [
        {"benchmark": "pty VER request->reply (median)", "value": pty["median_us"],
         "unit": "us", "target": "<= 1000"},
        {"benchmark": "pty VER request->reply (p99)", "value": pty["p99_us"], "unit": "us",
         "target": ""},
        {"benchmark": "DIST+PING+ADC cycle over pty", "value": pty["cycle_hz"], "unit": "Hz",
         "target": ">= 500"},
        {"benchmark": "DIST+PING+ADC cycle in-process (sim clock, per CPU s)", "value": inproc,
         "unit": "Hz", "target": ">= 5000"},
        {"benchmark": "emulator plant on sim clock (10 ms steps, per CPU s)", "value": factor,
         "unit": "x real time", "target": ">= 1000"},
        {"benchmark": "115200 baud wire time of one cycle (real board)", "value": wire_ms,
         "unit": "ms", "target": f"ceiling {1e3 / wire_ms:.0f} Hz"},
    ]
    rows.append({"benchmark": "machine load (1-min average) at the end", "value": os.getloadavg()[0],
                 "unit": "", "target": f"{os.cpu_count()} CPUs"})
    print_table(rows, ["benchmark", "value", "unit", "target"])
    write_results("robot", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
