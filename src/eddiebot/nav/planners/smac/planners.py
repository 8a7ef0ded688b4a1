"""``nav2_smac_planner::SmacPlanner2D`` and ``nav2_smac_planner::SmacPlannerHybrid``.

Both take ``create_plan(start, goal, costmap)`` like the other planners and raise the typed
failures of :mod:`eddiebot.nav.errors`: a start or goal off the map, a start in collision
(:class:`StartOccupied`), a goal in collision when ``tolerance`` is 0 or when nothing within
it is reachable (:class:`GoalOccupied`), :class:`NoValidPath` when the search runs dry, and
:class:`PlannerTimedOut` when ``max_iterations`` or ``max_planning_time`` is spent (upstream
reports the time limit as "no valid path"; it is a time-out here).

Differences from upstream kept on purpose: SmacPlanner2D's poses lie at cell centres
(upstream's at cell corners); every pose carries the heading of its segment, the last one the
goal's yaw (or the final approach's with ``use_final_approach_orientation``); the Hybrid
``lookup_table_size`` window is evaluated on demand (same values as upstream's table).
No ``unsmoothed_plan``, ``expansions`` or footprint marker topics are published, so
``debug_visualizations`` is not a key here: a params file that sets it has it named as ignored
at start (``last_raw_path`` holds the unsmoothed plan).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import (
    GoalOccupied,
    GoalOutsideMapBounds,
    NoValidPath,
    ParameterError,
    PlannerError,
    PlannerTimedOut,
    StartOccupied,
    StartOutsideMapBounds,
)
from eddiebot.nav.params import from_params, require
from eddiebot.nav.planners.smac import search as S
from eddiebot.nav.planners.smac.smoother import SmacSmootherConfig, smooth_path
from eddiebot.nav.types import as_pose

#: motion models Nav2 names; the Hybrid planner searches with the two Ackermann ones
MOTION_MODELS = ("MOORE", "VON_NEUMANN", "DUBIN", "REEDS_SHEPP", "STATE_LATTICE")


def _smoother_block(obj: Any, server: str) -> None:
    """Turn a ``smoother:`` mapping into :class:`SmacSmootherConfig` (frozen dataclass)."""
    value = obj.smoother
    if isinstance(value, SmacSmootherConfig):
        value.validate(server)
        return
    if not isinstance(value, Mapping):
        raise ParameterError(server, "smoother", value, "expected a mapping of smoother keys")
    unknown = sorted(set(value) - set(SmacSmootherConfig.__dataclass_fields__))
    if unknown:
        raise ParameterError(server, f"smoother.{unknown[0]}", value[unknown[0]],
                             "unknown smoother parameter; known: "
                             f"{sorted(SmacSmootherConfig.__dataclass_fields__)}")
    cfg = from_params(SmacSmootherConfig, dict(value), server=server)
    object.__setattr__(obj, "smoother", cfg)


@dataclass(frozen=True)
class SmacPlanner2DConfig:
    """``SmacPlanner2D`` parameters (Jazzy code defaults)."""

    tolerance: float = 0.125
    downsample_costmap: bool = False
    downsampling_factor: int = 1
    cost_travel_multiplier: float = 1.0
    allow_unknown: bool = True
    max_iterations: int = 1000000
    max_on_approach_iterations: int = 1000
    terminal_checking_interval: int = 5000
    use_final_approach_orientation: bool = False
    max_planning_time: float = 2.0
    smoother: Any = field(default_factory=SmacSmootherConfig)
    #: sections of the plugin's parameters read into their own config (``smoother.*``)
    NESTED: ClassVar[dict[str, type]] = {"smoother": SmacSmootherConfig}

    def validate(self, server: str = "planner_server") -> None:
        require(self.tolerance >= 0.0, server, "tolerance", self.tolerance, "must be >= 0")
        require(self.downsampling_factor >= 1, server, "downsampling_factor",
                self.downsampling_factor, "must be >= 1")
        require(self.cost_travel_multiplier >= 0.0, server, "cost_travel_multiplier",
                self.cost_travel_multiplier, "must be >= 0")
        require(self.terminal_checking_interval >= 1, server, "terminal_checking_interval",
                self.terminal_checking_interval, "must be >= 1")
        require(self.max_planning_time > 0.0, server, "max_planning_time",
                self.max_planning_time, "must be > 0")
        _smoother_block(self, server)


@dataclass(frozen=True)
class SmacPlannerHybridConfig:
    """``SmacPlannerHybrid`` parameters (Jazzy code defaults)."""

    downsample_costmap: bool = False
    downsampling_factor: int = 1
    angle_quantization_bins: int = 72
    tolerance: float = 0.25
    allow_unknown: bool = True
    max_iterations: int = 1000000
    max_on_approach_iterations: int = 1000
    terminal_checking_interval: int = 5000
    smooth_path: bool = True
    minimum_turning_radius: float = 0.4
    allow_primitive_interpolation: bool = False
    cache_obstacle_heuristic: bool = False
    reverse_penalty: float = 2.0
    change_penalty: float = 0.0
    non_straight_penalty: float = 1.2
    cost_penalty: float = 2.0
    retrospective_penalty: float = 0.015
    analytic_expansion_ratio: float = 3.5
    analytic_expansion_max_cost: float = 200.0
    analytic_expansion_max_cost_override: bool = False
    use_quadratic_cost_penalty: bool = False
    downsample_obstacle_heuristic: bool = True
    analytic_expansion_max_length: float = 3.0
    max_planning_time: float = 5.0
    lookup_table_size: float = 20.0
    motion_model_for_search: str = "DUBIN"
    smoother: Any = field(default_factory=SmacSmootherConfig)
    #: sections of the plugin's parameters read into their own config (``smoother.*``)
    NESTED: ClassVar[dict[str, type]] = {"smoother": SmacSmootherConfig}

    def validate(self, server: str = "planner_server") -> None:
        m = self.motion_model_for_search
        require(m in MOTION_MODELS, server, "motion_model_for_search", m,
                f"unknown motion model; valid: {list(MOTION_MODELS)}")
        require(m in ("DUBIN", "REEDS_SHEPP"), server, "motion_model_for_search", m,
                "SmacPlannerHybrid searches with DUBIN or REEDS_SHEPP")
        require(self.angle_quantization_bins >= 1, server, "angle_quantization_bins",
                self.angle_quantization_bins, "must be >= 1")
        require(self.downsampling_factor >= 1, server, "downsampling_factor",
                self.downsampling_factor, "must be >= 1")
        require(self.minimum_turning_radius > 0.0, server, "minimum_turning_radius",
                self.minimum_turning_radius, "must be > 0")
        require(self.tolerance >= 0.0, server, "tolerance", self.tolerance, "must be >= 0")
        for key in ("reverse_penalty", "non_straight_penalty"):
            require(getattr(self, key) >= 1.0, server, key, getattr(self, key), "must be >= 1")
        for key in ("change_penalty", "cost_penalty", "retrospective_penalty",
                    "analytic_expansion_max_length", "lookup_table_size"):
            require(getattr(self, key) >= 0.0, server, key, getattr(self, key), "must be >= 0")
        require(self.retrospective_penalty <= 1.0, server, "retrospective_penalty",
                self.retrospective_penalty, "must be <= 1")
        require(self.analytic_expansion_ratio > 0.0, server, "analytic_expansion_ratio",
                self.analytic_expansion_ratio, "must be > 0")
        require(self.terminal_checking_interval >= 1, server, "terminal_checking_interval",
                self.terminal_checking_interval, "must be >= 1")
        require(self.max_planning_time > 0.0, server, "max_planning_time",
                self.max_planning_time, "must be > 0")
        _smoother_block(self, server)


_LOADED: set[str] = set()


def _load_kernels(planner: Any) -> None:
    """Plan once on a small empty map so that loading the compiled kernels (seconds on a
    busy machine) is not charged to the first real plan's ``max_planning_time``."""
    kind = type(planner).__name__
    if kind in _LOADED:
        return
    _LOADED.add(kind)
    cm = Costmap2D(40, 40, 0.05, 0.0, 0.0, 0)
    try:
        planner.create_plan((0.5, 0.5, 0.0), (1.5, 1.5, 0.0), cm)
    except PlannerError:
        pass


