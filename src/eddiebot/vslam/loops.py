"""Appearance-only loop-closure detection over an image sequence (no depth, no geometry).

Bag of words + TF-IDF + the Bayes filter with a virtual place, exactly the detector inside
`Rtabmap` but fed with bare images; `detect_loops(folder)` returns ``(query, match, score)`` rows
in numeric file order, with an empty match when no loop is accepted.
"""

from __future__ import annotations

import csv
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.bayes import BayesFilter, adjust_likelihood, tfidf_scores
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.errors import VslamError
from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.memory import Link, LinkType, Memory, Node, NodeData
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.tum import numeric_sort_key
from eddiebot.vslam.vocabulary import Vocabulary

__all__ = [
    "IMAGE_SUFFIXES",
    "AppearanceLoopDetector",
    "LoopDetection",
    "detect_loops",
    "list_images",
    "precision_recall_curve",
    "recall_at_full_precision",
    "write_loop_rows",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")


@dataclass(frozen=True)
class LoopDetection:
    """Per image: best hypothesis (id, value = 1 − P(new place)) and the accepted loop id (0 = none)."""

    node_id: int
    hypothesis_id: int
    hypothesis_value: float
    loop_id: int


class AppearanceLoopDetector:
    """Incremental bag-of-words + Bayes loop detector over images (`Rtabmap/LoopThr`, STM, ...)."""

    def __init__(self, params: RtabmapParameters | Mapping[str, str] | None = None) -> None:
        if params is None:
            params = RtabmapParameters()
        elif not isinstance(params, RtabmapParameters):
            params = RtabmapParameters.from_dict(params)
        self.params = params
        self.vocabulary = Vocabulary(params.kp_nndr_ratio)
        self.memory = Memory(self.vocabulary, params.mem_stm_size)
        self.bayes = BayesFilter(params.prediction_lc(), params.bayes_virtual_place_prior_thr)
        self._extractor = FeatureExtractor(
            params, max_features=params.kp_max_features, strategy=params.kp_detector_strategy
        )
        self._next_id = 1
        self._dummy_camera = CameraIntrinsics(500.0, 500.0, 320.0, 240.0, 640, 480)

    def process(self, image: NDArray[np.uint8]) -> LoopDetection:
        """Add one image; returns its id and the loop decision."""
        features = self._extractor.extract(image, None, self._dummy_camera, depth_as_mask=False)
        words = self.vocabulary.quantize(features.descriptors)
        data = NodeData(features, words)
        node = Node(self._next_id, 0, 0, np.eye(4), data=data, word_counts=data.word_counts())
        self._next_id += 1
        prev = self.memory.stm[-1] if self.memory.stm else 0
        moved = self.memory.add_to_stm(node)
        if prev:
            self.memory.add_link(Link(prev, node.id, LinkType.NEIGHBOR, np.eye(4), np.eye(6)))
        for m in moved:
            self.bayes.node_entered(m, self.memory.neighbours(m, self.bayes.max_depth))
        wm = self.memory.wm_ids
        if not wm or not node.word_counts:
            return LoopDetection(node.id, 0, 0.0, 0)
        mem = self.memory
        scores = tfidf_scores(node.word_counts, mem.inverted, mem.word_totals,
                              len(mem.wm) + len(mem.stm), wm)
        like = adjust_likelihood(scores, self.params.rtabmap_virtual_place_likelihood_ratio)
        self.bayes.update(like, lambda i, d: mem.neighbours(i, d))
        best, value = self.bayes.highest_hypothesis()
        loop = best if (best and value >= self.params.rtabmap_loop_thr and len(wm) > 1) else 0
        return LoopDetection(node.id, best, value, loop)


def precision_recall_curve(
    values: Sequence[float], verdicts: Sequence[int], n_positive: int
) -> list[tuple[float, float, float]]:
    """(threshold, precision, recall) for each distinct hypothesis value used as `Rtabmap/LoopThr`.

    Per query image: `values` = its best hypothesis value, `verdicts` = 1 if that hypothesis is
    the same place, −1 if it is a wrong place, 0 if it is neither counted right nor wrong (a
    near place within the ground truth's tolerance); `n_positive` = query images that have a
    same place among the loop candidates. Images accepted at a threshold t have value ≥ t;
    precision is 1 while only near places have been accepted.
    """
    v = np.asarray(values, np.float64)
    d = np.asarray(verdicts, np.int64)
    order = np.argsort(-v, kind="stable")
    v, d = v[order], d[order]
    tp = np.cumsum(d == 1)
    fp = np.cumsum(d == -1)
    out = []
    for k in range(v.size):
        if v[k] <= 0.0:
            break
        if k + 1 < v.size and v[k + 1] == v[k]:
            continue  # ties: take all images with this value together
        counted = tp[k] + fp[k]
        precision = tp[k] / counted if counted else 1.0  # only near places so far: no error
        out.append((float(v[k]), float(precision), float(tp[k] / max(1, n_positive))))
    return out


def recall_at_full_precision(
    values: Sequence[float], verdicts: Sequence[int], n_positive: int
) -> tuple[float, float]:
    """RTAB-Map's metric: sort the query images by hypothesis value, count the right ones
    until the first wrong one. Returns (recall, the lowest `Rtabmap/LoopThr` that keeps
    precision at 100 %; 1.0 when the very first is wrong)."""
    best_recall, best_thr = 0.0, 1.0
    for thr, precision, recall in precision_recall_curve(values, verdicts, n_positive):
        if precision < 1.0:
            break
        best_recall, best_thr = recall, thr
    return best_recall, best_thr


def list_images(folder: str | Path) -> list[Path]:
    """Image files of a folder in numeric order of the last number in their names."""
    root = Path(folder)
    if not root.is_dir():
        raise VslamError(f"{root}: not a folder")
    files = [p for p in root.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(files, key=numeric_sort_key)


def detect_loops(
    folder: str | Path, params: RtabmapParameters | Mapping[str, str] | None = None
) -> list[tuple[str, str, float]]:
    """``(query, match, score)`` per image: file names; empty match when no loop is accepted.

    The score is the highest hypothesis value (1 − P(new place)) whether or not accepted, so
    the rows also give a precision–recall curve.
    """
    detector = AppearanceLoopDetector(params)
    images = list_images(folder)
    names: dict[int, str] = {}
    rows = []
    for path in images:
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise VslamError(f"cannot read image {path}")
        det = detector.process(np.asarray(img, dtype=np.uint8))
        names[det.node_id] = path.name
        rows.append((path.name, names.get(det.loop_id, "") if det.loop_id else "",
                     round(det.hypothesis_value, 6)))
    return rows


def write_loop_rows(rows: Sequence[tuple[str, str, float]], path: str | Path) -> None:
    """CSV with a ``query,match,score`` header, written atomically."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name, suffix=".tmp")
    with os.fdopen(fd, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["query", "match", "score"])
        writer.writerows(rows)
    os.replace(tmp, target)
