"""Mapping and lifelong mode: nodes and odometry edges, slip recovery, links between odometry
chains, loop closures, and the removal of depreciated nodes (lifelong)."""


from __future__ import annotations

import math

import numpy as np

from eddiebot.geometry import wrap_angle
from eddiebot.slam.loop_closure import (
    LoopClosure,
    find_loop_candidates,
    near_linked_nodes,
    verify_loop,
)
from eddiebot.slam.mapper.lifelong import ScanBox, rescore, scan_box, scan_boxes
from eddiebot.slam.mapper.matching import ScanMatching
from eddiebot.slam.mapper.measurement import (
    _NO_HEADING_VARIANCE,
    SEQUENTIAL_POSITION_VARIANCE_SCALE,
    _odometry_covariance,
    _rotate_covariance,
    constrained_information,
    fuse_increments,
    sequential_edge_covariance,
)
from eddiebot.slam.mapper.results import (
    FloatArray,
    NodeRecord,
    ProcessResult,
    ProcessStatus,
    SlamWarning,
)
from eddiebot.slam.mapper.se2_rows import _between1, _compose1, _compose_rows, _inverse1
from eddiebot.slam.pose_graph import EdgeKind
from eddiebot.slam.scan import Scan, scan_points
from eddiebot.slam.scan_matcher import MatchResult

_MARGINALIZE_BATCH = 10
"""Fewest retired nodes marginalised together (each batch restarts iSAM2 once)."""


