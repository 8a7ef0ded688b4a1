"""Dashboard latency and CPU: pose and scan from publication to a WebSocket client, and the
server's CPU share under a realistic stream (loopback, wall clock).

Stream: TF 30 Hz, /odom 30 Hz, /scan 10 Hz (640 rays), /image_raw and /depth/image_raw
30 Hz (640x480), five IR/PING ranges 10 Hz, /map 20 x 15 m at 0.05 m 1 Hz (a few cells
change), local costmap 3 x 3 m 5 Hz, battery 1 Hz; the working layers: AMCL's
/particle_cloud 10 Hz (2000 particles, AMCL's max_particles), /plan 1 Hz (300 poses),
/local_plan and /lookahead_point 10 Hz, /cmd_vel_safe 20 Hz (the mux's navigation input),
/rosout 10 lines/s, the vSLAM graph 1 Hz (300 nodes). ``--cloud`` also opens the 3D view with
/points at 30 Hz (640x480 = 307,200 points, as the Kinect's). CPU is the dashboard's own
threads (node executor + web server), read from /proc. Prints a table; writes
benchmarks/results/dashboard.json (dashboard_cloud.json with ``--cloud``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import threading
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.core.tf import make_transform_2d
from eddiebot.maps import OccupancyMap, map_to_msg
from eddiebot.msgs.eddiebot_msgs import BatteryLevel
from eddiebot.msgs.geometry_msgs import Point, PointStamped, Pose, PoseStamped, Quaternion, Twist
from eddiebot.msgs.nav2_msgs import Particle, ParticleCloud
from eddiebot.msgs.nav_msgs import OccupancyGrid, Odometry
from eddiebot.msgs.nav_msgs import Path as NavPath
from eddiebot.msgs.rcl_interfaces import Log
from eddiebot.msgs.sensor_msgs import Image, LaserScan, PointCloud2, PointField, Range
from eddiebot.msgs.std_msgs import Header
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.msgs.visualization_msgs import Marker, MarkerArray
from eddiebot.viz.dashboard import start_dashboard
from eddiebot.viz.dashboard.core import split_binary_frame

RESULTS = Path(__file__).parent / "results" / "dashboard.json"


def thread_cpu_s(native_ids: list[int]) -> float:
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for tid in native_ids:
        fields = Path(f"/proc/self/task/{tid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])  # utime + stime
    return total / tick


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--cloud", action="store_true", help="open the 3D view, with /points at 30 Hz")
    args = ap.parse_args()

    ctx = Context()
    node = Node("bench_pub", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    dash = start_dashboard(ctx, "127.0.0.1", 0, print_url=False)
    dash_tids = [t.native_id for t in dash._threads if t.native_id is not None]

    tf_pub = node.create_publisher(TFMessage, "/tf", 100)
    odom_pub = node.create_publisher(Odometry, "/odom", 10)
    scan_pub = node.create_publisher(LaserScan, "/scan", 10)
    img_pub = node.create_publisher(Image, "/image_raw", 5)
    depth_pub = node.create_publisher(Image, "/depth/image_raw", 5)
    map_pub = node.create_publisher(OccupancyGrid, "/map", qos_profile_latched)
    lc_pub = node.create_publisher(OccupancyGrid, "/local_costmap/costmap", qos_profile_latched)
    range_pubs = [node.create_publisher(Range, t, 10) for t in
                  ("/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right", "/eddie/ping/left", "/eddie/ping/right")]
    bat_pub = node.create_publisher(BatteryLevel, "/eddie/battery_level", 5)
    part_pub = node.create_publisher(ParticleCloud, "/particle_cloud", 1)
    plan_pub = node.create_publisher(NavPath, "/plan", 1)
    local_pub = node.create_publisher(NavPath, "/local_plan", 1)
    look_pub = node.create_publisher(PointStamped, "/lookahead_point", 1)
    nav_pub = node.create_publisher(Twist, "/cmd_vel_safe", 10)
    log_pub = node.create_publisher(Log, "/rosout", 100)
    graph_pub = node.create_publisher(MarkerArray, "/rtabmap/mapGraph", qos_profile_latched)
    points_pub = node.create_publisher(PointCloud2, "/points", 5)
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, (480, 640, 3), dtype=np.uint8)
    depth = (rng.random((480, 640)) * 4000 + 500).astype(np.uint16)
    cells = np.zeros((300, 400), np.int8)
    cells[:, :50] = -1
    particles = [Particle(pose=Pose(position=Point(x=float(x), y=float(y), z=0.0),
                                    orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)), weight=5e-4)
                 for x, y in rng.normal(0.0, 0.3, (2000, 2))]

    def path(n: int, step: float) -> NavPath:
        poses = []
        for i in range(n):
            ps = PoseStamped(header=Header(frame_id="map"))
            ps.pose.position.x, ps.pose.position.y = i * step, 1.0
            poses.append(ps)
        return NavPath(header=Header(frame_id="map"), poses=poses)

    plan, local_plan = path(300, 0.05), path(30, 0.05)
    look = PointStamped(header=Header(frame_id="map"), point=Point(x=1.0, y=1.0, z=0.0))
    nodes = Marker(header=Header(frame_id="map"), ns="rtabmap_nodes", id=0, type=Marker.SPHERE_LIST,
                   action=Marker.ADD)
    nodes.pose.orientation.w = 1.0
    nodes.points = [Point(x=0.05 * i, y=0.0, z=0.0) for i in range(300)]
    links = Marker(header=Header(frame_id="map"), ns="rtabmap_neighbor_links", id=1,
                   type=Marker.LINE_LIST, action=Marker.ADD)
    links.pose.orientation.w = 1.0
    links.points = [p for a, b in zip(nodes.points, nodes.points[1:], strict=False) for p in (a, b)]
    xyz = rng.uniform(0.5, 4.0, (640 * 480, 3)).astype(np.float32)
    cloud = PointCloud2(header=Header(frame_id="base_footprint"), height=480, width=640,
                        fields=[PointField(name=k, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                                for i, k in enumerate("xyz")],
                        is_bigendian=False, point_step=12, row_step=12 * 640,
                        data=xyz.view(np.uint8).reshape(-1), is_dense=True)
    sent: dict[str, dict[int, int]] = {"pose": {}, "scan": {}}
    seq = {"pose": 0, "scan": 0}
    lock = threading.Lock()

    def tf_tick() -> None:
        seq["pose"] += 1
        k = seq["pose"] % 1000
        now = time.time_ns()
        with lock:
            sent["pose"][k] = time.perf_counter_ns()
        tf_pub.publish(TFMessage(transforms=[make_transform_2d("map", "odom", now, 0, 0, 0),
                                             make_transform_2d("odom", "base_footprint", now, k * 0.01, 1.0, 0.2)]))
        odom_pub.publish(Odometry())

    def scan_tick() -> None:
        seq["scan"] += 1
        k = seq["scan"] % 1000
        scan = LaserScan(angle_min=-0.5, angle_increment=1.0 / 640, range_min=0.45, range_max=8.0,
                         ranges=np.full(640, 2.0, np.float32))
        scan.header.frame_id = "base_footprint"
        scan.header.stamp.sec = k
        with lock:
            sent["scan"][k] = time.perf_counter_ns()
        scan_pub.publish(scan)
        for p in range_pubs:
            r = Range(field_of_view=0.3, min_range=0.1, max_range=1.0, range=0.6)
            r.header.frame_id = "base_footprint"
            p.publish(r)

    def image_tick() -> None:
        img_pub.publish(Image(height=480, width=640, encoding="rgb8", step=1920, data=rgb.reshape(-1)))
        depth_pub.publish(Image(height=480, width=640, encoding="16UC1", step=1280,
                                data=depth.view(np.uint8).reshape(-1)))

    def map_tick() -> None:
        i = int(rng.integers(0, 300))
        cells[i, 200:210] = 100
        map_pub.publish(map_to_msg(OccupancyMap(cells.copy(), 0.05, (-10.0, -7.5, 0.0)), frame_id="map"))
        bat_pub.publish(BatteryLevel(value=12.1))

    def costmap_tick() -> None:
        lc = (rng.random((60, 60)) * 100).astype(np.int8)
        lc_pub.publish(map_to_msg(OccupancyMap(lc, 0.05, (-0.5, -0.5, 0.0)), frame_id="odom"))

    def nav_tick() -> None:
        part_pub.publish(ParticleCloud(header=Header(frame_id="map"), particles=particles))
        local_pub.publish(local_plan)
        look_pub.publish(look)
        log_pub.publish(Log(level=20, name="bench", msg="a line of log"))

    def nav_cmd_tick() -> None:
        nav_pub.publish(Twist())

    def slow_tick() -> None:
        plan_pub.publish(plan)
        graph_pub.publish(MarkerArray(markers=[nodes, links]))

    def cloud_tick() -> None:
        points_pub.publish(cloud)

    skip = set(os.environ.get("BENCH_SKIP", "").split(","))
    if not args.cloud:
        skip.add("cloud_tick")
    for period, cb in ((1 / 30, tf_tick), (0.1, scan_tick), (1 / 30, image_tick), (1.0, map_tick),
                       (0.2, costmap_tick), (0.1, nav_tick), (0.05, nav_cmd_tick), (1.0, slow_tick),
                       (1 / 30, cloud_tick)):
        if cb.__name__ not in skip:
            node.create_timer(period, cb)
    spin = threading.Thread(target=ex.spin, daemon=True)
    spin.start()

    lat: dict[str, list[float]] = {"pose": [], "scan": []}
    counts: dict[str, int] = {"pose": 0, "scan": 0}
    kinds: dict[str, int] = {}  # frames received per kind, to show what the stream exercised
    url = dash.url.replace("http://", "ws://") + "ws"
    with connect(url, origin=dash.url.rstrip("/"), max_size=None) as ws:  # type: ignore[call-overload]
        if args.cloud:
            ws.send(json.dumps({"op": "view", "name": "cloud", "engage": True}))
        warm_end = time.perf_counter() + 1.0  # warm up (first JPEG, first tiles), reading all
        while time.perf_counter() < warm_end:
            try:
                ws.recv(timeout=0.1)
            except TimeoutError:
                pass
        cpu0, wall0 = thread_cpu_s(dash_tids), time.perf_counter()
        t_end = time.perf_counter() + args.seconds
        while time.perf_counter() < t_end:
            try:
                frame = ws.recv(timeout=0.5)
            except TimeoutError:
                continue
            now = time.perf_counter_ns()
            if isinstance(frame, bytes):
                head, _ = split_binary_frame(frame)
                kinds[head["t"]] = kinds.get(head["t"], 0) + 1
                if head["t"] == "scan":
                    k = head["stamp"][0]
                    with lock:
                        t0 = sent["scan"].get(k)
                    if t0 is not None:
                        lat["scan"].append((now - t0) / 1e6)
                        counts["scan"] += 1
            else:
                msg = json.loads(frame)
                kinds[msg["t"]] = kinds.get(msg["t"], 0) + 1
                if msg["t"] == "pose":
                    k = round(msg["x"] / 0.01)
                    with lock:
                        t0 = sent["pose"].get(k)
                    if t0 is not None:
                        lat["pose"].append((now - t0) / 1e6)
                        counts["pose"] += 1
        cpu1, wall1 = thread_cpu_s(dash_tids), time.perf_counter()
    dash.stop()
    ex.shutdown()
    ctx.shutdown()
    elapsed = wall1 - wall0
    cpu_pct = 100.0 * (cpu1 - cpu0) / elapsed
    rows = []
    for name in ("pose", "scan"):
        v = sorted(lat[name])
        rows.append({"stream": name, "rate_hz": round(counts[name] / elapsed, 1),
                     "median_ms": round(statistics.median(v), 2) if v else None,
                     "p95_ms": round(v[int(0.95 * (len(v) - 1))], 2) if v else None,
                     "max_ms": round(v[-1], 2) if v else None})
    print(f"{'stream':8} {'rate Hz':>8} {'median ms':>10} {'p95 ms':>8} {'max ms':>8}")
    for r in rows:
        print(f"{r['stream']:8} {r['rate_hz']:8} {r['median_ms']:10} {r['p95_ms']:8} {r['max_ms']:8}")
    print(f"dashboard CPU: {cpu_pct:.1f} % of one core over {elapsed:.1f} s")
    print("frames received:", ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    out = RESULTS.with_name("dashboard_cloud.json") if args.cloud else RESULTS
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "benchmark": "dashboard", "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                    "python": platform.python_version()},
        "seconds": round(elapsed, 2), "cloud_view": args.cloud, "latency": rows, "frames": kinds, "cpu_percent_one_core": round(cpu_pct, 1),
        "targets": {"latency_ms": 50, "rate_hz": 10, "cpu_percent": 10}}, indent=2) + "\n")


if __name__ == "__main__":
    main()
