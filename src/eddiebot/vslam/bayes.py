"""Loop-closure likelihood (TF-IDF) and the discrete Bayes filter with a virtual "new place".

State −1 is the virtual place (the current image shows somewhere not in memory); the other
states are working-memory node ids. See rtabmap_semantics.md §2.2–2.4.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["VIRTUAL_PLACE_ID", "BayesFilter", "adjust_likelihood", "tfidf_scores"]

VIRTUAL_PLACE_ID = -1
_MASS_TOLERANCE = 1e-9  # column sums closer than this to the full mass count as full


def tfidf_scores(
    words: Mapping[int, int],
    inverted_index: Mapping[int, Mapping[int, int]],
    node_word_totals: Mapping[int, int],
    n_nodes: int,
    candidates: Iterable[int],
) -> dict[int, float]:
    """Σ over the new node's unique words of (n_wj / n_j)·log10(N / n_w) for each candidate j.

    `words`: word id → occurrences in the new node; `inverted_index`: word → {node: occurrences}
    over all nodes in memory (N = `n_nodes`); `node_word_totals`: n_j (word occurrences in j).
    """
    scores = dict.fromkeys(set(candidates), 0.0)
    if n_nodes <= 0:
        return scores
    get = inverted_index.get
    log10 = math.log10
    for w in words:
        postings = get(w)
        if not postings:
            continue
        idf = log10(n_nodes / len(postings))
        if idf <= 0.0:
            continue
        for j, n_wj in postings.items():
            if j in scores:
                scores[j] += n_wj / node_word_totals[j] * idf
    return scores


def adjust_likelihood(scores: Mapping[int, float], virtual_ratio_mode: int = 0) -> dict[int, float]:
    """RTAB-Map's likelihood adjustment; returns likelihoods including the virtual place (−1).

    With mean μ and std σ of the non-zero scores: s > μ + σ → (s − σ + 1e-4)/μ, else 1; the
    virtual place gets μ/σ + 1 (or 2 when σ ≤ 1e-4 or no score > 0). Mode 1 uses (s − μ)/σ and
    σ/(max − μ) + 1. σ is the sample standard deviation (n − 1; 0 for a single score), as
    upstream's `sqrt(uVariance(values, mean))`.
    """
    all_values = np.fromiter(scores.values(), np.float64, len(scores))
    values = all_values[all_values > 0.0]
    out = dict.fromkeys(scores, 1.0)
    if values.size == 0:
        out[VIRTUAL_PLACE_ID] = 2.0
        return out
    mu = float(values.mean())
    sigma = float(values.std(ddof=1)) if values.size > 1 else 0.0
    top = float(values.max())
    high = np.flatnonzero(all_values > mu + sigma)
    if high.size:
        s = all_values[high]
        adjusted = (s - mu) / sigma if virtual_ratio_mode == 1 else (s - sigma + 1e-4) / mu
        keys = list(scores)
        for i, v in zip(high.tolist(), adjusted.tolist()):
            out[keys[i]] = v
    if sigma > 1e-4:
        if virtual_ratio_mode == 1:
            out[VIRTUAL_PLACE_ID] = sigma / (top - mu) + 1.0 if top > mu else 2.0
        else:
            out[VIRTUAL_PLACE_ID] = mu / sigma + 1.0
    else:
        out[VIRTUAL_PLACE_ID] = 2.0
    return out


class BayesFilter:
    """posterior_t ∝ likelihood_t ⊙ (prediction · posterior_{t−1}) over {virtual} ∪ WM.

    `neighbours(id, max_depth)` returns {neighbour id: link depth} within the graph (depth 0:
    a loop partner, which gets `PredictionLC[1]` as the place itself), excluding
    short-term-memory nodes; prediction columns are cached per id and invalidated by
    `invalidate(ids)` when a node's neighbourhood changes (incremental prediction update).

    The columns live in one append-only table of (column, row, PredictionLC value) entries;
    changes append or retire entries, and a step is a few gathers and `bincount`s over the
    table (no per-column Python), about a millisecond at 1,000 states.
    """

    def __init__(self, prediction_lc: tuple[float, ...], virtual_place_prior_thr: float = 0.9):
        self._lc = prediction_lc
        self._vp_stay = virtual_place_prior_thr
        # a column whose entries sum below this gets the difference on its own cell
        # (upstream's normalize: "add values of not found neighbours to loop closure")
        self._full_mass = float(sum(prediction_lc)) - prediction_lc[0]
        self._states = np.zeros(0, np.int64)  # last posterior's states, virtual place first
        self._post = np.zeros(0)
        self.reset()

    @property
    def posterior(self) -> dict[int, float]:
        """Last posterior, virtual place (−1) included."""
        return dict(zip(self._states.tolist(), self._post.tolist()))

    @property
    def max_depth(self) -> int:
        """Neighbour depth covered by `Bayes/PredictionLC`."""
        return len(self._lc) - 2

    def reset(self) -> None:
        """Forget the posterior (e.g. after a new map)."""
        self._states = np.zeros(0, np.int64)
        self._post = np.zeros(0)
        self._columns: dict[int, dict[int, int]] = {}  # column id → {row id: entry}
        self._short: set[int] = set()  # columns whose own cell holds missing neighbours' mass
        self._e_col = np.zeros(1024, np.int64)
        self._e_row = np.zeros(1024, np.int64)
        self._e_raw = np.zeros(1024)  # 0 = retired entry
        self._n = 0
        self._dead = 0
        self._max_id = 0  # largest id in the table
        # per column id: Σ of its live entries' values, added in table order (the sums the
        # prediction divides by, kept as entries come and go); while ids stay small and ≥ 0
        self._col_sum = np.zeros(1024)
        self._col_sum_ok = True

    def invalidate(self, ids: Iterable[int]) -> None:
        """Recompute these ids' prediction columns at the next update."""
        sums = self._col_sum
        for i in ids:
            col = self._columns.pop(i, None)
            self._short.discard(i)
            if col:
                self._e_raw[np.fromiter(col.values(), np.int64, len(col))] = 0.0
                self._dead += len(col)
                if 0 <= i < sums.size:
                    sums[i] = 0.0

    def add_neighbour(self, column_id: int, neighbour_id: int, depth: int) -> None:
        """Incremental prediction update: `neighbour_id` is now `depth` links from `column_id`."""
        col = self._columns.get(column_id)
        if col is None or not 0 <= depth <= self.max_depth or neighbour_id in col:
            return
        if column_id in self._short:  # its own cell changes too: rebuilt at the next update
            self.invalidate([column_id])
            return
        if not 0 <= neighbour_id <= self._max_id:
            self._track_ids(neighbour_id, neighbour_id)
        col[neighbour_id] = self._append(column_id, [neighbour_id], [self._lc[depth + 1]])

    def remove_neighbour(self, column_id: int, neighbour_id: int) -> None:
        """Incremental prediction update: `neighbour_id` left the neighbourhood of `column_id`."""
        col = self._columns.get(column_id)
        if col is None or neighbour_id not in col:
            return
        self._e_raw[col.pop(neighbour_id)] = 0.0
        self._dead += 1
        if column_id in self._short or float(self._e_raw[
                np.fromiter(col.values(), np.int64, len(col))].sum()) < self._full_mass - _MASS_TOLERANCE:
            self.invalidate([column_id])  # the missing mass moves to its own cell
        elif self._col_sum_ok:
            # the column's sum again, its live entries added in table order
            total = 0.0
            for e in sorted(col.values()):
                total += float(self._e_raw[e])
            self._col_sum[column_id] = total

    def node_entered(self, node_id: int, neighbourhood: Mapping[int, int]) -> None:
        """A node joined the states; `neighbourhood` = {id: depth} of its WM neighbours.

        `add_neighbour` for each neighbour, appended to the table in one go (same entries, same
        order)."""
        columns = self._columns
        lc = self._lc
        top = self.max_depth
        cols: list[int] = []
        vals: list[float] = []
        targets: list[dict[int, int]] = []
        short: list[int] = []
        for j, depth in neighbourhood.items():
            col = columns.get(j)
            if col is None or not 0 <= depth <= top or node_id in col:
                continue
            if j in self._short:
                short.append(j)
                continue
            cols.append(j)
            vals.append(lc[depth + 1])
            targets.append(col)
        if cols:
            if not 0 <= node_id <= self._max_id:
                self._track_ids(node_id, node_id)
            first = self._append(cols, [node_id] * len(cols), vals)
            for k, col in enumerate(targets):
                col[node_id] = first + k
        self.invalidate([node_id, *short])

    def node_left(self, node_id: int, neighbourhood: Iterable[int]) -> None:
        """A node left the states (transfer to LTM or deletion)."""
        for j in neighbourhood:
            self.remove_neighbour(j, node_id)
        self.forget([node_id])

    def forget(self, ids: Iterable[int]) -> None:
        """Remove states (nodes left WM)."""
        gone = set(ids)
        self.invalidate(gone)
        if gone and self._states.size:
            keep = ~np.isin(self._states, np.fromiter(gone, np.int64, len(gone)))
            keep[0] = True  # the virtual place stays
            self._states = self._states[keep]
            self._post = self._post[keep]

    def _append(self, column_id: int | list[int], rows: list[int], raw: list[float]) -> int:
        """Append entries (of one column, or one column per entry); returns the index of the
        first."""
        n, m = self._n, len(rows)
        if n + m > self._e_col.size:
            if self._dead > n // 2:
                self._compact()
                n = self._n
            if n + m > self._e_col.size:
                cap = max(n + m, 2 * self._e_col.size)
                self._e_col = np.resize(self._e_col, cap)
                self._e_row = np.resize(self._e_row, cap)
                self._e_raw = np.resize(self._e_raw, cap)
        self._e_col[n:n + m] = column_id
        self._e_row[n:n + m] = rows
        self._e_raw[n:n + m] = raw
        self._n = n + m
        if self._col_sum_ok:
            self._add_to_sums(column_id, raw)
        return n

    def _add_to_sums(self, column_id: int | list[int], raw: list[float]) -> None:
        """Add appended entries to their columns' sums, in table order."""
        top = column_id if isinstance(column_id, int) else max(column_id, default=0)
        low = column_id if isinstance(column_id, int) else min(column_id, default=0)
        if low < 0 or top >= 1 << 24:
            self._col_sum_ok = False  # ids unsuited to a dense table: sums in the pass
            return
        sums = self._col_sum
        if top >= sums.size:
            sums = self._col_sum = np.concatenate(
                [sums, np.zeros(max(top + 1, 2 * sums.size) - sums.size)])
        if isinstance(column_id, int):
            total = float(sums[column_id])
            for v in raw:
                total += v
            sums[column_id] = total
        else:  # one entry per column, in order (np.add.at adds repeated columns in order)
            np.add.at(sums, np.asarray(column_id, np.int64), np.asarray(raw, np.float64))

    def _compact(self) -> None:
        alive = np.flatnonzero(self._e_raw[: self._n] > 0.0)
        new_index = np.full(self._n, -1, np.int64)
        new_index[alive] = np.arange(alive.size)
        for col in self._columns.values():
            for row, e in col.items():
                col[row] = int(new_index[e])
        for arr in (self._e_col, self._e_row, self._e_raw):
            arr[: alive.size] = arr[alive]
        self._n = alive.size
        self._dead = 0

    def _ensure_column(self, i: int, neighbours: Callable[[int, int], Mapping[int, int]]) -> None:
        if i in self._columns:
            return
        lc = self._lc
        top = self.max_depth
        rows = [i]
        vals = [lc[1]]
        for j, depth in neighbours(i, top).items():
            if j != i and 0 <= depth <= top:
                rows.append(j)
                vals.append(lc[depth + 1])
        missing = self._full_mass - sum(vals)
        if missing > _MASS_TOLERANCE:
            vals[0] += missing
            self._short.add(i)
        self._track_ids(min(rows), max(rows))  # rows include the column's own id
        first = self._append(i, rows, vals)
        self._columns[i] = {r: first + k for k, r in enumerate(rows)}

    def _track_ids(self, low: int, high: int) -> None:
        # negative ids cannot index the dense table: they keep the searchsorted lookup
        self._max_id = max(self._max_id, high) if low >= 0 else 1 << 62

    def update(
        self,
        likelihood: Mapping[int, float],
        neighbours: Callable[[int, int], Mapping[int, int]],
    ) -> dict[int, float]:
        """One filter step. `likelihood` holds the virtual place and every WM candidate."""
        like_map = dict(likelihood)
        vp_like = like_map.pop(VIRTUAL_PLACE_ID, 1.0)
        locations = np.fromiter(like_map.keys(), np.int64, len(like_map))
        order = np.argsort(locations, kind="stable")
        states = np.concatenate([[VIRTUAL_PLACE_ID], locations[order]])
        like = np.concatenate([[vp_like],
                               np.fromiter(like_map.values(), np.float64, len(like_map))[order]])
        n = states.size
        n_loc = n - 1
        prior = np.zeros(n)
        if self._post.size == 0:
            prior[0] = 1.0
        else:
            prior[0] = self._post[0]
            prev = _lookup(states, self._states[1:])
            ok = prev < n
            prior[prev[ok]] = self._post[1:][ok]
            total = prior.sum()
            if total > 0:
                prior /= total
            else:
                prior[:] = 0.0
                prior[0] = 1.0
        predicted = np.zeros(n)
        # virtual-place column
        predicted[0] += prior[0] * self._vp_stay
        if n_loc > 0:
            predicted[1:] += prior[0] * (1.0 - self._vp_stay) / n_loc
        # location columns: lc[0] to the virtual place, the rest rescaled to 1 − lc[0]
        active = np.flatnonzero(prior[1:] > 0) + 1
        if active.size:
            predicted[0] += prior[active].sum() * self._lc[0]
            for s in sorted(set(states[active].tolist()) - self._columns.keys()):
                self._ensure_column(s, neighbours)
            table = _dense_table(states, self._max_id)
            if table is not None and self._col_sum_ok:
                # one compiled pass over the live entries, the column sums kept (the same
                # values as summing the table in the pass: same order, same rounding)
                kept_sums = np.zeros(n + 1)
                ids = states[1:]
                inside = ids < self._col_sum.size
                kept_sums[1:n][inside] = self._col_sum[ids[inside]]
                predicted += _predict_entries(self._e_col, self._e_row, self._e_raw, self._n,
                                              table, np.append(prior, 0.0), 1.0 - self._lc[0],
                                              kept_sums)
            elif table is not None:
                # one compiled pass: the gathers and bincounts below, entry by entry (same
                # order of sums, same rounding)
                predicted += _predict_entries_summed(self._e_col, self._e_row, self._e_raw,
                                                     self._n, table, np.append(prior, 0.0),
                                                     1.0 - self._lc[0], n)
            else:
                # absent ids map to the extra state n (prior 0, dropped at the end); no boolean
                # compressions, which cost more than the gathers on ~10⁵ entries
                m = self._n
                raw = self._e_raw[:m]
                col = _lookup(states, self._e_col[:m])
                col_prior = np.append(prior, 0.0)[col]
                sums = np.bincount(col, raw, minlength=n + 1)
                scale = np.divide(1.0 - self._lc[0], sums, out=np.zeros_like(sums),
                                  where=sums > 0)
                weight = raw * col_prior * scale[col]
                row = _lookup(states, self._e_row[:m])
                predicted += np.bincount(row, weight, minlength=n + 1)[:n]
        post = like * predicted
        total = post.sum()
        if total > 0:
            post /= total
        else:
            post = np.zeros(n)
            post[0] = 1.0
        post[post < 1e-12] = 0.0
        self._states = states
        self._post = post
        return self.posterior

    def highest_hypothesis(self) -> tuple[int, float]:
        """(location with the top posterior, 1 − P(virtual place)) of the last update; ties go to
        the lowest id, (0, 0.0) before any update or without locations."""
        if self._states.size < 2:
            return 0, (1.0 - float(self._post[0])) if self._post.size else 0.0
        k = int(np.argmax(self._post[1:])) + 1
        return int(self._states[k]), 1.0 - float(self._post[0])

    def posterior_arrays(self) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        """Last posterior as (state ids, probabilities), the virtual place (−1) first."""
        return self._states.copy(), self._post.copy()


