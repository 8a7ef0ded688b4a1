"""Incremental bag-of-words vocabulary of 256-bit binary descriptors (Hamming distance).

A descriptor is quantised to the nearest existing word when it passes the nearest-neighbour
distance-ratio test (`Kp/NndrRatio`, two candidates needed), otherwise it becomes a new word.
Words carry a reference count (how many in-memory nodes use them); unreferenced words are kept
(so ids stay valid and nodes retrieved from long-term memory find them again) but are excluded
from matching, and the search indexes are compacted so time follows the *referenced* words.

Search structure: recent words are searched exactly (brute force popcount); older words sit in
a few FLANN LSH indexes of geometrically growing size (a logarithmic method), so adding words
costs amortised O(log n) rebuilds. LSH with 8 tables of 20-bit keys: on ORB words of the
1,000-node benchmark it picks the exact nearest word for 99.7 % of the descriptors the exact
NNDR test accepts, at a quarter of the query time of 16 tables of 16 bits. An LSH query may
miss a far second neighbour; a missing second candidate is then taken at 80 bits (a typical
distance between unrelated ORB descriptors), so a lone candidate is accepted only when it is
clearly close (≤ 64 bits at 0.8).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.matching import as_words64, knn2_hamming

__all__ = ["Vocabulary"]

_FLANN_LSH = 6
_UNRELATED_DISTANCE = 80
LSH_SEED = 0x5EED  # base of the LSH index seeds; benchmarks vary it for seed studies


@dataclass
class _Level:
    ids: NDArray[np.int64]  # word indices (0-based) held by this index
    index: cv2.flann.Index


class Vocabulary:
    """Words with ids 1, 2, ...; `quantize` maps descriptors to word ids."""

    def __init__(
        self,
        nndr_ratio: float = 0.8,
        *,
        exact_max: int = 2048,
        lsh_tables: int = 8,
        lsh_key_size: int = 20,
        lsh_multi_probe: int = 0,
    ) -> None:
        self.nndr_ratio = nndr_ratio
        self._exact_max = exact_max
        self._lsh_params: dict[str, bool | int | float | str] = {
            "algorithm": _FLANN_LSH, "table_number": lsh_tables, "key_size": lsh_key_size,
            "multi_probe_level": lsh_multi_probe,
        }
        self._desc = np.zeros((1024, 32), np.uint8)
        self._refs = np.zeros(1024, np.int64)
        self._indexed = np.zeros(1024, bool)
        self._n = 0
        self._tail: list[int] = []
        self._levels: list[_Level] = []

    # -- sizes ------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self._n

    @property
    def active_words(self) -> int:
        """Words referenced by at least one node in memory."""
        return int(np.count_nonzero(self._refs[: self._n] > 0))

    @property
    def next_id(self) -> int:
        """Id the next new word will get."""
        return self._n + 1

    def descriptor(self, word_id: int) -> NDArray[np.uint8]:
        """The descriptor of a word."""
        return self._desc[word_id - 1].copy()

    def descriptors(self, word_ids: NDArray[np.int64]) -> NDArray[np.uint8]:
        """Descriptors of several words, (N, 32)."""
        return self._desc[np.asarray(word_ids, np.int64) - 1].copy()

    def references(self, word_id: int) -> int:
        """Reference count of a word."""
        return int(self._refs[word_id - 1])

    # -- updates ----------------------------------------------------------------------------
    def add_word(self, word_id: int, descriptor: NDArray[np.uint8]) -> None:
        """Restore a word with a known id (from a database), in increasing id order.

        Ids skipped (words of frames that were not kept) become unreferenced placeholders.
        """
        if word_id <= self._n:
            raise ValueError(f"word ids must be restored in increasing order (got {word_id})")
        gap = word_id - 1 - self._n
        if gap:
            self._append(np.zeros((gap, 32), np.uint8))
        self._append(descriptor.reshape(1, 32))

    def add_references(self, word_ids: NDArray[np.int64]) -> None:
        """A node using these words (one id per occurrence; ids < 1 ignored) entered memory."""
        ids = np.asarray(word_ids, np.int64)
        ids = np.unique(ids[ids > 0]) - 1
        self._refs[ids] += 1
        newly = ids[~self._indexed[ids]]
        if newly.size:
            self._indexed[newly] = True
            self._tail.extend(int(i) for i in newly)

    def remove_references(self, word_ids: NDArray[np.int64]) -> None:
        """A node using these words left memory."""
        ids = np.asarray(word_ids, np.int64)
        ids = np.unique(ids[ids > 0]) - 1
        self._refs[ids] = np.maximum(self._refs[ids] - 1, 0)

    def quantize(self, descriptors: NDArray[np.uint8], *, add_new: bool = True) -> NDArray[np.int64]:
        """Word id per descriptor; rejected descriptors become new words (or -1 if not `add_new`).

        New words are created unreferenced; call `add_references` when a node keeps them.
        """
        n = descriptors.shape[0]
        out = np.full(n, -1, np.int64)
        if n == 0:
            return out
        self._maintain()
        idx, dist = self._knn2(np.ascontiguousarray(descriptors, np.uint8))
        has2 = idx[:, 0] >= 0
        d2 = np.where(idx[:, 1] >= 0, dist[:, 1], _UNRELATED_DISTANCE)
        accept = has2 & (dist[:, 0] <= self.nndr_ratio * d2) & (self._n >= 2)
        out[accept] = idx[accept, 0] + 1
        if add_new:
            rejected = np.flatnonzero(~accept)
            if rejected.size:
                first = self._n + 1
                self._append(descriptors[rejected])
                out[rejected] = np.arange(first, first + rejected.size)
                # New words are searchable at once, like RTAB-Map's incremental index.
                self._indexed[first - 1 : first - 1 + rejected.size] = True
                self._tail.extend(range(first - 1, first - 1 + rejected.size))
        return out

    # -- internals --------------------------------------------------------------------------
    def _append(self, desc: NDArray[np.uint8]) -> None:
        need = self._n + desc.shape[0]
        if need > self._desc.shape[0]:
            cap = max(need, 2 * self._desc.shape[0])
            self._desc = np.resize(self._desc, (cap, 32))
            self._refs = np.concatenate([self._refs, np.zeros(cap - self._refs.size, np.int64)])
            self._indexed = np.concatenate([self._indexed, np.zeros(cap - self._indexed.size, bool)])
        self._desc[self._n : need] = desc
        self._refs[self._n : need] = 0
        self._indexed[self._n : need] = False
        self._n = need

    def _active_mask(self) -> NDArray[np.bool_]:
        return self._refs[: self._n] > 0

    def _build(self, ids: NDArray[np.int64]) -> _Level:
        index = cv2.flann.Index()
        # FLANN draws its LSH bit selections from OpenCV's process-wide RNG, so without a seed
        # the index (and every loop closure after it) depended on what ran before in the
        # process. Seeding from the level's size makes each build a function of its words.
        cv2.setRNGSeed(LSH_SEED + int(ids.shape[0]))
        index.build(np.ascontiguousarray(self._desc[ids]), self._lsh_params, 9)  # 9 = Hamming
        return _Level(ids, index)

    def _maintain(self) -> None:
        # Drop unreferenced words from an overfull tail; they are re-added if referenced again.
        if len(self._tail) > self._exact_max:
            tail = np.asarray(self._tail, np.int64)
            alive = self._refs[tail] > 0
            self._indexed[tail[~alive]] = False
            self._tail = tail[alive].tolist()
        if len(self._tail) >= self._exact_max:
            self._levels.append(self._build(np.asarray(self._tail, np.int64)))
            self._tail = []
        # Merge equal-sized levels (each level at least twice the next one).
        while len(self._levels) >= 2 and self._levels[-2].ids.size <= 2 * self._levels[-1].ids.size:
            b = self._levels.pop()
            a = self._levels.pop()
            ids = np.concatenate([a.ids, b.ids])
            self._levels.append(self._compact(ids))
        # Compact levels that are mostly unreferenced.
        for k, level in enumerate(self._levels):
            alive = self._refs[level.ids] > 0
            if alive.mean() < 0.5:
                self._levels[k] = self._compact(level.ids)
        self._levels = [lv for lv in self._levels if lv.ids.size > 0]

    def _compact(self, ids: NDArray[np.int64]) -> _Level:
        alive = self._refs[ids] > 0
        self._indexed[ids[~alive]] = False
        ids = ids[alive]
        if ids.size == 0:
            return _Level(ids, cv2.flann.Index())
        return self._build(ids)

    def _knn2(self, desc: NDArray[np.uint8]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        n = desc.shape[0]
        best_i = np.full((n, 2), -1, np.int64)
        best_d = np.full((n, 2), 1 << 30, np.int64)
        active = self._active_mask()
        candidates_i = []
        candidates_d = []
        tail = np.asarray(self._tail, np.int64)
        if tail.size:
            ti, td = knn2_hamming(as_words64(desc), as_words64(self._desc[tail]))
            candidates_i.append(np.where(ti >= 0, tail[np.maximum(ti, 0)], -1))
            candidates_d.append(td)
        for level in self._levels:
            if level.ids.size < 2:
                continue
            li, ld = level.index.knnSearch(desc, 2, params={"checks": 32})
            li = np.asarray(li, np.int64).reshape(n, -1)
            ld = np.asarray(ld, np.int64).reshape(n, -1)
            valid = (li >= 0) & (li < level.ids.size)
            words = np.where(valid, level.ids[np.clip(li, 0, level.ids.size - 1)], -1)
            candidates_i.append(words)
            candidates_d.append(np.where(valid, ld, 1 << 30))
        if not candidates_i:
            return best_i, best_d
        all_i = np.concatenate(candidates_i, axis=1)
        all_d = np.concatenate(candidates_d, axis=1)
        usable = all_i >= 0
        usable[usable] = active[all_i[usable]] | self._in_tail(all_i[usable], tail)
        all_d = np.where(usable, all_d, 1 << 30)
        all_i = np.where(usable, all_i, -1)
        order = np.argsort(all_d, axis=1, kind="stable")[:, :2]
        best_i = np.take_along_axis(all_i, order, axis=1)
        best_d = np.take_along_axis(all_d, order, axis=1)
        best_i[best_d >= (1 << 30)] = -1
        return best_i, best_d

    def _in_tail(self, ids: NDArray[np.int64], tail: NDArray[np.int64]) -> NDArray[np.bool_]:
        # Unreferenced words in the exact tail were created by recent frames whose node is not
        # stored (yet): they stay searchable, like RTAB-Map's not-yet-referenced new words.
        # Unreferenced words inside an LSH level are dead and skipped.
        if not tail.size:
            return np.zeros(ids.size, bool)
        return np.isin(ids, tail)
