"""Lifelong mapping on the MIT CSAIL log: a second pass over the same log must not double
the graph, its memory or its CPU.

Pass 1 maps the raw log in mapping mode (config/slam_defaults.yaml, sync, every scan) and
saves the session. Pass 2 loads it, starts at its first node (START_AT_FIRST_NODE), runs the
same log again and saves; pass 3 does the same from pass 2's session; in one of three set-ups:

* ``mapping``: mapping mode continues the session (every pass adds its nodes: the baseline);
* ``lifelong_sample``: lifelong mode with slam_toolbox's ``mapper_params_lifelong.yaml``
  scores (removal below 0.04, 0.06 per overlapping scan);
* ``lifelong_defaults``: lifelong mode with slam_toolbox's code defaults (removal below 0.10,
  0.5 per overlapping scan).

Per pass: nodes in the graph at its end (live, and marginalised), the scans' bytes held
(ranges, angles and end points of the live nodes), the process's resident memory, CPU per
processed scan and per added node, and quality against the corrected log:

* the pass's trajectory as in ``bench_slam_csail.py`` (each corrected scan's pose carried by
  odometry from the pass's latest node, one SE(2) alignment): relative pose error 1 s / 5 s /
  30 s apart and evo's APE (a removed node counts at the pose it had when removed);
* the map: the graph's live nodes that are corrected scans, from both passes, one SE(2)
  alignment: relative pose error over every pair 1-10 m apart on the corrected poses (a node
  of one pass against one of the other included) and APE.

    python benchmarks/bench_slam_lifelong.py
"""

from __future__ import annotations

import gc
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from _slam_metrics import align_se2, evo_ape_rmse, rpe_by_time

from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper import ProcessStatus, SlamCore
from eddiebot.slam.scan import Scan
from eddiebot.slam.session import load_session, save_session

ROOT = Path(__file__).resolve().parents[1]
RAW = DATASETS / "slam2d" / "mit-csail" / "mit-csail.clf"
CORRECTED = DATASETS / "slam2d" / "mit-csail" / "csail-corrected.log.gz"
CONFIG = ROOT / "config" / "slam_defaults.yaml"
LIFELONG_SAMPLE = ROOT / "tests" / "data" / "slam_toolbox" / "mapper_params_lifelong.yaml"


def _rss_mb() -> float:
    gc.collect()
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _scan_mb(core: SlamCore) -> float:
    total = sum(
        n.scan.ranges.nbytes + n.scan.angles.nbytes + n.points.nbytes for n in core.nodes
    )
    return total / 2**20


_PASS_NS = 10**12
"""Each pass's scans are stamped this much later than the last's (1000 s, beyond the log)."""


def _run(core: SlamCore, lasers: list[Any], offset_ns: int = 0) -> tuple[list[int], list[int], float]:
    """Every scan through the core; returns (log index, node id) of the nodes added and the
    CPU time (s)."""
    records, ids = [], []
    cpu = 0.0
    for k, rec in enumerate(lasers):
        stamp = round(rec.timestamp * 1e9) + offset_ns
        scan = Scan(rec.ranges, rec.angles, 0.0, rec.range_max, stamp)
        t0 = time.process_time()
        out = core.process(scan, rec.odom_pose, expected_beams=scan.ranges.size)
        cpu += time.process_time() - t0
        if out.status is ProcessStatus.ADDED and out.node_id is not None:
            records.append(k)
            ids.append(out.node_id)
    t0 = time.process_time()
    core.node_poses()  # pending work belongs to the pass
    return records, ids, cpu + time.process_time() - t0


def _quality(
    core: SlamCore, records: list[int], ids: list[int], lasers: list[Any], pairs: list[tuple[int, Any]]
) -> dict[str, float]:
    """The pass's trajectory against the corrected log (see the module docstring)."""
    odom = np.array([r.odom_pose for r in lasers])
    poses = core.node_poses()
    rec = np.asarray(records)
    est, ref, stamps = [], [], []
    for k, c in pairs:
        n = int(np.searchsorted(rec, k, side="right")) - 1
        if n < 0:
            continue
        est.append(se2_compose(poses[ids[n]], se2_between(odom[rec[n]], odom[k])))
        ref.append(c.laser_pose)
        stamps.append(lasers[k].timestamp)
    ref_a = np.array(ref)
    est_a = align_se2(np.array(est), ref_a)
    t = np.array(stamps)
    row: dict[str, float] = {}
    for delta in (1.0, 5.0, 30.0):
        m = rpe_by_time(est_a, ref_a, t, delta)
        row[f"rpe_{int(delta)}s_trans_mean_m"] = m["trans_mean_m"]
        row[f"rpe_{int(delta)}s_rot_mean_deg"] = m["rot_mean_deg"]
    ape = evo_ape_rmse(t, est_a, ref_a)
    row["ape_rmse_m"] = float("nan") if ape is None else ape
    return row


