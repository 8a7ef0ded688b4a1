"""Runs localization's whole-map relocalisation searches in a process of its own, so that the
SLAM node's scan callback never waits for one.

A search is a branch and bound over the whole map at every heading, of one scan (its view of
the buffered scans is then checked at the scan's best places): 0.1–1 s of CPU on the Intel,
ACES and CSAIL half-maps (benchmarks/bench_slam_localization.py). The kernels are
compiled numba functions that hold the GIL for the whole of each call, so a thread would stall
the node's executor as long. The child is spawned once, keeps the map's correlation grid
between searches (rebuilt when `GlobalMap.key` changes) and answers one search at a time;
`Localization` polls for the answer on each later scan (`Localization.global_search`).
"""

from __future__ import annotations

import multiprocessing
import threading
import time
from multiprocessing.connection import Connection
from typing import Any

from eddiebot.slam.mapper.localization import GlobalMap
from eddiebot.slam.mapper.results import FloatArray
from eddiebot.slam.scan_matcher import CorrelationGrid, MatchResult

__all__ = ["RelocalizationProcess"]


def _child(conn: Connection) -> None:
    """Serve (ticket, map or None, points, view or None, tracked or None) requests with
    (ticket, match, CPU seconds)."""
    source: GlobalMap | None = None
    grid: CorrelationGrid | None = None
    while True:
        try:
            request = conn.recv()
        except EOFError:
            return
        if request is None:
            return
        ticket, new_source, points, view, tracked = request
        t0 = time.process_time()
        if new_source is not None:
            source, grid = new_source, new_source.grid()
        assert source is not None and grid is not None
        match = source.search(points, grid, view, tracked)
        conn.send((ticket, match, time.process_time() - t0))


class RelocalizationProcess:
    """A `eddiebot.slam.mapper.localization.GlobalSearch` in a spawned child process (started
    at the first search). ``submit`` and ``poll`` never wait for a search; the map is sent
    once per `GlobalMap.key`. ``search_cpu_s`` holds each finished search's CPU time in the
    child."""

    def __init__(self) -> None:
        self._ctx = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._proc: Any = None
        self._conn: Connection | None = None
        self._sent_key: int | None = None
        self._tickets = 0
        self._in_flight = 0
        self.search_cpu_s: list[float] = []

    def submit(
        self,
        source: GlobalMap,
        points: FloatArray,
        view: FloatArray | None = None,
        tracked: FloatArray | None = None,
    ) -> int:
        with self._lock:
            if self._conn is None:
                parent, child = self._ctx.Pipe(duplex=True)
                self._proc = self._ctx.Process(
                    target=_child, args=(child,), name="slam-relocalization", daemon=True
                )
                self._proc.start()
                child.close()
                self._conn = parent
                self._sent_key = None
            self._tickets += 1
            send = source if source.key != self._sent_key else None
            self._conn.send((self._tickets, send, points, view, tracked))
            self._sent_key = source.key
            self._in_flight += 1
            return self._tickets

    def poll(self) -> tuple[int, MatchResult] | None:
        with self._lock:
            conn = self._conn
            if conn is None or self._in_flight == 0:
                return None
            try:
                if not conn.poll():
                    return None
                ticket, match, cpu = conn.recv()
            except (EOFError, OSError):
                self._drop()
                return None
            self._in_flight -= 1
            self.search_cpu_s.append(cpu)
            return ticket, match

    def busy(self) -> bool:
        """A search is running (or waiting to)."""
        return self._in_flight > 0

    def wait(self, timeout: float | None = None) -> bool:
        """Block until an answer can be polled (True) or ``timeout`` s pass (False)."""
        conn = self._conn
        if conn is None or self._in_flight == 0:
            return False
        return bool(conn.poll(timeout))

    def _drop(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._conn = None
        self._in_flight = 0
        if self._proc is not None:
            self._proc.join(1.0)
        self._proc = None

    def close(self) -> None:
        """End the child (a search in flight is abandoned)."""
        with self._lock:
            proc = self._proc
            if self._conn is not None:
                try:
                    self._conn.send(None)
                except (BrokenPipeError, OSError):
                    pass
            if proc is not None and proc.is_alive():
                proc.terminate()
            self._drop()