class Mapping(ScanMatching):
    """`ScanMatching` with the mapping and lifelong modes."""

    # -- mapping / lifelong
    def _map(self, scan: Scan, odom: FloatArray, warnings: list[SlamWarning]) -> ProcessResult:
        cfg = self.config
        st = self._state
        stamp = int(scan.stamp_ns)
        points = scan_points(scan, cfg.max_laser_range)
        prior = self._prior(odom)
        prior_sensor = _compose1(prior, self.sensor_offset)
        response = 0.0
        covariance: FloatArray | None = None
        pose = prior
        running = [i for i in st.running if not self.nodes[i].retired]
        matched = False
        chain_from_odometry = st.last_processed_odom is not None
        odo_delta: FloatArray | None = None
        if chain_from_odometry and st.last_processed_odom is not None:
            odo_delta = _between1(st.last_processed_odom, odom)
        if cfg.use_scan_matching and running:
            match = self._match_against(running, points, prior_sensor, self._seq_params)
            match = self._recover_slip(
                running, points, prior_sensor, match, warnings, stamp, odo_delta
            )
            response, covariance = match.response, match.covariance
            if match.response >= cfg.link_match_minimum_response_fine:
                pose = _compose1(match.pose, _inverse1(self.sensor_offset))
                matched = True
                self._check_covariance(match, warnings, stamp)
            else:
                self._warn(
                    warnings,
                    "weak_match",
                    f"scan match response {match.response:.2f} below "
                    f"{cfg.link_match_minimum_response_fine}; using odometry",
                    stamp,
                )
        edge: tuple[FloatArray, FloatArray, EdgeKind] | None = None
        link = len(self.nodes) - 1
        if self.nodes:
            if not chain_from_odometry and running:
                # a new chain (after a load, a start pose, an odometry jump): linked to the
                # nearest node it was matched against, not to the last node added
                here = _compose1(pose, self.sensor_offset)[:2]
                link = min(running, key=lambda i: float(np.hypot(*(self._reference_position(i) - here))))
            prev_pose = self.graph.pose(link)
            if not chain_from_odometry and not matched:
                # first scan after loading a session: the odom frames of the two runs are
                # unrelated, so only a weak link to where the session ended
                edge = (_between1(prev_pose, pose), np.diag([1.0, 1.0, 0.5]), EdgeKind.ODOMETRY)
            elif matched and covariance is not None:
                delta = _between1(prev_pose, pose)
                cov = _rotate_covariance(covariance, float(prev_pose[2]))
                if cfg.fuse_odometry and odo_delta is not None:
                    # one edge carrying both measurements: equivalent to an odometry edge plus
                    # a scan-match edge whose information is the match's restricted to the
                    # directions the scan observes (a corridor match only across it)
                    info, _ = constrained_information(cov, cfg.corridor_covariance_threshold)
                    # (its position information as the unfused edge's: ×1/0.2)
                    info[:2, :2] /= SEQUENTIAL_POSITION_VARIANCE_SCALE
                    delta, cov = fuse_increments(
                        odo_delta, self._step_odometry_covariance(odo_delta), delta, info
                    )
                    pose = _compose1(prev_pose, delta)
                else:
                    cov = sequential_edge_covariance(cov)
                edge = (delta, cov, EdgeKind.SCAN_MATCH)
            elif odo_delta is not None:
                edge = (odo_delta, _odometry_covariance(odo_delta, cfg), EdgeKind.ODOMETRY)
        idx = self.graph.add_node(pose)
        self.nodes.append(NodeRecord(scan, points, odom.copy()))
        if edge is not None:
            self.graph.add_edge(link, idx, edge[0], edge[1], kind=edge[2])
        if not chain_from_odometry:
            st.chain_start = idx
        span = cfg.odometry_span_nodes
        if span > 0 and matched and idx - span >= st.chain_start:
            self._add_odometry_span(idx - span, idx)
        # running buffer
        st.running.append(idx)
        while len(st.running) > cfg.scan_buffer_size:
            st.running.popleft()
        here = self._reference_position(idx)
        while len(st.running) > 1:
            d = np.hypot(*(self._reference_position(st.running[0]) - here))
            if d <= cfg.scan_buffer_maximum_scan_distance:
                break
            st.running.popleft()
        if matched and idx > 0:
            self._link_near_chains(idx, points)
        loop_closed = False
        if cfg.do_loop_closing and idx > 0:
            loop_closed = self._try_close_loops(idx, points, warnings, stamp)
        self.graph.optimize(full=loop_closed)
        final = self.graph.pose(idx)
        if self.mode == "lifelong":
            self._evaluate_node_depreciation(idx)
        st.last_pose = final
        st.last_processed_odom = odom.copy()
        st.map_to_odom = _compose1(final, _inverse1(odom))
        return ProcessResult(
            ProcessStatus.ADDED,
            self.map_to_odom,
            pose=final.copy(),
            node_id=idx,
            response=response,
            covariance=covariance,
            loop_closed=loop_closed,
            warnings=tuple(warnings),
        )


    def _step_odometry_covariance(self, odo_delta: FloatArray) -> FloatArray:
        """Odometry covariance of one sequential step for fusion (`fused_step_heading`)."""
        cfg = self.config
        cov = _odometry_covariance(odo_delta, cfg)
        if cfg.odometry_span_nodes <= 0 or cfg.fused_step_heading == "odometry":
            return cov
        if cfg.fused_step_heading == "quantization":
            floor = 2.0 * cfg.odometry_heading_quantization**2
            cov[2, 2] = max(float(cov[2, 2]), floor)
        else:
            # no heading information from the odometry: the match's heading sets the step
            cov[2, 2] = _NO_HEADING_VARIANCE
        return cov


    def _recover_slip(
        self,
        nodes: list[int],
        points: FloatArray,
        prior_sensor: FloatArray,
        match: MatchResult,
        warnings: list[SlamWarning],
        stamp: int,
        odo_delta: FloatArray | None = None,
    ) -> MatchResult:
        """Re-search a wider window when the match is weak or pinned to the window's edge.

        A wheel slip larger than the sequential window (±0.25 m by default) otherwise yields
        a wrong, border-hugging match; eddiebot's addition, off when
        ``slip_search_dimension`` is 0. With ``slip_search_maximum_sigmas`` set, the wide
        result is taken only when it is well constrained in every direction (a corridor
        aliases along its length) and the odometry increment ``odo_delta`` does not rule the
        jump out.
        """
        cfg = self.config
        if cfg.slip_search_dimension <= cfg.correlation_search_space_dimension:
            return match
        half = 0.5 * cfg.correlation_search_space_dimension
        offset = match.pose[:2] - prior_sensor[:2]
        at_edge = bool(
            np.any(np.abs(offset) >= half - 2.0 * cfg.correlation_search_space_resolution)
        )
        if match.response >= self._weak_response and not at_edge:
            return match
        wide = self._match_against(nodes, points, prior_sensor, self._slip_params)
        # (a response at or below the bar below is discarded: no need to finish such a match)
        fine = self._match_against(
            nodes, points, wide.pose, self._loop_fine, reject_below=match.response + 0.05
        )
        if (
            fine.response > match.response + 0.05
            and (cfg.slip_search_maximum_sigmas <= 0.0 or self._well_constrained(fine.covariance))
            and not self._odometry_contradicts(prior_sensor, fine.pose, odo_delta)
        ):
            self._warn(
                warnings,
                "slip",
                f"odometry off by {np.hypot(*(fine.pose[:2] - prior_sensor[:2])):.2f} m / "
                f"{math.degrees(float(wrap_angle(fine.pose[2] - prior_sensor[2]))):.1f}°; "
                "recovered by a wide search",
                stamp,
            )
            return fine
        return match


    def _well_constrained(self, covariance: FloatArray) -> bool:
        """True when a match's position variance is below the corridor threshold everywhere."""
        w = np.linalg.eigvalsh(0.5 * (covariance[:2, :2] + covariance[:2, :2].T))
        return bool(w[-1] <= self.config.corridor_covariance_threshold)


    def _odometry_contradicts(
        self, prior_sensor: FloatArray, pose: FloatArray, odo_delta: FloatArray | None
    ) -> bool:
        """True when a jump from the odometry prediction is implausible under its noise model."""
        gate = self.config.slip_search_maximum_sigmas
        if gate <= 0.0 or odo_delta is None:
            return False
        jump = np.asarray(pose, dtype=np.float64) - prior_sensor
        jump[2] = float(wrap_angle(jump[2]))
        cov = _odometry_covariance(odo_delta, self.config)
        th = float(prior_sensor[2])
        cov_map = _rotate_covariance(cov, -th)
        m2 = float(jump @ np.linalg.solve(cov_map, jump))
        return m2 > gate * gate


    def _near_chains(self, idx: int, positions: FloatArray) -> list[tuple[int, ...]]:
        """Karto's ``FindNearChains``: runs of consecutive nodes whose sensor positions lie
        within ``link_scan_maximum_distance`` of node ``idx``'s, each grown from a node the
        graph links to ``idx`` through nodes whose reference positions (``positions``) stay
        that near (`near_linked_nodes`), leaving out the run that reaches ``idx`` itself (its
        own running chain) and retired nodes."""
        dist = self.config.link_scan_maximum_distance
        near = near_linked_nodes(idx, positions, self.graph.adjacent, dist)
        near.discard(idx)
        if not near:
            return []
        # sensor positions only once a linked node is near (most scans stop above)
        sensors = _compose_rows(self.graph.poses[: idx + 1], self.sensor_offset)
        d = sensors[:, :2] - sensors[idx, :2]
        within = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= dist * dist + 1e-12).tolist()
        active = self._active_nodes()
        processed: set[int] = set()
        chains: list[tuple[int, ...]] = []
        for n in sorted(near):
            if n in processed:
                continue
            lo = n
            while lo > 0 and within[lo - 1]:
                lo -= 1
            hi = n
            while hi < idx and within[hi + 1]:
                hi += 1
            processed.update(range(lo, hi + 1))
            if hi >= idx:
                continue
            chain = tuple(i for i in range(lo, hi + 1) if active[i])
            if chain:
                chains.append(chain)
        return chains


    def _link_near_chains(self, idx: int, points: FloatArray) -> int:
        """Karto's ``LinkNearChains``: match node ``idx``'s scan against each near chain of at
        least ``loop_match_minimum_chain_size`` nodes (`_near_chains`) with the sequential
        matcher around its current estimate, and link it to the chain's node nearest to it when
        the response reaches ``link_match_minimum_response_fine``. Once a loop closure has tied
        a revisit to an earlier pass, these links keep every later scan there tied to it.
        The edges are robust: gated against the estimate like loop closures, under the loop
        kernel. Returns the number of links added."""
        cfg = self.config
        if cfg.link_scan_maximum_distance <= 0.0:
            return 0
        positions = self._positions()
        chains = [
            c for c in self._near_chains(idx, positions)
            if len(c) >= cfg.loop_match_minimum_chain_size
        ]
        if not chains:
            return 0
        pose = self.graph.pose(idx)
        sensor = _compose1(pose, self.sensor_offset)
        added = 0
        for chain in chains:
            match = self._match_against(list(chain), points, sensor, self._seq_params)
            if match.response < cfg.link_match_minimum_response_fine:
                continue
            if cfg.loop_match_range_covariance:
                match = self._with_range_error(match, points, idx)
            # Karto's GetClosestScanToPose: the chain node whose reference position is nearest
            offsets = positions[list(chain)] - positions[idx]
            near = chain[int(np.argmin(np.hypot(offsets[:, 0], offsets[:, 1])))]
            near_pose = self.graph.pose(near)
            base = _compose1(match.pose, _inverse1(self.sensor_offset))
            cov = _rotate_covariance(match.covariance, float(near_pose[2]))
            self.graph.add_edge(near, idx, _between1(near_pose, base), cov,
                                kind=EdgeKind.SCAN_MATCH, robust=True)
            added += 1
        self.near_chain_links += added
        return added


    def _try_close_loops(
        self, idx: int, points: FloatArray, warnings: list[SlamWarning], stamp: int
    ) -> bool:
        cfg = self.config
        closed = False
        for _ in range(2):
            positions = self._positions()
            linked = near_linked_nodes(
                idx, positions, self.graph.adjacent, cfg.loop_search_maximum_distance
            )
            chains = find_loop_candidates(
                idx,
                positions,
                linked,
                max_distance=cfg.loop_search_maximum_distance,
                min_chain_size=cfg.loop_match_minimum_chain_size,
                min_chain_length=(cfg.loop_match_minimum_chain_size - 1)
                * cfg.minimum_travel_distance,
                active=self._active_nodes(),
            )
            found: LoopClosure | None = None
            poses = self.graph.poses  # in sync since _positions: no second pass
            sensor = _compose1(poses[idx], self.sensor_offset)
            if cfg.loop_match_maximum_chains > 0:
                chains = chains[: cfg.loop_match_maximum_chains]
            for chain in chains:
                ref = self._reference(chain, poses)[0]
                found = verify_loop(
                    points,
                    sensor,
                    chain,
                    ref,
                    positions[list(chain)],
                    coarse=self._loop_coarse,
                    fine=self._loop_fine,
                    min_response_coarse=cfg.loop_match_minimum_response_coarse,
                    max_variance_coarse=cfg.loop_match_maximum_variance_coarse,
                    min_response_fine=cfg.loop_match_minimum_response_fine,
                    max_variance_fine=cfg.loop_match_maximum_variance_fine,
                )
                if found is not None:
                    break
            if found is None:
                return closed
            base = _compose1(found.match.pose, _inverse1(self.sensor_offset))
            cand_pose = self.graph.pose(found.candidate)
            delta = _between1(cand_pose, base)
            match = found.match
            if cfg.loop_match_range_covariance:
                match = self._with_range_error(match, points, idx)
            cov = _rotate_covariance(match.covariance, float(cand_pose[2]))
            self.graph.add_edge(found.candidate, idx, delta, cov, kind=EdgeKind.LOOP, robust=True)
            self.loop_closures.append(found)
            self.graph.optimize(full=True)
            closed = True
        return closed


    def _evaluate_node_depreciation(self, idx: int) -> None:
        """slam_toolbox's ``evaluateNodeDepreciation``: re-score the older nodes near new node
        ``idx`` (`eddiebot.slam.mapper.lifelong`); a node whose score falls below
        ``lifelong_node_removal_score`` leaves the map and the match and loop searches at
        once, and the pose graph by marginalisation (`_remove_depreciated`)."""
        cfg = self.config
        params = self._lifelong_params
        new_pts = self._world_points(idx)
        if new_pts.shape[0] == 0:
            return
        pose = self.graph.pose(idx)
        new_box = scan_box(new_pts, _compose1(pose, self.sensor_offset))
        positions = self._positions()
        active = self._active_nodes()
        if params.search_use_tree:
            d = positions - positions[idx]
            near = np.flatnonzero(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] <= new_box.radius**2)
            candidates = [int(j) for j in near]
        else:
            candidates = sorted(
                near_linked_nodes(idx, positions, self.graph.adjacent, new_box.radius)
            )
        # the newest nodes may still get odometry span edges: they stay until those are in
        protect = max(cfg.scan_buffer_size, cfg.odometry_span_nodes + 1)
        adjacent = self.graph.adjacent
        nodes = self.nodes
        # upstream re-scores a node only with IoU >= lifelong_minimum_score and two edges, and
        # leaves the newest scan_buffer_size nodes and nodes 0 and 1 as they are
        cands = [
            j for j in candidates
            if active[j] and idx - j >= protect and j > 1
            and len(adjacent(j)) >= 2 and nodes[j].points.shape[0]
        ]
        if cands:
            self._rescore(idx, new_box, cands)
        # each batch restarts iSAM2 (cost ~ the graph): batches of a tenth of it keep that a
        # constant share of the work per removed node
        if len(self._depreciated) >= max(_MARGINALIZE_BATCH, self.graph.live_nodes // 10):
            self._remove_depreciated()

    def _rescore(self, idx: int, new_box: ScanBox, cands: list[int]) -> None:
        """Upstream's ``computeScores`` for candidates ``cands`` of new node ``idx``."""
        poses = self.graph.poses
        world, _ = self._reference(cands, poses)
        counts = np.array([self.nodes[j].points.shape[0] for j in cands], dtype=np.int64)
        sensors = _compose_rows(poses[cands], self.sensor_offset)[:, :2]
        scored, scores = rescore(
            self._lifelong_params,
            new_box,
            scan_boxes(world, counts, sensors),
            world,
            counts,
            np.array([len(self.graph.adjacent(j)) for j in cands], dtype=np.int64),
            np.array([self.lifelong_scores.get(j, 1.0) for j in cands]),
        )
        removal = self._lifelong_params.node_removal_score
        for j, score in zip(np.asarray(cands)[scored].tolist(), scores[scored].tolist()):
            if score < removal:
                self._retire(j)
            else:
                self.lifelong_scores[j] = score

    def _retire(self, j: int) -> None:
        """Take node ``j`` out of the map and the searches; queue it for marginalisation."""
        self.nodes[j].retired = True
        self._active_nodes()[j] = False
        self.lifelong_scores.pop(j, None)
        old = self._rasterized.pop(j, None)
        if old is not None:
            self._cast(j, old, -1)
        self._depreciated.append(j)

    def _remove_depreciated(self) -> None:
        """Marginalise the retired nodes out of the pose graph and free their scans."""
        if not self._depreciated:
            return
        removed, self._depreciated = self._depreciated, []
        self.graph.marginalize(removed)
        for j in removed:
            node = self.nodes[j]
            empty = np.zeros(0)
            self.nodes[j] = NodeRecord(
                Scan(empty, empty, node.scan.range_min, node.scan.range_max, node.scan.stamp_ns),
                np.zeros((0, 2)),
                node.odom_pose,
                retired=True,
            )
            for cache in (self._ref_cache, self._pos_cache, self._normal_cache):
                cache.pop(j, None)
        self.removed_nodes += len(removed)
