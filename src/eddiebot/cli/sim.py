"""``eddie sim --world office``: the simulator with the whole base stack.

The simulated Eddie is the firmware emulator's plant; the real board driver talks to it,
so everything from ``/cmd_vel_teleop`` down to the wheel encoders is the robot's own code.
Drive it from another terminal with ``eddie teleop``.
"""

from __future__ import annotations

import argparse

from eddiebot.cli._stack import add_run_arguments, run_stack


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default="office",
                        help="a built-in world (eddie world list) or a world/nav2 map YAML file")
    parser.add_argument("--camera", default="640x480@30",
                        help="Kinect resolution and rate, WxH@HZ (e.g. 320x240@10; @0 disables)")
    add_run_arguments(parser)


def camera_args(spec: str) -> dict[str, str]:
    size, _, rate = spec.partition("@")
    w, _, h = size.partition("x")
    return {"camera_width": str(int(w)), "camera_height": str(int(h)),
            "camera_rate": str(float(rate or 30))}


def run(args: argparse.Namespace) -> int:
    launch_args = {"world": args.world, "seed": str(args.seed), **camera_args(args.camera)}
    return run_stack(args, "sim", launch_args)
