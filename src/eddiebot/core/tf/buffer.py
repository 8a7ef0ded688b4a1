"""The transform buffer (tf2_ros.Buffer): stores transforms and answers lookups."""

from __future__ import annotations

import logging
import math
import threading
import time as _time
from typing import TYPE_CHECKING, Any

from eddiebot.core.task import Future
from eddiebot.core.tf._algebra import _IDENTITY, _compose, _inverse, _Tf
from eddiebot.core.tf._cache import _Edge, _fmt, _FrameCache, _strip, _timeout_s, _to_ns
from eddiebot.core.tf.errors import (
    ConnectivityException,
    ExtrapolationException,
    InvalidArgumentException,
    LookupException,
    TimeoutException,
    TransformException,
)
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

_log = logging.getLogger("eddiebot.tf")

#: Longest parent chain followed before a loop is assumed (tf2's MAX_GRAPH_DEPTH).
MAX_GRAPH_DEPTH = 1000


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
