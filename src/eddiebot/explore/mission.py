"""A whole exploration in the simulator: build the stack, run it, judge it against the world.

The simulator, Eddie's base (through the firmware emulator), depthimage_to_laserscan, SLAM
in mapping mode, Nav2's servers and the explore node run in one process on the sim clock,
as fast as the CPU allows. The stack is composed from the package's own launch files
(``slam``: simulator + base + SLAM; ``nav``: the servers, without its localization, which
SLAM provides), as `eddie demo` builds its stages. Afterwards the map is saved (nav2
map_server files) and measured: coverage of the world's reachable free floor, agreement
with the scan-height ground truth, trajectory error of the SLAM poses, distance,
collisions, and whether the robot came home.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml
from scipy import ndimage

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import (
    LaunchDescription,
    NodeSpec,
    build_nodes,
    find_launch_file,
    parse_launch_file,
)
from eddiebot.core.node import Node
from eddiebot.explore.config import EDDIE_EXPLORE_PARAMS
from eddiebot.maps import OccupancyMap
from eddiebot.registry import NODES

__all__ = ["ExploreResult", "coverage", "explore_description", "reachable_free_area", "run_exploration"]

#: The robot counts as home within this distance of its start (m, ground truth).
HOME_TOLERANCE = 0.35
#: Time allowed to come home after exploring stops (sim s).
RETURN_ALLOWANCE = 480.0
#: SLAM settings for exploring: the frontiers are judged on a map at most 2 s old
#: (slam_toolbox publishes every 5 s by default).
SLAM_OVERRIDES: dict[str, Any] = {"map_update_interval": 2.0}
#: The coverage curve's sampling period (exploring time, s).
CURVE_PERIOD = 60.0
#: Without a time limit, exploration stops after this long anyway (sim s).
DEFAULT_CAP = 3600.0


@dataclass
class ExploreResult:
    world: str
    seed: int = 0
    reason: str = ""
    coverage: float = math.nan
    coverage_aligned: float = math.nan
    """Coverage with the map placed by the fit that ATE uses (SLAM poses onto the truth)
    instead of the start pose: a map bent or turned by SLAM's error loses only what its
    shape lost."""
    map_agreement: float = math.nan
    map_agreement_tolerant: float = math.nan
    ate_m: float = math.nan
    distance_m: float = 0.0
    sim_time_s: float = 0.0
    explore_time_s: float = 0.0
    wall_time_s: float = 0.0
    collisions: int = 0
    returned_home: bool = False
    home_error_m: float = math.nan
    home_failure: str = ""
    """Why the robot is not home: the last goal home's failure, or where it ended."""
    turning_share: float = math.nan
    waiting_share: float = math.nan
    """Share of the time standing still (neither driving nor turning): between goals,
    waiting for a plan or a map."""
    coverage_curve: list[tuple[float, float]] = field(default_factory=list)
    """(exploring time s, coverage) every ``CURVE_PERIOD`` s, on the map the explore node
    had then."""
    frontiers_visited: int = 0
    frontiers_abandoned: int = 0
    goals_sent: int = 0
    reachable_area_m2: float = 0.0
    mapped_free_m2: float = 0.0
    map_to_world: tuple[float, float, float] = (0.0, 0.0, 0.0)
    abandoned: list[dict[str, Any]] = field(default_factory=list)
    goals: list[dict[str, Any]] = field(default_factory=list)
    interrupted: bool = False
    truth: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    grid: OccupancyMap | None = None

    def summary(self) -> dict[str, Any]:
        """The figures report.json holds (JSON-ready)."""
        keys = ("world", "seed", "reason", "coverage", "coverage_aligned", "map_agreement", "map_agreement_tolerant",
                "ate_m", "distance_m", "sim_time_s", "explore_time_s", "wall_time_s", "collisions",
                "returned_home", "home_error_m", "home_failure", "turning_share", "waiting_share",
                "frontiers_visited",
                "frontiers_abandoned", "goals_sent", "reachable_area_m2", "mapped_free_m2",
                "interrupted")
        out: dict[str, Any] = {}
        for k in keys:
            v = getattr(self, k)
            out[k] = None if isinstance(v, float) and math.isnan(v) else v
        out["map_to_world"] = list(self.map_to_world)
        out["coverage_curve"] = [[round(t, 1), round(c, 4)] for t, c in self.coverage_curve]
        out["abandoned"] = self.abandoned
        out["goals"] = self.goals
        return out


