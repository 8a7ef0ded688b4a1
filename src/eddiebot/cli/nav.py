"""``eddie nav --map FILE.yaml [--world NAME]``: autonomous navigation.

With ``--world`` the simulator, Eddie's base, localization and Nav2's servers run in one
process on the sim clock (launch ``nav_sim``). Without it the navigation alone (launch
``nav``) attaches to the simulator (``eddie sim``) or the real robot's bring-up already
running on the same ROS_DOMAIN_ID (a ``/clock`` or ``/odom`` publisher within
``--attach-timeout`` s, default 10; else one line and exit status 2), following ``/clock``
when there is one; stopping it leaves the robot running. The parameters file (``--params``,
default config/nav2.yaml; config/nav2_report.yaml holds the report's values) is resolved
into ``<run dir>/nav2_params.yaml`` with the costmaps folded into their servers, plus the
initial pose for AMCL.

The initial pose, in the map frame: ``--initial-pose X Y YAW``; else, attached to the
robot whose running odometry the map was saved with (the map YAML's ``map_to_odom`` and
``odom_session`` keys, written by SLAM), where the robot is in the map now; else, with
``--world`` and a map without those keys (a map in the world frame), the world's start
pose. Otherwise the run says it cannot know and AMCL waits for one (``--initial-pose`` or
the dashboard). A pose outside the map, in unknown space or on an obstacle is an error.
Send goals with ``eddie goal X Y YAW``.

Costmap filters: ``--keepout MASK.yaml`` and ``--speed-mask MASK.yaml`` (map_server
files: a keepout zone is occupied, a speed zone's value ``v`` limits the speed to
``100 - v`` % unless the parameters file's ``speed_costmap_filter_info_server`` says
otherwise) start a filter mask server and a costmap filter info server each and enable the
filter in the costmaps; with ``--dashboard`` and no keepout mask, an empty one shaped as the
map is served so the dashboard's keepout paint tool has a server to send its zones to. A
parameters file with ``*filter_mask_server`` sections naming a
``yaml_filename`` (relative to the file) starts them by itself. A mask that cannot be used
(see :func:`eddiebot.nav.nodes.costmap_filters.check_mask`) stops the run before it starts,
naming the file.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

from eddiebot.cli._stack import add_run_arguments, check_world, run_nodes, run_stack
from eddiebot.cli.errors import CliError
from eddiebot.nav.params_file import default_params
from eddiebot.nav.params_file import resolve_params as _resolve

__all__ = ["HELP", "add_arguments", "resolve_params", "run"]

HELP = "navigate on a map: the simulator with --world, else the real robot"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", required=True, type=Path, help="nav2 map YAML (or a SLAM "
                        "session with --localization slam)")
    parser.add_argument("--world", default=None, help="run in the simulator in this world")
    parser.add_argument("--params", type=Path, default=None,
                        help="Nav2 parameters file (default config/nav2.yaml)")
    parser.add_argument("--localization", choices=("amcl", "slam"), default="amcl")
    parser.add_argument("--initial-pose", type=float, nargs=3, metavar=("X", "Y", "YAW"),
                        default=None, help="AMCL's initial pose in the map frame")
    parser.add_argument("--camera", default="160x120@5",
                        help="simulated Kinect WxH@HZ (default 160x120@5: enough for the scan)")
    parser.add_argument("--attach-timeout", type=float, default=None,
                        help="without --world: how long to wait for a simulator or robot, s "
                        "(default 10)")
    parser.add_argument("--keepout", type=Path, default=None, metavar="MASK.yaml",
                        help="keepout zones: a map_server mask whose occupied cells the "
                        "planner and controller keep out of")
    parser.add_argument("--speed-mask", type=Path, default=None, metavar="MASK.yaml",
                        help="speed zones: a map_server mask; value v limits the speed to "
                        "100 - v %% of the maximum")
    parser.add_argument("--run-dir", type=Path, default=None,
                        help="where the resolved parameters are written (default a temp dir)")
    add_run_arguments(parser)


def resolve_params(source: Path, out_dir: Path, initial_pose: tuple[float, float, float] | None
                   ) -> Path:
    """:func:`eddiebot.nav.params_file.resolve_params`, its warnings on stderr."""
    return _resolve(source, out_dir, initial_pose,
                    warn=lambda text: print(f"eddie nav: {text}", file=sys.stderr))


def check_map(path: Path, localization: str) -> None:
    """Raise a typed error naming the file unless ``path`` is a usable map: a nav2 map YAML
    whose image exists (AMCL), or an existing SLAM session (``--localization slam``)."""
    if not path.exists():
        raise CliError(f"{path}: no such map file")
    if localization == "amcl":
        from eddiebot.maps import MapFormatError, read_map_yaml

        meta = read_map_yaml(path)
        if not meta.image.is_file():
            raise MapFormatError(f"{path}: key 'image': file {meta.image} not found")


def check_initial_pose(path: Path, pose: tuple[float, float, float]) -> None:
    """Raise `CliError` unless ``pose`` lies on a free cell of the map ``path`` (a map that
    does not load is left to map_server, whose bring-up names what is wrong)."""
    import numpy as np

    from eddiebot.maps import FREE, UNKNOWN, MapError, is_inside, load_map, world_to_map

    try:
        grid = load_map(path)
    except MapError:
        return
    cell = world_to_map(grid, np.array([pose[0], pose[1]]))
    at = f"initial pose ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})"
    if not bool(is_inside(grid, cell)):
        x0, y0 = grid.origin[0], grid.origin[1]
        raise CliError(
            f"eddie nav: {at} is outside {path} (x {x0:.2f}..{x0 + grid.width * grid.resolution:.2f}"
            f", y {y0:.2f}..{y0 + grid.height * grid.resolution:.2f} m); give --initial-pose "
            "X Y YAW in the map's frame")
    value = int(grid.data[int(cell[1]), int(cell[0])])
    if value == UNKNOWN:
        raise CliError(f"eddie nav: {at} lies in unknown space of {path}; give --initial-pose "
                       "X Y YAW on a free cell")
    if value > FREE + 50:
        raise CliError(f"eddie nav: {at} lies on an obstacle of {path}; give --initial-pose "
                       "X Y YAW on a free cell")


def initial_pose(args: argparse.Namespace, robot: Any, read_odom: Any
                 ) -> tuple[tuple[float, float, float] | None, str]:
    """AMCL's initial pose (or None: unknown) and one line saying where it comes from."""
    from eddiebot.maps import read_map_yaml

    name = args.map.name
    if args.initial_pose is not None:
        pose = (float(args.initial_pose[0]), float(args.initial_pose[1]),
                float(args.initial_pose[2]))
        return pose, f"starting at --initial-pose ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})"
    anchor = read_map_yaml(args.map).anchor
    session = getattr(robot, "odom_session", None)
    if anchor is not None and session is not None and anchor.odom_session == session:
        odom = read_odom()
        if odom is not None:
            from eddiebot.geometry import se2_compose

            x, y, th = (float(v) for v in se2_compose(anchor.map_to_odom, odom))
            return (x, y, th), (f"starting localised at ({x:.2f}, {y:.2f}, {th:.2f}) in {name}: "
                                "the map was saved on this robot's running odometry")
    if args.world is not None and anchor is None:
        from eddiebot.sim.worlds import load_world

        start = load_world(args.world).start
        pose = (float(start[0]), float(start[1]), float(start[2]))
        return pose, (f"starting at the world's start pose ({pose[0]:.2f}, {pose[1]:.2f}, "
                      f"{pose[2]:.2f}) ({name} has no map_to_odom: taken to be in the world frame)")
    if anchor is None:
        why = f"{name} does not record where the robot was (no map_to_odom / odom_session)"
    elif robot is None:
        why = f"{name} was saved on a robot that is not this run's simulator"
    else:
        why = f"{name} was saved on an odometry that no longer runs"
    return None, (f"eddie nav: cannot know where the robot is in {name} ({why}); AMCL waits "
                  "for an initial pose: give --initial-pose X Y YAW (or set it in the dashboard)")


