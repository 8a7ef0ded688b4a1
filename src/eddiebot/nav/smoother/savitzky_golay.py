"""``nav2_smoother::SavitzkyGolaySmoother``: a 7-point Savitzky-Golay filter (quadratic fit,
coefficients (-2, 3, 6, 7, 6, 3, -2)/21) over each directional segment longer than 10 poses,
the window padded with the segment's first and last points, both ends fixed;
``do_refinement`` filters the result ``refinement_num`` more times. It does not check collisions, as upstream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import InvalidPathForSmoothing
from eddiebot.nav.params import require
from eddiebot.nav.smoother.base import SmoothResult
from eddiebot.nav.types import as_path


@dataclass(frozen=True)
class SavitzkyGolaySmootherConfig:
    """``nav2_smoother::SavitzkyGolaySmoother`` parameters (Jazzy code defaults)."""

    do_refinement: bool = True
    refinement_num: int = 2

    def validate(self, server: str = "smoother_server") -> None:
        require(self.refinement_num >= 0, server, "refinement_num", self.refinement_num,
                "must be >= 0")


SG_COEFFICIENTS = np.array([-2.0, 3.0, 6.0, 7.0, 6.0, 3.0, -2.0]) / 21.0


def _directional_segments(path: npt.NDArray[np.float64]) -> list[tuple[int, int]]:
    """``smoother_utils::findDirectionalPathSegments``: split at cusps (the step direction
    reverses) and at in-place rotations; (start, end inclusive) pairs sharing their ends."""
    out = []
    start = 0
    for i in range(1, path.shape[0] - 1):
        oa = path[i, :2] - path[i - 1, :2]
        ab = path[i + 1, :2] - path[i, :2]
        if float(oa @ ab) < 0.0:
            out.append((start, i))
            start = i
        dth = math.remainder(float(path[i + 1, 2] - path[i, 2]), 2.0 * math.pi)
        if abs(ab[0]) < 1e-4 and abs(ab[1]) < 1e-4 and abs(dth) > 1e-4:
            out.append((start, i))
            start = i
    out.append((start, path.shape[0] - 1))
    return out


def _sg_pass(xy: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """One filter pass over (N, 2) points: points 1..N-2 replaced, the window padded with the
    first point before and the last point after (upstream's ``applyFilterOverAxes``)."""
    n = xy.shape[0]
    padded = np.concatenate([np.repeat(xy[:1], 2, axis=0), xy, np.repeat(xy[-1:], 3, axis=0)])
    out = xy.copy()
    for idx in range(1, n - 1):
        out[idx] = SG_COEFFICIENTS @ padded[idx - 1:idx + 6]
    return out


def _approximate_orientations(seg: npt.NDArray[np.float64]) -> None:
    """``smoother_utils::updateApproximatePathOrientations``: every pose but the last faces
    the next point (plus π on a reversing segment, judged at pose 1); repeated points keep
    their heading."""
    d = seg[2, :2] - seg[1, :2]
    reversing = abs(math.remainder(math.atan2(d[1], d[0]) - float(seg[1, 2]), 2 * math.pi)) \
        > math.pi / 2
    for i in range(seg.shape[0] - 1):
        dx, dy = seg[i + 1, 0] - seg[i, 0], seg[i + 1, 1] - seg[i, 1]
        if abs(dx) < 1e-4 and abs(dy) < 1e-4:
            continue
        th = math.atan2(dy, dx) + (math.pi if reversing else 0.0)
        seg[i, 2] = math.atan2(math.sin(th), math.cos(th))


class SavitzkyGolaySmoother:
    """Smoother plugin; :meth:`smooth` returns a new (N, 3) path (``costmap`` unused)."""

    def __init__(self, config: SavitzkyGolaySmootherConfig | None = None,
                 name: str = "savitzky_golay_smoother") -> None:
        self.config = config or SavitzkyGolaySmootherConfig()
        self.config.validate()
        self.name = name

    def smooth(self, path: npt.ArrayLike, costmap: Costmap2D | None = None) -> SmoothResult:
        p = as_path(path)
        if p.shape[0] == 0:
            raise InvalidPathForSmoothing("empty path")
        out = p.copy()
        passes = 1 + (self.config.refinement_num if self.config.do_refinement else 0)
        for s, e in _directional_segments(p):
            if e - s <= 9:
                continue
            seg = out[s:e + 1].copy()
            for _ in range(passes):
                seg[:, :2] = _sg_pass(seg[:, :2])
            _approximate_orientations(seg)
            out[s:e + 1] = seg
        return SmoothResult(out, True)



__all__ = ["SG_COEFFICIENTS", "SavitzkyGolaySmoother", "SavitzkyGolaySmootherConfig"]
