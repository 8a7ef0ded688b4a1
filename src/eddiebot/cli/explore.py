"""``eddie explore --world W [--time-limit S] [--seed N] -o OUTDIR``: map a building alone.

The simulator, Eddie's base, SLAM, Nav2's servers and the explore node (explore_lite's
frontier exploration) run in one process on the sim clock, as fast as the CPU allows. The
robot looks around, drives to frontiers until none is left (or ``--time-limit`` simulated
seconds of exploring), then goes back to its start. OUTDIR receives ``map.yaml`` +
``map.pgm``, ``report.json`` and ``report.md`` with a picture. Ctrl-C stops the robot
where it is (it is not sent home) and still writes what was mapped.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["HELP", "add_arguments", "run"]

HELP = "explore and map a world by itself (frontier exploration), then come home"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default=None, help="explore this simulator world "
                        "(`eddie world list`); without it: a running robot (not supported yet)")
    parser.add_argument("--time-limit", type=float, default=None, metavar="SIM_SECONDS",
                        help="stop exploring after this many simulated seconds, then go home")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random process")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="output directory (default out/explore/<world>)")
    parser.add_argument("--camera", default="160x120@10",
                        help="simulated Kinect WxH@HZ (default 160x120@10)")
    parser.add_argument("--no-return", action="store_true",
                        help="stay where exploring ended (return_to_init false)")


def run(args: argparse.Namespace) -> int:
    if args.world is None:
        print("eddie explore: attaching to a running simulator or robot is not supported yet; "
              "use --world NAME", file=sys.stderr)
        return 2
    from eddiebot.cli._stack import check_world
    from eddiebot.cli.sim import camera_args
    from eddiebot.explore.mission import run_exploration
    from eddiebot.explore.report import write_report

    check_world(args.world)
    cam = camera_args(args.camera)
    camera = (int(cam["camera_width"]), int(cam["camera_height"]), float(cam["camera_rate"]))
    out = args.output or Path("out") / "explore" / Path(args.world).stem
    params = {"return_to_init": False} if args.no_return else None
    result = run_exploration(out, world=args.world, seed=args.seed, time_limit=args.time_limit,
                             camera=camera, explore_params=params)
    json_path, md_path = write_report(result, out)
    print(f"{result.reason}: coverage {100 * result.coverage:.1f} %, agreement "
          f"{100 * result.map_agreement:.1f} %, ATE {result.ate_m:.3f} m, "
          f"{result.distance_m:.1f} m in {result.sim_time_s:.0f} s simulated "
          f"({result.wall_time_s:.0f} s wall), {result.collisions} collisions, "
          f"home: {result.returned_home}")
    print(f"map     {out / 'map.yaml'}\nreport  {md_path}\nfigures {json_path}")
    return 130 if result.interrupted else 0
