"""Links of a pose graph and their residuals: `GraphLink`, the `LinkLike` and
`PoseGraphOptimizer` shapes, `link_errors` (`RGBD/OptimizeMaxError`'s normalised residuals)
and the conversions both optimisers share (4×4 ↔ gtsam poses, information → noise)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple, Protocol

import gtsam
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.transforms import yaw_of

__all__ = ["GraphLink", "LinkError", "LinkLike", "PoseGraphOptimizer", "link_errors"]

F64 = NDArray[np.float64]
_FIXED_SIGMA = 1e-6
_IDX_POSE2 = np.array([0, 1, 5])
_IDX_POSE3 = np.array([3, 4, 5, 0, 1, 2])
_INFO_IGNORED = 1e-4
_MIN_VARIANCE = 1e-6  # (1 mm)², (1 mrad)²: floor of link variances in the incremental graph


@dataclass(frozen=True)
class GraphLink:
    """A constraint: pose of `to_id` in the frame of `from_id`, with its information matrix."""

    from_id: int
    to_id: int
    transform: F64
    information: F64
    #: a loop closure, which `Optimizer/Robust` may switch off (odometry links: False)
    switchable: bool = False


class LinkLike(Protocol):
    """Anything with a link's fields (`GraphLink`, `eddiebot.vslam.memory.Link`)."""

    @property
    def from_id(self) -> int: ...
    @property
    def to_id(self) -> int: ...
    @property
    def transform(self) -> F64: ...
    @property
    def information(self) -> F64: ...
    @property
    def switchable(self) -> bool: ...


class LinkError(NamedTuple):
    """RTAB-Map's normalised residual of one link after optimisation (`RGBD/OptimizeMaxError`)."""

    from_id: int
    to_id: int
    linear_ratio: float
    angular_ratio: float


class PoseGraphOptimizer(Protocol):
    """What the SLAM core needs from a pose-graph back end."""

    def optimize(
        self,
        poses: Mapping[int, F64],
        links: Iterable[LinkLike],
        root_id: int,
        iterations: int,
    ) -> dict[int, F64]:
        """Optimised poses of the nodes connected to `root_id` (which stays fixed)."""
        ...


def _floored_covariance(information: F64) -> F64:
    """Σ = Ω⁻¹ with eigenvalues ≥ `_MIN_VARIANCE`: near-exact registrations (σ ≈ 0.1 mm on
    synthetic images) next to the anchor prior otherwise make iSAM2's Cholesky ill-posed.
    Cached by the matrix's bytes: a rebuilt graph re-adds the same links (read-only result)."""
    info = np.ascontiguousarray(information, dtype=np.float64)
    return _floored_covariance_of(info.tobytes(), info.shape)


@lru_cache(maxsize=1 << 16)
def _floored_covariance_of(data: bytes, shape: tuple[int, ...]) -> F64:
    information = np.frombuffer(data, dtype=np.float64).reshape(shape)
    w, v = np.linalg.eigh(0.5 * (information + information.T))
    w = 1.0 / np.clip(w, 1e-12, None)
    out = np.asarray((v * np.clip(w, _MIN_VARIANCE, None)) @ v.T)
    out.flags.writeable = False
    return out


def _xyt(t: F64) -> F64:
    return np.array([float(t[0, 3]), float(t[1, 3]), yaw_of(t)])


def _pose2(t: F64) -> gtsam.Pose2:
    return gtsam.Pose2(float(t[0, 3]), float(t[1, 3]), yaw_of(t))


def _pose3(t: F64) -> gtsam.Pose3:
    return gtsam.Pose3(np.asarray(t, dtype=np.float64))


def _component(root: int, links: list[LinkLike]) -> set[int]:
    adjacency: dict[int, list[int]] = {}
    for lk in links:
        adjacency.setdefault(lk.from_id, []).append(lk.to_id)
        adjacency.setdefault(lk.to_id, []).append(lk.from_id)
    seen = {root}
    stack = [root]
    while stack:
        n = stack.pop()
        for m in adjacency.get(n, ()):
            if m not in seen:
                seen.add(m)
                stack.append(m)
    return seen


