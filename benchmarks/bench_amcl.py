"""AMCL localization accuracy in the simulator against ground truth.

Each run is the simulator with Eddie's whole base stack (firmware emulator, odometry from the
encoders, the Kinect depth turned into a 57° scan), the map server holding the world's
ground-truth scan-plane map and the ``amcl`` node with ``config/nav2.yaml``'s parameters,
started at the true start pose, on the sim clock as fast as the CPU allows. The scripted
operator of the demo (`eddiebot.demo.route.RouteDriver`) drives the route on ground truth.

Figures per run:

* ``amcl_pose`` error: every published estimate against the true pose at its stamp (RMSE,
  p95, max of the position error; RMS heading error);
* ``map → base_footprint`` error: the transform a controller sees (latest ``map → odom``
  composed with the odometry), sampled every 0.2 s of sim time — odometry carries it between
  filter updates;
* wheel odometry alone (``odom`` aligned at the start) for comparison;
* ``diverged``: any ``map → base_footprint`` error above 0.5 m;
* update time: CPU and wall ms of each filter update (``Amcl.update``), median and p95.

    .venv/bin/python benchmarks/bench_amcl.py [--worlds office corridor] [--seeds 0 1]
        [--set name=value ...] [--out benchmarks/results/amcl.json]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import RESULTS, print_table, write_results

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.node import Node
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.core.time import stamp_to_ns
from eddiebot.demo.route import OFFICE_ROUTE, WAREHOUSE_ROUTE, RouteDriver, Waypoint
from eddiebot.demo.vslam_stage import CORRIDOR_ROUTE
from eddiebot.geometry import quaternion_to_yaw
from eddiebot.maps import OccupancyMap, save_map
from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.nav.nodes.amcl import AmclNode
from eddiebot.nav.nodes.map_server import MapServer
from eddiebot.registry import NODES
from eddiebot.sim import cached_ground_truth

ROOT = Path(__file__).resolve().parents[1]
NAV2_YAML = ROOT / "src" / "eddiebot" / "config" / "nav2.yaml"
ROUTES: dict[str, tuple[Waypoint, ...]] = {"office": OFFICE_ROUTE, "corridor": CORRIDOR_ROUTE,
                                           "warehouse": WAREHOUSE_ROUTE}
DIVERGED_M = 0.5
#: the motion-noise alphas of the sweep
_A = {f"alpha{i}": 0.005 for i in (1, 2, 3, 4)}
_PROB = {"laser_model_type": "likelihood_field_prob"}
#: the parameter study of docs/benchmarks/nav.md#amcl (``--sweep`` on recorded runs);
#: each entry overrides config/nav2.yaml's amcl block
BEFORE = {"laser_model_type": "likelihood_field", "do_beamskip": False,
          "resample_method": "multinomial", "laser_likelihood_surfaces_only": False,
          **{f"alpha{i}": 0.02 for i in (1, 2, 3, 4)}}
SWEEP: dict[str, dict[str, Any]] = {
    "before (alphas 0.02, likelihood_field, multinomial)": BEFORE,
    "alphas 0.005": {**BEFORE, **_A},
    "alphas 0.005 + likelihood_field_prob": {**BEFORE, **_A, **_PROB},
    "nav2.yaml": {},
    "nav2.yaml, alpha3 0.005": {"alpha3": 0.005},
    "nav2.yaml, multinomial": {"resample_method": "multinomial"},
    "nav2.yaml, sigma_hit 0.1": {"sigma_hit": 0.1},
    "nav2.yaml, update_min_d/a 0.2": {"update_min_d": 0.2, "update_min_a": 0.2},
}
#: the warehouse study of docs/benchmarks/nav.md#amcl-warehouse (``--sweep surfaces`` on
#: runs recorded in the office, corridor and warehouse, replayed on the footprint map)
SURFACES_SWEEP: dict[str, dict[str, Any]] = {
    "Nav2's field (all occupied cells)": {"laser_likelihood_surfaces_only": False},
    "nav2.yaml (surfaces only)": {},
    "nav2.yaml, laser_max_range 5": {"laser_max_range": 5.0},
    "nav2.yaml, laser_max_range 6": {"laser_max_range": 6.0},
}
SWEEPS = {"study": SWEEP, "surfaces": SURFACES_SWEEP}
SAMPLE_S = 0.2


def _pose_of(msg: Any) -> tuple[float, float, float]:
    p = msg.pose.pose
    q = p.orientation
    return (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))


def _amcl_params(overrides: dict[str, Any]) -> dict[str, Any]:
    doc = yaml.safe_load(NAV2_YAML.read_text())
    params: dict[str, Any] = dict(doc["amcl"]["ros__parameters"])
    params.update(overrides)
    return params


def surface_map(occ: OccupancyMap, start: tuple[float, ...]) -> OccupancyMap:
    """The ground-truth map as a perfect 2-D SLAM would have it: the free space reachable
    from ``start``, the occupied cells bordering it (the surfaces a scan sees), and unknown
    everywhere else (wall interiors, the outside)."""
    from scipy import ndimage

    free = occ.data == 0
    labels, _ = ndimage.label(free)
    i = int((start[0] - occ.origin[0]) / occ.resolution)
    j = int((start[1] - occ.origin[1]) / occ.resolution)
    reach = labels == labels[j, i]
    border = ndimage.binary_dilation(reach, structure=np.ones((3, 3), dtype=bool)) & (occ.data == 100)
    data = np.full(occ.data.shape, -1, dtype=np.int8)
    data[reach] = 0
    data[border] = 100
    return OccupancyMap(data, occ.resolution, occ.origin)


def bench_map(world: Any, map_kind: str, start: tuple[float, ...]) -> OccupancyMap:
    """The map AMCL is given: ``surface`` (the scan-plane slice as a 2-D SLAM map holds it),
    ``full`` (the whole slice) or ``footprint`` (every prism between the ground clearance and
    the robot's height, the map ``bench_nav_worlds.py`` serves: it also holds what the scan
    plane misses, low pallets and table legs)."""
    maps = cached_ground_truth(world)
    if map_kind == "footprint":
        return maps.footprint
    return surface_map(maps.scan, start) if map_kind == "surface" else maps.scan


def _interp(stamps: np.ndarray, poses: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Ground-truth poses at ``query`` stamps (linear in x, y; heading unwrapped)."""
    th = np.unwrap(poses[:, 2])
    out = np.stack([np.interp(query, stamps, poses[:, 0]), np.interp(query, stamps, poses[:, 1]),
                    np.interp(query, stamps, th)], axis=-1)
    return out


