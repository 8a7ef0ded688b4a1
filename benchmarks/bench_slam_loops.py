"""Where a recorded simulator drive's SLAM trajectory goes wrong: per-node error, every loop
candidate, every graph edge against ground truth.

Replays one ``bench_slam_sim.py --keep DIR --record`` drive through `SlamCore` (with the
node's time gate, as live) and reports:

* the final and the online (at the time of the node) position and heading error along the
  route, beside wheel odometry's, every ``--every`` nodes;
* every loop-closure candidate the mapper verified: chain, coarse / fine response and
  variance, the verdict (``coarse_resp``, ``coarse_var``, ``fine_resp``, ``fine_var``, ``ok``)
  and the error of the fine match against the truth (the matched scan pose against where the
  truth puts it relative to the chain node's estimate at that time), split into forward /
  lateral in the scan's frame, with the median range of the scan's points;
* every graph edge's χ² against the truth (measurement − true relative pose), by kind.

    .venv/bin/python benchmarks/bench_slam_loops.py DIR --world warehouse [--set K:=V ...]
        [--every 8] [--name slam_loops]

Writes the summary to ``benchmarks/results/<--name>.json``.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import write_results
from bench_slam_sim import RUNS, _interp, _series

import eddiebot.slam.mapper as mapper_module
import eddiebot.slam.mapper.mapping as mapping_module
from eddiebot.geometry import se2_between, se2_compose, wrap_angle
from eddiebot.slam import loop_closure
from eddiebot.slam.scan_matcher import build_correlation_grid, match_scan


class _LoopLog:
    """Stands in for `verify_loop` in the mapper: verifies as it does and records each step."""

    def __init__(self) -> None:
        self.core: mapper_module.SlamCore | None = None
        self.tries: list[dict[str, Any]] = []

    def __call__(self, points: np.ndarray, prior: np.ndarray, chain: Any, ref: np.ndarray,
                 chain_pos: np.ndarray, **kw: Any) -> Any:
        assert self.core is not None
        coarse, fine = kw["coarse"], kw["fine"]
        rec: dict[str, Any] = {"idx": len(self.core.nodes) - 1, "chain": list(chain),
                               "chain_est": self.core.graph.poses[list(chain)].copy(),
                               "range_median": float(np.median(np.hypot(*points.T)))}
        cm = self._match(points, prior, ref, coarse)
        rec.update(coarse_response=cm.response, coarse_variance=float(max(cm.covariance[0, 0],
                                                                          cm.covariance[1, 1])))
        verdict = "ok"
        if not cm.response > kw["min_response_coarse"]:
            verdict = "coarse_resp"
        elif not (cm.covariance[0, 0] < kw["max_variance_coarse"]
                  and cm.covariance[1, 1] < kw["max_variance_coarse"]):
            verdict = "coarse_var"
        else:
            fm = self._match(points, cm.pose, ref, fine)
            var = float(np.linalg.eigvalsh(fm.covariance[:2, :2])[-1])
            rec.update(fine_response=fm.response, fine_variance=var, fine_pose=fm.pose.copy())
            if fm.response < kw["min_response_fine"]:
                verdict = "fine_resp"
            elif kw.get("max_variance_fine", 0.0) > 0.0 and var > kw["max_variance_fine"]:
                verdict = "fine_var"
        rec["verdict"] = verdict
        self.tries.append(rec)
        return loop_closure.verify_loop(points, prior, chain, ref, chain_pos, **kw)

    @staticmethod
    def _match(points: np.ndarray, prior: np.ndarray, ref: np.ndarray, params: Any) -> Any:
        world = loop_closure._transform(prior, points)
        half = 0.5 * params.search_dimension + 0.1
        bounds = (float(world[:, 0].min()) - half, float(world[:, 1].min()) - half,
                  float(world[:, 0].max()) + half, float(world[:, 1].max()) + half)
        grid = build_correlation_grid(ref, bounds, params.resolution, params.smear_deviation,
                                      loop_closure._levels_for(params))
        return match_scan(points, grid, prior, params)


def main() -> int:
    from eddiebot.bag import BagReader
    from eddiebot.cli.slam import _default_params
    from eddiebot.sim.worlds import load_world
    from eddiebot.slam import load_slam_config
    from eddiebot.slam.pose_graph import EdgeKind
    from eddiebot.slam.replay import check_bag_topics, scans_from_messages

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("drive", type=Path, help="a --keep DIR of bench_slam_sim.py --record")
    ap.add_argument("--world", default="warehouse", choices=list(RUNS))
    ap.add_argument("--set", action="append", default=[], metavar="NAME:=VALUE")
    ap.add_argument("--every", type=int, default=8, help="print every N-th node")
    ap.add_argument("--name", default="slam_loops")
    args = ap.parse_args()
    overrides = {k.strip(): yaml.safe_load(v)
                 for k, v in (item.split(":=", 1) for item in args.set)}
    cfg = load_slam_config(_default_params(), overrides=overrides)
    bag = args.drive / args.world / "mapping_bag"
    tg, pg = _series(bag, "/ground_truth/odom")
    with BagReader(bag) as reader:
        types = {c.topic: c.type_name for c in reader.connections}
        topics = check_bag_topics(types, scan_topic="/scan", odom_topic=None, source=str(bag))
        log = scans_from_messages(((m.topic, m.timestamp, m.decode())
                                   for m in reader.messages(topics.all)),
                                  topics, odom_frame=cfg.odom_frame, base_frame=cfg.base_frame)
    recorder = _LoopLog()
    original = mapping_module.verify_loop
    mapping_module.verify_loop = recorder  # type: ignore[assignment]
    try:
        core = mapper_module.SlamCore(cfg, sensor_offset=log.sensor_offset)
        recorder.core = core
        stamps, online = [], []
        last: int | None = None
        for k, scan in enumerate(log.scans):
            if last is not None and scan.stamp_ns - last < cfg.minimum_time_interval * 1e9 * 0.999:
                continue
            out = core.process(scan, log.odometry[k], expected_beams=scan.ranges.size)
            if out.status is mapper_module.ProcessStatus.ADDED and out.pose is not None:
                last = scan.stamp_ns
                stamps.append(scan.stamp_ns)
                online.append(out.pose)
    finally:
        mapping_module.verify_loop = original
    n = len(stamps)
    start = np.broadcast_to(np.array(load_world(RUNS[args.world][0]).start, dtype=float), (n, 3))
    gt = _interp(tg, pg, np.array(stamps, dtype=np.int64))
    est = se2_compose(start, core.node_poses())
    onl = se2_compose(start, np.array(online))
    odo = se2_compose(start, np.array([nd.odom_pose for nd in core.nodes]))

    def err(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.hypot(*(p[:, :2] - gt[:, :2]).T), np.degrees(wrap_angle(p[:, 2] - gt[:, 2]))

    (e, he), (eo, heo), (ed, _) = err(est), err(onl), err(odo)
    print(" node      x      y | final m  head° | online m  head° | odometry m")
    for k in range(0, n, args.every):
        print(f"{k:5d} {gt[k, 0]:6.2f} {gt[k, 1]:6.2f} | {e[k]:7.3f} {he[k]:+6.2f} |"
              f" {eo[k]:8.3f} {heo[k]:+6.2f} | {ed[k]:.3f}")
    # loop candidates against the truth
    offset = core.sensor_offset
    print("\n node chain       coarse resp/var  fine resp/var     verdict     err m  fwd    lat"
          "    head°  range")
    accepted_err = []
    for t in recorder.tries:
        line = (f"{t['idx']:5d} {t['chain'][0]:4d}-{t['chain'][-1]:<4d} "
                f"{t['coarse_response']:6.2f} {t['coarse_variance']:7.3f}")
        if "fine_pose" in t:
            p = t["fine_pose"]
            ce = t["chain_est"]
            j = int(np.argmin(np.hypot(ce[:, 0] - p[0], ce[:, 1] - p[1])))
            c = t["chain"][j]
            true = se2_compose(se2_compose(ce[j], se2_between(gt[c], gt[t["idx"]])), offset)
            d = p[:2] - true[:2]
            cs, sn = math.cos(true[2]), math.sin(true[2])
            fwd, lat = cs * d[0] + sn * d[1], -sn * d[0] + cs * d[1]
            t["error_m"] = float(np.hypot(*d))
            line += (f" {t['fine_response']:6.2f} {t['fine_variance']:7.4f}  {t['verdict']:11s}"
                     f" {t['error_m']:6.3f} {fwd:+.3f} {lat:+.3f}"
                     f" {math.degrees(wrap_angle(p[2] - true[2])):+6.2f}  {t['range_median']:.1f}")
            if t["verdict"] == "ok":
                accepted_err.append((t["error_m"], t["range_median"]))
        else:
            line += f" {'':22s}{t['verdict']}"
        print(line)
    # graph edges against the truth
    chi2: dict[str, list[float]] = {}
    for edge in core.graph.edges:
        z = se2_between(gt[edge.i], gt[edge.j])
        r = np.asarray(edge.measurement) - z
        r[2] = wrap_angle(r[2])
        kind = edge.kind.value
        if edge.kind is EdgeKind.ODOMETRY and edge.j - edge.i > 1:
            kind = "odometry_span"
        chi2.setdefault(kind, []).append(float(r @ np.linalg.solve(edge.covariance, r)))
    print()
    for kind, v in chi2.items():
        a = np.array(v)
        print(f"{kind:14s} edges {a.size:4d}  χ² vs truth median {np.median(a):6.2f}"
              f"  > 16: {int(np.sum(a > 16))}")
    verdicts = Counter(t["verdict"] for t in recorder.tries)
    print(f"\nnodes {n}, loops {len(core.loop_closures)}, candidates {dict(verdicts)}, "
          f"RMSE {math.sqrt(float(np.mean(e**2))):.3f} m (online {math.sqrt(float(np.mean(eo**2))):.3f},"
          f" odometry {math.sqrt(float(np.mean(ed**2))):.3f})")
    row = {
        "drive": str(args.drive), "world": args.world, "overrides": overrides, "nodes": n,
        "loop_closures": len(core.loop_closures), "candidates": dict(verdicts),
        "ate_rmse_m": math.sqrt(float(np.mean(e**2))),
        "online_rmse_m": math.sqrt(float(np.mean(eo**2))),
        "odom_rmse_m": math.sqrt(float(np.mean(ed**2))),
        "accepted_loop_error_m": [a for a, _ in accepted_err],
        "accepted_loop_range_median_m": [b for _, b in accepted_err],
        "edge_chi2_median": {k: float(np.median(v)) for k, v in chi2.items()},
        "edge_chi2_over_16": {k: int(np.sum(np.array(v) > 16)) for k, v in chi2.items()},
    }
    print(f"wrote {write_results(args.name, [row])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
