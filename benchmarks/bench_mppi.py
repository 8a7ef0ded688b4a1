"""MPPI controller: one control cycle at Nav2 Jazzy's sample settings, and a goal set driven
by MPPI, RPP and DWB side by side.

Cycle (``cycle``): ``nav2_mppi_controller::MPPIController`` configured from the
``FollowPath`` section of Nav2 Jazzy's ``nav2_params.yaml`` (batch 2000 × 56 time steps,
model_dt 0.05, regenerate_noises, the eight sample critics) on bench_nav.py's controller
scene: a 3 × 3 m rolling costmap at 0.05 m holding one Kinect scan, a 3 m sinusoidal path.
Numpy and BLAS are held to one thread (one core). Also timed: the code default batch (1000)
and each stage of the cycle.

Goals (``goals``): the office world's ground-truth footprint map (0.05 m) as a static
costmap with Eddie's local inflation (config/nav2.yaml: robot_radius 0.23,
inflation_radius 0.9, cost_scaling_factor 3.0); seeded goals as bench_nav_worlds.py draws
them, one after another; NavFn plans each leg; the controller drives a
unicycle integrated at 20 Hz (commands taken as the next velocity). RPP and DWB are
Eddie's tuning from config/nav2.yaml, MPPI the Jazzy sample section as is. A goal is
reached when the goal checker (0.25 m, 0.25 rad) says so within 3 × the plan's length at
0.2 m/s + 20 s; a collision is the robot's disc (0.2245 m) overlapping an occupied cell
(the move is refused). Each leg starts at the previous goal's pose, the same for every
controller; no recoveries (the navigator's backup, spin, costmap clearing) are run.

    .venv/bin/python benchmarks/bench_mppi.py                       # both parts
    .venv/bin/python benchmarks/bench_mppi.py --parts cycle --repeat 41
    .venv/bin/python benchmarks/bench_mppi.py --parts goals --goals 10 --seed 0 \
        --out benchmarks/results/mppi_goals.json

Prints tables and writes ``benchmarks/results/mppi.json`` (``--out`` to change).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import copy  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, machine, print_table  # noqa: E402
from bench_nav import kinect_scan, local_costmap  # noqa: E402
from bench_nav_worlds import FreeSpace, sample_goals  # noqa: E402

from eddiebot.nav.controllers import SimpleGoalChecker, build_controller_server  # noqa: E402
from eddiebot.nav.controllers.mppi import MPPIController  # noqa: E402
from eddiebot.nav.controllers.mppi.critics import CriticData  # noqa: E402
from eddiebot.nav.costmap import LayeredCostmap, build_costmap, scan_observation  # noqa: E402
from eddiebot.nav.errors import ControllerError, PlannerError  # noqa: E402
from eddiebot.nav.planners import NavfnPlanner  # noqa: E402
from eddiebot.nav.types import Twist2D, path_length  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
JAZZY = REPO / "tests" / "data" / "nav2" / "nav2_params_jazzy.yaml"
EDDIE = REPO / "config" / "nav2.yaml"
TARGET_CYCLE_MS = 50.0
ROBOT_RADIUS = 0.2245
DT = 0.05


def jazzy_follow_path() -> dict[str, Any]:
    doc = yaml.safe_load(JAZZY.read_text())
    return dict(doc["controller_server"]["ros__parameters"]["FollowPath"])


def _times(fn: Any, repeat: int) -> dict[str, float]:
    fn()
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        cpu.append((time.process_time() - c) * 1e3)
        wall.append((time.perf_counter() - t) * 1e3)
    wall.sort()
    return {"wall_median_ms": statistics.median(wall), "wall_p90_ms": wall[int(0.9 * (len(wall) - 1))],
            "cpu_median_ms": statistics.median(cpu), "n": len(wall)}


# --------------------------------------------------------------------------- cycle
def cycle(repeat: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng(1)
    lc = local_costmap(3)
    ranges, a0, inc = kinect_scan(rng)
    lc.layer("obstacle_layer").add_observation(
        "scan", scan_observation(ranges, a0, inc, 0.45, 10.0, (0.0, 0.0, 0.6, 0.0)))
    lc.update_map((0.0, 0.0, 0.0))
    t = np.linspace(0.0, 3.0, 120)
    path = np.stack([t, 0.4 * np.sin(t), np.arctan2(0.4 * np.cos(t), 1.0)], axis=1)
    pose = np.array([0.0, 0.0, 0.0])
    vel = Twist2D(0.3, 0.0, 0.2)
    rows: list[dict[str, Any]] = []
    for batch in (2000, 1000):
        params = jazzy_follow_path()
        params["batch_size"] = batch
        ctrl = MPPIController.from_params(params, seed=0)
        r = _times(lambda c=ctrl: c.compute_velocity_commands(pose, vel, path, lc, DT), repeat)
        rows.append({"case": f"cycle, batch {batch} x 56", **r,
                     "target_ms": TARGET_CYCLE_MS if batch == 2000 else None})
    # stages of one cycle at the sample's batch
    ctrl = MPPIController.from_params(jazzy_follow_path(), seed=0)
    ctrl.compute_velocity_commands(pose, vel, path, lc, DT)
    o = ctrl.optimizer
    plan = ctrl.path_handler.transform_path(pose, lc)
    goal = ctrl.path_handler.goal()
    rows.append({"case": "stage: noise + propagate + integrate",
                 **_times(lambda: o._generate_noised_trajectories(pose, vel), repeat)})
    for critic in o.critics:
        def score(c: Any = critic) -> None:
            d = CriticData(pose=pose, goal=goal, path=plan, vx=o.vx, wz=o.wz, traj_x=o.traj_x,
                           traj_y=o.traj_y, traj_yaw=o.traj_yaw, costs=np.zeros_like(o.costs),
                           model_dt=DT, costmap=lc, goal_tolerance=0.25)
            c.score(d)
        rows.append({"case": f"stage: {critic.name}", **_times(score, repeat)})
    rows.append({"case": "stage: softmax update + constraints",
                 **_times(o._update_control_sequence, repeat)})
    return rows


# --------------------------------------------------------------------------- goals
def office_costmap() -> tuple[LayeredCostmap, Any, tuple[float, float, float]]:
    from eddiebot.sim.ground_truth import footprint_map
    from eddiebot.sim.world import load_world_file
    from eddiebot.sim.worlds import world_path

    world = load_world_file(world_path("office"))
    grid = footprint_map(world)
    cm = build_costmap({
        "resolution": grid.resolution, "robot_radius": 0.23, "footprint_padding": 0.0,
        "plugins": ["static_layer", "inflation_layer"],
        "inflation_layer": {"inflation_radius": 0.9, "cost_scaling_factor": 3.0},
    }, "costmap")
    cm.set_static_map(grid)
    cm.update_map((0.0, 0.0, 0.0))
    return cm, grid, world.start


def controllers() -> dict[str, Any]:
    doc = yaml.safe_load(EDDIE.read_text())
    params = copy.deepcopy(doc["controller_server"]["ros__parameters"])
    srv = build_controller_server(params)
    return {"MPPI": MPPIController.from_params(jazzy_follow_path(), seed=0),
            "RPP": srv.controllers["FollowPath"], "DWB": srv.controllers["DWB"]}


def _collides(space: FreeSpace, x: float, y: float) -> bool:
    r, c = space.cell(x, y)
    if not (0 <= r < space.clearance.shape[0] and 0 <= c < space.clearance.shape[1]):
        return True
    return bool(space.clearance[r, c] < ROBOT_RADIUS - space.resolution / 2)


def drive(ctrl: Any, cm: LayeredCostmap, space: FreeSpace, start: np.ndarray,
          goal: tuple[float, float, float]) -> dict[str, Any]:
    try:
        plan = NavfnPlanner().create_plan(tuple(start), goal, cm.master)
    except PlannerError as exc:
        return {"status": f"no plan: {exc}", "pose": start}
    plan_len = path_length(plan)
    limit = 3.0 * plan_len / 0.2 + 20.0
    checker = SimpleGoalChecker()
    checker.reset()
    ctrl.set_plan(plan)
    ctrl.set_goal_tolerance(0.25)
    if hasattr(ctrl, "reset"):
        ctrl.reset()
    pose = start.copy()
    vel = Twist2D()
    driven, cpu, collided, failures = 0.0, [], False, 0
    steps = int(limit / DT)
    for k in range(steps):
        if checker.is_goal_reached(pose, plan[-1], vel):
            return {"status": "reached", "time_s": k * DT, "driven_m": driven,
                    "plan_m": plan_len, "collided": collided, "cpu_ms": cpu,
                    "failures": failures, "pose": pose}
        c0 = time.process_time()
        try:
            cmd = ctrl.compute_velocity_commands(pose, vel, None, cm, DT)
        except ControllerError:
            cmd = Twist2D()
            failures += 1
        cpu.append((time.process_time() - c0) * 1e3)
        th = pose[2] + 0.5 * cmd.wz * DT
        nx = pose[0] + cmd.vx * math.cos(th) * DT
        ny = pose[1] + cmd.vx * math.sin(th) * DT
        if _collides(space, nx, ny):
            collided = True
            cmd = Twist2D()
        else:
            driven += math.hypot(nx - pose[0], ny - pose[1])
            pose[0], pose[1] = nx, ny
        pose[2] = math.remainder(pose[2] + cmd.wz * DT, 2 * math.pi)
        vel = cmd
    return {"status": "timeout", "time_s": limit, "driven_m": driven, "plan_m": plan_len,
            "collided": collided, "cpu_ms": cpu, "failures": failures, "pose": pose}


def goals(n: int, seed: int, names: list[str]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    cm, grid, start = office_costmap()
    space = FreeSpace.of(grid)
    targets = sample_goals(space, (start[0], start[1]), n, seed)
    summary, per_goal = [], []
    for name, ctrl in controllers().items():
        if name not in names:
            continue
        recs = []
        for i, g in enumerate(targets):
            # every controller drives the same legs: each from the previous goal pose
            leg_start = np.array(start if i == 0 else targets[i - 1], dtype=float)
            rec = drive(ctrl, cm, space, leg_start, g)
            rec["final_error_m"] = float(np.hypot(*(np.asarray(rec.pop("pose"))[:2] - g[:2])))
            cpu = rec.pop("cpu_ms", [])
            rec.update(controller=name, goal=i, cpu_median_ms=statistics.median(cpu) if cpu else None)
            recs.append(rec)
            per_goal.append(rec)
        ok = [r for r in recs if r["status"] == "reached"]
        cpu_all = [r["cpu_median_ms"] for r in recs if r.get("cpu_median_ms") is not None]
        summary.append({
            "controller": name, "goals": len(recs), "reached": len(ok),
            "collisions": sum(1 for r in recs if r.get("collided")),
            "mean_time_s": statistics.mean(r["time_s"] for r in ok) if ok else None,
            "mean_driven_over_plan": statistics.mean(r["driven_m"] / r["plan_m"] for r in ok)
            if ok else None,
            "cycle_cpu_median_ms": statistics.median(cpu_all) if cpu_all else None,
        })
    return summary, per_goal


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--parts", nargs="+", default=["cycle", "goals"], choices=["cycle", "goals"])
    ap.add_argument("--repeat", type=int, default=21)
    ap.add_argument("--goals", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--controllers", nargs="+", default=["MPPI", "RPP", "DWB"])
    ap.add_argument("--out", type=Path, default=RESULTS / "mppi.json")
    args = ap.parse_args(argv)
    out: dict[str, Any] = {"machine": machine(), "load_average": os.getloadavg()}
    if "cycle" in args.parts:
        rows = cycle(args.repeat)
        print_table(rows, ["case", "target_ms", "wall_median_ms", "wall_p90_ms", "cpu_median_ms"])
        out["cycle"] = rows
    if "goals" in args.parts:
        summary, per_goal = goals(args.goals, args.seed, args.controllers)
        print_table(summary, ["controller", "goals", "reached", "collisions", "mean_time_s",
                              "mean_driven_over_plan", "cycle_cpu_median_ms"])
        out["goals"] = {"seed": args.seed, "summary": summary, "per_goal": per_goal}
    out["load_average_after"] = os.getloadavg()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1, default=float) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
