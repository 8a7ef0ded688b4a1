"""Range-sensor safety: what the motors may get (pure core) and the ``emergency_status`` node.

Core (no bus, no clock: every call takes ``now_ns``):

- :class:`VetoState` keeps each IR/PING reading with its time and answers which sensors
  forbid forward motion: a return in the corridor the robot sweeps closer than
  ``veto_distance`` (default 0.25 m) to its front, a reading older than ``stale_after``
  (default 0.5 s), an expected sensor that never reported, or — before any reading at all —
  :data:`NO_READING_YET`. Unknown is unsafe. ``+inf`` (REP-117: nothing in range) never
  vetoes, ``-inf`` (closer than the sensor can measure) always does; NaN is no reading, so a
  sensor that only sends NaN goes stale after ``stale_after`` rather than at once. An IR
  return counts only after ``ir_debounce`` consecutive samples (the GP2Y0A21 is spiky);
  PING is not debounced.
- :func:`limit_twist` turns a command into the one the motors may get: forward motion stops
  inside the veto and slows linearly in the ``slowdown_distance`` band beyond it, arcs keep
  their curvature (and are judged on their own path: a jamb beside the robot on the side
  it turns away from does not slow it), rotation in place passes, reverse is capped at ``max_reverse_speed``
  because Eddie has no rear sensors.

The board node applies :func:`limit_twist` last before GOSPD, so every command source is
covered, and publishes its verdict on :data:`SAFETY_VETO_TOPIC`; :class:`SafetyNode` serves
the original stack's ``emergency_status`` from that one verdict, so the two never disagree.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from eddiebot.core.node import Node
from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.core.qos import qos_profile_latched
from eddiebot.msgs.eddiebot_msgs import GetStatus
from eddiebot.msgs.std_msgs import Bool
from eddiebot.robot.constants import IR_SENSORS, PING_SENSORS, RangeSensorMount, SensorKind

__all__ = [
    "NO_READING_YET",
    "SAFETY_VETO_QOS",
    "SAFETY_VETO_TOPIC",
    "BoardVetoMonitor",
    "SafetyConfig",
    "SafetyNode",
    "VetoState",
    "declare_safety_parameters",
    "forward_factor",
    "limit_twist",
]

SAFETY_VETO_TOPIC = "/eddie/safety_veto"
"""``std_msgs/Bool``: the board node's veto (true = forward motion refused), sent every poll."""
SAFETY_VETO_QOS = qos_profile_latched
"""Depth 1, transient-local: a late ``emergency_status`` server gets the last verdict."""
NO_READING_YET = "no reading yet"
"""What :meth:`VetoState.too_close` names while no sensor has reported at all."""

#: Margin (m) beside the robot's radius within which a return counts as in its path.
_CORRIDOR_MARGIN_M = 0.02


@dataclass(frozen=True)
class SafetyConfig:
    """The veto's parameters (node parameters of the same names; ``enabled`` is ``veto_enabled``).

    ``slowdown_distance`` defaults to 0.5 m: the band then ends 0.75 m ahead of the front,
    which the centre GP2Y0A21 (mounted 1.5 cm behind the front edge, rated to 0.80 m) still
    covers, so both sensor kinds see the whole band; a robot entering it at nav2's 0.26 m/s
    is down to half speed 0.25 m later, so the ≤ 0.32 s STOP ramp starts from ≤ 0.1 m/s at
    the veto line instead of from full speed.

    ``enabled=False`` turns the range veto and the slowdown off; the reverse cap stays,
    because it stands for the rear sensors Eddie does not have, not for the ones that may be
    misbehaving (``max_reverse_speed=inf`` lifts it).
    """

    veto_distance: float = 0.25
    """Forward motion stops when a return in the path is this close to the front (m)."""
    enabled: bool = True
    stale_after: float = 0.5
    """A sensor whose latest reading is older than this (s) counts as unsafe."""
    slowdown_distance: float = 0.5
    """Width of the band beyond ``veto_distance`` where forward speed scales to 0 (m)."""
    max_reverse_speed: float = 0.1
    """Cap on backward speed (m/s): reverse is blind on Eddie."""
    ir_debounce: int = 2
    """Consecutive IR samples in the corridor before an IR return counts."""

    def __post_init__(self) -> None:
        if not self.veto_distance >= 0.0:
            raise ValueError(f"veto_distance must be >= 0 m, got {self.veto_distance}")
        if not self.stale_after > 0.0:
            raise ValueError(f"stale_after must be > 0 s, got {self.stale_after}")
        if not self.slowdown_distance >= 0.0:
            raise ValueError(f"slowdown_distance must be >= 0 m, got {self.slowdown_distance}")
        if not self.max_reverse_speed >= 0.0:
            raise ValueError(f"max_reverse_speed must be >= 0 m/s, got {self.max_reverse_speed}")
        if self.ir_debounce < 1:
            raise ValueError(f"ir_debounce must be >= 1 sample, got {self.ir_debounce}")


