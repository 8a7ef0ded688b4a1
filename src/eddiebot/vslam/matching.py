"""Hamming-distance matching of 256-bit binary descriptors (ORB): exact k=2 search and NNDR."""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["as_words64", "knn2_hamming", "knn2_hamming_candidates", "nndr_one_to_one"]

_NO_MATCH = 1 << 30


def as_words64(descriptors: NDArray[np.uint8]) -> NDArray[np.uint64]:
    """(N, 32) uint8 descriptors viewed as (N, 4) uint64 for popcount distances."""
    d = np.ascontiguousarray(descriptors, dtype=np.uint8)
    if d.shape[1] != 32:
        raise ValueError(f"expected 32-byte descriptors, got {d.shape[1]}")
    return d.view(np.uint64).reshape(-1, 4)


@njit(cache=True, inline="always")
def _popcount64(x: np.uint64) -> np.uint64:
    x = x - ((x >> np.uint64(1)) & np.uint64(0x5555555555555555))
    x = (x & np.uint64(0x3333333333333333)) + ((x >> np.uint64(2)) & np.uint64(0x3333333333333333))
    x = (x + (x >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (x * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True)
def _knn2(q, t, t_mask):  # type: ignore[no-untyped-def]
    n = q.shape[0]
    m = t.shape[0]
    out_i = np.full((n, 2), -1, np.int64)
    out_d = np.full((n, 2), _NO_MATCH, np.int64)
    for i in range(n):
        b1 = _NO_MATCH
        b2 = _NO_MATCH
        i1 = -1
        i2 = -1
        q0 = q[i, 0]
        q1 = q[i, 1]
        q2 = q[i, 2]
        q3 = q[i, 3]
        for j in range(m):
            if not t_mask[j]:
                continue
            d = int(
                _popcount64(q0 ^ t[j, 0]) + _popcount64(q1 ^ t[j, 1])
                + _popcount64(q2 ^ t[j, 2]) + _popcount64(q3 ^ t[j, 3])
            )
            if d < b2:
                if d < b1:
                    b2 = b1
                    i2 = i1
                    b1 = d
                    i1 = j
                else:
                    b2 = d
                    i2 = j
        out_i[i, 0] = i1
        out_i[i, 1] = i2
        out_d[i, 0] = b1
        out_d[i, 1] = b2
    return out_i, out_d


@njit(cache=True)
def _knn2_candidates(q, t, offsets, cand):  # type: ignore[no-untyped-def]
    n = q.shape[0]
    out_i = np.full((n, 2), -1, np.int64)
    out_d = np.full((n, 2), _NO_MATCH, np.int64)
    for i in range(n):
        b1 = _NO_MATCH
        b2 = _NO_MATCH
        i1 = -1
        i2 = -1
        for k in range(offsets[i], offsets[i + 1]):
            j = cand[k]
            d = int(
                _popcount64(q[i, 0] ^ t[j, 0]) + _popcount64(q[i, 1] ^ t[j, 1])
                + _popcount64(q[i, 2] ^ t[j, 2]) + _popcount64(q[i, 3] ^ t[j, 3])
            )
            if d < b2:
                if d < b1:
                    b2 = b1
                    i2 = i1
                    b1 = d
                    i1 = j
                else:
                    b2 = d
                    i2 = j
        out_i[i, 0] = i1
        out_i[i, 1] = i2
        out_d[i, 0] = b1
        out_d[i, 1] = b2
    return out_i, out_d


def knn2_hamming(
    query: NDArray[np.uint64], train: NDArray[np.uint64], train_mask: NDArray[np.bool_] | None = None
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Two nearest train rows per query row: (indices (N, 2), distances (N, 2)); -1 = none."""
    mask = np.ones(train.shape[0], np.bool_) if train_mask is None else train_mask
    if query.shape[0] == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64)
    return _knn2(query, train, mask)  # type: ignore[no-any-return]


def knn2_hamming_candidates(
    query: NDArray[np.uint64],
    train: NDArray[np.uint64],
    offsets: NDArray[np.int64],
    candidates: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """As `knn2_hamming` but query i only looks at train rows candidates[offsets[i]:offsets[i+1]]."""
    if query.shape[0] == 0:
        return np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64)
    return _knn2_candidates(query, train, offsets, candidates)  # type: ignore[no-any-return]


def nndr_one_to_one(
    indices: NDArray[np.int64], distances: NDArray[np.int64], ratio: float
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Query/train index pairs passing d1 <= ratio·d2 (two candidates needed), one-to-one by distance."""
    ok = (indices[:, 0] >= 0) & (indices[:, 1] >= 0)
    ok &= distances[:, 0] <= ratio * distances[:, 1]
    q = np.flatnonzero(ok)
    t = indices[q, 0]
    d = distances[q, 0]
    order = np.lexsort((q, d))
    q, t = q[order], t[order]
    _, first = np.unique(t, return_index=True)
    keep = np.sort(first)
    return q[keep].astype(np.intp), t[keep].astype(np.intp)
