"""`SlamCore`: the 2D SLAM facade the node, the replay CLI and the benchmarks call.

``process(scan, odom_pose)`` takes a scan (sensor frame) and the robot's odometry pose
(``odom → base_footprint``) and returns a `ProcessResult`; ``map_to_odom`` is the correction
to publish. Modes are strategies composed into the core, not subclasses:

* ``mapping``: each accepted scan becomes a node, matched against the running buffer of
  recent nodes, linked to the previous node, checked for loop closures, optimised;
* ``localization``: scans are matched against a loaded graph's scans near the prior; the
  graph is never extended;
* ``lifelong``: mapping on top of a loaded session; an older node whose scan is covered by a
  new node's (overlap >= ``lifelong_node_overlap``) is retired: it stays in the pose graph as
  a constraint but no longer renders into the map or serves as a match reference.

Which scans are processed: the first, then any whose *sensor* pose moved at least
``minimum_travel_distance`` **or** turned at least ``minimum_travel_heading`` since the last
processed one — in every mode. (Deviation from slam_toolbox, whose sync and localization
modes add a node-level gate that needs translation, so a robot turning on the spot is never
re-localised there; the time gate ``minimum_time_interval`` and ``throttle_scans`` are left
to the node.)

Bad input never raises and never reaches the graph: a scan with a beam count that does not
match its angles or its announced count, too few valid ranges, non-finite angles, a stamp
older than the previous scan's, or a non-finite odometry pose is skipped with one warning.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_between, se2_compose, se2_inverse, wrap_angle
from eddiebot.maps import OccupancyMap
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.loop_closure import (
    LoopClosure,
    find_loop_candidates,
    near_linked_nodes,
    verify_loop,
)
from eddiebot.slam.occupancy import OccupancyGridBuilder
from eddiebot.slam.pose_graph import EdgeKind, PoseGraph
from eddiebot.slam.scan import Scan, check_scan, scan_points, valid_beams
from eddiebot.slam.scan_matcher import (
    MatcherParams,
    MatchResult,
    build_correlation_grid,
    match_scan,
    point_normals,
    pyramid_levels,
    refine_icp,
    score_pose,
)

__all__ = [
    "NodeRecord",
    "ProcessResult",
    "ProcessStatus",
    "SlamCore",
    "SlamWarning",
    "matcher_params",
]

FloatArray = npt.NDArray[np.float64]


class ProcessStatus(str, enum.Enum):
    """What happened to a scan."""

    ADDED = "added"
    """Became a new graph node (mapping, lifelong)."""
    LOCALIZED = "localized"
    """Matched against the loaded graph (localization)."""
    NOT_MOVED = "not_moved"
    """Skipped: the robot has not moved enough since the last processed scan."""
    SKIPPED = "skipped"
    """Skipped: bad input (see the warnings)."""


@dataclass(frozen=True)
class SlamWarning:
    """A warning raised while processing; ``kind`` is a stable machine-readable tag."""

    kind: str
    message: str
    stamp_ns: int = 0


@dataclass(frozen=True)
class ProcessResult:
    """Outcome of `SlamCore.process`.

    ``pose``: robot (base) pose in the map frame for this scan (None when skipped);
    ``map_to_odom``: correction to publish (map frame ← odom frame, x, y, theta).
    """

    status: ProcessStatus
    map_to_odom: FloatArray
    pose: FloatArray | None = None
    node_id: int | None = None
    response: float = 0.0
    covariance: FloatArray | None = None
    loop_closed: bool = False
    warnings: tuple[SlamWarning, ...] = ()

    @property
    def processed(self) -> bool:
        """True when the scan was used (a node was added or the robot was localised)."""
        return self.status in (ProcessStatus.ADDED, ProcessStatus.LOCALIZED)


@dataclass
class NodeRecord:
    """A graph node's scan and bookkeeping (its pose lives in the `PoseGraph`)."""

    scan: Scan
    points: FloatArray
    """Valid end points in the sensor frame (M, 2), m."""
    odom_pose: FloatArray
    """Robot pose in the odom frame when the scan was taken."""
    retired: bool = False


