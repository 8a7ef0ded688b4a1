"""Who talks to the board, when: a queue of board transactions kept off the executor.

The board node never waits for the serial line on its executor. It hands each transaction
(one or a few request/reply exchanges: a ``DIST`` poll, a ``GOSPD``, the start-up handshake)
to a :class:`BoardIO` as a :class:`BoardOp` and gets the result back on the executor through
``op.done(result, error)``. Ops run one at a time in priority order; an op with
``priority=STOP`` also abandons the exchange in flight (a poll waiting on a mute board), so
a stop is on the wire within one read slice instead of after the poll's timeout. An
abandoned op marked ``rerun_after_stop`` (a query: ``DIST``, ``PING``, ``ADC``) goes back to
the head of its priority and runs again once the stop is through, instead of failing: the
robot's odometry is one ``DIST`` reply, and a driver that lost its poll to every stop (a
controller hovering around zero sends one every other command) left ``odom → base_footprint``
older than a controller's ``transform_tolerance`` (0.45 s between samples at a 12 Hz poll
rate; docs/benchmarks/nav.md#pose-age).

Two implementations, one behaviour:

* :class:`ThreadedBoardIO` — real serial links (a board, a pty, ``socket://``): a worker
  thread runs the ops; results come back through a guard condition.
* :class:`TimedBoardIO` — the in-process emulator on sim time: each op runs at once against
  the emulator, holds the link for the time the real wire would take
  (:class:`~eddiebot.robot.links.TimedEmulatorLink`), and its result is delivered when the
  reply would have arrived. Deterministic, and as fast as the CPU allows.
"""

from __future__ import annotations

import enum
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from eddiebot.robot.board import Board
from eddiebot.robot.errors import BoardInterrupted

__all__ = ["BoardIO", "BoardOp", "Priority", "ThreadedBoardIO", "TimedBoardIO"]

Done = Callable[[Any, BaseException | None], None]


class Priority(enum.IntEnum):
    """Lower runs first. ``STOP`` abandons a lower-priority exchange in flight."""

    STOP = 0
    MOTION = 1
    ROUTINE = 2


@dataclass(eq=False)
class BoardOp:
    """One board transaction: ``run(board)`` on the I/O side, ``done(result, error)`` on the
    executor. ``name`` lets the node ask whether such an op is still pending."""

    name: str
    run: Callable[[Board], Any]
    done: Done | None = None
    priority: Priority = Priority.ROUTINE
    #: abandoned for a stop, run again right after it (only for requests without effects)
    rerun_after_stop: bool = False
    cancelled: bool = field(default=False, init=False)


class BoardIO(Protocol):
    """The queue the board node submits to."""

    def submit(self, op: BoardOp) -> None:
        """Queue ``op`` behind ops of its priority or higher (``STOP``: abandon lower ones)."""
        ...

    def pending(self, name: str) -> bool:
        """Whether an op called ``name`` is queued or in flight."""
        ...

    def cancel(self, predicate: Callable[[BoardOp], bool]) -> None:
        """Drop queued ops that match (their ``done`` is never called)."""
        ...

    def close(self, timeout_s: float = 1.0) -> None:
        """Run what is queued (up to ``timeout_s``), then stop."""
        ...


def _insert(queue: deque[BoardOp], op: BoardOp) -> None:
    for i, queued in enumerate(queue):
        if queued.priority > op.priority:
            queue.insert(i, op)
            return
    queue.append(op)


def _insert_first(queue: deque[BoardOp], op: BoardOp) -> None:
    """``op`` ahead of every queued op of its priority (an abandoned op runs again next)."""
    for i, queued in enumerate(queue):
        if queued.priority >= op.priority:
            queue.insert(i, op)
            return
    queue.append(op)


class _OpQueue:
    """The queue both implementations keep: ops by priority and the one in flight."""

    def __init__(self, board: Board) -> None:
        self.board = board
        self._queue: deque[BoardOp] = deque()
        self._current: BoardOp | None = None
        self._cond = threading.Condition()

    def pending(self, name: str) -> bool:
        with self._cond:
            current = self._current
            return (current is not None and current.name == name) or any(
                op.name == name for op in self._queue)

    def cancel(self, predicate: Callable[[BoardOp], bool]) -> None:
        with self._cond:
            for op in [op for op in self._queue if predicate(op)]:
                op.cancelled = True
                self._queue.remove(op)


