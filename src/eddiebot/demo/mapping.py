"""Demo stage 2: Eddie maps the ``office`` world with the Kinect-made scan.

The simulator, the whole base stack, depthimage_to_laserscan and the SLAM node run in one
process on a simulated clock, as fast as the CPU allows; a scripted operator drives the
route. Afterwards the map is saved (nav2 map_server files) and judged against the world's
ground truth: trajectory error of the SLAM poses and agreement with the scan-height
ground-truth map on the cells both call known. The benchmark
(``benchmarks/bench_slam_sim.py``) runs the same stage on other worlds and longer routes.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.node import Node
from eddiebot.demo.route import OFFICE_ROUTE, RouteDriver, Waypoint
from eddiebot.geometry import quaternion_to_yaw, se2_compose
from eddiebot.maps import OccupancyMap, save_map
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.registry import NODES

__all__ = ["MappingResult", "aligned_position_errors", "map_agreement", "run_mapping"]


@dataclass
class MappingResult:
    world: str
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    distance_m: float = 0.0
    nodes: int = 0
    loop_closures: int = 0
    collisions: int = 0
    ate_rmse_m: float = math.nan
    ate_max_m: float = math.nan
    odom_end_error_m: float = math.nan
    slam_end_error_m: float = math.nan
    agreement: float = math.nan
    agreement_tolerant: float = math.nan
    map_yaml: Path | None = None
    session: Path | None = None
    bag: Path | None = None
    finished: bool = False
    slam_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    truth: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    odom_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    grid: OccupancyMap | None = None
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scan_cpu_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """CPU time the SLAM core spent on each processed scan (ms, the node's thread)."""
    map_update_cpu_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    low_feature_episodes: int = 0
    """Low-feature warnings logged (once per episode)."""
    low_feature_matches: int = 0
    """Scan matches whose variance along their weakest direction exceeded the threshold."""
    odom_ate_rmse_m: float = math.nan
    """Wheel odometry's position RMSE at the SLAM nodes' times (the same start alignment)."""
    ate_aligned_rmse_m: float = math.nan
    """Position RMSE after the one rigid planar transform that best fits the SLAM poses onto the
    truth (the TUM benchmark's and ``evo_ape --align``'s ATE): the map's shape, without the
    turn of the whole map about its start that the first nodes' heading error leaves."""
    ate_aligned_max_m: float = math.nan
    aligned_turn_deg: float = math.nan
    """The rotation of that fit: how far the whole SLAM map is turned against the world."""
    odom_ate_aligned_rmse_m: float = math.nan


def map_agreement(slam: OccupancyMap, truth: OccupancyMap, world_from_map: np.ndarray,
                  tolerance_cells: int = 1) -> tuple[float, float]:
    """Fraction of cells both maps call known on which they agree (occupied vs free): strict,
    and with an occupied cell matching any occupied ground-truth cell within
    ``tolerance_cells`` (walls one cell apart are the same wall)."""
    rows, cols = np.nonzero(slam.data >= 0)
    if rows.size == 0:
        return math.nan, math.nan
    res = slam.resolution
    ox, oy, oth = slam.origin
    local = np.stack([(cols + 0.5) * res, (rows + 0.5) * res], axis=1)
    c, s = math.cos(oth), math.sin(oth)
    in_map = np.stack([ox + c * local[:, 0] - s * local[:, 1], oy + s * local[:, 0] + c * local[:, 1]], 1)
    wx, wy, wth = world_from_map
    c, s = math.cos(wth), math.sin(wth)
    world = np.stack([wx + c * in_map[:, 0] - s * in_map[:, 1], wy + s * in_map[:, 0] + c * in_map[:, 1]], 1)
    tc = np.floor((world[:, 0] - truth.origin[0]) / truth.resolution).astype(int)
    tr = np.floor((world[:, 1] - truth.origin[1]) / truth.resolution).astype(int)
    inside = (tc >= 0) & (tr >= 0) & (tc < truth.width) & (tr < truth.height)
    slam_occ = slam.data[rows, cols] >= 65
    t = np.full(rows.size, -1, dtype=np.int16)
    t[inside] = truth.data[tr[inside], tc[inside]]
    known = t >= 0
    truth_occ = t >= 65
    strict = float(np.mean(slam_occ[known] == truth_occ[known])) if known.any() else math.nan
    # dilate the ground truth's occupied cells for the tolerant figure
    occ = truth.data >= 65
    dil = occ.copy()
    for dr in range(-tolerance_cells, tolerance_cells + 1):
        for dc in range(-tolerance_cells, tolerance_cells + 1):
            dil |= np.roll(np.roll(occ, dr, axis=0), dc, axis=1)
    near = np.zeros(rows.size, dtype=bool)
    near[inside] = dil[tr[inside], tc[inside]]
    ok = np.where(slam_occ, near, ~truth_occ)
    tolerant = float(np.mean(ok[known])) if known.any() else math.nan
    return strict, tolerant


def aligned_position_errors(est: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, float]:
    """Planar position errors of ``est`` (N, ≥2) against ``truth`` after the least-squares
    rigid 2D fit of the one onto the other (Kabsch/Horn, no scale), and the fit's rotation (rad).

    This is the absolute trajectory error of the TUM RGB-D benchmark and of ``evo_ape --align``;
    the errors measured against the start pose alone also hold any turn of the whole path.
    """
    from eddiebot.vslam.transforms import fit_rigid

    e = np.zeros((len(est), 3))
    g = np.zeros((len(truth), 3))
    e[:, :2] = np.asarray(est, dtype=float)[:, :2]
    g[:, :2] = np.asarray(truth, dtype=float)[:, :2]
    if len(e) < 2:
        return np.hypot(*(e[:, :2] - g[:, :2]).T), 0.0
    t = fit_rigid(g, e, np.ones(len(e)), three_dof=True)  # truth ≈ t · est
    moved = e[:, :2] @ t[:2, :2].T + t[:2, 3]
    return np.hypot(*(moved - g[:, :2]).T), math.atan2(t[1, 0], t[0, 0])


def _pose_of(msg: Any) -> tuple[float, float, float]:
    p = msg.pose.pose
    q = p.orientation
    return (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))


