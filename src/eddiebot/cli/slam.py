"""``eddie slam``: 2D SLAM.

    eddie slam --world office [--rate N | --fast] [--seed S] [--dashboard]
    eddie slam replay FILE [--mode sync|async] [-o DIR] [--params YAML] [--strict]
                      [--scan-topic /scan] [--odom-topic /odom]

Without a sub-command it runs the simulator, Eddie's base stack, depthimage_to_laserscan and
the SLAM node (slam_toolbox's parameters from ``config/slam.yaml``), ready for ``eddie
teleop`` in another terminal; ``eddie map save NAME`` saves the map.

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

    parser.add_argument("--world", default="office",
                        help="simulator world for live SLAM (eddie world list), or a world file")
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
    from eddiebot.slam import SlamError
    from eddiebot.slam.replay import check_bag_topics, replay_scans, scans_from_messages
    from eddiebot.viz.bag import BagError, BagReader

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
    from eddiebot.cli._stack import run_stack
    from eddiebot.cli.sim import camera_args

    launch_args = {"world": args.world, "seed": str(args.seed), **camera_args(args.camera)}
    if args.live_params is not None:
        from eddiebot.cli._params import load_params_file

        load_params_file(args.live_params)  # unreadable or not YAML: say so before the build
        launch_args["slam_params"] = str(args.live_params)
    return run_stack(args, "slam", launch_args)


def run(args: argparse.Namespace) -> int:
    if args.slam_command is None:
        return _live(args)
    if args.slam_command == "replay":
        return _replay(args)
    print(f"eddie slam: unknown sub-command {args.slam_command!r}", file=sys.stderr)
    return 2
