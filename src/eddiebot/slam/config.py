"""SLAM parameters: slam_toolbox's names and the upstream node's code defaults.

Field defaults are what ``slam_toolbox`` uses when a parameter is not set (its node code,
not its sample YAML; the two differ in a few places, e.g. ``minimum_distance_penalty``
0.05 in code vs 0.5 in ``mapper_params_online_async.yaml``). ``config/slam_defaults.yaml``
holds the sample YAML's values and ``config/slam.yaml`` Eddie's overrides.

Fields after ``occupancy_threshold`` are eddiebot's own (no upstream counterpart): the
pose-graph back end is GTSAM rather than Ceres, so the ``ceres_*`` keys are accepted and
ignored, and ``optimizer`` / ``loop_robust_kernel`` choose the GTSAM set-up.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from eddiebot.slam.errors import ConfigError

__all__ = [
    "CERES_PARAMETERS",
    "NODE_PARAMETERS",
    "REMOVED_PARAMETERS",
    "SlamConfig",
    "SlamMode",
    "load_slam_config",
    "parameter_warnings",
]

SlamMode = str  # "mapping" | "localization" | "lifelong"
_MODES = ("mapping", "localization", "lifelong")
_OPTIMIZERS = ("isam2", "levenberg_marquardt")
_FACTORIZATIONS = ("qr", "cholesky")  # eddiebot.slam.pose_graph.FACTORIZATIONS, without importing GTSAM
_KERNELS = ("none", "huber", "cauchy", "dcs")
_STEP_HEADINGS = ("odometry", "quantization", "match")


@dataclass(frozen=True)
class SlamConfig:
    """2D SLAM parameters (distances m, angles rad, times s)."""

    # --- node / ROS plumbing (used by the node, carried here so one file configures both)
    solver_plugin: str = "solver_plugins::CeresSolver"
    ceres_linear_solver: str = "SPARSE_NORMAL_CHOLESKY"
    ceres_preconditioner: str = "SCHUR_JACOBI"
    ceres_trust_strategy: str = "LEVENBERG_MARQUARDT"
    ceres_dogleg_type: str = "TRADITIONAL_DOGLEG"
    ceres_loss_function: str = "None"
    odom_frame: str = "odom"
    map_frame: str = "map"
    base_frame: str = "base_footprint"
    scan_topic: str = "/scan"
    use_map_saver: bool = True
    mode: str = "mapping"
    map_file_name: str = ""
    map_start_pose: tuple[float, ...] = ()
    """Pose (x, y, theta in the map frame, m/rad) at which a session loaded from
    ``map_file_name`` at start-up begins; empty = unset (see ``map_start_at_dock``)."""
    map_start_at_dock: bool = False
    """Begin a session loaded at start-up at its first node (mapping, lifelong)."""
    map_name: str = "/map"
    """Topic of the occupancy grid (its metadata on ``<map_name>_metadata``)."""
    scan_queue_size: int = 1
    """Async processing: scans kept waiting while one is processed (older ones dropped)."""
    paused_new_measurements: bool = False
    """Start with new measurements paused (``~/pause_new_measurements`` toggles it)."""
    debug_logging: bool = False
    throttle_scans: int = 1
    transform_publish_period: float = 0.05
    map_update_interval: float = 10.0
    resolution: float = 0.05
    max_laser_range: float = 25.0
    minimum_time_interval: float = 0.5
    transform_timeout: float = 0.5
    tf_buffer_duration: float = 30.0
    stack_size_to_use: int = 40_000_000
    enable_interactive_mode: bool = False
    # --- Karto mapper
    use_scan_matching: bool = True
    use_scan_barycenter: bool = True
    minimum_travel_distance: float = 0.5
    minimum_travel_heading: float = 0.5
    scan_buffer_size: int = 10
    scan_buffer_maximum_scan_distance: float = 10.0
    link_match_minimum_response_fine: float = 0.1
    link_scan_maximum_distance: float = 1.5
    loop_search_maximum_distance: float = 3.0
    do_loop_closing: bool = True
    loop_match_minimum_chain_size: int = 10
    loop_match_maximum_variance_coarse: float = 3.0
    loop_match_minimum_response_coarse: float = 0.35
    loop_match_minimum_response_fine: float = 0.45
    correlation_search_space_dimension: float = 0.5
    correlation_search_space_resolution: float = 0.01
    correlation_search_space_smear_deviation: float = 0.1
    loop_search_space_dimension: float = 8.0
    loop_search_space_resolution: float = 0.05
    loop_search_space_smear_deviation: float = 0.03
    distance_variance_penalty: float = 0.5
    angle_variance_penalty: float = 1.0
    fine_search_angle_offset: float = 0.00349
    coarse_search_angle_offset: float = 0.349
    coarse_angle_resolution: float = 0.0349
    minimum_angle_penalty: float = 0.9
    minimum_distance_penalty: float = 0.05
    use_response_expansion: bool = True
    min_pass_through: int = 2
    occupancy_threshold: float = 0.1
    # --- upstream keys accepted and not used (the node names each one it is given:
    # `ignored_parameters`)
    position_covariance_scale: float = 1.0
    yaw_covariance_scale: float = 1.0
    use_lifecycle_manager: bool = False
    # --- lifelong mode (slam_toolbox's LifelongSlamToolbox; eddiebot.slam.mapper.lifelong)
    lifelong_search_use_tree: bool = False
    """Score every node near a new one (true), or only those linked to it through the graph
    within that distance (false)."""
    lifelong_minimum_score: float = 0.1
    """Bounding-box IoU with the new scan below which a node is not re-scored."""
    lifelong_iou_match: float = 0.85
    """IoU above which a node with fewer than three edges is removed outright."""
    lifelong_node_removal_score: float = 0.10
    """A node whose score (1 when added) drops below this is marginalised out."""
    lifelong_overlap_score_scale: float = 0.5
    """Score taken off a node per new scan, times its overlap with the new scan."""
    lifelong_constraint_multiplier: float = 0.05
    """Score kept per edge beyond two (nodes that loop closures lean on decay slower)."""
    lifelong_nearby_penalty: float = 0.001
    """Score taken off a re-scored node for being near the new scan at all."""
    lifelong_candidates_scale: float = 0.03
    """Read and range-checked as upstream, where its only use is commented out."""
    # --- eddiebot's own
    optimizer: str = "isam2"
    """``isam2`` (incremental, every node) or ``levenberg_marquardt`` (batch, on loop closure)."""
    isam2_factorization: str = "qr"
    """iSAM2's elimination, ``qr`` or ``cholesky``: Cholesky takes about half the time per
    update but squares the conditioning; a graph whose update fails with it falls back to QR."""
    isam2_relinearize_skip: int = 1
    """iSAM2 checks for relinearisation every this many updates (GTSAM's default 10)."""
    isam2_recent_nodes_last: int = 0
    """Order the newest this many nodes last in every iSAM2 update, keeping them at the root
    of the Bayes tree (0 = GTSAM's default: the keys of the new factors last). With
    ``odometry_span_nodes`` N, N + 1 keeps a span edge's far end and everything after it at
    the root, so an update re-eliminates ~15 variables instead of the path from that node
    (70-100 once loops have closed). The solution is the same; its rounding is not."""
    isam2_wildfire_threshold: float = 0.001
    """iSAM2's back-substitution skips the cliques below one whose solution moved less than
    this (GTSAM's default); 0 computes every variable's solution on each update."""
    loop_robust_kernel: str = "dcs"
    """Robust kernel on loop-closure edges: ``none``, ``huber``, ``cauchy`` or ``dcs``."""
    loop_robust_kernel_width: float = 1.0
    """Kernel width in whitened units (σ)."""
    corridor_covariance_threshold: float = 0.01
    """Warn when the scan-match variance along the weakest direction exceeds this (m²)."""
    use_icp_refinement: bool = True
    """Polish each correlative match with point-to-line ICP on the reference points."""
    slip_search_dimension: float = 2.0
    """Side (m) of the wide re-search after a weak or window-edge sequential match; 0 = off."""
    slip_search_minimum_response: float = 0.0
    """A sequential match scoring below this response is weak: mapping re-searches it over
    ``slip_search_dimension`` (a wheel slip), localization over the loop-closure window (a lost
    pose). 0 = ``loop_match_minimum_response_fine``, a response good enough to close a loop."""
    slip_search_maximum_sigmas: float = 0.0
    """Reject a wide re-search result farther than this many odometry σ (Mahalanobis, under
    the odometry noise model below) from the odometry prediction, or not well constrained in
    every direction (variance above ``corridor_covariance_threshold``); 0 = neither check."""
    odometry_translation_sigma: float = 0.02
    """Odometry noise model: translation σ (m) per step, plus ``odometry_translation_noise``
    times the distance travelled."""
    odometry_translation_noise: float = 0.1
    """Odometry translation σ per metre travelled (m/m)."""
    odometry_rotation_sigma: float = 0.02
    """Odometry heading σ (rad) per step, plus ``odometry_rotation_noise`` times the turn and
    ``odometry_rotation_noise_per_meter`` times the distance."""
    odometry_rotation_noise: float = 0.1
    """Odometry heading σ per radian turned (rad/rad)."""
    odometry_rotation_noise_per_meter: float = 0.05
    """Odometry heading σ per metre travelled (rad/m)."""
    match_coarse_heading_variance: bool = False
    """Sequential matches take their heading variance from every coarse heading (how well
    the scan fits several degrees off), not only from the fine steps beside the best."""
    fuse_odometry: bool = False
    """Fuse each sequential match with odometry by information (under the noise model above):
    a match constrains the pose only along the directions it observes well (variance below
    ``corridor_covariance_threshold``); odometry fills in the rest (e.g. along a corridor).
    Off: the match alone sets the pose (slam_toolbox's behaviour)."""
    odometry_span_nodes: int = 0
    """Also link each scan-matched node to the node this many steps back in the same odometry
    chain by odometry alone (eddiebot's; 0 = off, slam_toolbox's behaviour). Per-step edges
    treat every odometry heading error as accumulating, but coarse encoders (Eddie's 36
    positions per wheel turn) quantise the heading in ≈ 2° steps: an error that is large from
    one step to the next and does not accumulate, while the narrow scan's sequential matches
    carry small heading errors that do. The span edge's heading σ is
    √2 · ``odometry_heading_quantization`` plus the noise model's accumulating part over the
    span, so a straight run keeps the wheels' heading."""
    odometry_heading_quantization: float = 0.01
    """σ (rad) of the odometry heading's non-accumulating error (encoder quantisation), used by
    ``odometry_span_nodes``."""
    fused_step_heading: str = "odometry"
    """Odometry heading σ of each fused sequential step (``fuse_odometry``): "odometry" = the
    noise model above; "quantization" = raised to at least √2 · ``odometry_heading_quantization``
    (two quantised poses' error, which does not accumulate); "match" = the step's heading from
    the scan match alone (the odometry gives no heading information to the step). The last two
    apply only with ``odometry_span_nodes`` > 0, whose span edges hold the heading drift."""
    loop_match_maximum_variance_fine: float = 0.0
    """Reject a loop closure whose fine match has a position variance (m², along its weakest
    direction) above this: an aliased corridor match constrains only one direction; 0 = off."""
    loop_match_maximum_chains: int = 0
    """Verify at most this many loop-closure candidate chains per scan, in Karto's order (the
    oldest first); 0 = every candidate, as Karto does. Each failed verification costs a coarse
    and a fine match (~7 ms on the simulated routes), so this bounds a scan's loop search."""
    scan_range_sigma: float = 0.01
    """Range error σ (m) of a scan point at zero range, for ``loop_match_range_covariance``."""
    scan_range_sigma_quadratic: float = 0.0
    """Range error σ growth with the squared range (1/m), for ``loop_match_range_covariance``:
    a depth camera's error grows as z² (a Kinect's disparity steps are 2.85e-3·z²)."""
    loop_match_range_covariance: bool = False
    """Add to every loop closure's covariance the position error the scan's range errors
    leave it (`eddiebot.slam.mapper.scan_position_covariance` with ``scan_range_sigma`` and
    ``scan_range_sigma_quadratic``): an error all points pinning a direction share, such as a
    depth camera's range bias, which grows as r², does not average out. A loop closed on
    walls 6-8 m ahead is then weak along the view and as strong as before across it. Off:
    the correlative search's covariance alone (Karto's)."""
    map_max_laser_range: float = 0.0
    """Range (m) beyond which beams leave no hit in the occupancy grid (cut there, clearing
    up to it), when shorter than ``max_laser_range`` (which still bounds scan matching): a
    depth camera's far returns are too coarse for the map; 0 = ``max_laser_range``."""
    max_odometry_jump: float = 1.0
    """Largest odometry translation (m) between two consecutive scans the core is given that
    is taken as motion; a larger change (a wheel-odometry reset, a bad sample) is not
    integrated: the odometry is re-anchored where the robot last was and the scan starts a
    new chain, linked to the graph by scan matching. 1 m is 2 s at Eddie's top speed
    (0.5 m/s), more than the node's ``minimum_time_interval`` gate lets pass; 0 = off."""
    max_odometry_jump_heading: float = 2.0
    """The same for the odometry heading (rad): 2 rad is 2 s at 1 rad/s, beyond anything
    Eddie turns between two scans that pass the node's gate; 0 = off."""
    extra: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)
    """Parameters present in the file but not used by the core (kept for the node)."""

    def __post_init__(self) -> None:
        # A node that declares every field as a parameter hands ``extra`` back as None.
        if self.extra is None:
            object.__setattr__(self, "extra", {})
        if not isinstance(self.map_start_pose, tuple):
            object.__setattr__(self, "map_start_pose", tuple(self.map_start_pose or ()))

    def validated(self) -> SlamConfig:
        """Apply the node's fall-backs for non-positive values and check enumerations."""
        changes: dict[str, Any] = {}
        if self.scan_buffer_size <= 0:
            changes["scan_buffer_size"] = 10
        if self.scan_buffer_maximum_scan_distance**2 <= 1e-6:
            changes["scan_buffer_maximum_scan_distance"] = 10.0
        fallbacks = (
            ("correlation_search_space_dimension", 0.5),
            ("correlation_search_space_resolution", 0.01),
            ("correlation_search_space_smear_deviation", 0.1),
            ("loop_search_space_dimension", 8.0),
            ("loop_search_space_resolution", 0.05),
            ("loop_search_space_smear_deviation", 0.03),
            ("resolution", 0.05),
        )
        changes.update({name: default for name, default in fallbacks if getattr(self, name) <= 0})
        out = dataclasses.replace(self, **changes) if changes else self
        if out.mode not in _MODES:
            raise ConfigError(f"parameter 'mode' must be one of {_MODES}, got {out.mode!r}")
        if out.optimizer not in _OPTIMIZERS:
            raise ConfigError(
                f"parameter 'optimizer' must be one of {_OPTIMIZERS}, got {out.optimizer!r}"
            )
        if out.isam2_factorization not in _FACTORIZATIONS:
            raise ConfigError(
                f"parameter 'isam2_factorization' must be one of {_FACTORIZATIONS}, "
                f"got {out.isam2_factorization!r}"
            )
        if out.loop_robust_kernel not in _KERNELS:
            raise ConfigError(
                f"parameter 'loop_robust_kernel' must be one of {_KERNELS}, got {out.loop_robust_kernel!r}"
            )
        if out.fused_step_heading not in _STEP_HEADINGS:
            raise ConfigError(
                f"parameter 'fused_step_heading' must be one of {_STEP_HEADINGS}, "
                f"got {out.fused_step_heading!r}"
            )
        for name in (
            "minimum_travel_distance",
            "minimum_travel_heading",
            "max_laser_range",
            "map_max_laser_range",
            "odometry_heading_quantization",
            "slip_search_minimum_response",
            "isam2_wildfire_threshold",
        ):
            value = getattr(out, name)
            if not math.isfinite(value) or value < 0:
                raise ConfigError(f"parameter '{name}' must be a finite value >= 0, got {value}")
        if out.map_start_pose and (
            len(out.map_start_pose) != 3
            or not all(
                isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                for v in out.map_start_pose
            )
        ):
            raise ConfigError(
                f"parameter 'map_start_pose' must be [x, y, theta], got {list(out.map_start_pose)}"
            )
        for name in _LIFELONG_PARAMETERS[1:]:
            value = getattr(out, name)
            if not 0.0 <= value <= 1.0:  # upstream exits on these (checkIsNotNormalized)
                raise ConfigError(f"parameter '{name}' must be in [0, 1], got {value}")
        for name in ("max_odometry_jump", "max_odometry_jump_heading"):
            value = getattr(out, name)
            if not math.isfinite(value) or value < 0:
                raise ConfigError(f"parameter '{name}' must be a finite value >= 0, got {value}")
        for name, least in (
            ("scan_queue_size", 1),
            ("isam2_relinearize_skip", 1),
            ("isam2_recent_nodes_last", 0),
            ("loop_match_maximum_chains", 0),
            ("odometry_span_nodes", 0),
        ):
            count = getattr(out, name)
            if count < least:
                raise ConfigError(f"parameter '{name}' must be >= {least}, got {count}")
        return out

    @classmethod
    def from_parameters(cls, params: dict[str, Any], *, source: str = "<parameters>") -> SlamConfig:
        """Build from a flat parameter dict; unknown keys go to ``extra``; types are checked."""
        known = {f.name: f for f in fields(cls) if f.name != "extra"}
        kwargs: dict[str, Any] = {}
        extra: dict[str, Any] = {}
        defaults = cls()
        for key, value in params.items():
            if key not in known:
                extra[key] = value
                continue
            default = getattr(defaults, key)
            kwargs[key] = _coerce(key, value, default, source)
        return cls(**kwargs, extra=extra).validated()

    def to_parameters(self) -> dict[str, Any]:
        """Flat dict of every parameter (for writing the resolved set beside outputs)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "extra"}
        out.update(self.extra)
        return out


def _coerce(key: str, value: Any, default: Any, source: str) -> Any:
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{source}: parameter '{key}' must be true/false, got {value!r}")
    if isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{source}: parameter '{key}' must be an integer, got {value!r}")
    if isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ConfigError(f"{source}: parameter '{key}' must be a number, got {value!r}")
    if isinstance(default, str):
        if isinstance(value, str):
            return value
        raise ConfigError(f"{source}: parameter '{key}' must be a string, got {value!r}")
    if isinstance(default, tuple):
        if isinstance(value, (list, tuple)) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
        ):
            return tuple(float(v) for v in value)
        raise ConfigError(f"{source}: parameter '{key}' must be a list of numbers, got {value!r}")
    return value


def load_slam_config(
    path: str | os.PathLike[str] | None = None,
    *,
    node_name: str = "slam_toolbox",
    overrides: dict[str, Any] | None = None,
) -> SlamConfig:
    """Read a ROS 2 parameter file (``node: {ros__parameters: {...}}`` or ``/**``).

    Several files can be layered by calling ``from_parameters`` on merged dicts; here one
    file plus ``overrides``. Errors name the file and the key.
    """
    params: dict[str, Any] = {}
    source = "<overrides>"
    if path is not None:
        source = str(path)
        try:
            doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
        except OSError as exc:
            raise ConfigError(f"{source}: cannot read: {exc.strerror or exc}") from exc
        except yaml.YAMLError as exc:
            raise ConfigError(f"{source}: not valid YAML: {exc}") from exc
        if not isinstance(doc, dict):
            raise ConfigError(f"{source}: expected '<node>: {{ros__parameters: ...}}'")
        found = False
        for name in ("/**", node_name, "/" + node_name):
            section = doc.get(name)
            if section is None:
                continue
            if not isinstance(section, dict) or not isinstance(
                section.get("ros__parameters"), dict
            ):
                raise ConfigError(f"{source}: key '{name}' must hold a 'ros__parameters' mapping")
            params.update(section["ros__parameters"])
            found = True
        if not found:
            raise ConfigError(f"{source}: no section for node '{node_name}' (or '/**')")
    if overrides:
        params.update(overrides)
    return SlamConfig.from_parameters(params, source=source)


#: The Ceres solver's keys: GTSAM optimises the pose graph instead (``optimizer``).
CERES_PARAMETERS = (
    "solver_plugin",
    "ceres_linear_solver",
    "ceres_preconditioner",
    "ceres_trust_strategy",
    "ceres_dogleg_type",
    "ceres_loss_function",
)

#: The node's own parameters, not `SlamConfig` fields.
NODE_PARAMETERS = ("processing", "use_sim_time", "odom_session")


_CORRELATIVE = "a match's covariance is the correlative search's, as Karto's"
_RANGES = "scan ranges are used as they are"

#: eddiebot options that were removed (off by default, on in no shipped configuration, and no
#: benchmark showed them paying: docs/benchmarks/slam.md#slam-extras) → what the SLAM does
#: instead. A file that still sets one is read; the key is named as not supported.
REMOVED_PARAMETERS: dict[str, str] = {
    "match_covariance": _CORRELATIVE,
    "icp_covariance_floor_translation": _CORRELATIVE,
    "icp_covariance_floor_rotation": _CORRELATIVE,
    "match_degeneracy_analysis": _CORRELATIVE,
    "loop_match_constrained_variance": _CORRELATIVE,
    "match_fine_search_climb": "the fine search covers Karto's single box",
    "odometry_span_batch": "each odometry span edge is added with its node",
    "scan_range_bias_quadratic": _RANGES,
    "loop_match_range_bias_quadratic": _RANGES,
}


_Rule = Callable[["SlamConfig", Any], "str | None"]


def _always(why: str) -> _Rule:
    return lambda _config, _value: why


def _if_true(why: str) -> _Rule:
    return lambda _config, value: why if value else None


def _if_not_one(why: str) -> _Rule:
    return lambda _config, value: why if value != 1.0 else None


def _lifelong(config: SlamConfig, _value: Any) -> str | None:
    if config.mode == "lifelong":
        return None
    return f"read in lifelong mode only, and mode is {config.mode}"


_LIFELONG_PARAMETERS = (
    "lifelong_search_use_tree",
    "lifelong_minimum_score",
    "lifelong_iou_match",
    "lifelong_node_removal_score",
    "lifelong_overlap_score_scale",
    "lifelong_constraint_multiplier",
    "lifelong_nearby_penalty",
    "lifelong_candidates_scale",
)

#: slam_toolbox keys that are accepted but change nothing here → why, or None when the given
#: value asks for nothing the node leaves out (a feature off, a scale of 1).
_IGNORED: dict[str, _Rule] = {
    **dict.fromkeys(
        CERES_PARAMETERS,
        lambda config, _value: (
            f"GTSAM replaces Ceres: the pose graph is optimised with {config.optimizer}, "
            "see the 'optimizer' parameter"
        ),
    ),
    "stack_size_to_use": _always("the Python (de)serialisation needs no larger stack"),
    "enable_interactive_mode": lambda config, value: (
        f"interactive editing works in mapping mode only, and mode is {config.mode}"
        if value and config.mode != "mapping"
        else None
    ),
    "position_covariance_scale": _if_not_one("no ~/pose topic is published"),
    "yaw_covariance_scale": _if_not_one("no ~/pose topic is published"),
    "use_lifecycle_manager": _if_true("the node is not a lifecycle node: it starts active"),
    "localization_on_configure": _always(
        "only slam_toolbox's experimental map_and_localization node reads it"
    ),
    "paused_processing": _always("slam_toolbox's interactive mode sets it at run time"),
    "interactive_mode": _always("slam_toolbox's interactive mode sets it at run time"),
    **dict.fromkeys(_LIFELONG_PARAMETERS, _lifelong),
}


def parameter_warnings(given: dict[str, Any], config: SlamConfig) -> list[str]:
    """What a parameter set asks for that the SLAM does not do, one line per reason.

    ``given``: the parameters a file or command line set (name → value), ``config`` the
    resulting configuration. Accepted-but-unused slam_toolbox keys whose value would matter
    give ``ignored: <key>[, <key>...] (<why>)`` (keys sharing a reason share a line: Ceres'
    keys, the lifelong ones); a key that is neither slam_toolbox's nor eddiebot's gives
    ``unknown parameter: <key> (...)``; a removed eddiebot option (`REMOVED_PARAMETERS`)
    gives ``not supported: <key>[, <key>...] (removed eddiebot option: <what is done instead>;
    ignored)``.
    """
    reasons: dict[str, list[str]] = {}
    removed: dict[str, list[str]] = {}
    unknown: list[str] = []
    known = {f.name for f in fields(SlamConfig)} - {"extra"}
    for name, value in given.items():
        if name in NODE_PARAMETERS:
            continue
        rule = _IGNORED.get(name)
        if rule is not None:
            why = rule(config, value)
            if why is not None:
                reasons.setdefault(why, []).append(name)
        elif name in REMOVED_PARAMETERS:
            removed.setdefault(REMOVED_PARAMETERS[name], []).append(name)
        elif name not in known:
            unknown.append(name)
    out = [f"ignored: {', '.join(names)} ({why})" for why, names in reasons.items()]
    out += [
        f"not supported: {', '.join(names)} (removed eddiebot option: {instead}; ignored)"
        for instead, names in removed.items()
    ]
    out += [
        f"unknown parameter: {name} (neither slam_toolbox's nor eddiebot's; ignored)"
        for name in unknown
    ]
    return out
