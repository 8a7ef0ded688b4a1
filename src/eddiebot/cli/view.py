"""``eddie view FILE [--trajectory TUM ...] [--at SECONDS] -o OUT.png``: render to PNG.

FILE is a nav2 map (``.yaml``), a rosbag2 (directory, ``.mcap`` or ``.db3``: map, trajectory,
plan, scan and robot at ``--at`` seconds) or a TUM trajectory file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="map .yaml, bag (dir/.mcap/.db3) or TUM file")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="PNG to write (default: FILE's name with .png)")
    parser.add_argument("-t", "--trajectory", action="append", default=[], type=Path,
                        metavar="TUM", help="add a TUM trajectory (repeatable; label = file name)")
    parser.add_argument("--at", type=float, default=None, metavar="SECONDS",
                        help="for a bag: the moment to draw, seconds after its start")
    parser.add_argument("--robot", type=float, nargs=3, default=None, metavar=("X", "Y", "YAW"),
                        help="draw the robot footprint at this pose (map frame)")
    parser.add_argument("--title", default=None, help="legend title")
    parser.add_argument("--size", type=int, default=800,
                        help="minimum length of the longer side, pixels")


def run(args: argparse.Namespace) -> int:
    from eddiebot.bag import BagError
    from eddiebot.maps import MapError
    from eddiebot.viz.snapshot import render_bag, render_map, render_trajectories

    src: Path = args.file
    out: Path = args.output or Path(f"{src.name if src.is_dir() else src.stem}.png")
    trajectories = list(args.trajectory) or None
    try:
        if src.suffix in (".yaml", ".yml"):
            from eddiebot.maps import load_map

            render_map(load_map(src), trajectories=trajectories, robot_pose=args.robot,
                       title=args.title, out_path=out, min_size=args.size)
        elif src.is_dir() or src.suffix in (".mcap", ".db3"):
            render_bag(src, at=args.at, trajectories=trajectories, title=args.title,
                       out_path=out, min_size=args.size)
        elif src.is_file():
            render_trajectories([src, *(trajectories or [])], robot_pose=args.robot,
                                title=args.title, out_path=out, min_size=args.size)
        else:
            print(f"eddie view: {src} does not exist", file=sys.stderr)
            return 2
    except (BagError, MapError, ValueError, OSError) as exc:
        print(f"eddie view: {exc}", file=sys.stderr)
        return 2
    print(out)
    return 0
