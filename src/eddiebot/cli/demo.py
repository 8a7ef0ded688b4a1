"""``eddie demo``: the main job, in the simulator, with a report under ``out/demo/``.

Stage ``base``: the emulator serves a pty; the bring-up stack drives a 1 m square over it
and prints wheel odometry against the emulator's true pose at each corner.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from eddiebot.demo.square import run_square


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", type=Path, default=Path("out/demo"), help="output folder")
    parser.add_argument("--side", type=float, default=1.0, help="square side in metres")


def run(args: argparse.Namespace) -> int:
    out: Path = args.output
    out.mkdir(parents=True, exist_ok=True)
    print("== stage 1: bring-up over a pty against the firmware emulator, 1 m square ==")
    result = run_square(out, side=args.side)
    print(f"emulated board on {result.device}")
    print(f"{'corner':>6}  {'odom x':>8} {'odom y':>8} {'odom θ°':>8}  {'true x':>8} {'true y':>8} "
          f"{'true θ°':>8}  {'Δpos m':>7} {'Δθ°':>5}")
    for c in result.corners:
        print(f"{c.index:>6}  {c.odom[0]:8.3f} {c.odom[1]:8.3f} {math.degrees(c.odom[2]):8.1f}  "
              f"{c.truth[0]:8.3f} {c.truth[1]:8.3f} {math.degrees(c.truth[2]):8.1f}  "
              f"{c.position_error:7.3f} {math.degrees(c.heading_error):5.1f}")
    if len(result.corners) != 4:
        print(f"the square did not finish: {len(result.corners)} corners", file=sys.stderr)
        return 1
    if result.bag is not None:
        print(f"recorded the run to {result.bag} (rosbag2 MCAP)")
    return 0
