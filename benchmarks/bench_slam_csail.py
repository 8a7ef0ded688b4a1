"""2D SLAM on the raw MIT CSAIL log: speed (warm and cold) and agreement with the corrected run.

Speed: the whole 424 s log through the SLAM core in sync mode with slam_toolbox's sample
parameters (config/slam_defaults.yaml), on one core: CPU time of the replay, warm (numba
kernels compiled and cached, after a warm-up run in the same process), cold (a fresh
process with an empty numba cache, so JIT compilation is included) and cached (a second
fresh process, kernels loaded from numba's on-disk cache). Cartographer: 12×.

Accuracy: the corrected log's 406 scans are matched to raw scans by identical range arrays
(the corrected timestamps are truncated); the SLAM pose at each such scan is its node pose
carried forward by odometry from the latest node; one SE(2) aligns it to the corrected poses;
relative pose errors for pairs 1 s, 5 s and 30 s apart, and evo's APE. The same errors are
also given over the corrected scans that are SLAM nodes themselves (no odometry in between).

    python benchmarks/bench_slam_csail.py [--no-cold] [--name slam_csail]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import align_se2, evo_ape_rmse, rpe_by_time

from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.replay import replay_lasers

RAW = DATASETS / "slam2d" / "mit-csail" / "mit-csail.clf"
CORRECTED = DATASETS / "slam2d" / "mit-csail" / "csail-corrected.log.gz"
CONFIG = Path(__file__).resolve().parents[1] / "config" / "slam_defaults.yaml"

_COLD = """
import sys, time
sys.path.insert(0, {src!r})
t0, c0 = time.perf_counter(), time.process_time()
from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.replay import replay_lasers
log = read_carmen({raw!r})
r = replay_lasers(log.lasers, load_slam_config({cfg!r}))
print(time.process_time() - c0, time.perf_counter() - t0, r.cpu_s)
"""


def cold_run() -> dict[str, float]:
    """Two fresh processes sharing a new numba cache: the first compiles every kernel (cold),
    the second loads them from the on-disk cache (a usual start after the first ever run)."""
    src = str(Path(__file__).resolve().parents[1] / "src")
    row: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for label in ("cold", "cached"):
            out = subprocess.run(
                [sys.executable, "-c", _COLD.format(src=src, raw=str(RAW), cfg=str(CONFIG))],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            ).stdout.split()
            cpu_total, wall_total, replay_cpu = (float(v) for v in out[-3:])
            row[f"{label}_process_cpu_s"] = cpu_total
            row[f"{label}_process_wall_s"] = wall_total
            row[f"{label}_replay_cpu_s"] = replay_cpu
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-cold", action="store_true",
                        help="skip the cold and cached runs in fresh processes")
    parser.add_argument("--name", default="slam_csail", help="results file name (benchmarks/results/)")
    args = parser.parse_args()
    if not RAW.exists():
        print(f"missing {RAW}")
        return 0
    raw = read_carmen(RAW)
    config = load_slam_config(CONFIG)
    replay_lasers(raw.lasers, config)  # warm-up: numba kernels compiled or loaded
    t0 = time.perf_counter()
    result = replay_lasers(raw.lasers, config, source=str(RAW))
    wall = time.perf_counter() - t0
    row: dict[str, object] = {
        "log_duration_s": result.duration_s,
        "scans": result.scans,
        "nodes": len(result.core.nodes),
        "loops": len(result.core.loop_closures),
        "warm_cpu_s": result.cpu_s,
        "warm_wall_s": wall,
        "warm_realtime_factor": result.duration_s / result.cpu_s,
        "cartographer_realtime_factor": 12.0,
    }
    if not args.no_cold:
        row.update(cold_run())
        row["cold_realtime_factor"] = result.duration_s / float(row["cold_process_cpu_s"])  # type: ignore[arg-type]
        row["cached_realtime_factor"] = result.duration_s / float(row["cached_process_cpu_s"])  # type: ignore[arg-type]
    # accuracy against the corrected run
    corrected = read_carmen(CORRECTED)
    by_ranges = {rec.ranges.tobytes(): k for k, rec in enumerate(raw.lasers)}
    pairs = [
        (by_ranges[c.ranges.tobytes()], c)
        for c in corrected.lasers
        if c.ranges.tobytes() in by_ranges
    ]
    odom = np.array([r.odom_pose for r in raw.lasers])
    nodes = np.asarray(result.node_records)
    node_poses = result.core.node_poses()
    est, ref, stamps = [], [], []
    for k, c in pairs:
        n = int(np.searchsorted(nodes, k, side="right")) - 1
        if n < 0:
            continue
        est.append(se2_compose(node_poses[n], se2_between(odom[nodes[n]], odom[k])))
        ref.append(c.laser_pose)
        stamps.append(raw.lasers[k].timestamp)
    est_a = align_se2(np.array(est), np.array(ref))
    ref_a = np.array(ref)
    t = np.array(stamps)
    row["matched_scans"] = len(pairs)
    for delta in (1.0, 5.0, 30.0):
        m = rpe_by_time(est_a, ref_a, t, delta)
        row[f"rpe_{int(delta)}s_trans_mean_m"] = m["trans_mean_m"]
        row[f"rpe_{int(delta)}s_rot_mean_deg"] = m["rot_mean_deg"]
        row[f"rpe_{int(delta)}s_pairs"] = m["pairs"]
    row["ape_rmse_m_evo"] = evo_ape_rmse(t, est_a, ref_a)
    # the same at the corrected scans that are themselves SLAM nodes (no odometry in between)
    node_of = {int(k): i for i, k in enumerate(nodes)}
    sel = [(node_of[k], c) for k, c in pairs if k in node_of]
    e2 = align_se2(
        np.array([node_poses[i] for i, _ in sel]), np.array([c.laser_pose for _, c in sel])
    )
    r2 = np.array([c.laser_pose for _, c in sel])
    t2 = np.array([raw.lasers[int(nodes[i])].timestamp for i, _ in sel])
    row["node_matched_scans"] = len(sel)
    for delta in (1.0, 5.0, 30.0):
        m = rpe_by_time(e2, r2, t2, delta)
        row[f"node_rpe_{int(delta)}s_trans_mean_m"] = m["trans_mean_m"]
        row[f"node_rpe_{int(delta)}s_rot_mean_deg"] = m["rot_mean_deg"]
    odo = align_se2(odom[[k for k, _ in pairs]], ref_a)
    row["odom_rpe_30s_trans_mean_m"] = rpe_by_time(odo, ref_a, t, 30.0)["trans_mean_m"]
    print_table(
        [row],
        [
            "nodes",
            "loops",
            "warm_cpu_s",
            "warm_realtime_factor",
            "cold_process_cpu_s",
            "cold_realtime_factor",
            "cached_process_cpu_s",
            "cached_realtime_factor",
            "matched_scans",
        ],
    )
    print_table(
        [row],
        [
            "rpe_1s_trans_mean_m",
            "rpe_5s_trans_mean_m",
            "rpe_30s_trans_mean_m",
            "rpe_30s_rot_mean_deg",
            "ape_rmse_m_evo",
            "odom_rpe_30s_trans_mean_m",
        ],
    )
    print_table(
        [row],
        [
            "node_matched_scans",
            "node_rpe_1s_trans_mean_m",
            "node_rpe_5s_trans_mean_m",
            "node_rpe_30s_trans_mean_m",
            "node_rpe_30s_rot_mean_deg",
        ],
    )
    print(write_results(args.name, [row]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
