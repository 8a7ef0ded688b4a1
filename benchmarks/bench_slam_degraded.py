"""SLAM on corrected CARMEN logs (Intel, ACES) with seeded degraded odometry.

The corrected laser poses are the reference; odometry is rebuilt from them with 5 % of the
distance as noise, 3°/m heading noise and four 0.3 m / 15° slips (benchmarks/degrade_odometry.py,
seed 1). The SLAM core runs in sync mode with the upstream sample parameters
(config/slam_defaults.yaml); errors are relative pose errors over every pair of processed
scans 1–10 m apart along the reference path, beside the degraded odometry's.

    python benchmarks/bench_slam_degraded.py [intel] [aces]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import evo_ape_rmse, rpe_by_distance
from degrade_odometry import degrade_odometry

from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.replay import replay_lasers

LOGS = {
    "intel": DATASETS / "slam2d" / "intel" / "intel-corrected.log.gz",
    "aces": DATASETS / "slam2d" / "aces" / "aces-corrected.log.gz",
}
CONFIG = Path(__file__).resolve().parents[1] / "config" / "slam_defaults.yaml"


def run_one(name: str, seed: int = 1) -> dict[str, object]:
    log = read_carmen(LOGS[name])
    ref = np.array([r.laser_pose for r in log.lasers])
    odom = degrade_odometry(ref, seed=seed)
    config = load_slam_config(CONFIG)
    t0 = time.process_time()
    result = replay_lasers(log.lasers, config, odometry=list(odom), source=str(LOGS[name]))
    cpu = time.process_time() - t0
    stamps = np.array([r.timestamp for r in log.lasers])
    idx = np.asarray(result.node_records)  # (the Intel log has stamps going backwards)
    est = result.core.node_poses()
    slam = rpe_by_distance(est, ref[idx])
    odo = rpe_by_distance(odom[idx], ref[idx])
    return {
        "log": name,
        "scans": len(log.lasers),
        "nodes": len(idx),
        "loops": len(result.core.loop_closures),
        "slips_recovered": result.warnings.get("slip", 0),
        "slam_trans_mean_m": slam["trans_mean_m"],
        "slam_rot_mean_deg": slam["rot_mean_deg"],
        "odom_trans_mean_m": odo["trans_mean_m"],
        "odom_rot_mean_deg": odo["rot_mean_deg"],
        "pairs": slam["pairs"],
        "slam_ape_rmse_m_evo": evo_ape_rmse(stamps[idx], est, ref[idx]),
        "odom_ape_rmse_m_evo": evo_ape_rmse(stamps[idx], odom[idx], ref[idx]),
        "cpu_s": cpu,
        "log_duration_s": result.duration_s,
        "seed": seed,
        "slam": slam,
        "odometry": odo,
    }


def main() -> int:
    names = [a for a in sys.argv[1:] if a in LOGS] or list(LOGS)
    rows = [run_one(n) for n in names if LOGS[n].exists()]
    print_table(
        rows,
        [
            "log",
            "nodes",
            "loops",
            "slips_recovered",
            "slam_trans_mean_m",
            "slam_rot_mean_deg",
            "odom_trans_mean_m",
            "odom_rot_mean_deg",
            "slam_ape_rmse_m_evo",
            "cpu_s",
        ],
    )
    print(write_results("slam_degraded", rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