def _dense_table(states: NDArray[np.int64], max_id: int) -> NDArray[np.int64] | None:
    """id → index among `states` (len(states) if absent) for ids 0..`max_id`, or None when ids
    are too sparse for a table."""
    n = states.size
    locations = states[1:]
    if locations.size == 0 or locations[0] < 0 or max_id > 16 * locations.size + 65536:
        return None
    table = np.full(max(max_id, int(locations[-1])) + 1, n, np.int64)
    table[locations] = np.arange(1, n)
    return table


@njit(cache=True)
def _predict_entries_summed(e_col, e_row, e_raw, m, table, prior, keep, n):  # type: ignore[no-untyped-def]
    """Σ over table entries of raw · prior[col] · keep / Σ_col raw, accumulated per row: the
    bincount formulation of `BayesFilter.update` entry by entry (same order, same rounding)."""
    sums = np.zeros(n + 1)
    for k in range(m):
        sums[table[e_col[k]]] += e_raw[k]
    scale = np.zeros(n + 1)
    for c in range(n + 1):
        if sums[c] > 0:
            scale[c] = keep / sums[c]
    acc = np.zeros(n + 1)
    for k in range(m):
        c = table[e_col[k]]
        acc[table[e_row[k]]] += e_raw[k] * prior[c] * scale[c]
    return acc[:n]