@dataclass
class VetoState:
    """Range readings with their times, and which of them forbid forward motion.

    A reading becomes a point in the base frame through its sensor's mount (``mounts``:
    name → (x, y, yaw) in base_link, from the sensor table). It is in the robot's way when
    it lies in the corridor the robot would sweep — within ``robot_radius`` + 2 cm of the
    centre line, ahead of the centre — and its distance ahead of the front is what the
    thresholds compare. Door jambs beside the robot (a 0.9 m door leaves 0.22 m each side)
    therefore do not stop it, a wall ahead does. Sensors without a mount fall back to the
    plain range.

    ``expected`` names sensors that must report (one that never did is unsafe; default
    none, so only "nothing at all yet" is); ``debounced`` (default: Eddie's IR sensors)
    names sensors whose return counts only when each of their last ``ir_debounce``
    samples agrees — the farthest of them is used, so a single spike does not count, while
    before the window has filled (start-up) the samples there are count as they are.
    :meth:`from_config` builds the state for a given sensor set, every sensor expected.
    """

    ranges: dict[str, float] = field(default_factory=dict)
    """Latest raw reading per sensor (m, REP-117 ±inf, NaN as received)."""
    veto_distance: float = 0.25
    mounts: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    robot_radius: float = 0.2245
    stale_after: float = 0.5
    ir_debounce: int = 2
    debounced: frozenset[str] = frozenset(s.name for s in IR_SENSORS)
    expected: frozenset[str] = frozenset()
    _history: dict[str, deque[float]] = field(default_factory=dict, init=False, repr=False)
    _stamp_ns: dict[str, int] = field(default_factory=dict, init=False, repr=False)
    _latest_ns: int | None = field(default=None, init=False, repr=False)

    @classmethod
    def from_config(
        cls,
        config: SafetyConfig,
        sensors: Iterable[RangeSensorMount] = (*IR_SENSORS, *PING_SENSORS),
        robot_radius: float = 0.2245,
    ) -> VetoState:
        """A state for ``sensors`` (default: Eddie's three IR and two PING))) ), all expected,
        the IR ones debounced. Leave out sensors that are switched off (``ping_mask``), or
        their silence vetoes forward motion for good."""
        sensors = tuple(sensors)
        return cls(
            veto_distance=config.veto_distance,
            mounts={s.name: (s.x_m, s.y_m, s.yaw_rad) for s in sensors},
            robot_radius=robot_radius,
            stale_after=config.stale_after,
            ir_debounce=config.ir_debounce,
            debounced=frozenset(s.name for s in sensors if s.kind == SensorKind.IR),
            expected=frozenset(s.name for s in sensors),
        )

    def update(self, ranges: Mapping[str, float], now_ns: int | None = None) -> None:
        """Record readings (m) taken at ``now_ns``. NaN is no reading: it does not refresh
        the sensor's time. Without ``now_ns`` (old callers) the readings take the time of
        the latest timed update, so an untimed state never goes stale."""
        t = now_ns if now_ns is not None else (self._latest_ns or 0)
        for name, r in ranges.items():
            r = float(r)
            self.ranges[name] = r
            if math.isnan(r):
                continue
            window = self.ir_debounce if name in self.debounced else 1
            history = self._history.get(name)
            if history is None or history.maxlen != window:
                history = self._history[name] = deque(history or (), maxlen=window)
            history.append(r)
            self._stamp_ns[name] = t
        self._latest_ns = t if self._latest_ns is None else max(self._latest_ns, t)

    @property
    def last_update_ns(self) -> int | None:
        """Time of the latest update (ns), None before the first."""
        return self._latest_ns

    def _ahead_of_front(self, name: str, r: float, curvature: float = 0.0) -> float:
        """How far ahead of the robot's front reading ``r`` of ``name`` lies (m); +inf when
        it is not in the robot's path (see :meth:`obstacles` for ``curvature``); -inf (too
        close to measure) stays -inf unmounted."""
        if r == math.inf:
            return math.inf
        mount = self.mounts.get(name)
        if mount is None:
            return r
        mx, my, myaw = mount
        rr = 0.0 if r == -math.inf else r  # the obstacle is at the sensor itself
        px, py = mx + rr * math.cos(myaw), my + rr * math.sin(myaw)
        half_width = self.robot_radius + _CORRIDOR_MARGIN_M
        if abs(py) > half_width or px < 0.0:
            return math.inf
        if py * curvature < 0.0 and r != -math.inf:
            # beside the path on the side the arc turns away from: in the way only when
            # inside the band the arc sweeps (centre (0, 1/k), radius 1/|k| ± half width)
            radius = 1.0 / abs(curvature)
            if math.hypot(px, abs(py) + radius) > radius + half_width:
                return math.inf
        return px - self.robot_radius

    def obstacles(self, now_ns: int, curvature: float = 0.0) -> dict[str, float]:
        """Per sensor, the distance (m) ahead of the front of its return in the robot's path
        (+inf: clear), -inf for a sensor that is stale or expected and not yet seen;
        ``{NO_READING_YET: -inf}`` while nothing has reported.

        The path is the straight corridor ahead, for ``curvature`` (rad/m, left positive) 0.
        For an arc, a return in that corridor on the side the arc turns away from is in
        the path only when the band the arc sweeps holds it: a door jamb beside a robot
        that turns into the door does not slow it down. Returns on the side it turns
        towards, and on the centre line, are judged as for the straight path (a sensor
        sees a point of what may be a wall across the arc)."""
        names = set(self.expected) | set(self._stamp_ns)
        if not names:
            return {NO_READING_YET: -math.inf}
        stale_ns = self.stale_after * 1e9
        out: dict[str, float] = {}
        for name in sorted(names):
            stamp = self._stamp_ns.get(name)
            history = self._history.get(name)
            if stamp is None or history is None or now_ns - stamp > stale_ns:
                out[name] = -math.inf
            else:
                # debounced: a return counts at the farthest of the window's samples, so one
                # spike does not; a window not yet full (start-up) counts what it has
                out[name] = max(self._ahead_of_front(name, r, curvature) for r in history)
        return out

    def clearance(self, now_ns: int, curvature: float = 0.0) -> float:
        """Free distance ahead of the front (m): the nearest obstacle in the path (straight,
        or the arc of ``curvature``: :meth:`obstacles`), -inf when anything is unknown,
        +inf when the path is clear."""
        return min(self.obstacles(now_ns, curvature).values())

    def too_close(self, now_ns: int, distance: float | None = None) -> list[str]:
        """Sensors that forbid forward motion at ``now_ns``: a return in the path within
        ``distance`` (default ``veto_distance``) of the front, stale, or not yet seen."""
        d = self.veto_distance if distance is None else distance
        return [name for name, ahead in self.obstacles(now_ns).items() if ahead <= d]

    def vetoed_at(self, now_ns: int) -> bool:
        """Whether forward motion is refused at ``now_ns``."""
        return bool(self.too_close(now_ns))


