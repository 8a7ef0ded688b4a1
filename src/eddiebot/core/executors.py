"""Executors: who runs the callbacks, in what order, and how time moves.

``SingleThreadedExecutor`` is deterministic: work runs in the order it arrived, timers in
the order they fall due, and a due timer waits for at most ``_FAIR_TIMER_EVERY`` callbacks
while work keeps arriving. On a simulated clock that this executor drives, it does not wait
for a timer — it moves the clock to the timer's due time (optionally paced to a real-time
factor), so a ten-minute run of idle nodes takes milliseconds and a test never sleeps.

``MultiThreadedExecutor`` runs callbacks on a thread pool, one at a time per mutually
exclusive callback group, for nodes that do blocking work.
"""

from __future__ import annotations

import threading
import time as _time
from collections import deque
from collections.abc import Callable, Coroutine
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

from eddiebot.core.context import Context, get_default_context
from eddiebot.core.task import Future, Task

if TYPE_CHECKING:
    from eddiebot.core.node import Node, Timer

__all__ = ["Executor", "MultiThreadedExecutor", "SingleThreadedExecutor"]

#: After this many ready callbacks in a row, a due timer runs before the next one.
_FAIR_TIMER_EVERY = 16


class _TaskEntity:
    """Adapts a ``Task`` to the executor's work queue."""

    __slots__ = ("callback_group", "node", "task")

    def __init__(self, task: Task) -> None:
        self.task = task
        self.callback_group = None
        self.node = None

    def execute(self) -> None:
        self.task.step()


