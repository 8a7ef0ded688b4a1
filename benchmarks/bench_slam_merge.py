"""Merging two sessions of one place (slam_toolbox's add_submap / merge_submaps, here
`eddiebot.slam.merge`) on real logs: Intel and ACES, each cut in two halves mapped as two
sessions, the second with its odometry in another frame.

Each corrected CARMEN log's laser poses are the reference. Odometry is degraded as in
``degrade_odometry.py`` (5 % of distance, 3°/m heading, four 0.3 m / 15° slips; seed 1); the
second half's odometry is then moved by ``SECOND_FRAME`` (the sessions' map frames differ by
a rigid transform the merge must find). Both halves are mapped with config/slam_defaults.yaml
(sync, every scan), and the second is placed by scan matching alone (no pose given) and
merged into the first.

Per log: the placement's error against the true transform (each session's nodes fitted onto
the reference by one SE(2) transform; the first's fit inverted, composed with the second's),
the relocalised samples and scan-matched links (and their lowest response), the placement and merge CPU time, and the merged
graph's node positions against the reference (one SE(2) alignment; the RMSE of the
second half's nodes and of all) beside the first half alone.

    python benchmarks/bench_slam_merge.py
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import align_se2
from degrade_odometry import degrade_odometry

from eddiebot.geometry import se2_compose, se2_inverse
from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper import ProcessStatus, SlamCore
from eddiebot.slam.merge import merge_session, place_session
from eddiebot.slam.scan import Scan

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config" / "slam_defaults.yaml"
LOGS = {
    "intel": DATASETS / "slam2d" / "intel" / "intel-corrected.log.gz",
    "aces": DATASETS / "slam2d" / "aces" / "aces-corrected.log.gz",
}
#: odometry degradation (`degrade_odometry`); empty: its defaults
DEGRADE: dict[str, Any] = {}
#: the second session's odometry frame in the first one's
SECOND_FRAME = np.array([7.0, -4.0, 1.2])


def _map(lasers: list[Any], odom: np.ndarray) -> tuple[SlamCore, list[int]]:
    # one scan per ~0.6 m of travel, up to 1.3 m on Intel: above max_odometry_jump's 1 m
    config = dataclasses.replace(load_slam_config(CONFIG), max_odometry_jump=2.0)
    core = SlamCore(config)
    records = []
    for k, rec in enumerate(lasers):
        scan = Scan(rec.ranges, rec.angles, 0.0, rec.range_max, round(rec.timestamp * 1e9))
        out = core.process(scan, odom[k], expected_beams=scan.ranges.size)
        if out.status is ProcessStatus.ADDED:
            records.append(k)
    core.node_poses()
    return core, records


def _fit(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """The SE(2) transform (x, y, theta) that best fits ``est``'s positions onto ``ref``."""
    a, b = est[:, :2], ref[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    t = cb - r @ ca
    return np.array([t[0], t[1], np.arctan2(r[1, 0], r[0, 0])])


def _rmse(est: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((est[:, :2] - ref[:, :2]) ** 2, axis=1))))


def _run(name: str, path: Path) -> dict[str, Any]:
    log = read_carmen(path)
    lasers = log.lasers
    # the laser poses as the robot's, as bench_slam_degraded.py
    robot_ref = np.array([r.laser_pose for r in lasers])
    odom = degrade_odometry(robot_ref, seed=1, **DEGRADE)
    half = len(lasers) // 2
    t0 = time.perf_counter()
    first, rec1 = _map(lasers[:half], odom[:half])
    second_odom = se2_compose(np.broadcast_to(se2_inverse(SECOND_FRAME), odom[half:].shape), odom[half:])
    second, rec2 = _map(lasers[half:], second_odom)
    map_s = time.perf_counter() - t0
    rec2_abs = [half + k for k in rec2]
    # the true transform: each session fitted onto the reference, one composed with the
    # other's inverse (each session's own drift stays in its fit)
    truth = se2_compose(se2_inverse(_fit(first.node_poses(), robot_ref[rec1])),
                        _fit(second.node_poses(), robot_ref[rec2_abs]))
    first_alone = _rmse(align_se2(first.node_poses(), robot_ref[rec1]), robot_ref[rec1])
    cpu0, wall0 = time.process_time(), time.perf_counter()
    placement = place_session(first, second)
    place_cpu = time.process_time() - cpu0
    ids = merge_session(first, second, placement)
    merge_cpu = time.process_time() - cpu0 - place_cpu
    wall = time.perf_counter() - wall0
    est = first.node_poses()
    refs = robot_ref[rec1 + rec2_abs]
    aligned = align_se2(est, refs)
    err_t = placement.transform - truth
    return {
        "log": name,
        "scans": len(lasers),
        "nodes_first": len(rec1),
        "nodes_second": len(ids),
        "relocalized": placement.relocalized,
        "links": len(placement.links),
        "link_response_min": min((lk.response for lk in placement.links), default=float("nan")),
        "place_err_m": float(np.hypot(err_t[0], err_t[1])),
        "place_err_deg": float(np.degrees(abs(np.remainder(err_t[2] + np.pi, 2 * np.pi) - np.pi))),
        "place_cpu_s": place_cpu,
        "merge_cpu_s": merge_cpu,
        "merge_wall_s": wall,
        "map_wall_s": map_s,
        "rmse_first_alone_m": first_alone,
        "rmse_merged_all_m": _rmse(aligned, refs),
        "rmse_merged_second_m": _rmse(aligned[len(rec1):], refs[len(rec1):]),
    }


def main() -> int:
    rows = []
    for name, path in LOGS.items():
        if not path.exists():
            print(f"missing {path}")
            continue
        rows.append(_run(name, path))
    if not rows:
        return 0
    print_table(rows, list(rows[0]))
    print(write_results("slam_merge", rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
