"""What each eddiebot-only SLAM parameter that the upstream sample configuration leaves on buys,
on real logs: each one switched off alone, against everything as configured.

Logs: Intel and ACES corrected logs with degraded odometry (benchmarks/degrade_odometry.py,
seed 1), config/slam_defaults.yaml, sync mode, as benchmarks/bench_slam_degraded.py; figures:
ATE RMSE after one SE(2) alignment and the relative pose error of pairs 1–10 m apart along the
path, against the corrected poses (GMapping's output: 0.05–0.07 m off the true relations per
Kümmerle et al. 2009), the loops closed and the replay's CPU time. ``max_odometry_jump`` is
2 m in every run, above the corrected logs' largest step between scans (1.3 m on Intel).

    python benchmarks/bench_slam_extras.py [intel] [aces] [--name slam_extras]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import align_se2, rpe_by_distance
from degrade_odometry import degrade_odometry

from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.replay import replay_lasers

LOGS = {
    "intel": DATASETS / "slam2d" / "intel" / "intel-corrected.log.gz",
    "aces": DATASETS / "slam2d" / "aces" / "aces-corrected.log.gz",
}
CONFIG = Path(__file__).resolve().parents[1] / "config" / "slam_defaults.yaml"

#: each extra, and the value that switches it off (Karto's / slam_toolbox's behaviour)
EXTRAS: dict[str, tuple[str, Any]] = {
    "ICP polish": ("use_icp_refinement", False),
    "slip re-search": ("slip_search_dimension", 0.0),
    "DCS loop kernel": ("loop_robust_kernel", "none"),
}


def run(name: str, overrides: dict[str, Any]) -> dict[str, Any]:
    log = read_carmen(LOGS[name])
    ref = np.array([r.laser_pose for r in log.lasers])
    odom = degrade_odometry(ref, seed=1)
    config = dataclasses.replace(load_slam_config(CONFIG), max_odometry_jump=2.0, **overrides)
    t0 = time.process_time()
    result = replay_lasers(log.lasers, config, odometry=list(odom))
    cpu = time.process_time() - t0
    idx = np.asarray(result.node_records)
    est = result.core.node_poses()
    aligned = align_se2(est, ref[idx])
    ate = float(np.sqrt(np.mean(np.sum((aligned[:, :2] - ref[idx][:, :2]) ** 2, axis=1))))
    rpe = rpe_by_distance(est, ref[idx])
    return {
        "log": name,
        "nodes": len(idx),
        "loops": len(result.core.loop_closures),
        "ate_rmse_m": ate,
        "rpe_trans_mean_m": rpe["trans_mean_m"],
        "rpe_rot_mean_deg": rpe["rot_mean_deg"],
        "cpu_s": cpu,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="*", metavar="LOG",
                        help=f"logs to run: {', '.join(LOGS)} (default: all)")
    parser.add_argument("--name", default="slam_extras", help="results file name")
    args = parser.parse_args()
    unknown = [n for n in args.logs if n not in LOGS]
    if unknown:
        parser.error(f"unknown log {', '.join(unknown)} (choose from {', '.join(LOGS)})")
    rows: list[dict[str, Any]] = []
    for name in args.logs or list(LOGS):
        if not LOGS[name].exists():
            continue
        rows.append({"extra": "(as configured)", **run(name, {})})
        for label, (key, off) in EXTRAS.items():
            rows.append({"extra": f"{label} off ({key}: {off})", **run(name, {key: off})})
    print_table(rows, ["log", "extra", "nodes", "loops", "ate_rmse_m", "rpe_trans_mean_m",
                       "rpe_rot_mean_deg", "cpu_s"])
    print(write_results(args.name, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
