"""``eddie waypoints FILE``: follow the waypoints of a YAML file (``follow_waypoints``).

The file is a list of ``{x, y, yaw}`` (yaw optional, rad; ``frame`` optional, default map),
or a mapping with such a list under ``waypoints``. Prints the current waypoint and the
missed ones; exits non-zero when any was missed.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import yaml

__all__ = ["HELP", "add_arguments", "load_waypoints", "run"]

HELP = "follow waypoints from a YAML list of {x, y, yaw}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", type=Path, help="YAML list of {x, y, yaw}")
    parser.add_argument("--frame", default="map")
    parser.add_argument("--loops", type=int, default=0, help="extra passes over the list")
    parser.add_argument("--timeout", type=float, default=None, help="wall seconds for everything")


def load_waypoints(path: Path, frame: str = "map") -> list[tuple[float, float, float, str]]:
    """(x, y, yaw, frame) per waypoint; ``ValueError`` naming the file and entry otherwise."""
    doc = yaml.safe_load(path.read_text())
    if isinstance(doc, dict):
        doc = doc.get("waypoints")
    if not isinstance(doc, list) or not doc:
        raise ValueError(f"{path}: expected a non-empty list of {{x, y, yaw}}")
    out = []
    for i, w in enumerate(doc):
        if not isinstance(w, dict) or "x" not in w or "y" not in w:
            raise ValueError(f"{path}: waypoint {i} needs x and y, got {w!r}")
        try:
            out.append((float(w["x"]), float(w["y"]), float(w.get("yaw", 0.0)),
                        str(w.get("frame", frame))))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: waypoint {i}: {exc}") from exc
    return out


def run(args: argparse.Namespace) -> int:
    from eddiebot.cli._common import cli_session
    from eddiebot.cli.goal import error_name, navigate, pose_goal
    from eddiebot.msgs.nav2_msgs import FollowWaypoints

    try:
        points = load_waypoints(args.file, args.frame)
    except (OSError, ValueError) as exc:
        print(f"eddie waypoints: {exc}", file=sys.stderr)
        return 2
    goal = FollowWaypoints.Goal(poses=[pose_goal(x, y, yaw, f) for x, y, yaw, f in points],
                                number_of_loops=args.loops)
    current = [-1]

    def on_feedback(msg: Any) -> None:
        i = int(msg.feedback.current_waypoint)
        if i != current[0]:
            current[0] = i
            x, y, _, _ = points[i]
            print(f"waypoint {i + 1}/{len(points)}: ({x:g}, {y:g})", flush=True)

    with cli_session("waypoints") as s:
        code, response = navigate(s, FollowWaypoints, "/follow_waypoints", goal,
                                  timeout=args.timeout, on_feedback=on_feedback)
        if response is None:
            return 1
        missed = list(response.result.missed_waypoints)
        for m in missed:
            print(f"missed waypoint {int(m.index) + 1}: {error_name(int(m.error_code))} "
                  f"({int(m.error_code)})", file=sys.stderr)
        if code == 0 and not missed:
            print(f"all {len(points)} waypoints reached")
            return 0
        return 1
