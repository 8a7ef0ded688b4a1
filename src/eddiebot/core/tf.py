"""A tf2-like transform buffer, listener and broadcasters.

``Buffer`` keeps, for every child frame, a time-sorted history of its transform to its
parent (``cache_time`` long) and, separately, static transforms that hold at every time.
``lookup_transform(target, source, time)`` walks both frames up to their common ancestor,
interpolating each edge at ``time`` (linear in translation, slerp in rotation), and
returns the geometry_msgs/TransformStamped that maps points in ``source`` into ``target``
(``header.frame_id = target``, ``child_frame_id = source``), as tf2 does. ``time`` 0
(``Time()``) means the latest time at which every edge of the chain is known.

Failures raise tf2's exception types: ``LookupException`` (a frame nobody published),
``ConnectivityException`` (frames in two trees), ``ExtrapolationException`` (a time
outside the cached range, into the past or the future) and ``TimeoutException``.

Frame ids carry no leading ``/`` (one is stripped, as tf2 does). Times are integer
nanoseconds internally; the public API accepts ``Time``, builtin_interfaces/Time, or
int nanoseconds.
"""

from __future__ import annotations

import bisect
import logging
import math
import threading
import time as _time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.core.task import Future
from eddiebot.core.time import (
    NS_PER_S,
    Duration,
    JumpHandle,
    JumpThreshold,
    Time,
    TimeJump,
    ns_to_stamp,
    stamp_to_ns,
)

if TYPE_CHECKING:
    from eddiebot.core.node import Node

__all__ = [
    "Buffer",
    "ConnectivityException",
    "ExtrapolationException",
    "InvalidArgumentException",
    "LookupException",
    "StaticTransformBroadcaster",
    "TimeoutException",
    "TransformBroadcaster",
    "TransformException",
    "TransformListener",
    "make_transform",
    "make_transform_2d",
]

_log = logging.getLogger("eddiebot.tf")

#: Longest parent chain followed before a loop is assumed (tf2's MAX_GRAPH_DEPTH).
MAX_GRAPH_DEPTH = 1000

#: /tf and /tf_static QoS as tf2_ros: depth 100, static ones transient-local.
TF_QOS = QoSProfile(depth=100)
TF_STATIC_QOS = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC_BROADCASTER_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


# -- exceptions ---------------------------------------------------------------------------
class TransformException(Exception):
    """Base class of tf errors (tf2.TransformException)."""


class LookupException(TransformException):
    """A frame that is not in the buffer."""


class ConnectivityException(TransformException):
    """The two frames are in trees that are not connected."""


class ExtrapolationException(TransformException):
    """The requested time is outside the time range cached for an edge of the chain."""


class InvalidArgumentException(TransformException):
    """A malformed frame id, time or transform."""


class TimeoutException(TransformException):
    """No transform became available within the timeout; ``cause`` says why."""

    def __init__(self, message: str, cause: TransformException | None = None) -> None:
        super().__init__(message)
        self.cause = cause


