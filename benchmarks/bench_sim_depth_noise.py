"""Simulated Kinect depth noise, independent vs spatially correlated (``noise_correlation_px``),
and what depthimage_to_laserscan makes of it on a flat wall (offline, no simulator run).

For each image size, scan_height and correlation window, frames of a wall facing the camera
at optical depth z (turned slightly about the vertical so its depth sweeps 3 disparity
steps across the image and the quantisation phase averages out) go through `kinect_depth`
and `depth_image_to_laserscan` (range_min 0.45, range_max 8, as config/sim launch); the
scan's central ±15° is compared with the same wall's noise-free scan:

* ``bias_m``: mean range error (m); ``bias_k``: bias / z² (the independent-noise nearest of
  10 rows is ≈ −2.2e-3);
* ``scan_sd_m``: standard deviation of the range error; ``scan_rho1``: correlation of the
  errors of neighbouring scan bins (how 'wavy' rather than 'grainy' the wall reads);
* per-pixel disparity σ and the neighbour correlation of the depth image itself
  (``pixel_sd_steps``, ``pixel_rho1_row``/``pixel_rho1_col``: σ 0.5 step plus 1/12 step²
  of quantisation; correlations as the window says);
* ``render_ms``/``render_cpu_ms``: `kinect_depth` wall and CPU time per frame (the pool
  built beforehand; ``pool_ms``: building it once).

    .venv/bin/python benchmarks/bench_sim_depth_noise.py [--frames 30] [--name sim_depth_noise_bias]

``--match`` measures instead what the noise alone does to the SLAM node's scan matcher:
at poses along the 10-minute office and warehouse routes, one frame's scan matched against
three other frames' scans from the same pose (true answer: zero) →
``benchmarks/results/sim_depth_noise_match.json``.

``--live-summary`` instead merges the live SLAM runs of ``bench_slam_sim.py
--noise-correlation-px N --name sim_depth_noise_live_<tag>`` (any number of seeds and
worlds; ``benchmarks/results/sim_depth_noise_live_*.json``) into
``benchmarks/results/sim_depth_noise_live.json`` (adding to the runs it already holds; a
newer run of the same world, seed and window replaces the older): every run, and per world and window the
mean / median over seeds of RMSE, end error, end ratio and map agreement, and the seeds on which the
correlated noise did better (paired by seed).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.perception import DepthToScanParams, depth_image_to_laserscan
from eddiebot.sim import KinectConfig, camera_info_msg, depth_image_msg
from eddiebot.sim.render import _correlated_pool, kinect_depth, noise_window_px

DEPTHS = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0)
#: (width, height, scan_height): the sim launch's 10 rows at the demo's 320×240 (20 native
#: rows) and at the Kinect's 640×480, and 5 rows at 320×240 (the same 10 native rows)
SETUPS = ((320, 240, 10), (640, 480, 10), (320, 240, 5))
WINDOWS = (0.0, 9.0, 13.0, 18.0)


def wall(cfg: KinectConfig, z: float) -> np.ndarray:
    h, w = cfg.depth.height, cfg.depth.width
    sweep = 3 * cfg.disparity_step_coeff * z * z
    return np.tile(np.linspace(z - sweep / 2, z + sweep / 2, w, dtype=np.float32), (h, 1))


def scan_errors(cfg: KinectConfig, z: float, scan_height: int, frames: int,
                row_selection: str = "nearest") -> np.ndarray:
    """(frames, bins) range error of the central ±15° (NaN where no return); the truth is the
    upstream rule on the noiseless image."""
    info = camera_info_msg(cfg.depth)
    exact = DepthToScanParams(range_min=0.45, range_max=8.0, scan_height=scan_height)
    params = replace(exact, row_selection=row_selection)
    ideal = wall(cfg, z)
    truth = np.asarray(depth_image_to_laserscan(depth_image_msg(ideal), info, exact).ranges,
                       dtype=np.float64)
    centre = np.abs(np.arange(truth.size) - truth.size / 2) < truth.size * 15 / 58
    out = []
    for i in range(frames):
        scan = depth_image_to_laserscan(depth_image_msg(kinect_depth(ideal, cfg, i)), info, params)
        out.append((np.asarray(scan.ranges, dtype=np.float64) - truth)[centre])
    return np.array(out)


def pixel_stats(cfg: KinectConfig, frames: int) -> dict[str, float]:
    c = 1.0 / cfg.disparity_step_coeff
    ideal = np.tile(np.linspace(2.0, 4.0, cfg.depth.width, dtype=np.float32), (cfg.depth.height, 1))
    flat = replace(cfg, dropout=0.0, edge_dropout=0.0)
    n = np.array([np.round(c / (kinect_depth(ideal, flat, i) / 1000.0)) - c / ideal
                  for i in range(frames)])
    row = np.corrcoef(n[:, :, 1:].reshape(-1), n[:, :, :-1].reshape(-1))[0, 1]
    col = np.corrcoef(n[:, 1:].reshape(-1), n[:, :-1].reshape(-1))[0, 1]
    return {"pixel_sd_steps": float(n.std()), "pixel_rho1_row": float(row),
            "pixel_rho1_col": float(col)}


def timing(cfg: KinectConfig, frames: int) -> dict[str, float]:
    ideal = wall(cfg, 4.0)
    window = noise_window_px(cfg, cfg.depth.width)
    _correlated_pool.cache_clear()
    t0 = time.perf_counter()
    kinect_depth(ideal, cfg, 0)
    pool_ms = 1e3 * (time.perf_counter() - t0) if window > 1 else 0.0
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(frames):
        kinect_depth(ideal, cfg, i)
    return {"pool_ms": pool_ms, "render_ms": 1e3 * (time.perf_counter() - w0) / frames,
            "render_cpu_ms": 1e3 * (time.process_time() - c0) / frames}


def _scan_points(cfg: KinectConfig, depth: np.ndarray, scan_height: int = 10) -> np.ndarray:
    info = camera_info_msg(cfg.depth)
    params = DepthToScanParams(range_min=0.45, range_max=8.0, scan_height=scan_height)
    scan = depth_image_to_laserscan(depth_image_msg(depth), info, params)
    r = np.asarray(scan.ranges, dtype=np.float64)
    a = scan.angle_min + scan.angle_increment * np.arange(r.size)
    ok = np.isfinite(r)
    return np.column_stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])])


def match_spread(windows: tuple[float, ...], poses_per_world: int, trials: int) -> int:
    """Scan-to-scan matching error with each noise model: at poses along the 10-minute
    routes (heading to the next waypoint), the scan of one frame is matched (the SLAM
    node's sequential matcher set-up from config/slam.yaml, prior 5 cm / 3 cm / 1° off)
    against a correlation grid of three other frames' scans from the same pose: the true
    answer is zero, so the error is what the depth noise alone does to a match."""
    from eddiebot.cli.slam import _default_params
    from eddiebot.demo.route import OFFICE_10MIN_ROUTE, WAREHOUSE_10MIN_ROUTE
    from eddiebot.sim import Renderer, load_world
    from eddiebot.slam import load_slam_config
    from eddiebot.slam.mapper import matcher_params
    from eddiebot.slam.scan_matcher import build_correlation_grid, match_scan

    params = matcher_params(load_slam_config(_default_params()))
    prior = np.array([0.05, -0.03, np.radians(1.0)])
    rows: list[dict[str, Any]] = []
    for world_name, route in (("office", OFFICE_10MIN_ROUTE), ("warehouse", WAREHOUSE_10MIN_ROUTE)):
        world = load_world(world_name)
        wps = [(w.x, w.y) for w in route]
        legs = [(a, b) for a, b in zip(wps, wps[1:]) if np.hypot(b[0] - a[0], b[1] - a[1]) > 0.5]
        pick = np.linspace(0, len(legs) - 1, poses_per_world).round().astype(int)
        poses = [(a[0], a[1], float(np.arctan2(b[1] - a[1], b[0] - a[0]))) for a, b in
                 (legs[i] for i in pick)]
        base = KinectConfig().at_resolution(320, 240)
        ideals = [Renderer(world, base).ideal_depth(p) for p in poses]
        warm = _scan_points(base, kinect_depth(ideals[0], base))  # compile before timing
        match_scan(warm, build_correlation_grid(warm, (-9.0, -9.0, 9.0, 9.0), params.resolution,
                                                params.smear_deviation, 1), prior, params)
        for px in windows:
            cfg = replace(base, noise_correlation_px=px)
            err, cpu = [], 0.0
            for k, ideal in enumerate(ideals):
                for t in range(trials):
                    f0 = 1000 * k + 4 * t
                    ref = np.concatenate([_scan_points(cfg, kinect_depth(ideal, cfg, f0 + j))
                                          for j in range(3)])
                    query = _scan_points(cfg, kinect_depth(ideal, cfg, f0 + 3))
                    if len(ref) < 20 or len(query) < 20:
                        continue
                    lo = np.minimum(ref.min(axis=0), query.min(axis=0)) - 0.6
                    hi = np.maximum(ref.max(axis=0), query.max(axis=0)) + 0.6
                    grid = build_correlation_grid(ref, (lo[0], lo[1], hi[0], hi[1]),
                                                  params.resolution, params.smear_deviation, 1)
                    c0 = time.process_time()
                    m = match_scan(query, grid, prior, params)
                    cpu += time.process_time() - c0
                    err.append(np.asarray(m.pose, dtype=np.float64))
            e = np.array(err)
            rows.append({"world": world_name, "window_native_px": px, "matches": len(e),
                         "rms_xy_m": float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
                         "p95_xy_m": float(np.percentile(np.hypot(e[:, 0], e[:, 1]), 95)),
                         "rms_theta_deg": float(np.degrees(np.sqrt(np.mean(e[:, 2] ** 2)))),
                         "match_cpu_ms": 1e3 * cpu / max(1, len(e))})
            print(rows[-1], flush=True)
    print()
    print_table(rows, ["world", "window_native_px", "matches", "rms_xy_m", "p95_xy_m",
                       "rms_theta_deg", "match_cpu_ms"])
    print(f"\nwrote {write_results('sim_depth_noise_match', rows)}")
    return 0


def live_summary() -> int:
    import json

    from _common import RESULTS

    merged = RESULTS / "sim_depth_noise_live.json"
    runs: list[dict[str, Any]] = json.loads(merged.read_text())["results"] if merged.exists() else []
    for path in sorted(RESULTS.glob("sim_depth_noise_live_*.json")):  # newer runs replace
        runs.extend(json.loads(path.read_text())["results"])
    key = {(r["run"], r["seed"], float(r["noise_correlation_px"] or 0.0)): r for r in runs}
    runs = sorted(key.values(), key=lambda r: (r["run"], r["noise_correlation_px"] or 0.0, r["seed"]))
    metrics = ("ate_rmse_m", "slam_end_m", "end_ratio", "agreement")
    summary: list[dict[str, Any]] = []
    for name in sorted({r["run"] for r in runs}):
        windows = sorted({float(r["noise_correlation_px"] or 0.0) for r in runs if r["run"] == name})
        for px in windows:
            rs = [r for r in runs if r["run"] == name and float(r["noise_correlation_px"] or 0.0) == px]
            row: dict[str, Any] = {"run": name, "window_native_px": px, "seeds": len(rs)}
            for m in metrics:
                v = np.array([r[m] for r in rs], dtype=np.float64)
                row[f"{m}_mean"], row[f"{m}_median"] = float(v.mean()), float(np.median(v))
            if px:  # paired with the independent noise on the same seeds
                base = {r["seed"]: r for r in runs
                        if r["run"] == name and not r["noise_correlation_px"]}
                pairs = [(r, base[r["seed"]]) for r in rs if r["seed"] in base]
                row["paired_seeds"] = len(pairs)
                row["rmse_better"] = sum(a["ate_rmse_m"] < b["ate_rmse_m"] for a, b in pairs)
                row["end_ratio_better"] = sum(a["end_ratio"] < b["end_ratio"] for a, b in pairs)
                row["agreement_better"] = sum(a["agreement"] > b["agreement"] for a, b in pairs)
            summary.append(row)
    print_table(runs, ["run", "seed", "noise_correlation_px", "ate_rmse_m", "ate_max_m",
                       "slam_end_m", "odom_end_m", "end_ratio", "agreement", "loop_closures",
                       "wall_s", "cpu_s"])
    print()
    print_table(summary, ["run", "window_native_px", "seeds", "ate_rmse_m_mean",
                          "ate_rmse_m_median", "slam_end_m_mean", "end_ratio_mean", "end_ratio_median",
                          "agreement_mean", "agreement_median", "paired_seeds", "rmse_better",
                          "end_ratio_better", "agreement_better"])
    out = json.loads(write_results("sim_depth_noise_live", runs).read_text())
    out["summary"] = summary
    merged.write_text(json.dumps(out, indent=2) + "\n")
    print(f"\nwrote {merged} (the sim_depth_noise_live_*.json it merged can go)")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--name", default="sim_depth_noise_bias")
    ap.add_argument("--live-summary", action="store_true",
                    help="merge benchmarks/results/sim_depth_noise_live_*.json instead")
    ap.add_argument("--match", action="store_true",
                    help="scan-to-scan matching error per noise model instead "
                    "(→ benchmarks/results/sim_depth_noise_match.json)")
    ap.add_argument("--poses", type=int, default=16, help="with --match: poses per world")
    ap.add_argument("--trials", type=int, default=6, help="with --match: matches per pose")
    ap.add_argument("--row-selection", default="nearest", choices=("nearest", "nearest_surface"),
                    help="depthimage_to_laserscan's row_selection for the bias table")
    ap.add_argument("--windows", type=float, nargs="+", default=list(WINDOWS),
                    help="noise_correlation_px values of the bias table (native pixels)")
    args = ap.parse_args()
    if args.live_summary:
        return live_summary()
    if args.match:
        return match_spread(WINDOWS, args.poses, args.trials)
    kinect_depth(np.full((8, 8), 2.0, np.float32))  # compile
    rows: list[dict[str, Any]] = []
    for width, height, scan_height in SETUPS:
        base = KinectConfig().at_resolution(width, height)
        for px in args.windows:
            cfg = replace(base, noise_correlation_px=px)
            common = {"size": f"{width}x{height}", "scan_height": scan_height,
                      "row_selection": args.row_selection,
                      "window_native_px": px, "window_px": noise_window_px(cfg, width)}
            extra = {**pixel_stats(cfg, 8), **timing(cfg, 30)} if scan_height == 10 else {}
            for z in DEPTHS:
                e = scan_errors(cfg, z, scan_height, args.frames, args.row_selection)
                ok = np.isfinite(e)
                d = np.where(ok, e - np.nanmean(e), 0.0)
                both = ok[:, 1:] & ok[:, :-1]
                rho = float(np.sum((d[:, 1:] * d[:, :-1])[both]) / np.sum(d[ok] ** 2))
                rows.append({**common, "z_m": z, "bias_m": float(np.nanmean(e)),
                             "bias_k": float(np.nanmean(e)) / z**2,
                             "scan_sd_m": float(np.nanstd(e)), "scan_rho1": rho,
                             "returns": float(ok.mean()), **(extra if z == DEPTHS[0] else {})})
                print(rows[-1], flush=True)
    print()
    print_table(rows, ["size", "scan_height", "row_selection", "window_native_px", "window_px", "z_m", "bias_m",
                       "bias_k", "scan_sd_m", "scan_rho1", "pixel_sd_steps", "pixel_rho1_row",
                       "pixel_rho1_col", "pool_ms", "render_ms", "render_cpu_ms"])
    print(f"\nwrote {write_results(args.name, rows)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
