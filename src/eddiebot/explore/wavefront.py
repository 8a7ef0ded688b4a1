"""The wavefront: path lengths (m, 8-connected Dijkstra, numba) through the cells a robot's
centre may occupy, from one cell or from several labelled seeds at once."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["distance_field"]


@njit(cache=True)
def _heap_push(hc: np.ndarray, hi: np.ndarray, n: int, cost: float, idx: int
               ) -> int:  # pragma: no cover - compiled
    """Push (cost, idx) on the binary min-heap held in ``hc``/``hi[:n]``; the new size."""
    hc[n] = cost
    hi[n] = idx
    j = n
    while j > 0:
        p = (j - 1) // 2
        if hc[p] <= hc[j]:
            break
        hc[p], hc[j] = hc[j], hc[p]
        hi[p], hi[j] = hi[j], hi[p]
        j = p
    return n + 1


@njit(cache=True)
def _dijkstra(passable: np.ndarray, seeds_r: np.ndarray, seeds_c: np.ndarray,
              seed_cost: np.ndarray, seed_label: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    h, w = passable.shape
    dist = np.full((h, w), np.inf)
    label = np.zeros((h, w), dtype=np.int64)
    # binary heap of (cost, flat index)
    cap = h * w * 4 + 16
    hc = np.empty(cap)
    hi = np.empty(cap, dtype=np.int64)
    n = 0
    for k in range(seeds_r.size):
        r, c = seeds_r[k], seeds_c[k]
        if seed_cost[k] < dist[r, c]:
            dist[r, c] = seed_cost[k]
            label[r, c] = seed_label[k]
            n = _heap_push(hc, hi, n, seed_cost[k], r * w + c)
    dr = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
    dc = np.array([-1, 0, 1, -1, 1, -1, 0, 1])
    step = np.array([1.4142135623730951, 1.0, 1.4142135623730951, 1.0, 1.0,
                     1.4142135623730951, 1.0, 1.4142135623730951])
    while n > 0:
        cost = hc[0]
        idx = hi[0]
        n -= 1
        hc[0] = hc[n]
        hi[0] = hi[n]
        j = 0
        while True:
            a = 2 * j + 1
            if a >= n:
                break
            b = a + 1
            m = b if b < n and hc[b] < hc[a] else a
            if hc[j] <= hc[m]:
                break
            hc[m], hc[j] = hc[j], hc[m]
            hi[m], hi[j] = hi[j], hi[m]
            j = m
        r = idx // w
        c = idx % w
        if cost > dist[r, c]:
            continue
        for k in range(8):
            rr = r + dr[k]
            cc = c + dc[k]
            if rr < 0 or cc < 0 or rr >= h or cc >= w or not passable[rr, cc]:
                continue
            nc = cost + step[k]
            if nc < dist[rr, cc]:
                dist[rr, cc] = nc
                label[rr, cc] = label[r, c]
                if n < cap:
                    n = _heap_push(hc, hi, n, nc, rr * w + cc)
    return dist, label


def distance_field(passable: npt.NDArray[np.bool_], start: tuple[int, int],
                   resolution: float, snap_radius_cells: int = 10) -> npt.NDArray[np.float64]:
    """Path length (m, 8-connected) from cell ``start`` = (column, row) through ``passable``
    cells; inf where none leads. A start off the passable cells (the robot inside the
    inflation after a map update) starts from the passable cells within
    ``snap_radius_cells``, each at its straight-line distance."""
    h, w = passable.shape
    c0, r0 = start
    rr, cc = np.mgrid[-snap_radius_cells:snap_radius_cells + 1, -snap_radius_cells:snap_radius_cells + 1]
    rr, cc = rr.ravel() + r0, cc.ravel() + c0
    ok = (rr >= 0) & (cc >= 0) & (rr < h) & (cc < w)
    rr, cc = rr[ok], cc[ok]
    if 0 <= r0 < h and 0 <= c0 < w and passable[r0, c0]:
        seeds_r, seeds_c, cost = np.array([r0]), np.array([c0]), np.zeros(1)
    else:
        keep = passable[rr, cc]
        seeds_r, seeds_c = rr[keep], cc[keep]
        cost = np.hypot(seeds_r - r0, seeds_c - c0).astype(np.float64)
    if seeds_r.size == 0:
        return np.full((h, w), np.inf)
    dist, _ = _dijkstra(np.ascontiguousarray(passable), seeds_r.astype(np.int64),
                        seeds_c.astype(np.int64), cost, np.zeros(seeds_r.size, dtype=np.int64))
    return dist * resolution
