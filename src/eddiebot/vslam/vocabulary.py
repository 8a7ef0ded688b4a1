"""Incremental bag-of-words vocabulary of 256-bit binary descriptors (Hamming distance).

A descriptor is quantised to the nearest existing word when it passes the nearest-neighbour
distance-ratio test (`Kp/NndrRatio`, two candidates needed), otherwise it becomes a new word.
Words carry a reference count (how many in-memory nodes use them); unreferenced words are kept
(so ids stay valid and nodes retrieved from long-term memory find them again) but are excluded
from matching, and the search indexes are compacted so time follows the *referenced* words.

Search structure: recent words are searched exactly (brute force popcount); older words sit in
a few LSH indexes of geometrically growing size (a logarithmic method), so adding words
costs amortised O(log n) rebuilds. LSH with 8 tables of 20-bit keys: on ORB words of the
1,000-node benchmark it picks the exact nearest word for 99.7 % of the descriptors the exact
NNDR test accepts, at a quarter of the query time of 16 tables of 16 bits. An LSH query may
miss a far second neighbour; a missing second candidate is then taken at 80 bits (a typical
distance between unrelated ORB descriptors), so a lone candidate is accepted only when it is
clearly close (≤ 64 bits at 0.8).

The LSH indexes are FLANN's (`cv2.flann`, algorithm 6) reimplemented as a compiled search,
one pass per level that also merges its answers with the tail's: the same bit selections
(drawn from OpenCV's RNG as FLANN's `LshTable` draws them), the same buckets in the same order
and FLANN's result set (unique candidates, a candidate at the current second distance turned
away), so each query returns what `cv2.flann.Index.knnSearch` returned, without its
per-candidate allocations and the merging in numpy (`tests/vslam/test_vslam_descriptor_search.py`
compares both).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from cv2 import randShuffle as _rand_shuffle
from numba import njit
from numpy.typing import NDArray

from eddiebot.vslam.matching import as_words64, knn2_hamming, popcount64

__all__ = ["Vocabulary"]

_UNRELATED_DISTANCE = 80
_NO_WORD = 1 << 30  # distance of a missing candidate
_FLANN_NO_DISTANCE = np.iinfo(np.int32).max  # FLANN's initial worst distance (int Hamming)
LSH_SEED = 0x5EED  # base of the LSH index seeds; benchmarks vary it for seed studies


@dataclass
class _Level:
    """One LSH index. Per table, FLANN's buckets: the words with one key, in insertion order;
    stored bucket after bucket with their descriptors inline (a bucket is read contiguously),
    found through an open-addressing hash of the keys."""

    ids: NDArray[np.int64]  # word indices (0-based) held by this index
    bits: NDArray[np.int64]  # (tables, key_size) descriptor bit positions of each table's key
    # (tables, slots, 2): a bucket's key (-1 = empty slot), and its first row in `members`
    # plus its length << 32
    slots: NDArray[np.int64]
    members: NDArray[np.int32]  # positions in `ids`, table after table, bucket after bucket
    member_words: NDArray[np.uint64]  # (len(members), 4) their descriptors


def _draw_bits(tables: int, key_size: int) -> NDArray[np.int64]:
    """Key bit positions of each table as FLANN's `LshTable<unsigned char>` draws them: a
    `cv::randShuffle` of the 256 bit positions from OpenCV's RNG, the first `key_size` kept."""
    out = np.zeros((tables, key_size), np.int64)
    for t in range(tables):
        order = np.arange(256, dtype=np.int32).reshape(-1, 1)
        _rand_shuffle(order)
        out[t] = np.sort(order[:key_size, 0])  # a key's bit k is its k-th lowest position
    return out


