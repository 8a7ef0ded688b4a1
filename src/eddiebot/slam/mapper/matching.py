"""Scan matching against the map: node points and reference grids, the sequential and loop
matches, and the covariance a match reports."""


from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import wrap_angle
from eddiebot.slam.mapper.measurement import scan_position_covariance
from eddiebot.slam.mapper.results import FloatArray, SlamWarning
from eddiebot.slam.mapper.se2_rows import _compose1, _compose_rows, _place_rows
from eddiebot.slam.mapper.state import MapperState
from eddiebot.slam.scan_matcher import (
    MatcherParams,
    MatchResult,
    build_correlation_grid,
    match_scan,
    point_normals,
    pyramid_levels,
    refine_icp,
)


class ScanMatching(MapperState):
    """`MapperState` with the scan matching of every mode."""


    def start_at(self, pose: npt.ArrayLike) -> None:
        """Begin the next scan at robot pose ``pose`` (map frame, m/rad) whatever its odometry.

        The scan starts a new odometry chain; in mapping and lifelong modes it is matched
        against, and linked to, the graph's nodes near ``pose`` (slam_toolbox's
        START_AT_GIVEN_POSE / START_AT_FIRST_NODE / LOCALIZE_AT_POSE after a load)."""
        p = np.asarray(pose, dtype=np.float64).reshape(3).copy()
        st = self._state
        st.pending_start = p
        st.last_pose = p.copy()
        st.last_processed_odom = None
        st.last_seen_odom = None
        if not self.nodes or self.mode == "localization":
            return
        positions = self._positions()
        sensor = _compose1(p, self.sensor_offset)
        active = np.flatnonzero(self._active_nodes())
        if active.size == 0:
            return
        d = np.hypot(positions[active, 0] - sensor[0], positions[active, 1] - sensor[1])
        order = np.argsort(d, kind="stable")
        near = [int(active[k]) for k in order if d[k] <= self.config.scan_buffer_maximum_scan_distance]
        if not near:
            near = [int(active[order[0]])]
        st.running = deque(sorted(near[: self.config.scan_buffer_size]))

    # -- node points / reference maps
    def _world_points(self, idx: int, pose: FloatArray | None = None) -> FloatArray:
        # the caches below compare poses as float lists: np.array_equal's value semantics
        # (0.0 == -0.0) at a tenth of its cost, which ~50 look-ups a scan add up to;
        # ``pose``: the node's current estimate when the caller has it (a row of graph.poses)
        if pose is None:
            pose = self.graph.pose(idx)
        cached = self._ref_cache.get(idx)
        if cached is not None and cached[0].tolist() == pose.tolist():
            return cached[1]
        sensor = _compose1(pose, self.sensor_offset)
        pts = self.nodes[idx].points
        c, s = math.cos(sensor[2]), math.sin(sensor[2])
        world = np.empty_like(pts)
        world[:, 0] = sensor[0] + c * pts[:, 0] - s * pts[:, 1]
        world[:, 1] = sensor[1] + s * pts[:, 0] + c * pts[:, 1]
        self._ref_cache[idx] = (pose, world)
        return world


    def _local_normals(self, idx: int) -> FloatArray:
        local = self._normal_cache.get(idx)
        if local is None:
            local = point_normals(self.nodes[idx].points)
            self._normal_cache[idx] = local
        return local


    def _reference(
        self, nodes: Sequence[int], poses: FloatArray, *, normals: bool = False
    ) -> tuple[FloatArray, FloatArray | None]:
        """The end points (and with ``normals`` their normals) of ``nodes``, concatenated in
        the map frame at their rows of ``poses``: `_world_points` of every node, and each node's
        `_local_normals` turned by its sensor heading, in one pass (the same operations on each
        value as the per-node code, so bit-identical to it)."""
        rows = poses[np.asarray(nodes, dtype=np.intp)]
        sensor = _compose_rows(rows, self.sensor_offset)
        th = sensor[:, 2].tolist()
        c = np.array([math.cos(t) for t in th])
        s = np.array([math.sin(t) for t in th])
        tx, ty = sensor[:, 0].copy(), sensor[:, 1].copy()
        local = np.concatenate([self.nodes[i].points for i in nodes])
        counts = np.array([self.nodes[i].points.shape[0] for i in nodes], dtype=np.int64)
        world = np.empty_like(local)
        if local.dtype == np.float64:
            _place_rows(local, counts, tx, ty, c, s, True, world)
        else:  # (float32 scans) numpy's own promotion rules, as `_world_points`
            pick = np.repeat(np.arange(len(nodes)), counts)
            lx, ly = local[:, 0], local[:, 1]
            for j, (pj, cj, sj) in enumerate(zip(sensor.tolist(), c.tolist(), s.tolist())):
                m = pick == j
                world[m, 0] = np.float64(pj[0]) + cj * lx[m] - sj * ly[m]
                world[m, 1] = np.float64(pj[1]) + sj * lx[m] + cj * ly[m]
        if not normals:
            return world, None
        ln = np.concatenate([self._local_normals(i) for i in nodes])
        wn = np.empty_like(ln)
        _place_rows(ln, counts, tx, ty, c, s, False, wn)
        return world, wn


    def _reference_position(self, idx: int) -> FloatArray:
        pose = self.graph.pose(idx)
        cached = self._pos_cache.get(idx)
        if cached is not None and cached[0].tolist() == pose.tolist():
            return cached[1]
        if self.config.use_scan_barycenter and self.nodes[idx].points.shape[0]:
            pos = self._world_points(idx).mean(axis=0)
        else:
            pos = _compose1(pose, self.sensor_offset)[:2]
        self._pos_cache[idx] = (pose, pos)
        return pos


    def _positions(self) -> FloatArray:
        """Reference positions of every node (N, 2), vectorised (barycentre or sensor)."""
        n = len(self.nodes)
        if n == 0:
            return np.zeros((0, 2))
        poses = self.graph.poses
        # `sensor_poses` (se2_compose on every row): the same ufuncs without its set-up
        sensors = _compose_rows(poses, self.sensor_offset) if poses.shape[0] else poses
        if not self.config.use_scan_barycenter:
            return sensors[:, :2].copy()
        if self._bary_local.shape[0] != n:
            extra = [
                n_.points.mean(axis=0) if n_.points.shape[0] else np.zeros(2)
                for n_ in self.nodes[self._bary_local.shape[0] :]
            ]
            self._bary_local = np.concatenate([self._bary_local, np.array(extra).reshape(-1, 2)])
        b = self._bary_local
        c, s = np.cos(sensors[:, 2]), np.sin(sensors[:, 2])
        return np.stack(
            [sensors[:, 0] + c * b[:, 0] - s * b[:, 1], sensors[:, 1] + s * b[:, 0] + c * b[:, 1]],
            axis=-1,
        )


    def _match_against(
        self,
        nodes: list[int],
        points: FloatArray,
        prior_sensor: FloatArray,
        params: MatcherParams,
        *,
        reject_below: float | None = None,
        extra: tuple[FloatArray, FloatArray] | None = None,
    ) -> MatchResult:
        # ``reject_below``: the caller discards a match whose response is below it, so such a
        # match stops once its response is known (`match_scan`) and is not polished;
        # ``extra``: further reference points and their normals (map frame) beside the nodes'
        # (localization's buffer of recent scans)
        # one pass over the optimiser's estimate (the same values as one look-up per node,
        # which the reference points and normals below would otherwise make ~40 times)
        poses = self.graph.poses
        polish = self.config.use_icp_refinement and params is not self._slip_params
        normals: FloatArray | None = None
        if nodes:
            ref, normals = self._reference(nodes, poses, normals=polish)
        else:
            ref = np.zeros((0, 2))
        if extra is not None and extra[0].shape[0]:
            ref = np.concatenate([ref, extra[0]])
            if normals is not None or (polish and not nodes):
                base = normals if normals is not None else np.zeros((0, 2))
                normals = np.concatenate([base, extra[1]])
        c, s = math.cos(prior_sensor[2]), math.sin(prior_sensor[2])
        wx = prior_sensor[0] + c * points[:, 0] - s * points[:, 1]
        wy = prior_sensor[1] + s * points[:, 0] + c * points[:, 1]
        half = 0.5 * params.search_dimension + 0.05
        bounds = (
            float(wx.min()) - half,
            float(wy.min()) - half,
            float(wx.max()) + half,
            float(wy.max()) + half,
        )
        grid = build_correlation_grid(
            ref, bounds, params.resolution, params.smear_deviation, pyramid_levels(params)
        )
        match = match_scan(points, grid, prior_sensor, params, reject_below=reject_below)
        if reject_below is not None and match.response < reject_below:
            return match
        if polish and match.response > 0.0:
            if normals is None:
                normals = np.zeros((0, 2))
            match = self._polish(match, points, ref, normals, params)
        return match


    def _polish(
        self,
        match: MatchResult,
        points: FloatArray,
        ref: FloatArray,
        normals: FloatArray,
        params: MatcherParams,
    ) -> MatchResult:
        """Point-to-line ICP from a correlative match (kept when it stays near the match)."""
        refined, share = refine_icp(points, ref, match.pose, reference_normals=normals)
        moved = float(np.hypot(*(refined[:2] - match.pose[:2])))
        turned = abs(float(wrap_angle(refined[2] - match.pose[2])))
        if not (
            share >= 0.5
            and moved <= 2.0 * params.smear_deviation + params.resolution
            and turned <= params.coarse_angle_resolution
        ):
            return match
        return MatchResult(refined, match.response, match.covariance)


    def _scan_normals(self, idx: int, points: FloatArray) -> FloatArray:
        """Sensor-frame normals of node ``idx``'s points (cached; ``idx`` may be the next node)."""
        local = self._normal_cache.get(idx)
        if local is None or local.shape[0] != points.shape[0]:
            local = point_normals(points)
            self._normal_cache[idx] = local
        return local


    def _scan_geometry(
        self, match: MatchResult, points: FloatArray, idx: int
    ) -> tuple[FloatArray, FloatArray]:
        """`scan_position_covariance` of node ``idx``'s scan (sensor frame) and the rotation
        by the match's heading that takes it into the map frame."""
        cfg = self.config
        geo = scan_position_covariance(
            points,
            self._scan_normals(idx, points),
            cfg.scan_range_sigma,
            cfg.scan_range_sigma_quadratic,
        )
        c, s = math.cos(float(match.pose[2])), math.sin(float(match.pose[2]))
        return geo, np.array([[c, -s], [s, c]])


    def _with_range_error(self, match: MatchResult, points: FloatArray, idx: int) -> MatchResult:
        """A match whose position covariance also holds the error its scan's range errors
        leave it (`scan_position_covariance`, turned into the map frame by the match's
        heading): ``loop_match_range_covariance``."""
        geo, rot = self._scan_geometry(match, points, idx)
        cov = np.array(match.covariance, dtype=np.float64)
        cov[:2, :2] += rot @ geo @ rot.T
        return MatchResult(match.pose, match.response, cov)


    def _check_covariance(
        self, match: MatchResult, warnings: list[SlamWarning], stamp: int
    ) -> None:
        xy = match.covariance[:2, :2]
        w, v = np.linalg.eigh(xy)
        if w[-1] > self.config.corridor_covariance_threshold:
            heading = math.degrees(math.atan2(v[1, -1], v[0, -1]))
            self._warn(
                warnings,
                "low_feature",
                f"scan match poorly constrained along {heading:.0f}° (σ {math.sqrt(w[-1]):.3f} m): "
                "low-feature area such as a corridor",
                stamp,
            )
