"""SE(2) pose graph on GTSAM: incremental (iSAM2) or batch (Levenberg–Marquardt).

Nodes are integer ids 0..N-1 holding poses (x, y, theta) in the map frame; edges are relative
measurements ``z = inv(x_i) ∘ x_j`` with a 3×3 covariance (x, y, theta order, GTSAM's Pose2
tangent order). Node 0 is anchored by a tight prior. Loop-closure edges can carry a robust
kernel (Huber, Cauchy or DCS) so that a false closure cannot drag the trajectory far: its
weight falls as its residual grows. The graph knows nothing about scans, so the RGB-D SLAM
reuses it unchanged.

``half_chi2`` reports ½ Σ eᵀ Ω e with every kernel removed (the figure the g2o benchmarks
quote), whatever optimiser produced the estimate.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt

__all__ = ["Edge", "EdgeKind", "PoseGraph"]

FloatArray = npt.NDArray[np.float64]

_PRIOR_SIGMAS = np.array([1e-4, 1e-4, 1e-5])


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
    w, v = np.linalg.eigh(c)
    w = np.clip(w, 1e-12, None)
    return np.asarray((v * w) @ v.T)


class PoseGraph:
    """An SE(2) pose graph with incremental or batch optimisation.

    ``optimizer`` is ``"isam2"`` (each `optimize` call folds the new nodes and edges into
    iSAM2; after a loop closure it relinearises a few extra rounds) or
    ``"levenberg_marquardt"`` (each call re-solves the whole graph from the current estimate).
    ``robust_kernel`` applies to edges added with ``robust=True``.
    """

    def __init__(
        self,
        *,
        optimizer: str = "isam2",
        robust_kernel: str = "cauchy",
        kernel_width: float = 1.0,
    ) -> None:
        if optimizer not in ("isam2", "levenberg_marquardt"):
            raise ValueError(
                f"optimizer must be 'isam2' or 'levenberg_marquardt', got {optimizer!r}"
            )
        if robust_kernel not in ("none", "huber", "cauchy", "dcs"):
            raise ValueError(f"unknown robust kernel {robust_kernel!r}")
        self.optimizer = optimizer
        self.robust_kernel = robust_kernel
        self.kernel_width = float(kernel_width)
        self._poses: list[FloatArray] = []
        self._edges: list[Edge] = []
        self._adjacency: list[set[int]] = []
        self._pending_nodes: list[int] = []
        self._pending_edges: list[Edge] = []
        self._needs_full_solve = False
        self._isam_broken = False
        self.isam_recoveries = 0
        """How often an iSAM2 update failed and was replaced by a batch solve."""
        self._isam: gtsam.ISAM2 | None = None
        self._reset_isam()

    # ------------------------------------------------------------------ building
    def _reset_isam(self) -> None:
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(0.01)
        params.relinearizeSkip = 1
        self._isam = gtsam.ISAM2(params)
        self._pending_nodes = list(range(len(self._poses)))
        self._pending_edges = list(self._edges)

    def add_node(self, pose: npt.ArrayLike) -> int:
        """Add a node with an initial estimate (map frame); returns its id."""
        p = np.asarray(pose, dtype=np.float64).reshape(3).copy()
        self._poses.append(p)
        self._adjacency.append(set())
        idx = len(self._poses) - 1
        self._pending_nodes.append(idx)
        return idx

    def add_edge(
        self,
        i: int,
        j: int,
        measurement: npt.ArrayLike,
        covariance: npt.ArrayLike,
        *,
        kind: EdgeKind = EdgeKind.SCAN_MATCH,
        robust: bool = False,
    ) -> Edge:
        """Add a relative-pose edge ``inv(x_i) ∘ x_j ≈ measurement``."""
        n = len(self._poses)
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"edge ({i}, {j}) needs two distinct existing nodes (have {n})")
        edge = Edge(
            int(i),
            int(j),
            np.asarray(measurement, dtype=np.float64).reshape(3).copy(),
            _sanitize_covariance(covariance),
            EdgeKind(kind),
            bool(robust),
        )
        self._edges.append(edge)
        self._adjacency[i].add(j)
        self._adjacency[j].add(i)
        self._pending_edges.append(edge)
        if kind is EdgeKind.LOOP:
            self._needs_full_solve = True
        return edge

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return len(self._poses)

    @property
    def poses(self) -> FloatArray:
        """Current estimates (N, 3), map frame."""
        if not self._poses:
            return np.zeros((0, 3))
        return np.array(self._poses)

    def pose(self, idx: int) -> FloatArray:
        """Current estimate of one node."""
        return self._poses[idx].copy()

    @property
    def edges(self) -> list[Edge]:
        """Every edge, in insertion order."""
        return list(self._edges)

    def neighbours(self, idx: int) -> set[int]:
        """Nodes sharing an edge with ``idx``."""
        return set(self._adjacency[idx])

    # ------------------------------------------------------------------ factors
    def _noise(self, edge: Edge, width: float | None = None) -> gtsam.noiseModel.Base:
        base = gtsam.noiseModel.Gaussian.Covariance(edge.covariance)
        if not edge.robust or self.robust_kernel == "none":
            return base
        k = self.kernel_width if width is None else width
        est = gtsam.noiseModel.mEstimator
        factory: Any = {"huber": est.Huber, "cauchy": est.Cauchy, "dcs": est.DCS}[
            self.robust_kernel
        ]
        kernel = factory.Create(k)
        return gtsam.noiseModel.Robust.Create(kernel, base)

    def _factor(self, edge: Edge, *, robust: bool = True) -> gtsam.BetweenFactorPose2:
        noise = (
            self._noise(edge) if robust else gtsam.noiseModel.Gaussian.Covariance(edge.covariance)
        )
        return gtsam.BetweenFactorPose2(edge.i, edge.j, _pose2(edge.measurement), noise)

    def _prior(self) -> gtsam.PriorFactorPose2:
        return gtsam.PriorFactorPose2(
            0, _pose2(self._poses[0]), gtsam.noiseModel.Diagonal.Sigmas(_PRIOR_SIGMAS)
        )

    def _graph(
        self, edges: Iterable[Edge], *, robust: bool = True, prior: bool = True
    ) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        if prior and self._poses:
            graph.add(self._prior())
        for e in edges:
            graph.add(self._factor(e, robust=robust))
        return graph

    def _values(self, nodes: Iterable[int]) -> gtsam.Values:
        values = gtsam.Values()
        for k in nodes:
            values.insert(k, _pose2(self._poses[k]))
        return values

    def _store(self, estimate: gtsam.Values) -> None:
        arr = gtsam.utilities.extractPose2(estimate)
        keys = list(estimate.keys())
        for k, row in zip(keys, arr):
            self._poses[int(k)] = np.array(row, dtype=np.float64)

    # ------------------------------------------------------------------ solving
    def optimize(self, *, full: bool | None = None) -> bool:
        """Fold pending nodes/edges into the estimate; returns True if it ran.

        With iSAM2, a graph that received a loop edge since the last call gets extra
        relinearisation rounds (or ``full=True`` asks for them). With Levenberg–Marquardt
        the whole graph is re-solved when anything is pending.
        """
        if not self._poses:
            return False
        loop = self._needs_full_solve if full is None else full
        if not self._pending_nodes and not self._pending_edges and not loop:
            return False
        if self.optimizer == "levenberg_marquardt" or self._isam_broken:
            self._solve_batch()
        else:
            try:
                self._solve_isam(loop)
            except RuntimeError:
                # GTSAM reports an ill-conditioned incremental update (e.g. a loop edge far
                # from the current linearisation) as IndeterminateSystemException: re-solve in
                # batch and restart iSAM2 from that optimum; if even that fails, stay batch.
                self._solve_batch()
                self.isam_recoveries += 1
                try:
                    self._reset_isam()
                    self._solve_isam(False)
                except RuntimeError:
                    self._isam_broken = True
        self._pending_nodes = []
        self._pending_edges = []
        self._needs_full_solve = False
        return True

    def _solve_isam(self, loop: bool) -> None:
        assert self._isam is not None
        graph = gtsam.NonlinearFactorGraph()
        if 0 in self._pending_nodes:
            graph.add(self._prior())
        for e in self._pending_edges:
            graph.add(self._factor(e))
        values = self._values(self._pending_nodes)
        self._isam.update(graph, values)
        for _ in range(4 if loop else 0):
            self._isam.update()
        self._store(self._isam.calculateEstimate())

    def _solve_batch(self) -> None:
        """Levenberg–Marquardt on the whole graph; with robust edges, the kernel is annealed.

        Robust kernels need a start near the answer: from a poor initial guess (e.g. chained
        odometry) true loop closures look like outliers too. So the kernel width starts wide
        (1000σ, nearly least squares) and shrinks by 10× per solve down to ``kernel_width``,
        each solve starting from the last (graduated non-convexity in its simplest form).
        """
        robust = self.robust_kernel != "none" and any(e.robust for e in self._edges)
        widths = [self.kernel_width]
        if robust:
            widths = [w for w in (1000.0, 100.0, 10.0) if w > self.kernel_width] + widths
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        params.setRelativeErrorTol(1e-6)
        params.setAbsoluteErrorTol(1e-6)
        for width in widths:
            graph = gtsam.NonlinearFactorGraph()
            graph.add(self._prior())
            for e in self._edges:
                graph.add(
                    gtsam.BetweenFactorPose2(e.i, e.j, _pose2(e.measurement), self._noise(e, width))
                )
            values = self._values(range(len(self._poses)))
            self._store(gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize())

    def optimize_batch(self) -> None:
        """Re-solve the whole graph with Levenberg–Marquardt (kernels annealed) from the current
        estimate, then restart iSAM2 from the result."""
        if not self._poses:
            return
        self._solve_batch()
        if self.optimizer == "isam2":
            self._reset_isam()
            self._solve_isam(False)
            self._pending_nodes = []
            self._pending_edges = []

    def half_chi2(self) -> float:
        """½ Σ eᵀ Ω e over all edges at the current estimate, without kernels or prior."""
        if not self._poses:
            return 0.0
        graph = self._graph(self._edges, robust=False, prior=False)
        return float(graph.error(self._values(range(len(self._poses)))))

    def set_poses(self, poses: npt.ArrayLike) -> None:
        """Replace every estimate (e.g. after loading a session) and restart iSAM2 from them."""
        arr = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if arr.shape[0] != len(self._poses):
            raise ValueError(f"{arr.shape[0]} poses for {len(self._poses)} nodes")
        self._poses = [row.copy() for row in arr]
        self._reset_isam()