def _errors(est: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pos = np.hypot(est[:, 0] - truth[:, 0], est[:, 1] - truth[:, 1])
    yaw = np.abs(np.arctan2(np.sin(est[:, 2] - truth[:, 2]), np.cos(est[:, 2] - truth[:, 2])))
    return pos, yaw


def _stats(prefix: str, pos: np.ndarray, yaw: np.ndarray) -> dict[str, float]:
    if pos.size == 0:
        return {f"{prefix}_rmse_m": math.nan}
    return {f"{prefix}_rmse_m": float(np.sqrt(np.mean(pos ** 2))),
            f"{prefix}_p95_m": float(np.percentile(pos, 95)),
            f"{prefix}_max_m": float(pos.max()),
            f"{prefix}_yaw_rms_deg": float(np.degrees(np.sqrt(np.mean(yaw ** 2))))}


class _Probe(Node):
    """Records ground truth, odometry, ``amcl_pose`` and samples ``map → base_footprint``."""

    def __init__(self, record: bool = False, **kwargs: Any) -> None:
        super().__init__("amcl_probe", **kwargs)
        from eddiebot.nav.nodes.map_server import MAP_QOS

        self.truth: list[tuple[int, tuple[float, float, float]]] = []
        self.odom: list[tuple[int, tuple[float, float, float]]] = []
        self.amcl: list[tuple[int, tuple[float, float, float], float]] = []
        self.tf: list[tuple[int, tuple[float, float, float]]] = []
        self.buffer = Buffer(node=self)
        self.listener = TransformListener(self.buffer, self)
        self.create_subscription(Odometry, "/ground_truth/odom",
                                 lambda m: self.truth.append((stamp_to_ns(m.header.stamp), _pose_of(m))), 100)
        self.create_subscription(Odometry, "/odom",
                                 lambda m: self.odom.append((stamp_to_ns(m.header.stamp), _pose_of(m))), 100)
        self.create_subscription(PoseWithCovarianceStamped, "/amcl_pose", self._on_amcl, MAP_QOS)
        self.scans: list[tuple[int, np.ndarray]] = []
        self.scan_meta: tuple[float, float, float, float] | None = None
        if record:
            from eddiebot.core.qos import qos_profile_sensor_data
            from eddiebot.msgs.sensor_msgs import LaserScan

            self.create_subscription(LaserScan, "/scan", self._on_scan, qos_profile_sensor_data)
        self.create_timer(SAMPLE_S, self._sample)

    def _on_scan(self, msg: Any) -> None:
        self.scan_meta = (msg.angle_min, msg.angle_increment, msg.range_min, msg.range_max)
        self.scans.append((stamp_to_ns(msg.header.stamp), np.asarray(msg.ranges, dtype=np.float32)))

    def _on_amcl(self, msg: Any) -> None:
        c = np.asarray(msg.pose.covariance).reshape(6, 6)
        self.amcl.append((stamp_to_ns(msg.header.stamp), _pose_of(msg), float(c[0, 0] + c[1, 1])))

    def _sample(self) -> None:
        try:
            t = self.buffer.lookup_transform("map", "base_footprint", 0)
        except TransformException:
            return
        tr, q = t.transform.translation, t.transform.rotation
        self.tf.append((stamp_to_ns(t.header.stamp), (tr.x, tr.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))))


