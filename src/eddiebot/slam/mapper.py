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
older than the previous scan's, a beam count or angle range other than the first scan's (as
Karto's laser check), or a non-finite odometry pose is skipped with one warning. NaN and ±Inf
ranges are ignored beam by beam (one warning, then counted in ``nonfinite_range_scans``). An
odometry step between consecutive scans beyond ``max_odometry_jump`` (m) or
``max_odometry_jump_heading`` (rad) is not integrated: the robot is taken to be where it was,
the odometry is re-anchored there, and the scan starts a new chain that scan matching links to
the nearest recent node (a weak link where the match fails); ``odometry_jumps`` counts them.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from numba import njit

from eddiebot.geometry import se2_compose, se2_inverse, wrap_angle
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
    refine_icp_with_covariance,
    score_pose,
)

__all__ = [
    "NodeRecord",
    "ProcessResult",
    "ProcessStatus",
    "SlamCore",
    "SlamWarning",
    "matcher_params",
    "unbiased_points",
    "warm_up",
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
            fine_search_climb=config.match_fine_search_climb,
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
        coarse_heading_variance=config.match_coarse_heading_variance,
        fine_search_climb=config.match_fine_search_climb,
    )


_PI = np.pi
_TWO_PI = 2.0 * np.pi
_NO_HEADING_VARIANCE = 1.0e4
"""Odometry heading variance (rad²) standing for no heading information in a fused step."""


def _wrap1(a: float) -> float:
    """`wrap_angle` of one angle: the same ufuncs on a scalar (bit-identical, no array setup)."""
    w: float = np.mod(a + _PI, _TWO_PI) - _PI
    return _PI if w == -_PI else w


def _compose1(a: FloatArray, b: FloatArray) -> FloatArray:
    """`se2_compose` of two single poses (3,), element by element with the same ufuncs and
    operation order, so bit-identical; about a fifth of its cost on the per-scan path."""
    a0, a1, a2 = a[0], a[1], a[2]
    b0, b1 = b[0], b[1]
    c, s = np.cos(a2), np.sin(a2)
    return np.array([a0 + c * b0 - s * b1, a1 + s * b0 + c * b1, _wrap1(a2 + b[2])])


def _inverse1(a: FloatArray) -> FloatArray:
    """`se2_inverse` of one pose (3,), bit-identical (see `_compose1`)."""
    a0, a1, a2 = a[0], a[1], a[2]
    c, s = np.cos(a2), np.sin(a2)
    return np.array([-c * a0 - s * a1, s * a0 - c * a1, _wrap1(-a2)])


def _between1(a: FloatArray, b: FloatArray) -> FloatArray:
    """`se2_between` of two single poses, bit-identical (see `_compose1`)."""
    return _compose1(_inverse1(a), b)


def _compose_rows(a: FloatArray, b: FloatArray) -> FloatArray:
    """`_compose1` of each row of ``a`` (K, 3) with one pose ``b`` (3,): the same ufuncs in
    the same order, element by element (each row bit-identical to `_compose1`)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1 = b[0], b[1]
    c, s = np.cos(a2), np.sin(a2)
    out = np.empty_like(a)
    out[:, 0] = a0 + c * b0 - s * b1
    out[:, 1] = a1 + s * b0 + c * b1
    w = np.mod(a2 + b[2] + _PI, _TWO_PI) - _PI
    out[:, 2] = np.where(w == -_PI, _PI, w)
    return out


@njit(cache=True)
def _place_rows(
    local: FloatArray,
    counts: npt.NDArray[np.int64],
    tx: FloatArray,
    ty: FloatArray,
    c: FloatArray,
    s: FloatArray,
    translate: bool,
    out: FloatArray,
) -> None:
    """Rows of ``local`` (run j: ``counts[j]`` rows) rotated by (c[j], s[j]) and, with
    ``translate``, moved by (tx[j], ty[j]): ``tx + c·x − s·y``, ``ty + s·x + c·y`` (without:
    ``c·x − s·y``, ``s·x + c·y``), each operation in the order numpy evaluates those
    expressions (no fused multiply-add), so the values are numpy's bit for bit."""
    k = 0
    for j in range(counts.size):
        cj, sj, xj, yj = c[j], s[j], tx[j], ty[j]
        for _ in range(counts[j]):
            x = local[k, 0]
            y = local[k, 1]
            if translate:
                out[k, 0] = xj + cj * x - sj * y
                out[k, 1] = yj + sj * x + cj * y
            else:
                out[k, 0] = cj * x - sj * y
                out[k, 1] = sj * x + cj * y
            k += 1


