"""Demo stage 3: Eddie tours a list of goals in the map it just made.

The simulator, the base stack, AMCL on the saved map and Nav2's servers run in one process
on the sim clock; goals go to ``navigate_to_pose`` one after another, as ``eddie goal`` sends
them. The report gives per goal the result, the time, the driven path length against the
straight line, and the final error against the ground truth, and draws planned and driven
paths on the map.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.action import ActionClient
from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.node import Node
from eddiebot.demo.report import Report, world_to_map
from eddiebot.geometry import quaternion_to_yaw, yaw_to_quaternion
from eddiebot.msgs.nav2_msgs import NavigateToPose
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.nav_msgs import Path as PathMsg
from eddiebot.registry import NODES

__all__ = ["OFFICE_GOALS", "GoalOutcome", "run_nav_stage"]

#: goals in the SLAM map frame (origin: the robot's start pose at (1.5, 7.5) in the world).
#: The second keeps 0.6 m south of the corridor's walking person's line (map y 0.3): the
#: mapping drive leaves that person's trace in the map at (10.5, 0.0-0.25), which made a
#: goal at (10.5, 0.1) occupied, and NavFn's tolerance moved it 0.3-0.4 m
OFFICE_GOALS: tuple[tuple[float, float, float], ...] = (
    (5.5, 0.0, 0.0),
    (10.5, -0.3, 0.0),
    (14.95, 2.6, math.pi / 2),
    (6.0, 0.0, math.pi),
    (0.5, 0.0, math.pi),
)


@dataclass
class GoalOutcome:
    goal: tuple[float, float, float]
    status: str = "not sent"
    error_code: int = 0
    seconds: float = 0.0
    driven_m: float = 0.0
    straight_m: float = 0.0
    final_error_m: float = math.nan
    reached: bool = False
    retried: str = ""
    """Why the goal was sent a second time ("" when it was not)."""


@dataclass
class NavStageResult:
    outcomes: list[GoalOutcome] = field(default_factory=list)
    wall_seconds: float = 0.0
    sim_seconds: float = 0.0
    collisions: int = 0
    driven: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    plans: list[np.ndarray] = field(default_factory=list)


def _resolved_params(out: Path, initial_pose: tuple[float, float, float]) -> Path:
    from eddiebot.nav.params_file import default_params, resolve_params

    return resolve_params(default_params(), out, initial_pose)


#: ComputePathToPose's GOAL_OCCUPIED: the goal cell is an obstacle (in the office, the
#: walking person may stand there); such a goal is sent again once after RETRY_WAIT_S.
GOAL_OCCUPIED = 206
RETRY_WAIT_S = 5.0


def run_nav_stage(out: Path, report: Report, *, seed: int = 0,
                  goals: tuple[tuple[float, float, float], ...] = OFFICE_GOALS,
                  goal_timeout_s: float = 120.0) -> bool:
    """Tour ``goals`` in ``out/office_map.yaml``; add a section to ``report``."""
    map_yaml = out / "office_map.yaml"
    if not map_yaml.exists():
        report.add("## Stage 3 — navigation\n\nSkipped: no map from the mapping stage.\n")
        print("no map from the mapping stage: navigation skipped")
        return False
    result = NavStageResult()
    context = Context(use_sim_time=True)
    params = _resolved_params(out, (0.0, 0.0, 0.0))
    args = {"world": "office", "seed": str(seed), "map": str(map_yaml), "params_file": str(params)}
    nodes: list[Node] = build_nodes(parse_launch_file(find_launch_file("nav_sim"), args), context, NODES)
    sim = context.resources["simulator"]
    start = sim.world.start
    client_node = Node("demo_navigator", context=context)
    client = ActionClient(client_node, NavigateToPose, "navigate_to_pose")
    truth: list[tuple[float, float, float]] = []

    def on_truth(msg: Any) -> None:
        p = msg.pose.pose
        q = p.orientation
        truth.append((p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w)))

    client_node.create_subscription(Odometry, "/ground_truth/odom", on_truth, 50)
    plans: list[np.ndarray] = []

    def on_plan(msg: Any) -> None:
        pts = np.array([[ps.pose.position.x, ps.pose.position.y] for ps in msg.poses])
        if len(pts):
            plans.append(pts)

    client_node.create_subscription(PathMsg, "/plan", on_plan, 10)
    executor = SingleThreadedExecutor(context=context)
    for n in [*nodes, client_node]:
        executor.add_node(n)
    t0 = time.perf_counter()
    executor.spin_for(3.0)  # lifecycle start-up, first scans for AMCL
    for goal in goals:
        outcome = GoalOutcome(goal)
        result.outcomes.append(outcome)
        pose_world_before = truth[-1] if truth else start
        before = world_to_map(np.array([pose_world_before]), start)[0]
        outcome.straight_m = math.hypot(goal[0] - before[0], goal[1] - before[1])
        msg = NavigateToPose.Goal()
        msg.pose.header.frame_id = "map"
        msg.pose.pose.position.x, msg.pose.pose.position.y = goal[0], goal[1]
        q = yaw_to_quaternion(goal[2])
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = q
        n_before = len(truth)
        t_goal = context.sim_clock.now_ns()
        deadline = t_goal + round(goal_timeout_s * 1e9)
        for attempt in range(2):
            send = client.send_goal_async(msg)
            while not send.done() and context.sim_clock.now_ns() < deadline:
                executor.spin_for(0.1)
            handle = send.result() if send.done() else None
            if handle is None or not handle.accepted:
                outcome.status = "rejected"
                break
            res_future = handle.get_result_async()
            while not res_future.done() and context.sim_clock.now_ns() < deadline:
                executor.spin_for(0.2)
            outcome.seconds = (context.sim_clock.now_ns() - t_goal) / 1e9
            if not res_future.done():
                outcome.status = "timed out"
                cancel = handle.cancel_goal_async()
                executor.spin_for(1.0)
                _ = cancel
                break
            wrapped = res_future.result()
            status = int(getattr(wrapped, "status", 0))
            res = getattr(wrapped, "result", wrapped)
            outcome.error_code = int(getattr(res, "error_code", 0))
            outcome.status = {4: "succeeded", 5: "canceled", 6: "aborted"}.get(status, str(status))
            if attempt == 0 and outcome.error_code == GOAL_OCCUPIED:
                # the office's walking person standing on the goal: as an operator would,
                # wait for them to walk on and send the goal again, once
                outcome.retried = f"code {GOAL_OCCUPIED}, goal occupied: sent again after {RETRY_WAIT_S:.0f} s"
                executor.spin_for(RETRY_WAIT_S)
                continue
            break
        if outcome.status in ("rejected", "timed out"):
            continue
        seg = np.array(truth[n_before:]) if len(truth) > n_before else np.zeros((0, 3))
        if len(seg) > 1:
            outcome.driven_m = float(np.sum(np.hypot(np.diff(seg[:, 0]), np.diff(seg[:, 1]))))
            end = world_to_map(seg[-1:], start)[0]
            outcome.final_error_m = math.hypot(end[0] - goal[0], end[1] - goal[1])
        outcome.reached = outcome.status == "succeeded" and outcome.final_error_m < 0.35
    result.wall_seconds = time.perf_counter() - t0
    result.sim_seconds = context.sim_clock.now_ns() / 1e9
    result.collisions = int(sim.collisions)
    result.driven = world_to_map(np.array(truth), start) if truth else np.zeros((0, 3))
    result.plans = plans
    for n in reversed([*nodes, client_node]):
        n.destroy_node()
    context.shutdown()
    _report(out, report, result, map_yaml)
    reached = sum(o.reached for o in result.outcomes)
    print(f"reached {reached}/{len(result.outcomes)} goals in {result.sim_seconds:.0f} s simulated "
          f"({result.wall_seconds:.0f} s wall), {result.collisions} collisions")
    for o in result.outcomes:
        print(f"  goal ({o.goal[0]:.2f}, {o.goal[1]:.2f}): {o.status} (code {o.error_code}) in "
              f"{o.seconds:.1f} s, drove {o.driven_m:.2f} m for {o.straight_m:.2f} m straight, "
              f"final error {o.final_error_m:.3f} m" + (f"; first try {o.retried}" if o.retried else ""))
    return reached == len(result.outcomes)


def _report(out: Path, report: Report, result: NavStageResult, map_yaml: Path) -> None:
    from eddiebot.maps import load_map
    from eddiebot.viz.snapshot import render_map

    rows = ["| goal (map frame) | result | time (s) | driven (m) | straight line (m) | final error (m) |",
            "|---|---|---|---|---|---|"]
    for o in result.outcomes:
        rows.append(f"| ({o.goal[0]:.2f}, {o.goal[1]:.2f}, {math.degrees(o.goal[2]):.0f}°) | "
                    f"{o.status} ({o.error_code}){f'; first try {o.retried}' if o.retried else ''} | "
                    f"{o.seconds:.1f} | {o.driven_m:.2f} | {o.straight_m:.2f} | {o.final_error_m:.3f} |")
    trajectories: dict[str, Any] = {"driven (ground truth)": result.driven}
    if result.plans:
        trajectories["last global plan"] = result.plans[-1]
    goals = {label: np.array([o.goal for o in result.outcomes if o.reached == hit])
             for label, hit in (("goal reached", True), ("goal missed", False))}
    markers = {label: pts for label, pts in goals.items() if len(pts)}
    try:
        render_map(load_map(map_yaml), trajectories=trajectories, markers=markers,
                   out_path=out / "navigation.png",
                   title="navigation in the saved map (map frame)")
        picture = "![navigation](navigation.png)\n"
    except Exception as exc:  # a picture must not lose the numbers
        picture = f"(no picture: {exc})\n"
    reached = sum(o.reached for o in result.outcomes)
    report.add("## Stage 3 — a tour of goals in the saved map (navigation)\n\n"
               "The simulator, the base stack, AMCL on the map from stage 2 and Nav2-style servers "
               "(planner, controller, smoother, velocity smoother, collision monitor, behaviours, "
               "BT navigator) ran in one process; each goal went to `navigate_to_pose`.\n\n"
               f"Reached {reached} of {len(result.outcomes)} goals; {result.collisions} collisions; "
               f"{result.sim_seconds:.0f} s simulated in {result.wall_seconds:.0f} s wall.\n\n"
               + "\n".join(rows) + "\n\n" + picture)

