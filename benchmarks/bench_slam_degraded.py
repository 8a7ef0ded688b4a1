"""SLAM on corrected CARMEN logs (Intel, ACES) with seeded degraded odometry.

The corrected laser poses are the reference; odometry is rebuilt from them with 5 % of the
distance as noise, 3°/m heading noise and ten 0.3 m / 15° slips (benchmarks/degrade_odometry.py,
seeds 1–3). The SLAM core runs in sync mode with the upstream sample parameters
(config/slam_defaults.yaml). Errors: relative pose errors over every pair of processed scans
1–10 m apart along the reference path; the *revisit* error, over pairs within 3 m of each
other but at least 30 m apart along the path (only a closed loop gets these right); ATE after
one SE(2) alignment (evo) — each beside the degraded odometry's.

Each log also runs with Karto's candidate chains (a run of ``loop_match_minimum_chain_size``
nodes, never counted by path length) to show what eddiebot's chain rule buys.

Two further figures say how far the reference itself can be trusted at this scale:

* ``floor``: each processed scan matched (correlative search + point-to-line ICP, the core's
  sequential matcher without the odometry penalty) against the ``scan_buffer_size`` processed
  scans before it, all at their *reference* poses; the relative pose error of these
  independently re-matched poses against the reference. A matcher that agreed with the
  reference to the millimetre would score ~0 here; what it scores is the reference's own
  local inconsistency, a floor no scan-alignment estimate can get below in this metric.
* ``consistency``: a reference-free sharpness figure (`_slam_metrics.scan_consistency`) of the
  SLAM, reference and odometry trajectories: mean distance from each scan's end points to the
  nearest end point of the ten scans before it.

    python benchmarks/bench_slam_degraded.py [intel] [aces] [--seeds 1 2 3] [--name slam_degraded]
        [--chains eddiebot karto] [--graph NAME=VALUE ...]

``--graph NAME=VALUE`` overrides an option of the mapper's `PoseGraph` (e.g.
``gate_probability=none``: no χ² gate, the loop kernel alone decides).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import evo_ape_rmse, revisit_error, rpe_by_distance, scan_consistency
from degrade_odometry import degrade_odometry

from eddiebot.geometry import se2_transform_points
from eddiebot.slam import SlamConfig, load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper import mapping, matcher_params
from eddiebot.slam.mapper import state as mapper_state
from eddiebot.slam.pose_graph import PoseGraph
from eddiebot.slam.replay import replay_lasers
from eddiebot.slam.scan_matcher import build_correlation_grid, match_scan, refine_icp

LOGS = {
    "intel": DATASETS / "slam2d" / "intel" / "intel-corrected.log.gz",
    "aces": DATASETS / "slam2d" / "aces" / "aces-corrected.log.gz",
}
CONFIG = Path(__file__).resolve().parents[1] / "config" / "slam_defaults.yaml"


def rematch_reference(
    poses: np.ndarray, points: list[np.ndarray], config: SlamConfig
) -> np.ndarray:
    """Each scan re-matched against the ``scan_buffer_size`` scans before it at ``poses``."""
    params = matcher_params(config, penalize=False)
    window = config.scan_buffer_size
    half = 0.5 * params.search_dimension + 0.05
    out = poses.copy()
    for k in range(window, len(poses)):
        ref = np.concatenate(
            [se2_transform_points(poses[j], points[j]) for j in range(k - window, k)]
        )
        world = se2_transform_points(poses[k], points[k])
        if ref.shape[0] < 10 or world.shape[0] < 10:
            continue
        lo, hi = world.min(axis=0) - half, world.max(axis=0) + half
        grid = build_correlation_grid(
            ref, (lo[0], lo[1], hi[0], hi[1]), params.resolution, params.smear_deviation
        )
        match = match_scan(points[k], grid, poses[k], params)
        refined, share = refine_icp(points[k], ref, match.pose)
        moved = float(np.hypot(*(refined[:2] - match.pose[:2])))
        ok = share >= 0.5 and moved <= 2.0 * params.smear_deviation + params.resolution
        out[k] = refined if ok else match.pose
    return out


@contextlib.contextmanager
def graph_options(options: dict[str, Any]) -> Iterator[None]:
    """The mapper's `PoseGraph` built with ``options`` over its own arguments."""
    original = mapper_state.PoseGraph
    if not options:
        yield
        return

    def build(**kwargs: Any) -> PoseGraph:
        return original(**{**kwargs, **options})

    mapper_state.PoseGraph = build  # type: ignore[assignment,misc]
    try:
        yield
    finally:
        mapper_state.PoseGraph = original  # type: ignore[misc]