def _odometry_covariance(delta: FloatArray, config: SlamConfig | None = None) -> FloatArray:
    """Covariance (x, y, theta) of an odometry increment under the config's noise model."""
    cfg = config or SlamConfig()
    d = math.hypot(float(delta[0]), float(delta[1]))
    sx = cfg.odometry_translation_sigma + cfg.odometry_translation_noise * d
    sth = (
        cfg.odometry_rotation_sigma
        + cfg.odometry_rotation_noise * abs(float(delta[2]))
        + cfg.odometry_rotation_noise_per_meter * d
    )
    return np.diag([sx * sx, sx * sx, sth * sth])


def _rotate_covariance(cov: FloatArray, theta: float) -> FloatArray:
    """Express a map-frame (x, y, theta) covariance in a frame turned by ``theta``."""
    rot = np.eye(3)
    c, s = math.cos(theta), math.sin(theta)
    rot[:2, :2] = [[c, s], [-s, c]]
    return np.asarray(rot @ cov @ rot.T)


def constrained_information(
    covariance: FloatArray, max_variance: float
) -> tuple[FloatArray, int]:
    """Information matrix of a match keeping only its well-observed position directions.

    The position block's eigen-directions with a variance above ``max_variance`` (m²) carry
    no information (a corridor match says nothing about the position along the corridor; the
    correlative search's window only bounds that variance). Returns the (3, 3) information
    and the number of position directions dropped (0, 1 or 2).
    """
    cov = 0.5 * (covariance + covariance.T)
    w, v = np.linalg.eigh(cov[:2, :2])
    w = np.maximum(w, 1e-12)
    keep = w <= max_variance
    info = np.zeros((3, 3))
    # position block from the kept directions; the heading kept as Karto reports it (no
    # cross terms: the search estimates the two separately)
    info[:2, :2] = (v[:, keep] / w[keep]) @ v[:, keep].T
    info[2, 2] = 1.0 / max(float(cov[2, 2]), 1e-12)
    return info, int(np.count_nonzero(~keep))


def corrected_scan(scan: Scan, bias_quadratic: float) -> Scan:
    """``scan`` with each finite range r in [range_min, range_max] read as
    ``r + bias_quadratic · r²`` (capped at range_max): a quadratic range bias removed."""
    r = np.array(scan.ranges, dtype=np.float64)
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
    r[ok] = np.minimum(r[ok] + bias_quadratic * r[ok] ** 2, scan.range_max)
    return dataclasses.replace(scan, ranges=r)


def unbiased_points(points: FloatArray, bias_quadratic: float) -> FloatArray:
    """Sensor-frame points (M, 2) each moved away from the sensor to range ``r + k · r²``
    (``k = bias_quadratic``, 1/m): a quadratic range bias removed from a scan's end points."""
    r = np.hypot(points[:, 0], points[:, 1])
    return np.asarray(points * (1.0 + bias_quadratic * r)[:, None], dtype=np.float64)


