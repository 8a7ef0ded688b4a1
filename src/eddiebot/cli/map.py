"""``eddie map save NAME``: save the current ``/map`` as nav2 map files (NAME.pgm + NAME.yaml).

Calls ``/map_saver/save_map`` (nav2_msgs/SaveMap) when a map saver runs (``eddie nav``),
else ``/slam_toolbox/save_map`` (slam_toolbox/SaveMap) during mapping.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["HELP", "add_arguments", "run"]

HELP = "save the current map (map_saver or slam_toolbox) as NAME.pgm + NAME.yaml"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="map_command", required=True)
    save = sub.add_parser("save", help="save /map to NAME.pgm and NAME.yaml")
    save.add_argument("name", help="output path without extension")
    save.add_argument("--format", default="pgm", choices=("pgm", "png", "bmp"))
    save.add_argument("--mode", default="trinary", choices=("trinary", "scale", "raw"))
    # None: the thresholds of eddiebot.maps (0.196 / 0.65), so grey 205 reloads as unknown
    save.add_argument("--free", type=float, default=None, help="free threshold (0.196)")
    save.add_argument("--occupied", type=float, default=None, help="occupied threshold (0.65)")
    save.add_argument("--topic", default="map")
    save.add_argument("--timeout", type=float, default=10.0)


def run(args: argparse.Namespace) -> int:
    from eddiebot.cli._common import cli_session
    from eddiebot.core import SingleThreadedExecutor
    from eddiebot.maps import DEFAULT_FREE_THRESH, DEFAULT_OCCUPIED_THRESH

    free = DEFAULT_FREE_THRESH if args.free is None else args.free
    occupied = DEFAULT_OCCUPIED_THRESH if args.occupied is None else args.occupied
    url = str(Path(args.name).expanduser().resolve())
    with cli_session("map") as s:
        ex = SingleThreadedExecutor(context=s.context)
        ex.add_node(s.node)
        from eddiebot.msgs import nav2_msgs, slam_toolbox

        nav = s.node.create_client(nav2_msgs.SaveMap, "/map_saver/save_map")
        slam = s.node.create_client(slam_toolbox.SaveMap, "/slam_toolbox/save_map")
        deadline = time.monotonic() + min(args.timeout, 5.0)
        while not (nav.service_is_ready() or slam.service_is_ready()) and time.monotonic() < deadline:
            time.sleep(0.05)
        if nav.service_is_ready():
            req = nav2_msgs.SaveMap.Request(map_topic=args.topic, map_url=url,
                                            image_format=args.format, map_mode=args.mode,
                                            free_thresh=free, occupied_thresh=occupied)
            future = nav.call_async(req)
            via = "/map_saver/save_map"
        elif slam.service_is_ready():
            req = slam_toolbox.SaveMap.Request()
            req.name.data = url
            future = slam.call_async(req)
            via = "/slam_toolbox/save_map"
        else:
            print("eddie map save: neither /map_saver/save_map nor /slam_toolbox/save_map is "
                  "available (run `eddie nav` or SLAM)", file=sys.stderr)
            return 1
        ex.spin_until_future_complete(future, timeout_sec=args.timeout)
        if not future.done():
            print(f"eddie map save: {via} did not answer within {args.timeout:g} s", file=sys.stderr)
            return 1
        response = future.result()
        ok = bool(response.result) if hasattr(response, "result") and isinstance(
            response.result, bool) else int(getattr(response, "result", 1)) == 0
        if not ok:
            print(f"eddie map save: {via} failed", file=sys.stderr)
            return 1
        print(f"map saved to {url}.yaml (via {via})")
        return 0