def run(world: str, seed: int, overrides: dict[str, Any], camera: tuple[int, int, float],
        wall_timeout_s: float = 1800.0, trace: Path | None = None,
        map_kind: str = "surface", record: Path | None = None) -> dict[str, Any]:
    context = Context(use_sim_time=True)
    args = {"world": world, "seed": str(seed), "camera_width": str(camera[0]),
            "camera_height": str(camera[1]), "camera_rate": str(camera[2])}
    nodes: list[Node] = build_nodes(parse_launch_file(find_launch_file("sim"), args), context, NODES)
    sim = context.resources["simulator"]
    start = tuple(float(v) for v in sim.world.start)
    gt = bench_map(sim.world, map_kind, start)
    update_cpu: list[float] = []
    update_wall: list[float] = []
    row: dict[str, Any] = {"world": world, "seed": seed, "map": map_kind}
    with tempfile.TemporaryDirectory() as tmp:
        save_map(gt, Path(tmp) / "truth")
        map_server = MapServer(context=context, parameter_overrides={
            "yaml_filename": str(Path(tmp) / "truth.yaml"), "use_sim_time": True})
        params = _amcl_params(overrides)
        params.update({"use_sim_time": True, "set_initial_pose": True, "random_seed": seed,
                       "initial_pose.x": start[0], "initial_pose.y": start[1],
                       "initial_pose.yaw": start[2]})
        amcl = AmclNode(context=context, parameter_overrides=params)
        for n in (map_server, amcl):
            assert n.trigger_configure() == 97, getattr(n, "last_error", "")
            assert n.trigger_activate() == 97
        assert amcl.amcl is not None
        core = amcl.amcl
        update = core.update

        def timed(*a: Any, **k: Any) -> Any:
            c0, w0 = time.process_time(), time.perf_counter()
            updated = update(*a, **k)
            if updated:  # a filter update, not a scan skipped for too little motion
                update_cpu.append((time.process_time() - c0) * 1e3)
                update_wall.append((time.perf_counter() - w0) * 1e3)
            return updated

        core.update = timed  # type: ignore[method-assign]
        driver = RouteDriver(ROUTES[world], context=context)
        probe = _Probe(record=record is not None, context=context)
        nodes += [map_server, amcl, driver, probe]
        executor = SingleThreadedExecutor(context=context)
        for n in nodes:
            executor.add_node(n)
        w0, c0 = time.perf_counter(), time.process_time()
        try:
            while not driver.done.is_set() and time.perf_counter() - w0 < wall_timeout_s:
                executor.spin_for(1.0)
            executor.spin_for(1.0)
            row.update(finished=driver.done.is_set() and not driver.failed,
                       distance_m=round(driver.distance, 2),
                       sim_s=round(context.sim_clock.now_ns() / 1e9, 1),
                       wall_s=round(time.perf_counter() - w0, 1),
                       cpu_s=round(time.process_time() - c0, 1))
            row.update(_score(probe, start))
            if record is not None and probe.scans and probe.scan_meta is not None:
                record.mkdir(parents=True, exist_ok=True)
                np.savez_compressed(
                    record / f"{world}_{seed}.npz", world=world, start=np.array(start),
                    scan_t=np.array([t for t, _ in probe.scans], dtype=np.int64),
                    scan_r=np.stack([r for _, r in probe.scans]),
                    scan_meta=np.array(probe.scan_meta),
                    truth=np.array([(t, *p) for t, p in probe.truth]),
                    odom=np.array([(t, *p) for t, p in probe.odom]))
            if trace is not None:
                trace.mkdir(parents=True, exist_ok=True)
                np.savez(trace / f"{world}_{seed}.npz",
                         truth=np.array([(t, *p) for t, p in probe.truth]),
                         odom=np.array([(t, *p) for t, p in probe.odom]),
                         amcl=np.array([(t, *p, c) for t, p, c in probe.amcl]),
                         tf=np.array([(t, *p) for t, p in probe.tf]))
        finally:
            for n in reversed(nodes):
                n.destroy_node()
            context.shutdown()
    row.update(updates=len(update_cpu),
               update_cpu_median_ms=float(np.median(update_cpu)) if update_cpu else math.nan,
               update_cpu_p95_ms=float(np.percentile(update_cpu, 95)) if update_cpu else math.nan,
               update_wall_median_ms=float(np.median(update_wall)) if update_wall else math.nan)
    return row


