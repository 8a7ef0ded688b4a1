"""What the Smac searches share: their status codes, the cell costs they test, the turn
directions of the Hybrid motion primitives, and a clock readable inside numba."""

from __future__ import annotations

import time

from numba import njit, objmode

FOUND = 0
NO_PATH = 1
MAX_ITERATIONS = 2
TIMED_OUT = 3

UNKNOWN = 255
OCCUPIED = 254
INSCRIBED = 253

# turn directions (upstream's TurnDirection)
FORWARD = 0
LEFT = 1
RIGHT = 2
REVERSE = 3
REV_LEFT = 4
REV_RIGHT = 5


@njit(cache=True)
def _now() -> float:
    with objmode(t="float64"):
        t = time.perf_counter()
    return t


__all__ = ["FORWARD", "FOUND", "INSCRIBED", "LEFT", "MAX_ITERATIONS", "NO_PATH", "OCCUPIED", "REVERSE", "REV_LEFT", "REV_RIGHT", "RIGHT", "TIMED_OUT", "UNKNOWN", "_now"]
