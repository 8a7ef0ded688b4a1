"""``eddie explore --world W [--time-limit S] [--seed N] -o OUTDIR``: map a building alone.

The simulator, Eddie's base, SLAM, Nav2's servers and the explore node (explore_lite's
frontier exploration) run in one process on the sim clock, as fast as the CPU allows. The
robot looks around, drives to frontiers until none is left (or ``--time-limit`` simulated
seconds of exploring), then goes back to its start. OUTDIR receives ``map.yaml`` +
``map.pgm``, ``report.json`` and ``report.md`` with a picture. Ctrl-C stops the robot
where it is (it is not sent home) and still writes what was mapped.

Without ``--world`` it attaches to the simulator (``eddie sim``) or the real robot's
bring-up already running on the same ROS_DOMAIN_ID (a ``/clock`` or ``/odom`` publisher
within ``--attach-timeout`` seconds, default 10), as ``eddie slam`` and ``eddie nav`` do,
and runs SLAM (launch ``mapping``), the navigation servers (``nav``, SLAM localizing) and
the explore node against it, following ``/clock`` when it is a simulator. OUTDIR then
receives the SLAM session as well; the report has no ground-truth figures. With
``--paused`` the explore node waits for a resume — the dashboard's "Map this floor" button,
``explore/resume`` (std_srvs/SetBool service or std_msgs/Bool topic) — before it starts.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["HELP", "add_arguments", "run"]

HELP = "explore and map a world by itself (frontier exploration), then come home"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default=None, help="explore this simulator world "
                        "(`eddie world list`); without it, attach to the simulator or robot "
                        "already running")
    parser.add_argument("--attach-timeout", type=float, default=None, metavar="SECONDS",
                        help="without --world: how long to wait for the robot (default 10)")
    parser.add_argument("--time-limit", type=float, default=None, metavar="SIM_SECONDS",
                        help="stop exploring after this many simulated seconds, then go home")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random process")
    parser.add_argument("-o", "--output", type=Path, default=None,
                        help="output directory (default out/explore/<world>)")
    parser.add_argument("--camera", default="160x120@10",
                        help="simulated Kinect WxH@HZ (default 160x120@10)")
    parser.add_argument("--no-return", action="store_true",
                        help="stay where exploring ended (return_to_init false)")
    parser.add_argument("--paused", action="store_true",
                        help="wait for a resume (the dashboard's \"Map this floor\", or "
                        "explore/resume) before exploring (start_paused true)")


def _explore_params(args: argparse.Namespace) -> dict[str, object] | None:
    params: dict[str, object] = {}
    if args.no_return:
        params["return_to_init"] = False
    if args.paused:
        params["start_paused"] = True
    return params or None


def run(args: argparse.Namespace) -> int:
    if args.world is None:
        return _run_attached(args)
    if args.paused:
        from eddiebot.cli.errors import CliError

        raise CliError("eddie explore: --paused waits for a resume from another process, and "
                       "--world runs in a graph of its own: start `eddie sim --world "
                       f"{args.world}` and run `eddie explore --paused` (no --world) beside it")
    from eddiebot.cli._stack import check_world
    from eddiebot.cli.sim import camera_args
    from eddiebot.explore.mission import run_exploration
    from eddiebot.explore.report import write_report

    check_world(args.world)
    cam = camera_args(args.camera)
    camera = (int(cam["camera_width"]), int(cam["camera_height"]), float(cam["camera_rate"]))
    out = args.output or Path("out") / "explore" / Path(args.world).stem
    params = _explore_params(args)
    result = run_exploration(out, world=args.world, seed=args.seed, time_limit=args.time_limit,
                             camera=camera, explore_params=params)
    json_path, md_path = write_report(result, out)
    _print_summary(result, out, json_path, md_path)
    return 130 if result.interrupted else 0


def _print_summary(result: object, out: Path, json_path: Path, md_path: Path) -> None:
    from eddiebot.explore.mission import ExploreResult

    assert isinstance(result, ExploreResult)
    if result.world == "attached":
        home = result.returned_home if not result.home_failure else \
            f"{result.returned_home} ({result.home_failure})"
        print(f"{result.reason}: {result.mapped_free_m2:.1f} m² mapped free, "
              f"{result.distance_m:.1f} m driven, {result.frontiers_visited} frontiers reached, "
              f"{result.frontiers_abandoned} abandoned, home: {home}")
        print(f"map     {out / 'map.yaml'}\nsession {out / 'session.eslam'}\n"
              f"report  {md_path}\nfigures {json_path}")
        return
    print(f"{result.reason}: coverage {100 * result.coverage:.1f} %, agreement "
          f"{100 * result.map_agreement:.1f} %, ATE {result.ate_m:.3f} m, "
          f"{result.distance_m:.1f} m in {result.sim_time_s:.0f} s simulated "
          f"({result.wall_time_s:.0f} s wall), {result.collisions} collisions, "
          f"home: {result.returned_home}")
    print(f"map     {out / 'map.yaml'}\nreport  {md_path}\nfigures {json_path}")


def _run_attached(args: argparse.Namespace) -> int:
    """SLAM, navigation and exploration against the simulator or robot on this domain."""
    import time

    from eddiebot.cli._attach import ATTACH_WAIT_S, graph_cache, wait_for_robot
    from eddiebot.cli._common import connect_transport
    from eddiebot.cli.errors import CliError
    from eddiebot.core.context import Context
    from eddiebot.explore.mission import run_attached
    from eddiebot.explore.report import write_report

    context = Context(use_sim_time=True)
    try:
        connect_transport(context)
        wait = ATTACH_WAIT_S if args.attach_timeout is None else args.attach_timeout
        robot = wait_for_robot(context, "eddie explore", wait)
        context.use_sim_time = robot.simulated
        cache = graph_cache(context)
        if cache is not None and any(e.node_name == "slam_toolbox" for e in cache.nodes()):
            raise CliError("eddie explore: slam_toolbox runs on this domain already (eddie slam "
                           "or eddie nav --localization slam); exploring brings its own SLAM: "
                           "stop it first (Ctrl-C saves its map)")
        print(f"attached to {robot.what}", flush=True)
        cloud = robot.simulated and cache is not None and not cache.publishers("/points")
        out = args.output or Path("out") / "explore" / time.strftime("%Y%m%d-%H%M%S")
        params = _explore_params(args)
        result = run_attached(out, context, simulated=robot.simulated, with_cloud=cloud,
                              time_limit=args.time_limit, explore_params=params)
    finally:
        context.shutdown()
    json_path, md_path = write_report(result, out)
    _print_summary(result, out, json_path, md_path)
    return 130 if result.interrupted else 0
