"""What every path smoother returns, and the interface the smoother server calls."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D


@dataclass(frozen=True)
class SmoothResult:
    path: npt.NDArray[np.float64]
    converged: bool
    """False when stopped by max_its or by a collision (the last admissible path is returned)."""



class Smoother(Protocol):
    name: str

    def smooth(self, path: npt.ArrayLike, costmap: Costmap2D | None = None) -> SmoothResult: ...



__all__ = ["SmoothResult", "Smoother"]
