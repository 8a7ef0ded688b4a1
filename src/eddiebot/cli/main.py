"""``eddie``: the command-line front door, in the ros2 CLI's habits.

Each sub-command lives in ``eddiebot.cli.<module>`` and exposes
``add_arguments(parser)`` and ``run(args) -> int``; modules are imported only when their
command runs, so ``eddie --help`` is instant.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence

#: (command, module, one-line help) — the explicit registry of sub-commands.
COMMANDS: list[tuple[str, str, str]] = [
    ("demo", "eddiebot.cli.demo", "run the main job in the simulator and write a report under out/demo/"),
    ("launch", "eddiebot.cli.launch", "run a YAML launch file (eddie launch bringup port:=/dev/ttyUSB0)"),
    ("run", "eddiebot.cli.run", "run one registered node (eddie run eddiebot.base.odometry)"),
    ("sim", "eddiebot.cli.sim", "start the simulator with the bring-up stack"),
    ("teleop", "eddiebot.cli.teleop", "drive with the keyboard (teleop_twist_keyboard keys)"),
    ("slam", "eddiebot.cli.slam", "2D SLAM: live in the simulator, or replay a log"),
    ("map", "eddiebot.cli.map", "save or show maps"),
    ("nav", "eddiebot.cli.nav", "navigation in a saved map (simulator or robot)"),
    ("goal", "eddiebot.cli.goal", "send a navigation goal X Y YAW"),
    ("waypoints", "eddiebot.cli.waypoints", "follow waypoints from a file"),
    ("vslam", "eddiebot.cli.vslam", "RGB-D SLAM: live, replay, loops, database tools"),
    ("posegraph", "eddiebot.cli.posegraph", "pose-graph tools (optimize g2o/TORO files)"),
    ("world", "eddiebot.cli.world", "list simulator worlds and render their previews"),
    ("emulator", "eddiebot.cli.emulator", "serve the Eddie firmware emulator on a pty"),
    ("board", "eddiebot.cli.board", "send a raw firmware command to the board (eddie board VER)"),
    ("calibrate", "eddiebot.cli.calibrate", "UMBmark calibration of track width and wheel radius"),
    ("topic", "eddiebot.cli.topic", "list|echo|hz|info|pub topics"),
    ("node", "eddiebot.cli.node_cmd", "list nodes"),
    ("param", "eddiebot.cli.param", "list|get|set parameters"),
    ("service", "eddiebot.cli.service", "list|call services"),
    ("action", "eddiebot.cli.action", "list|send_goal actions"),
    ("interface", "eddiebot.cli.interface", "show message, service and action definitions"),
    ("record", "eddiebot.cli.record", "record topics to a rosbag2 (MCAP)"),
    ("play", "eddiebot.cli.play", "play a rosbag2 with its original timing"),
    ("bag", "eddiebot.cli.bag", "bag info"),
    ("daemon", "eddiebot.cli.daemon", "run the Zenoh router other processes meet at"),
    ("dashboard", "eddiebot.cli.dashboard", "web dashboard: map, robot, scan, camera, teleop"),
    ("foxglove", "eddiebot.cli.foxglove", "Foxglove WebSocket bridge"),
    ("view", "eddiebot.cli.view", "render a map, bag or trajectory to PNG"),
]


def _available() -> list[tuple[str, str, str]]:
    """Registered commands whose module is installed."""
    import importlib.util

    return [c for c in COMMANDS if importlib.util.find_spec(c[1]) is not None]


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    parser = argparse.ArgumentParser(
        prog="eddie",
        description="eddiebot: bring up, drive, map and navigate a Parallax Eddie "
        "(or any differential-drive robot with an RGB-D camera), in ROS 2's formats.",
    )
    parser.add_argument("--log-level", default=os.environ.get("EDDIE_LOG_LEVEL", "info"),
                        choices=["debug", "info", "warn", "error"], help="logging level")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers = {}
    for name, module, help_text in _available():
        subparsers[name] = sub.add_parser(name, help=help_text, description=help_text)
        subparsers[name].set_defaults(_module=module)
    return parser, subparsers


def configure_logging(level: str) -> None:
    levels = {"debug": logging.DEBUG, "info": logging.INFO, "warn": logging.WARNING,
              "error": logging.ERROR}
    logging.basicConfig(
        level=levels[level],
        format="[%(levelname)s] [%(asctime)s] [%(name)s]: %(message)s",
        stream=sys.stderr,
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser, subparsers = build_parser()
    args_list = list(sys.argv[1:] if argv is None else argv)
    # Only the chosen command's module is imported to add its arguments.
    chosen = None
    skip = False
    for a in args_list:
        if skip:
            skip = False
        elif a == "--log-level":
            skip = True  # its value is not the command
        elif not a.startswith("-"):
            chosen = a
            break
    if chosen in subparsers:
        module = importlib.import_module(subparsers[chosen].get_default("_module"))
        module.add_arguments(subparsers[chosen])
    args = parser.parse_args(args_list)
    if not getattr(args, "command", None):
        parser.print_help()
        return 0
    configure_logging(args.log_level)
    module = importlib.import_module(args._module)
    try:
        return int(module.run(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
