"""Zenoh's blocking session calls (open, close) run in a helper thread that the caller waits
for interruptibly: inside Zenoh's native code the main thread runs no Python signal handler,
so Ctrl-C would otherwise wait for the call to return."""

from __future__ import annotations

import logging
import threading
import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

log = logging.getLogger("eddiebot.transport")

#: Helper threads still opening or closing a session that nobody waits for any more.
_LEFT_RUNNING: set[threading.Thread] = set()


def sessions_still_closing() -> bool:
    """True while a session open or close that the caller stopped waiting for still runs.

    Python joins no daemon thread at exit, but such a thread returning from Zenoh during
    interpreter shutdown can abort the process; exit with ``os._exit`` instead.
    """
    return any(t.is_alive() for t in list(_LEFT_RUNNING))


def _call_in_thread(fn: Callable[[], Any], what: str, timeout_s: float | None,
                    on_late_result: Callable[[Any], None] | None = None) -> tuple[bool, Any]:
    """Run ``fn`` in a daemon thread and wait for it, interruptibly (Ctrl-C), for at most
    ``timeout_s`` (None: until it returns). Returns (finished, result); re-raises what ``fn``
    raised. When the wait ends first, ``on_late_result`` gets the result once ``fn`` returns.
    """
    lock = threading.Lock()
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            value = fn()
        except BaseException as exc:
            with lock:
                box["error"] = exc
            return
        with lock:
            box["value"] = value
            late = box.get("abandoned", False)
        if late and on_late_result is not None:
            on_late_result(value)

    thread = threading.Thread(target=target, name=f"eddie-zenoh-{what}", daemon=True)
    thread.start()
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    try:
        while thread.is_alive():
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            thread.join(0.05 if remaining is None else min(0.05, remaining))
    finally:
        with lock:
            done = "value" in box or "error" in box
            if not done:
                box["abandoned"] = True
                _LEFT_RUNNING.add(thread)
    if "error" in box:
        raise box["error"]
    return done, box.get("value")


def _close_quietly(session: Any) -> None:
    try:
        session.close()
    except Exception as exc:  # pragma: no cover
        log.debug("closing the zenoh session: %s", exc)
