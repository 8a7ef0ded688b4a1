"""Runs `eddiebot.slam.merge.place_copy` in a process of its own, for the SLAM node's
``~/add_submap``.

A thread is not enough: the scan-matching kernels are compiled numba functions that hold
the GIL for the whole of each call, and a placement's global searches make calls of up to
seconds each, during which the node's executor could run no callback (measured on Intel by
``benchmarks/bench_slam_merge_stall.py``: a 20 ms timer waited up to 3.8 s with the search on a
thread). In a spawned process the search shares nothing with the node but the two map copies
it is sent and the placement it sends back.
"""

from __future__ import annotations

import multiprocessing
import threading
from multiprocessing.connection import Connection
from typing import Any

from eddiebot.slam.errors import MergeError
from eddiebot.slam.merge import MapCopy, Placement, place_copy

__all__ = ["PlacementProcess"]


def _child(conn: Connection, map_copy: MapCopy, session: MapCopy) -> None:
    try:
        answer: tuple[Any, BaseException | None] = (place_copy(map_copy, session), None)
    except MergeError as exc:
        answer = (None, exc)
    except Exception as exc:  # sent back whole: the node logs it with the file name
        answer = (None, MergeError(f"placement failed: {type(exc).__name__}: {exc}"))
    conn.send(answer)
    conn.close()


class PlacementProcess:
    """Places sessions one at a time, each in a fresh spawned process (``run`` blocks its
    caller — the node's worker thread — until the answer; ``stop`` ends a search in
    flight)."""

    def __init__(self) -> None:
        self._ctx = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()
        self._proc: Any = None
        self._stopped = False

    def run(self, map_copy: MapCopy, session: MapCopy) -> Placement:
        """``place_copy(map_copy, session)`` in a child process; `MergeError` as it raises
        it, or when the process ends without an answer."""
        receive, send = self._ctx.Pipe(duplex=False)
        proc = self._ctx.Process(
            target=_child, args=(send, map_copy, session), name="slam-placement", daemon=True
        )
        with self._lock:
            if self._stopped:
                raise MergeError("the node is shutting down")
            proc.start()
            self._proc = proc
        send.close()
        try:
            placement, error = receive.recv()
        except EOFError:
            proc.join()
            raise MergeError(
                f"the placement process ended without an answer (exit code {proc.exitcode})"
            ) from None
        finally:
            receive.close()
            with self._lock:
                self._proc = None
        proc.join()
        if error is not None:
            raise error
        return placement  # type: ignore[no-any-return]

    def stop(self) -> None:
        """End the search in flight, if any, and refuse further ones."""
        with self._lock:
            self._stopped = True
            proc = self._proc
        if proc is not None and proc.is_alive():
            proc.terminate()
            proc.join(1.0)
