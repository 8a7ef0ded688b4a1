"""RGB-D visual odometry: frame-to-map (`Odom/Strategy` 0) and frame-to-frame (1).

Pure core: frames in, pose of the robot base in the odometry frame out. When tracking is lost
the result carries ``pose=None`` and a covariance of 9999 on the diagonal (what the ROS node
publishes as a "null" odometry); a pose is never made up.

Registration (`Reg/Strategy`, upstream semantics): 0 visual; 1 ICP of the depth cloud against
a local scan map from the motion prediction; 2 visual, then ICP from the visual result (a
failure of either loses the frame). `Odom/IcpFallbackInliers` (not upstream, 0 = off) adds to
0 and 2: a frame whose visual registration fails or keeps fewer inliers is registered by ICP
(from the visual result, else the prediction) and becomes a key frame, so the visual map keeps
growing through a textureless stretch and re-forms once texture is back; with it on,
strategy 2 also keeps a visual result with that many inliers when ICP fails (no cloud within
`Icp/RangeMax`). See `depth_icp`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.depth_icp import (
    IcpResult,
    IcpSettings,
    ScanCloud,
    ScanMap,
    icp_register,
    make_scan,
)
from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.parameters import ODOM_STRATEGY_F2F, RtabmapParameters
from eddiebot.vslam.registration import (
    RegistrationResult,
    estimate_covariance,
    huge_covariance,
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
# σ of the constant-velocity prediction per frame: this floor plus the predicted step itself
# (m, rad); the variance given to what ICP leaves at the prediction (along a wall).
_PREDICTION_SIGMA_FLOOR = 0.01
# Frames whose median translation rate predicts what ICP leaves free: one poorly registered
# frame (a visual result on 20 inliers off by 5 cm) must not be extrapolated along a wall.
_TWIST_WINDOW = 5
_REG_ICP = 1
_REG_VIS_ICP = 2


@dataclass(frozen=True)
class OdometryResult:
    """One odometry update. `pose`: base in odom frame (4×4, m), None when lost."""

    pose: F64 | None
    covariance: F64 = field(default_factory=huge_covariance)
    lost: bool = False
    keyframe: bool = False
    inliers: int = 0
    matches: int = 0
    features: int = 0
    local_map_size: int = 0
    frame_features: FrameFeatures | None = None
    #: the pose comes from ICP on the depth (Reg/Strategy 1 or 2, or the fallback)
    icp: bool = False
    #: share of the depth cloud's points with an ICP correspondence (0 when ICP did not run)
    icp_ratio: float = 0.0
    #: points in the local scan map
    scan_map_size: int = 0


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
        self._icp = IcpSettings.from_parameters(params)
        self._scan_map = ScanMap(params.odom_f2m_scan_max_size,
                                 params.odom_f2m_scan_subtract_radius)
        self._initial = np.eye(4) if initial_pose is None else np.asarray(initial_pose, float)
        self.reset(self._initial)

    # -- state ------------------------------------------------------------------------------
    def reset(self, pose: F64 | None = None) -> None:
        """Forget the map; the next frame starts again at `pose` (default: the initial pose)."""
        self._pose = (self._initial if pose is None else np.asarray(pose, float)).copy()
        self._velocity: F64 | None = None  # per-second twist as (x, y, z, roll, pitch, yaw)
        self._twists: list[F64] = []  # the last _TWIST_WINDOW of them
        self._last_stamp_ns: int | None = None
        self._keyframe: FrameFeatures | None = None
        self._keyframe_pose = self._pose.copy()
        self._map: _LocalMap | None = None
        self._frame = 0
        self._lost_count = 0
        self._initialised = False
        self._twists = []
        if hasattr(self, "_scan_map"):
            self._scan_map.reset()

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
        if self.params.reg_strategy == _REG_ICP:
            features = FrameFeatures.empty()
        else:
            features = self._extractor.extract(image, depth, camera, depth_as_mask=False)
        return self.process_features(features, camera, stamp_ns, depth=depth)

    def process_features(
        self, features: FrameFeatures, camera: CameraIntrinsics, stamp_ns: int,
        depth: NDArray[np.generic] | None = None,
    ) -> OdometryResult:
        """Track a frame whose features were already extracted (base-frame 3D points);
        `depth` (the registered depth image) is needed by `Reg/Strategy` 1 and 2 and by the
        ICP fallback."""
        p = self.params
        self._frame += 1
        uses_icp = p.reg_strategy in (_REG_ICP, _REG_VIS_ICP) or p.odom_icp_fallback_inliers > 0
        if depth is None and p.reg_strategy in (_REG_ICP, _REG_VIS_ICP):
            raise ParameterError(f"Reg/Strategy={p.reg_strategy} needs the depth image")
        has_scan = uses_icp and depth is not None
        # the depth cloud is built lazily: only when ICP runs or the frame becomes a key frame
        # that feeds the scan map (a tracked visual frame needs none)
        built: list[ScanCloud] = []

        def get_scan() -> ScanCloud:
            if not built:
                assert depth is not None
                built.append(make_scan(depth, camera, self._icp))
            return built[0]

        n_depth = int(features.has_depth.sum())
        if not self._initialised:
            visual_ok = p.reg_strategy != _REG_ICP and n_depth >= p.vis_min_inliers
            scan_ok = has_scan and (visual_ok or len(get_scan()) >= p.vis_min_inliers)
            if not (visual_ok or (scan_ok and (p.reg_strategy == _REG_ICP
                                               or p.odom_icp_fallback_inliers > 0))):
                return OdometryResult(None, lost=True, features=len(features),
                                      frame_features=features)
            if p.reg_strategy != _REG_ICP:
                self._start_map(features)
            if has_scan:
                self._scan_map.reset(get_scan().transformed(self._pose), self._frame)
            self._last_stamp_ns = stamp_ns
            self._initialised = True
            self._lost_count = 0
            return OdometryResult(self._pose.copy(), huge_covariance(), keyframe=True,
                                  features=len(features), local_map_size=self._map_size(),
                                  frame_features=features, scan_map_size=len(self._scan_map))
        dt = 0.0 if self._last_stamp_ns is None else (stamp_ns - self._last_stamp_ns) * 1e-9
        motion = self._predict(dt)
        predicted = self._pose @ motion
        icp: IcpResult | None = None
        if uses_icp:
            steady = self._predict(dt, median_translation=True)
            steady_pose, steady_cov = self._pose @ steady, self._prediction_covariance(steady)
        if p.reg_strategy == _REG_ICP:
            icp = self._register_icp(get_scan(), steady_pose, steady_cov)
            result = RegistrationResult(None)
            new_pose = icp.transform
        elif p.odom_strategy == ODOM_STRATEGY_F2F:
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
        fallback = p.odom_icp_fallback_inliers
        if p.reg_strategy == _REG_VIS_ICP and new_pose is not None:
            icp = self._register_icp(get_scan(), self._planar(new_pose), result.covariance)
            # upstream loses the frame when ICP fails; with the fallback on, a visual result
            # with enough inliers stands (facing open space beyond Icp/RangeMax, no cloud)
            if icp.ok or fallback <= 0 or result.inliers < fallback:
                new_pose = icp.transform
        if (p.reg_strategy != _REG_ICP and fallback > 0 and has_scan
                and (new_pose is None or result.inliers < fallback)):
            if new_pose is not None:
                second = self._register_icp(get_scan(), self._planar(new_pose),
                                            result.covariance)
                second = _fuse_free_axis(second, result.covariance, steady_pose, steady_cov)
            else:
                second = self._register_icp(get_scan(), steady_pose, steady_cov)
            if second.ok:
                icp, new_pose = second, second.transform
        if new_pose is None:
            return self._lost(features, result, icp)
        if p.reg_force_3dof:
            new_pose = to_3dof(new_pose)
        covariance = result.covariance if icp is None or not icp.ok else icp.covariance
        if dt > 0:
            self._velocity = np.array(xyz_rpy(se3_inverse(self._pose) @ new_pose)) / dt
            self._twists = [*self._twists[1 - _TWIST_WINDOW:], self._velocity]
        self._pose = new_pose
        self._last_stamp_ns = stamp_ns
        self._lost_count = 0
        by_icp = icp is not None and icp.ok
        visual_key = p.reg_strategy != _REG_ICP and self._is_keyframe(result, len(features))
        # the fallback: every frame ICP carried is a key frame (the visual map keeps growing)
        fallback_key = by_icp and p.reg_strategy != _REG_ICP and result.inliers < fallback
        scan_key = icp is not None and icp.ok and (
            p.odom_scan_key_frame_thr == 0 or icp.ratio <= p.odom_scan_key_frame_thr)
        keyframe = visual_key or fallback_key or scan_key
        if keyframe and p.reg_strategy != _REG_ICP:
            if p.odom_strategy == ODOM_STRATEGY_F2F:
                if n_depth >= p.vis_min_inliers:
                    self._keyframe = features
                    self._keyframe_pose = new_pose.copy()
            else:
                self._update_map(features, result, new_pose)
        if keyframe and has_scan:
            moved = get_scan().transformed(new_pose)
            if p.odom_strategy == ODOM_STRATEGY_F2F:
                self._scan_map.reset(moved, self._frame)
            else:
                self._scan_map.add(moved, self._frame)
        return OdometryResult(
            new_pose.copy(), covariance, keyframe=keyframe, inliers=result.inliers,
            matches=result.matches, features=len(features), local_map_size=self._map_size(),
            frame_features=features, icp=by_icp, icp_ratio=0.0 if icp is None else icp.ratio,
            scan_map_size=len(self._scan_map),
        )

    # -- helpers ----------------------------------------------------------------------------
    def _planar(self, pose: F64) -> F64:
        return to_3dof(pose) if self.params.reg_force_3dof else pose

    def _register_icp(self, scan: ScanCloud, guess: F64, guess_covariance: F64) -> IcpResult:
        if len(self._scan_map) == 0:
            return IcpResult(None, reason="empty scan map")
        return icp_register(self._scan_map.cloud, scan, guess, self._icp, guess_covariance,
                            tree=self._scan_map.tree)

    @staticmethod
    def _prediction_covariance(motion: F64) -> F64:
        """Variance of the constant-velocity prediction over one frame: σ = 1 cm (0.01 rad)
        plus the predicted step itself."""
        lin = (_PREDICTION_SIGMA_FLOOR + float(np.linalg.norm(motion[:3, 3]))) ** 2
        ang = (_PREDICTION_SIGMA_FLOOR + abs(yaw_of(motion))) ** 2
        return np.diag([lin, lin, lin, ang, ang, ang])

    def _predict(self, dt: float, median_translation: bool = False) -> F64:
        """Constant-velocity motion over `dt`; with `median_translation` the translation rate is
        the median of the last frames' (the rotation rate stays the last frame's)."""
        if not self.params.odom_guess_motion or self._velocity is None or dt <= 0:
            return np.eye(4)
        v = self._velocity * dt
        if median_translation and self._twists:
            v[:3] = np.median(np.stack(self._twists)[:, :3], axis=0) * dt
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

    def _lost(self, features: FrameFeatures, result: RegistrationResult,
              icp: IcpResult | None = None) -> OdometryResult:
        self._velocity = None
        self._twists = []
        self._lost_count += 1
        countdown = self.params.odom_reset_countdown
        if countdown > 0 and self._lost_count >= countdown:
            self.reset(self._pose)
        return OdometryResult(None, huge_covariance(), lost=True, matches=result.matches,
                              inliers=result.inliers, features=len(features),
                              local_map_size=self._map_size(), frame_features=features,
                              icp_ratio=0.0 if icp is None else icp.ratio,
                              scan_map_size=len(self._scan_map))

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


def _fuse_free_axis(icp: IcpResult, visual_cov: F64, steady_pose: F64,
                    steady_cov: F64) -> IcpResult:
    """Along the translation ICP left free, a weak visual result (the guess) and the motion
    prediction are two estimates of one coordinate: take their inverse-variance mean."""
    if not icp.ok or icp.free_axis is None or icp.transform is None:
        return icp
    f = icp.free_axis
    var_v = float(f @ visual_cov[:3, :3] @ f)
    var_p = float(f @ steady_cov[:3, :3] @ f)
    if var_v <= 0 or var_p <= 0:
        return icp
    w = var_v / (var_v + var_p)  # weight of the prediction
    t = icp.transform.copy()
    t[:3, 3] += w * float(f @ (steady_pose[:3, 3] - t[:3, 3])) * f
    cov = icp.covariance.copy()
    fused = var_v * var_p / (var_v + var_p)
    cov[:3, :3] += (fused - var_v) * np.outer(f, f)
    return replace(icp, transform=t, covariance=cov)