def matcher_params(
    config: SlamConfig, *, loop: bool = False, penalize: bool = True
) -> MatcherParams:
    """Matcher set-up for sequential matching (or the coarse loop search) from a config."""
    if loop:
        return MatcherParams(
            search_dimension=config.loop_search_space_dimension,
            resolution=config.loop_search_space_resolution,
            smear_deviation=config.loop_search_space_smear_deviation,
            coarse_angle_offset=config.coarse_search_angle_offset,
            coarse_angle_resolution=config.coarse_angle_resolution,
            fine_angle_step=config.fine_search_angle_offset,
            penalize=False,
            use_response_expansion=config.use_response_expansion,
        )
    return MatcherParams(
        search_dimension=config.correlation_search_space_dimension,
        resolution=config.correlation_search_space_resolution,
        smear_deviation=config.correlation_search_space_smear_deviation,
        coarse_angle_offset=config.coarse_search_angle_offset,
        coarse_angle_resolution=config.coarse_angle_resolution,
        fine_angle_step=config.fine_search_angle_offset,
        penalize=penalize,
        distance_variance_penalty=config.distance_variance_penalty,
        angle_variance_penalty=config.angle_variance_penalty,
        minimum_distance_penalty=config.minimum_distance_penalty,
        minimum_angle_penalty=config.minimum_angle_penalty,
        use_response_expansion=config.use_response_expansion,
    )


def _odometry_covariance(delta: FloatArray) -> FloatArray:
    d = math.hypot(float(delta[0]), float(delta[1]))
    sx = 0.02 + 0.1 * d
    sth = 0.02 + 0.1 * abs(float(delta[2])) + 0.05 * d
    return np.diag([sx * sx, sx * sx, sth * sth])


@dataclass
class _State:
    last_stamp_ns: int | None = None
    last_processed_odom: FloatArray | None = None
    last_pose: FloatArray | None = None
    map_to_odom: FloatArray = field(default_factory=lambda: np.zeros(3))
    running: deque[int] = field(default_factory=deque)


