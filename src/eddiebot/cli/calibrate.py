"""``eddie calibrate``: UMBmark calibration of wheel separation and wheel diameters.

The robot drives an L×L square clockwise and counter-clockwise ``--runs`` times each (closed
loop on its own odometry, like any dead-reckoning run); after each run you measure where it
stopped relative to the start mark — x forward, y left, in metres, in the frame of the start
pose — and type it in. The fitted ``wheel_separation_multiplier`` and left/right
``wheel_radius_multiplier`` are written as a parameter file for ``eddie_odom``; ``eddie
launch bringup`` loads it from ``--output``'s default place.

The original URDF put the wheels 0.381 m apart, the firmware's geometry implies 0.394 m and
the documents say 0.39 m: this is how to find out for your robot.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import yaml

from eddiebot.base.calibration import umbmark
from eddiebot.robot.constants import TRACK_M

DEFAULT_OUTPUT = Path(os.environ.get("EDDIE_CALIBRATION", "~/.config/eddiebot/calibration.yaml"))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--port", default="/dev/ttyUSB0", help="the board's serial port")
    parser.add_argument("--side", type=float, default=2.0, help="square side in metres (UMBmark: 4)")
    parser.add_argument("--runs", type=int, default=3, help="runs per direction (UMBmark: 5)")
    parser.add_argument("--speed", type=float, default=0.2, help="straight-line speed, m/s")
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT,
                        help=f"parameter file to write (default {DEFAULT_OUTPUT})")
    parser.add_argument("--errors", type=Path,
                        help="skip driving: a YAML file {cw: [[x, y], ...], ccw: [[x, y], ...]}")


def _drive_runs(args: argparse.Namespace) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    from eddiebot.core.context import Context
    from eddiebot.core.executors import SingleThreadedExecutor
    from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
    from eddiebot.demo.square import SquareDriver
    from eddiebot.registry import NODES

    errors: dict[int, list[tuple[float, float]]] = {-1: [], 1: []}
    for direction in (-1, 1):
        for run in range(args.runs):
            name = "clockwise" if direction < 0 else "counter-clockwise"
            input(f"\nPlace the robot on the start mark for {name} run {run + 1}/{args.runs}; press Enter.")
            context = Context()
            desc = parse_launch_file(find_launch_file("bringup"), {"port": args.port})
            nodes = build_nodes(desc, context, NODES)
            driver = SquareDriver(side=args.side, speed=args.speed, direction=direction, context=context)
            ex = SingleThreadedExecutor(context=context)
            for n in [*nodes, driver]:
                ex.add_node(n)
            deadline = time.monotonic() + 60 + 8 * args.side / args.speed
            while not driver.done.is_set() and time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.05)
            for n in reversed([*nodes, driver]):
                n.destroy_node()
            context.shutdown()
            if not driver.done.is_set():
                raise RuntimeError("the square did not finish in time; check the robot and the port")
            text = input("Measured stop position relative to the start (x forward, y left, m): ")
            x, y = (float(v) for v in text.replace(",", " ").split()[:2])
            errors[direction].append((x, y))
    return errors[-1], errors[1]


def run(args: argparse.Namespace) -> int:
    try:
        if args.errors:
            data = yaml.safe_load(args.errors.read_text())
            cw = [(float(e[0]), float(e[1])) for e in data["cw"]]
            ccw = [(float(e[0]), float(e[1])) for e in data["ccw"]]
        else:
            cw, ccw = _drive_runs(args)
        result = umbmark(cw, ccw, args.side, TRACK_M)
    except (KeyError, ValueError, OSError, RuntimeError) as exc:
        print(f"eddie calibrate: {exc}", file=sys.stderr)
        return 2
    print(f"α = {result.alpha_rad:+.5f} rad (separation), β = {result.beta_rad:+.5f} rad (diameters)")
    print(f"Ed = D_R/D_L = {result.ed:.5f}; Eb = b_actual/b_nominal = {result.eb:.5f} "
          f"→ wheel separation {TRACK_M * result.eb:.4f} m")
    params = {
        "eddie_odom": {
            "ros__parameters": {
                "wheel_separation_multiplier": round(float(result.wheel_separation_multiplier), 6),
                "left_wheel_radius_multiplier": round(float(result.left_wheel_radius_multiplier), 6),
                "right_wheel_radius_multiplier": round(float(result.right_wheel_radius_multiplier), 6),
            }
        }
    }
    out = args.output.expanduser()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(f"# UMBmark calibration, side {args.side} m\n" + yaml.safe_dump(params, sort_keys=False))
    tmp.replace(out)
    print(f"wrote {out}")
    return 0
