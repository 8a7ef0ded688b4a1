"""Pose-graph back end on g2o benchmarks: incremental iSAM2 node by node, and false loops.

For intel.g2o and manhattan.g2o:

1. a batch Levenberg–Marquardt solve (the clean optimum, beside the GTSAM 4.3 figure in the
   datasets README);
2. the nodes fed one at a time with their edges through iSAM2, loop edges (j != i + 1) marked
   robust as the SLAM front end marks them: per-node update time (median, p99, wall and CPU),
   final ½χ², deviation from the clean optimum;
3. the same replay with 5 % and 10 % false loop closures added (random node pairs, random
   relative poses within ±1 m / ±0.5 rad, the information of a typical loop edge; seed 7), each
   arriving with its later node: with the χ² gate (the default `PoseGraph`, DCS kernel; the
   SLAM mapper's), with the gate and no kernel ("gate only"), and without the gate (kernel
   alone, and no protection at all). Gated replays report the live estimate
   after the last node (``live_*``) and the estimate after `PoseGraph.reconsider`, the final
   consistency pass (the unprefixed figures);
4. the same false loops solved in one batch from the file's initial guess (chained odometry):
   with the gate (swept node by node, then polished) and without it (kernel annealed).

Deviation = max / mean position distance from the clean optimum.

    python benchmarks/bench_slam_backend.py [--graphs intel manhattan] [--shares 0.05 0.1]
        [--runs clean incremental batch] [--handlings "gate+dcs" "gate only" "dcs only" none]

Results go to benchmarks/results/slam_backend.json (slam_backend_<graph>.json for one graph).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results

from eddiebot.geometry import se2_compose
from eddiebot.slam import EdgeKind, PoseGraph
from eddiebot.slam.io import PoseGraphFile, build_pose_graph, read_g2o

FILES = {
    "intel": (DATASETS / "slam2d" / "intel" / "intel.g2o", 22.50),
    "manhattan": (DATASETS / "posegraph" / "manhattan.g2o", 1774.5),
}

# (i, j, measurement, covariance, false?)
EdgeRow = tuple[int, int, np.ndarray, np.ndarray, bool]


def edge_rows(data: PoseGraphFile, share: float, seed: int = 7) -> list[EdgeRow]:
    """The file's edges plus ``share`` × their number of false loop closures."""
    rows: list[EdgeRow] = [
        (int(i), int(j), z, np.linalg.inv(info), False)
        for (i, j), z, info in zip(data.edge_index, data.measurements, data.information)
    ]
    rng = np.random.default_rng(seed)
    loops = [e for e, (i, j) in enumerate(data.edge_index) if j != i + 1]
    cov = np.linalg.inv(data.information[loops[0]] if loops else data.information[0])
    n = len(data.poses)
    for _ in range(round(share * len(data.edge_index))):
        i, j = sorted(rng.choice(n, size=2, replace=False))
        z = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)])
        rows.append((int(i), int(j), z, cov, True))
    return rows


def _is_loop(row: EdgeRow) -> bool:
    return row[4] or row[1] != row[0] + 1


def _deviation(poses: np.ndarray, clean: np.ndarray) -> tuple[float, float]:
    dev = np.hypot(*(poses[:, :2] - clean[:, :2]).T)
    return float(dev.max()), float(dev.mean())


def _decisions(graph: PoseGraph, source: list[int], rows: list[EdgeRow]) -> tuple[int, int]:
    """(true loops left out, false loops let in); ``source[k]`` = row of graph edge k."""
    out = set(graph.rejected) | set(graph.held)
    dropped = sum(1 for k in out if not rows[source[k]][4])
    n_false = sum(1 for r in rows if r[4])
    return dropped, n_false - sum(1 for k in out if rows[source[k]][4])