class SlamCore:
    """2D graph SLAM over laser scans and odometry (pure: no clock, no bus, no files).

    ``sensor_offset`` is the laser's pose in the base frame (x, y, theta).
    ``on_warning`` is called for every warning (e.g. the node logs them); warnings are also
    returned in each `ProcessResult`.
    """

    def __init__(
        self,
        config: SlamConfig | None = None,
        *,
        sensor_offset: npt.ArrayLike = (0.0, 0.0, 0.0),
        on_warning: Callable[[SlamWarning], None] | None = None,
    ) -> None:
        self.config = (config or SlamConfig()).validated()
        self.sensor_offset = np.asarray(sensor_offset, dtype=np.float64).reshape(3).copy()
        self.on_warning = on_warning
        self._seq_params = matcher_params(self.config)
        self._loop_coarse = matcher_params(self.config, loop=True)
        self._loop_fine = matcher_params(self.config, penalize=False)
        self._slip_params = dataclasses.replace(
            self._loop_coarse, search_dimension=self.config.slip_search_dimension
        )
        self.clear()

    # ------------------------------------------------------------------ state
    def clear(self) -> None:
        """Forget the graph, the scans and the map (keeps config and mode)."""
        self.graph = PoseGraph(
            optimizer=self.config.optimizer,
            robust_kernel=self.config.loop_robust_kernel,
            kernel_width=self.config.loop_robust_kernel_width,
        )
        self.nodes: list[NodeRecord] = []
        self.loop_closures: list[LoopClosure] = []
        self._state = _State()
        self._grid = OccupancyGridBuilder(
            self.config.resolution,
            self.config.max_laser_range,
            occupancy_threshold=self.config.occupancy_threshold,
            min_pass_through=self.config.min_pass_through,
        )
        self._rasterized: dict[int, FloatArray] = {}
        self._ref_cache: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._pos_cache: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._bary_local = np.zeros((0, 2))
        self._normal_cache: dict[int, FloatArray] = {}

    @property
    def mode(self) -> str:
        """``mapping``, ``localization`` or ``lifelong``."""
        return self.config.mode

    @property
    def map_to_odom(self) -> FloatArray:
        """Current map → odom correction (x, y, theta)."""
        return self._state.map_to_odom.copy()

    def node_poses(self) -> FloatArray:
        """Robot (base) poses of every node in the map frame (N, 3)."""
        return self.graph.poses

    def sensor_poses(self) -> FloatArray:
        """Sensor poses of every node in the map frame (N, 3)."""
        poses = self.graph.poses
        if poses.shape[0] == 0:
            return poses
        return se2_compose(poses, np.broadcast_to(self.sensor_offset, poses.shape))

    def active_mask(self) -> npt.NDArray[np.bool_]:
        """Nodes not retired (N,)."""
        return np.array([not n.retired for n in self.nodes], dtype=bool)

    def set_initial_pose(self, pose: npt.ArrayLike, odom_pose: npt.ArrayLike | None = None) -> None:
        """Localisation start: robot pose in the map frame (and its odom pose, default 0)."""
        p = np.asarray(pose, dtype=np.float64).reshape(3)
        o = np.zeros(3) if odom_pose is None else np.asarray(odom_pose, dtype=np.float64).reshape(3)
        self._state.last_pose = p.copy()
        self._state.last_processed_odom = None
        self._state.map_to_odom = se2_compose(p, se2_inverse(o))

    # ------------------------------------------------------------------ warnings
    def _warn(self, out: list[SlamWarning], kind: str, message: str, stamp_ns: int) -> None:
        w = SlamWarning(kind, message, stamp_ns)
        out.append(w)
        if self.on_warning is not None:
            self.on_warning(w)

    # ------------------------------------------------------------------ processing
    def process_ranges(
        self,
        ranges: npt.ArrayLike,
        angles: npt.ArrayLike,
        odom_pose: npt.ArrayLike,
        stamp_ns: int,
        *,
        range_min: float = 0.0,
        range_max: float = math.inf,
        expected_beams: int | None = None,
    ) -> ProcessResult:
        """`process` with the scan given as arrays."""
        scan = Scan(
            np.asarray(ranges, dtype=np.float64),
            np.asarray(angles, dtype=np.float64),
            float(range_min),
            float(range_max),
            int(stamp_ns),
        )
        return self.process(scan, odom_pose, expected_beams=expected_beams)

    def process(
        self,
        scan: Scan,
        odom_pose: npt.ArrayLike,
        *,
        expected_beams: int | None = None,
    ) -> ProcessResult:
        """Process one scan taken at robot pose ``odom_pose`` (odom frame, m/rad)."""
        warnings: list[SlamWarning] = []
        st = self._state
        stamp = int(scan.stamp_ns)
        odom = np.asarray(odom_pose, dtype=np.float64).reshape(-1)
        if odom.size != 3 or not np.all(np.isfinite(odom)):
            self._warn(
                warnings, "bad_odometry", f"non-finite or malformed odometry pose {odom}", stamp
            )
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        check = check_scan(
            scan,
            expected_beams=expected_beams,
            last_stamp_ns=st.last_stamp_ns,
            max_laser_range=self.config.max_laser_range,
        )
        if not check.ok:
            kind = "time_backwards" if "backwards" in check.reason else "bad_scan"
            self._warn(warnings, kind, f"scan at {stamp} ns skipped: {check.reason}", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        st.last_stamp_ns = stamp
        if not self._moved_enough(odom):
            return ProcessResult(
                ProcessStatus.NOT_MOVED, self.map_to_odom, warnings=tuple(warnings)
            )
        if self.mode == "localization":
            return self._localize(scan, odom, warnings)
        return self._map(scan, odom, warnings)

    def _moved_enough(self, odom: FloatArray) -> bool:
        last = self._state.last_processed_odom
        if last is None:
            return True
        a = se2_compose(last, self.sensor_offset)
        b = se2_compose(odom, self.sensor_offset)
        if abs(float(wrap_angle(b[2] - a[2]))) >= self.config.minimum_travel_heading:
            return True
        d2 = float((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2)
        return d2 >= self.config.minimum_travel_distance**2 - 1e-9

    def _prior(self, odom: FloatArray) -> FloatArray:
        st = self._state
        if st.last_pose is None or st.last_processed_odom is None:
            return se2_compose(st.map_to_odom, odom)
        return se2_compose(st.last_pose, se2_between(st.last_processed_odom, odom))

    # -- node points / reference maps
    def _world_points(self, idx: int) -> FloatArray:
        pose = self.graph.pose(idx)
        cached = self._ref_cache.get(idx)
        if cached is not None and np.array_equal(cached[0], pose):
            return cached[1]
        sensor = se2_compose(pose, self.sensor_offset)
        pts = self.nodes[idx].points
        c, s = math.cos(sensor[2]), math.sin(sensor[2])
        world = np.empty_like(pts)
        world[:, 0] = sensor[0] + c * pts[:, 0] - s * pts[:, 1]
        world[:, 1] = sensor[1] + s * pts[:, 0] + c * pts[:, 1]
        self._ref_cache[idx] = (pose, world)
        return world

    def _world_normals(self, idx: int) -> FloatArray:
        """Normals of a node's end points in the map frame (computed once, in its own frame)."""
        local = self._normal_cache.get(idx)
        if local is None:
            local = point_normals(self.nodes[idx].points)
            self._normal_cache[idx] = local
        th = float(se2_compose(self.graph.pose(idx), self.sensor_offset)[2])
        c, s = math.cos(th), math.sin(th)
        return np.stack(
            [c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]], axis=-1
        )

    def _reference_position(self, idx: int) -> FloatArray:
        pose = self.graph.pose(idx)
        cached = self._pos_cache.get(idx)
        if cached is not None and np.array_equal(cached[0], pose):
            return cached[1]
        if self.config.use_scan_barycenter and self.nodes[idx].points.shape[0]:
            pos = self._world_points(idx).mean(axis=0)
        else:
            pos = se2_compose(pose, self.sensor_offset)[:2]
        self._pos_cache[idx] = (pose, pos)
        return pos

    def _positions(self) -> FloatArray:
        """Reference positions of every node (N, 2), vectorised (barycentre or sensor)."""
        n = len(self.nodes)
        if n == 0:
            return np.zeros((0, 2))
        sensors = self.sensor_poses()
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
        self, nodes: list[int], points: FloatArray, prior_sensor: FloatArray, params: MatcherParams
    ) -> MatchResult:
        ref = np.concatenate([self._world_points(i) for i in nodes]) if nodes else np.zeros((0, 2))
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
        match = match_scan(points, grid, prior_sensor, params)
        if (
            self.config.use_icp_refinement
            and match.response > 0.0
            and params is not self._slip_params
        ):
            normals = np.concatenate([self._world_normals(i) for i in nodes])
            refined, share = refine_icp(points, ref, match.pose, reference_normals=normals)
            moved = float(np.hypot(*(refined[:2] - match.pose[:2])))
            turned = abs(float(wrap_angle(refined[2] - match.pose[2])))
            if (
                share >= 0.5
                and moved <= 2.0 * params.smear_deviation + params.resolution
                and turned <= params.coarse_angle_resolution
            ):
                match = MatchResult(refined, match.response, match.covariance)
        return match

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

    # -- mapping / lifelong
    def _map(self, scan: Scan, odom: FloatArray, warnings: list[SlamWarning]) -> ProcessResult:
        cfg = self.config
        st = self._state
        stamp = int(scan.stamp_ns)
        points = scan_points(scan, cfg.max_laser_range)
        prior = self._prior(odom)
        prior_sensor = se2_compose(prior, self.sensor_offset)
        response = 0.0
        covariance: FloatArray | None = None
        pose = prior
        running = [i for i in st.running if not self.nodes[i].retired]
        matched = False
        if cfg.use_scan_matching and running:
            match = self._match_against(running, points, prior_sensor, self._seq_params)
            match = self._recover_slip(running, points, prior_sensor, match, warnings, stamp)
            response, covariance = match.response, match.covariance
            if match.response >= cfg.link_match_minimum_response_fine:
                pose = se2_compose(match.pose, se2_inverse(self.sensor_offset))
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
        chain_from_odometry = st.last_processed_odom is not None
        idx = self.graph.add_node(pose)
        self.nodes.append(NodeRecord(scan, points, odom.copy()))
        if idx > 0 and not chain_from_odometry and not matched:
            # first scan after loading a session: the odom frames of the two runs are
            # unrelated, so only a weak link to where the session ended
            prev = len(self.nodes) - 2
            delta = se2_between(self.graph.pose(prev), pose)
            self.graph.add_edge(prev, idx, delta, np.diag([1.0, 1.0, 0.5]), kind=EdgeKind.ODOMETRY)
        elif idx > 0:
            prev = len(self.nodes) - 2
            prev_pose = self.graph.pose(prev)
            delta = se2_between(prev_pose, pose)
            if matched and covariance is not None:
                rot = np.eye(3)
                c, s = math.cos(prev_pose[2]), math.sin(prev_pose[2])
                rot[:2, :2] = [[c, s], [-s, c]]
                cov = rot @ covariance @ rot.T
                self.graph.add_edge(prev, idx, delta, cov, kind=EdgeKind.SCAN_MATCH)
            else:
                odo_delta = se2_between(self.nodes[prev].odom_pose, odom)
                self.graph.add_edge(
                    prev, idx, odo_delta, _odometry_covariance(odo_delta), kind=EdgeKind.ODOMETRY
                )
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
        loop_closed = False
        if cfg.do_loop_closing and idx > 0:
            loop_closed = self._try_close_loops(idx, points, warnings, stamp)
        self.graph.optimize(full=loop_closed)
        final = self.graph.pose(idx)
        if self.mode == "lifelong":
            self._retire_superseded(idx)
        st.last_pose = final
        st.last_processed_odom = odom.copy()
        st.map_to_odom = se2_compose(final, se2_inverse(odom))
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

    def _recover_slip(
        self,
        nodes: list[int],
        points: FloatArray,
        prior_sensor: FloatArray,
        match: MatchResult,
        warnings: list[SlamWarning],
        stamp: int,
    ) -> MatchResult:
        """Re-search a wider window when the match is weak or pinned to the window's edge.

        A wheel slip larger than the sequential window (±0.25 m by default) otherwise yields
        a wrong, border-hugging match; eddiebot's addition, off when
        ``slip_search_dimension`` is 0.
        """
        cfg = self.config
        if cfg.slip_search_dimension <= cfg.correlation_search_space_dimension:
            return match
        half = 0.5 * cfg.correlation_search_space_dimension
        offset = match.pose[:2] - prior_sensor[:2]
        at_edge = bool(
            np.any(np.abs(offset) >= half - 2.0 * cfg.correlation_search_space_resolution)
        )
        if match.response >= cfg.loop_match_minimum_response_fine and not at_edge:
            return match
        wide = self._match_against(nodes, points, prior_sensor, self._slip_params)
        fine = self._match_against(nodes, points, wide.pose, self._loop_fine)
        if fine.response > match.response + 0.05:
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

    def _try_close_loops(
        self, idx: int, points: FloatArray, warnings: list[SlamWarning], stamp: int
    ) -> bool:
        cfg = self.config
        closed = False
        for _ in range(2):
            positions = self._positions()
            linked = near_linked_nodes(
                idx, positions, self.graph.neighbours, cfg.loop_search_maximum_distance
            )
            chains = find_loop_candidates(
                idx,
                positions,
                linked,
                max_distance=cfg.loop_search_maximum_distance,
                min_chain_size=cfg.loop_match_minimum_chain_size,
                active=self.active_mask(),
            )
            found: LoopClosure | None = None
            sensor = se2_compose(self.graph.pose(idx), self.sensor_offset)
            for chain in chains:
                ref = np.concatenate([self._world_points(i) for i in chain])
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
                )
                if found is not None:
                    break
            if found is None:
                return closed
            base = se2_compose(found.match.pose, se2_inverse(self.sensor_offset))
            cand_pose = self.graph.pose(found.candidate)
            delta = se2_between(cand_pose, base)
            rot = np.eye(3)
            c, s = math.cos(cand_pose[2]), math.sin(cand_pose[2])
            rot[:2, :2] = [[c, s], [-s, c]]
            cov = rot @ found.match.covariance @ rot.T
            self.graph.add_edge(found.candidate, idx, delta, cov, kind=EdgeKind.LOOP, robust=True)
            self.loop_closures.append(found)
            self.graph.optimize(full=True)
            closed = True
        return closed

    def _retire_superseded(self, idx: int) -> None:
        cfg = self.config
        new_pts = self._world_points(idx)
        if new_pts.shape[0] == 0:
            return
        here = self._reference_position(idx)
        recent = set(self._state.running)
        lo, hi = new_pts.min(axis=0) - 0.5, new_pts.max(axis=0) + 0.5
        grid = build_correlation_grid(
            new_pts, (lo[0], lo[1], hi[0], hi[1]), cfg.resolution, cfg.resolution, 1
        )
        for j, node in enumerate(self.nodes[:idx]):
            if node.retired or j in recent or node.points.shape[0] == 0:
                continue
            if np.hypot(*(self._reference_position(j) - here)) > cfg.minimum_travel_distance:
                continue
            sensor = se2_compose(self.graph.pose(j), self.sensor_offset)
            if score_pose(node.points, sensor, grid) >= cfg.lifelong_node_overlap:
                node.retired = True

    # -- localization
    def _localize(self, scan: Scan, odom: FloatArray, warnings: list[SlamWarning]) -> ProcessResult:
        cfg = self.config
        st = self._state
        stamp = int(scan.stamp_ns)
        if not self.nodes:
            self._warn(warnings, "no_map", "localization mode without a loaded session", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        if st.last_pose is None:
            st.last_pose = self.graph.pose(0)
            st.map_to_odom = se2_compose(st.last_pose, se2_inverse(odom))
        points = scan_points(scan, cfg.max_laser_range)
        prior = self._prior(odom)
        prior_sensor = se2_compose(prior, self.sensor_offset)
        positions = self._positions()
        active = np.flatnonzero(self.active_mask())
        d = np.hypot(positions[active, 0] - prior_sensor[0], positions[active, 1] - prior_sensor[1])
        near = active[d <= cfg.scan_buffer_maximum_scan_distance]
        near = near[
            np.argsort(
                np.hypot(positions[near, 0] - prior_sensor[0], positions[near, 1] - prior_sensor[1])
            )
        ]
        ref_nodes = [int(i) for i in near[: 2 * cfg.scan_buffer_size]]
        pose = prior
        response = 0.0
        covariance = None
        if ref_nodes:
            match = self._match_against(ref_nodes, points, prior_sensor, self._seq_params)
            if match.response < cfg.loop_match_minimum_response_fine:
                wide = self._match_against(ref_nodes, points, prior_sensor, self._loop_coarse)
                if wide.response > match.response:
                    match = self._match_against(ref_nodes, points, wide.pose, self._loop_fine)
            response, covariance = match.response, match.covariance
            if match.response >= cfg.link_match_minimum_response_fine:
                pose = se2_compose(match.pose, se2_inverse(self.sensor_offset))
                self._check_covariance(match, warnings, stamp)
            else:
                self._warn(
                    warnings,
                    "weak_match",
                    f"localization match response {match.response:.2f}; using odometry",
                    stamp,
                )
        else:
            self._warn(
                warnings, "off_map", "no map nodes near the predicted pose; using odometry", stamp
            )
        st.last_pose = pose.copy()
        st.last_processed_odom = odom.copy()
        st.map_to_odom = se2_compose(pose, se2_inverse(odom))
        return ProcessResult(
            ProcessStatus.LOCALIZED,
            self.map_to_odom,
            pose=pose.copy(),
            response=response,
            covariance=covariance,
            warnings=tuple(warnings),
        )

    # ------------------------------------------------------------------ map
    def update_map(self) -> bool:
        """Bring the occupancy grid up to date; only new, moved or retired nodes are re-cast."""
        changed = False
        sensors = self.sensor_poses()
        for i, node in enumerate(self.nodes):
            old = self._rasterized.get(i)
            if node.retired:
                if old is not None:
                    self._cast(i, old, -1)
                    del self._rasterized[i]
                    changed = True
                continue
            new = sensors[i]
            if old is not None:
                if (
                    abs(new[0] - old[0]) < 1e-4
                    and abs(new[1] - old[1]) < 1e-4
                    and abs(wrap_angle(new[2] - old[2])) < 1e-5
                ):
                    continue
                self._cast(i, old, -1)
            self._cast(i, new, 1)
            self._rasterized[i] = new.copy()
            changed = True
        return changed

    def _cast(self, idx: int, sensor_pose: FloatArray, weight: int) -> None:
        scan = self.nodes[idx].scan
        self._grid.add_scan(
            sensor_pose,
            scan.ranges,
            scan.angles,
            range_min=scan.range_min,
            range_max=scan.range_max,
            weight=weight,
        )

    def occupancy_map(self) -> OccupancyMap:
        """The current occupancy grid (map frame), updated incrementally first."""
        self.update_map()
        return self._grid.to_map(frame_id=self.config.map_frame)

    def rebuild_map(self) -> OccupancyMap:
        """Re-cast every active node from scratch (e.g. after a resolution change)."""
        self._grid.clear()
        self._rasterized.clear()
        return self.occupancy_map()

    # ------------------------------------------------------------------ restore
    def _restore(
        self,
        nodes: list[NodeRecord],
        poses: FloatArray,
        edges: list[tuple[int, int, FloatArray, FloatArray, EdgeKind, bool]],
    ) -> None:
        """Install a loaded graph (used by `eddiebot.slam.session`)."""
        self.clear()
        self.nodes = nodes
        for p in poses:
            self.graph.add_node(p)
        for i, j, z, cov, kind, robust in edges:
            self.graph.add_edge(i, j, z, cov, kind=kind, robust=robust)
        # the stored estimate is kept as is; iSAM2 takes the whole graph at the next update
        self.graph.set_poses(poses)
        if nodes and self.mode in ("mapping", "lifelong"):
            last = len(nodes) - 1
            st = self._state
            st.last_pose = self.graph.pose(last)
            st.last_processed_odom = None
            # the odom frame of a new run is unrelated to the saved one: assume the robot
            # starts where the session ended until told otherwise (set_initial_pose)
            st.map_to_odom = st.last_pose.copy()
            st.running = deque(
                i for i in range(max(0, last - self.config.scan_buffer_size + 1), last + 1)
            )


def valid_point_count(scan: Scan, max_laser_range: float) -> int:
    """Number of usable beams in a scan."""
    return int(np.count_nonzero(valid_beams(scan, max_laser_range)))
