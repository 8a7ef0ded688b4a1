"""Loop-closure likelihood (TF-IDF) and the discrete Bayes filter with a virtual "new place".

State −1 is the virtual place (the current image shows somewhere not in memory); the other
states are working-memory node ids. See rtabmap_semantics.md §2.2–2.4.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping

import numpy as np

__all__ = ["VIRTUAL_PLACE_ID", "BayesFilter", "adjust_likelihood", "tfidf_scores"]

VIRTUAL_PLACE_ID = -1


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
    cand = set(candidates)
    scores = dict.fromkeys(cand, 0.0)
    if n_nodes <= 0:
        return scores
    for w in words:
        postings = inverted_index.get(w)
        if not postings:
            continue
        idf = math.log10(n_nodes / len(postings))
        if idf <= 0.0:
            continue
        for j, n_wj in postings.items():
            if j in cand:
                scores[j] += n_wj / node_word_totals[j] * idf
    return scores


def adjust_likelihood(scores: Mapping[int, float], virtual_ratio_mode: int = 0) -> dict[int, float]:
    """RTAB-Map's likelihood adjustment; returns likelihoods including the virtual place (−1).

    With mean μ and std σ of the non-zero scores: s > μ + σ → (s − σ + 1e-4)/μ, else 1; the
    virtual place gets μ/σ + 1 (or 2 when σ ≤ 1e-4 or no score > 0). Mode 1 uses (s − μ)/σ and
    σ/(max − μ) + 1.
    """
    values = np.array([v for v in scores.values() if v > 0.0])
    out = dict.fromkeys(scores, 1.0)
    if values.size == 0:
        out[VIRTUAL_PLACE_ID] = 2.0
        return out
    mu = float(values.mean())
    sigma = float(values.std())
    top = float(values.max())
    for k, s in scores.items():
        if s > mu + sigma:
            out[k] = (s - mu) / sigma if virtual_ratio_mode == 1 else (s - sigma + 1e-4) / mu
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

    `neighbours(id, max_depth)` returns {neighbour id: link depth} within the graph, excluding
    short-term-memory nodes; prediction columns are cached per id and invalidated by
    `invalidate(ids)` when a node's neighbourhood changes (incremental prediction update).
    """

    def __init__(self, prediction_lc: tuple[float, ...], virtual_place_prior_thr: float = 0.9):
        self._lc = prediction_lc
        self._vp_stay = virtual_place_prior_thr
        self._posterior: dict[int, float] = {}
        # id → (rows, normalised values, row set, raw PredictionLC values)
        self._columns: dict[int, tuple[np.ndarray, np.ndarray, set[int], np.ndarray]] = {}

    @property
    def posterior(self) -> dict[int, float]:
        """Last posterior, virtual place (−1) included."""
        return dict(self._posterior)

    @property
    def max_depth(self) -> int:
        """Neighbour depth covered by `Bayes/PredictionLC`."""
        return len(self._lc) - 2

    def reset(self) -> None:
        """Forget the posterior (e.g. after a new map)."""
        self._posterior = {}
        self._columns = {}

    def invalidate(self, ids: Iterable[int]) -> None:
        """Recompute these ids' prediction columns at the next update."""
        for i in ids:
            self._columns.pop(i, None)

    def add_neighbour(self, column_id: int, neighbour_id: int, depth: int) -> None:
        """Incremental prediction update: `neighbour_id` is now `depth` links from `column_id`."""
        col = self._columns.get(column_id)
        if col is None or not 1 <= depth <= self.max_depth or neighbour_id in col[2]:
            return
        rows = np.append(col[0], neighbour_id)
        raw = np.append(col[3], self._lc[depth + 1])
        self._columns[column_id] = (rows, (1.0 - self._lc[0]) * raw / raw.sum(),
                                    col[2] | {neighbour_id}, raw)

    def remove_neighbour(self, column_id: int, neighbour_id: int) -> None:
        """Incremental prediction update: `neighbour_id` left the neighbourhood of `column_id`."""
        col = self._columns.get(column_id)
        if col is None or neighbour_id not in col[2]:
            return
        keep = col[0] != neighbour_id
        raw = col[3][keep]
        self._columns[column_id] = (col[0][keep], (1.0 - self._lc[0]) * raw / raw.sum(),
                                    col[2] - {neighbour_id}, raw)

    def node_entered(self, node_id: int, neighbourhood: Mapping[int, int]) -> None:
        """A node joined the states; `neighbourhood` = {id: depth} of its WM neighbours."""
        for j, depth in neighbourhood.items():
            self.add_neighbour(j, node_id, depth)
        self.invalidate([node_id])

    def node_left(self, node_id: int, neighbourhood: Iterable[int]) -> None:
        """A node left the states (transfer to LTM or deletion)."""
        for j in neighbourhood:
            self.remove_neighbour(j, node_id)
        self.forget([node_id])

    def forget(self, ids: Iterable[int]) -> None:
        """Remove states (nodes left WM)."""
        for i in ids:
            self._posterior.pop(i, None)
            self._columns.pop(i, None)

    def _column(
        self, i: int, neighbours: Callable[[int, int], Mapping[int, int]]
    ) -> tuple[np.ndarray, np.ndarray, set[int], np.ndarray]:
        col = self._columns.get(i)
        if col is None:
            rows = [i]
            vals = [self._lc[1]]
            for j, depth in neighbours(i, self.max_depth).items():
                if j != i and 1 <= depth <= self.max_depth:
                    rows.append(j)
                    vals.append(self._lc[depth + 1])
            v = np.asarray(vals)
            # lc[0] goes to the virtual place; the location part is rescaled to 1 − lc[0].
            col = (np.asarray(rows, np.int64), (1.0 - self._lc[0]) * v / v.sum(), set(rows), v)
            self._columns[i] = col
        return col

    def update(
        self,
        likelihood: Mapping[int, float],
        neighbours: Callable[[int, int], Mapping[int, int]],
    ) -> dict[int, float]:
        """One filter step. `likelihood` holds the virtual place and every WM candidate."""
        states = [VIRTUAL_PLACE_ID, *sorted(k for k in likelihood if k != VIRTUAL_PLACE_ID)]
        index = {s: k for k, s in enumerate(states)}
        n = len(states)
        prior = np.zeros(n)
        if not self._posterior:
            prior[0] = 1.0
        else:
            for s, p in self._posterior.items():
                k = index.get(s)
                if k is not None:
                    prior[k] = p
            total = prior.sum()
            prior = prior / total if total > 0 else np.eye(1, n, 0).ravel()
        predicted = np.zeros(n)
        n_loc = n - 1
        # virtual-place column
        predicted[0] += prior[0] * self._vp_stay
        if n_loc > 0:
            predicted[1:] += prior[0] * (1.0 - self._vp_stay) / n_loc
        # location columns
        active = np.flatnonzero(prior[1:] > 0) + 1
        if active.size:
            predicted[0] += prior[active].sum() * self._lc[0]
            cols = [self._column(states[k], neighbours) for k in active]
            rows = np.concatenate([c[0] for c in cols])
            vals = np.concatenate([prior[k] * c[1] for k, c in zip(active, cols)])
            state_arr = np.asarray(states, np.int64)
            pos = np.searchsorted(state_arr, rows)
            pos = np.clip(pos, 0, n - 1)
            present = state_arr[pos] == rows
            np.add.at(predicted, pos[present], vals[present])
        like = np.array([likelihood[s] for s in states])
        post = like * predicted
        total = post.sum()
        post = post / total if total > 0 else np.eye(1, n, 0).ravel()
        post[post < 1e-12] = 0.0
        self._posterior = {s: float(p) for s, p in zip(states, post)}
        return self.posterior