def replay(data: PoseGraphFile, rows: list[EdgeRow], **kwargs: Any) -> dict[str, Any]:
    """Feed nodes one at a time with the edges ending at them; time each update."""
    graph = PoseGraph(optimizer="isam2", **kwargs)
    by_last: dict[int, list[int]] = {}
    for r, row in enumerate(rows):
        by_last.setdefault(max(row[0], row[1]), []).append(r)
    source: list[int] = []
    wall, cpu = [], []
    constrained = {0}
    pending: list[int] = []
    for n in range(len(data.poses)):
        t0, c0 = time.perf_counter(), time.process_time()
        here = by_last.get(n, [])
        if n == 0:
            graph.add_node(data.poses[0])
        else:
            odo = [r for r in here if not rows[r][4] and rows[r][0] == n - 1]
            prev = graph.pose(n - 1)
            graph.add_node(se2_compose(prev, rows[odo[0]][2]) if odo else prev)
        for r in here:
            i, j, z, cov, _ = rows[r]
            loop = _is_loop(rows[r])
            graph.add_edge(
                i, j, z, cov, kind=EdgeKind.LOOP if loop else EdgeKind.ODOMETRY, robust=loop
            )
            source.append(r)
        # a node whose edges all lead to later nodes waits for them (iSAM2 cannot take an
        # unconstrained variable)
        pending.append(n)
        changed = True
        while changed:
            changed = False
            for p in list(pending):
                if p in constrained or graph.neighbours(p) & constrained:
                    constrained.add(p)
                    pending.remove(p)
                    changed = True
        if not pending:
            graph.optimize()
        graph.pose(n)  # what the front end reads back after each update
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    w, c = np.array(wall) * 1e3, np.array(cpu) * 1e3
    live = graph.poses
    live_dropped, live_in = _decisions(graph, source, rows)
    # the final consistency pass (what a session does before it saves its map)
    c0 = time.process_time()
    graph.reconsider()
    final_cpu = time.process_time() - c0
    dropped, let_in = _decisions(graph, source, rows)
    return {
        "poses": graph.poses,
        "live_poses": live,
        "live_true_dropped": live_dropped,
        "live_false_in": live_in,
        "final_pass_cpu_s": final_cpu,
        "half_chi2": graph.half_chi2(include_rejected=False),
        "median_ms": float(np.median(w)),
        "p99_ms": float(np.percentile(w, 99)),
        "max_ms": float(w.max()),
        "cpu_median_ms": float(np.median(c)),
        "cpu_p99_ms": float(np.percentile(c, 99)),
        "cpu_total_s": float(c.sum() / 1e3),
        "true_dropped": dropped,
        "false_in": let_in,
        "isam_recoveries": graph.isam_recoveries,
        "late_accepts": graph.late_accepts,
        "marginal_queries": graph.marginal_queries,
    }