class Executor:
    """Base executor: a queue of ready work plus the timers of its nodes."""

    def __init__(
        self,
        *,
        context: Context | None = None,
        drive_sim_time: bool | None = None,
        real_time_factor: float | None = None,
        stop_on_callback_error: bool = False,
    ) -> None:
        self.context = context or get_default_context()
        self._nodes: list[Node] = []
        self._timer_cache: list[Timer] | None = None
        self._ready: deque[Any] = deque()
        self._ready_streak = 0
        self._cond = threading.Condition()
        self._spinning: set[int] = set()
        self._shutdown = False
        #: Move the sim clock to the next due timer instead of waiting (the sim owner does).
        self.drive_sim_time = self.context.use_sim_time if drive_sim_time is None else drive_sim_time
        #: None: as fast as possible; 1.0: real time; N: N× real time (sim clock only).
        self.real_time_factor = real_time_factor
        self.stop_on_callback_error = stop_on_callback_error
        self._pace_anchor: tuple[float, int] | None = None
        #: Called with the new time (ns) whenever this executor moves the sim clock.
        self.on_sim_time_advanced: list[Callable[[int], None]] = []

    # -- nodes ----------------------------------------------------------------------------
    def add_node(self, node: Node) -> bool:
        if node in self._nodes:
            return False
        if node.executor is not None and node.executor is not self:
            node.executor.remove_node(node)
        self._nodes.append(node)
        node.executor = self
        self._timer_cache = None
        for entity in node._take_pending():
            self.enqueue(entity)
        self.wake()
        return True

    def remove_node(self, node: Node) -> None:
        if node in self._nodes:
            self._nodes.remove(node)
            node.executor = None
            self._timer_cache = None

    def get_nodes(self) -> list[Node]:
        return list(self._nodes)

    # -- work -----------------------------------------------------------------------------
    def enqueue(self, entity: Any) -> None:
        with self._cond:
            self._ready.append(entity)
            self._cond.notify_all()

    def wake(self) -> None:
        with self._cond:
            self._cond.notify_all()

    def create_task(self, coro: Coroutine[Any, Any, Any] | Callable[[], Any]) -> Task:
        """Run a coroutine (or a plain callable) on this executor; returns its future."""
        if not hasattr(coro, "send"):
            fn = coro

            async def wrap() -> Any:
                return fn()  # type: ignore[operator]

            coro = wrap()
        task = Task(coro, self._schedule_task)  # type: ignore[arg-type]
        self._schedule_task(task)
        return task

    def _schedule_task(self, task: Task) -> None:
        self.enqueue(_TaskEntity(task))

    def is_current_thread_spinning(self) -> bool:
        return threading.get_ident() in self._spinning

    def is_spinning(self) -> bool:
        return bool(self._spinning)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self._shutdown = True
        self.wake()
        return True

    # -- timers and time ------------------------------------------------------------------
    def invalidate_timers(self) -> None:
        self._timer_cache = None
        self.wake()

    def _timers(self) -> list[Timer]:
        cache = self._timer_cache
        if cache is None:
            cache = self._timer_cache = [t for n in self._nodes for t in n.timers]
        return cache

    def _idle_timers(self) -> list[Timer]:
        """Timers this executor may hand out now (a multi-threaded one leaves out those
        running or waiting for their group)."""
        return self._timers()

    def _earliest_timer(self) -> Timer | None:
        best: Timer | None = None
        best_ns = 0
        for t in self._idle_timers():
            if not t.canceled and (best is None or t.next_call_ns < best_ns):
                best, best_ns = t, t.next_call_ns
        return best

    def _due_timer(self) -> Timer | None:
        best: Timer | None = None
        for t in self._idle_timers():
            if t.is_ready(t.clock.now_ns()) and (best is None or t.next_call_ns < best.next_call_ns):
                best = t
        return best

    def _next_sim_due(self) -> int | None:
        sim = self.context.sim_clock
        due = [t.next_call_ns for t in self._idle_timers() if t.clock is sim and not t.canceled]
        return min(due) if due else None

    def _wall_wait_s(self) -> float | None:
        waits = [
            (t.next_call_ns - t.clock.now_ns()) / 1e9
            for t in self._idle_timers()
            if not t.clock.is_sim and not t.canceled
        ]
        return max(0.0, min(waits)) if waits else None

    def _advance_sim(self, target_ns: int, deadline: float | None) -> bool:
        """Move the sim clock to ``target_ns``, pacing to the real-time factor; False if
        new work or the deadline interrupted the wait."""
        sim = self.context.sim_clock
        rtf = self.real_time_factor
        if rtf is not None and rtf > 0:
            now_wall = _time.monotonic()
            if self._pace_anchor is None:
                self._pace_anchor = (now_wall, sim.now_ns())
            wall0, sim0 = self._pace_anchor
            target_wall = wall0 + (target_ns - sim0) / 1e9 / rtf
            if target_wall - now_wall > 0.2:
                # fell far behind or restarted: re-anchor so we do not race to catch up
                pass
            wait = target_wall - now_wall
            if deadline is not None:
                wait = min(wait, deadline - now_wall)
            if wait > 0:
                with self._cond:
                    if not self._ready:
                        self._cond.wait(wait)
                    if self._ready or self._shutdown:
                        return False
                if _time.monotonic() < target_wall:
                    return False
            elif wait < -0.5:
                self._pace_anchor = (now_wall, target_ns)
        sim.set_ns(target_ns)
        for cb in self.on_sim_time_advanced:
            cb(target_ns)
        return True

    # -- one unit of work -----------------------------------------------------------------
    def _next_work(self, timeout_sec: float | None) -> Any | None:
        """The next entity to run, waiting at most ``timeout_sec`` (None: forever)."""
        deadline = None if timeout_sec is None else _time.monotonic() + timeout_sec
        while not self._shutdown and self.context.ok():
            with self._cond:
                if self._ready:
                    # a due timer gets a turn now and then even while messages keep coming
                    # (as rclpy's wait set offers ready timers first): a recorder that cannot
                    # keep up with a camera still polls the graph
                    self._ready_streak += 1
                    if self._ready_streak <= _FAIR_TIMER_EVERY:
                        return self._ready.popleft()
            self._ready_streak = 0
            if self._ready:
                timer = self._due_timer()
                if timer is not None:
                    return timer
                with self._cond:
                    if self._ready:
                        return self._ready.popleft()
            if self.drive_sim_time:
                # fast path: the earliest timer is on the driven sim clock
                first = self._earliest_timer()
                if first is not None and first.clock is self.context.sim_clock:
                    if first.next_call_ns <= first.clock.now_ns():
                        return first
                    if self.real_time_factor is None and self._wall_wait_s() is None:
                        self._advance_sim(first.next_call_ns, deadline)
                        return first
            timer = self._due_timer()
            if timer is not None:
                return timer
            if self.drive_sim_time:
                nxt = self._next_sim_due()
                if nxt is not None:
                    self._advance_sim(nxt, deadline)
                    if deadline is not None and _time.monotonic() >= deadline:
                        with self._cond:
                            if self._ready:
                                return self._ready.popleft()
                        return self._due_timer()
                    continue
            wait = self._wall_wait_s()
            if deadline is not None:
                remaining = deadline - _time.monotonic()
                if remaining <= 0:
                    return None
                wait = remaining if wait is None else min(wait, remaining)
            with self._cond:
                if not self._ready:
                    # A sim clock driven from outside (/clock) wakes us through new work.
                    self._cond.wait(0.05 if wait is None else min(wait, 0.05)
                                    if self.context.use_sim_time and not self.drive_sim_time
                                    else wait)
        return None

    def spin_once(self, timeout_sec: float | None = None) -> bool:
        """Run one callback (waiting up to ``timeout_sec``); True if one ran."""
        raise NotImplementedError

    def spin(self) -> None:
        """Run callbacks until the context shuts down or ``shutdown()`` is called."""
        while self.context.ok() and not self._shutdown:
            self.spin_once(timeout_sec=0.1)

    def spin_until_future_complete(self, future: Future, timeout_sec: float | None = None) -> None:
        """Run callbacks until ``future`` is done or ``timeout_sec`` of wall time passed."""
        deadline = None if timeout_sec is None else _time.monotonic() + timeout_sec
        while not future.done() and self.context.ok() and not self._shutdown:
            remaining = None if deadline is None else deadline - _time.monotonic()
            if remaining is not None and remaining <= 0:
                return
            self.spin_once(timeout_sec=0.1 if remaining is None else min(remaining, 0.1))

    def spin_until(self, time_ns: int, *, timeout_sec: float | None = None) -> None:
        """Run callbacks until the node clock (sim or wall) reaches ``time_ns``.

        On a driven sim clock this jumps through timers and then sets the clock to
        ``time_ns`` exactly.
        """
        sim = self.context.sim_clock
        clock = sim if self.context.use_sim_time else self.context.system_clock
        deadline = None if timeout_sec is None else _time.monotonic() + timeout_sec
        if (
            clock is sim
            and self.drive_sim_time
            and self.real_time_factor is None
            and isinstance(self, SingleThreadedExecutor)
        ):
            self._spin_sim_fast(time_ns, deadline)
        while clock.now_ns() < time_ns and self.context.ok() and not self._shutdown:
            if deadline is not None and _time.monotonic() >= deadline:
                return
            if self.drive_sim_time and clock is sim:
                with self._cond:
                    has_ready = bool(self._ready)
                nxt = self._next_sim_due()
                if not has_ready and self._due_timer() is None and (nxt is None or nxt > time_ns):
                    self._advance_sim(time_ns, deadline)
                    continue
            self.spin_once(timeout_sec=0.1)
        # run what became due exactly at time_ns, without moving time further
        self.spin_until_idle()

    def _spin_sim_fast(self, time_ns: int, deadline: float | None) -> None:
        """As-fast-as-possible sim time on one thread: the hot loop of simulated runs."""
        sim = self.context.sim_clock
        ready = self._ready
        me = threading.get_ident()
        self._spinning.add(me)
        try:
            count = 0
            while self.context.ok() and not self._shutdown:
                if ready:
                    ready.popleft().execute()
                    continue
                first = self._earliest_timer()
                if first is None or first.next_call_ns > time_ns or not first.clock.is_sim:
                    if self._wall_wait_s() is not None:
                        return  # wall timers too: let the general loop interleave them
                    break
                if first.next_call_ns > sim.now_ns():
                    sim.set_ns(first.next_call_ns)
                    for cb in self.on_sim_time_advanced:
                        cb(first.next_call_ns)
                first.execute()
                count += 1
                if deadline is not None and count % 1000 == 0 and _time.monotonic() >= deadline:
                    return
            if sim.now_ns() < time_ns:
                sim.set_ns(time_ns)
                for cb in self.on_sim_time_advanced:
                    cb(time_ns)
        finally:
            self._spinning.discard(me)

    def spin_for(self, seconds: float) -> None:
        """Run for ``seconds`` of node-clock time (sim time when it is sim)."""
        clock = self.context.sim_clock if self.context.use_sim_time else self.context.system_clock
        self.spin_until(clock.now_ns() + round(seconds * 1e9))

    def spin_until_idle(self, max_callbacks: int = 1_000_000) -> int:
        """Run ready work (not future timers); returns the number of callbacks run."""
        n = 0
        while n < max_callbacks:
            with self._cond:
                has_ready = bool(self._ready)
            if not has_ready and self._due_timer() is None:
                break
            if not self.spin_once(timeout_sec=0):
                break
            n += 1
        return n