def explore_description(world: str, seed: int, nav_params: Path, *,
                        camera: tuple[int, int, float] = (320, 240, 10.0),
                        explore_params: dict[str, Any] | None = None) -> LaunchDescription:
    """The launch description of a simulated exploration: ``slam`` (simulator, base, SLAM
    in mapping mode), the depth cloud, ``nav``'s servers without a localization (SLAM owns
    map → odom) and the explore node."""
    args = {"world": world, "seed": str(seed), "camera_width": str(camera[0]),
            "camera_height": str(camera[1]), "camera_rate": str(camera[2])}
    desc = parse_launch_file(find_launch_file("slam"), args)
    nav = parse_launch_file(find_launch_file("nav"), {
        "params_file": str(nav_params), "localization": "slam", "use_sim_time": "true"})
    for spec in desc.nodes:
        if spec.type == "eddiebot.slam.slam_toolbox":
            spec.params.update(SLAM_OVERRIDES)
    servers = [s for s in nav.nodes if s.type != "eddiebot.slam.slam_toolbox"]
    params = {**EDDIE_EXPLORE_PARAMS, **(explore_params or {}), "use_sim_time": True}
    return LaunchDescription(
        nodes=[*desc.nodes, NodeSpec("eddiebot.perception.depth_to_cloud"), *servers,
               NodeSpec("eddiebot.explore.explore", params=params, where="explore")],
        args=desc.args)


def _nav_params(out_dir: Path) -> Path:
    """config/nav2.yaml for exploring (no AMCL, plans through known space only) with the
    costmaps folded into their servers, written to ``out_dir``."""
    from eddiebot.core.launch import package_share
    from eddiebot.nav.nodes._common import nest_nav2_params

    doc = yaml.safe_load((package_share() / "config" / "nav2.yaml").read_text()) or {}
    doc.pop("amcl", None)  # SLAM localizes
    # plans only through space the map has seen: a shortcut through the unknown is often
    # through a wall not yet mapped, and the robot then stalls against it
    planner = doc.get("planner_server", {}).get("ros__parameters", {})
    for name in planner.get("planner_plugins", []):
        if isinstance(planner.get(name), dict):
            planner[name]["allow_unknown"] = False
    # the global costmap also marks from the depth cloud, as the local one: what stands
    # below the scan's band (the office's 0.45 m chairs) is not in the SLAM map, and
    # without it NavFn and the explore node's search plan straight across it
    _add_cloud_source(doc.get("global_costmap", {}).get("global_costmap", {})
                      .get("ros__parameters", {}))
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "nav2_params.yaml"
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(yaml.safe_dump(nest_nav2_params(doc), sort_keys=False))
    tmp.replace(path)
    return path


#: The depth cloud as an observation source of the global costmap's obstacle layer (the
#: local costmap's ``points`` source, config/nav2.yaml). It marks out to the scan's
#: ``raytrace_max_range``: the scan's rays pass over a chair and clear it, and a chair seen
#: within that range is marked again in the same update.
CLOUD_SOURCE: dict[str, Any] = {
    "topic": "/points", "data_type": "PointCloud2", "marking": True, "clearing": False,
    "min_obstacle_height": 0.05, "max_obstacle_height": 0.67,
    "obstacle_max_range": 4.0, "obstacle_min_range": 0.0,
    "raytrace_max_range": 4.5, "raytrace_min_range": 0.0,
}


def _add_cloud_source(costmap: dict[str, Any]) -> None:
    """Add the depth cloud (`CLOUD_SOURCE`, as ``points``) to the obstacle or voxel layer of
    a costmap's parameters, unless a PointCloud2 source is there already."""
    for name in costmap.get("plugins", []):
        layer = costmap.get(name)
        if not isinstance(layer, dict) or not str(layer.get("plugin", "")).endswith(
                ("ObstacleLayer", "VoxelLayer")):
            continue
        sources = str(layer.get("observation_sources", "")).split()
        if any(isinstance(layer.get(s), dict) and layer[s].get("data_type") == "PointCloud2"
               for s in sources):
            return
        layer["observation_sources"] = " ".join([*sources, "points"])
        layer["points"] = dict(CLOUD_SOURCE)
        return


