"""RGB-D visual odometry: frame-to-map (`Odom/Strategy` 0) and frame-to-frame (1).

Pure core: frames in, pose of the robot base in the odometry frame out. When tracking is lost
the result carries ``pose=None`` and a covariance of 9999 on the diagonal (what the ROS node
publishes as a "null" odometry); a pose is never made up.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.parameters import ODOM_STRATEGY_F2F, RtabmapParameters
from eddiebot.vslam.registration import (
    LOST_VARIANCE,
    RegistrationResult,
    estimate_covariance,
    refine_pnp,
    register,
    reprojection_errors,
)
from eddiebot.vslam.transforms import from_xyz_rpy, se3_inverse, to_3dof, xyz_rpy, yaw_of

__all__ = ["OdometryResult", "VisualOdometry"]

F64 = NDArray[np.float64]
# A result this close to the prediction is the tracked motion (m, rad)...
_SAME_AS_PREDICTED = (0.02, np.radians(1.0))
# ...and a re-solve this close to the result found the same solution.
_SAME_SOLUTION = (0.01, np.radians(0.5))
_MIN_SECOND_MOTION_SHARE = 0.25  # of the result's inliers


def _lost_covariance() -> F64:
    return np.eye(6) * LOST_VARIANCE


@dataclass(frozen=True)
class OdometryResult:
    """One odometry update. `pose`: base in odom frame (4×4, m), None when lost."""

    pose: F64 | None
    covariance: F64 = field(default_factory=_lost_covariance)
    lost: bool = False
    keyframe: bool = False
    inliers: int = 0
    matches: int = 0
    features: int = 0
    local_map_size: int = 0
    frame_features: FrameFeatures | None = None


@dataclass
class _LocalMap:
    points: F64  # (M, 3) odom frame
    descriptors: NDArray[np.uint8]
    responses: NDArray[np.float32]
    born: NDArray[np.int64]  # frame counter when added

    def as_features(self) -> FrameFeatures:
        m = self.points.shape[0]
        return FrameFeatures(
            np.zeros((m, 2), np.float32), self.responses, np.zeros(m, np.float32),
            np.zeros(m, np.float32), np.zeros(m, np.int32), self.descriptors, self.points,
        )


class VisualOdometry:
    """Frame-to-map or frame-to-frame visual odometry with constant-velocity motion prediction."""

    def __init__(self, params: RtabmapParameters, initial_pose: F64 | None = None) -> None:
        self.params = params
        self._extractor = FeatureExtractor(
            params, max_features=params.vis_max_features, strategy=params.vis_feature_type
        )
        self._initial = np.eye(4) if initial_pose is None else np.asarray(initial_pose, float)
        self.reset(self._initial)

    # -- state ------------------------------------------------------------------------------
    def reset(self, pose: F64 | None = None) -> None:
        """Forget the map; the next frame starts again at `pose` (default: the initial pose)."""
        self._pose = (self._initial if pose is None else np.asarray(pose, float)).copy()
        self._velocity: F64 | None = None  # per-second twist as (x, y, z, roll, pitch, yaw)
        self._last_stamp_ns: int | None = None
        self._keyframe: FrameFeatures | None = None
        self._keyframe_pose = self._pose.copy()
        self._map: _LocalMap | None = None
        self._frame = 0
        self._lost_count = 0
        self._initialised = False

    @property
    def pose(self) -> F64:
        """Last tracked pose (base in odom frame)."""
        return self._pose.copy()

    # -- processing -------------------------------------------------------------------------
    def process(
        self,
        image: NDArray[np.uint8],
        depth: NDArray[np.generic],
        camera: CameraIntrinsics,
        stamp_ns: int,
    ) -> OdometryResult:
        """Track one registered RGB-D frame stamped `stamp_ns`."""
        features = self._extractor.extract(image, depth, camera, depth_as_mask=False)
        return self.process_features(features, camera, stamp_ns)

    def process_features(
        self, features: FrameFeatures, camera: CameraIntrinsics, stamp_ns: int
    ) -> OdometryResult:
        """Track a frame whose features were already extracted (base-frame 3D points)."""
        p = self.params
        self._frame += 1
        n_depth = int(features.has_depth.sum())
        if not self._initialised:
            if n_depth < p.vis_min_inliers:
                return OdometryResult(None, lost=True, features=len(features),
                                      frame_features=features)
            self._start_map(features)
            self._last_stamp_ns = stamp_ns
            self._initialised = True
            self._lost_count = 0
            return OdometryResult(self._pose.copy(), _lost_covariance(), keyframe=True,
                                  features=len(features), local_map_size=self._map_size(),
                                  frame_features=features)
        dt = 0.0 if self._last_stamp_ns is None else (stamp_ns - self._last_stamp_ns) * 1e-9
        motion = self._predict(dt)
        predicted = self._pose @ motion
        if p.odom_strategy == ODOM_STRATEGY_F2F:
            assert self._keyframe is not None
            guess = se3_inverse(self._keyframe_pose) @ predicted
            result = register(self._keyframe, features, camera, p, guess)
            if p.odom_motion_consistency > 0 and self._velocity is not None:
                result = self._keep_tracked_motion(result, self._keyframe, features, camera,
                                                   guess)
            new_pose = None if result.transform is None else self._keyframe_pose @ result.transform
        else:
            assert self._map is not None
            local_map = self._map.as_features()
            result = register(local_map, features, camera, p, predicted)
            if p.odom_motion_consistency > 0 and self._velocity is not None:
                result = self._keep_tracked_motion(result, local_map, features, camera, predicted)
            new_pose = result.transform
        if new_pose is None:
            return self._lost(features, result)
        if p.reg_force_3dof:
            new_pose = to_3dof(new_pose)
        if dt > 0:
            self._velocity = np.array(xyz_rpy(se3_inverse(self._pose) @ new_pose)) / dt
        self._pose = new_pose
        self._last_stamp_ns = stamp_ns
        self._lost_count = 0
        keyframe = self._is_keyframe(result, len(features))
        if keyframe:
            if p.odom_strategy == ODOM_STRATEGY_F2F:
                if n_depth >= p.vis_min_inliers:
                    self._keyframe = features
                    self._keyframe_pose = new_pose.copy()
            else:
                self._update_map(features, result, new_pose)
        return OdometryResult(
            new_pose.copy(), result.covariance, keyframe=keyframe, inliers=result.inliers,
            matches=result.matches, features=len(features), local_map_size=self._map_size(),
            frame_features=features,
        )

    # -- helpers ----------------------------------------------------------------------------
    def _predict(self, dt: float) -> F64:
        if not self.params.odom_guess_motion or self._velocity is None or dt <= 0:
            return np.eye(4)
        v = self._velocity * dt
        motion = from_xyz_rpy(*(float(x) for x in v))
        return to_3dof(motion) if self.params.reg_force_3dof else motion

    def _keep_tracked_motion(
        self,
        result: RegistrationResult,
        old: FrameFeatures,
        new: FrameFeatures,
        camera: CameraIntrinsics,
        guess: F64,
    ) -> RegistrationResult:
        """`Odom/MotionConsistencyReprojError`. RANSAC keeps the motion with the most support, so a
        textured person walking towards the robot can carry it (the odometry then reports the
        closing speed). When the result leaves the prediction, re-solve from the prediction
        on the matches it explains within the tighter gate; if that converges elsewhere with
        enough inliers, the matches hold two rigid motions: keep the one that continues the
        tracked motion. One rigid scene has one solution, so both starts agree there."""
        p = self.params
        if not result.ok or result.transform is None or result.match_from_index.size == 0:
            return result
        if p.reg_force_3dof:
            guess = to_3dof(guess)
        d = se3_inverse(guess) @ result.transform
        if (np.hypot(d[0, 3], d[1, 3]) < _SAME_AS_PREDICTED[0]
                and abs(yaw_of(d)) < _SAME_AS_PREDICTED[1]):
            return result
        mf, mt = result.match_from_index, result.match_to_index
        gate = float(p.odom_motion_consistency)
        err = reprojection_errors(guess, old.points[mf], new.uv[mt], camera)
        fit = np.flatnonzero(err < gate).astype(np.intp)
        if fit.size < p.vis_min_inliers:
            return result
        tight = replace(p, vis_pnp_reproj_error=gate,
                        vis_pnp_refine_iterations=max(3, p.vis_pnp_refine_iterations))
        transform, inl = refine_pnp(guess, old.points[mf], new.uv[mt], fit, camera, tight)
        if inl.size < max(p.vis_min_inliers, _MIN_SECOND_MOTION_SHARE * result.inliers):
            return result
        d = se3_inverse(transform) @ result.transform
        if np.hypot(d[0, 3], d[1, 3]) < _SAME_SOLUTION[0] and abs(yaw_of(d)) < _SAME_SOLUTION[1]:
            return result
        fi, ti = mf[inl], mt[inl]
        cov = estimate_covariance(transform, old.points[fi], new.points[ti], new.uv[ti], camera,
                                  p.vis_pnp_variance_median_ratio)
        return RegistrationResult(transform, cov, int(inl.size), int(mf.size), fi, ti,
                                  match_from_index=mf, match_to_index=mt)

    def _lost(self, features: FrameFeatures, result: RegistrationResult) -> OdometryResult:
        self._velocity = None
        self._lost_count += 1
        countdown = self.params.odom_reset_countdown
        if countdown > 0 and self._lost_count >= countdown:
            self.reset(self._pose)
        return OdometryResult(None, _lost_covariance(), lost=True, matches=result.matches,
                              inliers=result.inliers, features=len(features),
                              local_map_size=self._map_size(), frame_features=features)

    def _is_keyframe(self, result: RegistrationResult, n_features: int) -> bool:
        p = self.params
        if p.odom_key_frame_thr == 0 or p.odom_vis_key_frame_thr == 0:
            return True
        return bool(
            result.inliers <= p.odom_key_frame_thr * n_features
            or result.inliers <= p.odom_vis_key_frame_thr
        )

    def _map_size(self) -> int:
        if self._map is not None:
            return int(self._map.points.shape[0])
        return 0 if self._keyframe is None else len(self._keyframe)

    def _start_map(self, features: FrameFeatures) -> None:
        self._keyframe = features
        self._keyframe_pose = self._pose.copy()
        valid = np.flatnonzero(features.has_depth)
        pts = features.points[valid] @ self._pose[:3, :3].T + self._pose[:3, 3]
        self._map = _LocalMap(pts, features.descriptors[valid].copy(),
                              features.responses[valid].copy(),
                              np.full(valid.size, self._frame, np.int64))

    def _update_map(self, features: FrameFeatures, result: RegistrationResult, pose: F64) -> None:
        lm = self._map
        assert lm is not None
        p = self.params
        matched_new = np.zeros(len(features), bool)
        matched_new[result.to_index] = True
        candidates = np.flatnonzero(~matched_new & features.has_depth)
        candidates = candidates[np.argsort(-features.responses[candidates], kind="stable")]
        if p.odom_f2m_max_new_features > 0:
            candidates = candidates[: p.odom_f2m_max_new_features]
        new_pts = features.points[candidates] @ pose[:3, :3].T + pose[:3, 3]
        inlier_map = np.zeros(lm.points.shape[0], bool)
        inlier_map[result.from_index] = True
        points = np.concatenate([lm.points, new_pts])
        desc = np.concatenate([lm.descriptors, features.descriptors[candidates]])
        resp = np.concatenate([lm.responses, features.responses[candidates]])
        born = np.concatenate([lm.born, np.full(candidates.size, self._frame, np.int64)])
        protected = np.concatenate([inlier_map, np.ones(candidates.size, bool)])
        excess = points.shape[0] - p.odom_f2m_max_size
        if p.odom_f2m_max_size > 0 and excess > 0:
            # Drop the oldest words that were not inliers of this frame first.
            removable = np.flatnonzero(~protected)
            order = removable[np.argsort(born[removable], kind="stable")]
            drop = order[:excess]
            if drop.size < excess:
                rest = np.flatnonzero(protected[: lm.points.shape[0]])
                rest = rest[np.argsort(born[rest], kind="stable")]
                drop = np.concatenate([drop, rest[: excess - drop.size]])
            keep = np.ones(points.shape[0], bool)
            keep[drop] = False
            points, desc, resp, born = points[keep], desc[keep], resp[keep], born[keep]
        self._map = _LocalMap(points, desc, resp, born)
        self._keyframe = features
        self._keyframe_pose = pose.copy()