def _limit(n: int) -> int:
    return n if n > 0 else 2 ** 62


def _map_continuous(cm: Costmap2D, x: float, y: float) -> tuple[float, float] | None:
    """``worldToMapContinuous``."""
    mx = (x - cm.origin_x) / cm.resolution
    my = (y - cm.origin_y) / cm.resolution
    if mx < 0.0 or my < 0.0 or mx >= cm.size_x or my >= cm.size_y:
        return None
    return mx, my


def _search_grid(costmap: Costmap2D, downsample: bool, factor: int
                 ) -> tuple[npt.NDArray[np.uint8], float]:
    if downsample and factor > 1:
        return S.downsample_max(costmap.data, factor), costmap.resolution * factor
    return costmap.data, costmap.resolution


def _finish_headings(out: npt.NDArray[np.float64], start: npt.NDArray[np.float64],
                     goal: npt.NDArray[np.float64], final_approach: bool) -> None:
    n = out.shape[0]
    if final_approach:
        if n == 1:
            out[0, 2] = start[2]
        else:
            d = out[-1, :2] - out[-2, :2]
            out[-1, 2] = math.atan2(d[1], d[0])
    else:
        out[-1, 2] = goal[2]


def _raise_failure(status: int, iterations: int, what: str, goal_blocked: bool,
                   g: npt.NDArray[np.float64]) -> None:
    if status == S.TIMED_OUT:
        raise PlannerTimedOut(f"{what} exceeded max_planning_time after {iterations} expansions")
    if status == S.MAX_ITERATIONS:
        raise PlannerTimedOut(f"{what} exceeded max_iterations ({iterations} expansions)")
    if goal_blocked:
        raise GoalOccupied(f"goal ({g[0]:.2f}, {g[1]:.2f}) is occupied and no free pose lies "
                           "within tolerance")
    raise NoValidPath(f"{what} found no valid path ({iterations} expansions)")


