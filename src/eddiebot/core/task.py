"""Futures and coroutine tasks run by the executors (rclpy's ``Future`` and ``Task``)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Coroutine, Generator
from typing import Any


class Future:
    """The result of work that finishes later: a service call, an action goal, a task.

    ``await future`` inside a coroutine callback suspends that callback until the future is
    done; the executor resumes it. Done-callbacks run on the thread that completes it.
    """

    def __init__(self) -> None:
        self._done = False
        self._cancelled = False
        self._result: Any = None
        self._exception: BaseException | None = None
        self._callbacks: list[Callable[[Future], None]] = []
        self._lock = threading.Lock()
        self._event = threading.Event()

    def done(self) -> bool:
        return self._done

    def cancelled(self) -> bool:
        return self._cancelled

    def cancel(self) -> None:
        self._complete(None, None, cancelled=True)

    def result(self) -> Any:
        """The result, or raise the exception the work raised (None while not done)."""
        if self._exception is not None:
            raise self._exception
        return self._result

    def exception(self) -> BaseException | None:
        return self._exception

    def set_result(self, result: Any) -> None:
        self._complete(result, None)

    def set_exception(self, exc: BaseException) -> None:
        self._complete(None, exc)

    def _complete(self, result: Any, exc: BaseException | None, cancelled: bool = False) -> None:
        with self._lock:
            if self._done:
                return
            self._result, self._exception, self._cancelled = result, exc, cancelled
            self._done = True
            callbacks, self._callbacks = self._callbacks, []
        self._event.set()
        for cb in callbacks:
            cb(self)

    def add_done_callback(self, callback: Callable[[Future], None]) -> None:
        with self._lock:
            if not self._done:
                self._callbacks.append(callback)
                return
        callback(self)

    def wait(self, timeout_s: float | None = None) -> bool:
        """Block this thread until done (only when another thread completes it)."""
        return self._event.wait(timeout_s)

    def __await__(self) -> Generator[Future, None, Any]:
        if not self._done:
            yield self
        return self.result()


class Task(Future):
    """A coroutine driven by an executor; it is itself a future of the coroutine's result."""

    def __init__(self, coro: Coroutine[Any, Any, Any], reschedule: Callable[[Task], None]) -> None:
        super().__init__()
        self._coro = coro
        self._reschedule = reschedule
        self._running = threading.Lock()

    def step(self) -> None:
        """Run the coroutine until it awaits a pending future or finishes."""
        if self._done or not self._running.acquire(blocking=False):
            return
        try:
            awaited = self._coro.send(None)
        except StopIteration as stop:
            self.set_result(stop.value)
            return
        except BaseException as exc:
            self.set_exception(exc)
            return
        finally:
            self._running.release()
        if isinstance(awaited, Future):
            awaited.add_done_callback(lambda _f: self._reschedule(self))
        else:
            # a bare `yield` / unknown awaitable: try again on the next round
            self._reschedule(self)