def reachable_free_area(footprint: OccupancyMap, start: tuple[float, float],
                        robot_radius: float) -> npt.NDArray[np.bool_]:
    """Cells of ``footprint`` (the ground truth of what the robot can hit) the robot's
    body can cover: within ``robot_radius`` of a centre position that is clear of every
    obstacle by ``robot_radius`` and connected to ``start`` (world frame, m)."""
    from eddiebot.maps import world_to_map

    occupied = footprint.data >= 65
    clearance = ndimage.distance_transform_edt(~occupied) * footprint.resolution
    centres = clearance >= robot_radius
    labels, _ = ndimage.label(centres, structure=np.ones((3, 3), bool))
    c, r = world_to_map(footprint, np.array(start))
    if not (0 <= r < labels.shape[0] and 0 <= c < labels.shape[1]) or labels[r, c] == 0:
        return np.zeros_like(occupied)
    mine = labels == labels[r, c]
    reach = ndimage.distance_transform_edt(~mine) * footprint.resolution <= robot_radius
    return reach & ~occupied


def coverage(slam: OccupancyMap, area: npt.NDArray[np.bool_], truth: OccupancyMap,
             world_from_map: tuple[float, float, float], free_threshold: int = 19) -> float:
    """Share of the ground-truth ``area`` cells (on ``truth``'s grid) that the SLAM map,
    placed in the world by ``world_from_map``, marks free."""
    from eddiebot.maps import is_inside, map_to_world, world_to_map

    rows, cols = np.nonzero(area)
    if rows.size == 0:
        return math.nan
    world = map_to_world(truth, np.stack([cols, rows], axis=1))
    wx, wy, wth = world_from_map
    c, s = math.cos(wth), math.sin(wth)
    dx, dy = world[:, 0] - wx, world[:, 1] - wy
    in_map = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)
    cells = world_to_map(slam, in_map)
    inside = is_inside(slam, cells)
    v = np.full(rows.size, -1, dtype=np.int16)
    v[inside] = slam.data[cells[inside, 1], cells[inside, 0]]
    return float(np.mean((v >= 0) & (v <= free_threshold)))


def _aligned_placement(est: npt.NDArray[np.float64], truth: npt.NDArray[np.float64],
                       start: tuple[float, ...]) -> tuple[float, float, float]:
    """The map frame's pose in the world by the least-squares rigid fit of the SLAM poses
    ``est`` (world frame, placed by ``start``) onto ``truth`` (ATE's fit), instead of the
    start pose alone."""
    from eddiebot.vslam.transforms import fit_rigid

    e = np.zeros((len(est), 3))
    g = np.zeros((len(truth), 3))
    e[:, :2] = est[:, :2]
    g[:, :2] = truth[:, :2]
    t = fit_rigid(g, e, np.ones(len(e)), three_dof=True)  # truth ≈ t · est
    xy = t[:2, :2] @ np.array(start[:2]) + t[:2, 3]
    return (float(xy[0]), float(xy[1]), float(start[2]) + math.atan2(t[1, 0], t[0, 0]))


def _pose_of(msg: Any) -> tuple[float, float, float]:
    from eddiebot.geometry import quaternion_to_yaw

    p = msg.pose.pose
    q = p.orientation
    return (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))


def turning_share(times_s: npt.NDArray[np.float64], poses: npt.NDArray[np.float64],
                  min_rate: float = 0.2, max_speed: float = 0.05, *,
                  still: bool = False) -> float:
    """Share of the time spent turning in place (|ω| > ``min_rate`` rad/s while moving
    slower than ``max_speed`` m/s), from poses (N, 3) sampled at ``times_s``; with
    ``still``, the share standing still instead (|ω| ≤ ``min_rate``, slower than
    ``max_speed``)."""
    if len(poses) < 2:
        return math.nan
    dt = np.diff(times_s)
    ok = dt > 0
    speed = np.hypot(np.diff(poses[:, 0]), np.diff(poses[:, 1]))[ok] / dt[ok]
    dyaw = np.abs((np.diff(poses[:, 2]) + np.pi) % (2 * np.pi) - np.pi)[ok] / dt[ok]
    turning = (dyaw <= min_rate if still else dyaw > min_rate) & (speed < max_speed)
    total = float(np.sum(dt[ok]))
    return float(np.sum(dt[ok][turning]) / total) if total > 0 else math.nan


