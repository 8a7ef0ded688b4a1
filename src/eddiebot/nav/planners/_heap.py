"""The binary min-heap of the planners' open sets (Theta*, Smac), as parallel key/value
arrays (numba)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _grow(hk: np.ndarray, hv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The heap's arrays, doubled when full (call before :func:`_push`)."""
    if size < hk.shape[0]:
        return hk, hv
    return (np.concatenate((hk, np.empty(hk.shape[0]))),
            np.concatenate((hv, np.empty(hv.shape[0], dtype=np.int64))))


@njit(cache=True)
def _push(hk: np.ndarray, hv: np.ndarray, size: int, key: float, val: int) -> int:
    i = size
    hk[i] = key
    hv[i] = val
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= hk[i]:
            break
        hk[p], hk[i] = hk[i], hk[p]
        hv[p], hv[i] = hv[i], hv[p]
        i = p
    return size + 1


@njit(cache=True)
def _pop(hk: np.ndarray, hv: np.ndarray, size: int) -> tuple[float, int, int]:
    """The smallest key, its value and the new size."""
    key = hk[0]
    top = hv[0]
    size -= 1
    hk[0] = hk[size]
    hv[0] = hv[size]
    i = 0
    while True:
        left = 2 * i + 1
        r = left + 1
        m = i
        if left < size and hk[left] < hk[m]:
            m = left
        if r < size and hk[r] < hk[m]:
            m = r
        if m == i:
            break
        hk[m], hk[i] = hk[i], hk[m]
        hv[m], hv[i] = hv[i], hv[m]
        i = m
    return key, top, size


__all__ = ["_grow", "_pop", "_push"]
