"""The pose graph's vocabulary: edge kinds, edges with their covariance, and the small
GTSAM and χ² helpers the graph classes share."""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt
from scipy.special import gammaincinv

FloatArray = npt.NDArray[np.float64]

FACTORIZATIONS = ("qr", "cholesky")
"""iSAM2 eliminations `PoseGraph` offers."""
_PRIOR_SIGMAS = np.array([1e-4, 1e-4, 1e-5])
_EXTRA_ROUNDS = 4
"""At most this many extra iSAM2 relinearisation rounds after a loop closure."""


class EdgeKind(str, enum.Enum):
    """Where an edge came from."""

    ODOMETRY = "odometry"
    SCAN_MATCH = "scan_match"
    LOOP = "loop"


@dataclass(frozen=True)
class Edge:
    """A relative-pose measurement from node ``i`` to node ``j``."""

    i: int
    j: int
    measurement: FloatArray
    covariance: FloatArray
    kind: EdgeKind = EdgeKind.SCAN_MATCH
    robust: bool = False

    @property
    def information(self) -> FloatArray:
        """Ω = Σ⁻¹."""
        return np.asarray(np.linalg.inv(self.covariance))


def _pose2(p: npt.ArrayLike) -> gtsam.Pose2:
    a = np.asarray(p, dtype=np.float64)
    return gtsam.Pose2(float(a[0]), float(a[1]), float(a[2]))


def _sanitize_covariance(cov: npt.ArrayLike) -> FloatArray:
    c = np.asarray(cov, dtype=np.float64).reshape(3, 3)
    c = 0.5 * (c + c.T)
    try:
        np.linalg.cholesky(c)
        if np.linalg.cond(c) < 1e12:
            return c
    except np.linalg.LinAlgError:
        pass
    w, v = np.linalg.eigh(c)
    w = np.clip(w, 1e-12, None)
    return np.asarray((v * w) @ v.T)


def _joint(marginal: Any, keys: list[int]) -> FloatArray:
    """The dense joint covariance of ``keys`` from a GTSAM JointMarginal."""
    return np.block([[marginal.at(a, b) for b in keys] for a in keys])


def _marginal_fn(source: Any) -> Callable[[list[int]], FloatArray]:
    """``keys -> joint covariance`` from an ISAM2 or a Marginals object."""

    def marginal(keys: list[int]) -> FloatArray:
        return _joint(source.jointMarginalCovariance(keys), keys)

    return marginal


def chi2_quantile(probability: float, dof: int = 3) -> float:
    """χ²_dof quantile: the squared Mahalanobis distance under which ``probability`` of a
    correct measurement's residuals fall."""
    return float(2.0 * gammaincinv(0.5 * dof, probability))