def run_exploration(out_dir: Path, *, world: str = "office", seed: int = 0,
                    time_limit: float | None = None, camera: tuple[int, int, float] = (320, 240, 10.0),
                    explore_params: dict[str, Any] | None = None,
                    wall_timeout_s: float = 3600.0, progress: Any = None) -> ExploreResult:
    """Explore ``world`` in the simulator; write map.yaml/map.pgm under ``out_dir`` and
    return the figures. ``time_limit``: exploring time (sim s) after which the robot goes
    home. Ctrl-C (KeyboardInterrupt) stops the robot where it is, saves what was mapped and
    re-raises nothing: the result says ``interrupted``."""
    from eddiebot.demo.mapping import aligned_position_errors, map_agreement
    from eddiebot.explore.node import ExploreNode, ExploreState
    from eddiebot.geometry import se2_compose
    from eddiebot.msgs.geometry_msgs import Twist
    from eddiebot.msgs.nav_msgs import Odometry
    from eddiebot.sim.ground_truth import cached_ground_truth
    from eddiebot.sim.world import ROBOT_RADIUS

    result = ExploreResult(world, seed)
    context = Context(use_sim_time=True)
    params = dict(explore_params or {})
    if time_limit:
        params["time_limit"] = float(time_limit)
    desc = explore_description(world, seed, _nav_params(out_dir), camera=camera,
                               explore_params=params)
    nodes: list[Node] = build_nodes(desc, context, NODES)
    explore: ExploreNode = next(n for n in nodes if isinstance(n, ExploreNode))
    slam: Any = next(n for n in nodes if n.get_name() == "slam_toolbox")
    sim = context.resources["simulator"]
    start = tuple(float(v) for v in sim.world.start)
    result.map_to_world = start  # type: ignore[assignment]
    truth: list[tuple[float, float, float, float]] = []
    probe = Node("explore_probe", context=context)
    probe.create_subscription(Odometry, "/ground_truth/odom", lambda m: truth.append(
        (probe.get_clock().now_ns() / 1e9, *_pose_of(m))), 50)
    stop_pub = probe.create_publisher(Twist, "/cmd_vel_teleop", 1)
    nodes.append(probe)
    executor = SingleThreadedExecutor(context=context)
    for n in nodes:
        executor.add_node(n)
    cap = (time_limit or DEFAULT_CAP) + RETURN_ALLOWANCE + 60.0
    gt = cached_ground_truth(sim.world)
    area = reachable_free_area(gt.footprint, (start[0], start[1]), ROBOT_RADIUS)
    next_sample = 0.0
    t0 = time.perf_counter()
    try:
        while explore.state is not ExploreState.DONE:
            began = explore.started_s
            if (began is not None and explore.grid is not None
                    and explore.state is ExploreState.EXPLORING
                    and context.sim_clock.now_ns() / 1e9 - began >= next_sample):
                result.coverage_curve.append((next_sample, coverage(
                    explore.grid, area, gt.footprint, start)))  # type: ignore[arg-type]
                next_sample += CURVE_PERIOD
            if time.perf_counter() - t0 > wall_timeout_s:
                explore.stop("wall-clock timeout")
                break
            if context.sim_clock.now_ns() / 1e9 > cap:
                explore.stop("sim time cap")
                break
            executor.spin_for(1.0)
            if progress is not None:
                progress(explore, context.sim_clock.now_ns() / 1e9)
        executor.spin_for(1.0)  # let the last scans into the map
    except KeyboardInterrupt:
        result.interrupted = True
        explore.stop("interrupted")
        stop_pub.publish(Twist())  # the teleop source outranks navigation at the mux
        try:
            executor.spin_for(0.3)
        except KeyboardInterrupt:
            pass
    result.wall_time_s = time.perf_counter() - t0
    _fill_from_node(result, explore)
    result.sim_time_s = context.sim_clock.now_ns() / 1e9
    result.collisions = int(sim.collisions)
    tr = np.array(truth) if truth else np.zeros((0, 4))
    result.truth = tr[:, 1:] if len(tr) else np.zeros((0, 3))
    if len(tr) > 1:
        result.distance_m = float(np.sum(np.hypot(np.diff(tr[:, 1]), np.diff(tr[:, 2]))))
        result.turning_share = turning_share(tr[:, 0], tr[:, 1:])
        result.waiting_share = turning_share(tr[:, 0], tr[:, 1:], still=True)
        result.home_error_m = float(math.hypot(tr[-1, 1] - start[0], tr[-1, 2] - start[1]))
        result.returned_home = bool(explore.returned_home) and result.home_error_m <= HOME_TOLERANCE
        if explore.config.return_to_init and not result.interrupted and not result.returned_home:
            result.home_failure = explore.home_failure or (
                f"ended {result.home_error_m:.2f} m from the start" if explore.returned_home
                else "the run's time cap came before the robot was home")
    core = slam.core
    poses = core.node_poses()
    placed: tuple[float, float, float] | None = None
    if len(poses) > 1 and len(tr):
        stamps = np.array([n.scan.stamp_ns for n in core.nodes], dtype=np.float64) / 1e9
        idx = np.clip(np.searchsorted(tr[:, 0], stamps), 0, len(tr) - 1)
        est = se2_compose(np.broadcast_to(np.array(start), poses.shape), poses)
        errors, _ = aligned_position_errors(est, tr[idx, 1:])
        result.ate_m = float(np.sqrt(np.mean(errors**2)))
        placed = _aligned_placement(est, tr[idx, 1:], start)
    core.update_map()
    grid = core.occupancy_map()
    result.grid = grid
    out_dir.mkdir(parents=True, exist_ok=True)
    slam.save_outputs(out_dir)  # the session, and the map as nav2 map_server files
    result.reachable_area_m2 = float(area.sum() * gt.footprint.resolution**2)
    result.coverage = coverage(grid, area, gt.footprint, start)  # type: ignore[arg-type]
    if placed is not None:
        result.coverage_aligned = coverage(grid, area, gt.footprint, placed)
    result.mapped_free_m2 = float(np.sum((grid.data >= 0) & (grid.data <= 19)) * grid.resolution**2)
    result.map_agreement, result.map_agreement_tolerant = map_agreement(grid, gt.scan, np.array(start))
    for n in reversed(nodes):
        n.destroy_node()
    context.shutdown()
    return result


