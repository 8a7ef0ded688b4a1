"""``eddie vslam``: RGB-D graph SLAM (rtabmap's role).

    eddie vslam [--world office | --attach-timeout S] [--rate N | --fast] [--seed S]
                [--dashboard] [--database FILE] [--delete_db_on_start] [--localization]
                [--map-topic /rtabmap/map]
    eddie vslam sim [--world office] ...
    eddie vslam replay DIR|BAG [-o OUT] [--max-frames N] [--set Group/Name=VALUE ...]
                      [--depth-scale UNITS_PER_M] [--fx FX --fy FY --cx CX --cy CY |
                       --camera-info FILE.yaml]
    eddie vslam loops DIR -o FILE.csv
    eddie vslam db info FILE
    eddie vslam db export FILE [--ply OUT.ply] [--mesh OUT.ply|OUT.obj] [--poses OUT.tum]
                          [--voxel M] [--decimation N] [--max_range M] [--poisson_depth N] ...
                          (rtabmap-export's options; one file per unmerged map; --mesh needs
                          the `mesh` extra, Open3D)

With ``--world`` (or ``sim``, default world office) it runs the simulator, Eddie's base stack
and the ``rtabmap`` node with the report's parameters (``launch/vslam.yaml``). Without
``--world`` it attaches to the simulator (``eddie sim``) or the real robot's bring-up already
running on the same ROS_DOMAIN_ID (a ``/clock`` or ``/odom`` publisher within
``--attach-timeout`` seconds, default 10; else one line and exit status 2) and runs the
``rtabmap`` node alone (``launch/rgbd_mapping.yaml``), following ``/clock`` when there is one
(without a ``/scan`` publisher it maps without the scan); stopping it leaves the robot running.
The grid is published on ``/map`` (``--map-topic``). ``replay`` runs visual odometry + SLAM over a TUM RGB-D folder, or the
``rtabmap`` node (the report's parameters) over a rosbag2 of our topics (``/image_raw``,
``/depth/image_raw``, camera infos, ``/tf``, ``/tf_static``, ``/odom``, ``/scan``), writing
``rtabmap.db``, ``poses.txt`` (every input colour frame), ``keyframes.txt``, ``odom.txt``
(TUM, the colour camera's optical frame) and ``report.json`` into OUT. A TUM
folder's intrinsics come from ``--fx/--fy/--cx/--cy`` or ``--camera-info`` (ROS camera_info
YAML), else from its name (freiburg1/2/3), else 525/525/319.5/239.5; its depth PNGs have
``--depth-scale`` units per metre (default TUM's 5000; ICL-NUIM 1000). A bag's come from its
camera_info and depth encoding. Depth whose median is not 0.3–10 m is refused. ``loops`` runs appearance-only loop detection over an image folder and writes
``query,match,score`` rows. ``db`` inspects and exports a session database.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

__all__ = ["HELP", "add_arguments", "run"]

HELP = "RGB-D SLAM: live, replay, loops, database tools"

#: The report's rtabmap parameters (eddiebot rtabmap.launch.py), used for rosbag2 replays of
#: Eddie's topics unless overridden with --set.
REPORT_PARAMETERS = {
    "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "RGBD/ProximityBySpace": "false",
    "RGBD/AngularUpdate": "0.01", "RGBD/LinearUpdate": "0.01",
    "RGBD/OptimizeFromGraphEnd": "false",
}


def _add_sim_arguments(parser: argparse.ArgumentParser, world: str | None = None) -> None:
    from eddiebot.cli._stack import add_run_arguments

    if world is None:
        parser.add_argument("--world", default=None,
                            help="bring a simulator in this world (eddie world list, or a "
                            "world file); without it, attach to the simulator or robot "
                            "already running")
        parser.add_argument("--attach-timeout", type=float, default=None,
                            help="without --world: how long to wait for a simulator or "
                            "robot, s (default 10)")
    else:
        parser.add_argument("--world", default=world,
                            help="simulator world (eddie world list), or a world file")
    parser.add_argument("--camera", default="320x240@10",
                        help="Kinect resolution and rate, WxH@HZ (default 320x240@10)")
    parser.add_argument("--database", default="~/.local/share/eddiebot/rtabmap.db",
                        help="session database (default ~/.local/share/eddiebot/rtabmap.db)")
    parser.add_argument("--delete_db_on_start", "--delete-db-on-start", action="store_true",
                        help="erase the database before starting (rtabmap's -d); by default "
                        "its map is continued in a new session")
    parser.add_argument("--keep-database", action="store_true",
                        help=argparse.SUPPRESS)  # the default now; kept for old scripts
    parser.add_argument("--localization", action="store_true",
                        help="localize in the database's map (Mem/IncrementalMemory false)")
    parser.add_argument("--map-topic", default="/map",
                        help="occupancy grid topic (default /map: vSLAM is the mapper; "
                             "/rtabmap/map beside 2D SLAM)")
    parser.add_argument("--rtabmap-args", default="",
                        help="upstream-style arguments, e.g. \"--Vis/MinInliers 15\"")
    add_run_arguments(parser)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    _add_sim_arguments(parser)
    sub = parser.add_subparsers(dest="vslam_command")
    sim = sub.add_parser("sim", help="simulator + vSLAM (eddie vslam --world office)")
    _add_sim_arguments(sim, world="office")
    rep = sub.add_parser("replay", help="replay a TUM RGB-D folder or a rosbag2 through vSLAM")
    rep.add_argument("source", type=Path, help="TUM RGB-D folder or rosbag2 (folder/.mcap/.db3)")
    rep.add_argument("-o", "--output", type=Path, default=None,
                     help="output folder (default out/vslam/<name>)")
    rep.add_argument("--max-frames", type=int, default=0, help="stop after N frames (TUM)")
    rep.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE",
                     help="RTAB-Map parameter (repeatable), e.g. --set Reg/Force3DoF=true")
    rep.add_argument("--depth-scale", type=float, default=None, metavar="UNITS_PER_M",
                     help="depth PNG units per metre (TUM folder; default 5000, ICL-NUIM 1000)")
    for name in ("fx", "fy", "cx", "cy"):
        rep.add_argument(f"--{name}", type=float, default=None,
                         help=f"intrinsic {name} in pixels (TUM folder; give all four)")
    rep.add_argument("--camera-info", type=Path, default=None, metavar="FILE.yaml",
                     help="intrinsics from a ROS camera_info YAML (TUM folder)")
    loops = sub.add_parser("loops", help="appearance-only loop detection over an image folder")
    loops.add_argument("folder", type=Path, help="folder of images (numeric order)")
    loops.add_argument("-o", "--output", type=Path, required=True, help="CSV to write")
    loops.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE")
    db = sub.add_parser("db", help="session database tools")
    dbsub = db.add_subparsers(dest="db_command")
    info = dbsub.add_parser("info", help="summary of a session database")
    info.add_argument("file", type=Path)
    info.add_argument("--json", action="store_true", help="print JSON")
    exp = dbsub.add_parser("export", help="export cloud (PLY) and/or optimised poses (TUM)")
    exp.add_argument("file", type=Path)
    exp.add_argument("--ply", type=Path, default=None, help="assembled point cloud, map frame")
    exp.add_argument("--poses", type=Path, default=None, help="optimised node poses, TUM format")
    # cloud and mesh options: rtabmap-export's names (underscores) and defaults
    exp.add_argument("--voxel", type=float, default=0.01, metavar="M",
                     help="voxel size of the cloud (m, default 0.01; 0 = none)")
    exp.add_argument("--decimation", type=int, default=4, metavar="N",
                     help="depth image decimation before making the clouds (default 4)")
    exp.add_argument("--min_range", "--min-range", dest="min_range", type=float, default=0.0,
                     metavar="M", help="minimum range of the clouds (m, default 0)")
    exp.add_argument("--max_range", "--max-range", dest="max_range", type=float, default=4.0,
                     metavar="M", help="maximum range of the clouds (m, default 4; 0 = none)")
    exp.add_argument("--mesh", type=Path, default=None, metavar="OUT.ply|OUT.obj",
                     help="coloured Poisson mesh of the cloud, map frame (needs Open3D: "
                          "pip install 'eddiebot[mesh]')")
    exp.add_argument("--poisson_depth", "--poisson-depth", dest="poisson_depth", type=int,
                     default=0, metavar="N",
                     help="Poisson depth (default 0: from --poisson_size)")
    exp.add_argument("--poisson_size", "--poisson-size", dest="poisson_size", type=float,
                     default=0.03, metavar="M",
                     help="target polygon size choosing the Poisson depth (m, default 0.03)")
    exp.add_argument("--max_polygons", "--max-polygons", dest="max_polygons", type=int,
                     default=300_000, metavar="N",
                     help="maximum polygons of the mesh (default 300000; 0 = no limit)")
    exp.add_argument("--color_radius", "--color-radius", dest="color_radius", type=float,
                     default=0.05, metavar="M",
                     help="radius colouring the mesh from the cloud; polygons with no cloud "
                          "point within it are removed (m, default 0.05; 0 = nearest; -1 = off)")
    exp.add_argument("--min_cluster", "--min-cluster", dest="min_cluster", type=int,
                     default=200, metavar="N",
                     help="drop mesh pieces of fewer polygons (default 200; -1 = largest only)")

def _settings(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set expects Group/Name=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def run(args: argparse.Namespace) -> int:
    cmd = getattr(args, "vslam_command", None)
    try:
        if cmd in (None, "sim"):
            return _sim(args)
        if cmd == "replay":
            return _replay(args)
        if cmd == "loops":
            return _loops(args)
        if cmd == "db":
            if args.db_command == "info":
                return _db_info(args)
            if args.db_command == "export":
                return _db_export(args)
            print("eddie vslam db: choose info or export", file=sys.stderr)
            return 2
    except ValueError as exc:
        print(f"eddie vslam: {exc}", file=sys.stderr)
        return 2
    print(f"eddie vslam: unknown command {cmd!r}", file=sys.stderr)
    return 2


# -- sim ------------------------------------------------------------------------------------
def _sim(args: argparse.Namespace) -> int:
    from eddiebot.cli._stack import run_stack

    try:
        size, rate = args.camera.split("@")
        width, height = size.lower().split("x")
        float(rate)
        int(width)
        int(height)
    except ValueError:
        print(f"eddie vslam: --camera expects WxH@HZ, got {args.camera!r}", file=sys.stderr)
        return 2
    from eddiebot.vslam.database import is_session_database
    from eddiebot.vslam.errors import DatabaseError

    database = Path(args.database).expanduser()
    try:
        foreign = database.exists() and not is_session_database(database)
    except DatabaseError as exc:
        print(f"eddie vslam: {exc}", file=sys.stderr)
        return 1
    if foreign:
        print(f"eddie vslam: {database} is not an eddiebot vslam session database; not "
              "touching it: choose another file with --database", file=sys.stderr)
        return 1
    delete = bool(args.delete_db_on_start) and not args.localization
    launch_args = {
        "database_path": args.database,
        "delete_db_on_start": "true" if delete else "false",
        "localization": "true" if args.localization else "false",
        "map_topic": args.map_topic, "rtabmap_args": args.rtabmap_args,
    }
    if args.world is None:
        return _run_attached(args, launch_args)
    launch_args.update({"world": args.world, "seed": str(args.seed), "camera_width": width,
                        "camera_height": height, "camera_rate": rate})
    return run_stack(args, "vslam", launch_args)


#: Once attached, how long a ``/scan`` publisher of the robot may take to show, s.
_SCAN_GRACE_S = 1.0


def _run_attached(args: argparse.Namespace, launch_args: dict[str, str]) -> int:
    """The ``rtabmap`` node alone, attached to the simulator or robot on this domain."""
    from eddiebot.cli._attach import ATTACH_WAIT_S, graph_cache, wait_for_robot
    from eddiebot.cli._common import connect_transport
    from eddiebot.cli._stack import run_nodes
    from eddiebot.core.context import Context
    from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
    from eddiebot.registry import NODES

    context = Context(use_sim_time=True)
    try:
        if not args.no_transport:
            connect_transport(context)
        wait = ATTACH_WAIT_S if args.attach_timeout is None else args.attach_timeout
        robot = wait_for_robot(context, "eddie vslam", wait)
        context.use_sim_time = robot.simulated
        cache = graph_cache(context)
        scan = cache is not None and cache.wait_for(lambda: bool(cache.publishers("/scan")),
                                                     _SCAN_GRACE_S)
        print(f"attached to {robot.what}" + ("" if scan else " (no /scan: mapping without it)"),
              flush=True)
    except BaseException:
        context.shutdown()
        raise
    launch_args = {**launch_args, "use_sim_time": "true" if robot.simulated else "false",
                   "subscribe_scan": "true" if scan else "false"}

    def build() -> list[Any]:
        desc = parse_launch_file(find_launch_file("rgbd_mapping"), launch_args)
        return build_nodes(desc, context, NODES)

    return run_nodes(args, context, build, owns_sim_clock=False, connected=True)


# -- replay ---------------------------------------------------------------------------------
def _is_bag(path: Path) -> bool:
    if path.suffix in (".mcap", ".db3"):
        return True
    return path.is_dir() and ((path / "metadata.yaml").exists()
                              or any(path.glob("*.mcap")) or any(path.glob("*.db3")))


def _replay(args: argparse.Namespace) -> int:
    from eddiebot.vslam.errors import VslamError

    src: Path = args.source
    if not src.exists():
        print(f"eddie vslam replay: {src}: no such file or folder", file=sys.stderr)
        return 2
    out = args.output or Path("out") / "vslam" / src.name.split(".")[0]
    params = _settings(args.set)
    from eddiebot.vslam.features import retain_freed_memory

    retain_freed_memory()  # visual odometry runs in this process: no page faults per frame
    try:
        if _is_bag(src):
            given = [f"--{n.replace('_', '-')}" for n in
                     ("depth_scale", "fx", "fy", "cx", "cy", "camera_info")
                     if getattr(args, n, None) is not None]
            if given:
                raise ValueError(f"{' '.join(given)}: a rosbag2 replay takes the intrinsics "
                                 "from its camera_info and the depth units from its encoding")
            summary = replay_bag(src, out, params)
        else:
            from dataclasses import asdict

            from eddiebot.vslam.replay import replay_tum

            setup = _tum_setup(src, args)
            summary = asdict(replay_tum(src, out, params or None, max_frames=args.max_frames,
                                        setup=setup))
    except (VslamError, OSError) as exc:
        print(f"eddie vslam replay: {exc}", file=sys.stderr)
        return 1
    for k, v in summary.items():
        print(f"{k:16s} {v}")
    print(f"wrote {out}")
    return 0


def _tum_setup(folder: Path, args: argparse.Namespace) -> Any:
    """The replay's camera and depth units from --fx/--fy/--cx/--cy, --camera-info and
    --depth-scale, with where each came from."""
    import yaml

    from eddiebot.vslam.camera import CameraIntrinsics, camera_info_from_yaml
    from eddiebot.vslam.replay import tum_camera_setup
    from eddiebot.vslam.tum import read_tum_sequence

    values = [getattr(args, n, None) for n in ("fx", "fy", "cx", "cy")]
    info_file = getattr(args, "camera_info", None)
    camera = None
    source = ""
    if any(v is not None for v in values):
        if info_file is not None:
            raise ValueError("give either --fx/--fy/--cx/--cy or --camera-info, not both")
        if any(v is None for v in values):
            raise ValueError("--fx, --fy, --cx and --cy go together: give all four")
        size = read_tum_sequence(folder).camera
        fx, fy, cx, cy = (float(v) for v in values if v is not None)
        if fx <= 0 or fy <= 0:
            raise ValueError(f"--fx/--fy must be > 0, got {fx}, {fy}")
        camera = CameraIntrinsics(fx, fy, cx, cy, size.width, size.height)
        source = "--fx/--fy/--cx/--cy"
    elif info_file is not None:
        try:
            data = yaml.safe_load(Path(info_file).read_text())
        except yaml.YAMLError as exc:
            raise ValueError(f"--camera-info {info_file}: not YAML ({exc})") from exc
        if not isinstance(data, dict):
            raise ValueError(f"--camera-info {info_file}: not a camera_info YAML mapping")
        try:
            camera = camera_info_from_yaml(data)
        except ValueError as exc:
            raise ValueError(f"--camera-info {info_file}: {exc}") from exc
        source = f"--camera-info {info_file}"
    scale = getattr(args, "depth_scale", None)
    return tum_camera_setup(folder, camera, source, scale,
                            "--depth-scale" if scale is not None else "")


def _bag_camera(reader: Any, present: set[str]) -> dict[str, Any]:
    """The intrinsics (first /camera_info) and depth units (first depth image's encoding) a
    bag replay uses; refuses depth whose median is implausible."""
    import numpy as np

    from eddiebot.perception._image import image_to_array
    from eddiebot.perception.errors import ImageSizeError, UnsupportedEncodingError
    from eddiebot.vslam.camera import check_depth_plausible, depth_to_meters

    out: dict[str, Any] = {"intrinsics": None, "intrinsics_source": "none: no /camera_info",
                           "depth_scale": None, "depth_scale_source": "none: no depth"}
    wanted = [t for t in ("/camera_info", "/depth/image_raw") if t in present]
    for msg in reader.messages(topics=wanted):
        obj = msg.decode()
        if msg.topic == "/camera_info" and out["intrinsics"] is None:
            k = np.asarray(obj.k, dtype=np.float64)
            out["intrinsics"] = [float(k[0]), float(k[4]), float(k[2]), float(k[5]),
                                 int(obj.width), int(obj.height)]
            out["intrinsics_source"] = "the bag's /camera_info"
        elif msg.topic == "/depth/image_raw" and out["depth_scale"] is None:
            try:
                raw = image_to_array(obj, ("16UC1", "32FC1"))
            except (UnsupportedEncodingError, ImageSizeError):
                continue  # the node skips such images too
            scale = 1000.0 if raw.dtype == np.uint16 else 1.0
            out["depth_scale"] = scale
            out["depth_scale_source"] = f"the bag's depth encoding {obj.encoding}"
            check_depth_plausible(depth_to_meters(raw), scale,
                                  "the bag's depth images are not in ROS units (16UC1 mm, "
                                  "32FC1 m)")
        if out["intrinsics"] is not None and out["depth_scale"] is not None:
            break
    return out


def replay_bag(bag: Path, out_dir: Path, parameters: dict[str, str] | None = None
               ) -> dict[str, Any]:
    """Run the ``rtabmap`` node over a rosbag2 of our topics on the bag's clock; writes into
    ``out_dir`` (poses TUM, of the colour camera's optical frame as in a TUM replay):

    - ``poses.txt``: a pose for every input colour frame in the map frame (its key frame's
      optimised pose composed with the TF odometry since; a frame without odometry or
      skipped as bad input is counted lost and keeps the previous pose);
    - ``keyframes.txt``: the key frames' optimised poses; ``odom.txt``: the odometry (odom
      frame) of the frames that had it;
    - ``rtabmap.db`` and ``report.json`` (appearance loop closures, proximity links and
      rejected hypotheses counted separately)."""
    import numpy as np

    from eddiebot.bag import BagReader
    from eddiebot.core.context import Context
    from eddiebot.core.executors import SingleThreadedExecutor
    from eddiebot.core.node import Node
    from eddiebot.core.qos import qos_profile_latched
    from eddiebot.vslam.frame_track import FrameTrack
    from eddiebot.vslam.node import RtabmapNode
    from eddiebot.vslam.tum import write_tum_trajectory

    out_dir.mkdir(parents=True, exist_ok=True)
    topics = ["/image_raw", "/camera_info", "/depth/image_raw", "/depth/camera_info", "/tf",
              "/tf_static", "/odom", "/scan"]
    context = Context(use_sim_time=True)
    with BagReader(bag) as reader:
        present = {c.topic for c in reader.connections}
        camera = _bag_camera(reader, present)
        overrides: dict[str, Any] = {
            "use_sim_time": True, "database_path": str(out_dir / "rtabmap.db"),
            "delete_db_on_start": True, "subscribe_scan": "/scan" in present,
        }
        overrides.update(REPORT_PARAMETERS)
        overrides.update(parameters or {})
        slam = RtabmapNode(context=context, parameter_overrides=overrides)
        track = slam.frame_track = FrameTrack()
        player = Node("vslam_bag_player", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(slam)
        executor.add_node(player)
        pubs: dict[str, Any] = {}
        n = colour = 0
        for msg in reader.messages(topics=[t for t in topics if t in present]):
            obj = msg.decode()
            if msg.topic not in pubs:
                qos = qos_profile_latched if msg.topic == "/tf_static" else 50
                pubs[msg.topic] = player.create_publisher(type(obj), msg.topic, qos)
            if msg.timestamp > context.sim_clock.now_ns():
                executor.spin_until(msg.timestamp)
            pubs[msg.topic].publish(obj)
            executor.spin_until_idle()
            n += 1
            colour += msg.topic == "/image_raw"
        # past wait_for_transform: every frame still queued is processed or counted lost
        executor.spin_for(max(1.0, 2 * slam.wait_for_transform))
    optimized, _ = slam.core.graph()
    maps = max(1, len(slam.core.map_frames()))
    lt = slam.camera_transform if slam.camera_transform is not None else np.eye(4)
    stamps, poses = track.frame_poses(optimized)
    write_tum_trajectory(out_dir / "poses.txt", stamps, [p @ lt for p in poses])
    key_stamps, key_poses = track.keyframe_poses(optimized)
    write_tum_trajectory(out_dir / "keyframes.txt", key_stamps, [p @ lt for p in key_poses])
    odom = sorted((t, o) for t, o in track.records if o is not None)
    write_tum_trajectory(out_dir / "odom.txt", [t for t, _ in odom], [o @ lt for _, o in odom])
    # input colour frames the synchroniser never released (no depth after them) are lost too
    lost = track.lost + max(0, colour - track.frames)
    summary = {"messages": n, "frames": colour, "frames_processed": slam.frames_processed,
               "poses": len(stamps), "nodes": len(key_stamps), "lost_frames": lost,
               "loop_closures": track.loop_closures, "proximity_links": track.proximity_links,
               "rejected_hypotheses": track.rejected_hypotheses,
               "odometry_resets": track.new_maps, "map_merges": track.map_merges,
               "maps": maps, "database": str(out_dir / "rtabmap.db"), **camera}
    slam.destroy_node()
    player.destroy_node()
    context.shutdown()
    (out_dir / "report.json").write_text(json.dumps(summary, indent=2))
    return summary


# -- loops ----------------------------------------------------------------------------------
def _loops(args: argparse.Namespace) -> int:
    from eddiebot.vslam.errors import VslamError
    from eddiebot.vslam.loops import detect_loops, write_loop_rows

    try:
        rows = detect_loops(args.folder, _settings(args.set) or None)
    except VslamError as exc:
        print(f"eddie vslam loops: {exc}", file=sys.stderr)
        return 1
    write_loop_rows(rows, args.output)
    found = sum(1 for r in rows if r[1])
    print(f"{len(rows)} images, {found} loop closures; wrote {args.output}")
    return 0


# -- db -------------------------------------------------------------------------------------
def database_info(path: Path) -> dict[str, Any]:
    """Counts, sessions, link types, graph length and parameters of a session database."""
    import sqlite3
    from collections import Counter

    import numpy as np

    from eddiebot.vslam.database import SessionDatabase
    from eddiebot.vslam.memory import LinkType

    with SessionDatabase(path, read_only=True) as db:
        nodes = db.nodes()
        links = db.links()
        opt = db.optimized_poses()
        params = db.last_parameters()
        conn: sqlite3.Connection = db._conn
        words = int(conn.execute("SELECT COUNT(*) FROM Word").fetchone()[0])
        features = int(conn.execute("SELECT COUNT(*) FROM Feature").fetchone()[0])
        sessions = int(conn.execute("SELECT COUNT(*) FROM Info").fetchone()[0])
    kinds = Counter(LinkType(lk.type).name.lower() for lk in links)
    poses = [opt.get(n.id, n.odom_pose) for n in nodes]
    length = float(sum(np.linalg.norm(b[:3, 3] - a[:3, 3]) for a, b in zip(poses, poses[1:])))
    stamps = [n.stamp_ns for n in nodes]
    return {
        "file": str(path), "size_bytes": path.stat().st_size, "sessions": sessions,
        "maps": len({n.map_id for n in nodes}), "nodes": len(nodes), "links": len(links),
        "link_types": dict(sorted(kinds.items())), "words": words, "features": features,
        "optimized_poses": len(opt), "path_length_m": round(length, 3),
        "duration_s": round((max(stamps) - min(stamps)) / 1e9, 3) if stamps else 0.0,
        "parameters": len(params),
        "Reg/Force3DoF": params.get("Reg/Force3DoF", ""),
    }


def _db_info(args: argparse.Namespace) -> int:
    from eddiebot.vslam.errors import DatabaseError

    try:
        info = database_info(args.file)
    except (DatabaseError, OSError) as exc:
        print(f"eddie vslam db info: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        for k, v in info.items():
            print(f"{k + ':':20s}{v}")
    return 0


def _db_export(args: argparse.Namespace) -> int:
    from eddiebot.vslam.database import SessionDatabase
    from eddiebot.vslam.errors import DatabaseError, VslamError
    from eddiebot.vslam.export import write_ply
    from eddiebot.vslam.export_mesh import (
        MESH_SUFFIXES,
        MeshSettings,
        MeshUnavailableError,
        require_open3d,
    )
    from eddiebot.vslam.rtabmap import Rtabmap
    from eddiebot.vslam.tum import write_tum_trajectory

    if args.ply is None and args.poses is None and args.mesh is None:
        print("eddie vslam db export: give --ply, --mesh and/or --poses", file=sys.stderr)
        return 2
    settings = MeshSettings(
        decimation=args.decimation, min_range=args.min_range, max_range=args.max_range,
        voxel=args.voxel, poisson_depth=args.poisson_depth, poisson_size=args.poisson_size,
        max_polygons=args.max_polygons, color_radius=args.color_radius,
        min_cluster=args.min_cluster)
    try:
        settings.check()
        if args.mesh is not None:
            if args.mesh.suffix.lower() not in MESH_SUFFIXES:
                raise ValueError(f"--mesh {args.mesh}: the file must end in .ply or .obj")
            require_open3d()
    except (ValueError, MeshUnavailableError) as exc:
        print(f"eddie vslam db export: {exc}", file=sys.stderr)
        return 2
    try:
        with SessionDatabase(args.file, read_only=True) as db:
            params = db.last_parameters()
            # read-only use: load the map without starting a new session
            from eddiebot.vslam.parameters import RtabmapParameters

            p = RtabmapParameters.from_dict(params, strict=False).replace(
                {"Mem/IncrementalMemory": "false", "Mem/InitWMWithAllNodes": "true"})
            core = Rtabmap(p, database=db)
            stamps = {n.id: n.stamp_ns for n in db.nodes()}
            all_poses, _ = core.graph()
            # maps not merged (an odometry reset, another session) are in frames of their
            # own: the largest goes to the given file, each other one beside it (_map<id>)
            frames = sorted(core.map_frames().items(), key=lambda kv: (-len(kv[1]), kv[0]))
            if len(frames) > 1:
                print(f"{len(frames)} maps not merged with each other: one file each")
            for k, (frame, ids_in) in enumerate(frames):
                poses = {i: all_poses[i] for i in ids_in}
                if args.poses is not None:
                    out = _map_path(args.poses, frame, k)
                    ids = sorted(i for i in poses if i in stamps)
                    write_tum_trajectory(out, [stamps[i] / 1e9 for i in ids],
                                         [poses[i] for i in ids])
                    print(f"wrote {len(ids)} poses to {out}")
                if args.ply is None and args.mesh is None:
                    continue
                xyz, rgb, view, nodes = _cloud_from_db(db, poses, settings)
                if args.ply is not None:
                    out = _map_path(args.ply, frame, k)
                    write_ply(out, xyz, rgb)
                    print(f"wrote {xyz.shape[0]} points to {out}")
                if args.mesh is not None:
                    _export_mesh(xyz, rgb, view, nodes, settings,
                                 _map_path(args.mesh, frame, k))
    except (DatabaseError, VslamError, OSError) as exc:
        print(f"eddie vslam db export: {exc}", file=sys.stderr)
        return 1
    return 0


def _cloud_from_db(db: Any, poses: dict[int, Any], settings: Any) -> tuple[Any, Any, Any, int]:
    """The cloud of one map re-made from its nodes' stored RGB-D frames (loaded nodes carry
    no cloud) at `poses` (its optimised poses): xyz, colours, the camera that saw each point,
    and the number of frames used."""
    from eddiebot.vslam.export_mesh import assemble_viewed_cloud

    used = 0

    def frames() -> Any:
        nonlocal used
        for node_id in sorted(poses):
            rgb, depth, cam = db.frame(node_id)
            if depth is not None and cam is not None:
                used += 1
                yield rgb, depth, cam, poses[node_id]

    xyz, rgb, view = assemble_viewed_cloud(frames(), settings)
    return xyz, rgb, view, used


def _export_mesh(xyz: Any, rgb: Any, view: Any, nodes: int, settings: Any, out: Path) -> None:
    import time

    from eddiebot.vslam.export_mesh import poisson_mesh, write_mesh

    t0 = time.perf_counter()
    mesh = poisson_mesh(xyz, rgb, view, settings)
    write_mesh(out, mesh)
    print(f"wrote {mesh.vertices.shape[0]} vertices, {mesh.triangles.shape[0]} polygons to "
          f"{out} ({nodes} nodes, {xyz.shape[0]} points, Poisson depth {mesh.poisson_depth}, "
          f"{time.perf_counter() - t0:.1f} s)")


def _map_path(path: Path, frame: int, rank: int) -> Path:
    """The export file of one map: `path` for the largest, `<stem>_map<id><suffix>` beside."""
    return path if rank == 0 else path.with_name(f"{path.stem}_map{frame}{path.suffix}")
