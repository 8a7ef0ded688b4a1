"""How the buffer stores transforms: frame ids without a leading ``/``, times in integer
nanoseconds, and per child frame a time-sorted history (a tf2 TimeCache)."""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any

from eddiebot.core.tf._algebra import _interpolate, _Tf
from eddiebot.core.tf.errors import InvalidArgumentException
from eddiebot.core.time import NS_PER_S, Duration, Time, stamp_to_ns


def _to_ns(time: Any) -> int:
    """Time, builtin_interfaces/Time, Duration-free int ns, or float seconds → int ns."""
    if time is None:
        return 0
    if isinstance(time, Time):
        return time.nanoseconds
    if isinstance(time, bool):
        raise InvalidArgumentException(f"not a time: {time!r}")
    if isinstance(time, int):
        return time
    if isinstance(time, float):
        return round(time * NS_PER_S)
    if hasattr(time, "sec") and hasattr(time, "nanosec"):
        return stamp_to_ns(time)
    raise InvalidArgumentException(f"not a time: {time!r}")


def _timeout_s(timeout: Any) -> float:
    if timeout is None:
        return 0.0
    if isinstance(timeout, Duration):
        return timeout.to_seconds()
    if hasattr(timeout, "sec") and hasattr(timeout, "nanosec"):
        return Duration.from_msg(timeout).to_seconds()
    return float(timeout)


def _fmt(ns: int) -> str:
    return f"{ns / NS_PER_S:.6f}"


def _strip(frame_id: str) -> str:
    return frame_id[1:] if frame_id.startswith("/") else frame_id


@dataclass
class _Edge:
    """One stored transform child → parent."""

    parent: str
    tf: _Tf
    authority: str


class _FrameCache:
    """Time-sorted history of one child frame (a tf2 TimeCache)."""

    __slots__ = ("edges", "stamps")

    def __init__(self) -> None:
        self.stamps: list[int] = []
        self.edges: list[_Edge] = []

    def insert(self, stamp: int, edge: _Edge, cache_ns: int) -> bool:
        stamps = self.stamps
        if stamps and stamp < stamps[-1] - cache_ns:
            return False  # older than the window: tf2's TF_OLD_DATA
        if not stamps or stamp > stamps[-1]:
            stamps.append(stamp)
            self.edges.append(edge)
        else:
            i = bisect.bisect_left(stamps, stamp)
            if i < len(stamps) and stamps[i] == stamp:
                self.edges[i] = edge
            else:
                stamps.insert(i, stamp)
                self.edges.insert(i, edge)
        # prune what fell out of the window (keep at least one entry)
        cutoff = stamps[-1] - cache_ns
        k = bisect.bisect_left(stamps, cutoff)
        if k > 0:
            del stamps[:k]
            del self.edges[:k]
        return True

    def latest(self) -> tuple[int, _Edge]:
        return self.stamps[-1], self.edges[-1]

    def parent_at(self, time_ns: int) -> str:
        if time_ns == 0:
            return self.edges[-1].parent
        i = bisect.bisect_right(self.stamps, time_ns) - 1
        return self.edges[max(i, 0)].parent

    def get(self, time_ns: int, frame: str) -> tuple[str, _Tf] | str:
        """(parent, transform) at ``time_ns`` (0: latest), or an error message."""
        stamps = self.stamps
        if time_ns == 0:
            e = self.edges[-1]
            return e.parent, e.tf
        first, last = stamps[0], stamps[-1]
        if time_ns > last:
            return (
                f"Lookup would require extrapolation into the future. Requested time "
                f"{_fmt(time_ns)} but the latest data is at time {_fmt(last)}, "
                f"when looking up transform from frame [{frame}] to frame "
                f"[{self.edges[-1].parent}]"
            )
        if time_ns < first:
            return (
                f"Lookup would require extrapolation into the past. Requested time "
                f"{_fmt(time_ns)} but the earliest data is at time {_fmt(first)}, "
                f"when looking up transform from frame [{frame}] to frame "
                f"[{self.edges[0].parent}]"
            )
        i = bisect.bisect_left(stamps, time_ns)
        if stamps[i] == time_ns:
            e = self.edges[i]
            return e.parent, e.tf
        t0, t1 = stamps[i - 1], stamps[i]
        e0, e1 = self.edges[i - 1], self.edges[i]
        if e0.parent != e1.parent:
            return e0.parent, e0.tf  # reparented between samples: no interpolation, as tf2
        return e0.parent, _interpolate(e0.tf, e1.tf, (time_ns - t0) / (t1 - t0))