class ThreadedBoardIO(_OpQueue):
    """Runs ops on a worker thread; ``post(fn)`` must run ``fn`` on the node's executor."""

    def __init__(self, board: Board, post: Callable[[Callable[[], None]], None]) -> None:
        super().__init__(board)
        self._post = post
        self._closing = False
        self._thread = threading.Thread(target=self._worker, name="board-io", daemon=True)
        self._thread.start()

    def submit(self, op: BoardOp) -> None:
        with self._cond:
            _insert(self._queue, op)
            current = self._current
            if op.priority == Priority.STOP and current is not None and current.priority > op.priority:
                self.board.core.interrupt()
            self._cond.notify_all()

    def _worker(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closing:
                    self._cond.wait()
                if not self._queue:
                    return
                op = self._queue.popleft()
                self._current = op
                # an interrupt meant for an op that has finished must not hit this one
                self.board.core.clear_interrupt()
            result: Any = None
            error: BaseException | None = None
            try:
                result = op.run(self.board)
            except Exception as exc:
                error = exc
            with self._cond:
                self._current = None
                rerun = (isinstance(error, BoardInterrupted) and op.rerun_after_stop
                         and not op.cancelled and not self._closing)
                if rerun:
                    _insert_first(self._queue, op)
                self._cond.notify_all()
            if rerun:
                continue
            if op.done is not None and not op.cancelled:
                done = op.done
                self._post(lambda d=done, r=result, e=error: d(r, e))  # type: ignore[misc]

    def close(self, timeout_s: float = 1.0) -> None:
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        self._thread.join(timeout_s)

    def wait_idle(self, timeout_s: float) -> bool:
        """Block until nothing is queued or in flight (True) or ``timeout_s`` passes."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._queue and self._current is None,
                                       timeout_s)


class TimedBoardIO(_OpQueue):
    """Runs ops inline against a :class:`~eddiebot.robot.links.TimedEmulatorLink` and
    delivers each result after the wire time the link accounted for.

    ``call_later(delay_ns, fn)`` schedules ``fn`` on the node's clock (a one-shot timer).
    """

    def __init__(self, board: Board, call_later: Callable[[int, Callable[[], None]], Any]) -> None:
        super().__init__(board)
        self._call_later = call_later
        self._result: tuple[Any, BaseException | None] = (None, None)
        self._token = 0
        self._closing = False

    def submit(self, op: BoardOp) -> None:
        _insert(self._queue, op)
        current = self._current
        if op.priority == Priority.STOP and current is not None and current.priority > op.priority:
            # abandon the exchange in flight: its reply is never delivered
            self._token += 1
            self._current = None
            if current.rerun_after_stop and not current.cancelled:
                _insert_first(self._queue, current)
            elif current.done is not None and not current.cancelled:
                current.done(None, BoardInterrupted(current.name))
        self._kick()

    def _kick(self) -> None:
        if self._current is not None or not self._queue:
            return
        op = self._queue.popleft()
        self._current = op
        link: Any = self.board.link
        link.take_elapsed_ns()
        result: Any = None
        error: BaseException | None = None
        try:
            result = op.run(self.board)
        except Exception as exc:
            error = exc
        self._result = (result, error)
        self._token += 1
        token = self._token
        self._call_later(max(1, link.take_elapsed_ns()), lambda: self._complete(token))

    def _complete(self, token: int) -> None:
        if token != self._token or self._current is None:
            return  # abandoned for a stop
        op, self._current = self._current, None
        result, error = self._result
        if op.done is not None and not op.cancelled:
            op.done(result, error)
        if not self._closing:
            self._kick()

    def close(self, timeout_s: float = 1.0) -> None:
        """Run what is queued now, without waiting for the wire (shutdown)."""
        self._closing = True
        while self._queue:
            op = self._queue.popleft()
            try:
                op.run(self.board)
            except Exception:
                pass