def scan_position_covariance(
    points: FloatArray,
    normals: FloatArray,
    range_sigma: float,
    range_sigma_quadratic: float = 0.0,
) -> FloatArray:
    """Position covariance (2, 2; the points' frame, m²) a scan's geometry allows a match.

    Degeneracy analysis of the point-to-line fit (Zhang, Kaess and Singh 2016, "On degeneracy
    of optimization-based state estimation problems"): the position block of its Hessian,
    ``H = Σ n nᵀ / σ²`` over the points with a normal (``σ = range_sigma +
    range_sigma_quadratic · r²``, each point's range error at range r), has eigen-directions
    ``d`` with information ``λ_d``. The variance along ``d`` is ``(Σ (n·d)² + 1) / λ_d``:
    the information-weighted mean range variance of the points whose normals pin ``d`` — an
    error they share, such as a depth camera's range bias, does not average out over many
    points — plus one point's worth of random error. Along a direction no line observes (a
    corridor's length) λ_d is near zero and the variance unbounded; along one only far points
    pin (a corridor's end wall seen from metres away) it is their range variance.
    """
    ok = np.isfinite(normals[:, 0])
    n = normals[ok]
    if n.shape[0] == 0:
        return np.eye(2) * 1.0e6
    r2 = np.einsum("ij,ij->i", points[ok], points[ok])
    sigma = range_sigma + range_sigma_quadratic * r2
    w = 1.0 / np.maximum(sigma * sigma, 1e-12)
    h = (n * w[:, None]).T @ n
    lam, v = np.linalg.eigh(0.5 * (h + h.T))
    count = np.sum((n @ v) ** 2, axis=0)
    var = np.minimum((count + 1.0) / np.maximum(lam, 1e-12), 1.0e6)
    return np.asarray((v * var) @ v.T)


def constrained_covariance(
    covariance: FloatArray, max_variance: float, unobserved_variance: float = 1.0e4
) -> FloatArray:
    """A match covariance with its poorly observed position directions made uninformative.

    The position directions `constrained_information` drops get ``unobserved_variance`` (m²;
    an edge with no information there, still invertible for the optimiser); the others and
    the heading are kept as `constrained_information` keeps them.
    """
    info, dropped = constrained_information(covariance, max_variance)
    if dropped == 0:
        return np.asarray(covariance, dtype=np.float64)
    cov = 0.5 * (covariance + covariance.T)
    w, v = np.linalg.eigh(cov[:2, :2])
    drop = v[:, np.maximum(w, 1e-12) > max_variance]
    info[:2, :2] += (drop @ drop.T) / unobserved_variance
    out = np.linalg.inv(info)
    return np.asarray(0.5 * (out + out.T))