def attached_description(nav_params: Path, *, simulated: bool, with_cloud: bool,
                         slam_params: Path | None = None,
                         explore_params: dict[str, Any] | None = None) -> LaunchDescription:
    """The launch description of an exploration attached to a running simulator or robot:
    ``mapping`` (SLAM alone, on the robot's ``/scan`` and odometry), ``nav``'s servers
    without a localization (SLAM owns map → odom), the depth cloud when the robot
    publishes none (``with_cloud``) and the explore node."""
    sim_time = "true" if simulated else "false"
    args = {"use_sim_time": sim_time}
    if slam_params is not None:
        args["slam_params"] = str(slam_params)
    desc = parse_launch_file(find_launch_file("mapping"), args)
    for spec in desc.nodes:
        if spec.type == "eddiebot.slam.slam_toolbox":
            spec.params.update(SLAM_OVERRIDES)
    nav = parse_launch_file(find_launch_file("nav"), {
        "params_file": str(nav_params), "localization": "slam", "use_sim_time": sim_time})
    servers = [s for s in nav.nodes if s.type != "eddiebot.slam.slam_toolbox"]
    extra = [NodeSpec("eddiebot.perception.depth_to_cloud", params={"use_sim_time": simulated})
             ] if with_cloud else []
    params = {**EDDIE_EXPLORE_PARAMS, **(explore_params or {}), "use_sim_time": simulated}
    return LaunchDescription(
        nodes=[*desc.nodes, *extra, *servers,
               NodeSpec("eddiebot.explore.explore", params=params, where="explore")],
        args=desc.args)