def forward_factor(state: VetoState, config: SafetyConfig, now_ns: int,
                   curvature: float = 0.0) -> float:
    """Share of a forward command along an arc of ``curvature`` (rad/m; 0 straight) the
    motors may get: 0 within ``veto_distance`` (or when anything is unknown), rising
    linearly to 1 at ``veto_distance + slowdown_distance``."""
    if not config.enabled:
        return 1.0
    clear = state.clearance(now_ns, curvature)
    if clear <= config.veto_distance:
        return 0.0
    if clear >= config.veto_distance + config.slowdown_distance:
        return 1.0
    return (clear - config.veto_distance) / config.slowdown_distance


def limit_twist(
    linear: float, angular: float, state: VetoState, config: SafetyConfig, now_ns: int
) -> tuple[float, float]:
    """The (linear m/s, angular rad/s) the motors may get for the command (linear, angular).

    - forward: scaled by :func:`forward_factor` of the arc's own path (a return beside
      the robot on the side it turns away from counts only inside the band the arc
      sweeps), angular too so an arc slows down along the same curve instead of
      tightening; a vetoed arc becomes (0, 0), not a spin in place;
    - rotation in place (linear == 0): unchanged — the robot is round, turning sweeps
      nothing new, and it is how the robot gets itself out;
    - reverse: capped at ``max_reverse_speed``, angular scaled to keep the curvature;
      applied even when ``config.enabled`` is false;
    - a NaN or infinite component: (0, 0).
    """
    if not (math.isfinite(linear) and math.isfinite(angular)):
        return 0.0, 0.0
    if linear < 0.0:
        if -linear <= config.max_reverse_speed:
            return linear, angular
        scale = config.max_reverse_speed / -linear
        return -config.max_reverse_speed + 0.0, angular * scale
    if linear == 0.0:
        return 0.0, angular
    factor = forward_factor(state, config, now_ns, angular / linear)
    if factor == 0.0:
        return 0.0, 0.0
    return linear * factor, angular * factor