def run(args: argparse.Namespace) -> int:
    if args.world is not None:
        check_world(args.world)
    check_map(args.map, args.localization)
    if args.world is None:
        return _run_attached(args)
    from eddiebot.cli.sim import camera_args

    pose, line = (None, "") if args.localization != "amcl" else initial_pose(args, None, None)
    launch_args = _launch_args(args, pose, line)
    launch_args.update({"world": args.world, "seed": str(args.seed), **camera_args(args.camera)})
    sections = filter_sections(args, Path(launch_args["params_file"]))
    if not sections:
        return run_stack(args, "nav_sim", launch_args)
    from eddiebot.cli._stack import build_description
    from eddiebot.core.context import Context
    from eddiebot.core.launch import build_nodes
    from eddiebot.nav.nodes.costmap_filters import build_filter_servers
    from eddiebot.registry import NODES

    context = Context(use_sim_time=True)
    return run_nodes(args, context, lambda: [
        *build_nodes(build_description("nav_sim", launch_args), context, NODES),
        *build_filter_servers(sections, context, use_sim_time=True)],
        real_time_factor=None if args.fast else args.rate, owns_sim_clock=True)


def filter_sections(args: argparse.Namespace, resolved: Path) -> list[Any]:
    """The costmap filter servers to start: ``--keepout`` / ``--speed-mask`` added to the
    resolved parameters (rewritten in place), plus those the parameters file names; each
    mask checked against the map. Raises `CliError` naming a mask that cannot be used."""
    import numpy as np
    import yaml

    from eddiebot.maps import MapError, OccupancyMap, load_map, save_map
    from eddiebot.nav.nodes.costmap_filters import (
        MaskError,
        add_filter_masks,
        check_mask,
        filter_server_sections,
    )

    keepout, speed = getattr(args, "keepout", None), getattr(args, "speed_mask", None)
    for path in (keepout, speed):
        if path is not None and not path.is_file():
            raise CliError(f"eddie nav: {path}: no such mask file")
    text = resolved.read_text()
    doc = yaml.safe_load(text) or {}
    source = args.params or default_params()
    base_dir = Path(source).resolve().parent
    nav_map = None
    if args.localization == "amcl":
        try:
            nav_map = load_map(args.map)
        except MapError:
            nav_map = None
    if keepout is None and nav_map is not None and getattr(args, "dashboard", False) and not any(
            s.node_name == "keepout_filter_mask_server"
            for s in filter_server_sections(doc, base_dir)):
        # the dashboard's keepout paint tool needs a keepout mask server: an empty mask
        keepout = save_map(OccupancyMap(np.zeros_like(nav_map.data), nav_map.resolution,
                                        nav_map.origin, nav_map.frame_id),
                           resolved.parent / "keepout_mask")
    add_filter_masks(doc, keepout=keepout, speed=speed)
    sections = filter_server_sections(doc, base_dir=base_dir)
    if sections:
        # the servers run beside the launch: their sections go to a file of their own
        servers = {s.node_name: {"ros__parameters": s.params} for s in sections}
        for name in servers:
            doc.pop(name, None)
            doc.pop("/" + name, None)
        resolved.write_text(text.splitlines()[0] + "\n" + yaml.safe_dump(doc, sort_keys=False))
        filters_file = resolved.parent / "costmap_filters.yaml"
        filters_file.write_text(yaml.safe_dump(servers, sort_keys=False))
        print(f"costmap filter servers: {filters_file}", flush=True)
    for section in sections:
        if section.node_name.endswith("filter_mask_server"):
            try:
                check_mask(section, doc, nav_map)
            except MaskError as exc:
                raise CliError(f"eddie nav: {exc}") from exc
    for section in sections:
        if section.node_name.endswith("filter_mask_server"):
            print(f"filter mask: {section.params['yaml_filename']} on "
                  f"{section.params.get('topic_name', 'filter_mask')}", flush=True)
    return sections


