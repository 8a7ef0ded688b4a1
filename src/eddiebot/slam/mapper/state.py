"""The mapper's state: configuration, nodes, graph, odometry chain and map; the input checks,
warnings, map rendering and session restore every mode shares."""


from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_compose, se2_inverse, wrap_angle
from eddiebot.maps import OccupancyMap
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.loop_closure import (
    LoopClosure,
)
from eddiebot.slam.mapper.lifelong import LifelongParams
from eddiebot.slam.mapper.measurement import matcher_params
from eddiebot.slam.mapper.results import FloatArray, NodeRecord, SlamWarning
from eddiebot.slam.mapper.se2_rows import _between1, _compose1, _inverse1, _wrap1
from eddiebot.slam.occupancy import OccupancyGridBuilder
from eddiebot.slam.pose_graph import EdgeKind, PoseGraph
from eddiebot.slam.scan import Scan


@dataclass
class _State:
    last_stamp_ns: int | None = None
    last_processed_odom: FloatArray | None = None
    last_pose: FloatArray | None = None
    map_to_odom: FloatArray = field(default_factory=lambda: np.zeros(3))
    running: deque[int] = field(default_factory=deque)
    chain_start: int = 0
    """First node of the current odometry chain (odometry poses before it are in another frame)."""
    last_seen_odom: FloatArray | None = None
    """Odometry pose of the last scan with a valid odometry pose and stamp, also one skipped
    for its ranges (for `max_odometry_jump`)."""
    pending_start: FloatArray | None = None
    """Robot pose (map frame) at which the next scan starts (`start_at`)."""
    scan_shape: tuple[int, float, float] | None = None
    """Beam count and first / last beam angle of the first scan; later scans must match."""