def fuse_increments(
    z_odom: FloatArray, cov_odom: FloatArray, z_match: FloatArray, info_match: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Information-weighted mean of two measurements of one SE(2) increment (x, y, theta).

    Linearised about the odometry increment; returns the fused increment and its covariance.
    """
    info_odom = np.linalg.inv(cov_odom)
    dz = np.asarray(z_match, dtype=np.float64) - z_odom
    dz[2] = float(_wrap1(dz[2]))
    info = info_odom + info_match
    cov = np.linalg.inv(info)
    fused = np.asarray(z_odom, dtype=np.float64) + cov @ (info_match @ dz)
    fused[2] = float(_wrap1(fused[2]))
    return fused, 0.5 * (cov + cov.T)


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
    """Odometry pose of the last scan that passed the input checks (for `max_odometry_jump`)."""
    pending_start: FloatArray | None = None
    """Robot pose (map frame) at which the next scan starts (`start_at`)."""
    scan_shape: tuple[int, float, float] | None = None
    """Beam count and first / last beam angle of the first scan; later scans must match."""


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
        # a sequential match below this is re-searched wider (slip, lost localization)
        self._weak_response = (
            self.config.slip_search_minimum_response
            or self.config.loop_match_minimum_response_fine
        )
        self.clear()

    # ------------------------------------------------------------------ state
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
        self._span_queue: list[tuple[int, int]] = []
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

    def _flush_spans(self) -> None:
        """Add the span edges `odometry_span_batch` holds back."""
        queue, self._span_queue = self._span_queue, []
        for j, idx in queue:
            self._add_odometry_span(j, idx)

    def node_poses(self) -> FloatArray:
        """Robot (base) poses of every node in the map frame (N, 3), optimised (span edges held
        by `odometry_span_batch` are folded in first)."""
        self._flush_spans()
        self.graph.optimize()
        return self.graph.poses

    def sensor_poses(self) -> FloatArray:
        """Sensor poses of every node in the map frame (N, 3), optimised as `node_poses`."""
        self._flush_spans()
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
        shape_error = self._scan_shape_error(scan)
        if shape_error:
            self._warn(
                warnings, "scan_shape", f"scan at {stamp * 1e-9:.3f} s skipped: {shape_error}", stamp
            )
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        nan = int(np.count_nonzero(np.isnan(scan.ranges)))
        inf = int(np.count_nonzero(np.isinf(scan.ranges)))
        if nan or inf:
            self.nonfinite_range_scans += 1
            if self.nonfinite_range_scans == 1:
                self._warn(
                    warnings,
                    "nonfinite_ranges",
                    f"scan at {stamp * 1e-9:.3f} s has {nan} NaN and {inf} ±Inf ranges of "
                    f"{scan.ranges.size}: those beams are ignored (counted in "
                    "nonfinite_range_scans; not repeated)",
                    stamp,
                )
        st.last_stamp_ns = stamp
        if st.pending_start is not None:
            st.map_to_odom = _compose1(st.pending_start, _inverse1(odom))
            st.pending_start = None
        else:
            jump = self._odometry_jumped(odom)
            if jump is not None:
                self._reanchor(odom, jump, warnings, stamp)
        st.last_seen_odom = odom.copy()
        if self.config.scan_range_bias_quadratic > 0.0:
            scan = corrected_scan(scan, self.config.scan_range_bias_quadratic)
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

    def _unbiased_world_points(self, idx: int, pose: FloatArray, bias: float) -> FloatArray:
        """Node ``idx``'s end points with the range bias removed (`unbiased_points`), in the
        map frame at ``pose`` (loop-closure matching only: not cached)."""
        sensor = _compose1(pose, self.sensor_offset)
        pts = unbiased_points(self.nodes[idx].points, bias)
        c, s = math.cos(sensor[2]), math.sin(sensor[2])
        world = np.empty_like(pts)
        world[:, 0] = sensor[0] + c * pts[:, 0] - s * pts[:, 1]
        world[:, 1] = sensor[1] + s * pts[:, 0] + c * pts[:, 1]
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
    ) -> MatchResult:
        # ``reject_below``: the caller discards a match whose response is below it, so such a
        # match stops once its response is known (`match_scan`) and is not polished
        # one pass over the optimiser's estimate (the same values as one look-up per node,
        # which the reference points and normals below would otherwise make ~40 times)
        poses = self.graph.poses
        polish = self.config.use_icp_refinement and params is not self._slip_params
        normals: FloatArray | None = None
        if nodes:
            ref, normals = self._reference(nodes, poses, normals=polish)
        else:
            ref = np.zeros((0, 2))
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
        """Point-to-line ICP from a correlative match; its fit's covariance when configured."""
        refined, share, icp_cov = refine_icp_with_covariance(
            points, ref, match.pose, reference_normals=normals
        )
        moved = float(np.hypot(*(refined[:2] - match.pose[:2])))
        turned = abs(float(wrap_angle(refined[2] - match.pose[2])))
        if not (
            share >= 0.5
            and moved <= 2.0 * params.smear_deviation + params.resolution
            and turned <= params.coarse_angle_resolution
        ):
            return match
        cov = match.covariance
        if self.config.match_covariance == "icp" and icp_cov is not None:
            cov = self._icp_covariance(icp_cov, match.covariance)
        return MatchResult(refined, match.response, cov)

    def _icp_covariance(self, icp_cov: FloatArray, response_cov: FloatArray) -> FloatArray:
        """ICP fit covariance plus the floors; directions the fit leaves unobserved (a
        corridor's length) are capped at the correlative search's largest spread."""
        cfg = self.config
        cov = np.array(icp_cov, dtype=np.float64)
        cap = float(np.linalg.eigvalsh(0.5 * (response_cov[:2, :2] + response_cov[:2, :2].T))[-1])
        w, v = np.linalg.eigh(cov[:2, :2])
        w = np.minimum(np.maximum(w, 0.0), max(cap, 0.0)) + cfg.icp_covariance_floor_translation**2
        cov[:2, :2] = (v * w) @ v.T
        cov[2, 2] = min(max(float(cov[2, 2]), 0.0), max(float(response_cov[2, 2]), 0.0))
        cov[2, 2] += cfg.icp_covariance_floor_rotation**2
        if float(np.linalg.eigvalsh(cov)[0]) <= 0.0:
            # a capped direction can leave the heading cross terms inconsistent
            cov[:2, 2] = 0.0
            cov[2, :2] = 0.0
        return cov

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

    def _with_scan_geometry(self, match: MatchResult, points: FloatArray, idx: int) -> MatchResult:
        """A match whose covariance also shows the directions its scan's geometry leaves
        degenerate: along each eigen-direction of `scan_position_covariance` with a variance
        above ``corridor_covariance_threshold`` that variance is added (the others, which the
        scan's lines pin, keep the correlative search's covariance)."""
        geo, rot = self._scan_geometry(match, points, idx)
        w, v = np.linalg.eigh(geo)
        weak = w > self.config.corridor_covariance_threshold
        if not np.any(weak):
            return match
        d = rot @ v[:, weak]
        cov = np.array(match.covariance, dtype=np.float64)
        cov[:2, :2] += (d * w[weak]) @ d.T
        return MatchResult(match.pose, match.response, cov)

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
            if cfg.match_degeneracy_analysis:
                match = self._with_scan_geometry(match, points, len(self.nodes))
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
                    delta, cov = fuse_increments(
                        odo_delta, self._step_odometry_covariance(odo_delta), delta, info
                    )
                    pose = _compose1(prev_pose, delta)
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
            self._span_queue.append((idx - span, idx))
            if len(self._span_queue) >= cfg.odometry_span_batch:
                self._flush_spans()
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
            self._retire_superseded(idx)
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
                active=self._active_nodes(),
            )
            found: LoopClosure | None = None
            poses = self.graph.poses  # in sync since _positions: no second pass
            sensor = _compose1(poses[idx], self.sensor_offset)
            icp_cov = cfg.use_icp_refinement and cfg.match_covariance == "icp"
            bias = cfg.loop_match_range_bias_quadratic
            query = points if bias <= 0.0 else unbiased_points(points, bias)
            if cfg.loop_match_maximum_chains > 0:
                chains = chains[: cfg.loop_match_maximum_chains]
            for chain in chains:
                if bias > 0.0:
                    ref = np.concatenate([self._unbiased_world_points(i, poses[i], bias)
                                          for i in chain])
                else:
                    ref = self._reference(chain, poses)[0]
                found = verify_loop(
                    query,
                    sensor,
                    chain,
                    ref,
                    positions[list(chain)],
                    coarse=self._loop_coarse,
                    fine=self._loop_fine,
                    min_response_coarse=cfg.loop_match_minimum_response_coarse,
                    max_variance_coarse=cfg.loop_match_maximum_variance_coarse,
                    min_response_fine=cfg.loop_match_minimum_response_fine,
                    max_variance_fine=0.0 if icp_cov else cfg.loop_match_maximum_variance_fine,
                )
                if found is not None and icp_cov:
                    normals = self._reference(chain, poses, normals=True)[1]
                    assert normals is not None
                    polished = self._polish(found.match, query, ref, normals, self._loop_fine)
                    found = dataclasses.replace(found, match=polished)
                    if cfg.loop_match_maximum_variance_fine > 0.0 and (
                        float(np.linalg.eigvalsh(polished.covariance[:2, :2])[-1])
                        > cfg.loop_match_maximum_variance_fine
                    ):
                        found = None
                if found is not None:
                    break
            if found is None:
                return closed
            base = _compose1(found.match.pose, _inverse1(self.sensor_offset))
            cand_pose = self.graph.pose(found.candidate)
            delta = _between1(cand_pose, base)
            match = found.match
            if cfg.match_degeneracy_analysis:
                match = self._with_scan_geometry(match, points, idx)
            if cfg.loop_match_range_covariance:
                match = self._with_range_error(match, points, idx)
            cov = _rotate_covariance(match.covariance, float(cand_pose[2]))
            if cfg.loop_match_constrained_variance > 0.0:
                cov = constrained_covariance(cov, cfg.loop_match_constrained_variance)
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
                if j < self._active.shape[0]:
                    self._active[j] = False

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
            if match.response < self._weak_response:
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


