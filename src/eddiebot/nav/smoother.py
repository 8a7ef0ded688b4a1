"""Nav2's path smoothers (``nav2_smoother``): ``SimpleSmoother`` and ``SavitzkyGolaySmoother``.

``SimpleSmoother``: gradient smoothing that never enters collision.

Each interior point moves by ``w_data·(original - current) + w_smooth·(next + prev -
2·current)`` per iteration until the total change falls below ``tolerance``; if a moved point
lands on a cost above ``MAX_NON_OBSTACLE`` (unknown excepted) the path of the previous
iteration is returned. Segments between cusps are smoothed separately with fixed ends;
``do_refinement`` reruns the smoother ``refinement_num`` times on its own output.

``SavitzkyGolaySmoother``: a 7-point Savitzky-Golay filter (quadratic fit, coefficients
(-2, 3, 6, 7, 6, 3, -2)/21) over each directional segment longer than 10 poses, the window
padded with the segment's first and last points, both ends fixed; ``do_refinement`` filters
the result ``refinement_num`` more times. It does not check collisions, as upstream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from eddiebot.nav.cost_values import MAX_NON_OBSTACLE, NO_INFORMATION
from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import InvalidPathForSmoothing
from eddiebot.nav.params import from_params, require
from eddiebot.nav.plugins import PluginContext, PluginFactory, registry
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


@dataclass(frozen=True)
class SmoothResult:
    path: npt.NDArray[np.float64]
    converged: bool
    """False when stopped by max_its or by a collision (the last admissible path is returned)."""


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


class Smoother(Protocol):
    name: str

    def smooth(self, path: npt.ArrayLike, costmap: Costmap2D | None = None) -> SmoothResult: ...


SMOOTHERS = registry("smoothers")


def register_smoother(type_name: str, cls: type[Any], config_cls: type[Any]) -> None:
    """Register a smoother built as ``cls(config, name)`` with its config dataclass
    ``config_cls`` read from the instance's parameters."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(from_params(config_cls, params, server=context.where), name)

    f: PluginFactory = factory
    SMOOTHERS.register(type_name, f, config_cls, source="built-in")


register_smoother("nav2_smoother::SimpleSmoother", SimpleSmoother, SimpleSmootherConfig)
register_smoother("nav2_smoother::SavitzkyGolaySmoother", SavitzkyGolaySmoother,
                  SavitzkyGolaySmootherConfig)


def build_smoother(name: str, params: dict[str, Any], server: str = "smoother_server"
                   ) -> Smoother:
    """The smoother instance ``name`` from its parameter block (``plugin`` defaults to
    SimpleSmoother, as in Nav2's sample files)."""
    plugin = str(params.get("plugin", "nav2_smoother::SimpleSmoother"))
    smoother: Smoother = SMOOTHERS.create(plugin, params, name, PluginContext(server, name))
    return smoother


__all__ = ["SMOOTHERS", "SavitzkyGolaySmoother", "SavitzkyGolaySmootherConfig", "SimpleSmoother",
           "SimpleSmootherConfig", "SmoothResult", "Smoother", "build_smoother", "register_smoother"]
