"""``eddie world``: list the built-in simulator worlds, or show one as a top-view PNG.

    eddie world list
    eddie world show office [-o office.png] [--scale 20] [--maps DIR]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_arguments", "run"]

HELP = "list the built-in simulator worlds, or render one to a top-view PNG"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="world_command", required=True)
    sub.add_parser("list", help="name and describe every built-in world")
    show = sub.add_parser("show", help="write a top-view PNG of a world")
    show.add_argument("name", help="built-in world name or path to a world YAML file")
    show.add_argument("-o", "--output", type=Path, default=None,
                      help="PNG file to write (default: <name>.png in the current directory)")
    show.add_argument("--scale", type=float, default=20.0, help="pixels per metre (default 20)")
    show.add_argument("--maps", type=Path, default=None,
                      help="also write the ground-truth scan and footprint maps (nav2 format) here")


def run(args: argparse.Namespace) -> int:
    from eddiebot.sim.worlds import list_worlds, load_world

    if args.world_command == "list":
        for name in list_worlds():
            w = load_world(name)
            xmin, ymin, xmax, ymax = w.bounds
            print(f"{name:<10} {xmax - xmin:5.1f} x {ymax - ymin:4.1f} m  {w.description}")
        return 0
    # an unknown name raises UnknownWorldError, which eddie's main prints as one line
    world = load_world(args.name)
    import cv2

    from eddiebot.sim.preview import top_view

    out = args.output or Path(f"{world.name}.png")
    img = top_view(world, px_per_m=args.scale)
    if not cv2.imwrite(str(out), img[..., ::-1]):
        print(f"eddie world: cannot write {out}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({img.shape[1]}x{img.shape[0]} px, {len(world.prisms)} prisms)")
    if args.maps is not None:
        from eddiebot.maps import save_map
        from eddiebot.sim.ground_truth import ground_truth_maps

        args.maps.mkdir(parents=True, exist_ok=True)
        maps = ground_truth_maps(world)
        for kind, grid in (("scan", maps.scan), ("footprint", maps.footprint)):
            path = save_map(grid, args.maps / f"{world.name}-{kind}")
            print(f"wrote {path}")
    return 0