def _map_quality(
    core: SlamCore, node_log: list[int], by_log: dict[int, Any]
) -> dict[str, float]:
    """The graph's live nodes that are corrected scans, from every pass, aligned by one SE(2):
    relative pose error over every pair 1-10 m apart on the corrected poses (a node of one
    pass against a node of another included), and their APE."""
    gone = set(core.graph.removed_nodes)
    poses = core.node_poses()
    sel = [(n, by_log[k]) for n, k in enumerate(node_log) if n not in gone and k in by_log]
    ref = np.array([c.laser_pose for _, c in sel])
    est = align_se2(np.array([poses[n] for n, _ in sel]), ref)
    ii, jj = np.triu_indices(len(sel), k=1)
    d = np.hypot(ref[jj, 0] - ref[ii, 0], ref[jj, 1] - ref[ii, 1])
    keep = (d >= 1.0) & (d <= 10.0)
    de = se2_between(est[ii[keep]], est[jj[keep]])
    dr = se2_between(ref[ii[keep]], ref[jj[keep]])
    trans = np.hypot(de[:, 0] - dr[:, 0], de[:, 1] - dr[:, 1])
    ape = np.sqrt(np.mean(np.sum((est[:, :2] - ref[:, :2]) ** 2, axis=1)))
    return {
        "map_nodes_scored": len(sel),
        "map_rpe_1_10m_trans_mean_m": float(trans.mean()),
        "map_rpe_1_10m_trans_p95_m": float(np.percentile(trans, 95)),
        "map_ape_rmse_m": float(ape),
    }


def _pass_row(
    name: str, core: SlamCore, records: list[int], ids: list[int], cpu: float,
    processed: int, lasers: list[Any], pairs: list[tuple[int, Any]], node_log: list[int],
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "pass": name,
        "graph_nodes": core.graph.live_nodes,
        "nodes_added": len(ids),
        "nodes_removed": len(core.graph.removed_nodes),
        "edges": len(core.graph.edges) - len(core.graph.removed_edges),
        "loops": len(core.loop_closures),
        "scan_mb": _scan_mb(core),
        "rss_mb": _rss_mb(),
        "cpu_s": cpu,
        "cpu_ms_per_scan": 1e3 * cpu / processed,
        "cpu_ms_per_node": 1e3 * cpu / max(1, len(ids)),
    }
    row.update(_quality(core, records, ids, lasers, pairs))
    row.update(_map_quality(core, node_log, dict(pairs)))
    return row


def main() -> int:
    if not RAW.exists():
        print(f"missing {RAW}")
        return 0
    raw = read_carmen(RAW)
    lasers = list(raw.lasers)
    corrected = read_carmen(CORRECTED)
    by_ranges = {rec.ranges.tobytes(): k for k, rec in enumerate(lasers)}
    pairs = [(by_ranges[c.ranges.tobytes()], c) for c in corrected.lasers
             if c.ranges.tobytes() in by_ranges]
    sample = yaml.safe_load(LIFELONG_SAMPLE.read_text())["slam_toolbox"]["ros__parameters"]
    sample_scores = {k: v for k, v in sample.items() if k.startswith("lifelong_")}
    base = load_slam_config(CONFIG)
    _run(SlamCore(base), lasers[:300])  # warm-up: numba kernels compiled or loaded
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        first = SlamCore(base)
        records, ids, cpu = _run(first, lasers)
        first_log = records
        rows.append(_pass_row("1: mapping", first, records, ids, cpu, len(lasers), lasers, pairs,
                              first_log))
        session = save_session(first, Path(tmp) / "csail.eslam")
        start = first.node_poses()[0]
        del first
        setups: list[tuple[str, str, dict[str, Any]]] = [
            ("mapping", "mapping", {}),
            ("lifelong_sample", "lifelong", sample_scores),
            ("lifelong_defaults", "lifelong", {}),
        ]
        for name, mode, overrides in setups:
            config = load_slam_config(CONFIG, overrides={**overrides, "mode": mode})
            saved, node_log = session, list(first_log)
            for n in (2, 3):
                core = load_session(saved, config)
                core.start_at(start)
                records, ids, cpu = _run(core, lasers, n * _PASS_NS)
                node_log = node_log + records
                rows.append(_pass_row(f"{n}: {name}", core, records, ids, cpu, len(lasers),
                                      lasers, pairs, node_log))
                saved = save_session(core, Path(tmp) / f"{name}-{n}.eslam")
                gone = set(core.graph.removed_nodes)
                node_log = [k for i, k in enumerate(node_log) if i not in gone]
                del core
    print_table(rows, ["pass", "graph_nodes", "nodes_added", "nodes_removed", "edges", "loops",
                       "scan_mb", "rss_mb", "cpu_s", "cpu_ms_per_scan", "cpu_ms_per_node"])
    print_table(rows, ["pass", "rpe_1s_trans_mean_m", "rpe_5s_trans_mean_m",
                       "rpe_30s_trans_mean_m", "rpe_30s_rot_mean_deg", "ape_rmse_m"])
    print_table(rows, ["pass", "map_nodes_scored", "map_rpe_1_10m_trans_mean_m",
                       "map_rpe_1_10m_trans_p95_m", "map_ape_rmse_m"])
    print(write_results("slam_lifelong", rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
