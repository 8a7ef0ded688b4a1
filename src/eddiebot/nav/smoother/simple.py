"""``nav2_smoother::SimpleSmoother``: gradient smoothing that never enters collision.

Each interior point moves by ``w_data·(original - current) + w_smooth·(next + prev -
2·current)`` per iteration until the total change falls below ``tolerance``; if a moved point
lands on a cost above ``MAX_NON_OBSTACLE`` (unknown excepted) the path of the previous
iteration is returned. Segments between cusps are smoothed separately with fixed ends;
``do_refinement`` reruns the smoother ``refinement_num`` times on its own output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import MAX_NON_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import InvalidPathForSmoothing
from eddiebot.nav.params import require
from eddiebot.nav.smoother.base import SmoothResult
from eddiebot.nav.types import as_path


@dataclass(frozen=True)
class SimpleSmootherConfig:
    """``nav2_smoother::SimpleSmoother`` parameters (Jazzy code defaults)."""

    tolerance: float = 1.0e-10
    max_its: int = 1000
    w_data: float = 0.2
    w_smooth: float = 0.3
    do_refinement: bool = True
    refinement_num: int = 2
    enforce_path_inversion: bool = True

    def validate(self, server: str = "smoother_server") -> None:
        require(self.max_its > 0, server, "max_its", self.max_its, "must be > 0")
        require(self.refinement_num >= 0, server, "refinement_num", self.refinement_num,
                "must be >= 0")



def _segments(path: npt.NDArray[np.float64], split: bool) -> list[tuple[int, int, bool]]:
    """(start, end inclusive, reversing) segments split at cusps."""
    n = path.shape[0]
    if not split or n < 3:
        return [(0, n - 1, False)]
    out = []
    start = 0
    d = np.diff(path[:, :2], axis=0)
    for i in range(1, n - 1):
        if float(d[i - 1] @ d[i]) < 0.0:
            out.append((start, i, False))
            start = i
    out.append((start, n - 1, False))
    # Direction of each segment relative to the pose heading (reversing when moving backwards).
    res = []
    for s, e, _ in out:
        seg = path[s:e + 1]
        dd = seg[1, :2] - seg[0, :2] if seg.shape[0] > 1 else np.zeros(2)
        heading = np.array([np.cos(seg[0, 2]), np.sin(seg[0, 2])])
        res.append((s, e, bool(dd @ heading < 0.0)))
    return res


def _orientations(seg: npt.NDArray[np.float64], reversing: bool) -> None:
    d = np.diff(seg[:, :2], axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0])
    if reversing:
        yaw = yaw + np.pi
    seg[:-1, 2] = np.arctan2(np.sin(yaw), np.cos(yaw))


class SimpleSmoother:
    """Smoother plugin; :meth:`smooth` returns a new (N, 3) path."""

    def __init__(self, config: SimpleSmootherConfig | None = None, name: str = "simple_smoother") -> None:
        self.config = config or SimpleSmootherConfig()
        self.config.validate()
        self.name = name

    def smooth(self, path: npt.ArrayLike, costmap: Costmap2D | None = None) -> SmoothResult:
        p = as_path(path)
        if p.shape[0] == 0:
            raise InvalidPathForSmoothing("empty path")
        out = p.copy()
        converged = True
        for s, e, rev in _segments(p, self.config.enforce_path_inversion):
            if e - s < 2:
                continue
            seg = out[s:e + 1].copy()
            refinements = 0
            while True:
                seg, ok = self._smooth_once(seg, costmap)
                converged = converged and ok
                if not ok or not self.config.do_refinement or refinements >= self.config.refinement_num:
                    break
                refinements += 1
            last_yaw = seg[-1, 2]
            _orientations(seg, rev)
            seg[-1, 2] = last_yaw
            out[s:e + 1] = seg
        return SmoothResult(out, converged)

    def _smooth_once(self, path: npt.NDArray[np.float64], costmap: Costmap2D | None
                     ) -> tuple[npt.NDArray[np.float64], bool]:
        cfg = self.config
        original = path[:, :2].copy()
        new = path[:, :2].copy()
        last = new.copy()
        n = new.shape[0]
        its = 0
        change = cfg.tolerance
        while change >= cfg.tolerance:
            its += 1
            change = 0.0
            if its >= cfg.max_its:
                out = path.copy()
                out[:, :2] = last
                return out, False
            for i in range(1, n - 1):
                for j in range(2):
                    y_i = new[i, j]
                    y_new = y_i + cfg.w_data * (original[i, j] - y_i) + cfg.w_smooth * (
                        new[i + 1, j] + new[i - 1, j] - 2.0 * y_i
                    )
                    new[i, j] = y_new
                    change += abs(y_new - y_i)
                if costmap is not None:
                    cell = costmap.world_to_map(new[i, 0], new[i, 1])
                    if cell is not None:
                        c = costmap.get_cost(*cell)
                        if c > MAX_NON_OBSTACLE and c != NO_INFORMATION:
                            out = path.copy()
                            out[:, :2] = last
                            return out, False
            last = new.copy()
        out = path.copy()
        out[:, :2] = new
        return out, True



__all__ = ["SimpleSmoother", "SimpleSmootherConfig"]