def run_attached(out_dir: Path, context: Context, *, simulated: bool, with_cloud: bool,
                 time_limit: float | None = None, explore_params: dict[str, Any] | None = None,
                 progress: Any = None) -> ExploreResult:
    """Explore with a robot already running on ``context``'s graph (the simulator of
    another process, or the real robot's bring-up): SLAM, navigation and the explore node
    run here, following ``/clock`` when ``simulated``. Stops when exploring and the way
    home are over, or on Ctrl-C / SIGTERM / SIGHUP (the goal is cancelled, a zero velocity
    goes to the teleop input, the robot is not sent home). Writes the SLAM session and
    map under ``out_dir``; the result has no ground-truth figures."""
    import signal
    import threading

    from eddiebot.core.clock_node import ClockFollower
    from eddiebot.core.launch import TERMINATING_SIGNALS
    from eddiebot.explore.node import ExploreNode, ExploreState
    from eddiebot.msgs.geometry_msgs import Twist

    result = ExploreResult("attached")
    params = dict(explore_params or {})
    if time_limit:
        params["time_limit"] = float(time_limit)
    desc = attached_description(_nav_params(out_dir), simulated=simulated,
                                with_cloud=with_cloud, explore_params=params)
    nodes: list[Node] = build_nodes(desc, context, NODES)
    explore: ExploreNode = next(n for n in nodes if isinstance(n, ExploreNode))
    slam: Any = next(n for n in nodes if n.get_name() == "slam_toolbox")
    probe = Node("explore_stop", context=context)
    stop_pub = probe.create_publisher(Twist, "/cmd_vel_teleop", 1)
    nodes.append(probe)
    if simulated:
        clock = Node("clock_follower", context=context)
        ClockFollower(clock)
        nodes.append(clock)
    executor = SingleThreadedExecutor(context=context, drive_sim_time=False)
    for n in nodes:
        executor.add_node(n)
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()

    old = {}
    if threading.current_thread() is threading.main_thread():
        for sig in TERMINATING_SIGNALS:
            old[sig] = signal.signal(sig, on_signal)
    t0 = time.perf_counter()
    try:
        while explore.state is not ExploreState.DONE and not stop.is_set():
            executor.spin_for(0.5)
            if progress is not None:
                progress(explore, explore.get_clock().now_ns() / 1e9)
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    if stop.is_set():
        result.interrupted = True
        explore.stop("interrupted")
        stop_pub.publish(Twist())
        executor.spin_for(0.3)
    result.wall_time_s = time.perf_counter() - t0
    _fill_from_node(result, explore)
    if explore.config.return_to_init and not result.interrupted:
        result.returned_home = bool(explore.returned_home)
        if not result.returned_home:
            result.home_failure = explore.home_failure or "exploring had not ended"
    try:
        slam.save_outputs(out_dir)
    finally:
        if slam.core.nodes:
            slam.core.update_map()
            result.grid = slam.core.occupancy_map()
            result.mapped_free_m2 = float(np.sum((result.grid.data >= 0) & (result.grid.data <= 19))
                                          * result.grid.resolution**2)
        for n in reversed(nodes):
            n.destroy_node()
    return result


def _fill_from_node(result: ExploreResult, explore: Any) -> None:
    """The figures the explore node itself knows: reason, goals, abandoned frontiers,
    times, and the distance along the path it recorded (map frame)."""
    result.reason = "interrupted" if result.interrupted else (explore.finish_reason or "stopped")
    if explore._started_s is not None:
        finished = [g.sent_s for g in explore.goals] or [explore._started_s]
        result.explore_time_s = max(finished) - explore._started_s
        result.sim_time_s = explore.get_clock().now_ns() / 1e9 - explore._started_s
    result.goals_sent = len(explore.goals)
    result.goals = [{"frontier": g.frontier_id, "viewpoint": [round(v, 3) for v in g.viewpoint],
                     "centroid": [round(v, 3) for v in g.centroid], "sent_s": round(g.sent_s, 2),
                     "outcome": g.outcome} for g in explore.goals]
    result.frontiers_visited = sum(g.outcome == "reached" for g in explore.goals)
    result.frontiers_abandoned = len(explore.blacklist)
    result.abandoned = [{"point": list(e.point), "reason": e.reason}
                        for e in explore.blacklist.entries]
    if len(explore.path) > 1:
        p = np.array([(x, y) for x, y, _ in explore.path])
        result.distance_m = float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))))
