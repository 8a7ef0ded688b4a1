"""Typed table of the RTAB-Map parameters this package understands.

Every field of `RtabmapParameters` carries the upstream name (``Group/Name``) in its metadata and
the upstream default (introlab/rtabmap @ 5fad2d29) unless the field's help says otherwise.
`RtabmapParameters.from_dict` takes the ``dict[str, str]`` form RTAB-Map uses on its command
line, in ROS parameters and in the database's ``Info.parameters``.
"""

from __future__ import annotations

import dataclasses
import re
import shlex
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from eddiebot.vslam.errors import ParameterError

__all__ = [
    "DEFAULT_PREDICTION_LC",
    "ODOM_STRATEGY_F2F",
    "ODOM_STRATEGY_F2M",
    "RtabmapParameters",
    "parameter_names",
]

DEFAULT_PREDICTION_LC = (
    "0.1 0.36 0.30 0.16 0.062 0.0151 0.00255 0.000324 2.5e-05 1.3e-06 4.8e-08 1.2e-09 "
    "1.9e-11 2.2e-13 1.7e-15 8.5e-18 2.9e-20 6.9e-23"
)
ODOM_STRATEGY_F2M = 0
ODOM_STRATEGY_F2F = 1

# Detector strategies implemented here (RTAB-Map numbering): 2 = ORB, 8 = GFTT/ORB.
_SUPPORTED_DETECTORS = (2, 8)


def _p(name: str, default: Any, help_: str) -> Any:
    return field(default=default, metadata={"name": name, "help": help_})


