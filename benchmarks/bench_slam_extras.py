"""What each eddiebot-only SLAM extra buys on real logs: Karto's algorithm as upstream (every
extra off), the upstream sample configuration as the code runs it (the extras on by default),
and each of those extras switched off alone.

Logs: Intel and ACES corrected logs with degraded odometry as benchmarks/bench_slam_degraded.py
(5 % distance and 3°/m heading noise, ten 0.3 m / 15° slips, seeds 1–3),
config/slam_defaults.yaml, sync mode. Figures as there, against the corrected poses (GMapping's
output: 0.05–0.07 m off the true relations per Kümmerle et al. 2009): the revisit error (pairs
within 3 m of each other, ≥ 30 m apart along the path), ATE RMSE after one SE(2) alignment, the
relative pose error of pairs 1–10 m apart along the path, the loops closed and the replay's CPU
time. ``max_odometry_jump`` is 2 m, above the corrected logs' largest step between scans
(1.3 m on Intel), in every run but Karto's (0: no jump check).

The extras on under the sample configuration, and what switches each off:

* ICP polish: ``use_icp_refinement: false``;
* slip re-search: ``slip_search_dimension: 0``;
* DCS loop kernel: ``loop_robust_kernel: none``;
* χ² loop gate: no parameter; the pose graph is built with ``gate_probability=None``;
* path-length loop chains: no parameter; chains counted by nodes only, as Karto counts them
  (`bench_slam_degraded.karto_chains`).

    python benchmarks/bench_slam_extras.py [intel] [aces] [--seeds 1 2 3] [--name slam_extras]
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results
from _slam_metrics import align_se2, revisit_error, rpe_by_distance
from bench_slam_degraded import CONFIG, LOGS, karto_chains
from degrade_odometry import degrade_odometry

from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper import state
from eddiebot.slam.replay import replay_lasers


@contextlib.contextmanager
def no_gate() -> Iterator[None]:
    """Loop closures added to the pose graph without the χ² gate (``gate_probability=None``)."""
    original = state.PoseGraph
    state.PoseGraph = functools.partial(original, gate_probability=None)  # type: ignore[misc]
    try:
        yield
    finally:
        state.PoseGraph = original  # type: ignore[misc]


Patch = Callable[[], contextlib.AbstractContextManager[None]]

#: extra → (parameter overrides that switch it off, code patches that switch it off)
EXTRAS: dict[str, tuple[dict[str, Any], tuple[Patch, ...]]] = {
    "ICP polish": ({"use_icp_refinement": False}, ()),
    "slip re-search": ({"slip_search_dimension": 0.0}, ()),
    "DCS loop kernel": ({"loop_robust_kernel": "none"}, ()),
    "χ² loop gate": ({}, (no_gate,)),
    "path-length chains": ({}, (karto_chains,)),
}

#: every extra off: Karto's algorithm as slam_toolbox runs it (GTSAM's iSAM2 still solves)
KARTO: tuple[dict[str, Any], tuple[Patch, ...]] = (
    {
        **{k: v for overrides, _ in EXTRAS.values() for k, v in overrides.items()},
        "max_odometry_jump": 0.0,
        "max_odometry_jump_heading": 0.0,
    },
    tuple(p for _, patches in EXTRAS.values() for p in patches),
)


def run(name: str, seed: int, overrides: dict[str, Any], patches: tuple[Patch, ...]) -> dict[str, Any]:
    log = read_carmen(LOGS[name])
    ref = np.array([r.laser_pose for r in log.lasers])
    odom = degrade_odometry(ref, seed=seed, slips=10)
    config = dataclasses.replace(load_slam_config(CONFIG), max_odometry_jump=2.0)
    config = dataclasses.replace(config, **overrides).validated()
    t0 = time.process_time()
    with contextlib.ExitStack() as stack:
        for patch in patches:
            stack.enter_context(patch())
        result = replay_lasers(log.lasers, config, odometry=list(odom), source=str(LOGS[name]))
    cpu = time.process_time() - t0
    idx = np.asarray(result.node_records)
    est = result.core.node_poses()
    aligned = align_se2(est, ref[idx])
    ate = float(np.sqrt(np.mean(np.sum((aligned[:, :2] - ref[idx][:, :2]) ** 2, axis=1))))
    rpe = rpe_by_distance(est, ref[idx])
    revisit = revisit_error(est, ref[idx])
    return {
        "log": name,
        "seed": seed,
        "nodes": len(idx),
        "loops": len(result.core.loop_closures),
        "slips_recovered": result.warnings.get("slip", 0),
        "revisit_trans_mean_m": revisit.get("trans_mean_m"),
        "ate_rmse_m": ate,
        "rpe_trans_mean_m": rpe["trans_mean_m"],
        "rpe_rot_mean_deg": rpe["rot_mean_deg"],
        "cpu_s": cpu,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="*", metavar="LOG",
                        help=f"logs to run: {', '.join(LOGS)} (default: all)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3],
                        help="odometry degradation seeds (default 1 2 3)")
    parser.add_argument("--name", default="slam_extras", help="results file name")
    args = parser.parse_args()
    unknown = [n for n in args.logs if n not in LOGS]
    if unknown:
        parser.error(f"unknown log {', '.join(unknown)} (choose from {', '.join(LOGS)})")
    variants: list[tuple[str, dict[str, Any], tuple[Patch, ...]]] = [
        ("(sample config, extras on)", {}, ()),
        ("every extra off (Karto)", *KARTO),
        *((f"{label} off", *off) for label, off in EXTRAS.items()),
    ]
    rows: list[dict[str, Any]] = []
    for name in args.logs or list(LOGS):
        if not LOGS[name].exists():
            continue
        for seed in args.seeds:
            for label, overrides, patches in variants:
                row = {"variant": label, **run(name, seed, overrides, patches)}
                print(row, flush=True)
                rows.append(row)
    print_table(rows, ["log", "seed", "variant", "nodes", "loops", "slips_recovered",
                       "revisit_trans_mean_m",
                       "ate_rmse_m", "rpe_trans_mean_m", "rpe_rot_mean_deg", "cpu_s"])
    print(write_results(args.name, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
