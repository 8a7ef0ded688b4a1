"""2D SLAM in simulated buildings with the Kinect-made scan (the demo's mapping stage).

Each run is `eddiebot.demo.mapping.run_mapping`: the simulator (default wheel slip and
encoder noise), Eddie's base stack, depthimage_to_laserscan and the SLAM node
(``config/slam.yaml``, sync processing) on a simulated clock, a scripted operator driving a
fixed route:

* ``office``: `OFFICE_LONG_ROUTE` (about 10 simulated minutes, every open room, the corridor
  and the start revisited);
* ``warehouse``: `WAREHOUSE_ROUTE` (about 10 simulated minutes, two loops through the aisles);
* ``corridor``: `CORRIDOR_ROUTE` of the RGB-D benchmark (down a 40 m low-feature hallway and
  back) — the low-feature warning and the end-point error against odometry alone;
* ``office-demo``: the demo's own `OFFICE_ROUTE` (about 5 minutes), to check the demo stage.

Figures: trajectory error of the SLAM nodes against ground truth (RMSE, max; the map frame
starts at the true start pose), wheel odometry's at the same times, end-point error of
SLAM's and odometry's final pose, agreement with the scan-height ground-truth map on the
cells both call known (strict; occupied within one cell), CPU time the SLAM core spent on
each processed scan in the node's thread (median, p99, max; targets ≤ 10 ms / ≤ 50 ms), and
the low-feature warnings (episodes logged, matches over the threshold). Prints a table and
writes ``benchmarks/results/slam_sim.json``.

    .venv/bin/python benchmarks/bench_slam_sim.py [--worlds office warehouse corridor office-demo]
        [--seed 0] [--params FILE] [--keep DIR [--record]]
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.demo.mapping import run_mapping
from eddiebot.demo.route import OFFICE_LONG_ROUTE, OFFICE_ROUTE, WAREHOUSE_ROUTE
from eddiebot.demo.vslam_stage import CORRIDOR_ROUTE

#: name → (world, route)
RUNS = {
    "office": ("office", OFFICE_LONG_ROUTE),
    "warehouse": ("warehouse", WAREHOUSE_ROUTE),
    "corridor": ("corridor", CORRIDOR_ROUTE),
    "office-demo": ("office", OFFICE_ROUTE),
}

TARGETS = {"ate_rmse_m": 0.05, "agreement": 0.95, "scan_cpu_median_ms": 10.0,
           "scan_cpu_p99_ms": 50.0, "corridor_end_ratio": 1.1}


#: what ``--record`` keeps: enough for ``eddie slam replay`` and for scoring against the truth
RECORD_TOPICS = ["/scan", "/odom", "/ground_truth/odom", "/tf", "/tf_static"]


def run_one(name: str, out: Path, seed: int, params: Path | None,
            record: bool = False) -> dict[str, Any]:
    world, route = RUNS[name]
    cpu0, wall0 = time.process_time(), time.perf_counter()
    r = run_mapping(out / name, world=world, route=route, seed=seed, record=record,
                    record_topics=RECORD_TOPICS, slam_params=params, wall_timeout_s=1800.0)
    cpu = time.process_time() - cpu0
    wall = time.perf_counter() - wall0
    scan = r.scan_cpu_ms
    row: dict[str, Any] = {
        "run": name, "world": world, "seed": seed, "finished": r.finished,
        "distance_m": r.distance_m, "sim_s": r.sim_seconds, "wall_s": wall, "cpu_s": cpu,
        "nodes": r.nodes, "loop_closures": r.loop_closures, "collisions": r.collisions,
        "ate_rmse_m": r.ate_rmse_m, "ate_max_m": r.ate_max_m, "odom_ate_rmse_m": r.odom_ate_rmse_m,
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
    }
    if name == "corridor":
        row["meets"] = bool(row["end_ratio"] <= TARGETS["corridor_end_ratio"])
    else:
        row["meets"] = bool(row["ate_rmse_m"] <= TARGETS["ate_rmse_m"]
                            and row["agreement"] >= TARGETS["agreement"]
                            and row["scan_cpu_median_ms"] <= TARGETS["scan_cpu_median_ms"]
                            and row["scan_cpu_p99_ms"] <= TARGETS["scan_cpu_p99_ms"])
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=list(RUNS), choices=list(RUNS))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--params", type=Path, default=None,
                    help="slam_toolbox parameter file (default: the package's config/slam.yaml)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="write maps and sessions here (default: a temporary folder)")
    ap.add_argument("--name", default="slam_sim", help="results file name (benchmarks/results/)")
    ap.add_argument("--record", action="store_true",
                    help="record /scan, /odom, /ground_truth/odom and TF of each run into "
                    "--keep DIR/<run>/mapping_bag (for eddie slam replay)")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep or Path(tmp)
        for name in args.worlds:
            row = run_one(name, out, args.seed, args.params, args.record and args.keep is not None)
            rows.append(row)
            print(f"{name}: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                          for k, v in row.items() if k not in ("run",)), flush=True)
    print()
    print_table(rows, ["run", "finished", "distance_m", "sim_s", "nodes", "loop_closures",
                       "ate_rmse_m", "ate_max_m", "odom_ate_rmse_m", "slam_end_m", "odom_end_m",
                       "agreement", "scan_cpu_median_ms", "scan_cpu_p99_ms",
                       "low_feature_episodes", "meets"])
    path = write_results(args.name, rows)
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
