"""Karto's match covariance: the response-weighted spread of the candidates near the best."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True)
def _weighted_covariance(
    values: FloatArray, coords: FloatArray, best: float, floor: FloatArray
) -> FloatArray:
    """Response-weighted covariance (D, D) of the candidates whose value is within 0.1 of
    ``best``, plus ``diag(floor)``; ``coords`` (K, D) are the candidates' coordinates."""
    dim = coords.shape[1]
    thresh = best - 0.1
    norm = 0.0
    mean = np.zeros(dim)
    for i in range(values.size):
        if values[i] >= thresh:
            norm += values[i]
            for j in range(dim):
                mean[j] += values[i] * coords[i, j]
    out = np.zeros((dim, dim))
    if norm <= 1e-12:
        for j in range(dim):
            out[j, j] = floor[j]
        return out
    for j in range(dim):
        mean[j] /= norm
    d = np.empty(dim)
    for i in range(values.size):
        if values[i] >= thresh:
            for j in range(dim):
                d[j] = coords[i, j] - mean[j]
            for j in range(dim):
                wd = values[i] * d[j]
                for m in range(dim):
                    out[j, m] += wd * d[m]
    for j in range(dim):
        for m in range(dim):
            out[j, m] = out[j, m] / norm + (floor[j] if j == m else 0.0)
    return out