def _score(probe: _Probe, start: tuple[float, ...]) -> dict[str, Any]:
    ts = np.array([t for t, _ in probe.truth], dtype=np.float64)
    tp = np.array([p for _, p in probe.truth], dtype=np.float64)
    order = np.argsort(ts)
    ts, tp = ts[order], tp[order]
    out: dict[str, Any] = {}

    def within(stamps: np.ndarray) -> np.ndarray:
        return (stamps >= ts[0]) & (stamps <= ts[-1])

    if probe.amcl:
        s = np.array([t for t, _, _ in probe.amcl], dtype=np.float64)
        e = np.array([p for _, p, _ in probe.amcl], dtype=np.float64)
        k = within(s)
        pos, yaw = _errors(e[k], _interp(ts, tp, s[k]))
        out.update(_stats("pose", pos, yaw))
        out["pose_count"] = int(k.sum())
        out["cov_xy_trace_median"] = float(np.median([c for _, _, c in probe.amcl]))
    if probe.tf:
        s = np.array([t for t, _ in probe.tf], dtype=np.float64)
        e = np.array([p for _, p in probe.tf], dtype=np.float64)
        k = within(s)
        pos, yaw = _errors(e[k], _interp(ts, tp, s[k]))
        out.update(_stats("tf", pos, yaw))
        out["diverged"] = bool(pos.size and pos.max() > DIVERGED_M)
    if probe.odom:
        s = np.array([t for t, _ in probe.odom], dtype=np.float64)
        o = np.array([p for _, p in probe.odom], dtype=np.float64)
        c, sn = math.cos(start[2]), math.sin(start[2])
        w = np.stack([start[0] + c * o[:, 0] - sn * o[:, 1], start[1] + sn * o[:, 0] + c * o[:, 1],
                      o[:, 2] + start[2]], axis=-1)
        k = within(s)
        pos, yaw = _errors(w[k], _interp(ts, tp, s[k]))
        out.update(_stats("odom", pos, yaw))
    return out