@dataclass
class BoardVetoMonitor:
    """The board node's latest veto as ``emergency_status`` sees it: okay only while a
    verdict younger than ``stale_after_ns`` says "not vetoed" (no board = not okay)."""

    stale_after_ns: int = 500_000_000
    vetoed: bool | None = None
    received_ns: int | None = None

    def on_veto(self, vetoed: bool, now_ns: int) -> None:
        self.vetoed, self.received_ns = bool(vetoed), now_ns

    def okay(self, now_ns: int) -> bool:
        if self.vetoed is None or self.received_ns is None:
            return False
        return not self.vetoed and now_ns - self.received_ns <= self.stale_after_ns


# -- node part ----------------------------------------------------------------------------------


def declare_safety_parameters(node: Node) -> SafetyConfig:
    """Declare the veto's parameters on ``node`` (``veto_distance``, ``veto_enabled``,
    ``stale_after``, ``slowdown_distance``, ``max_reverse_speed``, ``ir_debounce``) and
    return them as a validated :class:`SafetyConfig`."""
    d = SafetyConfig()
    return SafetyConfig(
        veto_distance=float(node.declare_parameter("veto_distance", d.veto_distance).value),
        enabled=bool(node.declare_parameter("veto_enabled", d.enabled).value),
        stale_after=float(node.declare_parameter("stale_after", d.stale_after).value),
        slowdown_distance=float(node.declare_parameter("slowdown_distance", d.slowdown_distance).value),
        max_reverse_speed=float(node.declare_parameter("max_reverse_speed", d.max_reverse_speed).value),
        ir_debounce=int(node.declare_parameter("ir_debounce", d.ir_debounce).value),
    )


class SafetyNode(Node):
    """Serves the original ``emergency_status`` (GetStatus) from the board node's veto on
    ``/eddie/safety_veto`` (Bool, depth 1, transient-local): ``okay`` is false while the
    board vetoes, when its latest verdict is older than ``stale_after`` (s, default 0.5) —
    Bool has no stamp, so age counts from arrival — and before any verdict arrived."""

    default_node_name = "eddie_safety"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        stale_after = float(self.declare_parameter(
            "stale_after", SafetyConfig.stale_after, ParameterDescriptor(read_only=True)).value)
        if not stale_after > 0.0:
            raise ValueError(f"{self.fully_qualified_name}: stale_after must be > 0 s")
        self.monitor = BoardVetoMonitor(stale_after_ns=round(stale_after * 1e9))
        self.create_subscription(Bool, SAFETY_VETO_TOPIC, self._on_veto, SAFETY_VETO_QOS)
        self.create_service(GetStatus, "emergency_status", self._status)

    def _on_veto(self, msg: Any) -> None:
        self.monitor.on_veto(bool(msg.data), self.get_clock().now_ns())

    def _status(self, req: Any, res: Any) -> Any:
        res.okay = self.monitor.okay(self.get_clock().now_ns())
        return res