class SmacPlanner2D:
    """Cost-aware 8-connected A* (``nav2_smac_planner::SmacPlanner2D``)."""

    def __init__(self, config: SmacPlanner2DConfig | None = None, name: str = "GridBased") -> None:
        self.config = config or SmacPlanner2DConfig()
        self.config.validate()
        self.name = name
        self.last_iterations = 0
        #: the search's path before smoothing (the smoother, as upstream's, may round
        #: corners into unknown space)
        self.last_raw_path = np.zeros((0, 3))

    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]:
        _load_kernels(self)
        t0 = time.perf_counter()
        cfg = self.config
        s = as_pose(start)
        g = as_pose(goal)
        grid, res = _search_grid(costmap, cfg.downsample_costmap, cfg.downsampling_factor)
        h, w = grid.shape
        ms = _map_continuous(costmap, s[0], s[1])
        if ms is None:
            raise StartOutsideMapBounds(f"start ({s[0]:.2f}, {s[1]:.2f}) is outside the costmap")
        mg = _map_continuous(costmap, g[0], g[1])
        if mg is None:
            raise GoalOutsideMapBounds(f"goal ({g[0]:.2f}, {g[1]:.2f}) is outside the costmap")
        k = costmap.resolution / res
        sx, sy = min(int(ms[0] * k), w - 1), min(int(ms[1] * k), h - 1)
        gx, gy = mg[0] * k, mg[1] * k
        if sx == int(gx) and sy == int(gy):
            yaw = s[2] if cfg.use_final_approach_orientation else g[2]
            return np.array([[s[0], s[1], yaw]])

        def free(c: int) -> bool:
            return c < S.INSCRIBED or (c == S.UNKNOWN and cfg.allow_unknown)

        if not free(int(grid[sy, sx])):
            raise StartOccupied(f"start ({s[0]:.2f}, {s[1]:.2f}) is in collision")
        goal_blocked = not free(int(grid[min(int(gy), h - 1), min(int(gx), w - 1)]))
        tol = cfg.tolerance / res
        if goal_blocked and tol < 0.001:
            raise GoalOccupied(f"goal ({g[0]:.2f}, {g[1]:.2f}) is in collision")
        status, cells, its = S.astar_2d(
            grid, sx, sy, gx, gy, cfg.cost_travel_multiplier, cfg.allow_unknown, tol,
            _limit(cfg.max_iterations), _limit(cfg.max_on_approach_iterations),
            cfg.terminal_checking_interval, cfg.max_planning_time)
        self.last_iterations = int(its)
        if status != S.FOUND:
            _raise_failure(int(status), int(its), "SmacPlanner2D", goal_blocked, g)
        out = np.zeros((cells.shape[0], 3))
        out[:, 0] = costmap.origin_x + (cells[:, 0] + 0.5) * res
        out[:, 1] = costmap.origin_y + (cells[:, 1] + 0.5) * res
        if out.shape[0] > 1:
            d = np.diff(out[:, :2], axis=0)
            out[:-1, 2] = np.arctan2(d[:, 1], d[:, 0])
            out[-1, 2] = out[-2, 2]
        self.last_raw_path = out.copy()
        remaining = cfg.max_planning_time - (time.perf_counter() - t0)
        out = smooth_path(out, grid, costmap.origin_x, costmap.origin_y, res, cfg.smoother,
                          True, remaining)
        _finish_headings(out, s, g, cfg.use_final_approach_orientation)
        return out


