"""Offline replay of a TUM RGB-D folder through visual odometry and the SLAM core."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.tum import (
    absolute_trajectory_error,
    load_tum_frame,
    read_tum_sequence,
    write_tum_trajectory,
)

__all__ = ["ReplayReport", "replay_tum"]


@dataclass(frozen=True)
class ReplayReport:
    """Figures of one replay (ATE in m, NaN without ground truth; times in ms per frame)."""

    frames: int
    nodes: int
    lost_frames: int
    loop_closures: int
    odom_ate_m: float
    slam_ate_m: float
    odom_ms_median: float
    slam_ms_median: float


def replay_tum(
    folder: str | Path, out_dir: str | Path,
    params: RtabmapParameters | Mapping[str, str] | None = None,
    *, max_frames: int = 0,
) -> ReplayReport:
    """Run VO + SLAM on every associated frame; write ``odom.txt``, ``poses.txt`` (camera poses,
    TUM format), ``rtabmap.db`` and ``report.json`` into `out_dir`.

    Every frame goes to the SLAM core (no `Rtabmap/DetectionRate` throttling, as in RTAB-Map's
    TUM evaluation with update thresholds at 0 when so configured); lost frames are skipped.
    """
    if params is None:
        params = RtabmapParameters()
    elif not isinstance(params, RtabmapParameters):
        params = RtabmapParameters.from_dict(params)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seq = read_tum_sequence(folder)
    camera = seq.camera
    lt = camera.local_transform
    vo = VisualOdometry(params)
    frames = seq.frames[:max_frames] if max_frames > 0 else seq.frames
    odom_stamps: list[float] = []
    odom_poses: list[np.ndarray] = []
    node_stamps: dict[int, float] = {}
    lost = 0
    loops = 0
    odom_ms: list[float] = []
    slam_ms: list[float] = []
    with SessionDatabase(out / "rtabmap.db", delete_on_start=True) as db:
        slam = Rtabmap(params, database=db)
        for frame in frames:
            rgb, depth = load_tum_frame(frame)
            stamp_ns = round(frame.stamp * 1e9)
            t0 = time.perf_counter()
            odom = vo.process(rgb, depth, camera, stamp_ns)
            odom_ms.append((time.perf_counter() - t0) * 1e3)
            if odom.pose is None:
                lost += 1
                continue
            odom_stamps.append(frame.stamp)
            odom_poses.append(odom.pose @ lt)
            t0 = time.perf_counter()
            result = slam.process(rgb, depth, camera, odom.pose, stamp_ns,
                                  odom_covariance=odom.covariance,
                                  features=odom.frame_features)
            slam_ms.append((time.perf_counter() - t0) * 1e3)
            if result.added:
                node_stamps[result.node_id] = frame.stamp
            if result.loop_closure_id:
                loops += 1
        poses, _ = slam.graph()
        db.save_optimized(poses, slam.occupancy_grid())
    ids = sorted(i for i in poses if i in node_stamps)
    slam_stamps = [node_stamps[i] for i in ids]
    slam_poses = [poses[i] @ lt for i in ids]
    write_tum_trajectory(out / "odom.txt", odom_stamps, odom_poses)
    write_tum_trajectory(out / "poses.txt", slam_stamps, slam_poses)
    odom_ate = slam_ate = float("nan")
    if seq.groundtruth_stamps.size:
        odom_ate, _ = absolute_trajectory_error(
            np.array(odom_stamps), np.array(odom_poses), seq.groundtruth_stamps,
            seq.groundtruth_poses)
        slam_ate, _ = absolute_trajectory_error(
            np.array(slam_stamps), np.array(slam_poses), seq.groundtruth_stamps,
            seq.groundtruth_poses)
    report = ReplayReport(
        len(frames), len(ids), lost, loops, odom_ate, slam_ate,
        float(np.median(odom_ms)) if odom_ms else float("nan"),
        float(np.median(slam_ms)) if slam_ms else float("nan"),
    )
    (out / "report.json").write_text(json.dumps(asdict(report), indent=2))
    return report