def valid_point_count(scan: Scan, max_laser_range: float) -> int:
    """Number of usable beams in a scan."""
    return int(np.count_nonzero(valid_beams(scan, max_laser_range)))


def _box_ranges(pose: FloatArray, angles: FloatArray, size: tuple[float, float]) -> FloatArray:
    """Ranges from ``pose`` (inside the box [0, w] × [0, h]) to the box's walls."""
    a = pose[2] + angles
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (size[0] - pose[0]) / c, np.where(c < 0, -pose[0] / c, np.inf))
        ty = np.where(s > 0, (size[1] - pose[1]) / s, np.where(s < 0, -pose[1] / s, np.inf))
    return np.asarray(np.minimum(tx, ty))


def warm_up(config: SlamConfig | None = None) -> float:
    """Run the core's compiled kernels once on a synthetic room, so that numba compiles them
    (first run after an install, ~10 s) or loads them from its cache (~0.3 s) now rather than
    on the first real scan; returns the seconds it took. Nothing is kept.

    A short drive along a box 4 m wide exercises sequential matching (correlative search,
    sub-cell refinement, ICP polish, covariance), the occupancy grid's ray casting and a
    loop-closure verification (multi-resolution coarse search, then fine).
    """
    t0 = time.perf_counter()
    cfg = dataclasses.replace(
        config or SlamConfig(), mode="mapping", minimum_time_interval=0.0, map_file_name=""
    )
    core = SlamCore(cfg)
    angles = np.linspace(-0.5, 0.5, 160)  # a 57° scan; the kernels do not depend on the width
    range_max = min(cfg.max_laser_range, 12.0)
    step = max(cfg.minimum_travel_distance, 0.1) + 0.05  # every pose becomes a node
    size = (2.0 + 3 * step + 3.0, 4.0)  # the last pose still 3 m short of the end wall
    for k in range(4):
        pose = np.array([1.0 + step * k, 1.5 + 0.02 * k, 0.05 * k])
        scan = Scan(_box_ranges(pose, angles, size), angles, 0.05, range_max, (k + 1) * 10**9)
        core.process(scan, pose)
    core.update_map()
    if len(core.nodes) >= 2:
        verify_loop(
            core.nodes[-1].points,
            _compose1(core.graph.pose(len(core.nodes) - 1), core.sensor_offset),
            (0,),
            core._world_points(0),
            core._positions()[:1],
            coarse=core._loop_coarse,
            fine=core._loop_fine,
            min_response_coarse=0.0,
            max_variance_coarse=math.inf,
            min_response_fine=0.0,
        )
    return time.perf_counter() - t0
