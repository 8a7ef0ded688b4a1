"""The pose graph's state: nodes and edges, their GTSAM factors, and queries on the estimate.

`PoseGraph` (``graph.py``) adds the χ² gate (``gate.py``) and the solvers on top.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from collections.abc import Set as AbstractSet
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt

from eddiebot.slam.pose_graph.edges import (
    _PRIOR_SIGMAS,
    FACTORIZATIONS,
    Edge,
    EdgeKind,
    FloatArray,
    _pose2,
    _sanitize_covariance,
    chi2_quantile,
)


class PoseGraphCore:
    """Nodes, edges, GTSAM factors and the estimate; the options are `PoseGraph`'s."""

    def __init__(
        self,
        *,
        optimizer: str = "isam2",
        robust_kernel: str = "cauchy",
        kernel_width: float = 1.0,
        gate_probability: float | None = 0.999,
        require_support: bool = True,
        support_window: int = 30,
        isolated_false_pass: float | None = 0.005,
        false_loop_extent: tuple[float, float, float] = (3.0, 3.0, math.pi),
        retest_interval: int = 50,
        max_retests: int = 2,
        factorization: str = "qr",
        relinearize_skip: int = 1,
        recent_last: int = 0,
        wildfire_threshold: float = 0.001,
    ) -> None:
        if optimizer not in ("isam2", "levenberg_marquardt"):
            raise ValueError(
                f"optimizer must be 'isam2' or 'levenberg_marquardt', got {optimizer!r}"
            )
        if robust_kernel not in ("none", "huber", "cauchy", "dcs"):
            raise ValueError(f"unknown robust kernel {robust_kernel!r}")
        if gate_probability is not None and not 0.0 < gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1) or None, got {gate_probability}")
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization must be one of {FACTORIZATIONS}, got {factorization!r}")
        if int(relinearize_skip) < 1:
            raise ValueError(f"relinearize_skip must be >= 1, got {relinearize_skip}")
        if int(recent_last) < 0:
            raise ValueError(f"recent_last must be >= 0, got {recent_last}")
        if not (math.isfinite(wildfire_threshold) and wildfire_threshold >= 0.0):
            raise ValueError(f"wildfire_threshold must be a finite value >= 0, got {wildfire_threshold}")
        self.optimizer = optimizer
        self.factorization = factorization
        """iSAM2's elimination: ``qr`` or ``cholesky`` (falls back to ``qr`` for good when an
        update reports an indeterminate system)."""
        self.relinearize_skip = int(relinearize_skip)
        self.recent_last = int(recent_last)
        """iSAM2 orders the newest ``recent_last`` nodes last in every update, so they stay at
        the root of the Bayes tree (0: GTSAM's default, the keys of the new factors last)."""
        self.wildfire_threshold = float(wildfire_threshold)
        """iSAM2's back-substitution stops below a clique whose solution moved less than this
        (GTSAM's default 0.001); 0 solves every variable on each update."""
        self.robust_kernel = robust_kernel
        self.kernel_width = float(kernel_width)
        self.gate_probability = gate_probability
        self._gate = None if gate_probability is None else chi2_quantile(gate_probability)
        self._innovation_gate: float | None = None  # the final pass's family-wise gate
        self.require_support = bool(require_support)
        self.support_window = int(support_window)
        if isolated_false_pass is not None and not 0.0 < isolated_false_pass < 1.0:
            raise ValueError(
                f"isolated_false_pass must be in (0, 1) or None, got {isolated_false_pass}"
            )
        self.isolated_false_pass = isolated_false_pass
        ext = np.asarray(false_loop_extent, dtype=np.float64).reshape(3)
        if np.any(ext <= 0.0):
            raise ValueError(f"false_loop_extent must be positive, got {false_loop_extent}")
        self.false_loop_extent = (float(ext[0]), float(ext[1]), float(ext[2]))
        self.retest_interval = int(retest_interval)
        self.max_retests = int(max_retests)
        # with the gate on, an accepted edge keeps full weight anywhere inside the gate
        self._accept_width = self.kernel_width
        if self._gate is not None:
            gate_width = self._gate if robust_kernel == "dcs" else float(np.sqrt(self._gate))
            self._accept_width = max(self.kernel_width, gate_width)
        self._p = np.zeros((16, 3))
        self._n = 0
        self._stale = False  # iSAM2 holds a newer estimate than _p (fetched on demand)
        self._edges: list[Edge] = []
        self._adjacency: list[set[int]] = []
        self._removed: set[int] = set()  # marginalised nodes (`PoseGraph.marginalize`)
        self._dropped: set[int] = set()  # their edges, replaced by marginal edges
        self._rejected: set[int] = set()
        self._held: list[int] = []
        self._trusted: set[int] = set()
        self._closures: dict[int, list[int]] = {}  # accepted loop edges: later end -> earlier ends
        self._dormant: dict[int, set[int]] = {}  # rejected robust edges by later end
        self._due: set[int] = set()  # rejected edges a new closure nearby sends back to the gate
        # pooled edge -> (eᵀe, innovation statistic, node count) when it was last gated
        self._tested: dict[int, tuple[float, float, int]] = {}
        self._info_cache: dict[int, FloatArray] = {}
        self._last_retest = 0  # node count at the last periodic pool re-test
        self._pending_nodes: list[int] = []
        self._pending_edges: list[int] = []
        self._needs_full_solve = False
        self._solved = False
        self._isam_broken = False
        self.isam_recoveries = 0
        """How often an iSAM2 update failed and was replaced by a batch solve."""
        self.factorization_fallbacks = 0
        """Cholesky iSAM2 updates that failed and switched this graph to QR."""
        self.variables_reeliminated = 0
        """Variables iSAM2 re-eliminated, summed over the updates that added factors."""
        self.gate_tests = 0
        """Robust edges tested by the χ² gate."""
        self.marginal_queries = 0
        """Gate tests that needed the joint marginal covariance (residual above the gate)."""
        self.late_accepts = 0
        """Robust edges accepted after being held or rejected (deferred acceptance)."""
        self._isam: gtsam.ISAM2 | None = None
        self._isam_keys: set[int] = set()
        self._reset_isam()

    # ------------------------------------------------------------------ building
    def _reset_isam(self) -> None:
        self._sync()
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(0.01)
        params.relinearizeSkip = self.relinearize_skip
        params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(self.wildfire_threshold))
        # Cholesky eliminates the normal equations (about half QR's time per update on the
        # simulated routes) but squares their conditioning: a loop closure with a near-singular
        # information matrix (as g2o graphs carry) can make it report an indeterminate system,
        # after which `optimize` re-solves in batch and this graph stays on QR
        params.setFactorization(self.factorization.upper())
        self._isam = gtsam.ISAM2(params)
        self._isam_keys = set()
        self._pending_nodes = [k for k in range(self._n) if k not in self._removed]
        self._pending_edges = [k for k in range(len(self._edges)) if k not in self._dropped]

    def add_node(self, pose: npt.ArrayLike) -> int:
        """Add a node with an initial estimate (map frame); returns its id."""
        p = np.asarray(pose, dtype=np.float64).reshape(3)
        if self._n == len(self._p):
            self._p = np.concatenate([self._p, np.zeros_like(self._p)])
        self._p[self._n] = p
        self._n += 1
        self._adjacency.append(set())
        idx = self._n - 1
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
        n = self._n
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"edge ({i}, {j}) needs two distinct existing nodes (have {n})")
        if i in self._removed or j in self._removed:
            raise ValueError(f"edge ({i}, {j}) touches a marginalised node")
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
        self._pending_edges.append(len(self._edges) - 1)
        if kind is EdgeKind.LOOP:
            self._needs_full_solve = True
        return edge

    # ------------------------------------------------------------------ queries
    def __len__(self) -> int:
        return self._n

    @property
    def poses(self) -> FloatArray:
        """Current estimates (N, 3), map frame."""
        self._sync()
        return self._p[: self._n].copy()

    def pose(self, idx: int) -> FloatArray:
        """Current estimate of one node."""
        if not 0 <= idx < self._n:
            raise IndexError(f"node {idx} out of range (have {self._n})")
        return self._current(idx)

    def _current(self, idx: int) -> FloatArray:
        if self._stale and idx in self._isam_keys:
            assert self._isam is not None
            p = self._isam.calculateEstimatePose2(idx)
            return np.array([p.x(), p.y(), p.theta()])
        return self._p[idx].copy()

    def _sync(self) -> None:
        """Copy iSAM2's current estimate into ``_p`` (one pass over every variable)."""
        if not self._stale:
            return
        self._stale = False
        assert self._isam is not None
        if self._isam_keys:
            self._store(self._isam.calculateEstimate(), len(self._isam_keys) == self._n)

    @property
    def edges(self) -> list[Edge]:
        """Every edge, in insertion order (rejected and marginalised ones included)."""
        return list(self._edges)

    @property
    def removed_nodes(self) -> list[int]:
        """Nodes marginalised out (`PoseGraph.marginalize`): their pose is frozen where it
        was, they have no edges, and no edge can be added to them."""
        return sorted(self._removed)

    @property
    def removed_edges(self) -> list[int]:
        """Indices into `edges` of the edges marginalised nodes took with them."""
        return sorted(self._dropped)

    @property
    def live_nodes(self) -> int:
        """Nodes in the graph that were not marginalised."""
        return self._n - len(self._removed)

    @property
    def rejected(self) -> list[int]:
        """Indices into `edges` of the robust edges the gate left out of the estimate."""
        return sorted(self._rejected)

    @property
    def held(self) -> list[int]:
        """Indices into `edges` of surprising edges waiting for a consistent partner."""
        return list(self._held)

    def neighbours(self, idx: int) -> set[int]:
        """Nodes sharing an edge with ``idx``."""
        return set(self._adjacency[idx])

    def adjacent(self, idx: int) -> AbstractSet[int]:
        """`neighbours` without the copy: the graph's own set, valid until the next edge."""
        return self._adjacency[idx]

    # ------------------------------------------------------------------ factors
    def _noise(self, edge: Edge, width: float | None = None) -> gtsam.noiseModel.Base:
        base = gtsam.noiseModel.Gaussian.Covariance(edge.covariance)
        if not edge.robust or self.robust_kernel == "none":
            return base
        k = self._accept_width if width is None else width
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
            0, _pose2(self._p[0]), gtsam.noiseModel.Diagonal.Sigmas(_PRIOR_SIGMAS)
        )

    def _graph(
        self, edges: Iterable[Edge], *, robust: bool = True, prior: bool = True
    ) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        if prior and self._n:
            graph.add(self._prior())
        for e in edges:
            graph.add(self._factor(e, robust=robust))
        return graph

    def _values(self, nodes: Iterable[int]) -> gtsam.Values:
        values = gtsam.Values()
        for k in nodes:
            if k not in self._removed:
                values.insert(k, _pose2(self._p[k]))
        return values

    def _store(self, estimate: gtsam.Values, contiguous: bool = False) -> None:
        arr = gtsam.utilities.extractPose2(estimate)
        if contiguous and len(arr) == self._n:
            self._p[: self._n] = arr
            return
        keys = np.array(list(estimate.keys()), dtype=np.int64)
        self._p[keys] = arr

    def _is_out(self, k: int) -> bool:
        return k in self._rejected or k in self._held or k in self._dropped

    def _inliers(self) -> list[Edge]:
        return [e for k, e in enumerate(self._edges) if not self._is_out(k)]

    def _edge_factor(self, k: int) -> gtsam.BetweenFactorPose2:
        """An accepted edge's factor: its kernel, or Huber at the gate if confirmed by support."""
        edge = self._edges[k]
        if k not in self._trusted or self._gate is None:
            return self._factor(edge)
        # a confirmed surprising edge: Huber at the gate, bounded pull until it is absorbed
        kernel = gtsam.noiseModel.mEstimator.Huber.Create(float(np.sqrt(self._gate)))
        base = gtsam.noiseModel.Gaussian.Covariance(edge.covariance)
        noise = gtsam.noiseModel.Robust.Create(kernel, base)
        return gtsam.BetweenFactorPose2(edge.i, edge.j, _pose2(edge.measurement), noise)

    def _inlier_graph(self) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        graph.add(self._prior())
        for k in range(len(self._edges)):
            if not self._is_out(k):
                graph.add(self._edge_factor(k))
        return graph