@njit(cache=True)
def _predict_entries(e_col, e_row, e_raw, m, table, prior, keep, sums):  # type: ignore[no-untyped-def]
    """`_predict_entries_summed` with the per-state column sums given (`sums`, n + 1): one
    pass, retired entries (value 0, which add nothing) skipped."""
    n = sums.size - 1
    scale = np.zeros(n + 1)
    for c in range(n):
        if sums[c] > 0:
            scale[c] = keep / sums[c]
    acc = np.zeros(n + 1)
    for k in range(m):
        r = e_raw[k]
        if r == 0.0:
            continue
        c = table[e_col[k]]
        acc[table[e_row[k]]] += r * prior[c] * scale[c]
    return acc[:n]


def _lookup(states: NDArray[np.int64], ids: NDArray[np.int64]) -> NDArray[np.int64]:
    """Index of each id among `states` (virtual place first, then sorted ids); len(states) if
    absent."""
    n = states.size
    locations = states[1:]
    if locations.size == 0:
        return np.full(ids.shape, n, np.int64)
    top = int(locations[-1])
    if locations[0] >= 0 and top <= 16 * locations.size + 65536:
        table = np.full(top + 2, n, np.int64)
        table[locations] = np.arange(1, n)
        return table[np.clip(ids, -1, top + 1)]  # −1 and top + 1 hold n
    k = np.clip(np.searchsorted(locations, ids), 0, locations.size - 1)
    return np.where(locations[k] == ids, k + 1, n)
