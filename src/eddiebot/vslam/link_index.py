"""The memory's links as arrays for the compiled loop-margin walk (the Bayes prediction's
neighbourhood search): `LinkIndex` mirrors `Memory.links`, `walk_loop_margin` walks it."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numba import njit
from numpy.typing import NDArray

from eddiebot.vslam.nodes import ODOMETRY_LINK_TYPES, LinkType

__all__ = ["LinkIndex", "link_kind", "walk_loop_margin"]

# kinds of a link in `LinkIndex` (how the loop-margin walk follows it)
_KIND_ODOMETRY, _KIND_LOOP, _KIND_LOCAL_SPACE = 0, 1, 2


class LinkIndex:
    """`Memory.links` as arrays for the compiled loop-margin walk: row `id` holds the node's
    neighbours and link kinds in the order of its links dict (a replaced link keeps its
    place, a removed one leaves the row, a re-added one goes last, as in a dict).

    Usable while node ids are non-negative and dense enough for rows indexed by id."""

    _MAX_SPARSITY = 4  # rows allowed per link-holding node (plus a constant)

    def __init__(self) -> None:
        self.nbr = np.zeros((64, 4), np.int64)
        self.kind = np.zeros((64, 4), np.int8)
        self.deg = np.zeros(64, np.int64)
        self.usable = True
        self._nodes = 0

    def _row(self, i: int) -> bool:
        if i < 0 or i >= self._MAX_SPARSITY * (self._nodes + 1) + 4096:
            self.usable = False
            return False
        if i >= self.deg.size:
            rows = max(i + 1, 2 * self.deg.size)
            extra = rows - self.deg.size
            self.nbr = np.concatenate([self.nbr, np.zeros((extra, self.nbr.shape[1]), np.int64)])
            self.kind = np.concatenate([self.kind,
                                        np.zeros((extra, self.kind.shape[1]), np.int8)])
            self.deg = np.concatenate([self.deg, np.zeros(extra, np.int64)])
        return True

    def register(self, i: int) -> None:
        """A node id now has a links dict."""
        self._nodes += 1
        if self.usable:
            self._row(i)

    def put(self, a: int, b: int, kind: int) -> None:
        """`links[a][b] = link` (of this kind)."""
        if not (self.usable and self._row(a) and self._row(b)):
            return
        d = int(self.deg[a])
        hit = np.flatnonzero(self.nbr[a, :d] == b)
        if hit.size:
            self.kind[a, hit[0]] = kind
            return
        if d == self.nbr.shape[1]:
            cols = 2 * d
            self.nbr = np.concatenate([self.nbr, np.zeros((self.nbr.shape[0], cols - d), np.int64)],
                                      axis=1)
            self.kind = np.concatenate([self.kind, np.zeros((self.kind.shape[0], cols - d), np.int8)],
                                       axis=1)
        self.nbr[a, d] = b
        self.kind[a, d] = kind
        self.deg[a] = d + 1

    def pop(self, a: int, b: int) -> None:
        """`links[a].pop(b)`."""
        if not self.usable or a < 0 or a >= self.deg.size:
            return
        d = int(self.deg[a])
        hit = np.flatnonzero(self.nbr[a, :d] == b)
        if hit.size:
            k = int(hit[0])
            self.nbr[a, k:d - 1] = self.nbr[a, k + 1:d].copy()
            self.kind[a, k:d - 1] = self.kind[a, k + 1:d].copy()
            self.deg[a] = d - 1

    def clear(self, a: int) -> None:
        """`links.pop(a)`."""
        if self.usable and 0 <= a < self.deg.size:
            self.deg[a] = 0

    def members(self, ids: Iterable[int], count: int) -> NDArray[np.bool_] | None:
        """Rows flagged for these ids (None if one cannot have a row)."""
        flags = np.zeros(self.deg.size, np.bool_)
        arr = np.fromiter(ids, np.int64, count)
        if arr.size and int(arr.min()) < 0:
            return None
        if arr.size and int(arr.max()) >= flags.size:
            arr = arr[arr < flags.size]  # ids beyond the rows hold no links: never reached
        flags[arr] = True
        return flags


def link_kind(link_type: LinkType) -> int:
    if link_type in ODOMETRY_LINK_TYPES:
        return _KIND_ODOMETRY
    return _KIND_LOCAL_SPACE if link_type == LinkType.LOCAL_SPACE_CLOSURE else _KIND_LOOP


@njit(cache=True)
def walk_loop_margin(nbr, kind, deg, start, max_depth, in_stm, in_wm, wm_only):  # type: ignore[no-untyped-def]
    """`Memory._neighbours_loop_margin` over `LinkIndex` rows: (ids, depths) in the order the
    Python walk inserts them."""
    n = deg.size
    out_id = np.empty(n, np.int64)
    out_depth = np.empty(n, np.int64)
    n_out = 0
    if start < 0 or start >= n:
        return out_id[:0], out_depth[:0]
    seen = np.zeros(n, np.bool_)
    seen[start] = True
    margin = np.empty(n + 1, np.int64)
    nxt = np.empty(n + 1, np.int64)
    odo = np.empty(int(deg.sum()) + 1, np.int64)
    margin[0] = start
    n_margin = 1
    for depth in range(max_depth + 1):
        n_odo = 0
        k = 0
        while k < n_margin:
            a = margin[k]
            k += 1
            for c in range(deg[a]):
                m = nbr[a, c]
                t = kind[a, c]
                if t == 0:
                    odo[n_odo] = m
                    n_odo += 1
                    continue
                if seen[m] or in_stm[m] or t == 2:
                    continue
                seen[m] = True
                if wm_only and not in_wm[m]:
                    continue
                out_id[n_out] = m
                out_depth[n_out] = depth
                n_out += 1
                margin[n_margin] = m
                n_margin += 1
        if depth == max_depth:
            break
        n_nxt = 0
        for q in range(n_odo):
            m = odo[q]
            if seen[m] or in_stm[m]:
                continue
            seen[m] = True
            if wm_only and not in_wm[m]:
                continue
            out_id[n_out] = m
            out_depth[n_out] = depth + 1
            n_out += 1
            nxt[n_nxt] = m
            n_nxt += 1
        if n_nxt == 0:
            break
        margin, nxt = nxt, margin
        n_margin = n_nxt
    return out_id[:n_out], out_depth[:n_out]