def run_mapping(out_dir: Path, *, world: str = "office", route: tuple[Waypoint, ...] = OFFICE_ROUTE,
                seed: int = 0, camera: tuple[int, int, float] = (320, 240, 10.0),
                record: bool = True, wall_timeout_s: float = 900.0,
                dashboard: bool = False, slam_params: Path | None = None,
                record_topics: list[str] | None = None) -> MappingResult:
    """Map ``world`` along ``route``; write map, session and bag under ``out_dir``.

    ``slam_params``: a slam_toolbox parameter file instead of the package's config/slam.yaml.
    ``record_topics``: record only these topics (no compressed RGB-D) when ``record``.
    Files are named after the world (``office_map.yaml``, ``office_session.slam``).
    """
    from eddiebot.sim.ground_truth import cached_ground_truth
    from eddiebot.slam.session import save_session

    result = MappingResult(world)
    context = Context(use_sim_time=True)
    args = {"world": world, "seed": str(seed), "camera_width": str(camera[0]),
            "camera_height": str(camera[1]), "camera_rate": str(camera[2])}
    if slam_params is not None:
        args["slam_params"] = str(slam_params)
    nodes: list[Node] = build_nodes(parse_launch_file(find_launch_file("slam"), args), context, NODES)
    slam: Any = next(n for n in nodes if n.get_name() == "slam_toolbox")
    sim = context.resources["simulator"]
    result.start = tuple(float(v) for v in sim.world.start)  # type: ignore[assignment]
    driver = RouteDriver(route, context=context)
    nodes.append(driver)
    truth: dict[int, tuple[float, float, float]] = {}
    odom: list[tuple[int, tuple[float, float, float]]] = []
    probe = Node("demo_probe", context=context)
    probe.create_subscription(Odometry, "/ground_truth/odom",
                              lambda m: truth.__setitem__(probe.get_clock().now_ns(), _pose_of(m)), 50)
    probe.create_subscription(Odometry, "/odom",
                              lambda m: odom.append((probe.get_clock().now_ns(), _pose_of(m))), 50)
    nodes.append(probe)
    if record:
        from eddiebot.bag import RecorderNode

        bag = out_dir / "mapping_bag"
        if bag.exists():
            import shutil

            shutil.rmtree(bag)
        from eddiebot.perception.compress import ImageCompressorNode

        topics = record_topics or ["/scan", "/odom", "/ground_truth/odom", "/tf", "/tf_static", "/map", "/cmd_vel",
                  "/joint_states", "/eddie/ir/left", "/eddie/ir/center", "/eddie/ir/right",
                  "/eddie/ping/left", "/eddie/ping/right", "/robot_description", "/sim/collisions",
                  "/image_raw/compressed", "/depth/image_raw/compressedDepth", "/camera_info",
                  "/depth/camera_info"]
        if record_topics is None:
            # RGB-D at 2 Hz, compressed (raw 30 Hz RGB-D would be 46 MB per simulated second)
            nodes.append(ImageCompressorNode(context=context,
                                             parameter_overrides={"max_rate": 2.0}))
        nodes.append(RecorderNode(context=context,
                                  parameter_overrides={"output": str(bag), "topics": topics}))
        result.bag = bag
    executor = SingleThreadedExecutor(context=context)
    for n in nodes:
        executor.add_node(n)
    handle = None
    if dashboard:
        try:
            from eddiebot.viz.dashboard import start_dashboard

            handle = start_dashboard(context, "127.0.0.1", 0, print_url=False)
            print(f"watch it live (fast-forward): {handle.url}", flush=True)
        except Exception as exc:  # the demo goes on without a viewer
            print(f"(no dashboard: {exc})")
    t0 = time.perf_counter()
    while not driver.done.is_set() and time.perf_counter() - t0 < wall_timeout_s:
        executor.spin_for(1.0)
    executor.spin_for(2.0)  # settle; let the last scans in
    result.wall_seconds = time.perf_counter() - t0
    result.sim_seconds = context.sim_clock.now_ns() / 1e9
    result.finished = driver.done.is_set() and not driver.failed
    result.distance_m = driver.distance
    result.collisions = int(sim.collisions)
    core = slam.core
    result.nodes = len(core.nodes)
    result.loop_closures = len(core.loop_closures)
    # SLAM poses in the world: the map frame starts at the robot's start pose
    start = np.array(result.start)
    poses = core.node_poses()
    stamps = np.array([n.scan.stamp_ns for n in core.nodes], dtype=np.int64)
    truth_t = np.array(sorted(truth))
    truth_p = np.array([truth[t] for t in truth_t])
    if len(poses) and len(truth_t):
        idx = np.clip(np.searchsorted(truth_t, stamps), 0, len(truth_t) - 1)
        gt = truth_p[idx]
        est = se2_compose(np.broadcast_to(start, poses.shape), poses)
        err = np.hypot(est[:, 0] - gt[:, 0], est[:, 1] - gt[:, 1])
        result.ate_rmse_m = float(np.sqrt(np.mean(err**2)))
        result.ate_max_m = float(err.max())
        aligned, turn = aligned_position_errors(est, gt)
        result.ate_aligned_rmse_m = float(np.sqrt(np.mean(aligned**2)))
        result.ate_aligned_max_m = float(aligned.max())
        result.aligned_turn_deg = math.degrees(turn)
        result.slam_world, result.truth = est, truth_p
        if odom:
            odom_t = np.array([t for t, _ in odom], dtype=np.int64)
            at = np.clip(np.searchsorted(odom_t, stamps), 0, len(odom) - 1)
            o_est = se2_compose(np.broadcast_to(start, (len(at), 3)),
                                np.array([odom[k][1] for k in at]))
            o_err = np.hypot(o_est[:, 0] - gt[:, 0], o_est[:, 1] - gt[:, 1])
            result.odom_ate_rmse_m = float(np.sqrt(np.mean(o_err**2)))
            o_aligned, _ = aligned_position_errors(o_est, gt)
            result.odom_ate_aligned_rmse_m = float(np.sqrt(np.mean(o_aligned**2)))
        # end-point errors: wheel odometry alone vs SLAM
        final_truth = truth_p[-1]
        if odom:
            o = se2_compose(start, np.array(odom[-1][1]))
            result.odom_end_error_m = float(math.hypot(o[0] - final_truth[0], o[1] - final_truth[1]))
            result.odom_world = se2_compose(np.broadcast_to(start, (len(odom), 3)),
                                            np.array([p for _, p in odom]))
        m2o = core.map_to_odom
        last_odom = np.array(odom[-1][1]) if odom else np.zeros(3)
        s_end = se2_compose(start, se2_compose(m2o, last_odom))
        result.slam_end_error_m = float(math.hypot(s_end[0] - final_truth[0], s_end[1] - final_truth[1]))
    result.scan_cpu_ms = 1e3 * np.array(slam.scan_cpu_s, dtype=np.float64)
    result.map_update_cpu_ms = 1e3 * np.array(slam.map_update_cpu_s, dtype=np.float64)
    result.low_feature_episodes = int(slam.low_feature_episodes)
    result.low_feature_matches = int(slam.low_feature_matches)
    core.update_map()
    grid = core.occupancy_map()
    result.grid = grid
    out_dir.mkdir(parents=True, exist_ok=True)
    name = Path(world).stem
    result.map_yaml = save_map(grid, out_dir / f"{name}_map")
    result.session = save_session(core, out_dir / f"{name}_session.slam")
    gt_maps = cached_ground_truth(sim.world)
    result.agreement, result.agreement_tolerant = map_agreement(grid, gt_maps.scan, start)
    if handle is not None:
        handle.stop()
    for n in reversed(nodes):
        n.destroy_node()
    context.shutdown()
    return result
