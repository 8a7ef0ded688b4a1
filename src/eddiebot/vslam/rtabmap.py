"""RTAB-Map-style RGB-D graph SLAM core: one call per synchronised frame.

`Rtabmap.process(rgb, depth, camera, odom_pose, stamp_ns, scan)` creates a node, runs the
bag-of-words Bayes loop-closure detector over working memory, verifies a hypothesis with PnP,
optionally adds proximity links, optimises the graph and returns the map→odom correction.
Pure core: the optional `SessionDatabase` is the only I/O, and time is only measured (for
`Rtabmap/TimeThr`) through an injected timer.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from eddiebot.vslam.bayes import BayesFilter, adjust_likelihood, tfidf_scores
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.closure_check import closure_mahalanobis, path_covariance
from eddiebot.vslam.depth_icp import IcpResult, IcpSettings, icp_register, make_scan
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.graph import (
    GraphLink,
    GtsamPoseGraph,
    IncrementalPose2Graph,
    PoseGraphOptimizer,
    optimized_link_errors,
)
from eddiebot.vslam.icp import icp_2d
from eddiebot.vslam.localization import OdometryCache
from eddiebot.vslam.memory import Link, LinkType, Memory, Node, NodeData
from eddiebot.vslam.occupancy import (
    CloudImages,
    GlobalGrid,
    LocalGrid,
    Scan2D,
    assemble_cloud,
    assemble_grid,
    depth_cloud,
    local_grid_from_points,
    local_grid_from_scan,
    merge_local_grids,
)
from eddiebot.vslam.odometry_frames import (
    ODOM_FRAME_ID_OFFSET,
    OdometryFrames,
    _worst_link_error,
    odometry_frame_graph,
)
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.records import FrameRecord, MapDatabase, ProcessResult, _Verification
from eddiebot.vslam.registration.pipeline import register
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, to_3dof, xyz_rpy, yaw_of
from eddiebot.vslam.vocabulary import Vocabulary

__all__ = ["ODOM_FRAME_ID_OFFSET", "FrameRecord", "OdometryFrames", "ProcessResult", "Rtabmap",
           "closure_mahalanobis", "odometry_frame_graph", "path_covariance"]

F64 = NDArray[np.float64]
_DEFAULT_ODOM_VARIANCE = 0.001
_CLOUD_VOXEL = 0.02
_REG_ICP, _REG_VIS_ICP = 1, 2  # Reg/Strategy
#: `RGBD/LoopClosureHypotheses`: a further hypothesis is not within this many links of one
#: already verified (the span where `Bayes/PredictionLC` gives a place's neighbours ≥ 1 %)
_HYPOTHESIS_MARGIN = 4


class Rtabmap:
    """The SLAM core. Create with RTAB-Map parameters, feed frames with `process`."""

    def __init__(
        self,
        params: RtabmapParameters | Mapping[str, str] | None = None,
        *,
        database: MapDatabase | None = None,
        optimizer: PoseGraphOptimizer | None = None,
        timer: Callable[[], float] = time.perf_counter,
    ) -> None:
        if params is None:
            params = RtabmapParameters()
        elif not isinstance(params, RtabmapParameters):
            params = RtabmapParameters.from_dict(params)
        self.params = params
        self._timer = timer
        self._db = database
        self.vocabulary = Vocabulary(params.kp_nndr_ratio)
        self.memory = Memory(self.vocabulary, params.mem_stm_size, store=database)
        self.bayes = BayesFilter(params.prediction_lc(), params.bayes_virtual_place_prior_thr)
        self._extractor = FeatureExtractor(
            params, max_features=params.vis_max_features, strategy=params.kp_detector_strategy
        )
        self._icp = IcpSettings.from_parameters(params)
        self.optimizer: PoseGraphOptimizer = optimizer or GtsamPoseGraph(
            params.reg_force_3dof, params.optimizer_epsilon
        )
        self.optimized_poses: dict[int, F64] = {}
        self.map_to_odom = np.eye(4)
        self._next_id = 1
        self._map_id = 0
        #: map id → id of the map whose frame it shares (itself until merged by a loop closure;
        #: merged maps take the oldest one's frame)
        self._map_frames: dict[int, int] = {0: 0}
        self.maps_started = 0  # new maps started within this session (odometry resets)
        self._last_node_id = 0
        self._weights_changed: set[int] = set()  # node ids whose weight the database lacks
        self._last_had_loop = False
        self._last_hypothesis = (0, 0.0)
        self._prev_hyp_value = 0.0
        self._localized = False
        self._odom_max_info: F64 | None = None  # per-axis largest odometry information
        self._frame_poses: dict[int, F64] = {}  # optimised odometry frames (RGBD/OdomHeadingSigma)
        self._frames = OdometryFrames()  # their links, kept between graph updates
        #: localization mode: the last frames' odometry and accepted localizations
        self._odom_cache = (
            OdometryCache(params.rgbd_max_odom_cache_size, params.reg_force_3dof,
                          prior_variance=params.rgbd_localization_prior_error,
                          max_error=params.rgbd_optimize_max_error,
                          iterations=params.optimizer_iterations,
                          epsilon=params.optimizer_epsilon)
            if not params.mem_incremental_memory and params.rgbd_max_odom_cache_size > 0
            else None)
        #: covariance (6×6) of the last accepted localization, None before one
        self.localization_covariance: F64 | None = None
        # the incremental graph holds the graph of the last `_optimize` (memory's link log
        # then tells what was added since)
        self._graph_live = False
        if database is not None:
            database.load_into(self)

    # -- properties -------------------------------------------------------------------------
    @property
    def map_id(self) -> int:
        """Current session/map id."""
        return self._map_id

    @property
    def localized(self) -> bool:
        """Localization mode: a localization was accepted since the start."""
        return self._localized

    @property
    def localization_mode(self) -> bool:
        """`Mem/IncrementalMemory` false."""
        return not self.params.mem_incremental_memory

    def restore_state(self, next_id: int, map_id: int) -> None:
        """Continue numbering after a database session (`map_id` is the new session's id);
        maps joined by links share the oldest one's frame."""
        self._next_id = max(self._next_id, next_id)
        self._map_id = map_id
        frames = {n.map_id: n.map_id for n in self.memory.nodes.values()}
        frames[map_id] = map_id
        changed = True
        while changed:
            changed = False
            for a, partners in self.memory.links.items():
                for b in partners:
                    na, nb = self.memory.nodes.get(a), self.memory.nodes.get(b)
                    if na is None or nb is None:
                        continue
                    fa, fb = frames[na.map_id], frames[nb.map_id]
                    if fa != fb:
                        low = min(fa, fb)
                        for m, f in frames.items():
                            if f in (fa, fb):
                                frames[m] = low
                        changed = True
        self._map_frames = frames

    def frame_of(self, node_id: int) -> int:
        """The map frame (the oldest map id of its merged group) a node's pose is in."""
        node = self.memory.nodes.get(node_id)
        map_id = self._map_id if node is None else node.map_id
        return self._map_frames.get(map_id, map_id)

    @property
    def current_frame(self) -> int:
        """The map frame of the current map (map→odom is in it)."""
        return self._map_frames.get(self._map_id, self._map_id)

    def map_frames(self) -> dict[int, list[int]]:
        """Node ids with an optimised pose, by map frame (maps not merged yet are apart)."""
        out: dict[int, list[int]] = {}
        for i in sorted(self.optimized_poses):
            out.setdefault(self.frame_of(i), []).append(i)
        return out

    def _odometry_reset(self, odom: F64, covariance: F64 | None) -> bool:
        """RTAB-Map's new-map triggers: the odometry's covariance at 9999 (lost, then
        re-initialised) or an identity pose after a non-identity one, once the current map has
        a node."""
        lost = (covariance is not None
                and float(np.asarray(covariance).reshape(6, 6)[0, 0]) >= 9999)
        if self.localization_mode:
            if lost and self._odom_cache is not None:
                self._odom_cache.clear()  # the odometry before the reset checks nothing now
            return False
        prev = self.memory.nodes.get(self._last_node_id)
        if prev is None or prev.map_id != self._map_id:
            return False
        if lost:
            return True
        eye = np.eye(4)
        return bool(np.allclose(odom, eye) and not np.allclose(prev.odom_pose, eye))

    def _start_new_map(self) -> None:
        """A new map in this session: no link to the previous node, its own frame (map→odom
        identity) until a loop closure merges it with another map."""
        self._map_id += 1
        self._map_frames[self._map_id] = self._map_id
        self.maps_started += 1
        self.map_to_odom = np.eye(4)
        self._graph_live = False
        self._last_had_loop = False

    def _merge_frames(self, node: Node, closure_links: list[Link]) -> bool:
        """Join the frames of maps a closure links: the newer frame's poses are moved into
        the older one through the closure (so the optimiser starts from a consistent guess).
        True if frames were merged."""
        merged = False
        for link in closure_links:
            new_id, old_id = link.from_id, link.to_id
            f_new, f_old = self.frame_of(new_id), self.frame_of(old_id)
            if f_new == f_old:
                continue
            p_new, p_old = self.optimized_poses[new_id], self.optimized_poses[old_id]
            if f_old < f_new:  # move the new node's frame: T_new(old frame) = T_old · link⁻¹
                moved, keep = f_new, f_old
                correction = p_old @ se3_inverse(link.transform) @ se3_inverse(p_new)
            else:
                moved, keep = f_old, f_new
                correction = p_new @ link.transform @ se3_inverse(p_old)
            for i in list(self.optimized_poses):
                if self.frame_of(i) == moved:
                    self.optimized_poses[i] = correction @ self.optimized_poses[i]
            if moved == self.current_frame:
                self.map_to_odom = correction @ self.map_to_odom
            for m, f in self._map_frames.items():
                if f == moved:
                    self._map_frames[m] = keep
            merged = True
        if merged:
            self._graph_live = False
            self._frame_poses = {}
        return merged

    # -- main entry -------------------------------------------------------------------------
    def process(
        self,
        rgb: NDArray[np.uint8],
        depth: NDArray[np.generic],
        camera: CameraIntrinsics,
        odom_pose: F64,
        stamp_ns: int,
        scan: Scan2D | None = None,
        *,
        odom_covariance: F64 | None = None,
        features: FrameFeatures | None = None,
    ) -> ProcessResult:
        """Process one synchronised frame; `odom_pose` is the base pose in the odom frame (4×4)."""
        p = self.params
        t0 = self._timer()
        stats: dict[str, float] = {}
        odom = np.asarray(odom_pose, dtype=np.float64)
        if p.reg_force_3dof:
            odom = to_3dof(odom)
        if not np.all(np.isfinite(odom)):
            return ProcessResult(0, False, self.map_to_odom.copy(), None,
                                 rejection_reason="invalid odometry pose")
        new_map = self._odometry_reset(odom, odom_covariance)
        if new_map:
            self._start_new_map()
        if features is None or len(features) == 0 or not p.mem_use_odom_features:
            # the memory's words do not depend on the odometry: an odometry without features
            # (ICP, Reg/Strategy 1) leaves the node's Kp/ features to extract here
            features = self._extractor.extract(rgb, depth, camera)
        n_words = len(features) if p.kp_max_features <= 0 else min(len(features), p.kp_max_features)
        words = np.full(len(features), -1, np.int64)
        words[:n_words] = self.vocabulary.quantize(
            features.descriptors[:n_words], add_new=not self.localization_mode
        )
        stats["Keypoint/Current_frame/words"] = float(n_words)
        grid = None
        if p.rgbd_create_occupancy_grid:
            xyz, _ = depth_cloud(depth, camera, p.grid_depth_decimation, p.grid_range_min,
                                 p.grid_range_max)
            grid = self._local_grid(xyz, camera, scan)
        cloud = CloudImages.from_frame(depth, rgb, camera, p.grid_depth_decimation,
                                       p.grid_range_min, p.grid_range_max)
        scan_points = scan.points_in_base() if scan is not None else None
        data = NodeData(features, words, grid, cloud, scan_points)
        node = Node(self._next_id, self._map_id, stamp_ns, odom, data=data,
                    word_counts=data.word_counts())
        self._next_id += 1
        bad = not node.word_counts

        prev = self.memory.nodes.get(self._last_node_id)
        small = False
        new_links: list[Link] = []
        if prev is not None and prev.map_id == node.map_id:
            delta = se3_inverse(prev.odom_pose) @ odom
            small = self._small_displacement(delta)
            info = self._odom_information(odom_covariance)
            link = Link(prev.id, node.id, LinkType.NEIGHBOR, delta, info)
            if p.rgbd_neighbor_link_refining and scan is not None and prev.data is not None:
                link = self._refine_with_scan(link, prev, scan)
            new_links.append(link)
            diag = np.diag(link.information).copy()
            self._odom_max_info = (diag if self._odom_max_info is None
                                   else np.maximum(self._odom_max_info, diag))

        t_mem = self._timer()
        stats["Timing/Features_and_words/ms"] = (t_mem - t0) * 1e3
        moved = self.memory.add_to_stm(node)
        for link in new_links:
            self.memory.add_link(link)
        merged_into = 0  # rehearsal: the previous node this one repeats (not kept)
        if not self.localization_mode and p.mem_rehearsal_similarity < 1.0:
            moving = self._moving(new_links[0].transform) if new_links else None
            rehearsed, sim, full = self.memory.rehearsal(
                node, p.mem_rehearsal_similarity, moving,
                p.mem_rehearsal_weight_ignored_while_moving)
            merged_into = rehearsed if full else 0
            stats["Memory/Rehearsal_sim/"] = sim
            stats["Memory/Rehearsal_id/"] = float(rehearsed)
            stats["Memory/Rehearsal_merged/"] = float(merged_into)
            if rehearsed:
                self._weights_changed.add(rehearsed)
        for m in moved:
            self.bayes.node_entered(m, self._bayes_neighbours(m, self.bayes.max_depth))

        # --- loop-closure hypothesis over WM ---
        hyp_id, hyp_value = 0, 0.0
        skip_update = bad or (small and self._last_had_loop)
        wm = self.memory.wm_ids
        if not skip_update and wm:
            scores = self._likelihood_scores(node, wm)
            like = adjust_likelihood(scores, p.rtabmap_virtual_place_likelihood_ratio)
            self.bayes.update(like, self._bayes_neighbours)
            hyp_id, hyp_value = self.bayes.highest_hypothesis()
            stats["Loop/Likelihood_max/"] = max(scores.values(), default=0.0)
        elif skip_update:
            hyp_id, hyp_value = self._last_hypothesis
        self._last_hypothesis = (hyp_id, hyp_value)
        t_bayes = self._timer()
        stats["Timing/Memory_and_Bayes/ms"] = (t_bayes - t_mem) * 1e3
        stats["Loop/Highest_hypothesis_id/"] = float(hyp_id)
        stats["Loop/Highest_hypothesis_value/"] = hyp_value

        # --- retrieval from LTM around the hypothesis ---
        retrieved = self._retrieve_around(hyp_id) if (self.memory.ltm and hyp_id) else []
        stats["Memory/Retrieved/"] = float(len(retrieved))

        loop_id = 0
        rejected_id = 0
        reason = ""
        candidate: Link | None = None  # the hypothesis' registered link, also when rejected
        mahalanobis = float("nan")
        graph_changed = bool(retrieved)
        closure_links: list[Link] = []
        accept_hyp = (
            not skip_update and hyp_id > 0 and hyp_value >= p.rtabmap_loop_thr
            and len(self.memory.wm) > 1
            and not (p.rtabmap_loop_ratio > 0
                     and (self._prev_hyp_value == 0 or hyp_value < p.rtabmap_loop_ratio * self._prev_hyp_value))
        )
        if not skip_update:
            self._prev_hyp_value = hyp_value
        if accept_hyp:
            top = self._verify(self.memory.nodes[hyp_id], node, camera, LinkType.GLOBAL_CLOSURE)
            candidate, reason, mahalanobis = top.registered, top.reason, top.mahalanobis
            if top.link is not None:
                closure_links.append(top.link)
                loop_id = hyp_id
            else:
                rejected_id = hyp_id
                # RGBD/LoopClosureHypotheses (not upstream): the next places of the posterior
                tried = 1
                for other in self._next_hypotheses(hyp_id, p.rgbd_loop_closure_hypotheses - 1):
                    tried += 1
                    v = self._verify(self.memory.nodes[other], node, camera,
                                     LinkType.GLOBAL_CLOSURE)
                    if v.link is not None:
                        closure_links.append(v.link)
                        loop_id = other
                        candidate, mahalanobis = v.registered, v.mahalanobis
                        rejected_id, reason = 0, ""
                        break
                stats["Loop/Hypotheses_verified/"] = float(tried)

        if loop_id:
            stats["Loop/Mahalanobis/"] = mahalanobis
        # --- proximity by space ---
        proximity_id = 0
        # as upstream, a small displacement after a closure skips proximity as it skips the
        # Bayes update (else a slow robot links each node to its own trail just out of STM)
        if p.rgbd_proximity_by_space and not loop_id and not skip_update and (
                not self.localization_mode or self._localized):
            near = self._proximity(node, camera)
            if near is not None:
                closure_links.append(near)
                proximity_id = near.to_id

        t_verify = self._timer()
        stats["Timing/Retrieval_and_verification/ms"] = (t_verify - t_bayes) * 1e3
        # --- graph update ---
        merged = False
        if self.localization_mode:
            pose, why = self._localize(closure_links, odom, self._odom_information(odom_covariance))
            if why and closure_links:
                rejected_id = rejected_id or (loop_id or proximity_id)
                reason = why
                loop_id = proximity_id = 0
                closure_links = []
        else:
            for link in closure_links:
                self.memory.add_link(link)
                # only the two ends learn about the shortcut (incremental prediction update)
                self.bayes.invalidate([link.from_id, link.to_id])
            graph_changed |= bool(closure_links)
            self.optimized_poses[node.id] = self.map_to_odom @ odom
            backup = (dict(self.optimized_poses), self.map_to_odom.copy(), dict(self._map_frames),
                      dict(self._frame_poses))
            merged = self._merge_frames(node, closure_links)
            if graph_changed:
                ok = self._optimize(node.id, closure_links)
                if not ok and merged:
                    (self.optimized_poses, self.map_to_odom, self._map_frames,
                     self._frame_poses) = backup
                    self._graph_live = False
                    merged = False
                if not ok:
                    for link in closure_links:
                        self.memory.remove_link(link.from_id, link.to_id)
                    rejected_id = rejected_id or (loop_id or proximity_id)
                    reason = "RGBD/OptimizeMaxError exceeded"
                    loop_id = proximity_id = 0
                    closure_links = []
                    self.optimized_poses[node.id] = self.map_to_odom @ odom
            for link in closure_links:  # weights follow accepted closures (upstream addLink)
                self.memory.closure_weights(link)
                self._weights_changed.update((link.from_id, link.to_id))
            pose = self.optimized_poses[node.id]
            self.map_to_odom = pose @ se3_inverse(odom)
        self._last_had_loop = bool(loop_id or proximity_id)
        stats["Timing/Optimization/ms"] = (self._timer() - t_verify) * 1e3

        # --- keep or delete the node ---
        keep = not self.localization_mode and (not (small or merged_into) or bool(closure_links))
        if prev is None and not self.localization_mode:
            keep = True
        if keep:
            self._last_node_id = node.id
        else:
            self.memory.remove_node(node.id)
            self.optimized_poses.pop(node.id, None)
            self.bayes.forget([node.id])
        stats["Loop/Id/"] = float(loop_id)
        stats["Proximity/Space_id/"] = float(proximity_id)
        # --- memory management ---
        transferred = self._manage_memory(t0, protected=set(retrieved) | {hyp_id, node.id})
        stats["Memory/Transferred/"] = float(transferred)
        stats["Memory/Working_memory_size/"] = float(len(self.memory.wm))
        stats["Memory/Short_time_memory_size/"] = float(len(self.memory.stm))
        stats["Keypoint/Dictionary_size/words"] = float(self.vocabulary.active_words)
        stats["Timing/Total/ms"] = (self._timer() - t0) * 1e3
        if keep and self._db is not None:
            all_new = tuple(new_links) + tuple(closure_links)
            used = np.array(sorted(node.word_counts), np.int64)
            self._weights_changed.discard(node.id)
            weights = tuple((i, self.memory.nodes[i].weight) for i in sorted(self._weights_changed)
                            if i in self.memory.nodes)
            self._weights_changed.clear()
            self._db.write_frame(FrameRecord(
                node, rgb, depth, camera, scan, all_new, used,
                self.vocabulary.descriptors(used), stats, weights))
        return ProcessResult(
            node.id if keep else 0, keep, self.map_to_odom.copy(), pose,
            loop_closure_id=loop_id, proximity_id=proximity_id, hypothesis_id=hyp_id,
            hypothesis_value=hyp_value, rejected_loop_id=rejected_id, rejection_reason=reason,
            localized=self._localized, statistics=stats, map_id=node.map_id,
            new_map=new_map, maps_merged=merged,
            rejected_transform=(candidate.transform.copy()
                                if rejected_id and candidate is not None else None),
        )

    # -- maps -------------------------------------------------------------------------------
    def occupancy_grid(self) -> GlobalGrid | None:
        """Global grid assembled from the local grids at the optimised poses, of the current
        map (with the maps merged into it; a map not merged yet is in a frame of its own)."""
        frame = self.current_frame
        grids = {i: n.data.grid for i, n in self.memory.nodes.items()
                 if n.data is not None and n.data.grid is not None and self.frame_of(i) == frame}
        return assemble_grid(grids, self.optimized_poses, self.params.grid_cell_size)

    def point_cloud(self, voxel_size: float = 0.05) -> tuple[F64, NDArray[np.uint8]]:
        """Assembled coloured cloud (map frame) of the current map's nodes in RAM."""
        frame = self.current_frame
        clouds = {}
        for i, n in self.memory.nodes.items():
            if n.data is None or self.frame_of(i) != frame or i not in self.optimized_poses:
                continue
            images = self._cloud_images(n)
            if images is not None:
                clouds[i] = images.cloud(_CLOUD_VOXEL)
        return assemble_cloud(clouds, self.optimized_poses, voxel_size)

    def _cloud_images(self, node: Node) -> CloudImages | None:
        """A node's cloud images; for a node loaded from the database (a reloaded map, a
        retrieval) they are made from its stored depth and colour the first time."""
        data = node.data
        if data is None:
            return None
        if data.cloud is None and self._db is not None:
            rgb, depth, camera = self._db.frame(node.id)
            if depth is not None and camera is not None:
                p = self.params
                data.cloud = CloudImages.from_frame(depth, rgb, camera, p.grid_depth_decimation,
                                                    p.grid_range_min, p.grid_range_max)
        return data.cloud

    def graph(self) -> tuple[dict[int, F64], list[Link]]:
        """Optimised poses and all links."""
        return dict(self.optimized_poses), self.memory.unique_links()

    # -- helpers ----------------------------------------------------------------------------
    def _local_grid(self, xyz: F64, camera: CameraIntrinsics,
                    scan: Scan2D | None) -> LocalGrid | None:
        p = self.params
        sensor = p.grid_sensor
        if sensor == 0:
            return local_grid_from_scan(scan, p) if scan is not None else None
        depth_grid = local_grid_from_points(xyz, camera.local_transform[:3, 3], p)
        if sensor == 2 and scan is not None:
            return merge_local_grids(depth_grid, local_grid_from_scan(scan, p))
        return depth_grid

    def _moving(self, delta: F64) -> bool:
        """Upstream rehearsal's test: a translation beyond `RGBD/LinearUpdate` or a rotation
        beyond `RGBD/AngularUpdate` on any axis (0 = any motion)."""
        x, y, z, roll, pitch, yaw = xyz_rpy(delta)
        p = self.params
        return bool(max(abs(x), abs(y), abs(z)) > p.rgbd_linear_update
                    or max(abs(roll), abs(pitch), abs(yaw)) > p.rgbd_angular_update)

    def _small_displacement(self, delta: F64) -> bool:
        p = self.params
        if p.rgbd_linear_update <= 0 and p.rgbd_angular_update <= 0:
            return False
        x, y, z, roll, pitch, yaw = xyz_rpy(delta)
        return (
            max(abs(x), abs(y), abs(z)) <= p.rgbd_linear_update
            and max(abs(roll), abs(pitch), abs(yaw)) <= p.rgbd_angular_update
        )

    def _odom_information(self, covariance: F64 | None) -> F64:
        if covariance is None:
            var = np.full(6, _DEFAULT_ODOM_VARIANCE)
        else:
            var = np.diag(np.asarray(covariance, dtype=np.float64).reshape(6, 6)).copy()
            if var[0] >= 9999 or var[0] == 1.0 or var[0] <= 0:
                var = np.full(6, _DEFAULT_ODOM_VARIANCE)
            var[var <= 0] = _DEFAULT_ODOM_VARIANCE
        if self.params.reg_force_3dof:
            var[2:5] = np.where(var[2:5] <= 0, 1.0, var[2:5])
        return np.asarray(np.diag(1.0 / var), dtype=np.float64)

    def _likelihood_scores(self, node: Node, candidates: list[int]) -> dict[int, float]:
        mem = self.memory
        if self.params.kp_tf_idf_likelihood_used:
            n_nodes = len(mem.wm) + len(mem.stm)
            return tfidf_scores(node.word_counts, mem.inverted, mem.word_totals, n_nodes,
                                candidates)
        scores = {}
        n_new = sum(node.word_counts.values())
        for j in candidates:
            other = mem.nodes[j].word_counts
            common = sum(min(c, other.get(w, 0)) for w, c in node.word_counts.items())
            scores[j] = common / max(1, max(n_new, sum(other.values())))
        return scores

    def _bayes_neighbours(self, node_id: int, max_depth: int) -> dict[int, int]:
        """A node's neighbourhood in the Bayes prediction: loop partners at the same depth
        (upstream's `getNeighborsId` as `BayesFilter` calls it)."""
        return self.memory.neighbours(node_id, max_depth, loop_margin=True)

    def _next_hypotheses(self, top: int, count: int) -> list[int]:
        """Up to `count` further places to verify after `top` was rejected, in decreasing
        posterior: each the best location not within `_HYPOTHESIS_MARGIN` links of one
        already chosen (the posterior spreads over a place's neighbours), with data in RAM."""
        if count <= 0:
            return []
        ids, post = self.bayes.posterior_arrays()
        order = np.argsort(-post[1:], kind="stable") + 1
        taken = {top: 0} | self.memory.neighbours(top, _HYPOTHESIS_MARGIN)
        out: list[int] = []
        for k in order.tolist():
            if post[k] <= 0.0 or len(out) >= count:
                break
            i = int(ids[k])
            node = self.memory.nodes.get(i)
            if i in taken or node is None or node.data is None:
                continue
            out.append(i)
            taken.update(self.memory.neighbours(i, _HYPOTHESIS_MARGIN))
            taken[i] = 0
        return out

    def _verify(self, old: Node, new: Node, camera: CameraIntrinsics,
                link_type: LinkType) -> _Verification:
        if old.data is None or new.data is None:
            return _Verification(None, "no data")
        reg = register(old.data.features, new.data.features, camera, self.params)
        if reg.transform is None:
            return _Verification(None, f"registration failed: {reg.reason} ({reg.inliers} inliers)")
        transform, covariance = reg.transform, reg.covariance
        if self.params.reg_strategy in (_REG_ICP, _REG_VIS_ICP):
            # as upstream's Memory::computeTransform: the visual result is ICP's guess
            icp = self._icp_refine(old, new, transform)
            if icp.transform is None:
                return _Verification(None, f"ICP failed: {icp.reason or 'no transform'}")
            transform, covariance = icp.transform, icp.covariance
        limit = self.params.rgbd_max_loop_closure_distance
        if limit > 0 and float(np.linalg.norm(transform[:3, 3])) > limit:
            return _Verification(None, "RGBD/MaxLoopClosureDistance exceeded")
        info = np.asarray(np.linalg.inv(covariance), dtype=np.float64)
        if self.params.rgbd_loop_cov_limited and self._odom_max_info is not None:
            # RGBD/LoopCovLimited: no axis more certain than the best odometry link
            cap = self._odom_max_info
            idx = np.flatnonzero((np.diag(info) > cap) & (cap > 0))
            info[idx, idx] = cap[idx]
        link = Link(new.id, old.id, link_type, se3_inverse(transform), info)
        gate = self.params.rgbd_loop_closure_max_mahalanobis
        if gate > 0 and not self.localization_mode and self.frame_of(old.id) == self.frame_of(new.id):
            old_pose = self.optimized_poses.get(old.id)
            if old_pose is not None:
                d = closure_mahalanobis(link, self.map_to_odom @ new.odom_pose, old_pose,
                                        self.memory.links,
                                        heading_sigma=self.params.rgbd_odom_heading_sigma)
                if d is not None and d > gate:
                    return _Verification(None, f"RGBD/LoopClosureMaxMahalanobis exceeded "
                                               f"({d:.1f} > {gate:g})", link, d)
                if d is not None:
                    return _Verification(link, "", link, d)
        return _Verification(link, "", link)

    def _icp_refine(self, old: Node, new: Node, guess: F64) -> IcpResult:
        """ICP of the new node's depth cloud against the old one's from `guess` (new node in
        the old one's frame); clouds rebuilt from the nodes' decimated depth."""
        a, b = self._cloud_images(old), self._cloud_images(new)
        if a is None or b is None:
            return IcpResult(None, reason="no depth")
        target = make_scan(a.depth(), a.camera, self._icp)
        source = make_scan(b.depth(), b.camera, self._icp)
        result = icp_register(target, source, guess, self._icp)
        if result.transform is None:
            return result
        # upstream's RegistrationIcp covariance: 2.1981 · median squared correspondence
        # distance / 10 on every axis, the rotation's a tenth of that
        t = result.transform
        moved = source.points @ t[:3, :3].T + t[:3, 3]
        dist, _ = cKDTree(target.points).query(
            moved, distance_upper_bound=self._icp.max_correspondence_distance)
        dist = dist[np.isfinite(dist)]
        if dist.size == 0:
            return result
        var = max(2.1981 * float(np.median(dist**2)) / 10.0, 1e-9)
        return replace(result, covariance=np.diag([var, var, var, var / 10, var / 10, var / 10]))

    def _refine_with_scan(self, link: Link, prev: Node, scan: Scan2D) -> Link:
        """`RGBD/NeighborLinkRefining`: 2D ICP of this scan against the previous node's scan."""
        prev_scan = None if prev.data is None else prev.data.scan_points
        cur = scan.points_in_base()
        if prev_scan is None or prev_scan.shape[0] < 10 or cur.shape[0] < 10:
            return link
        guess = link.transform
        result = icp_2d(prev_scan, cur, np.array([guess[0, 3], guess[1, 3], yaw_of(guess)]))
        if result is None:
            # failure: keep odometry, multiply its covariance by 100
            return Link(link.from_id, link.to_id, link.type, link.transform,
                        link.information / 100.0)
        t = from_xyz_yaw(result.x, result.y, result.theta)
        t[2, 3] = guess[2, 3]
        lin = 1.0 / result.linear_variance
        ang = 1.0 / result.angular_variance
        info = np.diag([lin, lin, link.information[2, 2], link.information[3, 3],
                        link.information[4, 4], ang])
        return Link(link.from_id, link.to_id, link.type, t, info)

    def _proximity_paths(self, node: Node, here: F64) -> list[list[int]]:
        """Proximity-by-space candidates grouped in paths (runs of consecutive ids, as the
        graph's odometry chains), nearest path first: WM nodes outside STM with an optimised
        pose within `RGBD/LocalRadius` of `here`, within `RGBD/ProximityMaxGraphDepth` links
        of the new node (0 = any depth), not linked to it, in its map."""
        p = self.params
        stm = set(self.memory.stm)
        linked = set(self.memory.links.get(node.id, ()))
        # in localization the frame is linked to nothing: every map node within the radius
        local = self.localization_mode
        reach = (self.memory.neighbours(node.id, p.rgbd_proximity_max_graph_depth,
                                        exclude_stm=False, wm_only=False)
                 if p.rgbd_proximity_max_graph_depth > 0 and not local else None)
        dist: dict[int, float] = {}
        for i in self.memory.wm:
            pose = self.optimized_poses.get(i)
            if i in stm or i in linked or pose is None or (reach is not None and i not in reach):
                continue
            if not local and self.frame_of(i) != self.frame_of(node.id):
                continue
            d = float(np.linalg.norm(pose[:2, 3] - here[:2, 3]))
            if p.rgbd_local_radius <= 0 or d <= p.rgbd_local_radius:
                dist[i] = d
        paths: list[list[int]] = []
        for i in sorted(dist):
            if paths and i - paths[-1][-1] == 1:
                paths[-1].append(i)
            else:
                paths.append([i])
        paths.sort(key=lambda path: min(dist[i] for i in path))
        return paths

    def _proximity(self, node: Node, camera: CameraIntrinsics) -> Link | None:
        """Proximity detection by space (`RGBD/ProximityBySpace`): per path (at most
        `RGBD/ProximityMaxPaths`), the nearest node facing within `RGBD/ProximityAngle` and
        within `RGBD/ProximityPathFilteringRadius` is registered visually; then, with
        `RGBD/ProximityPathMaxNeighbors` > 0 and a scan, the merged scans of the path are
        registered by 2D ICP (covariance × 100, as upstream)."""
        p = self.params
        if not self.optimized_poses:
            return None
        here = self.map_to_odom @ node.odom_pose
        radius = p.rgbd_proximity_path_filtering_radius
        max_angle = np.deg2rad(p.rgbd_proximity_angle)
        paths = self._proximity_paths(node, here)[: max(1, p.rgbd_proximity_max_paths)]
        for path in paths:
            best: tuple[float, int] | None = None
            for i in path:
                pose = self.optimized_poses[i]
                d = float(np.linalg.norm(pose[:2, 3] - here[:2, 3]))
                dyaw = abs(np.arctan2(np.sin(yaw_of(pose) - yaw_of(here)),
                                      np.cos(yaw_of(pose) - yaw_of(here))))
                if d <= radius and dyaw <= max_angle and (best is None or d < best[0]):
                    best = (d, i)
            if best is None:
                continue
            link = self._verify(self.memory.nodes[best[1]], node, camera,
                                LinkType.LOCAL_SPACE_CLOSURE).link
            if link is not None and float(np.linalg.norm(link.transform[:3, 3])) <= radius:
                return link
        if p.rgbd_proximity_path_max_neighbors > 0 and node.data is not None \
                and node.data.scan_points is not None:
            for path in paths:
                link = self._proximity_scan(node, here, path)
                if link is not None:
                    return link
        return None

    def _proximity_scan(self, node: Node, here: F64, path: list[int]) -> Link | None:
        """The scan pass of proximity detection on one path: the nearest node's scan merged
        with those of up to `RGBD/ProximityPathMaxNeighbors` path nodes around it (at their
        optimised poses, in the nearest node's frame), 2D ICP from the graph's guess."""
        scan = node.data.scan_points if node.data is not None else None
        if scan is None or scan.shape[0] < 10:
            return None
        poses = self.optimized_poses
        nearest = min(path, key=lambda i: float(np.linalg.norm(poses[i][:2, 3] - here[:2, 3])))
        k = path.index(nearest)
        half = self.params.rgbd_proximity_path_max_neighbors // 2
        lo = max(0, k - half)
        chosen = path[lo: lo + self.params.rgbd_proximity_path_max_neighbors + 1]
        ref_inv = se3_inverse(poses[nearest])
        parts = []
        for i in chosen:
            data = self.memory.nodes[i].data
            pts = None if data is None else data.scan_points
            if pts is None or pts.shape[0] == 0:
                continue
            rel = ref_inv @ poses[i]
            parts.append(pts @ rel[:2, :2].T + rel[:2, 3])
        if not parts:
            return None
        merged = np.concatenate(parts)
        if merged.shape[0] < 10:
            return None
        guess = ref_inv @ here
        result = icp_2d(merged, scan, np.array([guess[0, 3], guess[1, 3], yaw_of(guess)]))
        if result is None:
            return None
        t = from_xyz_yaw(result.x, result.y, result.theta)  # new node in the nearest's frame
        var = np.array([result.linear_variance, result.linear_variance, 1.0, 1.0, 1.0,
                        result.angular_variance]) * 100.0
        if float(np.linalg.norm(t[:2, 3] - guess[:2, 3])) > \
                self.params.rgbd_proximity_path_filtering_radius:
            return None
        return Link(node.id, nearest, LinkType.LOCAL_SPACE_CLOSURE, se3_inverse(t),
                    np.diag(1.0 / var))

    def _incremental(self) -> IncrementalPose2Graph | None:
        inner = (self.optimizer.incremental if isinstance(self.optimizer, GtsamPoseGraph)
                 else self.optimizer)
        return inner if isinstance(inner, IncrementalPose2Graph) else None

    def _whole_graph(self, current: int) -> tuple[dict[int, F64], list[Link] | list[GraphLink], int]:
        """The graph to optimise: poses, links and root of the component of `current`."""
        mem = self.memory
        in_ram = set(mem.wm) | set(mem.stm)
        comp = mem.component(current, in_ram)
        known = self.optimized_poses
        poses = {i: known[i] if i in known else self.map_to_odom @ mem.nodes[i].odom_pose
                 for i in comp}
        links: list[Link] | list[GraphLink] = mem.unique_links(comp)
        if self.params.rgbd_optimize_from_graph_end:
            root = current
            poses[root] = mem.nodes[root].odom_pose
        else:
            root = min(comp)
        sigma = self.params.rgbd_odom_heading_sigma
        if sigma > 0:
            poses, links = self._frames.graph(poses, links, root, sigma, self._frame_poses)
        return poses, links, root

    def _optimize(self, current: int, new_links: list[Link]) -> bool:
        log = self.memory.take_link_log()
        live, self._graph_live = self._graph_live, False
        if live and log is not None:
            done = self._optimize_added(current, new_links, log)
            if done is not None:
                self._graph_live = done
                return done
        poses, links, root = self._whole_graph(current)
        sigma = self.params.rgbd_odom_heading_sigma
        optimized = self.optimizer.optimize(poses, links, root, self.params.optimizer_iterations)
        thr = self.params.rgbd_optimize_max_error
        if thr > 0 and new_links:
            ids, lin, ang = optimized_link_errors(self.optimizer, optimized, links)
            if _worst_link_error(ids, lin, ang, sigma) > thr:
                return False
        if sigma > 0:
            self._frame_poses = {i: p for i, p in optimized.items() if i >= ODOM_FRAME_ID_OFFSET}
            optimized = {i: p for i, p in optimized.items() if i < ODOM_FRAME_ID_OFFSET}
        self.optimized_poses.update(optimized)
        self._graph_live = (self._incremental() is not None
                            and not self.params.rgbd_optimize_from_graph_end)
        return True

    def _optimize_added(self, current: int, new_links: list[Link],
                        log: list[tuple[int, int]]) -> bool | None:
        """`_optimize` when the memory graph only grew (by the links of `log`) since the
        incremental graph last took it: hands the graph the new nodes and links instead of
        the whole component. The same update, estimate and check as the whole-graph call;
        None (nothing changed) when the additions do not fit that case."""
        g = self._incremental()
        if g is None or self.params.rgbd_optimize_from_graph_end:
            return None
        mem = self.memory
        pairs = list(dict.fromkeys(log))
        pair_set = set(pairs)
        new = {i for pair in pairs for i in pair if not g.knows(i)}
        if not g.knows(current) and current not in new:
            return None
        for n in new:  # entered RAM as new nodes: every link they have was logged
            if n not in mem.nodes or not (n in mem.wm or n in mem.stm):
                return None
            for m in mem.links.get(n, ()):
                if ((n, m) if n < m else (m, n)) not in pair_set:
                    return None
        # the component of `current` grows by the new nodes the logged links reach
        reach: set[int] = set()
        grew = True
        while grew:
            grew = False
            for a, b in pairs:
                ina, inb = g.knows(a) or a in reach, g.knows(b) or b in reach
                if ina != inb:
                    reach.add(b if ina else a)
                    grew = True
        if (not g.knows(current) and current not in reach) or (reach and min(reach) < g.root_id):
            return None
        sigma = self.params.rgbd_odom_heading_sigma
        root = g.root_id
        if sigma > 0 and not self._frames.fits(root, sigma):
            return None
        known = self.optimized_poses
        m2o = self.map_to_odom
        poses: dict[int, F64] = {i: known[i] if i in known else m2o @ mem.nodes[i].odom_pose
                                 for i in reach}
        root_pose = known[root] if root in known else m2o @ mem.nodes[root].odom_pose
        links: list[Link] | list[GraphLink] = [
            mem.links[a][b] for a, b in pairs
            if (g.knows(a) or a in reach) and (g.knows(b) or b in reach)]
        if sigma > 0:
            poses, links = self._frames.extend(poses, links, root, sigma, self._frame_poses)

        def whole() -> tuple[Mapping[int, F64], list[Link] | list[GraphLink]]:
            p, lk, _ = self._whole_graph(current)
            return p, lk

        if not g.extend(poses, links, root, root_pose, self.params.optimizer_iterations, whole):
            return None
        thr = self.params.rgbd_optimize_max_error
        if thr > 0 and new_links:
            ids, lin, ang = g.link_error_ratios()
            if _worst_link_error(ids, lin, ang, sigma) > thr:
                return False
        mats = g.poses_array()
        ids_all = np.asarray(g.node_ids, np.int64)
        if sigma > 0:
            # as splitting the {id: pose} dict of the whole-graph call (graph order kept)
            frame = ids_all >= ODOM_FRAME_ID_OFFSET
            self._frame_poses = dict(zip(ids_all[frame].tolist(), mats[frame]))
            node = ~frame
            self.optimized_poses.update(zip(ids_all[node].tolist(), mats[node]))
        else:
            self.optimized_poses.update(zip(ids_all.tolist(), mats))
        return True

    def _localize(self, closure_links: list[Link], odom: F64, odom_info: F64
                  ) -> tuple[F64, str]:
        """Localization mode: map→odom moves only for a localization the odometry cache
        accepts (`RGBD/MaxOdomCacheSize`, `RGBD/OptimizeMaxError`); returns the base pose in
        the map frame and why a localization was rejected ("" if none was)."""
        cache = self._odom_cache
        if cache is not None:
            cache.add(odom, odom_info)
        if not closure_links:
            return self.map_to_odom @ odom, ""
        if cache is None:  # RGBD/MaxOdomCacheSize 0: every localization as is
            link = closure_links[0]
            old_pose = self.optimized_poses.get(link.to_id)
            if old_pose is None:
                return self.map_to_odom @ odom, "the linked map node has no pose"
            pose = old_pose @ se3_inverse(link.transform)
            self.localization_covariance = np.asarray(np.linalg.inv(link.information))
        else:
            check = cache.localize(closure_links, self.optimized_poses)
            if check.pose is None:
                return self.map_to_odom @ odom, check.reason
            pose = check.pose
            self.localization_covariance = check.covariance
        self.map_to_odom = pose @ se3_inverse(odom)
        self._localized = True
        return pose, ""

    def _retrieve_around(self, hyp_id: int) -> list[int]:
        mem = self.memory
        limit = self.params.rtabmap_max_retrieved
        if limit <= 0:
            return []
        frontier = [hyp_id]
        seen = {hyp_id}
        out: list[int] = []
        for _ in range(self.bayes.max_depth):
            nxt = []
            for n in frontier:
                # time neighbours (adjacent ids) first, then loop links
                for m in sorted(mem.links.get(n, ()), key=lambda k: (abs(k - n) != 1, k)):
                    if m in seen:
                        continue
                    seen.add(m)
                    nxt.append(m)
                    if m in mem.ltm and len(out) < limit and mem.retrieve(m):
                        out.append(m)
            if len(out) >= limit or not nxt:
                break
            frontier = nxt
        for m in out:
            self.bayes.node_entered(m, self._bayes_neighbours(m, self.bayes.max_depth))
        return out

    def _manage_memory(self, t0: float, protected: set[int]) -> int:
        p = self.params
        mem = self.memory
        elapsed_ms = (self._timer() - t0) * 1e3
        n = 0
        if p.rtabmap_memory_thr > 0 and len(mem.wm) > p.rtabmap_memory_thr:
            n = len(mem.wm) - p.rtabmap_memory_thr
        if p.rtabmap_time_thr > 0 and elapsed_ms > p.rtabmap_time_thr:
            n = max(n, 2)
        if n <= 0:
            return 0
        cands = mem.transfer_candidates(protected, p.mem_recent_wm_ratio, n,
                                        p.mem_transfer_sorting_by_weight_id)
        for i in cands:
            neighbourhood = self._bayes_neighbours(i, self.bayes.max_depth)
            mem.transfer_to_ltm(i)
            self.bayes.node_left(i, neighbourhood)
        return len(cands)
