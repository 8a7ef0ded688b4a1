"""Simulator and perception benchmarks.

* Kinect rendering (RGB + Kinect-processed depth, and each stream alone) at 640×480 and
  320×240 in the built-in worlds, along a path through each;
* depth image → LaserScan (depthimage_to_laserscan) on a 640×480 16UC1 frame;
* depth → PointCloud2 and depth registration on 640×480;
* physics steps per second (collision tests against the world, with slip noise);
* IR + PING readings (all five sensors) per second.

Times are process CPU time (``time.process_time``, all threads), best and median over repeats, so a
busy machine inflates them less than wall time would; the load average is recorded.
Targets: RGB+depth 640×480 ≤ 6 ms, 320×240 ≤ 1.5 ms; depth→scan ≤ 2 ms.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import print_table, write_results

from eddiebot.perception import (
    DepthToScanParams,
    depth_image_to_laserscan,
    depth_to_pointcloud2,
    register_depth,
)
from eddiebot.sim import (
    DriveParams,
    KinectConfig,
    Renderer,
    RobotState,
    camera_info_msg,
    collision_geometry,
    depth_image_msg,
    load_world,
    range_readings,
    step,
    twist_to_wheel_speeds,
)

WORLDS = ("office", "warehouse", "house", "maze")


def _time(fn: Callable[[int], Any], n: int) -> tuple[float, float]:
    fn(0)  # compile / warm caches
    times = []
    for i in range(n):
        t0 = time.process_time()
        fn(i)
        times.append(time.process_time() - t0)
    return min(times) * 1e3, statistics.median(times) * 1e3


def _poses(world_name: str, n: int) -> list[tuple[float, float, float]]:
    w = load_world(world_name)
    x0, y0, th0 = w.start
    rng = np.random.default_rng(0)
    poses = []
    for _ in range(n):
        for _ in range(50):
            x = x0 + rng.uniform(-3, 3)
            y = y0 + rng.uniform(-3, 3)
            if not w.overlapping(x, y):
                break
        else:
            x, y = x0, y0
        poses.append((x, y, float(rng.uniform(-np.pi, np.pi))))
    return poses


def render_rows(n: int = 60) -> list[dict[str, Any]]:
    rows = []
    for name in WORLDS:
        world = load_world(name)
        poses = _poses(name, n)
        for width, height in ((640, 480), (320, 240)):
            cfg = KinectConfig().at_resolution(width, height)
            r = Renderer(world, cfg)
            best, med = _time(lambda i, r=r, p=poses: r.frame(p[i % len(p)], i), n)
            rgb_best, rgb_med = _time(lambda i, r=r, p=poses: r.rgb(p[i % len(p)]), n)
            d_best, d_med = _time(lambda i, r=r, p=poses: r.depth(p[i % len(p)], i), n)
            rows.append({"bench": "render rgb+depth", "world": name, "size": f"{width}x{height}",
                         "best_ms": best, "median_ms": med, "rgb_median_ms": rgb_med,
                         "depth_median_ms": d_med, "prisms": len(world.prisms)})
    return rows


def perception_rows(n: int = 200) -> list[dict[str, Any]]:
    world = load_world("office")
    cfg = KinectConfig()
    frame = Renderer(world, cfg).frame(world.start)
    msg = depth_image_msg(frame.depth)
    info = camera_info_msg(cfg.depth)
    rows = []
    for h in (1, 50):
        params = DepthToScanParams(scan_height=h)
        best, med = _time(lambda i, p=params: depth_image_to_laserscan(msg, info, p), n)
        rows.append({"bench": "depth->scan", "world": "office", "size": f"640x480 h={h}",
                     "best_ms": best, "median_ms": med})
    best, med = _time(lambda i: depth_to_pointcloud2(msg, info), n // 4)
    rows.append({"bench": "depth->cloud xyz", "world": "office", "size": "640x480",
                 "best_ms": best, "median_ms": med})
    rgb_info = camera_info_msg(cfg.rgb, frame_id="camera_rgb_optical_frame")
    t = np.eye(4)
    t[0, 3] = -0.025
    best, med = _time(lambda i: register_depth(msg, info, rgb_info, t), n // 4)
    rows.append({"bench": "register depth", "world": "office", "size": "640x480",
                 "best_ms": best, "median_ms": med})
    return rows


def physics_rows(seconds: float = 2.0) -> list[dict[str, Any]]:
    rows = []
    for name in ("office", "warehouse"):
        world = load_world(name)
        geom = collision_geometry(world)
        params = DriveParams(slip_std=0.02, encoder_noise_std=0.001)
        rng = np.random.default_rng(0)
        s = RobotState(*world.start)
        wheels = twist_to_wheel_speeds(0.5, 0.3, params)
        step(s, wheels, 0.01, geom, params, rng)
        count = 0
        t0 = time.process_time()
        while time.process_time() - t0 < seconds:
            for _ in range(100):
                s = step(s, wheels, 0.01, geom, params, rng)
            count += 100
        rate = count / (time.process_time() - t0)
        rows.append({"bench": "physics step", "world": name, "size": f"{len(geom.segments)} segs",
                     "median_ms": 1e3 / rate, "rate_hz": rate})
        n = 300
        best, med = _time(lambda i, w=world: range_readings(w, (w.start[0], w.start[1], 0.01 * i)), n)
        rows.append({"bench": "IR+PING (5)", "world": name, "size": "", "best_ms": best,
                     "median_ms": med, "rate_hz": 1e3 / med})
    return rows


def reference_row(n: int = 200) -> dict[str, Any]:
    """A fixed workload to tell how fast the (shared) machine was during this run."""
    a = np.random.default_rng(0).random(640 * 480, dtype=np.float32)
    best, med = _time(lambda i: a * np.float32(2.0) + np.float32(1.0), n)
    return {"bench": "reference axpy", "world": "", "size": "307200 f32", "best_ms": best,
            "median_ms": med}


def main() -> int:
    rows = [reference_row(), *render_rows(), *perception_rows(), *physics_rows(), reference_row()]
    print_table(rows, ["bench", "world", "size", "best_ms", "median_ms", "rgb_median_ms",
                       "depth_median_ms", "rate_hz"])
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs")
    for r in rows:
        r["load_average_1min"] = load[0]
    path = write_results("sim", rows)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