def replay(path: Path, overrides: dict[str, Any], seed: int = 0,
           map_kind: str = "surface", series: bool = False) -> dict[str, Any]:
    """The AMCL core alone on a recorded run (``--record``): every scan with the odometry
    interpolated at its stamp, as the node pairs them. Much faster than a simulated run and
    identical input for every parameter set. Errors: ``pose_*`` at each filter update,
    ``tf_*`` for every scan (last map → odom composed with the odometry at the scan)."""
    from eddiebot.nav.amcl import Amcl, AmclConfig
    from eddiebot.nav.config import _flatten_amcl
    from eddiebot.nav.params import from_params
    from eddiebot.sim import KinectConfig, load_world

    rec = np.load(path)
    world = str(rec["world"])
    start = tuple(float(v) for v in rec["start"])
    gt = bench_map(load_world(world), map_kind, start)
    params = _amcl_params(overrides)
    params = {k: v for k, v in params.items() if not k.startswith("initial_pose")}
    cfg = from_params(AmclConfig, _flatten_amcl(params), server="amcl")
    amcl = Amcl(cfg, gt, seed=seed)
    amcl.initialize(start, np.zeros((3, 3)))
    laser = (*KinectConfig().depth_position[:2], 0.0)
    od = rec["odom"]
    od = od[np.argsort(od[:, 0])]
    oth = np.unwrap(od[:, 3])
    tr = rec["truth"]
    tr = tr[np.argsort(tr[:, 0])]
    a0, inc, rmin, rmax = (float(v) for v in rec["scan_meta"])
    st, sr = rec["scan_t"], rec["scan_r"]
    ok = (st >= od[0, 0]) & (st <= od[-1, 0])
    st, sr = st[ok], sr[ok]
    odom = np.stack([np.interp(st, od[:, 0], od[:, 1]), np.interp(st, od[:, 0], od[:, 2]),
                     np.interp(st, od[:, 0], oth)], axis=-1)
    upd_t, upd_est, tf_est = [], [], []
    cpu, wall = [], []
    map_odom = np.array([start[0], start[1], start[2]])
    for t, r, o in zip(st, sr, odom):
        c0, w0 = time.process_time(), time.perf_counter()
        updated = amcl.update(o, r, a0, inc, rmin, rmax, laser)
        if updated:
            cpu.append((time.process_time() - c0) * 1e3)
            wall.append((time.perf_counter() - w0) * 1e3)
            est, _ = amcl.estimate
            upd_t.append(t)
            upd_est.append(est)
            c, sn = math.cos(est[2] - o[2]), math.sin(est[2] - o[2])
            map_odom = np.array([est[0] - (c * o[0] - sn * o[1]), est[1] - (sn * o[0] + c * o[1]),
                                 est[2] - o[2]])
        c, sn = math.cos(map_odom[2]), math.sin(map_odom[2])
        tf_est.append((map_odom[0] + c * o[0] - sn * o[1], map_odom[1] + sn * o[0] + c * o[1],
                       map_odom[2] + o[2]))
    row: dict[str, Any] = {"world": world, "seed": seed, "map": map_kind, "replay": path.name}
    ut = np.array(upd_t, dtype=np.float64)
    pos, yaw = _errors(np.array(upd_est), _interp(tr[:, 0], tr[:, 1:4], ut))
    row.update(_stats("pose", pos, yaw))
    truth_at = _interp(tr[:, 0], tr[:, 1:4], st.astype(np.float64))
    pos, yaw = _errors(np.array(tf_est), truth_at)
    row.update(_stats("tf", pos, yaw))
    if series:  # per scan: stamp, truth (x, y, yaw), estimate (x, y, yaw)
        row["series"] = np.column_stack([st, truth_at, np.array(tf_est)])
    row["diverged"] = bool(pos.max() > DIVERGED_M)
    row.update(updates=len(cpu), update_cpu_median_ms=float(np.median(cpu)),
               update_cpu_p95_ms=float(np.percentile(cpu, 95)),
               update_wall_median_ms=float(np.median(wall)))
    return row


