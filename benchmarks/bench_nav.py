"""Navigation core benchmarks: planners, controllers, local costmap update, AMCL.

Run: ``.venv/bin/python benchmarks/bench_nav.py [--repeat N] [--only PREFIX,...]``. Prints a
table and writes ``benchmarks/results/nav.json`` (with ``--only``, only the cases whose names
start with one of the prefixes run, and their rows replace those of the existing file). Each
case is warmed up once (numba compilation, cached kernels) and then timed ``--repeat`` times;
the median is the figure of record.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numba import njit

from eddiebot.maps import OccupancyMap
from eddiebot.nav.amcl import Amcl, AmclConfig
from eddiebot.nav.controllers import (
    DWBConfig,
    DWBController,
    RegulatedPurePursuitConfig,
    RegulatedPurePursuitController,
)
from eddiebot.nav.costmap import LayeredCostmap, build_costmap, scan_observation
from eddiebot.nav.params import from_params
from eddiebot.nav.planners import NavfnConfig, NavfnPlanner, ThetaStarPlanner
from eddiebot.nav.planners.smac import (
    SmacPlanner2D,
    SmacPlannerHybrid,
    SmacPlannerHybridConfig,
)
from eddiebot.nav.types import Twist2D, path_length

RESULTS = Path(__file__).resolve().parent / "results" / "nav.json"
RES = 0.05

# Targets from the issue (ms).
TARGETS = {
    "navfn_1000": 100.0,
    "navfn_400": 15.0,
    "theta_star_400": 200.0,
    "rpp_cycle": 5.0,
    "dwb_cycle": 5.0,
    "local_costmap_scan": 5.0,
}


def clutter_map(n: int, seed: int = 0) -> OccupancyMap:
    """n x n cells at 5 cm: random rectangles (≈2.5 % of the area), free corners."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((n, n), dtype=np.int8)
    for _ in range(n * n // 2000):
        x, y = rng.integers(0, n, 2)
        w, h = rng.integers(2, max(3, n // 40), 2)
        occ[y:y + h, x:x + w] = 100
    occ[:20, :20] = 0
    occ[-20:, -20:] = 0
    return OccupancyMap(occ, RES)


def global_costmap(m: OccupancyMap) -> LayeredCostmap:
    cm = build_costmap({
        "resolution": RES, "robot_radius": 0.23, "footprint_padding": 0.0,
        "plugins": ["static_layer", "inflation_layer"],
        "inflation_layer": {"inflation_radius": 0.5, "cost_scaling_factor": 4.0},
    }, "global_costmap")
    cm.set_static_map(m)
    cm.update_map((0.0, 0.0, 0.0))
    return cm


def local_costmap(width: int = 5) -> LayeredCostmap:
    return build_costmap({
        "rolling_window": True, "width": width, "height": width, "resolution": RES,
        "robot_radius": 0.23, "footprint_padding": 0.0,
        "plugins": ["obstacle_layer", "inflation_layer"],
        "obstacle_layer": {
            "plugin": "nav2_costmap_2d::ObstacleLayer", "observation_sources": "scan",
            "scan": {"clearing": True, "marking": True, "max_obstacle_height": 1.0,
                     "obstacle_max_range": 3.5, "raytrace_max_range": 4.0},
        },
        "inflation_layer": {"inflation_radius": 0.5, "cost_scaling_factor": 4.0},
    }, "local_costmap")


def kinect_scan(rng: np.random.Generator, n: int = 640) -> tuple[np.ndarray, float, float]:
    fov = math.radians(57.0)
    ranges = 1.5 + 1.5 * np.abs(np.sin(np.linspace(0, 6, n))) + rng.normal(0, 0.01, n)
    ranges[rng.random(n) < 0.05] = np.nan
    return ranges, -fov / 2, fov / (n - 1)


@njit(cache=True)
def _reference_loop(a: np.ndarray) -> float:
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * 1.0001
    return s


def machine_reference_ms() -> float:
    """Median time of a fixed 10^7-element numba loop: a yardstick for CPU contention
    (about 9.5 ms on this machine when idle)."""
    a = np.random.default_rng(0).random(10**7).astype(np.float32)
    _reference_loop(a)
    ts = []
    for _ in range(5):
        t = time.perf_counter()
        _reference_loop(a)
        ts.append((time.perf_counter() - t) * 1000.0)
    return statistics.median(ts)


def timeit(fn: Callable[[], object], repeat: int) -> dict[str, float]:
    """Wall-clock and process CPU time per call (ms). On a shared machine the CPU time is
    the steadier figure; the wall time is what a node experiences."""
    fn()  # warm-up
    ts = []
    cpu = []
    for _ in range(repeat):
        t = time.perf_counter()
        c = time.process_time()
        fn()
        cpu.append((time.process_time() - c) * 1000.0)
        ts.append((time.perf_counter() - t) * 1000.0)
    ts.sort()
    return {"median_ms": statistics.median(ts), "p90_ms": ts[int(0.9 * (len(ts) - 1))],
            "min_ms": ts[0], "cpu_median_ms": statistics.median(cpu), "n": len(ts)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=15)
    ap.add_argument("--only", default="",
                    help="comma-separated case-name prefixes (e.g. smac_,navfn_)")
    args = ap.parse_args()
    prefixes = tuple(p for p in args.only.split(",") if p)

    def want(name: str) -> bool:
        return not prefixes or name.startswith(prefixes)

    rows: dict[str, dict[str, object]] = {}
    ref_before = machine_reference_ms()

    for n in (400, 1000):
        cm = global_costmap(clutter_map(n))
        start = (0.3, 0.3, 0.0)
        goal = (n * RES - 0.3, n * RES - 0.3, 0.0)
        straight = math.hypot(goal[0] - start[0], goal[1] - start[1])
        # Smac at Nav2's defaults (Hybrid: a circular robot, 72 bins, 0.4 m turning radius)
        for name, planner in (
            (f"navfn_{n}", NavfnPlanner(NavfnConfig())),
            (f"navfn_astar_{n}", NavfnPlanner(NavfnConfig(use_astar=True))),
            (f"theta_star_{n}", ThetaStarPlanner()),
            (f"smac_2d_{n}", SmacPlanner2D()),
            (f"smac_hybrid_{n}", SmacPlannerHybrid()),
            (f"smac_hybrid_rs_{n}", SmacPlannerHybrid(from_params(
                SmacPlannerHybridConfig, {"motion_model_for_search": "REEDS_SHEPP"}))),
        ):
            if not want(name):
                continue
            if name in ("theta_star_1000", "smac_hybrid_rs_1000") and args.repeat > 3:
                reps = 3
            else:
                reps = args.repeat
            r = timeit(lambda p=planner, c=cm, s=start, g=goal: p.create_plan(s, g, c.master), reps)
            # after the warm-up: a first call that loads the compiled kernels can use up Smac's
            # max_planning_time before smoothing
            path = planner.create_plan(start, goal, cm.master)
            r["path_length_m"] = path_length(path)
            if hasattr(planner, "last_iterations"):
                r["expansions"] = int(planner.last_iterations)
            r["straight_line_m"] = straight
            r["map_cells"] = f"{n}x{n}"
            rows[name] = r

    # Controllers on a 3 m x 3 m rolling local costmap (upstream sample size) with obstacles.
    rng = np.random.default_rng(1)
    _others(args.repeat, rng, rows, want)
    _report(rows, ref_before, prefixes)
    return 0


def _others(repeat: int, rng: np.random.Generator, rows: dict[str, dict[str, object]],
            want: Callable[[str], bool]) -> None:
    """Controllers, local costmap update and AMCL (all or none of them)."""
    if not any(want(n) for n in ("rpp_cycle", "dwb_cycle", "local_costmap_scan", "amcl_update")):
        return
    lc = local_costmap(3)
    ranges, a0, inc = kinect_scan(rng)
    lc.layer("obstacle_layer").add_observation(
        "scan", scan_observation(ranges, a0, inc, 0.45, 10.0, (0.0, 0.0, 0.6, 0.0)))
    lc.update_map((0.0, 0.0, 0.0))
    t = np.linspace(0.0, 3.0, 120)
    path = np.stack([t, 0.4 * np.sin(t), np.arctan2(0.4 * np.cos(t), 1.0)], axis=1)
    pose = (0.0, 0.0, 0.0)
    rpp = RegulatedPurePursuitController(RegulatedPurePursuitConfig(
        desired_linear_vel=0.4, use_collision_detection=True))
    dwb = DWBController(DWBConfig(
        max_vel_x=0.4, max_speed_xy=0.4, max_vel_theta=1.5, acc_lim_x=0.8, acc_lim_theta=2.0,
        decel_lim_x=-1.0, decel_lim_theta=-2.0, vy_samples=1,
        critics=("RotateToGoal", "Oscillation", "BaseObstacle", "GoalAlign", "PathAlign",
                 "PathDist", "GoalDist"),
        BaseObstacle_scale=0.02, PathAlign_scale=32.0, GoalAlign_scale=24.0,
        PathAlign_forward_point_distance=0.1, GoalAlign_forward_point_distance=0.1,
        PathDist_scale=32.0, GoalDist_scale=24.0, RotateToGoal_scale=32.0,
        linear_granularity=0.05, angular_granularity=0.025))
    vel = Twist2D(0.3, 0.0, 0.2)
    for name, ctrl in (("rpp_cycle", rpp), ("dwb_cycle", dwb)):
        r = timeit(lambda c=ctrl: c.compute_velocity_commands(pose, vel, path, lc, 0.05),
                   repeat * 10)
        r["costmap"] = "3x3 m @ 0.05"
        rows[name] = r

    # Local costmap update: one 57-degree Kinect scan (640 beams), 5 x 5 m at 0.05 m.
    lc5 = local_costmap(5)
    ol = lc5.layer("obstacle_layer")
    lc5.update_map((0.0, 0.0, 0.0))
    k = [0]

    def costmap_update() -> None:
        k[0] += 1
        ranges, a0, inc = kinect_scan(rng)
        x = 0.01 * k[0]
        ol.add_observation("scan", scan_observation(ranges, a0, inc, 0.45, 10.0, (x, 0.0, 0.6, 0.0)))
        lc5.update_map((x, 0.0, 0.0))

    r = timeit(costmap_update, repeat * 10)
    r["costmap"] = "5x5 m @ 0.05 (100x100), obstacle + inflation"
    rows["local_costmap_scan"] = r

    # AMCL: one filter update, 2000 particles, 60 beams.
    m = clutter_map(200, seed=3)
    amcl = Amcl(AmclConfig(), m, seed=0)
    amcl.initialize((5.0, 5.0, 0.0))
    odom = np.zeros(3)
    scan = np.full(360, 4.0)

    def amcl_update() -> None:
        odom[0] += 0.3
        amcl.update(odom, scan, -math.pi, 2 * math.pi / 360, 0.05, 8.0)

    r = timeit(amcl_update, repeat)
    r["particles_after"] = int(amcl.particles.shape[0])
    rows["amcl_update"] = r
    for name in [n for n in rows if not want(n)]:
        del rows[name]


def _report(rows: dict[str, dict[str, object]], ref_before: float,
            prefixes: tuple[str, ...]) -> None:
    """Print the table and write the results file (merging into it with ``--only``)."""
    print(f"{'case':<22} {'median ms':>10} {'p90 ms':>8} {'cpu ms':>8} {'target ms':>10}  notes")
    for name, r in rows.items():
        tgt = TARGETS.get(name)
        notes = {k2: v for k2, v in r.items()
                 if k2 not in ("median_ms", "p90_ms", "min_ms", "cpu_median_ms", "n")}
        note = ", ".join(f"{k2}={v:.2f}" if isinstance(v, float) else f"{k2}={v}"
                         for k2, v in notes.items())
        print(f"{name:<22} {r['median_ms']:>10.2f} {r['p90_ms']:>8.2f} "
              f"{r['cpu_median_ms']:>8.2f} "
              f"{(f'<= {tgt:g}' if tgt else '-'):>10}  {note}")
    ref_after = machine_reference_ms()
    print(f"machine reference loop: {ref_before:.1f} ms before, {ref_after:.1f} ms after "
          "(about 9.5 ms when the machine is idle)")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    if prefixes and RESULTS.exists():
        # rows of a partial run carry their own date and machine yardstick
        for r in rows.values():
            r["measured"] = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
            r["machine_reference_ms"] = (ref_before + ref_after) / 2
        old = json.loads(RESULTS.read_text())
        merged = dict(old.get("results", {}))
        merged.update(rows)
        rows = merged
    doc = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "processor": platform.processor(),
                    "python": platform.python_version(), "cpus": os.cpu_count()},
        "machine_reference_ms": {"before": ref_before, "after": ref_after, "idle": 9.5},
        "targets_ms": TARGETS,
        "results": rows,
    }
    RESULTS.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    raise SystemExit(main())
