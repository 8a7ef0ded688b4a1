"""``eddie slam``: 2D SLAM.

    eddie slam [--world office] [--output DIR] [--session FILE [--start-pose X Y YAW]]
               [--rate N | --fast] [--seed S] [--dashboard]
    eddie slam replay FILE [--mode sync|async] [-o DIR] [--params YAML] [--strict]
                      [--scan-topic /scan] [--odom-topic /odom]

Without a sub-command it runs live SLAM (slam_toolbox's parameters from
``config/slam.yaml``), ready for ``eddie teleop`` in another terminal; ``eddie map save
NAME`` saves the map. Without ``--world`` it attaches to the simulator (``eddie sim``) or
the real robot's bring-up already running on the same ROS_DOMAIN_ID (a ``/clock`` or
``/odom`` publisher within ``--attach-timeout`` seconds, default 10) and runs the SLAM node
alone (launch ``mapping``), following ``/clock``; stopping it leaves the robot running. With
``--world`` it brings its own simulator, Eddie's base stack and depthimage_to_laserscan
(launch ``slam``).

Stopping live SLAM (Ctrl-C, SIGTERM, SIGHUP, or the end of ``--duration``) saves the session
(``session.eslam``) and the map (``map.yaml`` + ``map.pgm``), each file atomically, to
``--output`` (default ``out/slam/<time>/``) and prints where. The map YAML and the
session's sidecar (``session.eslam.anchor.yaml``) record the map → odom transform and the
odometry they belong to. ``--session FILE`` continues a saved session: where the robot is
in it when attached to the same running odometry, else at ``--start-pose X Y YAW`` (which
also overrides the former); the run says which.

``replay`` runs the SLAM core over a CARMEN log (``.clf``, ``.log``, ``.log.gz``; with
slam_toolbox's sample parameters, ``config/slam_defaults.yaml``, unless ``--params`` names
others) or a rosbag2 (a bag directory, MCAP or sqlite3, or a bare ``.mcap`` / ``.db3`` file;
with Eddie's ``config/slam.yaml``) and writes
the map (nav2 ``.pgm`` + ``.yaml`` and a ``.png`` with the trajectory), the trajectory (TUM,
one line per processed scan, stamped with the scan's time) and ``report.md``. From a bag it
reads ``sensor_msgs/LaserScan`` on ``--scan-topic`` (default ``/scan``) and odometry from
``nav_msgs/Odometry`` on ``--odom-topic`` (default ``/odom``; without it, TF
``odom_frame → base_frame`` on ``/tf``), interpolated at each scan's header stamp; the
laser's mount comes from ``/tf_static``.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from eddiebot.slam.config import SlamConfig
    from eddiebot.slam.replay import ReplayResult

__all__ = ["HELP", "add_arguments", "is_bag", "replay_bag", "run"]

HELP = "2D SLAM: live in the simulator, or replay a CARMEN log or rosbag2 into a map"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from eddiebot.cli._stack import add_run_arguments

    parser.add_argument("--world", default=None,
                        help="bring a simulator in this world (eddie world list, or a world "
                        "file); without it, attach to the simulator or robot already running")
    parser.add_argument("--output", dest="live_output", type=Path, default=None,
                        help="where stopping saves the session and the map "
                        "(default out/slam/<time>/)")
    parser.add_argument("--session", dest="live_session", type=Path, default=None,
                        help="continue this saved session (session.eslam)")
    parser.add_argument("--start-pose", type=float, nargs=3, metavar=("X", "Y", "YAW"),
                        default=None, help="where the robot is in --session's map frame")
    parser.add_argument("--attach-timeout", type=float, default=None,
                        help="without --world: how long to wait for a simulator or robot, s "
                        "(default 10)")
    parser.add_argument("--camera", default="320x240@10",
                        help="Kinect resolution and rate, WxH@HZ (default 320x240@10)")
    parser.add_argument("--params", dest="live_params", type=Path, default=None,
                        help="slam_toolbox parameter file (default: the package's config/slam.yaml)")
    add_run_arguments(parser)
    sub = parser.add_subparsers(dest="slam_command")
    rep = sub.add_parser(
        "replay", help="run SLAM over a CARMEN log (.clf/.log/.log.gz) or a rosbag2 (MCAP/sqlite3)"
    )
    rep.add_argument(
        "file", type=Path, help="CARMEN log, or rosbag2 directory / .mcap / .db3 file"
    )
    rep.add_argument(
        "--mode",
        choices=("sync", "async"),
        default="sync",
        help="sync: every scan; async: drop scans that arrive while busy (default sync)",
    )
    rep.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        help="output folder (default out/slam/<log name>)",
    )
    rep.add_argument(
        "--params",
        type=Path,
        default=None,
        help="ROS 2 parameter file with a slam_toolbox section (default: config/slam.yaml, "
        "Eddie's, for a rosbag2; config/slam_defaults.yaml, slam_toolbox's sample values, "
        "for a CARMEN lidar log)",
    )
    rep.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME:=VALUE",
        help="override one parameter (repeatable), e.g. --set minimum_travel_distance:=0.2",
    )
    rep.add_argument("--strict", action="store_true", help="stop at the first malformed log line")
    rep.add_argument(
        "--session", type=Path, default=None, help="also save the session (graph + scans) here"
    )
    rep.add_argument("--no-progress", action="store_true", help="no progress bar")
    rep.add_argument(
        "--scan-topic",
        default="/scan",
        help="rosbag2: sensor_msgs/LaserScan topic (default /scan)",
    )
    rep.add_argument(
        "--odom-topic",
        default=None,
        help="rosbag2: nav_msgs/Odometry topic, or /tf for TF odom_frame → base_frame "
        "(default /odom if the bag has it, else /tf)",
    )


def _overrides(items: list[str]) -> dict[str, object]:
    import yaml

    out: dict[str, object] = {}
    for item in items:
        if ":=" not in item:
            raise ValueError(f"--set expects NAME:=VALUE, got {item!r}")
        key, value = item.split(":=", 1)
        out[key.strip()] = yaml.safe_load(value)
    return out


def _default_params(name: str = "slam.yaml") -> Path | None:
    here = Path(__file__).resolve()
    for parent in here.parents:
        candidate = parent / "config" / name
        if candidate.is_file():
            return candidate
    return None


def replay_params(log: Path) -> Path | None:
    """The parameter file `eddie slam replay` uses without ``--params``: Eddie's
    (``config/slam.yaml``, tuned for the Kinect-made 57° scan and Eddie's encoders) for a
    rosbag2, slam_toolbox's sample values (``config/slam_defaults.yaml``, tuned for 180–360°
    lidars) for a CARMEN log."""
    return _default_params("slam.yaml" if is_bag(log) else "slam_defaults.yaml")


def is_bag(path: Path) -> bool:
    """A rosbag2 directory or a bare .mcap / .db3 file (anything else: a CARMEN log)."""
    return path.is_dir() or path.suffix in (".mcap", ".db3")


def replay_bag(
    path: Path,
    config: SlamConfig,
    *,
    mode: str = "sync",
    scan_topic: str = "/scan",
    odom_topic: str | None = None,
    progress_factory: Callable[[int], Callable[[int], None]] | None = None,
) -> ReplayResult:
    """Read a rosbag2 with the project's bag reader and replay its scans (`ReplayResult`).

    Raises `eddiebot.slam.SlamError` (`BagInputError` for a missing or mistyped topic).
    """
    from eddiebot.bag import BagError, BagReader
    from eddiebot.slam import SlamError
    from eddiebot.slam.replay import check_bag_topics, replay_scans, scans_from_messages

    try:
        reader = BagReader(path)
    except BagError as exc:
        raise SlamError(str(exc)) from exc
    with reader:
        types = {c.topic: c.type_name for c in reader.connections}
        topics = check_bag_topics(
            types, scan_topic=scan_topic, odom_topic=odom_topic, source=str(path)
        )
        messages = (
            (m.topic, m.timestamp, m.decode()) for m in reader.messages(topics.all)
        )
        try:
            log = scans_from_messages(
                messages, topics, odom_frame=config.odom_frame, base_frame=config.base_frame
            )
        except SlamError as exc:
            raise type(exc)(f"{path}: {exc}") from exc
        problems = [str(p) for p in reader.problems]
    progress = progress_factory(len(log.scans)) if progress_factory is not None else None
    result = replay_scans(
        log.scans,
        log.odometry,
        config,
        mode=mode,
        sensor_offset=log.sensor_offset,
        source=str(path),
        progress=progress,
    )
    x, y, th = (float(v) for v in log.sensor_offset)
    result.notes += [
        f"rosbag2 ({reader.storage}): {log.scan_messages} scans on `{topics.scan}` "
        f"(frame `{log.scan_frame}`), {log.odometry_samples} odometry samples from "
        f"{log.odometry_source}",
        f"laser mount in `{config.base_frame}`: x {x:.3f} m, y {y:.3f} m, yaw {th:.3f} rad",
    ]
    for w in (*log.warnings, *problems):
        result.warnings["bag_input"] += 1
        result.first_warnings.append(w)
    return result


def _replay(args: argparse.Namespace) -> int:
    from eddiebot.slam import SlamError, load_slam_config, save_session
    from eddiebot.slam.replay import replay_log, write_outputs

    try:
        params = args.params or replay_params(args.file)
        config = load_slam_config(params, overrides=_overrides(args.set))
        print(f"parameters: {params}", file=sys.stderr)
    except (SlamError, ValueError) as exc:
        print(f"eddie slam replay: {exc}", file=sys.stderr)
        return 2
    progress_factory: Callable[[int], Callable[[int], None]] | None = None
    bar = None
    if not args.no_progress:
        from tqdm import tqdm

        def progress_factory(total: int) -> Callable[[int], None]:
            nonlocal bar
            bar = tqdm(total=total, unit="scan", desc=args.file.name, file=sys.stderr)
            return bar.update

    if not args.file.exists():
        print(f"eddie slam replay: {args.file} does not exist", file=sys.stderr)
        return 1
    try:
        if is_bag(args.file):
            result = replay_bag(
                args.file,
                config,
                mode=args.mode,
                scan_topic=args.scan_topic,
                odom_topic=args.odom_topic,
                progress_factory=progress_factory,
            )
        else:
            result = replay_log(
                args.file,
                config,
                mode=args.mode,
                strict=args.strict,
                progress_factory=progress_factory,
            )
    except SlamError as exc:
        print(f"eddie slam replay: {exc}", file=sys.stderr)
        return 1
    finally:
        if bar is not None:
            bar.close()
    name = args.file.resolve().name.split(".")[0]
    out_dir = args.output or Path("out") / "slam" / name
    paths = write_outputs(result, out_dir)
    if args.session is not None:
        save_session(result.core, args.session)
    core = result.core
    print(
        f"{result.scans} scans, {len(core.nodes)} processed, {len(core.loop_closures)} loops closed, "
        f"{result.cpu_s:.1f} s CPU ({result.realtime_factor:.1f}x real time)"
    )
    for key, path in paths.items():
        print(f"{key:10s} {path}")
    return 0


def _live(args: argparse.Namespace) -> int:
    import time as _time

    from eddiebot.cli._attach import ATTACH_WAIT_S, odom_pose, wait_for_robot
    from eddiebot.cli._common import connect_transport
    from eddiebot.cli._stack import check_world, run_nodes
    from eddiebot.cli.errors import CliError
    from eddiebot.cli.sim import camera_args
    from eddiebot.core.context import Context
    from eddiebot.core.launch import (
        build_nodes,
        find_launch_file,
        parse_launch_file,
    )
    from eddiebot.registry import NODES
    from eddiebot.slam.node import SlamNode

    if args.world is not None:
        check_world(args.world)
    source = args.live_params or _default_params()
    if source is None:
        raise CliError("eddie slam: config/slam.yaml not found; give --params")
    from eddiebot.cli._params import load_params_file

    doc, _ = load_params_file(source)  # unreadable or not YAML: say so before the build
    anchor = _session_anchor(args.live_session) if args.live_session is not None else None
    out_dir = args.live_output or Path("out") / "slam" / _time.strftime("%Y%m%d-%H%M%S")
    context = Context(use_sim_time=True)
    overrides: dict[str, object] = {}
    robot = None
    try:
        if args.world is None:
            if not args.no_transport:
                connect_transport(context)
            wait = ATTACH_WAIT_S if args.attach_timeout is None else args.attach_timeout
            robot = wait_for_robot(context, "eddie slam", wait)
            context.use_sim_time = robot.simulated
            print(f"attached to {robot.what}", flush=True)
            if robot.odom_session:
                overrides["odom_session"] = robot.odom_session
        if args.live_session is not None:
            pose, why = _start_pose(args, anchor, robot, lambda: odom_pose(context))
            overrides["map_file_name"] = str(args.live_session.resolve())
            overrides["map_start_pose"] = [float(v) for v in pose]
            print(f"continuing session {args.live_session} at ({pose[0]:.2f}, {pose[1]:.2f}, "
                  f"{pose[2]:.2f}): {why}", flush=True)
    except BaseException:
        context.shutdown()
        raise
    slam: list[SlamNode] = []

    def build() -> list:  # type: ignore[type-arg]
        if robot is None:  # its own odometry: named after this process's graph session
            overrides["odom_session"] = _own_odom_session(context)
        params = _write_params(doc, source, out_dir, overrides)
        if robot is None:
            launch_args = {"world": args.world, "seed": str(args.seed),
                           **camera_args(args.camera), "slam_params": str(params)}
            desc = parse_launch_file(find_launch_file("slam"), launch_args)
        else:
            desc = parse_launch_file(find_launch_file("mapping"), {
                "slam_params": str(params),
                "use_sim_time": "true" if robot.simulated else "false"})
        nodes = build_nodes(desc, context, NODES)
        slam.extend(n for n in nodes if isinstance(n, SlamNode))
        return nodes

    try:
        if robot is None:
            return run_nodes(args, context, build, owns_sim_clock=True,
                             real_time_factor=None if args.fast else args.rate)
        return run_nodes(args, context, build, owns_sim_clock=False, connected=True)
    finally:
        if slam:
            _save_outputs(slam[0], out_dir)


def _session_anchor(session: Path) -> object:
    """The session's sidecar anchor (`eddiebot.maps.MapAnchor`), or None."""
    from eddiebot.cli.errors import CliError
    from eddiebot.maps import read_anchor

    if not session.is_file():
        raise CliError(f"eddie slam: --session {session}: no such file")
    side = session.with_name(session.name + ".anchor.yaml")
    return read_anchor(side) if side.is_file() else None


