"""The range layer: sonar and IR cones through Nav2's ``RangeSensorLayer`` probabilistic model."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import (
    FREE_SPACE,
    LETHAL_OBSTACLE,
    NO_INFORMATION,
)
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.costmap.layers.base import (
    Bounds,
    CostmapLayer,
    touch,
    update_with_max,
)
from eddiebot.nav.params import require


@dataclass(frozen=True)
class RangeLayerConfig:
    """``range_sensor_layer`` parameters (Jazzy code defaults)."""

    enabled: bool = True
    topics: tuple[str, ...] = ("",)
    phi: float = 1.2
    inflate_cone: float = 1.0
    no_readings_timeout: float = 0.0
    clear_threshold: float = 0.2
    mark_threshold: float = 0.8
    clear_on_max_reading: bool = False
    input_sensor_type: str = "ALL"
    # eddiebot: "probabilistic" (Nav2's model) or "deterministic" (see RangeLayer)
    sensor_model: str = "probabilistic"

    def validate(self, server: str = "range_layer") -> None:
        require(self.input_sensor_type in ("ALL", "VARIABLE", "FIXED"), server,
                "input_sensor_type", self.input_sensor_type, "must be ALL, VARIABLE or FIXED")
        require(self.inflate_cone >= 0.0, server, "inflate_cone", self.inflate_cone, "must be >= 0")
        require(self.sensor_model in ("probabilistic", "deterministic"), server, "sensor_model",
                self.sensor_model, "must be probabilistic or deterministic")
        require(0.0 <= self.clear_threshold <= 1.0, server, "clear_threshold",
                self.clear_threshold, "must be a probability in [0, 1]")
        require(0.0 <= self.mark_threshold <= 1.0, server, "mark_threshold",
                self.mark_threshold, "must be a probability in [0, 1]")


@dataclass(frozen=True)
class RangeReading:
    """A ``sensor_msgs/Range`` reading with its sensor pose (x, y, yaw) in the global frame."""

    pose: tuple[float, float, float]
    field_of_view: float
    min_range: float
    max_range: float
    range: float


class RangeLayer(CostmapLayer):
    """Sonar/IR cones (``nav2_costmap_2d::RangeSensorLayer``).

    ``sensor_model: probabilistic`` (the default) is Nav2's model: the layer keeps an
    occupancy probability per cell (``cost / 254``, unknown cells start at 0.5) and every
    reading updates the cells of its cone by Bayes' rule with the sensor model of
    ``sensor_model()`` -- a clearing zone up to ``r - 2·res·r``, a marking band
    ``r ± res·r`` (res = the costmap resolution in m, as upstream), both weighted by
    ``delta(phi) = 1 - (1 + tanh(2 (phi - phi_v))) / 2`` (less trust far away, ``phi``) and
    ``gamma(theta) = 1 - (theta / half_fov)^2`` (less trust at the cone's edge). The cell of
    the measured point is first set to 233. With ``inflate_cone`` < 1 only the cells inside
    the cone's triangle, grown by ``inflate_cone`` (upstream's barycentric test), are updated;
    at 1 the whole bounding box of the triangle is. Cells above ``mark_threshold`` write
    LETHAL into the master, cells below ``clear_threshold`` FREE (into unknown or lower
    master cells only). Fixed rangers (``min_range == max_range``) report -inf (object) or
    +inf (nothing); variable ones are ignored outside [min_range, max_range], and a
    max-range reading clears the cone (sensor probability 0) with ``clear_on_max_reading``
    and is otherwise an ordinary reading. ``no_readings_timeout`` > 0 makes the layer
    not current when no reading arrived for that long (needs :meth:`set_time`).

    ``sensor_model: deterministic`` (eddiebot): a reading inside [min_range, max_range)
    marks the cells on the arc at the measured range (within the cone half-angle
    ``field_of_view/2 · inflate_cone``) LETHAL and clears the cells of the cone nearer than
    the arc; a max-range reading clears the whole cone when ``clear_on_max_reading`` is set
    and is otherwise ignored; readings below min_range are ignored.
    """

    clearable = True

    def __init__(self, name: str = "range_layer", config: RangeLayerConfig | None = None) -> None:
        super().__init__(name)
        self.config = config or RangeLayerConfig()
        self.config.validate(name)
        self.enabled = self.config.enabled
        self._pending: list[RangeReading] = []
        self._probabilistic = self.config.sensor_model == "probabilistic"
        self._now_ns: int | None = None
        self._last_reading_ns: int | None = None
        self._buffered = 0
        self._was_reset = False

    def _default_value(self) -> int:
        if self._probabilistic:
            return _to_cost(0.5)  # upstream default_value_
        return super()._default_value()

    def add_reading(self, reading: RangeReading) -> None:
        self._pending.append(reading)

    def set_time(self, now_ns: int) -> None:
        """The clock for ``no_readings_timeout`` (upstream reads the node clock)."""
        self._now_ns = int(now_ns)
        if self._last_reading_ns is None:
            self._last_reading_ns = self._now_ns

    def reset(self) -> None:
        self.costmap.reset_all()
        self._pending.clear()
        self._was_reset = True

    def update_bounds(self, robot_x: float, robot_y: float, robot_yaw: float, bounds: Bounds) -> None:
        if not self.enabled:
            self._pending.clear()
            self.current = True
            return
        self._use_extra_bounds(bounds)
        for rd in self._pending:
            used = self._process(rd, bounds) if self._probabilistic else self._apply(rd, bounds)
            if used:
                self._buffered += 1
                if self._now_ns is not None:
                    self._last_reading_ns = self._now_ns
        self._pending.clear()
        timeout = self.config.no_readings_timeout
        if (self._buffered == 0 and timeout > 0.0 and self._now_ns is not None
                and self._last_reading_ns is not None
                and (self._now_ns - self._last_reading_ns) * 1e-9 > timeout):
            self.current = False

    # -- Nav2's probabilistic model ------------------------------------------------------------
    def _process(self, rd: RangeReading, bounds: Bounds) -> bool:
        r = rd.range
        fixed = self.config.input_sensor_type == "FIXED" or (
            self.config.input_sensor_type == "ALL" and rd.min_range == rd.max_range)
        clear = False
        if fixed:
            if not math.isinf(r):
                return False  # only -inf (object) and +inf (nothing) are valid
            if r > 0:
                if not self.config.clear_on_max_reading:
                    return False
                clear = True
            r = rd.min_range
        else:
            if not (rd.min_range <= r <= rd.max_range):
                return False  # also NaN
            clear = r >= rd.max_range and self.config.clear_on_max_reading
        self._update_cone(rd, r, clear, bounds)
        return True

    def _update_cone(self, rd: RangeReading, r: float, clear: bool, bounds: Bounds) -> None:
        cm = self.costmap
        res = cm.resolution
        ox, oy, theta = rd.pose
        half = 0.5 * rd.field_of_view
        tx, ty = ox + r * math.cos(theta), oy + r * math.sin(theta)
        o = cm.world_to_map_no_bounds(ox, oy)
        touch(bounds, ox, oy)
        hit = cm.world_to_map(tx, ty)
        if hit is not None:
            cm.data[hit[1], hit[0]] = 233
            touch(bounds, tx, ty)
        d = abs(r)
        ax, ay = ox + math.cos(theta - half) * d * 1.2, oy + math.sin(theta - half) * d * 1.2
        bx, by = ox + math.cos(theta + half) * d * 1.2, oy + math.sin(theta + half) * d * 1.2
        a = cm.world_to_map_no_bounds(ax, ay)
        b = cm.world_to_map_no_bounds(bx, by)
        touch(bounds, ax, ay)
        touch(bounds, bx, by)
        i0 = max(0, min(o[0], a[0], b[0]))
        j0 = max(0, min(o[1], a[1], b[1]))
        i1 = min(cm.size_x - 1, max(o[0], a[0], b[0]))  # upstream loops to size (then skips)
        j1 = min(cm.size_y - 1, max(o[1], a[1], b[1]))
        if i1 < i0 or j1 < j0:
            return
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
        if self.config.inflate_cone < 1.0:
            def orient(p: tuple[int, int], q: tuple[int, int]) -> npt.NDArray[np.int64]:
                return (q[0] - p[0]) * (jj - p[1]) - (q[1] - p[1]) * (ii - p[0])

            area = abs((a[0] * (b[1] - o[1]) + b[0] * (o[1] - a[1]) + o[0] * (a[1] - b[1])) / 2.0)
            th = -float(np.float32(self.config.inflate_cone)) * area
            sel = (orient(a, b) >= th) & (orient(b, o) >= th) & (orient(o, a) >= th)
        else:
            sel = np.ones(ii.shape, dtype=bool)
        cx = cm.origin_x + (ii + 0.5) * res
        cy = cm.origin_y + (jj + 0.5) * res
        dx, dy = cx - ox, cy - oy
        phi = np.hypot(dx, dy)
        ang = (np.arctan2(dy, dx) - theta + math.pi) % (2.0 * math.pi) - math.pi
        sensor = np.zeros(phi.shape) if clear else sensor_model(
            r, phi, ang, half, self.config.phi, res)
        win = cm.data[j0:j1 + 1, i0:i1 + 1]
        prior = win.astype(np.float64) / LETHAL_OBSTACLE
        occ = sensor * prior
        not_occ = (1.0 - sensor) * (1.0 - prior)
        with np.errstate(invalid="ignore", divide="ignore"):
            post = occ / (occ + not_occ)
        sel &= np.isfinite(post)
        win[sel] = _to_cost_array(post[sel])

    # -- eddiebot's deterministic rule ---------------------------------------------------------
    def _apply(self, rd: RangeReading, bounds: Bounds) -> bool:
        r = rd.range
        if not math.isfinite(r) or r < rd.min_range or r > rd.max_range:
            return False
        at_max = r >= rd.max_range
        if at_max and not self.config.clear_on_max_reading:
            return False
        cm = self.costmap
        res = cm.resolution
        sx, sy, syaw = rd.pose
        half = 0.5 * rd.field_of_view * self.config.inflate_cone
        reach = r + res
        xs = [sx, sx + reach * math.cos(syaw - half), sx + reach * math.cos(syaw + half),
              sx + reach * math.cos(syaw)]
        ys = [sy, sy + reach * math.sin(syaw - half), sy + reach * math.sin(syaw + half),
              sy + reach * math.sin(syaw)]
        i0, j0 = cm.world_to_map_enforce_bounds(min(xs) - res, min(ys) - res)
        i1, j1 = cm.world_to_map_enforce_bounds(max(xs) + res, max(ys) + res)
        ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
        cx = cm.origin_x + (ii + 0.5) * res
        cy = cm.origin_y + (jj + 0.5) * res
        d = np.hypot(cx - sx, cy - sy)
        ang = np.abs((np.arctan2(cy - sy, cx - sx) - syaw + math.pi) % (2 * math.pi) - math.pi)
        in_cone = ang <= half
        win = cm.data[j0:j1 + 1, i0:i1 + 1]
        if at_max:
            win[in_cone & (d <= r)] = FREE_SPACE
        else:
            win[in_cone & (d < r - 0.5 * res)] = FREE_SPACE
            win[in_cone & (np.abs(d - r) <= 0.5 * res)] = LETHAL_OBSTACLE
            hit = cm.world_to_map(sx + r * math.cos(syaw), sy + r * math.sin(syaw))
            if hit is not None:
                cm.data[hit[1], hit[0]] = LETHAL_OBSTACLE
        touch(bounds, min(xs), min(ys))
        touch(bounds, max(xs), max(ys))
        return True

    def update_costs(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int) -> None:
        if not self.enabled:
            return
        if self._probabilistic:
            self._update_costs_probabilistic(master, i0, j0, i1, j1)
        else:
            update_with_max(master, self.costmap, i0, j0, i1, j1)
        self._buffered = 0
        if not self.current and self._was_reset:
            self._was_reset = False
            self.current = True

    def _update_costs_probabilistic(self, master: Costmap2D, i0: int, j0: int, i1: int, j1: int
                                    ) -> None:
        s = self.costmap.data[j0:j1, i0:i1]
        m = master.data[j0:j1, i0:i1]
        mark = _to_cost(self.config.mark_threshold)
        clear = _to_cost(self.config.clear_threshold)
        known = s != NO_INFORMATION
        cur = np.full(s.shape, -1, dtype=np.int16)
        cur[known & (s > mark)] = LETHAL_OBSTACLE
        cur[known & (s < clear)] = FREE_SPACE
        write = (cur >= 0) & ((m == NO_INFORMATION) | (m.astype(np.int16) < cur))
        m[write] = cur[write].astype(np.uint8)


def _to_cost(p: float) -> int:
    """Upstream ``to_cost``: probability -> cost, truncated (``p · 254``)."""
    return int(p * LETHAL_OBSTACLE)


def _to_cost_array(p: npt.NDArray[np.float64]) -> npt.NDArray[np.uint8]:
    return np.clip(np.trunc(p * LETHAL_OBSTACLE), 0, 255).astype(np.uint8)


def sensor_model(r: float, phi: npt.ArrayLike, theta: npt.ArrayLike, half_fov: float,
                 phi_v: float = 1.2, resolution: float = 0.05) -> npt.NDArray[np.float64]:
    """Nav2 ``RangeSensorLayer::sensor_model``: occupancy probability of a cell at distance
    ``phi`` and bearing ``theta`` (rad, from the cone axis) for a reading ``r`` (m)."""
    phi = np.asarray(phi, dtype=np.float64)
    theta = np.asarray(theta, dtype=np.float64)
    gamma = np.where(np.abs(theta) > half_fov, 0.0,
                     1.0 - (theta / half_fov) ** 2 if half_fov > 0 else 0.0)
    lbda = (1.0 - (1.0 + np.tanh(2.0 * (phi - phi_v))) / 2.0) * gamma
    dr = resolution * r
    out = np.full(phi.shape, 0.5)
    if dr <= 0.0:  # upstream divides by zero here; keep the prior instead
        near = (phi >= 0.0) & (phi < r)
        out[near] = (1.0 - lbda[near]) * 0.5
        return out
    near = (phi >= 0.0) & (phi < r - 2.0 * dr)
    rise = ~near & (phi < r - dr)
    band = ~near & ~rise & (phi < r + dr)
    out[near] = (1.0 - lbda[near]) * 0.5
    out[rise] = (lbda[rise] * 0.5 * ((phi[rise] - (r - 2.0 * dr)) / dr) ** 2
                 + (1.0 - lbda[rise]) * 0.5)
    j = (r - phi[band]) / dr
    out[band] = lbda[band] * ((1.0 - 0.5 * j ** 2) - 0.5) + 0.5
    return out


# --- inflation layer ---------------------------------------------------------------------
