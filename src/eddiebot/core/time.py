"""Time in integer nanoseconds, and the clocks that tell it.

Nothing else in the package reads the wall clock: nodes ask their ``Clock``; pure cores
receive times as arguments. A ``SimClock`` is advanced by whoever owns it (the executor
jumps it to the next due timer, or ``/clock`` messages set it).
"""

from __future__ import annotations

import enum
import threading
import time as _time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from eddiebot.msgs.builtin_interfaces import Duration as DurationMsg
from eddiebot.msgs.builtin_interfaces import Time as TimeMsg

NS_PER_S = 1_000_000_000


@dataclass(frozen=True, order=True)
class Duration:
    """A signed span of time in integer nanoseconds."""

    nanoseconds: int = 0

    @classmethod
    def from_seconds(cls, seconds: float) -> Duration:
        return cls(round(seconds * NS_PER_S))

    @classmethod
    def from_msg(cls, msg: Any) -> Duration:
        return cls(int(msg.sec) * NS_PER_S + int(msg.nanosec))

    def to_seconds(self) -> float:
        return self.nanoseconds / NS_PER_S

    def to_msg(self) -> Any:
        sec, nsec = divmod(self.nanoseconds, NS_PER_S)
        return DurationMsg(sec=sec, nanosec=nsec)

    def __add__(self, other: Duration) -> Duration:
        return Duration(self.nanoseconds + other.nanoseconds)

    def __sub__(self, other: Duration) -> Duration:
        return Duration(self.nanoseconds - other.nanoseconds)

    def __neg__(self) -> Duration:
        return Duration(-self.nanoseconds)


class ClockType(enum.IntEnum):
    """As rcl: ROS time follows /clock when use_sim_time is set; system and steady do not."""

    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


@dataclass(frozen=True, order=True)
class Time:
    """A point in time: integer nanoseconds since the clock's epoch."""

    nanoseconds: int = 0
    clock_type: ClockType = ClockType.ROS_TIME

    @classmethod
    def from_msg(cls, msg: Any, clock_type: ClockType = ClockType.ROS_TIME) -> Time:
        return cls(int(msg.sec) * NS_PER_S + int(msg.nanosec), clock_type)

    @classmethod
    def from_seconds(cls, seconds: float) -> Time:
        return cls(round(seconds * NS_PER_S))

    def to_msg(self) -> Any:
        sec, nsec = divmod(self.nanoseconds, NS_PER_S)
        return TimeMsg(sec=sec, nanosec=nsec)

    def to_seconds(self) -> float:
        return self.nanoseconds / NS_PER_S

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return divmod(self.nanoseconds, NS_PER_S)

    def __add__(self, other: Duration) -> Time:
        if not isinstance(other, Duration):
            return NotImplemented
        return Time(self.nanoseconds + other.nanoseconds, self.clock_type)

    def __sub__(self, other: Any) -> Any:
        if isinstance(other, Time):
            return Duration(self.nanoseconds - other.nanoseconds)
        if isinstance(other, Duration):
            return Time(self.nanoseconds - other.nanoseconds, self.clock_type)
        return NotImplemented


def stamp_to_ns(stamp: Any) -> int:
    """builtin_interfaces/Time → integer nanoseconds."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def ns_to_stamp(ns: int) -> Any:
    """Integer nanoseconds → builtin_interfaces/Time."""
    sec, nsec = divmod(int(ns), NS_PER_S)
    return TimeMsg(sec=sec, nanosec=nsec)


class ClockChange(enum.IntEnum):
    """What kind of jump a :class:`TimeJump` is (rcl's ``rcl_clock_change_t``)."""

    ROS_TIME_NO_CHANGE = 1
    ROS_TIME_ACTIVATED = 2
    ROS_TIME_DEACTIVATED = 3
    SYSTEM_TIME_NO_CHANGE = 4


@dataclass(frozen=True)
class TimeJump:
    """A discontinuity of a clock: ``delta`` is new time minus old time."""

    clock_change: ClockChange
    delta: Duration


@dataclass(frozen=True)
class JumpThreshold:
    """When a jump callback fires, as rclpy: a forward jump of at least ``min_forward``, a
    backward jump of at least ``|min_backward|`` (a negative duration), or a change of
    time source. None or a zero duration disables that direction."""

    min_forward: Duration | None
    min_backward: Duration | None
    on_clock_change: bool = True

    def __post_init__(self) -> None:
        if self.min_forward is not None and self.min_forward.nanoseconds < 0:
            raise ValueError(f"min_forward must be positive or zero, got {self.min_forward}")
        if self.min_backward is not None and self.min_backward.nanoseconds > 0:
            raise ValueError(f"min_backward must be negative or zero, got {self.min_backward}")

    def exceeded_by(self, jump: TimeJump) -> bool:
        if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED, ClockChange.ROS_TIME_DEACTIVATED):
            return self.on_clock_change
        ns = jump.delta.nanoseconds
        fwd = self.min_forward.nanoseconds if self.min_forward is not None else 0
        back = self.min_backward.nanoseconds if self.min_backward is not None else 0
        return (fwd > 0 and ns >= fwd) or (back < 0 and ns <= back)