def _start_pose(args: argparse.Namespace, anchor: object, robot: object,
                read_odom: Callable[[], tuple[float, float, float] | None]
                ) -> tuple[tuple[float, float, float], str]:
    """Where the robot is in ``--session``'s map, and why it is known."""
    from eddiebot.cli.errors import CliError
    from eddiebot.geometry import se2_compose

    if args.start_pose is not None:
        return tuple(args.start_pose), "--start-pose"  # type: ignore[return-value]
    session = getattr(robot, "odom_session", None)
    saved = getattr(anchor, "odom_session", None)
    if session is not None and saved == session:
        odom = read_odom()
        if odom is not None:
            x, y, th = (float(v) for v in se2_compose(anchor.map_to_odom, odom))  # type: ignore[attr-defined]
            return (x, y, th), "where the robot is in it (the same running odometry)"
    why = ("the session was saved on an odometry that no longer runs" if anchor is not None
           else "the session has no anchor file beside it")
    raise CliError(f"eddie slam: cannot know where the robot is in {args.live_session} ({why}); "
                   "give --start-pose X Y YAW (0 0 0 if it stands where that session began)")


def _own_odom_session(context: object) -> str:
    """This process's odometry, named by its graph session (random without transport)."""
    import uuid

    for transport in getattr(context, "transports", []):
        graph = getattr(transport, "graph", None)
        if graph is not None:
            return f"{graph()['zid']}/eddie_odom"
    return f"local-{uuid.uuid4().hex}/eddie_odom"