def _launch_args(args: argparse.Namespace, pose: tuple[float, float, float] | None,
                 line: str) -> dict[str, str]:
    params = args.params or default_params()
    run_dir = args.run_dir or Path(tempfile.mkdtemp(prefix="eddie_nav_"))
    resolved = resolve_params(params, run_dir, pose)  # its errors first
    if pose is not None:
        check_initial_pose(args.map, pose)
    print(f"parameters: {resolved}", flush=True)
    if line:
        print(line, flush=True)
    return {"map": str(args.map.resolve()), "params_file": str(resolved),
            "localization": args.localization}


def _run_attached(args: argparse.Namespace) -> int:
    """The navigation alone, attached to the simulator or robot running on this domain."""
    from eddiebot.cli._attach import ATTACH_WAIT_S, graph_cache, odom_pose, wait_for_robot
    from eddiebot.cli._common import connect_transport
    from eddiebot.core.context import Context
    from eddiebot.core.launch import (
        build_nodes,
        find_launch_file,
        parse_launch_file,
    )
    from eddiebot.registry import NODES

    context = Context(use_sim_time=True)
    try:
        if not args.no_transport:
            connect_transport(context)
        wait = ATTACH_WAIT_S if args.attach_timeout is None else args.attach_timeout
        robot = wait_for_robot(context, "eddie nav", wait)
        context.use_sim_time = robot.simulated
        print(f"attached to {robot.what}", flush=True)
        cache = graph_cache(context)
        if cache is not None and any(e.node_name == "slam_toolbox" for e in cache.nodes()):
            print("eddie nav: slam_toolbox runs on this domain and publishes map → odom too; "
                  "stop eddie slam (Ctrl-C saves its map) before navigating", flush=True)
        pose, line = (None, "") if args.localization != "amcl" else initial_pose(
            args, robot, lambda: odom_pose(context))
        launch_args = _launch_args(args, pose, line)
        launch_args["use_sim_time"] = "true" if robot.simulated else "false"
        sections = filter_sections(args, Path(launch_args["params_file"]))
        cloud = robot.simulated and cache is not None and not cache.publishers("/points")
    except BaseException:
        context.shutdown()
        raise

    def build() -> list[Any]:
        from eddiebot.nav.nodes.costmap_filters import build_filter_servers

        nodes = build_nodes(parse_launch_file(find_launch_file("nav"), launch_args), context, NODES)
        nodes += build_filter_servers(sections, context, use_sim_time=robot.simulated)
        if cloud:  # the simulator publishes no /points: the local costmap's source
            nodes += build_nodes(parse_launch_file(find_launch_file("depth_cloud"), {
                "use_sim_time": "true"}), context, NODES)
        return nodes

    return run_nodes(args, context, build, owns_sim_clock=False, connected=True)
