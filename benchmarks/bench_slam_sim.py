"""2D SLAM in simulated buildings with the Kinect-made scan (the demo's mapping stage).

Each run is `eddiebot.demo.mapping.run_mapping`: the simulator (default wheel slip and
encoder noise), Eddie's base stack, depthimage_to_laserscan and the SLAM node
(``config/slam.yaml``, sync processing) on a simulated clock, a scripted operator driving a
fixed route:

* ``office``: `OFFICE_10MIN_ROUTE` (about 10.5 simulated minutes, 141 m: every open room,
  the corridor and the start revisited, a third pass through five rooms);
* ``warehouse``: `WAREHOUSE_10MIN_ROUTE` (about 10.5 simulated minutes, 174 m: three loops
  through the aisles);
* ``corridor``: `CORRIDOR_ROUTE` of the RGB-D benchmark (down a 40 m low-feature hallway and
  back) — the low-feature warning and the end-point error against odometry alone;
* ``office-demo``: the demo's own `OFFICE_ROUTE` (about 3.5 minutes), to check the demo stage.

Figures: trajectory error of the SLAM nodes against ground truth (RMSE, max) two ways: from
the start pose (the map frame starts at the true start pose), and after the one rigid planar
transform that best fits the SLAM poses onto the truth (``ate_aligned_*``: the ATE of the TUM
benchmark and ``evo_ape --align``, the figure the ≤ 0.05 m target is judged on; replays also
give evo's own figure, ``ate_aligned_evo_rmse_m``) with that transform's rotation
(``aligned_turn_deg``: how far the whole map is turned about its start); wheel odometry's at
the same times, end-point error of SLAM's and odometry's final pose, agreement with the
scan-height ground-truth map on the cells both call known (strict; occupied within one cell),
CPU time the SLAM core spent on each processed scan in the node's thread (median, p99, max;
targets ≤ 10 ms / ≤ 50 ms), and the low-feature warnings (episodes logged, matches over the threshold). Prints a table and
writes ``benchmarks/results/slam_sim.json``.

    .venv/bin/python benchmarks/bench_slam_sim.py [--worlds office warehouse corridor office-demo]
        [--seed 0 [1 ...]] [--params FILE] [--keep DIR [--record]] [--noise-correlation-px N]

Several seeds run one after another into one results file, rewritten after each run (with
``--keep DIR`` each seed's runs go to ``DIR/s<seed>/<run>``, one drive folder per seed for
``--replay``). Each row carries the CPU reference time and the 1-minute load average at its end.

``--replay DIR`` scores the bags a ``--keep DIR --record`` run left (``DIR/<run>/mapping_bag``)
offline instead: each bag through `SlamCore` (as ``eddie slam replay`` does: every scan that
moved enough, no node time gate) with ``--set NAME:=VALUE`` overrides on config/slam.yaml —
how the parameters below were chosen. Each replay also scores every loop edge against the
ground-truth relation of its two scans (``loop_error_*``; ``false_loops``: over 0.5 m off;
``false_loops_in_estimate``: those the back end still uses at the end). Writes
``benchmarks/results/<--name>.json``.

    .venv/bin/python benchmarks/bench_slam_sim.py --replay DIR [DIR ...] [--worlds ...]
        [--set K:=V ...] [--node-time-gate] [--ensemble K]

``--ensemble K`` replays each drive K times, member 0 as recorded and members 1.. with every
odometry pose moved by seeded N(0, 1e-9) noise: the SLAM result is chaotic at the level of
floating-point rounding (a loop accepted or not near a threshold changes everything after it),
so one run of a drive is one sample; the ensemble's mean and spread are the figure to compare.

``--optimum-every N`` (with ``--replay``) compares, every N nodes, iSAM2's estimate with the
batch optimum of the factors it holds (``isam_gap_*``: ½χ² above the optimum, largest position
difference).

``--profile DIR`` (with ``--replay``) writes a cProfile of each drive's ``SlamCore.process``
calls to ``DIR/<drive>_<run>_<member>.prof`` (``python -m pstats FILE``); the profiler inflates the CPU
figures of that run.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import cpu_reference_ms, print_table, write_results
from _slam_metrics import evo_ape_rmse

from eddiebot.demo.mapping import aligned_position_errors, run_mapping
from eddiebot.demo.route import OFFICE_10MIN_ROUTE, OFFICE_ROUTE, WAREHOUSE_10MIN_ROUTE
from eddiebot.demo.vslam_stage import CORRIDOR_ROUTE

#: name → (world, route)
RUNS = {
    "office": ("office", OFFICE_10MIN_ROUTE),
    "warehouse": ("warehouse", WAREHOUSE_10MIN_ROUTE),
    "corridor": ("corridor", CORRIDOR_ROUTE),
    "office-demo": ("office", OFFICE_ROUTE),
}

TARGETS = {"ate_rmse_m": 0.05, "agreement": 0.95, "scan_cpu_median_ms": 10.0,
           "scan_cpu_p99_ms": 50.0, "corridor_end_ratio": 1.1}


#: what ``--record`` keeps: enough for ``eddie slam replay`` and for scoring against the truth
RECORD_TOPICS = ["/scan", "/odom", "/ground_truth/odom", "/tf", "/tf_static"]


#: the simulator's noise_correlation_px in the runs (None: the node's default)
_NOISE_CORRELATION_PX: float | None = None


def _sim_parameters(values: dict[str, Any]) -> None:
    """Give the simulator node of every following `run_mapping` these parameters (a global
    parameter source on the run's Context, as a ``--ros-args -p`` would)."""
    import eddiebot.demo.mapping as mapping
    from eddiebot.core.context import Context
    from eddiebot.core.parameters import ParameterOverride

    class _Context(Context):
        def __init__(self, **kwargs: Any) -> None:
            super().__init__(**kwargs)
            self.parameter_sources.extend(ParameterOverride("simulator", k, v, "bench_slam_sim")
                                          for k, v in values.items())

    global _NOISE_CORRELATION_PX
    _NOISE_CORRELATION_PX = values.get("noise_correlation_px", _NOISE_CORRELATION_PX)
    mapping.Context = _Context  # type: ignore[misc]


def run_one(name: str, out: Path, seed: int, params: Path | None,
            record: bool = False) -> dict[str, Any]:
    world, route = RUNS[name]
    reference_ms = round(cpu_reference_ms(), 2)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    r = run_mapping(out / name, world=world, route=route, seed=seed, record=record,
                    record_topics=RECORD_TOPICS, slam_params=params, wall_timeout_s=1800.0)
    cpu = time.process_time() - cpu0
    wall = time.perf_counter() - wall0
    scan = r.scan_cpu_ms
    row: dict[str, Any] = {
        "run": name, "world": world, "seed": seed, "finished": r.finished,
        "noise_correlation_px": _NOISE_CORRELATION_PX,
        "distance_m": r.distance_m, "sim_s": r.sim_seconds, "wall_s": wall, "cpu_s": cpu,
        "nodes": r.nodes, "loop_closures": r.loop_closures, "collisions": r.collisions,
        "ate_rmse_m": r.ate_rmse_m, "ate_max_m": r.ate_max_m, "odom_ate_rmse_m": r.odom_ate_rmse_m,
        "ate_aligned_rmse_m": r.ate_aligned_rmse_m, "ate_aligned_max_m": r.ate_aligned_max_m,
        "aligned_turn_deg": r.aligned_turn_deg, "odom_ate_aligned_rmse_m": r.odom_ate_aligned_rmse_m,
        "slam_end_m": r.slam_end_error_m, "odom_end_m": r.odom_end_error_m,
        "end_ratio": r.slam_end_error_m / r.odom_end_error_m if r.odom_end_error_m > 0 else math.nan,
        "agreement": r.agreement, "agreement_tolerant": r.agreement_tolerant,
        "scans_timed": int(scan.size),
        "scan_cpu_median_ms": float(np.median(scan)) if scan.size else math.nan,
        "scan_cpu_p99_ms": float(np.percentile(scan, 99)) if scan.size else math.nan,
        "scan_cpu_max_ms": float(scan.max()) if scan.size else math.nan,
        "map_update_cpu_median_ms": (float(np.median(r.map_update_cpu_ms))
                                     if r.map_update_cpu_ms.size else math.nan),
        "low_feature_episodes": r.low_feature_episodes,
        "low_feature_matches": r.low_feature_matches,
        "cpu_reference_ms": reference_ms,
        "load_average_1min": round(os.getloadavg()[0], 2),
    }
    if name == "corridor":
        row["meets"] = bool(row["end_ratio"] <= TARGETS["corridor_end_ratio"])
    else:
        row["meets"] = bool(row["ate_aligned_rmse_m"] <= TARGETS["ate_rmse_m"]
                            and row["agreement"] >= TARGETS["agreement"]
                            and row["scan_cpu_median_ms"] <= TARGETS["scan_cpu_median_ms"]
                            and row["scan_cpu_p99_ms"] <= TARGETS["scan_cpu_p99_ms"])
    return row


def _series(bag: Path, topic: str) -> tuple[np.ndarray, np.ndarray]:
    from eddiebot.bag import BagReader
    from eddiebot.geometry import quaternion_to_yaw

    t, p = [], []
    with BagReader(bag) as reader:
        for m in reader.messages([topic]):
            msg = m.decode()
            q = msg.pose.pose.orientation
            t.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            p.append((msg.pose.pose.position.x, msg.pose.pose.position.y,
                      quaternion_to_yaw(q.x, q.y, q.z, q.w)))
    return np.array(t, dtype=np.int64), np.array(p)


def _interp(t: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    out = np.empty((len(q), 3))
    out[:, 0] = np.interp(q, t, p[:, 0])
    out[:, 1] = np.interp(q, t, p[:, 1])
    out[:, 2] = np.interp(q, t, np.unwrap(p[:, 2]))
    return out


#: odometry perturbation of an ensemble member (m, rad): far below anything physical, it only
#: changes floating-point rounding, which decides loop closures near their thresholds
PERTURBATION_SIGMA = 1e-9


def replay_one(name: str, bag: Path, overrides: dict[str, Any],
               node_time_gate: bool = False, perturbation: int = 0,
               profile: Path | None = None, optimum_every: int = 0) -> dict[str, Any]:
    """Replay a recorded run's bag and score it against its ground truth (``node_time_gate``:
    the node's ``minimum_time_interval`` gate too, as in the live run; ``perturbation`` > 0:
    every odometry pose gets seeded N(0, `PERTURBATION_SIGMA`) noise, one ensemble member;
    ``optimum_every`` N > 0: every N nodes, how far iSAM2's estimate is from the batch optimum
    of the factors it holds, `_isam_gap`)."""
    from eddiebot.bag import BagReader
    from eddiebot.cli.slam import _default_params
    from eddiebot.geometry import se2_compose
    from eddiebot.sim.worlds import load_world
    from eddiebot.slam import load_slam_config
    from eddiebot.slam.replay import check_bag_topics, replay_scans, scans_from_messages

    start = np.array(load_world(RUNS[name][0]).start, dtype=np.float64)
    config = load_slam_config(_default_params(), overrides=overrides)
    tg, pg = _series(bag, "/ground_truth/odom")
    to, po = _series(bag, "/odom")
    with BagReader(bag) as reader:
        types = {c.topic: c.type_name for c in reader.connections}
        topics = check_bag_topics(types, scan_topic="/scan", odom_topic=None, source=str(bag))
        log = scans_from_messages(((m.topic, m.timestamp, m.decode())
                                   for m in reader.messages(topics.all)),
                                  topics, odom_frame=config.odom_frame,
                                  base_frame=config.base_frame)
    odometry = [np.asarray(o, dtype=np.float64) for o in log.odometry]
    if perturbation:
        rng = np.random.default_rng(perturbation)
        odometry = [o + rng.normal(0.0, PERTURBATION_SIGMA, 3) for o in odometry]
    gaps: list[tuple[float, float]] = []
    if profile is None and not optimum_every:
        res = replay_scans(log.scans, odometry, config, sensor_offset=log.sensor_offset,
                           source=str(bag), node_time_gate=node_time_gate)
    else:
        import cProfile

        import eddiebot.slam.replay as replay_module

        prof = cProfile.Profile() if profile is not None else None
        plain = replay_module.SlamCore

        class _Hooked(plain):  # type: ignore[misc, valid-type]
            def process(self, *a: Any, **k: Any) -> Any:
                if prof is not None:
                    prof.enable()
                try:
                    return super().process(*a, **k)
                finally:
                    if prof is not None:
                        prof.disable()
                    if optimum_every:
                        gap = _isam_gap(self.graph, optimum_every)
                        if gap is not None:
                            gaps.append(gap)

        replay_module.SlamCore = _Hooked  # type: ignore[misc]
        try:
            res = replay_scans(log.scans, odometry, config, sensor_offset=log.sensor_offset,
                               source=str(bag), node_time_gate=node_time_gate)
        finally:
            replay_module.SlamCore = plain  # type: ignore[misc]
        if profile is not None and prof is not None:
            profile.parent.mkdir(parents=True, exist_ok=True)
            prof.dump_stats(str(profile))
    stamps, poses = res.trajectory()
    q = np.round(stamps * 1e9).astype(np.int64)
    est = se2_compose(np.broadcast_to(start, poses.shape), poses)
    gt = _interp(tg, pg, q)
    od = se2_compose(np.broadcast_to(start, poses.shape), _interp(to, po, q))
    err = np.hypot(*(est[:, :2] - gt[:, :2]).T)
    oerr = np.hypot(*(od[:, :2] - gt[:, :2]).T)
    aerr, turn = aligned_position_errors(est, gt)
    oaerr, _ = aligned_position_errors(od, gt)

    def drift(a: np.ndarray) -> float:
        d = np.unwrap(a[:, 2]) - gt[:, 2]
        d = (d - d[0] + np.pi) % (2 * np.pi) - np.pi
        return float(np.degrees(np.abs(d).max()))

    cpu = 1e3 * np.asarray(res.scan_cpu_s)
    return {
        "run": name, "overrides": " ".join(f"{k}:={v}" for k, v in overrides.items()) or "-",
        "perturbation": perturbation,
        "nodes": len(poses), "loop_closures": len(res.core.loop_closures),
        "ate_rmse_m": float(np.sqrt(np.mean(err**2))), "ate_max_m": float(err.max()),
        "slam_end_m": float(err[-1]), "odom_ate_rmse_m": float(np.sqrt(np.mean(oerr**2))),
        "ate_aligned_rmse_m": float(np.sqrt(np.mean(aerr**2))), "ate_aligned_max_m": float(aerr.max()),
        "aligned_turn_deg": float(np.degrees(turn)),
        "ate_aligned_evo_rmse_m": evo_ape_rmse(stamps, est, gt),
        "odom_ate_aligned_rmse_m": float(np.sqrt(np.mean(oaerr**2))),
        "odom_end_m": float(oerr[-1]), "end_ratio": float(err[-1] / oerr[-1]),
        "heading_drift_max_deg": drift(est),
        "odom_heading_drift_max_deg": drift(od),
        "scan_cpu_median_ms": float(np.median(cpu)), "scan_cpu_p99_ms": float(np.percentile(cpu, 99)),
        **_loop_errors(res.core, tg, pg),
        **({} if not gaps else {
            "isam_gap_checks": len(gaps),
            "isam_gap_half_chi2_median": float(np.median([g[0] for g in gaps])),
            "isam_gap_half_chi2_max": float(max(g[0] for g in gaps)),
            "isam_gap_position_max_m": float(max(g[1] for g in gaps)),
        }),
    }


#: a loop edge this far (m) from the ground-truth relation is a false loop (an aliased match)
FALSE_LOOP_M = 0.5


def _loop_errors(core: Any, truth_t: np.ndarray, truth_p: np.ndarray) -> dict[str, Any]:
    """Each loop edge against the ground-truth relation between its two nodes' scans: the
    largest and 95th-percentile position error, and the false loops (over `FALSE_LOOP_M`) the
    back end still holds in its estimate at the end (neither rejected nor held by the gate),
    with their nodes."""
    from eddiebot.geometry import se2_between
    from eddiebot.slam.pose_graph.edges import EdgeKind

    graph = core.graph
    out_of_estimate = set(graph.rejected) | set(graph.held)
    stamps = np.array([n.scan.stamp_ns for n in core.nodes], dtype=np.int64)
    truth = _interp(truth_t, truth_p, stamps)
    errors, false_in = [], []
    for k, e in enumerate(graph.edges):
        if e.kind != EdgeKind.LOOP:
            continue
        rel = se2_between(truth[e.i], truth[e.j])
        err = float(np.hypot(*(np.asarray(e.measurement)[:2] - rel[:2])))
        errors.append(err)
        if err > FALSE_LOOP_M and k not in out_of_estimate:
            false_in.append(f"{e.i}->{e.j} ({err:.2f} m)")
    arr = np.asarray(errors) if errors else np.zeros(1)
    return {"loop_error_max_m": float(arr.max()), "loop_error_p95_m": float(np.percentile(arr, 95)),
            "false_loops": int((arr > FALSE_LOOP_M).sum()), "false_loops_in_estimate": false_in}


def _isam_gap(graph: Any, every: int) -> tuple[float, float] | None:
    """After every ``every``-th node: the ½χ² by which iSAM2's current estimate exceeds the
    batch (Levenberg–Marquardt) optimum of exactly the factors iSAM2 holds, and the largest
    position difference between the two (m). iSAM2 stops short of that optimum by design: it
    relinearises a variable only once its update exceeds the relinearisation threshold, and
    back-substitutes only below cliques whose solution moved more than the wildfire threshold.
    Reads the estimate as the next scan's pose query would (no extra update), so the run is the
    same as without the check."""
    import gtsam

    isam = getattr(graph, "_isam", None)
    n = len(graph)
    if isam is None or n == 0 or n % every or getattr(graph, "_gap_checked", -1) == n:
        return None
    graph._gap_checked = n
    factors = gtsam.NonlinearFactorGraph()
    held = isam.getFactorsUnsafe()
    for i in range(held.size()):
        if held.exists(i):
            factors.push_back(held.at(i))
    estimate = isam.calculateEstimate()
    optimum = gtsam.LevenbergMarquardtOptimizer(factors, estimate).optimize()
    a = gtsam.utilities.extractPose2(estimate)
    b = gtsam.utilities.extractPose2(optimum)
    return (float(factors.error(estimate) - factors.error(optimum)),
            float(np.max(np.hypot(*(a[:, :2] - b[:, :2]).T))))


def main_replay(args: argparse.Namespace) -> int:
    import yaml

    overrides: dict[str, Any] = {}
    for item in args.set:
        key, value = item.split(":=", 1)
        overrides[key.strip()] = yaml.safe_load(value)
    rows = []
    summary = []
    for folder in args.replay:
        for name in args.worlds:
            bag = folder / name / "mapping_bag"
            if not bag.exists():
                print(f"{name}: no {bag}, skipped")
                continue
            members = []
            for k in range(max(1, args.ensemble)):
                members.append({"drive": folder.name, "node_time_gate": args.node_time_gate,
                                **replay_one(name, bag, overrides, args.node_time_gate, k,
                                             None if args.profile is None else
                                             args.profile / f"{folder.name}_{name}_{k}.prof",
                                             args.optimum_every)})
                print(members[-1], flush=True)
            rows += members
            if args.ensemble > 1:
                summary.append(_ensemble_row(members))
    print_table(rows, ["drive", "run", "perturbation", "nodes", "loop_closures", "ate_rmse_m",
                       "ate_max_m", "ate_aligned_rmse_m", "aligned_turn_deg", "slam_end_m",
                       "odom_ate_rmse_m", "odom_end_m", "end_ratio",
                       "heading_drift_max_deg",
                       "odom_heading_drift_max_deg", "scan_cpu_median_ms", "overrides"])
    if summary:
        print()
        print_table(summary, ["drive", "run", "members", "ate_rmse_mean_m", "ate_rmse_sd_m",
                              "ate_rmse_min_m", "ate_rmse_max_m", "ate_aligned_rmse_mean_m",
                              "ate_aligned_rmse_max_m", "end_ratio_median",
                              "overrides"])
    print(f"\nwrote {write_results(args.name, rows + summary)}")
    return 0


def _ensemble_row(members: list[dict[str, Any]]) -> dict[str, Any]:
    """Mean, spread and range of an ensemble's RMSE (one drive, one configuration)."""
    rmse = np.array([m["ate_rmse_m"] for m in members])
    aligned = np.array([m["ate_aligned_rmse_m"] for m in members])
    return {"drive": members[0]["drive"], "run": members[0]["run"], "summary": "ensemble",
            "members": len(members), "overrides": members[0]["overrides"],
            "ate_rmse_mean_m": float(rmse.mean()), "ate_rmse_sd_m": float(rmse.std(ddof=1)),
            "ate_rmse_min_m": float(rmse.min()), "ate_rmse_max_m": float(rmse.max()),
            "ate_aligned_rmse_mean_m": float(aligned.mean()),
            "ate_aligned_rmse_max_m": float(aligned.max()),
            "end_ratio_median": float(np.median([m["end_ratio"] for m in members])),
            "loop_closures_mean": float(np.mean([m["loop_closures"] for m in members]))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=list(RUNS), choices=list(RUNS))
    ap.add_argument("--seed", type=int, nargs="+", default=[0],
                    help="simulation seed(s); several run one after another into one file")
    ap.add_argument("--params", type=Path, default=None,
                    help="slam_toolbox parameter file (default: the package's config/slam.yaml)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="write maps and sessions here (default: a temporary folder)")
    ap.add_argument("--name", default="slam_sim", help="results file name (benchmarks/results/)")
    ap.add_argument("--record", action="store_true",
                    help="record /scan, /odom, /ground_truth/odom and TF of each run into "
                    "--keep DIR/<run>/mapping_bag (for eddie slam replay)")
    ap.add_argument("--replay", type=Path, nargs="+", default=None, metavar="DIR",
                    help="score the bags of earlier --keep DIR --record runs offline "
                    "(several DIRs: several drives)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME:=VALUE",
                    help="with --replay: override one SLAM parameter (repeatable)")
    ap.add_argument("--node-time-gate", action="store_true",
                    help="with --replay: also skip scans within minimum_time_interval of the "
                    "last processed one, as the node does (closer to the live run)")
    ap.add_argument("--ensemble", type=int, default=1, metavar="K",
                    help="with --replay: K replays per drive, member k > 0 with its odometry "
                    "perturbed by seeded 1e-9 noise (rounding-level: shows how far loop "
                    "decisions near their thresholds move the figure); prints mean and spread")
    ap.add_argument("--profile", type=Path, default=None, metavar="DIR",
                    help="with --replay: cProfile each drive's SlamCore.process calls into "
                    "DIR/<drive>_<run>_<member>.prof (inflates that run's CPU figures)")
    ap.add_argument("--optimum-every", type=int, default=0, metavar="N",
                    help="with --replay: every N nodes, iSAM2's distance from the batch optimum "
                         "of its own factors (isam_gap_* fields)")
    ap.add_argument("--noise-correlation-px", type=float, default=None,
                    help="the simulator's noise_correlation_px (Kinect depth-noise correlation "
                    "window, native pixels; default: the node's default)")
    args = ap.parse_args()
    if args.noise_correlation_px is not None:
        _sim_parameters({"noise_correlation_px": args.noise_correlation_px})
    if args.replay is not None:
        if args.name == "slam_sim":
            args.name = "slam_sim_replay"
        return main_replay(args)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or Path(tmp)
        for seed in args.seed:
            folder = out / f"s{seed}" if len(args.seed) > 1 else out
            for name in args.worlds:
                row = run_one(name, folder, seed, args.params,
                              args.record and args.keep is not None)
                rows.append(row)
                write_results(args.name, rows)  # after each run: an interrupted set keeps its runs
                print(f"{name}: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float)
                                              else f"{k} {v}"
                                              for k, v in row.items() if k not in ("run",)),
                      flush=True)
    print()
    print_table(rows, ["run", "seed", "finished", "distance_m", "sim_s", "nodes", "loop_closures",
                       "ate_rmse_m", "ate_max_m", "ate_aligned_rmse_m", "aligned_turn_deg",
                       "odom_ate_rmse_m", "slam_end_m", "odom_end_m", "agreement",
                       "scan_cpu_median_ms", "scan_cpu_p99_ms",
                       "low_feature_episodes", "meets"])
    path = write_results(args.name, rows)
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
