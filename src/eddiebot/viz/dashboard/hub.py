"""Fan-out of dashboard frames from the node's thread to every browser connection.

Frames are keyed (``"pose"``, ``"scan"``, ``"tile:map:3:2"``, ...). A connection that falls
behind keeps only the newest frame per key, so a slow browser sees fewer updates instead of
an ever longer queue; the hub keeps the newest frame of each retained key so that a new
connection starts with the whole picture.

Some frames belong to a *view* a connection opens on request (``"tf"``, ``"cloud"``): they go
only to the connections that opened it, and the node builds them only while one has, so a
closed view costs nothing.
"""

from __future__ import annotations

import asyncio
import threading

__all__ = ["Frame", "Hub", "Outbox"]

Frame = str | bytes


class Outbox:
    """The frames waiting for one connection (newest per key), drained by its sender task."""

    def __init__(self, hub: Hub, loop: asyncio.AbstractEventLoop) -> None:
        self._hub = hub
        self._loop = loop
        self._pending: dict[str, Frame] = {}
        self._event = asyncio.Event()
        self._signalled = False
        #: on-demand views this connection opened
        self.views: set[str] = set()

    def _push(self, key: str, frame: Frame) -> None:
        # called with the hub lock held; an updated key keeps its place, so a grid's
        # description stays ahead of its tiles (a new generation drops the tiles first)
        self._pending[key] = frame
        if not self._signalled:
            self._signalled = True
            self._loop.call_soon_threadsafe(self._event.set)

    def _drop_prefix(self, prefix: str) -> None:
        for k in [k for k in self._pending if k.startswith(prefix)]:
            del self._pending[k]

    async def next_batch(self) -> list[Frame]:
        """Wait for frames, then take them all (in the order they became pending)."""
        await self._event.wait()
        self._event.clear()
        with self._hub.lock:
            self._signalled = False
            frames = list(self._pending.values())
            self._pending.clear()
        return frames


class Hub:
    """Thread-safe: ``post`` from any thread, outboxes drained on the server's event loop."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self._retained: dict[str, Frame] = {}
        #: view → key → newest frame, sent to a connection when it opens the view
        self._view_retained: dict[str, dict[str, Frame]] = {}
        self._outboxes: set[Outbox] = set()

    def post(self, key: str, frame: Frame, *, retain: bool = True, view: str | None = None) -> None:
        """Send ``frame`` to every connection (replacing an unsent frame of the same key);
        with ``view``, only to the connections that opened that view."""
        with self.lock:
            if view is not None:
                if retain:
                    self._view_retained.setdefault(view, {})[key] = frame
                for box in self._outboxes:
                    if view in box.views:
                        box._push(key, frame)
                return
            if retain:
                self._retained[key] = frame
            for box in self._outboxes:
                box._push(key, frame)

    def set_view(self, box: Outbox, view: str, on: bool) -> int:
        """Open or close ``view`` for one connection; the number of connections that have it
        open. Opening it sends the view's retained frames at once."""
        with self.lock:
            if on and view not in box.views:
                box.views.add(view)
                for key, frame in self._view_retained.get(view, {}).items():
                    box._push(key, frame)
            elif not on:
                box.views.discard(view)
            return sum(view in b.views for b in self._outboxes)

    def view_open(self, view: str) -> bool:
        """True while at least one connection has ``view`` open."""
        with self.lock:
            return any(view in b.views for b in self._outboxes)

    def drop_prefix(self, prefix: str) -> None:
        """Forget retained and unsent frames whose key starts with ``prefix``."""
        with self.lock:
            for k in [k for k in self._retained if k.startswith(prefix)]:
                del self._retained[k]
            for box in self._outboxes:
                box._drop_prefix(prefix)

    def attach(self, loop: asyncio.AbstractEventLoop) -> Outbox:
        """A new connection's outbox, primed with every retained frame."""
        box = Outbox(self, loop)
        with self.lock:
            for key, frame in self._retained.items():
                box._push(key, frame)
            self._outboxes.add(box)
        return box

    def detach(self, box: Outbox) -> None:
        with self.lock:
            self._outboxes.discard(box)

    @property
    def connections(self) -> int:
        with self.lock:
            return len(self._outboxes)