class SingleThreadedExecutor(Executor):
    """Runs every callback on the spinning thread, deterministically."""

    def spin_once(self, timeout_sec: float | None = None) -> bool:
        me = threading.get_ident()
        self._spinning.add(me)
        try:
            entity = self._next_work(timeout_sec)
            if entity is None:
                return False
            entity.execute()
            return True
        finally:
            self._spinning.discard(me)


class MultiThreadedExecutor(Executor):
    """Runs callbacks on ``num_threads`` workers, honouring callback groups.

    Work whose mutually exclusive group is busy waits beside its group and goes back to
    the front of the ready queue the moment the running callback of that group returns,
    so it starts as soon as the group frees (not on a polling tick)."""

    def __init__(self, num_threads: int | None = None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        import os

        self.num_threads = num_threads or max(2, os.cpu_count() or 2)
        self._pool = ThreadPoolExecutor(self.num_threads, thread_name_prefix="eddie-exec")
        #: id(group) → work that found the group busy, in arrival order
        self._blocked: dict[int, deque[Any]] = {}
        #: ids of entities waiting in ``_blocked`` (a due timer is not handed out twice)
        self._waiting: set[int] = set()
        self._inflight: set[int] = set()
        self._inflight_lock = threading.Lock()

    def spin_once(self, timeout_sec: float | None = None) -> bool:
        me = threading.get_ident()
        self._spinning.add(me)
        try:
            entity = self._next_work(timeout_sec)
            if entity is None:
                return False
            return self._dispatch(entity)
        finally:
            self._spinning.discard(me)

    def _dispatch(self, entity: Any) -> bool:
        key = id(entity)
        group = getattr(entity, "callback_group", None)
        group_lock: threading.Lock | None = (
            group.lock if group is not None and not group.reentrant else None)
        exclusive = group_lock is not None
        # A timer is found again by _due_timer while it is due, so it is handed out once;
        # any other entity comes once per notification (a message, a request), so each
        # one must run, however many are in flight or waiting.
        is_timer = hasattr(entity, "timer_period_ns")
        with self._inflight_lock:
            if is_timer and key in self._inflight:
                return False  # re-evaluated when it finishes
            if group_lock is not None and not group_lock.acquire(blocking=False):
                if not (is_timer and key in self._waiting):
                    self._blocked.setdefault(id(group), deque()).append(entity)
                    if is_timer:
                        self._waiting.add(key)
                return False
            self._inflight.add(key)

        def run() -> None:
            me = threading.get_ident()
            self._spinning.add(me)
            try:
                entity.execute()
            finally:
                self._spinning.discard(me)
                with self._inflight_lock:
                    self._inflight.discard(key)
                    waiting = self._blocked.pop(id(group), None) if exclusive else None
                    if group_lock is not None:
                        group_lock.release()
                    if waiting:
                        self._waiting.difference_update(id(e) for e in waiting)
                with self._cond:
                    if waiting:
                        self._ready.extendleft(reversed(waiting))
                    self._cond.notify_all()

        self._pool.submit(run)
        return True

    def _idle_timers(self) -> list[Timer]:
        with self._inflight_lock:
            if not self._inflight and not self._waiting:
                return self._timers()
            busy = self._inflight | self._waiting
        return [t for t in self._timers() if id(t) not in busy]

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        super().shutdown(timeout_sec)
        self._pool.shutdown(wait=True)
        return True


def spin(node: Node, executor: Executor | None = None) -> None:
    """Spin one node until shutdown (rclpy.spin)."""
    ex = executor or SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    ex.spin()


def spin_once(node: Node, *, executor: Executor | None = None, timeout_sec: float | None = None) -> None:
    ex = executor or node.executor or SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    ex.spin_once(timeout_sec)


def spin_until_future_complete(
    node: Node, future: Future, executor: Executor | None = None, timeout_sec: float | None = None
) -> None:
    ex = executor or node.executor or SingleThreadedExecutor(context=node.context)
    ex.add_node(node)
    ex.spin_until_future_complete(future, timeout_sec)