@dataclass(frozen=True)
class RtabmapParameters:
    """RTAB-Map parameters by their upstream names (metadata ``name``); units as upstream."""

    # --- features ---
    kp_detector_strategy: int = _p("Kp/DetectorStrategy", 8, "2 = ORB, 8 = GFTT/ORB")
    vis_feature_type: int = _p("Vis/FeatureType", 8, "detector for odometry/registration")
    kp_max_features: int = _p("Kp/MaxFeatures", 500, "features quantised to words (0 = all)")
    vis_max_features: int = _p("Vis/MaxFeatures", 1000, "features extracted per frame")
    kp_nndr_ratio: float = _p("Kp/NndrRatio", 0.8, "vocabulary NNDR")
    kp_min_depth: float = _p("Kp/MinDepth", 0.0, "m, 0 = off")
    kp_max_depth: float = _p("Kp/MaxDepth", 0.0, "m, 0 = off")
    kp_tf_idf_likelihood_used: bool = _p("Kp/TfIdfLikelihoodUsed", True, "TF-IDF likelihood")
    gftt_quality_level: float = _p("GFTT/QualityLevel", 0.001, "")
    gftt_min_distance: float = _p("GFTT/MinDistance", 7.0, "px")
    gftt_block_size: int = _p("GFTT/BlockSize", 3, "px")
    mem_depth_as_mask: bool = _p("Mem/DepthAsMask", True, "detect only where depth > 0")
    # --- registration ---
    vis_estimation_type: int = _p(
        "Vis/EstimationType", 1,
        "0 = 3D->3D (RANSAC on matches with depth in both frames, Vis/InlierDistance), 1 = PnP")
    vis_min_inliers: int = _p("Vis/MinInliers", 20, "")
    vis_inlier_distance: float = _p("Vis/InlierDistance", 0.1, "m, 3D inlier gate")
    vis_pnp_reproj_error: float = _p("Vis/PnPReprojError", 2.0, "px")
    vis_iterations: int = _p("Vis/Iterations", 300, "RANSAC iterations")
    vis_refine_iterations: int = _p("Vis/RefineIterations", 5, "3D->3D: re-fits on the inliers")
    vis_pnp_refine_iterations: int = _p(
        "Vis/PnPRefineIterations", 0,
        "re-solve on the inliers, then re-select them among all matches (upstream: 0 when "
        "built with g2o, else 1); with Reg/Force3DoF the re-solve is in x, y, yaw only")
    vis_cor_nndr: float = _p("Vis/CorNNDR", 0.8, "registration NNDR")
    vis_cor_guess_win_size: int = _p("Vis/CorGuessWinSize", 40, "px, projection matching window")
    vis_pnp_variance_median_ratio: int = _p("Vis/PnPVarianceMedianRatio", 4, "")
    vis_pnp_jacobian_covariance: bool = _p(
        "Vis/PnPJacobianCovariance", False,
        "not upstream: per axis, the larger of the 3D-error variance and the PnP geometry's "
        "σ²(JᵀJ)⁻¹ marginal (inlier reprojection residual, ≥ 0.5 px)")
    vis_pnp_minimal_3dof: bool = _p(
        "Vis/PnPMinimal3DoF", False,
        "not upstream: with Reg/Force3DoF, PnP RANSAC on 2-point hypotheses in x, y, yaw "
        "(old 3D points, new keypoints; adaptive to Vis/Iterations at confidence 0.99), the "
        "Vis/PnPReprojError inlier test, then a planar re-solve on the inliers; false = "
        "OpenCV's 6-DoF solvePnPRansac projected to 3 DoF (upstream)")
    reg_force_3dof: bool = _p("Reg/Force3DoF", False, "x, y, yaw only")
    reg_repeat_once: bool = _p("Reg/RepeatOnce", True, "second pass with the first result as guess")
    reg_strategy: int = _p(
        "Reg/Strategy", 0,
        "0 = Vis, 1 = Icp (depth cloud), 2 = VisIcp (visual, then ICP from its result); "
        "odometry only here (vslam/depth_icp.py)")
    # --- ICP on the registered depth (vslam/depth_icp.py; upstream defaults of a PCL build) ---
    icp_max_translation: float = _p("Icp/MaxTranslation", 0.2, "m, largest correction of the guess")
    icp_max_rotation: float = _p("Icp/MaxRotation", 0.78, "rad, largest correction of the guess")
    icp_voxel_size: float = _p("Icp/VoxelSize", 0.05, "m, uniform sampling, 0 = off")
    icp_downsampling_step: int = _p(
        "Icp/DownsamplingStep", 1,
        "1 = every depth pixel; the cloud is made from every n-th row and column of the depth")
    icp_range_min: float = _p("Icp/RangeMin", 0.0, "m, 0 = off")
    icp_range_max: float = _p("Icp/RangeMax", 0.0, "m, 0 = off")
    icp_max_correspondence_distance: float = _p("Icp/MaxCorrespondenceDistance", 0.05, "m")
    icp_iterations: int = _p("Icp/Iterations", 30, "")
    icp_epsilon: float = _p("Icp/Epsilon", 0.0, "convergence on the step (m / rad), 0 = 1e-6")
    icp_correspondence_ratio: float = _p(
        "Icp/CorrespondenceRatio", 0.1,
        "accept when this share of the new cloud's points has a correspondence (upstream "
        "divides by the larger cloud)")
    icp_reciprocal_correspondences: bool = _p(
        "Icp/ReciprocalCorrespondences", True,
        "the registration's variance counts only pairs that are each other's nearest point")
    icp_point_to_plane: bool = _p("Icp/PointToPlane", False, "else point to point")
    icp_point_to_plane_k: int = _p("Icp/PointToPlaneK", 5, "neighbours per normal")
    icp_point_to_plane_radius: float = _p("Icp/PointToPlaneRadius", 0.0, "m, 0 = use K")
    icp_point_to_plane_min_complexity: float = _p(
        "Icp/PointToPlaneMinComplexity", 0.02,
        "smallest eigenvalue of the normals' covariance (in the plane under Reg/Force3DoF) "
        "below which the geometry leaves a translation free (one wall, a corridor)")
    icp_point_to_plane_low_complexity_strategy: int = _p(
        "Icp/PointToPlaneLowComplexityStrategy", 1,
        "below the complexity: 0 = reject, 1 = correct only the constrained axes (the free "
        "translation stays at the guess, with the guess's variance), 2 = accept as is")
    # --- odometry ---
    odom_strategy: int = _p("Odom/Strategy", 0, "0 = frame-to-map, 1 = frame-to-frame")
    odom_key_frame_thr: float = _p("Odom/KeyFrameThr", 0.3, "inlier ratio")
    odom_vis_key_frame_thr: int = _p("Odom/VisKeyFrameThr", 150, "inliers")
    odom_guess_motion: bool = _p("Odom/GuessMotion", True, "constant-velocity prediction")
    odom_reset_countdown: int = _p("Odom/ResetCountdown", 0, "frames lost before reset, 0 = off")
    odom_motion_consistency: float = _p(
        "Odom/MotionConsistencyReprojError", 0.0,
        "not upstream; px, 0 = off: when the registration leaves the predicted motion, re-solve "
        "from the prediction on the matches within this reprojection error; if that keeps "
        "Vis/MinInliers and a quarter of the inliers, another rigid motion (a person walking "
        "through the view) took the RANSAC vote: keep the one that continues the tracked motion")
    odom_f2m_max_size: int = _p("OdomF2M/MaxSize", 2000, "local map words")
    odom_f2m_max_new_features: int = _p("OdomF2M/MaxNewFeatures", 0, "0 = all")
    odom_scan_key_frame_thr: float = _p(
        "Odom/ScanKeyFrameThr", 0.7, "add the cloud to the scan map when the ICP ratio is below")
    odom_f2m_scan_max_size: int = _p("OdomF2M/ScanMaxSize", 2000, "local scan map points")
    odom_f2m_scan_subtract_radius: float = _p(
        "OdomF2M/ScanSubtractRadius", 0.05, "m: new points this close to the map are not added")
    odom_icp_fallback_inliers: int = _p(
        "Odom/IcpFallbackInliers", 0,
        "not upstream; 0 = off: with Reg/Strategy 0, a frame whose visual registration fails "
        "or keeps fewer inliers than this is registered by ICP on the depth cloud (from the "
        "visual result, else the motion prediction) and becomes a key frame, so the visual "
        "map re-forms once texture is back")
    # --- loop closure ---
    rtabmap_loop_thr: float = _p("Rtabmap/LoopThr", 0.11, "")
    rtabmap_loop_ratio: float = _p("Rtabmap/LoopRatio", 0.0, "")
    rtabmap_virtual_place_likelihood_ratio: int = _p(
        "Rtabmap/VirtualPlaceLikelihoodRatio", 0, "0 = mu/sigma + 1, 1 = sigma/(max-mu) + 1"
    )
    rtabmap_detection_rate: float = _p("Rtabmap/DetectionRate", 1.0, "Hz (applied by the node)")
    rtabmap_time_thr: float = _p("Rtabmap/TimeThr", 0.0, "ms, 0 = off")
    rtabmap_memory_thr: int = _p("Rtabmap/MemoryThr", 0, "WM nodes, 0 = off")
    rtabmap_max_retrieved: int = _p("Rtabmap/MaxRetrieved", 2, "")
    bayes_prediction_lc: str = _p("Bayes/PredictionLC", DEFAULT_PREDICTION_LC, "")
    bayes_virtual_place_prior_thr: float = _p("Bayes/VirtualPlacePriorThr", 0.9, "")
    # --- memory ---
    mem_stm_size: int = _p("Mem/STMSize", 10, "")
    mem_incremental_memory: bool = _p("Mem/IncrementalMemory", True, "false = localization")
    mem_init_wm_with_all_nodes: bool = _p("Mem/InitWMWithAllNodes", False, "")
    mem_recent_wm_ratio: float = _p(
        "Mem/RecentWmRatio", 0.2,
        "share of WM after the last loop closure that cannot be transferred")
    mem_rehearsal_similarity: float = _p(
        "Mem/RehearsalSimilarity", 0.6,
        "a new node this similar (shared words / larger word count) to the previous one in STM "
        "is merged into it (not moving) or raises its weight (moving); 1 = off")
    mem_rehearsal_weight_ignored_while_moving: bool = _p(
        "Mem/RehearsalWeightIgnoredWhileMoving", False,
        "no weight update by rehearsal while moving more than RGBD/LinearUpdate|AngularUpdate")
    mem_transfer_sorting_by_weight_id: bool = _p(
        "Mem/TransferSortingByWeightId", False,
        "transfer order weight, then id (false: weight, then time of entry into WM, then id)")
    mem_use_odom_features: bool = _p(
        "Mem/UseOdomFeatures", True,
        "words from the odometry's features when it has some (none with Reg/Strategy 1: the "
        "node's Kp/ features are extracted from the image then)")
    mem_image_compression_format: str = _p("Mem/ImageCompressionFormat", ".jpg", ".jpg or .png")
    mem_depth_compression_format: str = _p(
        "Mem/DepthCompressionFormat", ".png", ".png only (upstream default .rvl)"
    )
    # --- RGB-D graph ---
    rgbd_linear_update: float = _p("RGBD/LinearUpdate", 0.1, "m")
    rgbd_angular_update: float = _p("RGBD/AngularUpdate", 0.1, "rad")
    rgbd_optimize_max_error: float = _p("RGBD/OptimizeMaxError", 3.0, "sigmas, 0 = off")
    rgbd_optimize_from_graph_end: bool = _p("RGBD/OptimizeFromGraphEnd", False, "")
    rgbd_max_loop_closure_distance: float = _p("RGBD/MaxLoopClosureDistance", 0.0, "m, 0 = off")
    rgbd_loop_cov_limited: bool = _p(
        "RGBD/LoopCovLimited", False,
        "cap a closure's information at the largest odometry information seen (per axis)")
    rgbd_loop_closure_max_mahalanobis: float = _p(
        "RGBD/LoopClosureMaxMahalanobis", 0.0,
        "not upstream; sigmas, 0 = off: reject a loop/proximity closure whose (x, y, yaw) is "
        "farther than this Mahalanobis distance from the graph's prediction, with the "
        "covariance of the closure plus the link covariances composed along the graph path")
    rgbd_loop_closure_hypotheses: int = _p(
        "RGBD/LoopClosureHypotheses", 1,
        "not upstream; places verified per image (1 = upstream: the top hypothesis only): when "
        "the top one (value ≥ Rtabmap/LoopThr) is rejected by the registration or the gate, "
        "the next places of the posterior, each ≥ 4 links from those already tried, until one "
        "passes")
    rgbd_odom_heading_sigma: float = _p(
        "RGBD/OdomHeadingSigma", 0.0,
        "not upstream; rad, 0 = off: σ of a non-accumulating error of the odometry heading at "
        "each node (wheel encoders that quantise the heading): in the optimised graph the "
        "neighbour links join per-node odometry frames, each tied to its node by this yaw σ "
        "(the root's frame is the root), so the neighbour links' angular variance is the "
        "accumulating part only")
    rgbd_max_odom_cache_size: int = _p(
        "RGBD/MaxOdomCacheSize", 10,
        "localization: frames of odometry kept to check a localization against (0 = off: "
        "every localization accepted as is)")
    rgbd_localization_prior_error: float = _p(
        "RGBD/LocalizationPriorError", 0.001,
        "localization: variance of the priors holding the map nodes in the local graph")
    rgbd_proximity_by_space: bool = _p("RGBD/ProximityBySpace", True, "")
    rgbd_local_radius: float = _p("RGBD/LocalRadius", 10.0, "m")
    rgbd_proximity_max_graph_depth: int = _p("RGBD/ProximityMaxGraphDepth", 50, "")
    rgbd_proximity_max_paths: int = _p("RGBD/ProximityMaxPaths", 3, "")
    rgbd_proximity_angle: float = _p("RGBD/ProximityAngle", 45.0, "deg")
    rgbd_proximity_path_filtering_radius: float = _p(
        "RGBD/ProximityPathFilteringRadius", 1.0, "m"
    )
    rgbd_proximity_path_max_neighbors: int = _p(
        "RGBD/ProximityPathMaxNeighbors", 0,
        "scan pass of proximity detection, 0 = off: the scans of this many path nodes around "
        "the nearest one, merged, registered by 2D ICP against the new node's scan")
    rgbd_neighbor_link_refining: bool = _p(
        "RGBD/NeighborLinkRefining", False, "refine neighbour links with the 2D scan (ICP)"
    )
    rgbd_create_occupancy_grid: bool = _p("RGBD/CreateOccupancyGrid", False, "the node sets true")
    # --- grid ---
    grid_sensor: int = _p("Grid/Sensor", 1, "0 = scan, 1 = depth, 2 = both")
    grid_cell_size: float = _p("Grid/CellSize", 0.05, "m")
    grid_range_min: float = _p("Grid/RangeMin", 0.0, "m")
    grid_range_max: float = _p("Grid/RangeMax", 5.0, "m, 0 = unbounded")
    grid_depth_decimation: int = _p("Grid/DepthDecimation", 4, "")
    grid_min_ground_height: float = _p("Grid/MinGroundHeight", 0.0, "m, 0 = unbounded")
    grid_max_ground_height: float = _p("Grid/MaxGroundHeight", 0.0, "m; 0 = one cell size")
    grid_max_obstacle_height: float = _p("Grid/MaxObstacleHeight", 0.0, "m, 0 = unbounded")
    grid_ray_tracing: bool = _p(
        "Grid/RayTracing", False,
        "cells between the sensor and each obstacle cell become empty (2D ray tracing)")
    grid_3d: bool = _p("Grid/3D", False, "false = 2D grid (the cloud projected on xy); true "
                       "(an OctoMap) is not supported")
    # --- optimiser ---
    optimizer_iterations: int = _p("Optimizer/Iterations", 20, "")
    optimizer_epsilon: float = _p("Optimizer/Epsilon", 1e-5, "")
    gtsam_incremental: bool = _p(
        "GTSAM/Incremental", True,
        "graph updates in iSAM2 (SE(2) under Reg/Force3DoF, else Pose3) instead of a "
        "Levenberg–Marquardt re-solve of the whole graph; upstream default false")
    optimizer_robust: bool = _p(
        "Optimizer/Robust", False,
        "loop closures as Vertigo switchable constraints, switched off when the graph "
        "contradicts them; RGBD/OptimizeMaxError is then ignored")

    def __post_init__(self) -> None:
        for strategy_name, value in (
            ("Kp/DetectorStrategy", self.kp_detector_strategy),
            ("Vis/FeatureType", self.vis_feature_type),
        ):
            if value not in _SUPPORTED_DETECTORS:
                raise ParameterError(
                    f"{strategy_name}={value} is not supported (supported: 2 ORB, 8 GFTT/ORB)"
                )
        if self.vis_estimation_type not in (0, 1):
            raise ParameterError("Vis/EstimationType: 0 (3D->3D) or 1 (PnP) are supported")
        if self.reg_strategy not in (0, 1, 2):
            raise ParameterError(f"Reg/Strategy={self.reg_strategy}: use 0, 1 or 2")
        if self.icp_point_to_plane_low_complexity_strategy not in (0, 1, 2):
            raise ParameterError("Icp/PointToPlaneLowComplexityStrategy must be 0, 1 or 2")
        if self.icp_downsampling_step < 1:
            raise ParameterError("Icp/DownsamplingStep must be >= 1")
        if self.odom_strategy not in (ODOM_STRATEGY_F2M, ODOM_STRATEGY_F2F):
            raise ParameterError(f"Odom/Strategy={self.odom_strategy}: use 0 (F2M) or 1 (F2F)")
        if self.mem_image_compression_format not in (".jpg", ".png"):
            raise ParameterError("Mem/ImageCompressionFormat must be .jpg or .png")
        if self.mem_depth_compression_format != ".png":
            raise ParameterError("Mem/DepthCompressionFormat: only .png is supported")
        if self.grid_3d:
            raise ParameterError("Grid/3D=true (a 3D OctoMap grid) is not supported: set "
                                 "Grid/3D false for the 2D grid")
        if self.rgbd_proximity_path_max_neighbors < 0:
            raise ParameterError("RGBD/ProximityPathMaxNeighbors must be >= 0")
        if self.rgbd_max_odom_cache_size < 0:
            raise ParameterError("RGBD/MaxOdomCacheSize must be >= 0")
        if self.rgbd_localization_prior_error <= 0:
            raise ParameterError("RGBD/LocalizationPriorError must be > 0")
        if self.rgbd_local_radius < 0:
            raise ParameterError("RGBD/LocalRadius must be >= 0")
        if self.grid_sensor not in (0, 1, 2):
            raise ParameterError("Grid/Sensor must be 0, 1 or 2")
        if self.rgbd_odom_heading_sigma < 0:
            raise ParameterError("RGBD/OdomHeadingSigma must be >= 0")
        if self.rgbd_loop_closure_hypotheses < 1:
            raise ParameterError("RGBD/LoopClosureHypotheses must be >= 1")
        if not 0.0 <= self.mem_rehearsal_similarity <= 1.0:
            raise ParameterError("Mem/RehearsalSimilarity must be within [0, 1]")
        if not 0.0 <= self.mem_recent_wm_ratio <= 1.0:
            raise ParameterError("Mem/RecentWmRatio must be within [0, 1]")
        if self.mem_stm_size < 0:
            raise ParameterError("Mem/STMSize must be >= 0")
        if self.vis_min_inliers < 4:
            raise ParameterError("Vis/MinInliers must be >= 4 (PnP needs 4 points)")
        self.prediction_lc()  # validates the string

    def prediction_lc(self) -> tuple[float, ...]:
        """`Bayes/PredictionLC` as numbers: (virtual place, loop, neighbour depth 1, 2, ...)."""
        try:
            values = tuple(float(v) for v in self.bayes_prediction_lc.split())
        except ValueError as exc:
            raise ParameterError(f"Bayes/PredictionLC: {exc}") from exc
        if len(values) < 2 or any(v < 0 for v in values):
            raise ParameterError("Bayes/PredictionLC needs >= 2 non-negative numbers")
        return values

    @classmethod
    def from_dict(
        cls, values: Mapping[str, str], *, strict: bool = True
    ) -> RtabmapParameters:
        """Parse RTAB-Map ``Group/Name -> str`` pairs; unknown names raise unless not strict."""
        by_name = {f.metadata["name"]: f for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, raw in values.items():
            f = by_name.get(key)
            if f is None:
                if strict:
                    raise ParameterError(f"unknown RTAB-Map parameter {key!r}")
                continue
            kwargs[f.name] = _parse(key, str(raw), type(f.default))
        return cls(**kwargs)

    def to_dict(self) -> dict[str, str]:
        """All parameters as RTAB-Map ``Group/Name -> str`` (booleans as true/false)."""
        out: dict[str, str] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            out[f.metadata["name"]] = (
                ("true" if value else "false") if isinstance(value, bool) else str(value)
            )
        return out

    def replace(self, values: Mapping[str, str]) -> RtabmapParameters:
        """A copy with some parameters (by RTAB-Map name) changed."""
        merged = self.to_dict()
        merged.update(values)
        return RtabmapParameters.from_dict(merged)


def parameter_names() -> tuple[str, ...]:
    """Every supported ``Group/Name``."""
    return tuple(f.metadata["name"] for f in dataclasses.fields(RtabmapParameters))


def _parse(key: str, raw: str, kind: type) -> Any:
    text = raw.strip()
    try:
        if kind is bool:
            low = text.lower()
            if low in ("true", "1", "yes", "on"):
                return True
            if low in ("false", "0", "no", "off"):
                return False
            raise ValueError(f"not a boolean: {raw!r}")
        if kind is int:
            as_float = float(text)
            if not as_float.is_integer():
                raise ValueError(f"not an integer: {raw!r}")
            return int(as_float)
        if kind is float:
            return float(text)
        return text
    except ValueError as exc:
        raise ParameterError(f"{key}: {exc}") from exc


#: an RTAB-Map parameter name, ``Group/Name`` (or ``Group.Name`` from nested YAML)
RTABMAP_NAME = re.compile(r"^[A-Z][A-Za-z0-9]*[/.][A-Z][A-Za-z0-9_/]*$")


def parse_rtabmap_args(text: str) -> tuple[dict[str, str], bool, list[str]]:
    """Upstream's ``rtabmap_args``: ``(-d|--delete_db_on_start) --Group/Name value ...`` →
    (parameters, delete_db_on_start, ignored tokens)."""
    tokens = shlex.split(text or "")
    params: dict[str, str] = {}
    ignored: list[str] = []
    delete = False
    k = 0
    while k < len(tokens):
        tok = tokens[k]
        if tok in ("-d", "--delete_db_on_start"):
            delete = True
        elif tok.startswith("--") and "/" in tok:
            name, _, inline = tok[2:].partition("=")
            if inline:
                value = inline
            elif k + 1 < len(tokens):
                k += 1
                value = tokens[k]
            else:
                ignored.append(tok)
                break
            if RTABMAP_NAME.match(name):
                params[name] = value
            else:
                ignored.append(tok)
        else:
            ignored.append(tok)
        k += 1
    return params, delete, ignored


def parameter_text(value: Any) -> str:
    """A parameter value as RTAB-Map's string form (booleans "true"/"false")."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