class JumpHandle:
    """A registered jump callback; :meth:`unregister` removes it (rclpy's JumpHandle)."""

    def __init__(self, clock: Clock, threshold: JumpThreshold,
                 pre_callback: Callable[[], Any] | None,
                 post_callback: Callable[[TimeJump], Any] | None) -> None:
        self.clock = clock
        self.threshold = threshold
        self.pre_callback = pre_callback
        self.post_callback = post_callback

    def unregister(self) -> None:
        self.clock._remove_jump_handle(self)


class Clock:
    """Wall-clock time (system or steady)."""

    def __init__(self, clock_type: ClockType = ClockType.SYSTEM_TIME) -> None:
        self.clock_type = clock_type
        self._jump_handles: list[JumpHandle] = []

    @property
    def is_sim(self) -> bool:
        return False

    def now_ns(self) -> int:
        if self.clock_type == ClockType.STEADY_TIME:
            return _time.monotonic_ns()
        return _time.time_ns()

    def now(self) -> Time:
        return Time(self.now_ns(), self.clock_type)

    def create_jump_callback(
        self,
        threshold: JumpThreshold,
        *,
        pre_callback: Callable[[], Any] | None = None,
        post_callback: Callable[[TimeJump], Any] | None = None,
    ) -> JumpHandle:
        """Call ``pre_callback()`` before and ``post_callback(jump)`` after a jump that
        exceeds ``threshold`` (rclpy's ``Clock.create_jump_callback``). Wall clocks are
        taken as they come (no jumps are reported); a ``SimClock`` reports the jumps of
        :meth:`SimClock.reset` — its ordinary forward moves are not jumps."""
        handle = JumpHandle(self, threshold, pre_callback, post_callback)
        self._jump_handles = [*self._jump_handles, handle]
        return handle

    def _remove_jump_handle(self, handle: JumpHandle) -> None:
        self._jump_handles = [h for h in self._jump_handles if h is not handle]

    def _jumped(self, jump: TimeJump, *, before: bool) -> None:
        for h in self._jump_handles:
            if not h.threshold.exceeded_by(jump):
                continue
            if before and h.pre_callback is not None:
                h.pre_callback()
            elif not before and h.post_callback is not None:
                h.post_callback(jump)


class SimClock(Clock):
    """Simulated ROS time: starts at ``start_ns`` and moves only when told to."""

    def __init__(self, start_ns: int = 0) -> None:
        super().__init__(ClockType.ROS_TIME)
        self._ns = int(start_ns)
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._waiters = 0

    @property
    def is_sim(self) -> bool:
        return True

    def now_ns(self) -> int:
        return self._ns

    def set_ns(self, ns: int) -> None:
        """Move the clock to ``ns``; time never goes backwards here (use ``reset``)."""
        if ns <= self._ns:
            return
        if not self._waiters:
            self._ns = int(ns)  # nobody blocks on us: skip the condition (hot path)
            return
        with self._cond:
            self._ns = int(ns)
            self._cond.notify_all()

    def advance(self, duration_ns: int) -> None:
        self.set_ns(self._ns + int(duration_ns))

    def reset(self, ns: int = 0) -> None:
        """Jump to ``ns``, backwards too (a bag replay looping, a simulator reset). Jump
        callbacks run around it, in the calling thread: timers restart their period and
        tf buffers forget what they held when time went back (as rcl and tf2_ros do)."""
        jump = TimeJump(ClockChange.ROS_TIME_NO_CHANGE, Duration(int(ns) - self._ns))
        if jump.delta.nanoseconds == 0:
            return
        self._jumped(jump, before=True)
        with self._cond:
            self._ns = int(ns)
            self._cond.notify_all()
        self._jumped(jump, before=False)

    def wait_until(self, ns: int, timeout_s: float | None = None) -> bool:
        """Block a thread until the sim time reaches ``ns`` (another thread advances it)."""
        with self._cond:
            self._waiters += 1
            try:
                return self._cond.wait_for(lambda: self._ns >= ns, timeout_s)
            finally:
                self._waiters -= 1
