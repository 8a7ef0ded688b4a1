"""Offline replay of a TUM RGB-D folder through visual odometry and the SLAM core."""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics, check_depth_plausible
from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.errors import TumFormatError
from eddiebot.vslam.frame_track import FrameTrack
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import to_3dof
from eddiebot.vslam.tum import (
    TUM_CALIBRATIONS,
    TUM_DEPTH_SCALE,
    absolute_trajectory_error,
    load_tum_frame,
    read_tum_sequence,
    write_tum_trajectory,
)

__all__ = ["CameraSetup", "ReplayReport", "replay_tum", "tum_camera_setup"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class CameraSetup:
    """The intrinsics and depth units a replay uses, and where each came from."""

    camera: CameraIntrinsics
    intrinsics_source: str
    depth_scale: float = TUM_DEPTH_SCALE
    depth_scale_source: str = "TUM default (5000 units per metre)"


def tum_camera_setup(
    folder: str | Path, camera: CameraIntrinsics | None = None, intrinsics_source: str = "",
    depth_scale: float | None = None, depth_scale_source: str = "",
) -> CameraSetup:
    """A TUM folder's camera: `camera` if given, else the TUM calibration its name selects
    (freiburg1/2/3), else 525/525/319.5/239.5 (said so in the source); depth units per metre
    `depth_scale` if given, else TUM's 5000."""
    seq_camera = read_tum_sequence(folder).camera
    if camera is not None:
        if (camera.width, camera.height) != (seq_camera.width, seq_camera.height):
            raise TumFormatError(
                f"{folder}: images are {seq_camera.width}x{seq_camera.height}, the given "
                f"intrinsics are for {camera.width}x{camera.height}")
        source = intrinsics_source or "given"
    else:
        camera = seq_camera
        name = Path(folder).name
        key = next((k for k in TUM_CALIBRATIONS if k in name), None)
        source = (f"TUM {key} calibration (folder name)" if key else
                  "default 525/525/319.5/239.5 (the folder name selects no TUM calibration)")
    if depth_scale is None:
        return CameraSetup(camera, source)
    if not depth_scale > 0:
        raise ValueError(f"depth scale must be > 0 units per metre, got {depth_scale}")
    return CameraSetup(camera, source, float(depth_scale), depth_scale_source or "given")


@dataclass(frozen=True)
class ReplayReport:
    """Figures of one replay (ATE in m, NaN without ground truth; times in ms per frame).

    `slam_ate_m` is over every input frame (a lost frame keeps the last pose), `keyframe_ate_m`
    over the key frames; `loop_closures` counts appearance (global) loop closures,
    `proximity_links` proximity-by-space links, `rejected_hypotheses` loop hypotheses that
    failed registration or `RGBD/OptimizeMaxError`. `odometry_resets` counts re-initialised
    odometry (each starts a new map), `map_merges` closures that joined two maps, `maps` the
    map frames left at the end (1 when every new map was merged; poses of the others are in
    their own frames, so one ATE alignment cannot fit them). `words` counts the visual words in
    the database, `node_kb` the mean RAM of a node's data (features, words, grid, cloud images)
    over the nodes that hold it at the end.
    """

    frames: int
    nodes: int
    lost_frames: int
    loop_closures: int
    odom_ate_m: float
    slam_ate_m: float
    odom_ms_median: float
    slam_ms_median: float
    proximity_links: int = 0
    rejected_hypotheses: int = 0
    keyframe_ate_m: float = float("nan")
    ate_frames: int = 0
    intrinsics: tuple[float, float, float, float, int, int] = (0.0, 0.0, 0.0, 0.0, 0, 0)
    intrinsics_source: str = ""
    depth_scale: float = TUM_DEPTH_SCALE
    depth_scale_source: str = ""
    odometry_resets: int = 0
    map_merges: int = 0
    maps: int = 1
    words: int = 0
    node_kb: float = 0.0


def replay_tum(
    folder: str | Path, out_dir: str | Path,
    params: RtabmapParameters | Mapping[str, str] | None = None,
    *, max_frames: int = 0, setup: CameraSetup | None = None,
) -> ReplayReport:
    """Run VO + SLAM on every associated frame; write into `out_dir`:

    - ``poses.txt``: a pose for every input frame (its key frame's optimised pose composed
      with the odometry since; a lost frame keeps the last one), TUM format, pose of the
      colour camera's optical frame in the map frame;
    - ``keyframes.txt``: the key frames' optimised poses (same frame);
    - ``odom.txt`` (frames odometry tracked), ``rtabmap.db`` and ``report.json``.

    Every frame goes to the SLAM core (no `Rtabmap/DetectionRate` throttling, as in RTAB-Map's
    TUM evaluation with update thresholds at 0 when so configured). Lost odometry is re-seeded
    from the current frame after `Odom/ResetCountdown` consecutive lost frames (2 when 0: no
    one is there to call ``reset_odom`` in a replay, and a single lost frame is often a glitch
    the next frame tracks through against the same local map) and the core starts a new map
    there, which a later loop closure merges with the earlier ones. The first frame's depth
    must be plausible at the setup's scale (`DepthScaleError`).
    """
    if params is None:
        params = RtabmapParameters()
    elif not isinstance(params, RtabmapParameters):
        params = RtabmapParameters.from_dict(params)
    out = Path(out_dir)
    seq = read_tum_sequence(folder)
    setup = setup or tum_camera_setup(folder)
    camera, scale = setup.camera, setup.depth_scale
    lt = camera.local_transform
    frames = seq.frames[:max_frames] if max_frames > 0 else seq.frames
    if frames:
        check_depth_plausible(load_tum_frame(frames[0], scale)[1], scale,
                              "give the depth images' units per metre with --depth-scale "
                              "(TUM 5000, ICL-NUIM/Redwood 1000)")
    out.mkdir(parents=True, exist_ok=True)
    vo = VisualOdometry(params)
    odom_stamps: list[float] = []
    odom_poses: list[F64] = []
    track = FrameTrack()
    resets = lost_run = 0
    reset_after = params.odom_reset_countdown if params.odom_reset_countdown > 0 else 2
    odom_ms: list[float] = []
    slam_ms: list[float] = []
    with SessionDatabase(out / "rtabmap.db", delete_on_start=True) as db:
        slam = Rtabmap(params, database=db)
        for frame in frames:
            rgb, depth = load_tum_frame(frame, scale)
            stamp_ns = round(frame.stamp * 1e9)
            t0 = time.perf_counter()
            odom = vo.process(rgb, depth, camera, stamp_ns)
            if odom.pose is None and track.has_key_frame:
                lost_run += 1
                if lost_run >= reset_after:
                    # re-seed the odometry from this frame, where it was: a new map starts
                    vo.reset(vo.pose)
                    odom = vo.process(rgb, depth, camera, stamp_ns)
                    resets += odom.pose is not None
            odom_ms.append((time.perf_counter() - t0) * 1e3)
            if odom.pose is None:
                track.lost_frame(frame.stamp)
                continue
            lost_run = 0
            odom_stamps.append(frame.stamp)
            odom_poses.append(odom.pose @ lt)
            t0 = time.perf_counter()
            result = slam.process(rgb, depth, camera, odom.pose, stamp_ns,
                                  odom_covariance=odom.covariance,
                                  features=odom.frame_features)
            slam_ms.append((time.perf_counter() - t0) * 1e3)
            core_odom = to_3dof(odom.pose) if params.reg_force_3dof else np.asarray(odom.pose)
            track.tracked(frame.stamp, result, core_odom)
        poses, _ = slam.graph()
        db.save_optimized(poses, slam.occupancy_grid())
        db.save_weights({i: n.weight for i, n in slam.memory.nodes.items()})
        words = db.word_count()
        in_ram = [n.data.nbytes for n in slam.memory.nodes.values() if n.data is not None]
        node_kb = float(np.mean(in_ram)) / 1e3 if in_ram else 0.0
    key_stamps, key_poses = track.keyframe_poses(poses)
    key_poses = [p @ lt for p in key_poses]
    frame_stamps, frame_poses = track.frame_poses(poses)
    frame_poses = [p @ lt for p in frame_poses]
    write_tum_trajectory(out / "odom.txt", odom_stamps, odom_poses)
    write_tum_trajectory(out / "poses.txt", frame_stamps, frame_poses)
    write_tum_trajectory(out / "keyframes.txt", key_stamps, key_poses)
    odom_ate = slam_ate = key_ate = float("nan")
    ate_pairs = 0
    if seq.groundtruth_stamps.size:
        gt = (seq.groundtruth_stamps, seq.groundtruth_poses)
        odom_ate, _ = absolute_trajectory_error(np.array(odom_stamps), np.array(odom_poses), *gt)
        slam_ate, ate_pairs = absolute_trajectory_error(
            np.array(frame_stamps), np.array(frame_poses), *gt)
        key_ate, _ = absolute_trajectory_error(np.array(key_stamps), np.array(key_poses), *gt)
    report = ReplayReport(
        len(frames), len(key_stamps), track.lost, track.loop_closures, odom_ate, slam_ate,
        float(np.median(odom_ms)) if odom_ms else float("nan"),
        float(np.median(slam_ms)) if slam_ms else float("nan"),
        proximity_links=track.proximity_links,
        rejected_hypotheses=track.rejected_hypotheses, keyframe_ate_m=key_ate,
        ate_frames=ate_pairs,
        intrinsics=(camera.fx, camera.fy, camera.cx, camera.cy, camera.width, camera.height),
        intrinsics_source=setup.intrinsics_source, depth_scale=scale,
        depth_scale_source=setup.depth_scale_source, odometry_resets=resets,
        map_merges=track.map_merges, maps=max(1, len(slam.map_frames())), words=words,
        node_kb=node_kb,
    )
    (out / "report.json").write_text(json.dumps(asdict(report), indent=2))
    return report