class SmacPlannerHybrid:
    """Hybrid-A* over (x, y, heading bin) (``nav2_smac_planner::SmacPlannerHybrid``).

    Motion primitives are the three (Dubins) or six (Reeds-Shepp) arcs of
    ``HybridMotionTable``: a chord of at least √2 cells at ``minimum_turning_radius``,
    turning a whole number of heading bins. The heuristic is the larger of the cost-aware
    2D wavefront from the goal and the Dubins/Reeds-Shepp distance; every
    ``analytic_expansion_ratio``-scaled number of expansions the exact curve to the goal is
    tried (``analytic_expansion_max_length``). Collision checking follows
    ``GridCollisionChecker``: a circular robot (``use_radius``) is checked at its centre cell
    (INSCRIBED is a collision); a polygon footprint, pre-rotated per heading bin, is checked
    along its outline whenever the centre cost reaches ``possible_collision_cost`` (the
    inflation cost at the circumscribed radius). Call :meth:`set_footprint` (or
    :meth:`configure_from_costmap` with the layered costmap) to give the robot's shape.
    """

    def __init__(self, config: SmacPlannerHybridConfig | None = None,
                 name: str = "GridBased") -> None:
        self.config = config or SmacPlannerHybridConfig()
        self.config.validate()
        self.name = name
        self.footprint: npt.NDArray[np.float64] | None = None
        self.use_radius = True
        self.possible_collision_cost = -1.0
        self.last_iterations = 0
        #: the search's path before smoothing, and which of its poses are driven in reverse
        self.last_raw_path = np.zeros((0, 3))
        self.last_reversing = np.zeros(0, dtype=bool)
        self._h_cache: tuple[Any, npt.NDArray[np.float64]] | None = None

    # --- robot shape -----------------------------------------------------------------------
    def set_footprint(self, footprint: npt.ArrayLike | None, use_radius: bool,
                      possible_collision_cost: float = -1.0) -> None:
        """``GridCollisionChecker::setFootprint``: polygon (M, 2) in metres, whether the robot
        is circular, and the cost from which a full footprint check is needed (<= 0: always)."""
        self.use_radius = bool(use_radius)
        self.footprint = None if footprint is None else \
            np.asarray(footprint, dtype=np.float64).reshape(-1, 2)
        if not self.use_radius and (self.footprint is None or self.footprint.shape[0] < 3):
            raise ParameterError(self.name, "footprint", footprint,
                                 "a non-circular robot needs a polygon of at least 3 points")
        self.possible_collision_cost = float(possible_collision_cost)

    def configure_from_costmap(self, layered: Any) -> None:
        """Footprint, ``use_radius`` and circumscribed cost of a ``LayeredCostmap``
        (``findCircumscribedCost``: the inflation layer's cost at the circumscribed radius,
        0 when the inflation radius is smaller, -1 without an inflation layer)."""
        from eddiebot.nav.costmap.layers.inflation import InflationLayer, inflation_cost

        cost = -1.0
        for lay in getattr(layered, "layers", []):
            if isinstance(lay, InflationLayer):
                res = layered.master.resolution
                circ = layered.circumscribed_radius
                if lay.config.inflation_radius < circ:
                    cost = 0.0
                else:
                    cost = float(inflation_cost(circ / res, res, layered.inscribed_radius,
                                                lay.config.cost_scaling_factor))
                break
        self.set_footprint(layered.footprint, layered.use_radius, cost)

    # --- motion table ----------------------------------------------------------------------
    def _motion_table(self, rho: float) -> tuple[np.ndarray, ...]:
        """``HybridMotionTable::initDubin`` / ``initReedsShepp`` (grid units)."""
        cfg = self.config
        bins = cfg.angle_quantization_bins
        bin_size = 2.0 * math.pi / bins
        angle = 2.0 * math.asin(min(1.0, math.sqrt(2.0) / (2.0 * rho)))
        inc = 1.0 if angle < bin_size else math.ceil(angle / bin_size)
        angle = inc * bin_size
        dx = rho * math.sin(angle)
        dy = rho - rho * math.cos(angle)
        dd = math.hypot(dx, dy)
        prims = [(dd, 0.0, 0.0, S.FORWARD), (dx, dy, inc, S.LEFT), (dx, -dy, -inc, S.RIGHT)]
        rs = cfg.motion_model_for_search == "REEDS_SHEPP"
        if rs:
            prims += [(-dd, 0.0, 0.0, S.REVERSE), (-dx, dy, -inc, S.REV_LEFT),
                      (-dx, -dy, inc, S.REV_RIGHT)]
        if cfg.allow_primitive_interpolation and inc > 1.0:
            for i in range(1, int(inc)):
                an = i * bin_size
                rn = dd / (2.0 * math.sin(an / 2.0))
                xn = rn * math.sin(an)
                yn = rn - rn * math.cos(an)
                prims += [(xn, yn, float(i), S.LEFT), (xn, -yn, -float(i), S.RIGHT)]
                if rs:
                    prims += [(-xn, yn, -float(i), S.REV_LEFT), (-xn, -yn, float(i), S.REV_RIGHT)]
        th = bin_size * np.arange(bins)
        c, s = np.cos(th), np.sin(th)
        px = np.array([p[0] for p in prims])
        py = np.array([p[1] for p in prims])
        proj_dx = px[:, None] * c[None, :] - py[:, None] * s[None, :]
        proj_dy = px[:, None] * s[None, :] + py[:, None] * c[None, :]
        dth = np.array([p[2] for p in prims])
        turn = np.array([p[3] for p in prims], dtype=np.int64)
        travel = np.empty(len(prims))
        for i, p in enumerate(prims):
            if p[3] in (S.FORWARD, S.REVERSE):
                travel[i] = dd
            else:
                a = abs(p[2]) * bin_size
                travel[i] = dd / (2.0 * math.sin(a / 2.0)) * a
        return proj_dx, proj_dy, dth, turn, travel

    def _footprints(self, bins: int, res: float) -> np.ndarray:
        if self.use_radius or self.footprint is None:
            return np.zeros((bins, 1, 2))
        fp = self.footprint / res
        th = 2.0 * math.pi / bins * np.arange(bins)
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        out = np.empty((bins, fp.shape[0], 2))
        out[:, :, 0] = fp[None, :, 0] * c - fp[None, :, 1] * s
        out[:, :, 1] = fp[None, :, 0] * s + fp[None, :, 1] * c
        return out

    def _bin(self, yaw: float) -> int:
        bins = self.config.angle_quantization_bins
        b = round(yaw / (2.0 * math.pi / bins))
        while b < 0:
            b += bins
        if b >= bins:
            b -= bins
        return int(b)

    # --- planning ----------------------------------------------------------------------------
    def create_plan(
        self, start: npt.ArrayLike, goal: npt.ArrayLike, costmap: Costmap2D
    ) -> npt.NDArray[np.float64]:
        _load_kernels(self)
        t0 = time.perf_counter()
        cfg = self.config
        s = as_pose(start)
        g = as_pose(goal)
        grid, res = _search_grid(costmap, cfg.downsample_costmap, cfg.downsampling_factor)
        ms = _map_continuous(costmap, s[0], s[1])
        if ms is None:
            raise StartOutsideMapBounds(f"start ({s[0]:.2f}, {s[1]:.2f}) is outside the costmap")
        mg = _map_continuous(costmap, g[0], g[1])
        if mg is None:
            raise GoalOutsideMapBounds(f"goal ({g[0]:.2f}, {g[1]:.2f}) is outside the costmap")
        k = costmap.resolution / res
        sx, sy, gx, gy = ms[0] * k, ms[1] * k, mg[0] * k, mg[1] * k
        sbin, gbin = self._bin(s[2]), self._bin(g[2])
        if int(sx) == int(gx) and int(sy) == int(gy):
            return np.array([[s[0], s[1], g[2]]])
        bins = cfg.angle_quantization_bins
        rho = max(cfg.minimum_turning_radius, res) / res
        fps = self._footprints(bins, res)
        pcost = self.possible_collision_cost
        coll, _ = S._in_collision(grid, sx, sy, sbin, cfg.allow_unknown, self.use_radius,
                                  pcost, fps)
        if coll:
            raise StartOccupied(f"start ({s[0]:.2f}, {s[1]:.2f}, {s[2]:.2f}) is in collision")
        goal_blocked = S._in_collision(grid, gx, gy, gbin, cfg.allow_unknown, self.use_radius,
                                       pcost, fps)[0]
        tol = cfg.tolerance / res
        if goal_blocked and tol < 0.001:
            raise GoalOccupied(f"goal ({g[0]:.2f}, {g[1]:.2f}, {g[2]:.2f}) is in collision")
        h_obs = self._obstacle_heuristic(grid, gx, gy)
        lookup = float(int(cfg.lookup_table_size / res))
        if int(lookup) % 2 == 0:
            lookup += 1.0
        pdx, pdy, pdth, turn, travel = self._motion_table(rho)
        status, poses, its = S.hybrid_astar(
            grid, sx, sy, sbin, gx, gy, gbin, bins, pdx, pdy, pdth, turn, travel, rho,
            cfg.motion_model_for_search == "REEDS_SHEPP", cfg.non_straight_penalty,
            cfg.change_penalty, cfg.reverse_penalty, cfg.cost_penalty,
            cfg.use_quadratic_cost_penalty,
            cfg.retrospective_penalty, cfg.analytic_expansion_ratio,
            cfg.analytic_expansion_max_length / res, cfg.analytic_expansion_max_cost,
            cfg.analytic_expansion_max_cost_override, lookup, h_obs,
            cfg.downsample_obstacle_heuristic, cfg.allow_unknown, self.use_radius, pcost, fps,
            tol, _limit(cfg.max_iterations), _limit(cfg.max_on_approach_iterations),
            cfg.terminal_checking_interval, cfg.max_planning_time)
        self.last_iterations = int(its)
        if status != S.FOUND:
            _raise_failure(int(status), int(its), "SmacPlannerHybrid", goal_blocked, g)
        out = np.empty((poses.shape[0], 3))
        out[:, 0] = costmap.origin_x + poses[:, 0] * res
        out[:, 1] = costmap.origin_y + poses[:, 1] * res
        out[:, 2] = np.remainder(poses[:, 2] * (2.0 * math.pi / bins) + math.pi,
                                 2.0 * math.pi) - math.pi
        self.last_reversing = poses[:, 3].astype(bool)
        self.last_raw_path = out.copy()
        if cfg.smooth_path and its > 1:
            remaining = cfg.max_planning_time - (time.perf_counter() - t0)
            out = smooth_path(out, grid, costmap.origin_x, costmap.origin_y, res, cfg.smoother,
                              False, remaining, rho * res)
        if abs(out[-1, 0] - g[0]) < 1e-9 and abs(out[-1, 1] - g[1]) < 1e-9:
            out[-1, 2] = g[2]  # the goal's exact yaw, not its bin's
        return out

    def _obstacle_heuristic(self, grid: np.ndarray, gx: float, gy: float) -> np.ndarray:
        cfg = self.config
        key = (int(gx), int(gy), grid.shape, cfg.cost_penalty)
        if cfg.cache_obstacle_heuristic and self._h_cache is not None \
                and self._h_cache[0] == key:
            return self._h_cache[1]
        h = S.obstacle_heuristic(grid, gx, gy, cfg.cost_penalty,
                                 cfg.downsample_obstacle_heuristic,
                                 cfg.use_quadratic_cost_penalty)
        self._h_cache = (key, h)
        return h


__all__ = [
    "MOTION_MODELS",
    "SmacPlanner2D",
    "SmacPlanner2DConfig",
    "SmacPlannerHybrid",
    "SmacPlannerHybridConfig",
    "SmacSmootherConfig",
]