def link_errors(poses: Mapping[int, F64], links: Iterable[LinkLike]) -> list[LinkError]:
    """Per link: max axis deviation / linear σ and rotation deviation / angular σ.

    σ comes from the smallest information term among x, y, z (resp. roll, pitch, yaw), ignoring
    terms ≤ 1e-4, so a huge z variance of planar odometry does not count; σ² is floored at
    1e-6 (1 mm, 1 mrad) as in `IncrementalPose2Graph`.
    """
    usable = [lk for lk in links if lk.from_id in poses and lk.to_id in poses]
    if not usable:
        return []
    a = np.stack([poses[lk.from_id] for lk in usable])
    b = np.stack([poses[lk.to_id] for lk in usable])
    m = np.stack([lk.transform for lk in usable])
    info = np.diagonal(np.stack([lk.information for lk in usable]), axis1=1, axis2=2)
    lin_ratio, ang_ratio = _error_ratios(a, b, m, info)
    return [LinkError(lk.from_id, lk.to_id, x, y)
            for lk, x, y in zip(usable, lin_ratio.tolist(), ang_ratio.tolist())]



def _error_ratios(a: F64, b: F64, m: F64, info: F64) -> tuple[F64, F64]:
    """Linear and angular ratios of links with poses `a` (from), `b` (to), transforms `m`
    (all (L, 4, 4)) and information diagonals `info` (L, 6)."""
    ra = a[:, :3, :3]
    # T = inv(A) B
    t_rot = np.einsum("nji,njk->nik", ra, b[:, :3, :3])
    t_tr = np.einsum("nji,nj->ni", ra, b[:, :3, 3] - a[:, :3, 3])
    rot = np.einsum("nji,njk->nik", m[:, :3, :3], t_rot)  # Mᵀ T
    axis = np.stack([rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0],
                     rot[:, 1, 0] - rot[:, 0, 1]], axis=1)
    two_sin = np.sqrt(np.einsum("ni,ni->n", axis, axis))
    trace = rot[:, 0, 0] + rot[:, 1, 1] + rot[:, 2, 2]
    return _ratios(np.abs(t_tr - m[:, :3, 3]), two_sin, trace, info)


def _ratios(d: F64, two_sin: F64, trace: F64, info: F64) -> tuple[F64, F64]:
    """Ratios from per-axis translation deviations `d` (L, 3), the rotation errors R = Mᵀ T
    as 2 sin θ (the norm of R − Rᵀ's axis vector) and trace(R) = 1 + 2 cos θ, and information
    diagonals (L, 6)."""
    lin_info = np.where(info[:, :3] > _INFO_IGNORED, info[:, :3], np.inf)
    ang_info = np.where(info[:, 3:] > _INFO_IGNORED, info[:, 3:], np.inf)
    # σ floored as the incremental graph floors link variances, so the check judges the
    # optimum by the noise it was computed with; minima and maxima over the three columns
    # element-wise (the values of `.min(axis=1)`, without its per-row reduction cost)
    lin_sigma = np.sqrt(np.maximum(1.0 / _min3(lin_info), _MIN_VARIANCE))
    ang_sigma = np.sqrt(np.maximum(1.0 / _min3(ang_info), _MIN_VARIANCE))
    lin_d = np.where(np.isfinite(lin_info), d, 0.0)
    lin = np.maximum(np.maximum(lin_d[:, 0], lin_d[:, 1]), lin_d[:, 2])
    # θ = atan2(2 sin θ, 2 cos θ): arccos of the trace alone cannot resolve angles below
    # ~2e-8 rad, so two exact formulas for the same link disagreed
    ang = np.arctan2(two_sin, trace - 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lin_ratio = np.where(lin_sigma > 0, lin / lin_sigma, 0.0)
        ang_ratio = np.where(ang_sigma > 0, ang / ang_sigma, 0.0)
    return lin_ratio, ang_ratio


def _min3(a: F64) -> F64:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])