# -- small pure-Python rigid-transform algebra (faster than numpy for single poses) --------
# A transform is (tx, ty, tz, qx, qy, qz, qw): p_parent = R(q) p_child + t.
_Tf = tuple[float, float, float, float, float, float, float]
_IDENTITY: _Tf = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _qmul(ax: float, ay: float, az: float, aw: float,
          bx: float, by: float, bz: float, bw: float) -> tuple[float, float, float, float]:
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _qrot(qx: float, qy: float, qz: float, qw: float,
          vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    # v' = v + 2w (q×v) + 2 q×(q×v)
    cx = qy * vz - qz * vy
    cy = qz * vx - qx * vz
    cz = qx * vy - qy * vx
    return (
        vx + 2.0 * (qw * cx + qy * cz - qz * cy),
        vy + 2.0 * (qw * cy + qz * cx - qx * cz),
        vz + 2.0 * (qw * cz + qx * cy - qy * cx),
    )


def _compose(a: _Tf, b: _Tf) -> _Tf:
    """a ∘ b: first b, then a."""
    rx, ry, rz = _qrot(a[3], a[4], a[5], a[6], b[0], b[1], b[2])
    q = _qmul(a[3], a[4], a[5], a[6], b[3], b[4], b[5], b[6])
    return (a[0] + rx, a[1] + ry, a[2] + rz, q[0], q[1], q[2], q[3])


def _inverse(a: _Tf) -> _Tf:
    ix, iy, iz, iw = -a[3], -a[4], -a[5], a[6]
    tx, ty, tz = _qrot(ix, iy, iz, iw, a[0], a[1], a[2])
    return (-tx, -ty, -tz, ix, iy, iz, iw)


def _slerp(a: Sequence[float], b: Sequence[float], t: float) -> tuple[float, float, float, float]:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    dot = ax * bx + ay * by + az * bz + aw * bw
    if dot < 0.0:
        bx, by, bz, bw, dot = -bx, -by, -bz, -bw, -dot
    if dot > 0.9995:
        s0, s1 = 1.0 - t, t
    else:
        theta = math.acos(min(1.0, dot))
        s = math.sin(theta)
        s0, s1 = math.sin((1.0 - t) * theta) / s, math.sin(t * theta) / s
    x, y, z, w = s0 * ax + s1 * bx, s0 * ay + s1 * by, s0 * az + s1 * bz, s0 * aw + s1 * bw
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


def _interpolate(a: _Tf, b: _Tf, t: float) -> _Tf:
    q = _slerp(a[3:], b[3:], t)
    return (
        a[0] + (b[0] - a[0]) * t,
        a[1] + (b[1] - a[1]) * t,
        a[2] + (b[2] - a[2]) * t,
        q[0], q[1], q[2], q[3],
    )


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


# -- storage ------------------------------------------------------------------------------
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


class Buffer:
    """Stores transforms and answers ``lookup_transform`` (tf2_ros.Buffer).

    Thread-safe: listeners may fill it from a transport thread while a node reads it.
    """

    def __init__(self, cache_time: Duration | float | None = None, node: Node | None = None) -> None:
        if cache_time is None:
            cache_ns = 10 * NS_PER_S
        elif isinstance(cache_time, Duration):
            cache_ns = cache_time.nanoseconds
        else:
            cache_ns = round(float(cache_time) * NS_PER_S)
        self.cache_time = Duration(cache_ns)
        self._cache_ns = cache_ns
        self._dynamic: dict[str, _FrameCache] = {}
        self._static: dict[str, _Edge] = {}
        self._parents_seen: set[str] = set()
        self._cond = threading.Condition(threading.RLock())
        self._waiters: list[tuple[str, str, int, Future]] = []
        #: Node whose executor a blocking lookup with a timeout may spin.
        self.node: Node | None = None
        self._jump_handle: JumpHandle | None = None
        if node is not None:
            self.set_node(node)

    def set_node(self, node: Node) -> None:
        """Use ``node``'s executor for blocking lookups and watch its clock: when time
        jumps back (a bag looping, a simulator reset) the buffer is cleared, as tf2_ros
        does — transforms from the future of the new time would be used otherwise."""
        self.node = node
        if self._jump_handle is not None:
            self._jump_handle.unregister()
        self._jump_handle = node.get_clock().create_jump_callback(
            JumpThreshold(None, Duration(-1)), post_callback=self._on_time_jump)

    def _on_time_jump(self, jump: TimeJump) -> None:
        _log.warning(f"detected a jump back in time of {-jump.delta.to_seconds():.3f} s; "
                     "clearing the tf buffer")
        self.clear()

    # -- filling ------------------------------------------------------------------------
    def set_transform(self, transform: Any, authority: str = "default_authority") -> bool:
        """Store a geometry_msgs/TransformStamped; False (and a log line) if it is invalid."""
        return self._set(transform, authority, static=False)

    def set_transform_static(self, transform: Any, authority: str = "default_authority") -> bool:
        """Store a transform that holds at every time."""
        return self._set(transform, authority, static=True)

    def _set(self, msg: Any, authority: str, *, static: bool) -> bool:
        child = _strip(msg.child_frame_id)
        parent = _strip(msg.header.frame_id)
        tr, rot = msg.transform.translation, msg.transform.rotation
        values = (float(tr.x), float(tr.y), float(tr.z),
                  float(rot.x), float(rot.y), float(rot.z), float(rot.w))
        where = f"from authority {authority!r}"
        if not child or not parent:
            _log.error(f"ignoring transform with an empty frame id "
                       f"(parent {parent!r}, child {child!r}) {where}")
            return False
        if child == parent:
            _log.error(f"ignoring transform from frame {child!r} to itself {where}")
            return False
        if not all(math.isfinite(v) for v in values):
            _log.error(f"ignoring transform {parent!r} → {child!r} with a NaN/inf {where}")
            return False
        qn = math.sqrt(sum(v * v for v in values[3:]))
        if abs(qn - 1.0) > 0.01:
            _log.error(f"ignoring transform {parent!r} → {child!r} with an unnormalised "
                       f"quaternion (norm {qn:.4f}) {where}")
            return False
        tf: _Tf = (values[0], values[1], values[2],
                   values[3] / qn, values[4] / qn, values[5] / qn, values[6] / qn)
        edge = _Edge(parent, tf, authority)
        with self._cond:
            if static:
                self._static[child] = edge
                self._dynamic.pop(child, None)
            else:
                if child in self._static:
                    _log.warning(f"frame {child!r} is static; ignoring a dynamic transform {where}")
                    return False
                cache = self._dynamic.get(child)
                if cache is None:
                    cache = self._dynamic[child] = _FrameCache()
                stamp = stamp_to_ns(msg.header.stamp)
                if not cache.insert(stamp, edge, self._cache_ns):
                    _log.warning(
                        f"ignoring data from the past for frame {child} at time {_fmt(stamp)} "
                        f"{where} (older than the {self.cache_time.to_seconds()} s cache)"
                    )
                    return False
            self._parents_seen.add(parent)
            if self._waiters:
                self._check_waiters()
            self._cond.notify_all()
        return True

    def clear(self) -> None:
        """Forget every dynamic transform (static ones stay, as tf2's clear())."""
        with self._cond:
            self._dynamic.clear()
            self._parents_seen = {e.parent for e in self._static.values()}

    # -- queries ------------------------------------------------------------------------
    def all_frames(self) -> list[str]:
        """Every frame id the buffer knows (as child or parent), sorted."""
        with self._cond:
            return sorted(set(self._dynamic) | set(self._static) | self._parents_seen)

    def all_frames_as_yaml(self) -> str:
        """tf2's frame summary: parent, authority, rate and time range per child frame."""
        lines = []
        with self._cond:
            for child in sorted(self._static):
                e = self._static[child]
                lines += [f"{child}:", f"  parent: '{e.parent}'", f"  broadcaster: '{e.authority}'",
                          "  rate: 10000.000", "  most_recent_transform: 0.0",
                          "  oldest_transform: 0.0", "  buffer_length: 0.0"]
            for child in sorted(self._dynamic):
                c = self._dynamic[child]
                first, last = c.stamps[0], c.stamps[-1]
                span = (last - first) / NS_PER_S
                rate = (len(c.stamps) - 1) / span if span > 0 else 0.0
                e = c.edges[-1]
                lines += [f"{child}:", f"  parent: '{e.parent}'", f"  broadcaster: '{e.authority}'",
                          f"  rate: {rate:.3f}", f"  most_recent_transform: {_fmt(last)}",
                          f"  oldest_transform: {_fmt(first)}", f"  buffer_length: {span:.3f}"]
        return "\n".join(lines) + ("\n" if lines else "")

    def _known(self, frame: str) -> bool:
        return frame in self._dynamic or frame in self._static or frame in self._parents_seen

    def _validate(self, frame: str, argument: str) -> str:
        if not frame:
            raise InvalidArgumentException(f"empty frame id passed as {argument}")
        frame = _strip(frame)
        if not self._known(frame):
            known = ", ".join(self.all_frames()) or "none"
            raise LookupException(
                f'"{frame}" passed to lookup_transform argument {argument} does not exist. '
                f"Known frames: {known}"
            )
        return frame

    def _edge_at(self, frame: str, time_ns: int) -> tuple[str, _Tf] | str | None:
        """(parent, tf) of ``frame`` at ``time_ns``; an error message; None for a root."""
        e = self._static.get(frame)
        if e is not None:
            return e.parent, e.tf
        cache = self._dynamic.get(frame)
        if cache is None:
            return None
        return cache.get(time_ns, frame)

    def _latest_common_time(self, target: str, source: str) -> int:
        """tf2's getLatestCommonTime: the newest time every dynamic edge of the chain has."""
        def chain(frame: str) -> list[tuple[str, int]]:
            out: list[tuple[str, int]] = [(frame, 0)]
            for _ in range(MAX_GRAPH_DEPTH):
                if frame in self._static:
                    parent, stamp = self._static[frame].parent, 0
                elif frame in self._dynamic:
                    stamp, edge = self._dynamic[frame].latest()
                    parent = edge.parent
                else:
                    return out
                out[-1] = (frame, stamp)
                frame = parent
                out.append((frame, 0))
            raise LookupException(f"the tf tree has a loop through frame {frame!r}")

        src, tgt = chain(source), chain(target)
        src_index = {f: i for i, (f, _) in enumerate(src)}
        for j, (f, _) in enumerate(tgt):
            if f in src_index:
                i = src_index[f]
                stamps = [s for _, s in src[:i]] + [s for _, s in tgt[:j]]
                dynamic = [s for s in stamps if s != 0]
                return min(dynamic) if dynamic else 0
        raise ConnectivityException(self._disconnected(target, source, src[-1][0], tgt[-1][0]))

    @staticmethod
    def _disconnected(target: str, source: str, src_root: str, tgt_root: str) -> str:
        return (
            f'Could not find a connection between "{target}" and "{source}" because they are '
            f"not part of the same tree. Tf has two or more unconnected trees "
            f'("{source}" is under "{src_root}", "{target}" is under "{tgt_root}").'
        )

    def _lookup(self, target: str, source: str, time_ns: int) -> tuple[_Tf, int]:
        """(transform mapping source points into target, the time used)."""
        target = self._validate(target, "target_frame")
        source = self._validate(source, "source_frame")
        if time_ns == 0:
            time_ns = self._latest_common_time(target, source)
        if target == source:
            return _IDENTITY, time_ns
        # Walk source up to its root (stopping at target); record an extrapolation failure
        # and keep going from the other side, as tf2's walkToTopParent.
        error: str | None = None
        src_frames: dict[str, _Tf] = {source: _IDENTITY}  # frame -> T(frame <- source)
        frame, acc = source, _IDENTITY
        for _ in range(MAX_GRAPH_DEPTH):
            if frame == target:
                return acc, time_ns
            got = self._edge_at(frame, time_ns)
            if got is None:
                break
            if isinstance(got, str):
                error = got
                break
            parent, tf = got
            acc = _compose(tf, acc)
            frame = parent
            src_frames[frame] = acc
        else:
            raise LookupException(f"the tf tree has a loop through frame {frame!r}")
        src_top = frame
        frame, acc = target, _IDENTITY  # acc = T(frame <- target)
        for _ in range(MAX_GRAPH_DEPTH):
            hit = src_frames.get(frame)
            if hit is not None:
                return _compose(_inverse(acc), hit), time_ns
            got = self._edge_at(frame, time_ns)
            if got is None:
                break
            if isinstance(got, str):
                error = error or got
                break
            parent, tf = got
            acc = _compose(tf, acc)
            frame = parent
        else:
            raise LookupException(f"the tf tree has a loop through frame {frame!r}")
        if error is not None:
            raise ExtrapolationException(error)
        raise ConnectivityException(self._disconnected(target, source, src_top, frame))

    def lookup_transform(
        self, target_frame: str, source_frame: str, time: Any = None, timeout: Any = None
    ) -> Any:
        """geometry_msgs/TransformStamped taking ``source_frame`` points into ``target_frame``.

        ``time`` 0 / ``Time()`` / None: the latest common time. With a ``timeout`` (s or
        Duration, wall time) wait for the data, spinning the buffer's node's executor when
        this thread is the one spinning it; ``TimeoutException`` when it does not come.
        """
        from eddiebot.msgs.geometry_msgs import TransformStamped

        time_ns = _to_ns(time)
        tf, used = self._lookup_waiting(target_frame, source_frame, time_ns, timeout)
        msg = TransformStamped()
        msg.header.stamp = ns_to_stamp(used)
        msg.header.frame_id = _strip(target_frame)
        msg.child_frame_id = _strip(source_frame)
        t, r = msg.transform.translation, msg.transform.rotation
        t.x, t.y, t.z = tf[0], tf[1], tf[2]
        r.x, r.y, r.z, r.w = tf[3], tf[4], tf[5], tf[6]
        return msg

    def lookup_transform_full(
        self, target_frame: str, target_time: Any, source_frame: str, source_time: Any,
        fixed_frame: str, timeout: Any = None,
    ) -> Any:
        """tf2's time-travel lookup: source at ``source_time`` to target at ``target_time``
        through ``fixed_frame`` (assumed not to move)."""
        from eddiebot.msgs.geometry_msgs import TransformStamped

        a, _ = self._lookup_waiting(fixed_frame, source_frame, _to_ns(source_time), timeout)
        b, used = self._lookup_waiting(target_frame, fixed_frame, _to_ns(target_time), timeout)
        tf = _compose(b, a)
        msg = TransformStamped()
        msg.header.stamp = ns_to_stamp(used)
        msg.header.frame_id = _strip(target_frame)
        msg.child_frame_id = _strip(source_frame)
        t, r = msg.transform.translation, msg.transform.rotation
        t.x, t.y, t.z = tf[0], tf[1], tf[2]
        r.x, r.y, r.z, r.w = tf[3], tf[4], tf[5], tf[6]
        return msg

    def _lookup_waiting(
        self, target: str, source: str, time_ns: int, timeout: Any
    ) -> tuple[_Tf, int]:
        wait_s = _timeout_s(timeout)
        with self._cond:
            try:
                return self._lookup(target, source, time_ns)
            except (LookupException, ConnectivityException, ExtrapolationException) as exc:
                if wait_s <= 0:
                    raise
                last: TransformException = exc
        deadline = _time.monotonic() + wait_s
        while True:
            remaining = deadline - _time.monotonic()
            if remaining <= 0:
                raise TimeoutException(
                    f"could not transform {source!r} into {target!r} at {_fmt(time_ns)} "
                    f"within {wait_s} s: {last}", last
                )
            executor = self.node.executor if self.node is not None else None
            if executor is not None and executor.is_current_thread_spinning():
                executor.spin_once(timeout_sec=min(remaining, 0.01))
            else:
                with self._cond:
                    self._cond.wait(min(remaining, 0.05))
            with self._cond:
                try:
                    return self._lookup(target, source, time_ns)
                except (LookupException, ConnectivityException, ExtrapolationException) as exc:
                    last = exc

    def can_transform(
        self, target_frame: str, source_frame: str, time: Any = None, timeout: Any = None,
        return_debug_tuple: bool = False,
    ) -> Any:
        """True if ``lookup_transform`` would succeed (waiting up to ``timeout``)."""
        try:
            self._lookup_waiting(target_frame, source_frame, _to_ns(time), timeout)
        except TransformException as exc:
            return (False, str(exc)) if return_debug_tuple else False
        return (True, "") if return_debug_tuple else True

    def lookup_pose2d(self, target_frame: str, source_frame: str, time_ns: int = 0) -> tuple[float, float, float]:
        """(x, y, yaw) of ``source_frame``'s origin in ``target_frame`` (m, rad).

        The planar part of the transform, for 2D users; no message is built.
        """
        with self._cond:
            tf, _ = self._lookup(target_frame, source_frame, int(time_ns))
        qx, qy, qz, qw = tf[3], tf[4], tf[5], tf[6]
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        return tf[0], tf[1], yaw

    def get_latest_common_time(self, target_frame: str, source_frame: str) -> Time:
        with self._cond:
            target = self._validate(target_frame, "target_frame")
            source = self._validate(source_frame, "source_frame")
            return Time(self._latest_common_time(target, source))

    # -- asynchronous waiting -------------------------------------------------------------
    def wait_for_transform_async(self, target_frame: str, source_frame: str, time: Any = None) -> Future:
        """A future completed (with the TransformStamped) once the lookup can succeed."""
        future = Future()
        time_ns = _to_ns(time)
        with self._cond:
            try:
                future.set_result(self.lookup_transform(target_frame, source_frame, time_ns))
            except TransformException:
                self._waiters.append((target_frame, source_frame, time_ns, future))
        return future

    def _check_waiters(self) -> None:
        still = []
        done: list[tuple[Future, Any]] = []
        for target, source, time_ns, fut in self._waiters:
            if fut.done():
                continue
            try:
                done.append((fut, self.lookup_transform(target, source, time_ns)))
            except TransformException:
                still.append((target, source, time_ns, fut))
        self._waiters = still
        for fut, msg in done:
            fut.set_result(msg)


# -- ROS plumbing -------------------------------------------------------------------------
class TransformListener:
    """Fills a ``Buffer`` from ``/tf`` and ``/tf_static`` (tf2_ros.TransformListener)."""

    def __init__(
        self,
        buffer: Buffer,
        node: Node,
        *,
        qos: QoSProfile | int = TF_QOS,
        static_qos: QoSProfile | int = TF_STATIC_QOS,
        spin_thread: bool = False,
    ) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        del spin_thread  # the node's executor delivers; kept for the tf2_ros signature
        self.buffer = buffer
        self.node = node
        if buffer.node is None:
            buffer.set_node(node)
        self.tf_sub = node.create_subscription(TFMessage, "/tf", self._on_tf, qos)
        self.tf_static_sub = node.create_subscription(
            TFMessage, "/tf_static", self._on_tf_static, static_qos
        )

    def _on_tf(self, msg: Any) -> None:
        for t in msg.transforms:
            self.buffer.set_transform(t, "default_authority")

    def _on_tf_static(self, msg: Any) -> None:
        for t in msg.transforms:
            self.buffer.set_transform_static(t, "default_authority")

    def unregister(self) -> None:
        self.node.destroy_subscription(self.tf_sub)
        self.node.destroy_subscription(self.tf_static_sub)


def _as_list(transform: Any | Iterable[Any]) -> list[Any]:
    if hasattr(transform, "child_frame_id"):
        return [transform]
    return list(transform)


class TransformBroadcaster:
    """Publishes transforms on ``/tf`` (tf2_ros.TransformBroadcaster)."""

    def __init__(self, node: Node, qos: QoSProfile | int = TF_QOS) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        self._msg_type = TFMessage
        self.pub = node.create_publisher(TFMessage, "/tf", qos)

    def sendTransform(self, transform: Any | Iterable[Any]) -> None:
        """Publish one geometry_msgs/TransformStamped or a list of them."""
        self.pub.publish(self._msg_type(transforms=_as_list(transform)))

    send_transform = sendTransform


class StaticTransformBroadcaster:
    """Latches static transforms on ``/tf_static``; every call republishes all frames it
    was given so far in one TFMessage, as tf2_ros does."""

    def __init__(self, node: Node, qos: QoSProfile | int = TF_STATIC_BROADCASTER_QOS) -> None:
        from eddiebot.msgs.tf2_msgs import TFMessage

        self._msg_type = TFMessage
        self._frames: dict[str, Any] = {}
        self.pub = node.create_publisher(TFMessage, "/tf_static", qos)

    def sendTransform(self, transform: Any | Iterable[Any]) -> None:
        for t in _as_list(transform):
            self._frames[_strip(t.child_frame_id)] = t
        self.pub.publish(self._msg_type(transforms=list(self._frames.values())))

    send_transform = sendTransform


def make_transform(
    parent: str, child: str, stamp_ns: int, x: float = 0.0, y: float = 0.0, z: float = 0.0,
    qx: float = 0.0, qy: float = 0.0, qz: float = 0.0, qw: float = 1.0,
) -> Any:
    """A geometry_msgs/TransformStamped from numbers (child pose in the parent frame)."""
    from eddiebot.msgs.geometry_msgs import TransformStamped

    msg = TransformStamped()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = parent
    msg.child_frame_id = child
    t, r = msg.transform.translation, msg.transform.rotation
    t.x, t.y, t.z = float(x), float(y), float(z)
    r.x, r.y, r.z, r.w = float(qx), float(qy), float(qz), float(qw)
    return msg


def make_transform_2d(parent: str, child: str, stamp_ns: int, x: float, y: float, yaw: float) -> Any:
    """A planar TransformStamped: child at (x, y) with heading ``yaw`` in the parent (m, rad)."""
    return make_transform(parent, child, stamp_ns, x, y, 0.0, 0.0, 0.0,
                          math.sin(yaw / 2.0), math.cos(yaw / 2.0))

