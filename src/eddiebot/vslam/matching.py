"""Hamming-distance matching of 256-bit binary descriptors (ORB): exact k=2 search and NNDR."""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

from eddiebot.geometry.grid import bucket_grid

__all__ = [
    "as_words64",
    "knn2_hamming",
    "knn2_hamming_candidates",
    "knn2_hamming_window",
    "nndr_one_to_one",
    "popcount64",
]

_NO_MATCH = 1 << 30


def as_words64(descriptors: NDArray[np.uint8]) -> NDArray[np.uint64]:
    """(N, 32) uint8 descriptors viewed as (N, 4) uint64 for popcount distances."""
    d = np.ascontiguousarray(descriptors, dtype=np.uint8)
    if d.shape[1] != 32:
        raise ValueError(f"expected 32-byte descriptors, got {d.shape[1]}")
    return d.view(np.uint64).reshape(-1, 4)


@njit(cache=True, inline="always")
def popcount64(x: np.uint64) -> np.uint64:
    """Set bits of a 64-bit word (compiled; for use inside other compiled kernels)."""
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
    # train words column by column and a distance pass before the selection pass: the
    # distance loop then compiles to vector popcounts (about 2x faster than row by row)
    t0 = np.ascontiguousarray(t[:, 0])
    t1 = np.ascontiguousarray(t[:, 1])
    t2 = np.ascontiguousarray(t[:, 2])
    t3 = np.ascontiguousarray(t[:, 3])
    dist = np.empty(m, np.int64)
    for i in range(n):
        q0 = q[i, 0]
        q1 = q[i, 1]
        q2 = q[i, 2]
        q3 = q[i, 3]
        for j in range(m):
            dist[j] = np.int64(popcount64(q0 ^ t0[j]) + popcount64(q1 ^ t1[j])
                               + popcount64(q2 ^ t2[j]) + popcount64(q3 ^ t3[j]))
        b1 = _NO_MATCH
        b2 = _NO_MATCH
        i1 = -1
        i2 = -1
        for j in range(m):
            d = dist[j]
            if d < b2 and t_mask[j]:
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
                popcount64(q[i, 0] ^ t[j, 0]) + popcount64(q[i, 1] ^ t[j, 1])
                + popcount64(q[i, 2] ^ t[j, 2]) + popcount64(q[i, 3] ^ t[j, 3])
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
def _knn2_window(q, t, q_uv, t_uv, t_rows, radius):  # type: ignore[no-untyped-def]
    n = q.shape[0]
    m = t_uv.shape[0]
    out_i = np.full((n, 2), -1, np.int64)
    out_d = np.full((n, 2), _NO_MATCH, np.int64)
    if m == 0 or n == 0 or not radius >= 0.0:
        return out_i, out_d
    r2 = radius * radius
    # grid of cells a little wider than the radius: a point within the radius of a query lies
    # in the query's cell or a neighbouring one, whatever the rounding
    cell = radius * 1.0001 + 1e-9
    u0, v0, nx, ny, start, order = bucket_grid(t_uv, cell)
    for i in range(n):
        qu = q_uv[i, 0]
        qv = q_uv[i, 1]
        gx = math.floor((qu - u0) / cell)
        gy = math.floor((qv - v0) / cell)
        b1 = _NO_MATCH
        b2 = _NO_MATCH
        k1 = m
        k2 = m
        for y in range(max(gy - 1, 0), min(gy + 2, ny)):
            for x in range(max(gx - 1, 0), min(gx + 2, nx)):
                c = y * nx + x
                for e in range(start[c], start[c + 1]):
                    k = order[e]
                    du = t_uv[k, 0] - qu
                    dv = t_uv[k, 1] - qv
                    if du * du + dv * dv > r2:
                        continue
                    j = t_rows[k]
                    d = int(popcount64(q[i, 0] ^ t[j, 0]) + popcount64(q[i, 1] ^ t[j, 1])
                            + popcount64(q[i, 2] ^ t[j, 2]) + popcount64(q[i, 3] ^ t[j, 3]))
                    # the two smallest (distance, position): what a scan in position order
                    # keeping the first of equal distances gives
                    if d < b1 or (d == b1 and k < k1):
                        b2 = b1
                        k2 = k1
                        b1 = d
                        k1 = k
                    elif d < b2 or (d == b2 and k < k2):
                        b2 = d
                        k2 = k
        if k1 < m:
            out_i[i, 0] = t_rows[k1]
            out_d[i, 0] = b1
        if k2 < m:
            out_i[i, 1] = t_rows[k2]
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


def knn2_hamming_window(
    query: NDArray[np.uint64],
    train: NDArray[np.uint64],
    query_uv: NDArray[np.floating],
    train_uv: NDArray[np.floating],
    train_rows: NDArray[np.integer],
    radius: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """As `knn2_hamming_candidates` with, for query i, the candidates `train_rows[k]` whose
    image position `train_uv[k]` lies within `radius` px (Euclidean, inclusive) of
    `query_uv[i]`, in increasing k: the lists `cKDTree.query_ball_point` gives, searched on a
    grid in one compiled pass instead of as Python lists. Indices are rows of `train`."""
    return _knn2_window(  # type: ignore[no-any-return]
        query, train, np.ascontiguousarray(query_uv, np.float64),
        np.ascontiguousarray(train_uv, np.float64), np.ascontiguousarray(train_rows, np.int64),
        float(radius))


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
