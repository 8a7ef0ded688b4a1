"""``eddie calibrate``: UMBmark calibration of wheel separation and wheel diameters.

The robot drives an L×L square clockwise and counter-clockwise ``--runs`` times each (closed
loop on its own odometry, like any dead-reckoning run); after each run you measure where it
stopped relative to the start mark — x forward, y left, in metres, in the frame of the start
pose — and type it in. The fitted ``wheel_separation_multiplier`` and left/right
``wheel_radius_multiplier`` refine the calibration already in ``--output`` (the runs are
driven with it, so the new factors compose with the old ones) and are written for both
``eddie_odom`` (odometry) and ``eddie`` (the driver's twist → wheel speeds); ``eddie
launch bringup`` loads the file from ``--output``'s default place. The port is checked
before you are asked to place the robot.

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
    from eddiebot.robot.errors import LinkLost
    from eddiebot.robot.links import SerialLink

    probe = SerialLink(args.port)
    try:
        probe.open()
    except LinkLost as exc:
        raise RuntimeError(f"{exc} (is the board on and plugged in? ls /dev/ttyUSB*)") from None
    probe.close()
    errors: dict[int, list[tuple[float, float]]] = {-1: [], 1: []}
    for direction in (-1, 1):
        for run in range(args.runs):
            name = "clockwise" if direction < 0 else "counter-clockwise"
            input(f"\nPlace the robot on the start mark for {name} run {run + 1}/{args.runs}; press Enter.")
            context = Context()
            desc = parse_launch_file(find_launch_file("bringup"),
                                     {"port": args.port, "calibration": str(args.output)})
            nodes = build_nodes(desc, context, NODES)
            driver = SquareDriver(side=args.side, speed=args.speed, direction=direction, context=context)
            ex = SingleThreadedExecutor(context=context)
            for n in [*nodes, driver]:
                ex.add_node(n)
            board = next(n for n in nodes if n.get_name() == "eddie")
            start = time.monotonic()
            deadline = start + 60 + 8 * args.side / args.speed
            while not driver.done.is_set() and time.monotonic() < deadline:
                ex.spin_once(timeout_sec=0.05)
                if not getattr(board, "connected", True) and time.monotonic() - start > 5.0:
                    deadline = 0.0  # the board does not answer: give up now, not in a minute
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
    out = args.output.expanduser()
    old = _existing_factors(out)
    factors = {
        "wheel_separation_multiplier": old["wheel_separation_multiplier"]
        * float(result.wheel_separation_multiplier),
        "left_wheel_radius_multiplier": old["left_wheel_radius_multiplier"]
        * float(result.left_wheel_radius_multiplier),
        "right_wheel_radius_multiplier": old["right_wheel_radius_multiplier"]
        * float(result.right_wheel_radius_multiplier),
    }
    if old != _IDENTITY:
        print(f"refined the calibration in {out}: "
              + ", ".join(f"{k} {old[k]:.5f} → {v:.5f}" for k, v in factors.items()))
    section = {"ros__parameters": {k: round(v, 6) for k, v in factors.items()}}
    params = {"eddie_odom": section, "eddie": section}
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(f"# UMBmark calibration, side {args.side} m\n"
                   + yaml.safe_dump(params, sort_keys=False, default_flow_style=False))
    tmp.replace(out)
    print(f"wrote {out}")
    return 0


_IDENTITY = {"wheel_separation_multiplier": 1.0, "left_wheel_radius_multiplier": 1.0,
             "right_wheel_radius_multiplier": 1.0}


def _existing_factors(path: Path) -> dict[str, float]:
    """The factors of an earlier calibration file (odometry's section), or 1.0 each."""
    try:
        data = yaml.safe_load(path.read_text()) or {}
        section = data["eddie_odom"]["ros__parameters"]
    except (OSError, KeyError, TypeError, yaml.YAMLError):
        return dict(_IDENTITY)
    return {k: float(section.get(k, 1.0)) for k in _IDENTITY}
