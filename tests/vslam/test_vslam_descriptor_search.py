"""The compiled descriptor searches give exactly what the library searches they replace give."""

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from eddiebot.vslam import vocabulary
from eddiebot.vslam.matching import (
    as_words64,
    knn2_hamming,
    knn2_hamming_candidates,
    knn2_hamming_window,
)
from eddiebot.vslam.vocabulary import Vocabulary


def _clustered(rng: np.random.Generator, n: int, base: np.ndarray, flip: float) -> np.ndarray:
    """ORB-like descriptors: copies of a few centres with some bits flipped (many near ties,
    some exact duplicates of the first centre)."""
    bits = np.unpackbits(base[rng.integers(0, base.shape[0], n)], axis=1)
    bits ^= (rng.random(bits.shape) < flip).astype(np.uint8)
    out = np.packbits(bits, axis=1)
    out[rng.random(n) < 0.05] = base[0]  # exact duplicates
    return out


def _centres(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.integers(0, 256, (n, 32), dtype=np.uint8)


def _flann_knn2(voc: Vocabulary, desc: np.ndarray, multi_probe: int) -> tuple[np.ndarray, ...]:
    """The previous implementation: one `cv2.flann` LSH index per level (built after the same
    seed), the exact tail, merged in numpy by a stable sort on distance."""
    n = desc.shape[0]
    words = voc._desc[: len(voc)]
    usable = voc._refs[: len(voc)] > 0
    tail = np.asarray(voc._tail, np.int64)
    usable[tail] = True
    cand_i, cand_d = [], []
    if tail.size:
        ti, td = knn2_hamming(as_words64(desc), as_words64(words[tail]))
        cand_i.append(np.where(ti >= 0, tail[np.maximum(ti, 0)], -1))
        cand_d.append(td)
    for level in voc._levels:
        if level.ids.size < 2:
            continue
        cv2.setRNGSeed(vocabulary.LSH_SEED + int(level.ids.size))
        index = cv2.flann.Index()
        index.build(np.ascontiguousarray(words[level.ids]),
                    {"algorithm": 6, "table_number": 8, "key_size": 20,
                     "multi_probe_level": multi_probe}, 9)
        li, ld = index.knnSearch(desc, 2, params={"checks": 32})
        li = np.asarray(li, np.int64).reshape(n, -1)
        ld = np.asarray(ld, np.int64).reshape(n, -1)
        cand_i.append(np.where(li >= 0, level.ids[np.maximum(li, 0)], -1))
        cand_d.append(np.where(li >= 0, ld, 1 << 30))
    all_i = np.concatenate(cand_i, axis=1)
    all_d = np.concatenate(cand_d, axis=1)
    ok = all_i >= 0
    ok[ok] = usable[all_i[ok]]
    all_d = np.where(ok, all_d, 1 << 30)
    all_i = np.where(ok, all_i, -1)
    order = np.argsort(all_d, axis=1, kind="stable")[:, :2]
    best_i = np.take_along_axis(all_i, order, axis=1)
    best_d = np.take_along_axis(all_d, order, axis=1)
    best_i[best_d >= 1 << 30] = -1
    return best_i, best_d


@pytest.mark.parametrize("multi_probe", [0, 1])
def test_vocabulary_search_equals_flann_lsh(multi_probe: int):
    rng = np.random.default_rng(11)
    voc = Vocabulary(0.8, exact_max=128, lsh_multi_probe=multi_probe)
    base = _centres(rng, 150)
    stream = _clustered(rng, 3000, base, 0.06)
    for k in range(0, 3000, 100):
        ids = voc.quantize(stream[k:k + 100])
        voc.add_references(ids)
        if k == 1500:  # some words leave memory: dead words inside levels, compaction
            voc.remove_references(ids)
    assert len(voc._levels) >= 2 and voc._tail  # levels and tail both searched
    queries = _clustered(rng, 600, base, 0.06)
    got_i, got_d = voc._knn2(queries)
    ref_i, ref_d = _flann_knn2(voc, queries, multi_probe)
    np.testing.assert_array_equal(got_i, ref_i)
    found = got_i >= 0
    np.testing.assert_array_equal(got_d[found], ref_d[found])
    # both the levels and the tail give nearest words
    in_levels = np.isin(got_i[:, 0], np.concatenate([lv.ids for lv in voc._levels]))
    assert 0.2 < in_levels.mean() < 0.95


def test_hamming_knn2_takes_the_first_of_equal_distances():
    rng = np.random.default_rng(3)
    base = _centres(rng, 20)
    train = _clustered(rng, 700, base, 0.03)
    query = _clustered(rng, 300, base, 0.03)
    mask = rng.random(700) < 0.7
    idx, dist = knn2_hamming(as_words64(query), as_words64(train), mask)
    full = np.unpackbits(query[:, None, :] ^ train[None, :, :], axis=2).sum(axis=2)
    full = np.where(mask[None, :], full, 1 << 30)
    order = np.argsort(full, axis=1, kind="stable")[:, :2]
    np.testing.assert_array_equal(idx, order)
    np.testing.assert_array_equal(dist, np.take_along_axis(full, order, axis=1))
    assert np.any(dist[:, 0] == dist[:, 1])  # ties were exercised


@pytest.mark.parametrize("radius", [40.0, 5.0])
def test_window_search_equals_ball_query_lists(radius: float):
    rng = np.random.default_rng(int(radius))
    m, n = 800, 900
    base = _centres(rng, 30)
    train = _clustered(rng, m + 40, base, 0.04)
    query = _clustered(rng, n, base, 0.04)
    rows = np.sort(rng.choice(m + 40, m, replace=False))
    # integer pixel positions put many points exactly on the window's edge (3-4-5 triangles)
    train_uv = rng.integers(-40, 680, (m, 2)).astype(np.float64)
    query_uv = rng.integers(0, 640, (n, 2)).astype(np.float32)
    got = knn2_hamming_window(as_words64(query), as_words64(train), query_uv, train_uv, rows,
                              radius)
    lists = cKDTree(train_uv).query_ball_point(query_uv.astype(np.float64), r=radius)
    offsets = np.concatenate([[0], np.cumsum([len(c) for c in lists])]).astype(np.int64)
    flat = np.concatenate([np.asarray(c, np.int64) for c in lists])
    ref = knn2_hamming_candidates(as_words64(query), as_words64(train), offsets, rows[flat])
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_array_equal(got[1], ref[1])
    # windows with no candidate, with one, and with two or more
    assert 0.0 < np.mean(got[0][:, 1] >= 0) < np.mean(got[0][:, 0] >= 0) < 1.0