class MapperState:
    """State shared by `SlamCore`'s modes (see `SlamCore` for the arguments)."""


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
        # a sequential match below this is re-searched wider (slip, lost localization)
        self._weak_response = (
            self.config.slip_search_minimum_response
            or self.config.loop_match_minimum_response_fine
        )
        self.clear()

    def clear(self) -> None:
        """Forget the graph, the scans and the map (keeps config and mode)."""
        self.graph = PoseGraph(
            optimizer=self.config.optimizer,
            robust_kernel=self.config.loop_robust_kernel,
            kernel_width=self.config.loop_robust_kernel_width,
            factorization=self.config.isam2_factorization,
            relinearize_skip=self.config.isam2_relinearize_skip,
            recent_last=self.config.isam2_recent_nodes_last,
            wildfire_threshold=self.config.isam2_wildfire_threshold,
        )
        self.nodes: list[NodeRecord] = []
        self.loop_closures: list[LoopClosure] = []
        self.near_chain_links = 0
        """Edges `_link_near_chains` added (Karto's near-chain links)."""
        self._state = _State()
        self._grid = OccupancyGridBuilder(
            self.config.resolution,
            self.config.map_max_laser_range or self.config.max_laser_range,
            occupancy_threshold=self.config.occupancy_threshold,
            min_pass_through=self.config.min_pass_through,
        )
        self._rasterized: dict[int, FloatArray] = {}
        self._ref_cache: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._pos_cache: dict[int, tuple[FloatArray, FloatArray]] = {}
        self._bary_local = np.zeros((0, 2))
        self._normal_cache: dict[int, FloatArray] = {}
        self._active = np.zeros(0, dtype=bool)
        self._lifelong_params = LifelongParams.from_config(self.config)
        self.lifelong_scores: dict[int, float] = {}
        """Lifelong scores of the nodes re-scored so far (the rest have 1)."""
        self._depreciated: list[int] = []  # retired, waiting to be marginalised
        self.removed_nodes = 0
        """Nodes lifelong mode marginalised out of the pose graph."""
        self.odometry_jumps = 0
        """Odometry jumps beyond `max_odometry_jump` / `max_odometry_jump_heading` re-anchored."""
        self.nonfinite_range_scans = 0
        """Scans that held NaN or ±Inf ranges (those beams are ignored)."""


    @property
    def mode(self) -> str:
        """``mapping``, ``localization`` or ``lifelong``."""
        return self.config.mode


    @property
    def map_to_odom(self) -> FloatArray:
        """Current map → odom correction (x, y, theta)."""
        return self._state.map_to_odom.copy()


    def node_poses(self) -> FloatArray:
        """Robot (base) poses of every node in the map frame (N, 3), optimised."""
        self.graph.optimize()
        return self.graph.poses


    def sensor_poses(self) -> FloatArray:
        """Sensor poses of every node in the map frame (N, 3), optimised as `node_poses`."""
        self.graph.optimize()
        poses = self.graph.poses
        if poses.shape[0] == 0:
            return poses
        return se2_compose(poses, np.broadcast_to(self.sensor_offset, poses.shape))


    def active_mask(self) -> npt.NDArray[np.bool_]:
        """Nodes not retired (N,)."""
        return np.array([not n.retired for n in self.nodes], dtype=bool)


    def _active_nodes(self) -> npt.NDArray[np.bool_]:
        """`active_mask` kept across scans: extended by the nodes added since, cleared where
        `_retire_superseded` retires one (the only place a node of the graph retires)."""
        have = self._active.shape[0]
        if have != len(self.nodes):
            extra = np.array([not n.retired for n in self.nodes[have:]], dtype=bool)
            self._active = np.concatenate([self._active[: len(self.nodes)], extra])
        return self._active


    def set_initial_pose(self, pose: npt.ArrayLike, odom_pose: npt.ArrayLike | None = None) -> None:
        """Localisation start: robot pose in the map frame (and its odom pose, default 0)."""
        p = np.asarray(pose, dtype=np.float64).reshape(3)
        o = np.zeros(3) if odom_pose is None else np.asarray(odom_pose, dtype=np.float64).reshape(3)
        self._state.last_pose = p.copy()
        self._state.last_processed_odom = None
        self._state.map_to_odom = se2_compose(p, se2_inverse(o))


    def forget_odometry(self) -> None:
        """Do not compare the next scan's odometry with the last one's (after a pause, when
        the robot may have moved any distance)."""
        self._state.last_seen_odom = None


    def _reanchor(
        self, odom: FloatArray, step: FloatArray, warnings: list[SlamWarning], stamp: int
    ) -> None:
        """Refuse an odometry jump: the robot is taken to be where it was before it, and the
        scan starts a new chain (linked to the graph by scan matching, see `_map`)."""
        st = self._state
        before = st.last_seen_odom
        assert before is not None
        if st.last_pose is not None and st.last_processed_odom is not None:
            where = _compose1(st.last_pose, _between1(st.last_processed_odom, before))
        else:
            where = _compose1(st.map_to_odom, before)
        st.map_to_odom = _compose1(where, _inverse1(odom))
        st.last_pose = where
        st.last_processed_odom = None
        self.odometry_jumps += 1
        cfg = self.config
        self._warn(
            warnings,
            "odometry_jump",
            f"odometry jumped {math.hypot(step[0], step[1]):.2f} m, "
            f"{abs(_wrap1(float(step[2]))):.2f} rad before the scan at {stamp * 1e-9:.3f} s "
            f"(max_odometry_jump {cfg.max_odometry_jump} m, max_odometry_jump_heading "
            f"{cfg.max_odometry_jump_heading} rad): not integrated; the odometry is re-anchored "
            "where the robot was and the scan starts a new chain, linked by scan matching",
            stamp,
        )


    def _follow_odometry(self, odom: FloatArray, warnings: list[SlamWarning], stamp: int) -> None:
        """Take a scan's odometry pose as the latest seen: a step beyond the jump limits
        since the one before is refused (`_reanchor`). Also for a scan skipped for its
        ranges (too few valid beams, another shape): its odometry is as good, and the
        robot driving on past a run of such scans is motion, not a jump. Before a start
        pose is applied (``pending_start``) there is nothing to compare with."""
        if self._state.pending_start is None:
            jump = self._odometry_jumped(odom)
            if jump is not None:
                self._reanchor(odom, jump, warnings, stamp)
            self._state.last_seen_odom = odom.copy()

    def _odometry_jumped(self, odom: FloatArray) -> FloatArray | None:
        """The odometry step since the last scan when it is a jump, else None."""
        last = self._state.last_seen_odom
        if last is None:
            return None
        cfg = self.config
        step = _between1(last, odom)
        far = cfg.max_odometry_jump > 0 and math.hypot(step[0], step[1]) > cfg.max_odometry_jump
        turned = (
            cfg.max_odometry_jump_heading > 0
            and abs(_wrap1(float(step[2]))) > cfg.max_odometry_jump_heading
        )
        return step if far or turned else None


    def _scan_shape_error(self, scan: Scan) -> str:
        """Why a scan's beams differ from the first scan's (empty when they do not)."""
        n = scan.ranges.size
        shape = (n, float(scan.angles[0]), float(scan.angles[-1])) if n else (0, 0.0, 0.0)
        first = self._state.scan_shape
        if first is None:
            self._state.scan_shape = shape
            return ""
        if shape[0] == first[0] and abs(shape[1] - first[1]) <= 1e-6 and abs(shape[2] - first[2]) <= 1e-6:
            return ""
        return (
            f"{shape[0]} beams over [{shape[1]:.4f}, {shape[2]:.4f}] rad; the first scan had "
            f"{first[0]} over [{first[1]:.4f}, {first[2]:.4f}] rad"
        )

    def _warn(self, out: list[SlamWarning], kind: str, message: str, stamp_ns: int) -> None:
        w = SlamWarning(kind, message, stamp_ns)
        out.append(w)
        if self.on_warning is not None:
            self.on_warning(w)


    def _moved_enough(self, odom: FloatArray) -> bool:
        last = self._state.last_processed_odom
        if last is None:
            return True
        a = _compose1(last, self.sensor_offset)
        b = _compose1(odom, self.sensor_offset)
        if abs(float(_wrap1(b[2] - a[2]))) >= self.config.minimum_travel_heading:
            return True
        d2 = float((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2)
        return d2 >= self.config.minimum_travel_distance**2 - 1e-9


    def _prior(self, odom: FloatArray) -> FloatArray:
        st = self._state
        if st.last_pose is None or st.last_processed_odom is None:
            return _compose1(st.map_to_odom, odom)
        return _compose1(st.last_pose, _between1(st.last_processed_odom, odom))


    def _add_odometry_span(self, j: int, idx: int) -> None:
        """Odometry alone from node ``j`` to node ``idx`` of one chain (`odometry_span_nodes`)."""
        cfg = self.config
        odo = [self.nodes[m].odom_pose for m in range(j, idx + 1)]
        dist = sum(math.hypot(float(b[0] - a[0]), float(b[1] - a[1])) for a, b in zip(odo, odo[1:]))
        turn = sum(abs(_wrap1(float(b[2] - a[2]))) for a, b in zip(odo, odo[1:]))
        sth = math.hypot(math.sqrt(2.0) * cfg.odometry_heading_quantization,
                         cfg.odometry_rotation_noise * turn
                         + cfg.odometry_rotation_noise_per_meter * dist)
        sx = cfg.odometry_translation_sigma + cfg.odometry_translation_noise * dist
        self.graph.add_edge(j, idx, _between1(odo[0], odo[-1]), np.diag([sx * sx, sx * sx, sth * sth]),
                            kind=EdgeKind.ODOMETRY)

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

    def _restore(
        self,
        nodes: list[NodeRecord],
        poses: FloatArray,
        edges: list[tuple[int, int, FloatArray, FloatArray, EdgeKind, bool]],
        rejected: list[int] | None = None,
    ) -> None:
        """Install a loaded graph (used by `eddiebot.slam.session`); ``rejected``: the edges
        the stored estimate was solved without (None: gate every robust edge again)."""
        self.clear()
        self.nodes = nodes
        for p in poses:
            self.graph.add_node(p)
        for i, j, z, cov, kind, robust in edges:
            self.graph.add_edge(i, j, z, cov, kind=kind, robust=robust)
        # the stored estimate is kept as is; iSAM2 takes the whole graph at the next update
        self.graph.set_poses(poses, rejected=rejected)
        if nodes:
            self._scan_shape_error(nodes[0].scan)  # later scans must have the session's beams
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
