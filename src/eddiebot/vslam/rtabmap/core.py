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

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.bayes import BayesFilter, adjust_likelihood
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.depth_icp import IcpSettings
from eddiebot.vslam.features import FeatureExtractor, FrameFeatures
from eddiebot.vslam.graph import GtsamPoseGraph, PoseGraphOptimizer
from eddiebot.vslam.localization import OdometryCache
from eddiebot.vslam.memory import Link, LinkType, Memory, Node, NodeData
from eddiebot.vslam.occupancy import CloudImages, Scan2D, depth_cloud
from eddiebot.vslam.odometry_frames import OdometryFrames
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.records import FrameRecord, MapDatabase, ProcessResult
from eddiebot.vslam.rtabmap.graph_update import GraphUpdate
from eddiebot.vslam.rtabmap.localize import Localize
from eddiebot.vslam.rtabmap.memory_management import MemoryManagement
from eddiebot.vslam.rtabmap.odometry_links import OdometryLinks
from eddiebot.vslam.rtabmap.proximity import ProximityDetection
from eddiebot.vslam.rtabmap.state import F64
from eddiebot.vslam.transforms import se3_inverse, to_3dof
from eddiebot.vslam.vocabulary import Vocabulary

__all__ = ["Rtabmap"]


class Rtabmap(ProximityDetection, GraphUpdate, Localize, MemoryManagement, OdometryLinks):
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
            params.reg_force_3dof, params.optimizer_epsilon,
            incremental=params.gtsam_incremental, robust=params.optimizer_robust
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
