"""Points bucketed into a regular 2D grid (a counting sort by cell), for radius searches in
compiled loops: scan-matching ICP correspondences and image-window descriptor matching."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

__all__ = ["bucket_grid"]


@njit(cache=True)
def bucket_grid(
    reference: npt.NDArray[np.float64], cell: float
) -> tuple[float, float, int, int, npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Reference points bucketed into square cells of side ``cell``: (x0, y0, nx, ny, start,
    order); cell k = iy·nx + ix holds ``order[start[k]:start[k + 1]]``."""
    n = reference.shape[0]
    x0 = reference[0, 0]
    y0 = reference[0, 1]
    x1 = x0
    y1 = y0
    for i in range(1, n):
        x0 = min(x0, reference[i, 0])
        x1 = max(x1, reference[i, 0])
        y0 = min(y0, reference[i, 1])
        y1 = max(y1, reference[i, 1])
    nx = int((x1 - x0) / cell) + 1
    ny = int((y1 - y0) / cell) + 1
    key = np.empty(n, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        ix = min(int((reference[i, 0] - x0) / cell), nx - 1)
        iy = min(int((reference[i, 1] - y0) / cell), ny - 1)
        key[i] = iy * nx + ix
        start[key[i] + 1] += 1
    for k in range(nx * ny):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return x0, y0, nx, ny, start, order