def _xor_masks(key_size: int, level: int) -> NDArray[np.int64]:
    """FLANN's multi-probe key perturbations, in its order (`fill_xor_mask`)."""
    masks: list[int] = []

    def fill(key: int, lowest: int, depth: int) -> None:
        masks.append(key)
        if depth == 0:
            return
        for index in range(lowest - 1, -1, -1):
            fill(key | (1 << index), index, depth - 1)

    fill(0, key_size, level)
    return np.asarray(masks, np.int64)


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
        if not 1 <= lsh_key_size <= 62:
            raise ValueError(f"LSH key size must be 1..62 bits (got {lsh_key_size})")
        self._lsh_tables = lsh_tables
        self._lsh_key_size = lsh_key_size
        self._xor = _xor_masks(lsh_key_size, lsh_multi_probe)
        self._desc = np.zeros((1024, 32), np.uint8)
        self._refs = np.zeros(1024, np.int64)
        self._indexed = np.zeros(1024, bool)
        self._n = 0
        self._tail: list[int] = []
        self._levels: list[_Level] = []
        self._refs_dropped = False  # references removed since the levels were last checked

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
        self._refs_dropped = True

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

    def _build(self, ids: NDArray[np.int64]) -> _Level:
        # FLANN draws its LSH bit selections from OpenCV's process-wide RNG, so without a seed
        # the index (and every loop closure after it) depended on what ran before in the
        # process. Seeding from the level's size makes each build a function of its words.
        cv2.setRNGSeed(LSH_SEED + int(ids.shape[0]))
        bits = _draw_bits(self._lsh_tables, self._lsh_key_size)
        slots = 1 << max(4, int(ids.size + ids.size // 4).bit_length())  # load factor < 0.8
        table, members, member_words = _build_tables(as_words64(self._desc[: self._n]), ids,
                                                     bits, slots)
        return _Level(ids, bits, table, members, member_words)

    def _maintain(self) -> None:
        # Drop unreferenced words from an overfull tail; they are re-added if referenced again.
        if len(self._tail) > self._exact_max:
            tail = np.asarray(self._tail, np.int64)
            alive = self._refs[tail] > 0
            self._indexed[tail[~alive]] = False
            self._tail = tail[alive].tolist()
        check = self._refs_dropped  # a level's share of referenced words fell, or levels changed
        if len(self._tail) >= self._exact_max:
            self._levels.append(self._build(np.asarray(self._tail, np.int64)))
            self._tail = []
            check = True
        # Merge equal-sized levels (each level at least twice the next one).
        while len(self._levels) >= 2 and self._levels[-2].ids.size <= 2 * self._levels[-1].ids.size:
            b = self._levels.pop()
            a = self._levels.pop()
            ids = np.concatenate([a.ids, b.ids])
            self._levels.append(self._compact(ids))
        # Compact levels that are mostly unreferenced (a level's share of referenced words
        # only falls when references are removed: otherwise there is nothing to look at).
        if check:
            for k, level in enumerate(self._levels):
                alive = self._refs[level.ids] > 0
                if alive.mean() < 0.5:
                    self._levels[k] = self._compact(level.ids)
            self._refs_dropped = False
        self._levels = [lv for lv in self._levels if lv.ids.size > 0]

    def _compact(self, ids: NDArray[np.int64]) -> _Level:
        alive = self._refs[ids] > 0
        self._indexed[ids[~alive]] = False
        ids = ids[alive]
        if ids.size == 0:
            return _Level(ids, np.zeros((0, self._lsh_key_size), np.int64),
                          np.zeros((0, 0, 2), np.int64), np.zeros(0, np.int32),
                          np.zeros((0, 4), np.uint64))
        return self._build(ids)

    def _knn2(self, desc: NDArray[np.uint8]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Two nearest usable words per descriptor (-1 = none): the exact tail's two and each
        LSH level's two, merged by distance (ties: tail first, then the levels in order).
        Usable: referenced, or in the tail (not-yet-referenced new words)."""
        n = desc.shape[0]
        q = as_words64(desc)
        tail = np.asarray(self._tail, np.int64)
        if tail.size:
            ti, td = knn2_hamming(q, as_words64(self._desc[tail]))
            best_i = np.where(ti >= 0, tail[np.maximum(ti, 0)], -1)
            best_d = td
        else:
            best_i = np.full((n, 2), -1, np.int64)
            best_d = np.full((n, 2), _NO_WORD, np.int64)
        # Unreferenced words in the exact tail were created by recent frames whose node is not
        # stored (yet): they stay searchable, like RTAB-Map's not-yet-referenced new words.
        # Unreferenced words inside an LSH level are dead and skipped.
        usable = self._refs[: self._n] > 0
        usable[tail] = True
        for level in self._levels:
            if level.ids.size >= 2:
                _level_knn2_merge(q, level.ids, level.bits, level.slots, level.members,
                                  level.member_words, self._xor, usable, best_i, best_d)
        return best_i, best_d


_HASH_MULTIPLIER = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True, inline="always")
def _slot_of(key, shift):  # type: ignore[no-untyped-def]
    return np.int64((np.uint64(key) * _HASH_MULTIPLIER) >> np.uint64(shift))


@njit(cache=True, inline="always")
def _hash_shift(slots):  # type: ignore[no-untyped-def]
    """64 − log2(slots) (slots a power of two): the multiplicative hash keeps the top bits."""
    bits = 0
    while (1 << bits) < slots:
        bits += 1
    return 64 - bits


@njit(cache=True, inline="always")
def _key(words, row, bits, t):  # type: ignore[no-untyped-def]
    """LSH key of descriptor `row` in table t: bit k = descriptor bit bits[t, k]."""
    key = 0
    for k in range(bits.shape[1]):
        b = bits[t, k]
        if (words[row, b >> 6] >> np.uint64(b & 63)) & np.uint64(1):
            key |= 1 << k
    return key


@njit(cache=True)
def _build_tables(words, ids, bits, n_slots):  # type: ignore[no-untyped-def]
    """Each table's buckets (words of equal key, in `ids` order as FLANN fills them), laid out
    contiguously with their descriptors, and an open-addressing (linear probing) hash from key
    to bucket."""
    tables = bits.shape[0]
    n = ids.size
    shift = _hash_shift(n_slots)
    slots = np.zeros((tables, n_slots, 2), np.int64)
    slots[:, :, 0] = -1
    length = np.zeros(n_slots, np.int64)
    members = np.empty(tables * n, np.int32)
    member_words = np.empty((tables * n, 4), np.uint64)
    slot_of = np.empty(n, np.int64)
    cursor = np.empty(n_slots, np.int64)
    for t in range(tables):
        length[:] = 0
        for i in range(n):
            key = _key(words, ids[i], bits, t)
            s = _slot_of(key, shift)
            while slots[t, s, 0] >= 0 and slots[t, s, 0] != key:
                s = (s + 1) & (n_slots - 1)
            slots[t, s, 0] = key
            length[s] += 1
            slot_of[i] = s
        at = t * n
        for s in range(n_slots):
            slots[t, s, 1] = at | (length[s] << 32)
            cursor[s] = at
            at += length[s]
        for i in range(n):
            p = cursor[slot_of[i]]
            cursor[slot_of[i]] = p + 1
            members[p] = i
            for c in range(4):
                member_words[p, c] = words[ids[i], c]
    return slots, members, member_words


@njit(cache=True)
def _level_knn2_merge(q, ids, bits, slots, members, member_words, xor_masks, usable,  # type: ignore[no-untyped-def]
                      best_i, best_d):
    """Query one LSH level as FLANN's `knnSearch(k=2)` does and merge its (usable) answers into
    `best_i`/`best_d` after the candidates already there (a tie keeps the earlier one)."""
    tables = bits.shape[0]
    n_slots = slots.shape[1]
    shift = _hash_shift(n_slots)
    n = q.shape[0]
    probes = xor_masks.size
    # all hash look-ups first (independent memory accesses), then the buckets query by query
    found = np.empty((n, tables * probes), np.int64)
    for t in range(tables):
        for x in range(probes):
            col = t * probes + x
            for i in range(n):
                sub = _key(q, i, bits, t) ^ xor_masks[x]
                s = _slot_of(sub, shift)
                while slots[t, s, 0] >= 0 and slots[t, s, 0] != sub:
                    s = (s + 1) & (n_slots - 1)
                found[i, col] = slots[t, s, 1] if slots[t, s, 0] >= 0 else -1
    for i in range(n):
        # FLANN's KNNUniqueResultSet(2): a sorted set of (distance, index); a candidate at
        # or beyond the worst distance of a full set is turned away
        count = 0
        s1d = _FLANN_NO_DISTANCE
        s1m = -1
        s2d = _FLANN_NO_DISTANCE
        s2m = -1
        worst = _FLANN_NO_DISTANCE
        q0, q1, q2, q3 = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        for col in range(tables * probes):
            bucket = found[i, col]
            if bucket < 0:
                continue
            start = bucket & 0xFFFFFFFF
            for p in range(start, start + (bucket >> 32)):
                d = int(popcount64(q0 ^ member_words[p, 0]) + popcount64(q1 ^ member_words[p, 1])
                        + popcount64(q2 ^ member_words[p, 2])
                        + popcount64(q3 ^ member_words[p, 3]))
                if d >= worst:
                    continue
                m = members[p]
                if (count >= 1 and d == s1d and m == s1m) or (
                        count == 2 and d == s2d and m == s2m):
                    continue  # already in the set
                if count == 0:
                    s1d, s1m = d, m
                    count = 1
                elif d < s1d or (d == s1d and m < s1m):
                    s2d, s2m, s1d, s1m = s1d, s1m, d, m
                    count = 2
                    worst = s2d
                else:
                    s2d, s2m = d, m
                    count = 2
                    worst = s2d
        b1, b2 = best_d[i, 0], best_d[i, 1]
        i1, i2 = best_i[i, 0], best_i[i, 1]
        for c in range(count):
            w = ids[s1m] if c == 0 else ids[s2m]
            d = s1d if c == 0 else s2d
            if usable[w] and d < b2:
                if d < b1:
                    b2, i2, b1, i1 = b1, i1, d, w
                else:
                    b2, i2 = d, w
        best_d[i, 0], best_d[i, 1] = b1, b2
        best_i[i, 0], best_i[i, 1] = i1, i2
