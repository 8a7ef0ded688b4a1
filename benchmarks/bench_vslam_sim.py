"""RGB-D graph SLAM in the simulator: the report's setup (wheel odometry + Kinect RGB-D,
``Reg/Force3DoF``, ``Vis/MinInliers`` 12, no proximity) along routes with revisits.

Each world runs `eddiebot.demo.vslam_stage.run_vslam` (simulator + base stack + the ``rtabmap``
node on the sim clock, as fast as the CPU allows): ATE RMSE / max of the vSLAM nodes against
ground truth, wheel-odometry end-point error and ATE, frame-to-map visual odometry on every
camera frame (drift as % of the distance), per-frame SLAM time. Prints a table and writes
``benchmarks/results/vslam_sim.json``.

    .venv/bin/python benchmarks/bench_vslam_sim.py [--worlds office_long corridor_long]
        [--profile gated|report] [--no-vo] [--keep DIR]
    .venv/bin/python benchmarks/bench_vslam_sim.py --graph   # back-end only, ~1,100 nodes

``--replay DIR [DIR ...]`` re-runs the SLAM core offline on sessions kept with ``--keep`` (the
stored features, depth, odometry poses and scans of every kept node, in order, with the session's
parameters and the ``--set`` overrides) and scores it against the stored ground truth: seconds
instead of minutes, for comparing loop-closure settings on the same data. It also prints the
error of every accepted closure against the true relative pose, next to its claimed σ.

``--graph`` times the pose-graph back end alone (optimisation + the OptimizeMaxError check) on a
synthetic 1,100-node SE(2) graph with a loop closure at every node from the second lap on (a
300-node lap), incremental (iSAM2 on `eddiebot.slam.pose_graph.PoseGraph`) against gtsam batch
Levenberg–Marquardt, and writes ``benchmarks/results/vslam_graph.json``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import platform
import tempfile
from pathlib import Path

from eddiebot.demo.route import OFFICE_LONG_ROUTE, OFFICE_ROUTE
from eddiebot.demo.vslam_stage import CORRIDOR_LONG_ROUTE, CORRIDOR_ROUTE, run_vslam

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "vslam_sim.json"
#: route name -> (world, waypoints); the ``_long`` routes are about ten simulated minutes
ROUTES = {"office": ("office", OFFICE_ROUTE), "corridor": ("corridor", CORRIDOR_ROUTE),
          "office_long": ("office", OFFICE_LONG_ROUTE),
          "corridor_long": ("corridor", CORRIDOR_LONG_ROUTE)}
#: ``--profile``: ``report`` = the report's parameters (launch/vslam.yaml) unchanged;
#: ``gated`` adds the odometry variance measured on the simulated wheel odometry (σ 1 cm and
#: 0.18° per node instead of rtabmap_ros's 0.001 default, i.e. σ 3.2 cm and 1.8°) and the
#: loop-closure plausibility gate `RGBD/LoopClosureMaxMahalanobis` 4 (not upstream).
PROFILES: dict[str, dict[str, object]] = {
    "report": {},
    "gated": {"odom_tf_linear_variance": 1e-4, "odom_tf_angular_variance": 1e-5,
              "RGBD/LoopClosureMaxMahalanobis": "4"},
}


def bench_graph(n_nodes: int = 1100, lap: int = 300) -> dict[str, dict[str, float]]:
    """CPU/wall ms per loop-closure optimisation, last 100 calls, incremental vs batch."""
    import time

    import numpy as np

    from eddiebot.vslam.graph import GraphLink, GtsamPoseGraph, IncrementalPose2Graph, link_errors
    from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

    def truth(k: int) -> np.ndarray:
        a = 2 * np.pi * (k % lap) / lap
        return from_xyz_yaw(10 * np.cos(a), 10 * np.sin(a), a + np.pi / 2)

    info = np.diag([1e3, 1e3, 1.0, 1.0, 1.0, 1e3])
    out: dict[str, dict[str, float]] = {}
    for name, opt in (("incremental", IncrementalPose2Graph()),
                      ("batch", GtsamPoseGraph(True, incremental=False))):
        poses = {1: truth(0)}
        links: list[GraphLink] = []
        cpu: list[float] = []
        wall: list[float] = []
        for k in range(1, n_nodes):
            step = se3_inverse(truth(k - 1)) @ truth(k)
            step[0, 3] *= 1.02
            links.append(GraphLink(k, k + 1, step, info))
            poses[k + 1] = poses[k] @ step
            if k > lap + 10:
                links.append(GraphLink(k + 1, k + 1 - lap, se3_inverse(truth(k)) @ truth(k - lap),
                                       info))
                c0, w0 = time.process_time(), time.perf_counter()
                result = opt.optimize(poses, links, 1, 20)
                link_errors(result, links)
                cpu.append((time.process_time() - c0) * 1e3)
                wall.append((time.perf_counter() - w0) * 1e3)
                poses.update(result)
        out[name] = {"cpu_median_ms": float(np.median(cpu[-100:])),
                     "wall_median_ms": float(np.median(wall[-100:])),
                     "cpu_p95_ms": float(np.percentile(cpu[-100:], 95)),
                     "nodes": len(poses), "links": len(links)}
        print(f"{name:12s} {out[name]}", flush=True)
    return out


def replay_session(folder: Path, overrides: dict[str, str], verbose: bool = False,
                   odom_variance: tuple[float, float] | None = None) -> dict[str, object]:
    """Re-run `Rtabmap` on a kept session (``rtabmap.db``, ``groundtruth.tum``, ``result.json``).

    Returns ATE RMSE / max of the optimised nodes against ground truth, closures accepted and
    rejected, and the errors of the accepted closures against the true relative poses.
    """
    import time

    import numpy as np

    from eddiebot.geometry import se2_between, se2_compose
    from eddiebot.vslam.database import SessionDatabase
    from eddiebot.vslam.parameters import RtabmapParameters
    from eddiebot.vslam.rtabmap import Rtabmap
    from eddiebot.vslam.transforms import yaw_of

    start = np.array(json.loads((folder / "result.json").read_text())["start"], dtype=float)
    gt_rows = np.loadtxt(folder / "groundtruth.tum", ndmin=2)
    gt_by_stamp = {round(r[0] * 1e9): np.array([r[1], r[2], 2 * np.arctan2(r[6], r[7])])
                   for r in gt_rows}
    import shutil

    tmp = tempfile.TemporaryDirectory()
    shutil.copy(folder / "rtabmap.db", Path(tmp.name) / "rtabmap.db")  # replays in parallel
    db = SessionDatabase(Path(tmp.name) / "rtabmap.db")
    try:
        params = dict(db.last_parameters())
        params.update(overrides)
        params["RGBD/CreateOccupancyGrid"] = "false"
        core = Rtabmap(RtabmapParameters.from_dict(params, strict=False))

        class _StoredScan:
            def __init__(self, pts: np.ndarray) -> None:
                self.pts = pts

            def points_in_base(self) -> np.ndarray:
                return self.pts

        camera_row = db._conn.execute("SELECT calibration FROM Data LIMIT 1").fetchone()
        from eddiebot.vslam.database import camera_from_json

        camera = camera_from_json(camera_row[0])
        stamps: dict[int, int] = {}
        accepted: list[tuple[int, int]] = []
        rejected: list[tuple[int, int, str]] = []
        cov = None
        if odom_variance is not None:
            lin, ang = odom_variance
            cov = np.diag([lin, lin, lin, ang, ang, ang])
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for node in db.nodes():
            data = db.load_node_data(node.id)
            _, depth = db.image(node.id)
            if data is None or depth is None:
                continue
            rgb = np.zeros((*depth.shape, 3), np.uint8)
            scan = _StoredScan(data.scan_points) if data.scan_points is not None else None
            r = core.process(rgb, depth, camera, node.odom_pose, node.stamp_ns,
                             scan,  # type: ignore[arg-type]
                             odom_covariance=cov, features=data.features)
            if r.added:
                stamps[r.node_id] = node.stamp_ns
            if r.loop_closure_id or r.proximity_id:
                accepted.append((r.node_id, r.loop_closure_id or r.proximity_id))
            if r.rejected_loop_id:
                rejected.append((r.node_id, r.rejected_loop_id, r.rejection_reason))
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    finally:
        db.close()
        tmp.cleanup()
    poses, links = core.graph()
    ids = [i for i in sorted(poses) if i in stamps and stamps[i] in gt_by_stamp]
    xyt = np.array([[poses[i][0, 3], poses[i][1, 3], yaw_of(poses[i])] for i in ids])
    est = se2_compose(np.broadcast_to(start, xyt.shape), xyt)
    gt = np.array([gt_by_stamp[stamps[i]] for i in ids])
    err = np.hypot(*(est[:, :2] - gt[:, :2]).T)
    gt_of = dict(zip(ids, gt))
    closures = []
    for lk in links:
        if lk.type.name == "NEIGHBOR" or lk.from_id not in gt_of or lk.to_id not in gt_of:
            continue
        true = se2_between(gt_of[lk.from_id], gt_of[lk.to_id])
        meas = np.array([lk.transform[0, 3], lk.transform[1, 3], yaw_of(lk.transform)])
        d = meas - true
        d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
        sig = 1.0 / np.sqrt(np.diag(lk.information)[[0, 1, 5]])
        closures.append({"from": lk.from_id, "to": lk.to_id,
                         "error_xy_m": float(np.hypot(d[0], d[1])),
                         "error_yaw_deg": float(np.degrees(d[2])),
                         "sigma_xy_m": float(sig[0]), "sigma_yaw_deg": float(np.degrees(sig[2]))})
        if verbose:
            c = closures[-1]
            print(f"  closure {lk.from_id}->{lk.to_id}: err {c['error_xy_m']:.3f} m "
                  f"{c['error_yaw_deg']:+.2f} deg  sigma {c['sigma_xy_m']:.4f} m "
                  f"{c['sigma_yaw_deg']:.3f} deg")
    if verbose:
        for a, b, why in rejected:
            print(f"  rejected {a}->{b}: {why}")
    return {"session": str(folder), "overrides": overrides, "odom_variance": odom_variance,
            "nodes": len(ids),
            "loop_closures": len(accepted), "rejected": len(rejected),
            "ate_rmse_m": float(np.sqrt(np.mean(err**2))), "ate_max_m": float(err.max()),
            "cpu_s": cpu, "wall_s": wall,
            "closure_error_max_m": max((c["error_xy_m"] for c in closures), default=0.0),
            "closures": closures}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office_long", "corridor_long"],
                    choices=sorted(ROUTES), help="routes (world[_long])")
    ap.add_argument("--profile", choices=sorted(PROFILES), default="gated",
                    help="parameter set (see PROFILES); --set/--odom-offset add to it")
    ap.add_argument("--camera", default="320x240@10", help="WxH@HZ")
    ap.add_argument("--no-vo", action="store_true", help="skip the visual-odometry drift run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE",
                    help="extra RTAB-Map parameter for the node (repeatable)")
    ap.add_argument("--odom-offset", type=float, default=0.0,
                    help="node parameter odom_stamp_offset (s): odometry latency compensation")
    ap.add_argument("--out", type=Path, default=RESULTS)
    ap.add_argument("--record-vo", action="store_true",
                    help="write vo_frames.npz (VO input) per route, for --replay-vo (with --keep)")
    ap.add_argument("--timeout", type=float, default=7200.0, help="wall-clock limit per route (s)")
    ap.add_argument("--keep", type=Path, default=None, help="keep databases/trajectories here")
    ap.add_argument("--graph", action="store_true", help="back-end timing only")
    ap.add_argument("--replay", nargs="+", type=Path, default=None, metavar="DIR",
                    help="re-run the core offline on sessions kept with --keep")
    ap.add_argument("--odom-variance", nargs=2, type=float, default=None, metavar=("LIN", "ANG"),
                    help="with --replay: odom_tf_linear/angular_variance (default: the core's 0.001)")
    ap.add_argument("-v", "--verbose", action="store_true", help="with --replay: every closure")
    args = ap.parse_args()
    if args.replay:
        overrides = dict(item.split("=", 1) for item in args.set)
        rows = [replay_session(d, overrides, args.verbose,
                               tuple(args.odom_variance) if args.odom_variance else None) for d in args.replay]
        print(f"{'session':30s} {'nodes':>6s} {'loops':>6s} {'rej':>4s} {'ATE rmse':>9s} "
              f"{'ATE max':>8s} {'worst closure m':>15s} {'cpu s':>6s}")
        for r in rows:
            print(f"{str(r['session'])[-30:]:30s} {r['nodes']:6d} {r['loop_closures']:6d} "
                  f"{r['rejected']:4d} {r['ate_rmse_m']:9.3f} {r['ate_max_m']:8.3f} "
                  f"{r['closure_error_max_m']:15.3f} {r['cpu_s']:6.1f}")
        out = RESULTS.with_name("vslam_sim_replay.json") if args.out == RESULTS else args.out
        out.write_text(json.dumps({
            "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            "overrides": overrides, "odom_variance": args.odom_variance, "sessions": rows},
            indent=2, default=str))
        print(f"wrote {out}")
        return 0
    if args.graph:
        graph = bench_graph()
        target = ROOT / "benchmarks" / "results" / "vslam_graph.json"
        target.write_text(json.dumps({
            "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            "machine": platform.processor() or platform.machine(), **graph}, indent=2))
        print(f"wrote {target}")
        return 0
    size, rate = args.camera.split("@")
    w, h = (int(v) for v in size.split("x"))
    extra: dict[str, object] = dict(PROFILES[args.profile])
    extra.update(item.split("=", 1) for item in args.set)
    if args.odom_offset:
        extra["odom_stamp_offset"] = args.odom_offset
    results: dict[str, object] = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "camera": args.camera, "profile": args.profile, "extra_parameters": extra, "worlds": {},
    }
    worlds: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for world in args.worlds:
            out = (args.keep or Path(tmp)) / world
            world_name, route = ROUTES[world]
            r = run_vslam(out, world=world_name, route=route, seed=args.seed,
                          camera=(w, h, float(rate)), parameters=extra or None,
                          visual_odometry=not args.no_vo, wall_timeout_s=args.timeout,
                          record_vo=args.record_vo)
            worlds[world] = r.summary()
            print(f"{world}: {json.dumps(r.summary(), default=str)}", flush=True)
    results["worlds"] = worlds
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2, default=str))
    print()
    print(f"{'world':10s} {'dist m':>7s} {'nodes':>6s} {'loops':>6s} {'ATE rmse':>9s} "
          f"{'ATE max':>8s} {'odom end':>9s} {'odom ATE':>9s} {'VO drift %':>10s} "
          f"{'ms/frame':>9s} {'wall s':>7s} {'sim s':>6s}")
    for world, s in worlds.items():
        assert isinstance(s, dict)
        print(f"{world:10s} {s['distance_m']:7.1f} {s['nodes']:6d} {s['loop_closures']:6d} "
              f"{s['ate_rmse_m']:9.3f} {s['ate_max_m']:8.3f} {s['odom_end_error_m']:9.3f} "
              f"{s['odom_ate_rmse_m']:9.3f} {s['vo_drift_percent']:10.2f} "
              f"{s['frame_ms_median']:9.1f} {s['wall_seconds']:7.0f} {s['sim_seconds']:6.0f}")
    print("targets: ATE RMSE <= 0.10 m, max <= 0.20 m (anchor: RTAB-Map, PR2 wheel odometry "
          "+ RGB-D loop closure, 0.11-0.19 m at the end)")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