def parse_graph_option(text: str) -> tuple[str, Any]:
    """``NAME=VALUE`` (VALUE a number, true/false or none) for `graph_options`."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    low = value.strip().lower()
    if low == "none":
        return name, None
    if low in ("true", "false"):
        return name, low == "true"
    try:
        number = float(value)
    except ValueError:
        return name, value
    return name, int(number) if number.is_integer() and "." not in value else number


@contextlib.contextmanager
def karto_chains() -> Iterator[None]:
    """Loop candidate chains by node count only, as Karto counts them."""
    original = mapping.find_loop_candidates

    def by_count(*args: Any, **kwargs: Any) -> Any:
        kwargs.pop("min_chain_length", None)
        return original(*args, **kwargs)

    mapping.find_loop_candidates = by_count  # type: ignore[assignment]
    try:
        yield
    finally:
        mapping.find_loop_candidates = original  # type: ignore[assignment]


def run_one(
    name: str, seed: int = 1, chains: str = "eddiebot", graph: dict[str, Any] | None = None
) -> dict[str, object]:
    log = read_carmen(LOGS[name])
    ref = np.array([r.laser_pose for r in log.lasers])
    odom = degrade_odometry(ref, seed=seed, slips=10)
    # one scan per ~0.6 m of travel, up to 1.3 m on Intel: above max_odometry_jump's 1 m
    config = dataclasses.replace(load_slam_config(CONFIG), max_odometry_jump=2.0)
    t0 = time.process_time()
    with (
        karto_chains() if chains == "karto" else contextlib.nullcontext(),
        graph_options(graph or {}),
    ):
        result = replay_lasers(log.lasers, config, odometry=list(odom), source=str(LOGS[name]))
    cpu = time.process_time() - t0
    stamps = np.array([r.timestamp for r in log.lasers])
    idx = np.asarray(result.node_records)  # (the Intel log has stamps going backwards)
    est = result.core.node_poses()
    slam = rpe_by_distance(est, ref[idx])
    odo = rpe_by_distance(odom[idx], ref[idx])
    revisit = revisit_error(est, ref[idx])
    odo_revisit = revisit_error(odom[idx], ref[idx])
    points = [n.points for n in result.core.nodes]
    floor = rpe_by_distance(rematch_reference(ref[idx], points, config), ref[idx])
    consistency = {
        "slam": scan_consistency(result.core.sensor_poses(), points),
        "reference": scan_consistency(ref[idx], points),
        "odometry": scan_consistency(odom[idx], points),
    }
    return {
        "log": name,
        "chains": chains,
        "scans": len(log.lasers),
        "nodes": len(idx),
        "loops": len(result.core.loop_closures),
        "slips_recovered": result.warnings.get("slip", 0),
        "slam_trans_mean_m": slam["trans_mean_m"],
        "slam_rot_mean_deg": slam["rot_mean_deg"],
        "odom_trans_mean_m": odo["trans_mean_m"],
        "odom_rot_mean_deg": odo["rot_mean_deg"],
        "pairs": slam["pairs"],
        "revisit_trans_mean_m": revisit.get("trans_mean_m"),
        "revisit_trans_p95_m": revisit.get("trans_p95_m"),
        "revisit_rot_mean_deg": revisit.get("rot_mean_deg"),
        "revisit_pairs": revisit["pairs"],
        "odom_revisit_trans_mean_m": odo_revisit.get("trans_mean_m"),
        "floor_trans_mean_m": floor["trans_mean_m"],
        "floor_rot_mean_deg": floor["rot_mean_deg"],
        "consistency_slam_m": consistency["slam"]["mean_m"],
        "consistency_reference_m": consistency["reference"]["mean_m"],
        "slam_ape_rmse_m_evo": evo_ape_rmse(stamps[idx], est, ref[idx]),
        "odom_ape_rmse_m_evo": evo_ape_rmse(stamps[idx], odom[idx], ref[idx]),
        "cpu_s": cpu,
        "log_duration_s": result.duration_s,
        "seed": seed,
        "graph_options": dict(graph or {}),
        "slam": slam,
        "odometry": odo,
        "floor": floor,
        "revisit": revisit,
        "consistency": consistency,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="*", metavar="LOG",
                        help=f"logs to run: {', '.join(LOGS)} (default: all)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3],
                        help="odometry degradation seeds (default 1 2 3)")
    parser.add_argument("--name", default="slam_degraded", help="results file name (benchmarks/results/)")
    parser.add_argument("--chains", nargs="+", default=["eddiebot", "karto"],
                        choices=["eddiebot", "karto"], help="loop candidate chains to run")
    parser.add_argument("--graph", nargs="+", type=parse_graph_option, default=[],
                        metavar="NAME=VALUE",
                        help="PoseGraph option over the mapper's (e.g. gate_probability=none)")
    args = parser.parse_args()
    unknown = [n for n in args.logs if n not in LOGS]
    if unknown:
        parser.error(f"unknown log {', '.join(unknown)} (choose from {', '.join(LOGS)})")
    names = args.logs or list(LOGS)
    rows = [
        run_one(n, seed, chains, dict(args.graph))
        for n in names
        if LOGS[n].exists()
        for seed in args.seeds
        for chains in args.chains
    ]
    print_table(
        rows,
        [
            "log",
            "seed",
            "chains",
            "nodes",
            "loops",
            "slips_recovered",
            "revisit_trans_mean_m",
            "revisit_trans_p95_m",
            "odom_revisit_trans_mean_m",
            "slam_trans_mean_m",
            "slam_rot_mean_deg",
            "floor_trans_mean_m",
            "slam_ape_rmse_m_evo",
            "cpu_s",
        ],
    )
    print(write_results(args.name, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
