"""Appearance-only loop-closure detection on simulated routes with revisits: recall at 100 %
precision (RTAB-Map's metric), precision–recall over `Rtabmap/LoopThr`, time per image.

Images: the simulator's Kinect RGB camera (640×480, `eddiebot.sim.render`) along the demo
routes of several worlds, one image every 0.35 m or 0.5 rad (Eddie at ~1 Hz), with a small
pose jitter (σ 3 cm, 1°) and pixel noise (σ 2 grey levels) so that revisits never see the
very same image. The detector is `AppearanceLoopDetector` (`eddie vslam loops`): GFTT/ORB,
incremental vocabulary, TF-IDF, Bayes filter, RTAB-Map defaults.

Ground truth from the true poses and the rendered depth: two images show the *same place* when
the cameras are within 1 m and 30° and at least half of the first view (a 40×30 grid of its
depth points) re-projects into the second with consistent depth. A query image is *positive*
when a same place is among its loop candidates (older than `Mem/STMSize` images). Its best
hypothesis is *right* if it is a same place; *near* (counted neither right nor wrong) if the
headings are within 45° and 30 % of one of the two views re-projects into the other (e.g. a
view 3 m further down a corridor: geometric verification could still register it); else
*wrong*.

    .venv/bin/python benchmarks/bench_vslam_recall.py [--worlds office corridor warehouse]
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import platform
import time
from pathlib import Path

import cv2
import numpy as np

from eddiebot.demo.route import OFFICE_LONG_ROUTE, WAREHOUSE_ROUTE, Waypoint
from eddiebot.demo.vslam_stage import CORRIDOR_LONG_ROUTE
from eddiebot.sim.camera import KinectConfig
from eddiebot.sim.render import camera_pose, render_view
from eddiebot.sim.worlds import load_world
from eddiebot.vslam.loops import (
    AppearanceLoopDetector,
    precision_recall_curve,
    recall_at_full_precision,
)
from eddiebot.vslam.parameters import RtabmapParameters

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "vslam_recall.json"
ROUTES: dict[str, tuple[Waypoint, ...]] = {
    "office": OFFICE_LONG_ROUTE, "corridor": CORRIDOR_LONG_ROUTE, "warehouse": WAREHOUSE_ROUTE,
}
GRID = (40, 30)  # depth points per view for the overlap test


def route_poses(start: tuple[float, float, float], route: tuple[Waypoint, ...],
                step: float, turn_step: float) -> list[tuple[float, float, float]]:
    """Poses (x, y, θ) every `step` m or `turn_step` rad: turn towards each waypoint, drive to
    it, spin there."""
    x, y, th = start
    out = [(x, y, th)]

    def turn(target: float) -> None:
        nonlocal th
        delta = math.atan2(math.sin(target - th), math.cos(target - th))
        n = max(1, math.ceil(abs(delta) / turn_step)) if abs(delta) > 1e-6 else 0
        for k in range(n):
            out.append((x, y, th + delta * (k + 1) / n))
        th = th + delta

    for wp in route:
        dist = math.hypot(wp.x - x, wp.y - y)
        if dist > 1e-6:
            turn(math.atan2(wp.y - y, wp.x - x))
            n = max(1, math.ceil(dist / step))
            x0, y0 = x, y
            for k in range(n):
                out.append((x0 + (wp.x - x0) * (k + 1) / n, y0 + (wp.y - y0) * (k + 1) / n, th))
            x, y = wp.x, wp.y
        if wp.spin:
            n = max(1, math.ceil(abs(wp.spin) / turn_step))
            th0 = th
            for k in range(n):
                out.append((x, y, th0 + wp.spin * (k + 1) / n))
            th = th0 + wp.spin
    return out


def _rays(intr, stride_u: int, stride_v: int):
    us = (np.arange(GRID[0]) + 0.5) * stride_u
    vs = (np.arange(GRID[1]) + 0.5) * stride_v
    u, v = np.meshgrid(us, vs)
    return u.ravel(), v.ravel()


class Views:
    """Camera poses and sub-sampled depth of every image, for the overlap test."""

    def __init__(self, intr) -> None:
        self.intr = intr
        self.su, self.sv = intr.width // GRID[0], intr.height // GRID[1]
        self.u, self.v = _rays(intr, self.su, self.sv)
        self.cams: list[tuple[float, float, float, float]] = []
        self.depth: list[np.ndarray] = []

    def add(self, cam: tuple[float, float, float, float], depth: np.ndarray) -> None:
        self.cams.append(cam)
        iu = self.u.astype(int)
        iv = self.v.astype(int)
        self.depth.append(depth[iv, iu].reshape(GRID[1], GRID[0]).astype(np.float64))

    def _axes(self, k: int):
        x, y, z, yaw = self.cams[k]
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x, y, z]), np.array([c, s, 0.0]), np.array([s, -c, 0.0]), \
            np.array([0.0, 0.0, -1.0])

    def overlap(self, i: int, j: int) -> float:
        """Share of view i's depth points seen by view j at a consistent depth."""
        intr = self.intr
        z = self.depth[i].ravel()
        ok = np.isfinite(z) & (z > 0.3) & (z < 8.0)
        if not ok.any():
            return 0.0
        o, f, r, d = self._axes(i)
        xr = (self.u[ok] - intr.cx) / intr.fx
        yd = (self.v[ok] - intr.cy) / intr.fy
        pts = o + z[ok, None] * (f + xr[:, None] * r + yd[:, None] * d)
        o2, f2, r2, d2 = self._axes(j)
        rel = pts - o2
        zf = rel @ f2
        front = zf > 0.3
        u = intr.cx + intr.fx * (rel @ r2) / np.where(front, zf, 1.0)
        v = intr.cy + intr.fy * (rel @ d2) / np.where(front, zf, 1.0)
        inside = front & (u >= 0) & (u < intr.width - 1) & (v >= 0) & (v < intr.height - 1)
        gu = np.clip(np.round(u / self.su - 0.5).astype(int), 0, GRID[0] - 1)
        gv = np.clip(np.round(v / self.sv - 0.5).astype(int), 0, GRID[1] - 1)
        seen = self.depth[j][gv, gu]
        consistent = inside & np.isfinite(seen) & (np.abs(seen - zf) < 0.15 * zf + 0.05)
        return float(consistent.sum() / ok.sum())


