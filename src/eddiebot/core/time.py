"""Time in integer nanoseconds, and the clocks that tell it.

Nothing else in the package reads the wall clock: nodes ask their ``Clock``; pure cores
receive times as arguments. A ``SimClock`` is advanced by whoever owns it (the executor
jumps it to the next due timer, or ``/clock`` messages set it).
"""

from __future__ import annotations

import enum
import threading
import time as _time
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


class Clock:
    """Wall-clock time (system or steady)."""

    def __init__(self, clock_type: ClockType = ClockType.SYSTEM_TIME) -> None:
        self.clock_type = clock_type

    @property
    def is_sim(self) -> bool:
        return False

    def now_ns(self) -> int:
        if self.clock_type == ClockType.STEADY_TIME:
            return _time.monotonic_ns()
        return _time.time_ns()

    def now(self) -> Time:
        return Time(self.now_ns(), self.clock_type)


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
        """Jump back (a bag replay restarting); listeners see time move backwards once."""
        with self._cond:
            self._ns = int(ns)
            self._cond.notify_all()

    def wait_until(self, ns: int, timeout_s: float | None = None) -> bool:
        """Block a thread until the sim time reaches ``ns`` (another thread advances it)."""
        with self._cond:
            self._waiters += 1
            try:
                return self._cond.wait_for(lambda: self._ns >= ns, timeout_s)
            finally:
                self._waiters -= 1