def batch(data: PoseGraphFile, rows: list[EdgeRow], **kwargs: Any) -> dict[str, Any]:
    """Every node at its initial guess, every edge, one `optimize` (Levenberg–Marquardt)."""
    graph = PoseGraph(optimizer="levenberg_marquardt", **kwargs)
    for pose in data.poses:
        graph.add_node(pose)
    for i, j, z, cov, false in rows:
        loop = _is_loop((i, j, z, cov, false))
        graph.add_edge(i, j, z, cov, kind=EdgeKind.LOOP if loop else EdgeKind.ODOMETRY, robust=loop)
    t0, c0 = time.perf_counter(), time.process_time()
    graph.optimize()
    dropped, let_in = _decisions(graph, list(range(len(rows))), rows)
    return {
        "poses": graph.poses,
        "s": time.perf_counter() - t0,
        "cpu_s": time.process_time() - c0,
        "true_dropped": dropped,
        "false_in": let_in,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--graphs", nargs="+", default=list(FILES), choices=list(FILES))
    parser.add_argument("--shares", nargs="*", type=float, default=[0.05, 0.10])
    parser.add_argument(
        "--no-baselines", action="store_true", help="skip the runs without the gate"
    )
    parser.add_argument(
        "--runs",
        nargs="+",
        default=["clean", "incremental", "batch"],
        choices=["clean", "incremental", "batch"],
        help="which parts to run (clean = the node-by-node replay without false loops)",
    )
    parser.add_argument(
        "--handlings",
        nargs="+",
        default=["gate+dcs", "dcs only", "none"],
        choices=["gate+dcs", "gate only", "dcs only", "none"],
        help="false-loop handlings to run: the χ² gate with the DCS kernel (the SLAM mapper's), "
        "the gate with no kernel, the kernel alone, no protection (incremental only); "
        "default all but 'gate only'",
    )
    parser.add_argument("--out", default=None, help="results name (benchmarks/results/NAME.json)")
    parser.add_argument(
        "--gate",
        type=float,
        default=None,
        help="χ² gate probability of the gated runs (default: PoseGraph's, 0.999)",
    )
    parser.add_argument(
        "--isolated",
        type=float,
        default=None,
        help="isolated_false_pass of the gated runs (default: PoseGraph's)",
    )
    parser.add_argument(
        "--factorization",
        default="qr",
        choices=["qr", "cholesky"],
        help="iSAM2 elimination of every run (PoseGraph's; cholesky falls back to QR for good "
        "when an update is indeterminate, counted in isam2_isam_recoveries)",
    )
    args = parser.parse_args(argv)
    gated: dict[str, Any] = {"robust_kernel": "dcs", "factorization": args.factorization}
    if args.gate is not None:
        gated["gate_probability"] = args.gate
    if args.isolated is not None:
        gated["isolated_false_pass"] = args.isolated
    rows_out: list[dict[str, Any]] = []
    false_rows: list[dict[str, Any]] = []
    for name in args.graphs:
        path, reference = FILES[name]
        if not path.exists():
            print(f"skipping {name}: {path} not found")
            continue
        data = read_g2o(path)
        lm = build_pose_graph(data)
        t0, c0 = time.perf_counter(), time.process_time()
        lm.optimize()
        lm_s, lm_cpu = time.perf_counter() - t0, time.process_time() - c0
        clean = lm.poses
        row: dict[str, Any] = {
            "graph": name,
            "poses": len(data.poses),
            "edges": len(data.edge_index),
            "readme_half_chi2": reference,
            "lm_half_chi2": lm.half_chi2(),
            "lm_s": lm_s,
            "lm_cpu_s": lm_cpu,
        }
        if "clean" in args.runs:
            inc = replay(data, edge_rows(data, 0.0), **gated)
            row["isam2_half_chi2"] = inc["half_chi2"]
            row["isam2_max_dev_m"], row["isam2_mean_dev_m"] = _deviation(inc["poses"], clean)
            live = _deviation(inc["live_poses"], clean)
            row["isam2_live_max_dev_m"], row["isam2_live_mean_dev_m"] = live
            row.update(
                {
                    f"isam2_{k}": v
                    for k, v in inc.items()
                    if k not in ("poses", "live_poses", "half_chi2")
                }
            )
        rows_out.append(row)
        for share in args.shares:
            rows = edge_rows(data, share)
            bare = {**gated, "robust_kernel": "none"}
            variants: list[tuple[str, str, dict[str, Any]]] = [
                ("incremental", "gate+dcs", gated), ("incremental", "gate only", bare)
            ]
            if "incremental" not in args.runs:
                variants = []
            elif not args.no_baselines:
                variants += [
                    ("incremental", "dcs only", {**gated, "gate_probability": None}),
                    ("incremental", "none",
                     {**gated, "robust_kernel": "none", "gate_probability": None}),
                ]
            if "batch" in args.runs:
                variants.append(("batch", "gate+dcs", gated))
                variants.append(("batch", "gate only", bare))
            if "batch" in args.runs and not args.no_baselines:
                variants.append(
                    ("batch", "dcs only", {"robust_kernel": "dcs", "gate_probability": None})
                )
            variants = [v for v in variants if v[1] in args.handlings]
            for mode, label, kwargs in variants:
                res: dict[str, Any] = (replay if mode == "incremental" else batch)(
                    data, rows, **kwargs
                )
                dmax, dmean = _deviation(res.pop("poses"), clean)
                out = {"graph": name, "false_share": share, "mode": mode, "handling": label}
                out.update(max_dev_m=dmax, mean_dev_m=dmean)
                if "live_poses" in res:
                    lmax, lmean = _deviation(res.pop("live_poses"), clean)
                    out.update(live_max_dev_m=lmax, live_mean_dev_m=lmean)
                out.update(res)
                false_rows.append(out)
                print(
                    f"{name} {share:.0%} {mode} {label}: max {dmax:.4g} m, mean {dmean:.4g} m"
                    f" (true dropped {res['true_dropped']}, false in {res['false_in']})",
                    flush=True,
                )
    name = args.out or "slam_backend"
    if args.out is None and sorted(args.graphs) != sorted(FILES):
        name += "_" + "_".join(args.graphs)
    path = write_results(name, rows_out + false_rows)
    print_table(
        rows_out,
        [
            "graph",
            "poses",
            "edges",
            "readme_half_chi2",
            "lm_half_chi2",
            "lm_s",
            "isam2_half_chi2",
            "isam2_live_max_dev_m",
            "isam2_max_dev_m",
            "isam2_true_dropped",
            "isam2_late_accepts",
            "isam2_median_ms",
            "isam2_p99_ms",
            "isam2_cpu_median_ms",
            "isam2_cpu_p99_ms",
        ],
    )
    if false_rows:
        print_table(
            false_rows,
            [
                "graph",
                "false_share",
                "mode",
                "handling",
                "live_max_dev_m",
                "max_dev_m",
                "mean_dev_m",
                "live_true_dropped",
                "true_dropped",
                "false_in",
                "late_accepts",
                "cpu_median_ms",
                "cpu_p99_ms",
                "cpu_s",
            ],
        )
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