def _value(text: str) -> Any:
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office", "corridor"], choices=sorted(ROUTES))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--camera", default="320x240@10", help="WxH@HZ")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="amcl parameter override (repeatable)")
    ap.add_argument("--map", choices=("surface", "full", "footprint"), default="surface",
                    help="surface: the slice's visible surfaces only, as a 2-D SLAM map; "
                         "full: the whole slice (walls with their thickness); footprint: "
                         "the navigation benchmark's map")
    ap.add_argument("--name", default="amcl", help="results file benchmarks/results/<name>.json")
    ap.add_argument("--record", type=Path, default=None,
                    help="also save each run's scans, odometry and ground truth here (npz)")
    ap.add_argument("--replay", type=Path, nargs="+", default=None,
                    help="run the AMCL core on recorded runs instead of simulating")
    ap.add_argument("--sweep", nargs="?", const="study", default=None, choices=sorted(SWEEPS),
                    help="with --replay: every parameter set of SWEEP (study, the default) or "
                         "SURFACES_SWEEP (surfaces), mean over --seeds")
    ap.add_argument("--only", default="",
                    help="with --sweep: only the parameter sets whose label contains this")
    ap.add_argument("--before", action="store_true",
                    help="simulate with the amcl parameters nav2.yaml had before this study")
    ap.add_argument("--trace", type=Path, default=None,
                    help="write each run's time series (truth, odom, amcl_pose, TF) as .npz here")
    args = ap.parse_args()
    size, rate = args.camera.split("@")
    w, h = (int(v) for v in size.split("x"))
    overrides = {k: _value(v) for k, v in (item.split("=", 1) for item in args.set)}
    rows = []
    if args.before:
        overrides = {**BEFORE, **overrides}
    if args.replay and args.sweep:
        for label, sweep_set in SWEEPS[args.sweep].items():
            if args.only not in label:
                continue
            for path in args.replay:
                runs = [replay(path, {**sweep_set, **overrides}, seed, args.map)
                        for seed in args.seeds]
                row = {"parameters": label, "replay": path.name, "seeds": len(runs),
                       "overrides": sweep_set}
                for key in ("tf_rmse_m", "tf_p95_m", "tf_yaw_rms_deg", "update_cpu_median_ms"):
                    row[key] = float(np.mean([r[key] for r in runs]))
                row["tf_rmse_worst_seed_m"] = float(max(r["tf_rmse_m"] for r in runs))
                row["tf_max_m"] = float(max(r["tf_max_m"] for r in runs))
                row["diverged"] = any(r["diverged"] for r in runs)
                rows.append(row)
                print(row, flush=True)
                write_results(args.name, rows)  # a sweep cut short keeps what it measured
        print()
        print_table(rows, ["parameters", "replay", "tf_rmse_m", "tf_rmse_worst_seed_m", "tf_p95_m",
                           "tf_max_m", "tf_yaw_rms_deg", "diverged", "update_cpu_median_ms"])
        print(f"wrote {write_results(args.name, rows).relative_to(RESULTS.parent.parent)}")
        return 0
    if args.replay:
        for path in args.replay:
            for seed in args.seeds:
                row = replay(path, overrides, seed, args.map)
                row["overrides"] = overrides
                rows.append(row)
                print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()},
                      flush=True)
        print()
        print_table(rows, ["replay", "seed", "pose_rmse_m", "pose_p95_m", "pose_max_m", "tf_rmse_m",
                           "tf_p95_m", "tf_max_m", "tf_yaw_rms_deg", "diverged", "updates",
                           "update_cpu_median_ms"])
        print(f"wrote {write_results(args.name, rows).relative_to(RESULTS.parent.parent)}")
        return 0
    for world in args.worlds:
        for seed in args.seeds:
            row = run(world, seed, overrides, (w, h, float(rate)), trace=args.trace,
                      map_kind=args.map, record=args.record)
            row["overrides"] = overrides
            rows.append(row)
            print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}, flush=True)
    print()
    print_table(rows, ["world", "seed", "map", "distance_m", "pose_rmse_m", "pose_p95_m", "pose_max_m",
                       "tf_rmse_m", "tf_p95_m", "tf_max_m", "tf_yaw_rms_deg", "odom_rmse_m",
                       "diverged", "updates", "update_cpu_median_ms", "update_cpu_p95_ms", "wall_s"])
    print(f"target: RMSE <= 0.05 m, no divergence (error > {DIVERGED_M} m); wrote "
          f"{write_results(args.name, rows).relative_to(RESULTS.parent.parent)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