def _place(poses, views, i: int, j: int, dist: float, angle: float, share: float,
           either: bool = False) -> bool:
    """Within `dist` m and `angle` degrees, and `share` of both views (of either view if
    `either`) re-project into the other."""
    (xi, yi, ti), (xj, yj, tj) = poses[i], poses[j]
    if math.hypot(xi - xj, yi - yj) > dist:
        return False
    if abs(math.atan2(math.sin(ti - tj), math.cos(ti - tj))) > math.radians(angle):
        return False
    a, b = views.overlap(i, j), views.overlap(j, i)
    return (max(a, b) if either else min(a, b)) >= share


def run_world(name: str, params: dict[str, str], step: float, turn_step: float,
              seed: int) -> dict[str, object]:
    world = load_world(name)
    config = KinectConfig()
    intr = config.rgb
    truth = route_poses(world.start, ROUTES[name], step, turn_step)
    rng = np.random.default_rng(seed)
    detector = AppearanceLoopDetector(RtabmapParameters.from_dict(params))
    stm = detector.params.mem_stm_size
    views = Views(intr)
    poses: list[tuple[float, float, float]] = []
    values: list[float] = []
    verdicts: list[int] = []
    positive = 0
    wall: list[float] = []
    cpu: list[float] = []
    render_s = 0.0
    for k, (x, y, th) in enumerate(truth):
        pose = (x + rng.normal(0, 0.03), y + rng.normal(0, 0.03), th + rng.normal(0, 0.017))
        t0 = time.perf_counter()
        cam = camera_pose(pose, config.rgb_position)
        rgb, depth = render_view(world, cam, intr, shading=config.shading)
        grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float64)
        grey = np.clip(grey + rng.normal(0, 2.0, grey.shape), 0, 255).astype(np.uint8)
        render_s += time.perf_counter() - t0
        views.add(cam, depth)
        poses.append(pose)
        t0, c0 = time.perf_counter(), time.process_time()
        det = detector.process(grey)
        wall.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
        # loop candidates: images older than the short-term memory
        candidates = range(k - stm + 1)
        has_loop = any(_place(poses, views, k, j, 1.0, 30.0, 0.5) for j in candidates)
        positive += has_loop
        values.append(det.hypothesis_value if det.hypothesis_id else 0.0)
        if not det.hypothesis_id:
            verdicts.append(0)
            continue
        h = det.hypothesis_id - 1  # node ids are image indices + 1
        if _place(poses, views, k, h, 1.0, 30.0, 0.5):
            verdicts.append(1)
        elif _place(poses, views, k, h, math.inf, 45.0, 0.3, either=True):
            verdicts.append(0)
        else:
            verdicts.append(-1)
    recall, thr = recall_at_full_precision(values, verdicts, positive)
    curve = precision_recall_curve(values, verdicts, positive)
    loop_thr = detector.params.rtabmap_loop_thr
    at_default = [(p, r) for t, p, r in curve if t >= loop_thr]
    p_def, r_def = at_default[-1] if at_default else (1.0, 0.0)
    return {
        "world": name, "images": len(truth), "positives": positive,
        "recall_at_100_precision": recall, "threshold_at_100_precision": thr,
        "at_default_loop_thr": {"Rtabmap/LoopThr": loop_thr, "precision": p_def,
                                "recall": r_def},
        "right": int(sum(v == 1 for v in verdicts)), "near": int(sum(
            v == 0 and val > 0 for v, val in zip(verdicts, values))),
        "wrong": int(sum(v == -1 for v in verdicts)),
        "curve": [{"thr": t, "precision": p, "recall": r} for t, p, r in curve[:: max(1, len(curve) // 60)]],
        "per_image_wall_ms": {"median": float(np.median(wall)), "p95": float(np.percentile(wall, 95))},
        "per_image_cpu_ms": {"median": float(np.median(cpu)), "p95": float(np.percentile(cpu, 95))},
        "render_s": render_s,
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["office", "corridor", "warehouse"],
                    choices=sorted(ROUTES))
    ap.add_argument("--step", type=float, default=0.35, help="metres between images")
    ap.add_argument("--turn-step", type=float, default=0.5, help="radians between images")
    ap.add_argument("--set", action="append", default=[], metavar="Group/Name=VALUE",
                    help="RTAB-Map parameter override (repeatable)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    params = dict(item.split("=", 1) for item in args.set)
    results: dict[str, object] = {
        "machine": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "parameters": params, "step_m": args.step, "turn_step_rad": args.turn_step,
    }
    rows = []
    print(f"{'world':10s} {'images':>6s} {'loops':>6s} {'R@100%P':>8s} {'thr':>6s} "
          f"{'P/R @0.11':>12s} {'right':>5s} {'near':>5s} {'wrong':>5s} {'ms/img cpu':>10s}")
    for name in args.worlds:
        r = run_world(name, params, args.step, args.turn_step, args.seed)
        rows.append(r)
        d = r["at_default_loop_thr"]
        assert isinstance(d, dict)
        cpu = r["per_image_cpu_ms"]
        assert isinstance(cpu, dict)
        print(f"{name:10s} {r['images']:6d} {r['positives']:6d} "
              f"{r['recall_at_100_precision']:8.3f} {r['threshold_at_100_precision']:6.3f} "
              f"{d['precision']:5.3f}/{d['recall']:5.3f} {r['right']:5d} {r['near']:5d} "
              f"{r['wrong']:5d} {cpu['median']:10.1f}", flush=True)
    results["worlds"] = rows
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