def _write_params(doc: object, source: Path, out_dir: Path, overrides: dict[str, object]) -> Path:
    """``<out>/slam_params.yaml``: the parameters file with ``overrides`` for slam_toolbox."""
    import yaml

    from eddiebot.cli.errors import ParamsFileError

    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise ParamsFileError(f"{source}: top level must map node names to "
                              "{ros__parameters: {...}}")
    merged = dict(doc)
    if overrides:
        section = dict(merged.get("slam_toolbox") or {})
        params = dict(section.get("ros__parameters") or {})
        params.update(overrides)
        section["ros__parameters"] = params
        merged["slam_toolbox"] = section
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / "slam_params.yaml"
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(f"# resolved from {source}\n" + yaml.safe_dump(merged, sort_keys=False))
    tmp.replace(out)
    return out


def _save_outputs(node: object, out_dir: Path) -> None:
    """Save the session and the map; say where (a closed terminal is no reason to fail)."""
    try:
        paths = node.save_outputs(out_dir)  # type: ignore[attr-defined]
    except Exception as exc:
        with contextlib.suppress(OSError):
            print(f"eddie slam: could not save the session to {out_dir}: {exc}", file=sys.stderr)
        return
    names = ", ".join(p.name for p in paths.values())
    with contextlib.suppress(OSError):  # SIGHUP: the terminal may be gone
        print(f"saved the session and the map to {out_dir}/ ({names})", flush=True)


def run(args: argparse.Namespace) -> int:
    if args.slam_command is None:
        return _live(args)
    if args.slam_command == "replay":
        return _replay(args)
    print(f"eddie slam: unknown sub-command {args.slam_command!r}", file=sys.stderr)
    return 2
