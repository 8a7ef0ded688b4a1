"""Demo stage: Eddie maps a world with RGB-D graph SLAM (the ``rtabmap`` node) on wheel odometry.

The simulator, the base stack, depthimage_to_laserscan and the vSLAM node (the report's
parameters, ``launch/vslam.yaml``) run in one process on a simulated clock, as fast as the CPU
allows, while `RouteDriver` drives the route. The vSLAM node poses are taken to the world by the
start pose (the map frame starts at the robot's start) and compared with the simulator's ground
truth at the node stamps: ATE RMSE and max, and the end-point error of wheel odometry alone.
Writes ``rtabmap.db`` (the session), ``vslam_trajectory.tum`` and ``groundtruth.tum`` (world
frame) and ``result.json`` under ``out_dir``.

Optionally (``visual_odometry=True``) frame-to-map visual odometry runs on every camera frame
beside it, for the VO-only drift figure.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.core.node import Node
from eddiebot.core.time import stamp_to_ns
from eddiebot.demo.route import OFFICE_ROUTE, RouteDriver, Waypoint
from eddiebot.geometry import quaternion_to_yaw, se2_compose
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.registry import NODES

__all__ = ["CORRIDOR_LONG_ROUTE", "CORRIDOR_ROUTE", "SLAM_PARAMETERS", "VO_PARAMETERS", "VslamResult",
           "replay_vo_frames", "run_vslam"]

#: Down the ``corridor`` world (40 × 2.2 m) and back, looking around at both ends and again at
#: the start: about 34 m, the return leg revisits every place of the outward one.
CORRIDOR_ROUTE: tuple[Waypoint, ...] = (
    Waypoint(2.5, 1.1, spin=2 * math.pi),
    Waypoint(18.0, 1.1, spin=2 * math.pi),
    Waypoint(2.5, 1.1, spin=2 * math.pi),
)

#: About ten simulated minutes in the ``corridor`` world: to the far end (past both doors, to
#: the cabinet) and back, then half-way and back, a full spin at every turn-around and at the
#: start: about 94 m, five spins, every place revisited at least once.
CORRIDOR_LONG_ROUTE: tuple[Waypoint, ...] = (
    Waypoint(2.5, 1.1, spin=2 * math.pi),
    Waypoint(34.0, 1.1, spin=2 * math.pi),
    Waypoint(2.5, 1.1, spin=2 * math.pi),
    Waypoint(18.0, 1.1, spin=2 * math.pi),
    Waypoint(2.5, 1.1, spin=2 * math.pi),
)


#: The SLAM node's settings for the simulated Eddie on top of launch/vslam.yaml (pass as
#: ``run_vslam(parameters=...)``): the wheel odometry's heading error is modelled as it behaves
#: against ground truth in the simulator: mostly a non-accumulating error per node (the
#: encoders quantise the heading in ≈ 2° steps; σ ≈ 0.8° per node, up to 2.4°), held by
#: per-node odometry frames (`RGBD/OdomHeadingSigma` 1.8°), plus a small accumulating part per
#: node link (0.18°; σ 3 mm in position); loop closures registered 3D→3D from both frames'
#: depth (`Vis/EstimationType` 0), which PnP on floor-tile inliers in a narrow depth band got
#: up to 2.5° wrong in yaw (docs/benchmarks/vslam_sim.md#vslam-sim-ate). Loop hypotheses from
#: a posterior of 0.05 (`Rtabmap/LoopThr`, upstream 0.11) and, when the top one fails, the next
#: two places verified (`RGBD/LoopClosureHypotheses` 3, not upstream): recall at 100 % precision
#: 0.923 / 0.911 on office / warehouse against 0.841 / 0.837 (docs/benchmarks/vslam.md#vslam-recall).
#: launch/vslam.yaml carries the same profile (tests/vslam/test_vslam_parameters_launch_profile.py).
SLAM_PARAMETERS: dict[str, Any] = {"odom_tf_linear_variance": 1e-5,
                                   "odom_tf_angular_variance": 1e-5,
                                   "Vis/EstimationType": "0",
                                   "RGBD/OdomHeadingSigma": "0.0314",
                                   "Rtabmap/LoopThr": "0.05",
                                   "RGBD/LoopClosureHypotheses": "3"}


#: Parameters of the visual odometry run beside the SLAM (VO-only drift): the report's
#: 3-DoF mode, with the inliers' x, y, yaw re-solve (`Vis/PnPRefineIterations`; upstream
#: refines its F2M odometry by local bundle adjustment instead, which is not implemented here)
#: and the check that keeps the tracked motion when a walking person carries the RANSAC vote
#: (`Odom/MotionConsistencyReprojError`, not upstream). Where the visual registration fails
#: or keeps fewer than 40 inliers (a blank wall at a spin), the frame is registered by
#: point-to-plane ICP of the depth cloud (every 4th pixel, ≤ 3 m: the Kinect's depth steps
#: beyond lock ICP onto the last frame) against a 10,000-point scan map
#: (`Odom/IcpFallbackInliers`, not upstream; docs/benchmarks/vslam_sim.md#vslam-sim-vo).
#: The PnP RANSAC draws 2-point planar hypotheses (`Vis/PnPMinimal3DoF`, not upstream; far
#: fewer draws than 6-DoF samples at a low inlier ratio; docs/benchmarks/vslam.md#vslam-vo).
VO_PARAMETERS: dict[str, str] = {"Reg/Force3DoF": "true", "Vis/PnPRefineIterations": "1",
                                 "Vis/PnPMinimal3DoF": "true",
                                 "Odom/MotionConsistencyReprojError": "1.0",
                                 "Odom/IcpFallbackInliers": "40", "Icp/PointToPlane": "true",
                                 "Icp/DownsamplingStep": "4", "Icp/RangeMax": "3",
                                 "Icp/MaxCorrespondenceDistance": "0.1",
                                 "OdomF2M/ScanMaxSize": "10000"}


@dataclass
class VslamResult:
    """Figures of one `run_vslam` (lengths in m, times in s; NaN when not measured)."""

    world: str
    finished: bool = False
    sim_seconds: float = 0.0
    wall_seconds: float = 0.0
    distance_m: float = 0.0
    frames: int = 0
    nodes: int = 0
    loop_closures: int = 0
    ate_rmse_m: float = math.nan
    ate_max_m: float = math.nan
    slam_end_error_m: float = math.nan
    odom_end_error_m: float = math.nan
    odom_ate_rmse_m: float = math.nan
    vo_end_error_m: float = math.nan
    vo_drift_percent: float = math.nan
    vo_lost_frames: int = 0
    frame_ms_median: float = math.nan
    frame_ms_p95: float = math.nan
    database: Path | None = None
    trajectory: Path | None = None
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    slam_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    truth: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def summary(self) -> dict[str, Any]:
        """JSON-ready figures (no arrays)."""
        out = {k: v for k, v in asdict(self).items() if k not in ("slam_world", "truth")}
        for k in ("database", "trajectory"):
            out[k] = str(out[k]) if out[k] is not None else None
        return out


def _pose_of(msg: Any) -> tuple[float, float, float]:
    p = msg.pose.pose
    q = p.orientation
    return (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))


def _write_tum(path: Path, stamps_ns: np.ndarray, xyt: np.ndarray) -> None:
    lines = []
    for t, (x, y, th) in zip(stamps_ns, xyt):
        lines.append(f"{t / 1e9:.9f} {x:.6f} {y:.6f} 0.000000 0.000000 0.000000 "
                     f"{math.sin(th / 2):.9f} {math.cos(th / 2):.9f}")
    path.write_text("\n".join(lines) + ("\n" if lines else ""))


class _VoProbe(Node):
    """Visual odometry on every synchronised RGB + registered depth frame (VO-only drift)."""

    def __init__(self, slam: Any, **kwargs: Any) -> None:
        from eddiebot.msgs.sensor_msgs import Image
        from eddiebot.vslam.odometry import VisualOdometry
        from eddiebot.vslam.parameters import RtabmapParameters

        super().__init__("vo_probe", **kwargs)
        self.slam = slam
        self.vo = VisualOdometry(RtabmapParameters.from_dict(VO_PARAMETERS))
        self.depth: dict[int, Any] = {}
        self.rgb: dict[int, Any] = {}
        self.poses: list[tuple[int, np.ndarray]] = []
        self.lost = 0
        #: (stamp, features, camera) of every frame, when recording for offline VO replays
        self.recorded: list[tuple[int, Any, Any]] | None = None
        #: (rgb, registered depth, raw depth) of every frame, when recording the images too
        self.images: list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self.create_subscription(Image, "/depth/image_raw", self._on_depth, 5)
        self.create_subscription(Image, "/image_raw", self._on_rgb, 5)

    def _on_depth(self, msg: Any) -> None:
        t = stamp_to_ns(msg.header.stamp)
        self.depth = {t: msg}
        if t in self.rgb:
            self._pair(self.rgb.pop(t), msg, t)

    def _on_rgb(self, msg: Any) -> None:
        t = stamp_to_ns(msg.header.stamp)
        self.rgb = {t: msg}
        if t in self.depth:
            self._pair(msg, self.depth.pop(t), t)

    def _pair(self, msg: Any, d: Any, t: int) -> None:
        from eddiebot.vslam.camera import CameraIntrinsics

        slam = self.slam
        info = slam._info_for(slam._rgb_info, t, msg.header.frame_id)
        if info is None:
            return
        rgb_frame = str(info.header.frame_id)
        depth = slam._depth_array(d, info, rgb_frame, t)
        lt = slam._static_tf(slam.frame_id, rgb_frame)
        if depth is None or lt is None:
            return
        rgb = np.asarray(msg.data, np.uint8).reshape(int(msg.height), int(msg.width), 3)
        cam = CameraIntrinsics.from_k(info.k, int(info.width), int(info.height), lt)
        r = self.vo.process(rgb, depth, cam, t)
        if self.recorded is not None:
            self.recorded.append((t, r.frame_features, cam))
        if self.images is not None:
            raw = np.asarray(d.data, np.uint8).view(
                np.uint16 if d.encoding == "16UC1" else np.float32).reshape(int(d.height), int(d.width))
            self.images.append((rgb.copy(), np.asarray(depth).copy(), raw.copy()))
        if r.pose is None:
            self.lost += 1
            return
        self.poses.append((t, r.pose))


def run_vslam(out_dir: Path, *, world: str = "office", route: tuple[Waypoint, ...] = OFFICE_ROUTE,
              seed: int = 0, camera: tuple[int, int, float] = (320, 240, 10.0),
              parameters: dict[str, Any] | None = None, visual_odometry: bool = False,
              wall_timeout_s: float = 1800.0, record_vo: bool = False,
              record_images: bool = False) -> VslamResult:
    """Map ``world`` along ``route`` with the vSLAM node; write database and trajectory under
    ``out_dir``. ``parameters`` are extra node parameters (RTAB-Map ``Group/Name`` strings or the
    node's own, e.g. ``odom_stamp_offset``). ``record_vo`` (with ``visual_odometry``) also writes
    the visual odometry's input — every frame's features, camera and ground truth — to
    ``vo_frames.npz`` for offline odometry replays (`replay_vo_frames`); ``record_images``
    adds every frame's RGB, registered and raw depth (``vo_images.npz``), for work on the
    feature extraction offline."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = VslamResult(world)
    db_path = out_dir / "rtabmap.db"
    context = Context(use_sim_time=True)
    args = {"world": world, "seed": str(seed), "camera_width": str(camera[0]),
            "camera_height": str(camera[1]), "camera_rate": str(camera[2]),
            "database_path": str(db_path), "delete_db_on_start": "true"}
    desc = parse_launch_file(find_launch_file("vslam"), args)
    if parameters:
        spec = next(n for n in desc.nodes if n.type == "eddiebot.vslam.rtabmap")
        spec.params.update(parameters)
    nodes: list[Node] = build_nodes(desc, context, NODES)
    from eddiebot.vslam.node import RtabmapNode

    slam = next(n for n in nodes if isinstance(n, RtabmapNode))
    sim = context.resources["simulator"]
    result.start = tuple(float(v) for v in sim.world.start)  # type: ignore[assignment]
    driver = RouteDriver(route, context=context)
    nodes.append(driver)
    truth: dict[int, tuple[float, float, float]] = {}
    odom: list[tuple[int, tuple[float, float, float]]] = []
    probe = Node("vslam_probe", context=context)
    probe.create_subscription(
        Odometry, "/ground_truth/odom",
        lambda m: truth.__setitem__(stamp_to_ns(m.header.stamp), _pose_of(m)), 50)
    probe.create_subscription(
        Odometry, "/odom", lambda m: odom.append((stamp_to_ns(m.header.stamp), _pose_of(m))), 50)
    nodes.append(probe)
    vo_probe = _VoProbe(slam, context=context) if visual_odometry else None
    if vo_probe is not None:
        nodes.append(vo_probe)
        if record_vo:
            vo_probe.recorded = []
        if record_images:
            vo_probe.images = []
    frame_ms: list[float] = []
    process = slam.core.process

    def timed(*a: Any, **k: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return process(*a, **k)
        finally:
            frame_ms.append((time.perf_counter() - t0) * 1e3)

    slam.core.process = timed  # type: ignore[method-assign]
    executor = SingleThreadedExecutor(context=context)
    for n in nodes:
        executor.add_node(n)
    t0 = time.perf_counter()
    try:
        while not driver.done.is_set() and time.perf_counter() - t0 < wall_timeout_s:
            executor.spin_for(1.0)
        executor.spin_for(2.0)  # settle: the last frames in
        result.wall_seconds = time.perf_counter() - t0
        result.sim_seconds = context.sim_clock.now_ns() / 1e9
        result.finished = driver.done.is_set() and not driver.failed
        result.distance_m = driver.distance
        result.frames = slam.frames_processed
        result.loop_closures = slam.loop_closures
        if frame_ms:
            result.frame_ms_median = float(np.median(frame_ms))
            result.frame_ms_p95 = float(np.percentile(frame_ms, 95))
        _score(result, slam, truth, odom, vo_probe, out_dir)
        if vo_probe is not None and vo_probe.recorded:
            _save_vo_frames(out_dir / "vo_frames.npz", vo_probe.recorded, truth,
                            result.distance_m)
        if vo_probe is not None and vo_probe.images:
            np.savez_compressed(out_dir / "vo_images.npz",
                                rgb=np.stack([i[0] for i in vo_probe.images]),
                                depth=np.stack([i[1] for i in vo_probe.images]),
                                raw_depth=np.stack([i[2] for i in vo_probe.images]))
    finally:
        for n in reversed(nodes):
            n.destroy_node()  # the vSLAM node closes (and completes) its database
        context.shutdown()
    result.database = db_path
    (out_dir / "result.json").write_text(json.dumps(_strict(result.summary()), indent=2,
                                                    allow_nan=False))
    return result


_FEATURE_FIELDS = ("uv", "responses", "sizes", "angles", "octaves", "descriptors", "points")


def _save_vo_frames(path: Path, recorded: list[tuple[int, Any, Any]],
                    truth: dict[int, tuple[float, float, float]], distance_m: float) -> None:
    """Every VO frame's features (concatenated, with per-frame counts), the camera, and the
    ground truth at the frame stamps (world x, y, θ)."""
    stamps = np.array([t for t, _, _ in recorded], np.int64)
    counts = np.array([len(f) for _, f, _ in recorded], np.int64)
    arrays: dict[str, Any] = {name: np.concatenate([getattr(f, name) for _, f, _ in recorded])
              for name in _FEATURE_FIELDS}
    cam = recorded[0][2]
    truth_t = np.array(sorted(truth), dtype=np.int64)
    truth_p = np.array([truth[t] for t in truth_t])
    np.savez_compressed(
        path, stamps=stamps, counts=counts, k=cam.matrix, size=np.array([cam.width, cam.height]),
        local_transform=cam.local_transform, truth=_nearest(truth_t, truth_p, stamps),
        distance=np.array(distance_m), **arrays)


def replay_vo_frames(path: Path, parameters: dict[str, str] | None = None, *,
                     images: Path | None = None, extract: bool = False) -> dict[str, float]:
    """Run `VisualOdometry` offline on frames written by ``record_vo``: end-point drift (% of
    the distance driven), frames lost, CPU seconds. ``images`` (``vo_images.npz`` of the same
    run, ``record_images``) gives every frame's registered depth to the odometry (needed by
    ICP: `Reg/Strategy` 1/2, `Odom/IcpFallbackInliers`); with ``extract`` the features are
    extracted again from its RGB instead of the recorded ones."""
    from eddiebot.vslam.camera import CameraIntrinsics
    from eddiebot.vslam.features import FrameFeatures
    from eddiebot.vslam.odometry import VisualOdometry
    from eddiebot.vslam.parameters import RtabmapParameters

    data = np.load(path)
    w, h = (int(v) for v in data["size"])
    cam = CameraIntrinsics.from_k(data["k"].ravel(), w, h, data["local_transform"])
    vo = VisualOdometry(RtabmapParameters.from_dict({**VO_PARAMETERS, **(parameters or {})}))
    offsets = np.concatenate([[0], np.cumsum(data["counts"])])
    fields = {name: data[name] for name in _FEATURE_FIELDS}
    depth: np.ndarray | None = None
    rgb: np.ndarray | None = None
    if images is not None:
        with np.load(images) as img:
            depth = img["depth"]
            if extract:
                rgb = img["rgb"]
    poses: list[tuple[int, np.ndarray]] = []
    lost = 0
    by_icp = 0
    cpu_ms: list[float] = []
    for i, t in enumerate(data["stamps"]):
        c0 = time.process_time()
        if rgb is not None and depth is not None:
            r = vo.process(rgb[i], depth[i], cam, int(t))
        else:
            a, b = offsets[i], offsets[i + 1]
            feats = FrameFeatures(*(fields[name][a:b] for name in _FEATURE_FIELDS))
            r = vo.process_features(feats, cam, int(t), depth=None if depth is None else depth[i])
        cpu_ms.append((time.process_time() - c0) * 1e3)
        by_icp += int(r.icp)
        if r.pose is None:
            lost += 1
        else:
            poses.append((i, r.pose))
    truth = data["truth"]
    dist = float(data["distance"])
    out = {"frames": float(len(data["stamps"])), "lost": float(lost), "icp_frames": float(by_icp),
           "cpu_s": float(np.sum(cpu_ms) / 1e3), "cpu_ms_median": float(np.median(cpu_ms)),
           "cpu_ms_p95": float(np.percentile(cpu_ms, 95)), "end_error_m": math.nan,
           "drift_percent": math.nan, "yaw_error_deg": math.nan}
    if not poses:
        return out
    i0, first = poses[0]
    i1, last = poses[-1]
    rel = np.linalg.inv(first) @ last
    end = se2_compose(truth[i0], np.array([rel[0, 3], rel[1, 3], math.atan2(rel[1, 0], rel[0, 0])]))
    err = float(np.hypot(*(end[:2] - truth[i1][:2])))
    out["end_error_m"] = err
    out["drift_percent"] = 100.0 * err / dist if dist > 0 else math.nan
    out["yaw_error_deg"] = math.degrees(math.atan2(math.sin(end[2] - truth[i1][2]),
                                                   math.cos(end[2] - truth[i1][2])))
    return out


def _nearest(stamps: np.ndarray, values: np.ndarray, query: np.ndarray) -> np.ndarray:
    idx = np.clip(np.searchsorted(stamps, query), 1, len(stamps) - 1)
    left = np.abs(query - stamps[idx - 1]) <= np.abs(stamps[idx] - query)
    return values[np.where(left, idx - 1, idx)]


def _score(result: VslamResult, slam: Any, truth: dict[int, tuple[float, float, float]],
           odom: list[tuple[int, tuple[float, float, float]]], vo_probe: _VoProbe | None,
           out_dir: Path) -> None:
    start = np.array(result.start)
    stamps, poses = slam.trajectory()
    result.nodes = len(stamps)
    if len(truth) < 2:
        return
    truth_t = np.array(sorted(truth), dtype=np.int64)
    truth_p = np.array([truth[t] for t in truth_t])
    final_truth = truth_p[-1]
    if odom:
        o_t = np.array([t for t, _ in odom], dtype=np.int64)
        o_p = np.array([p for _, p in odom])
        o_w = se2_compose(np.broadcast_to(start, o_p.shape), o_p)
        result.odom_end_error_m = float(np.hypot(*(o_w[-1, :2] - final_truth[:2])))
        gt_o = _nearest(truth_t, truth_p, o_t)
        result.odom_ate_rmse_m = float(np.sqrt(np.mean(np.sum((o_w[:, :2] - gt_o[:, :2]) ** 2, 1))))
        # the map-frame estimate of the end: map→odom × last odometry
        m2o = slam.core.map_to_odom
        last = np.array(odom[-1][1])
        m2o_xyt = np.array([m2o[0, 3], m2o[1, 3], math.atan2(m2o[1, 0], m2o[0, 0])])
        end = se2_compose(start, se2_compose(m2o_xyt, last))
        result.slam_end_error_m = float(np.hypot(*(end[:2] - final_truth[:2])))
    if len(stamps):
        xyt = np.stack([poses[:, 0, 3], poses[:, 1, 3], np.arctan2(poses[:, 1, 0], poses[:, 0, 0])], 1)
        est = se2_compose(np.broadcast_to(start, xyt.shape), xyt)
        gt = _nearest(truth_t, truth_p, stamps)
        err = np.hypot(est[:, 0] - gt[:, 0], est[:, 1] - gt[:, 1])
        result.ate_rmse_m = float(np.sqrt(np.mean(err**2)))
        result.ate_max_m = float(err.max())
        result.slam_world, result.truth = est, gt
        result.trajectory = out_dir / "vslam_trajectory.tum"
        _write_tum(result.trajectory, stamps, est)
        _write_tum(out_dir / "groundtruth.tum", stamps, gt)
    if vo_probe is not None and vo_probe.poses:
        result.vo_lost_frames = vo_probe.lost
        t_first, first = vo_probe.poses[0]
        t_last, last_vo = vo_probe.poses[-1]
        rel = np.linalg.inv(first) @ last_vo
        rel_xyt = np.array([rel[0, 3], rel[1, 3], math.atan2(rel[1, 0], rel[0, 0])])
        g0 = _nearest(truth_t, truth_p, np.array([t_first]))[0]
        g1 = _nearest(truth_t, truth_p, np.array([t_last]))[0]
        est_end = se2_compose(g0, rel_xyt)
        result.vo_end_error_m = float(np.hypot(*(est_end[:2] - g1[:2])))
        if result.distance_m > 0:
            result.vo_drift_percent = 100.0 * result.vo_end_error_m / result.distance_m


def _strict(value: Any) -> Any:
    """JSON has no NaN or infinity: a figure that could not be computed is null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    return value
