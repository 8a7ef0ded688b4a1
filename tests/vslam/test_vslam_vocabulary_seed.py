"""The vocabulary's LSH index is seeded: quantisation does not depend on OpenCV's global RNG."""

import cv2
import numpy as np
import pytest

from eddiebot.vslam import vocabulary
from eddiebot.vslam.vocabulary import Vocabulary


def _stream(seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Random 256-bit words, and queries that are copies of them with 30 bits flipped: close
    enough to pass the NNDR test, far enough that an LSH table finds them only sometimes."""
    rng = np.random.default_rng(seed)
    words = rng.integers(0, 256, (600, 32), dtype=np.uint8)
    bits = np.unpackbits(words[:300], axis=1)
    for row in bits:
        row[rng.choice(256, 30, replace=False)] ^= 1
    return words, np.packbits(bits, axis=1)


def _quantize_after(rng_seed: int, draws: int) -> np.ndarray:
    """Words the queries get when OpenCV's global RNG was used before every index build."""
    words, queries = _stream()
    voc = Vocabulary(0.8, exact_max=64)
    cv2.setRNGSeed(rng_seed)
    cv2.randu(np.zeros(draws, np.float32), 0, 1)  # unrelated use of the global RNG
    for k in range(0, len(words), 50):
        ids = voc.quantize(words[k:k + 50])
        voc.add_references(ids)
    return voc.quantize(queries, add_new=False)


def test_quantisation_does_not_depend_on_global_rng_history():
    a = _quantize_after(1, 10)
    b = _quantize_after(777, 12345)
    # the LSH search is approximate: some queries find their word, some do not
    found = np.count_nonzero(a == np.arange(1, 301))
    assert 30 < found < 300
    np.testing.assert_array_equal(a, b)


def test_without_the_seed_the_index_follows_the_global_rng(monkeypatch: pytest.MonkeyPatch):
    class _Unseeded:
        flann = cv2.flann

        @staticmethod
        def setRNGSeed(seed: int) -> None:  # OpenCV's name
            pass

    monkeypatch.setattr(vocabulary, "cv2", _Unseeded)
    a = _quantize_after(1, 10)
    b = _quantize_after(777, 12345)
    assert np.count_nonzero(a != b) > 5


def test_seed_base_selects_another_draw(monkeypatch: pytest.MonkeyPatch):
    a = _quantize_after(1, 10)
    monkeypatch.setattr(vocabulary, "LSH_SEED", vocabulary.LSH_SEED + 1)
    b = _quantize_after(1, 10)
    assert np.count_nonzero(a != b) > 5
