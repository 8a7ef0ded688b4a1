"""SE(2) pose graph on GTSAM: incremental (iSAM2) or batch (Levenberg–Marquardt).

Nodes are integer ids 0..N-1 holding poses (x, y, theta) in the map frame; edges are relative
measurements ``z = inv(x_i) ∘ x_j`` with a 3×3 covariance (x, y, theta order, GTSAM's Pose2
tangent order). Node 0 is anchored by a tight prior. The graph knows nothing about scans, so
the RGB-D SLAM reuses it unchanged.

False loop closures are handled on edges added with ``robust=True`` (the loop closures), in
three steps, each edge tested when it arrives, against the estimate of the graph so far:

1. **Residual on its own covariance.** An edge whose whitened residual ``eᵀe`` at the current
   estimate is within ``χ²₃(gate_probability)`` agrees with the graph as it is: accepted.
2. **χ² gate on the innovation.** Otherwise, with ``A`` the whitened Jacobian over both poses
   and ``S`` their joint marginal covariance (from iSAM2's Bayes tree, or batch marginals with
   Levenberg–Marquardt), the edge is rejected when ``eᵀ (I + A S Aᵀ)⁻¹ e > χ²₃(p)``: even the
   graph's own uncertainty cannot explain it. Since ``I + A S Aᵀ ⪰ I``, step 1 never rejects
   what this test would accept, and only surprising edges pay for the marginal.
3. **Support** (``require_support``, default on). A surprising edge that passes the gate is one
   the graph cannot yet confirm: a long drift, or covariances too loose for the gate to mean
   much. It is taken when its gate is narrow — a false match spread uniformly over
   ±``false_loop_extent`` (x, y, θ) would land inside the gate ellipsoid with probability at
   most ``isolated_false_pass`` — or when another loop closes the same place: an accepted loop
   edge with both ends within ``support_window`` nodes of its own, or a held one with which it
   passes the joint test (the conditional innovation of one given the other within the gate;
   pairwise consistency as in PCM), the "consistent over consecutive detections" check of
   visual loop closing. Until then it is held (`held`).

**No verdict is final (deferred acceptance).** Held and rejected edges stay in a pool. Whenever
the estimate moves materially (a surprising edge was accepted) or every ``retest_interval``
nodes, each pooled edge's residual is recomputed at the current estimate (vectorised, no
marginal): one now within the gate on its own covariance is accepted outright; a rejected one
whose residual shrank enough that its innovation statistic, scaled alike, would pass, and a held
one whose residual halved or doubled or that waited ``retest_interval`` nodes, goes through
steps 2–3 again (at most ``max_retests`` per update, as each needs a marginal). A rejected edge
also goes back through the gate when a loop accepted later closes the same place.
`reconsider` is the final consistency pass: every pooled edge re-tested until nothing changes,
then a Levenberg–Marquardt polish of the accepted edges.

Edges accepted in step 3 carry a Huber kernel at the gate (√χ²₃(p) σ): their residual is large
until the graph absorbs them, and Huber pulls with bounded force rather than ignoring them as a
redescending kernel would. The rest carry ``robust_kernel`` with its width raised to the gate,
so that a vetted edge keeps full weight while it agrees with the graph. Rejected edges stay in
`edges` (listed by `rejected`).

A graph solved in one go from its initial guess (e.g. a g2o file initialised by chained
odometry) has no estimate to test against: ``optimize`` then sweeps it node by node through the
same gated iSAM2 path in node order (node k placed from a non-robust edge to an earlier node)
and polishes the result with Levenberg–Marquardt on the accepted edges. ``gate_probability=None``
turns all this off: the kernel alone (in batch annealed from 1000σ down to ``kernel_width``).

``half_chi2`` reports ½ Σ eᵀ Ω e with every kernel removed (the figure the g2o benchmarks
quote), whatever optimiser produced the estimate.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterable, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
import numpy.typing as npt
from scipy.special import gammaincinv

from eddiebot.geometry import se2_between

__all__ = ["FACTORIZATIONS", "Edge", "EdgeKind", "PoseGraph"]

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


class PoseGraph:
    """An SE(2) pose graph with incremental or batch optimisation.

    ``optimizer`` is ``"isam2"`` (each `optimize` call folds the new nodes and edges into
    iSAM2; after a loop closure it relinearises until nothing moves, at most 4 extra rounds) or
    ``"levenberg_marquardt"`` (each call re-solves the whole graph from the current estimate).
    ``robust_kernel``, the χ² gate (``gate_probability``; None disables it), the support
    rule (``require_support``, ``support_window`` in nodes), the narrow-gate rule
    (``isolated_false_pass`` over ±``false_loop_extent``; None disables it) and the re-tests of
    held and rejected edges (``retest_interval`` nodes, ``max_retests`` per update) apply to
    edges added with ``robust=True``; see the module docstring and `reconsider`.
    """

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
        self._pending_nodes = list(range(self._n))
        self._pending_edges = list(range(len(self._edges)))

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
        """Every edge, in insertion order (rejected ones included)."""
        return list(self._edges)

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
        return k in self._rejected or k in self._held

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

    # ------------------------------------------------------------------ gate
    def _linearized(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Whitened Jacobian (3×6 over poses i, j) and residual of edge k at the estimate."""
        e = self._edges[k]
        factor = gtsam.BetweenFactorPose2(
            e.i, e.j, _pose2(e.measurement), gtsam.noiseModel.Gaussian.Covariance(e.covariance)
        )
        values = gtsam.Values()
        values.insert(e.i, _pose2(self._current(e.i)))
        values.insert(e.j, _pose2(self._current(e.j)))
        a, b = factor.linearize(values).jacobian()
        return np.asarray(a), np.asarray(b)

    def _innovation(self, ks: Sequence[int], marginal: Any) -> tuple[FloatArray, FloatArray]:
        """Stacked whitened residual of edges ``ks`` and its covariance I + A S Aᵀ."""
        keys = list(dict.fromkeys(v for k in ks for v in (self._edges[k].i, self._edges[k].j)))
        col = {key: 3 * c for c, key in enumerate(keys)}
        a_all = np.zeros((3 * len(ks), 3 * len(keys)))
        b_all = np.zeros(3 * len(ks))
        for r, k in enumerate(ks):
            a, b = self._linearized(k)
            e = self._edges[k]
            a_all[3 * r : 3 * r + 3, col[e.i] : col[e.i] + 3] += a[:, :3]
            a_all[3 * r : 3 * r + 3, col[e.j] : col[e.j] + 3] += a[:, 3:]
            b_all[3 * r : 3 * r + 3] = b
        cov = marginal(keys)
        return b_all, np.eye(len(b_all)) + a_all @ cov @ a_all.T

    def _gate_edges(self, candidates: Sequence[int], marginal: Any) -> tuple[list[int], bool]:
        """Split robust edges into accepted ones (returned), held and rejected ones (recorded).

        ``marginal(keys)`` gives the joint covariance of those poses at the current estimate.
        The second return value says whether any accepted edge was surprising (residual beyond
        the gate on its own covariance), i.e. worth extra relinearisation rounds.
        """
        assert self._gate is not None
        gate = self._gate
        accepted: list[int] = []
        surprising = False
        # held edges a closure accepted since has come to support get another test, and so do
        # rejected ones it closes the same place as
        retry = [h for h in self._held if self._supported(h)]
        self._held = [h for h in self._held if h not in retry]
        for k in sorted(self._due):
            self._dormant.get(self._last_end(k), set()).discard(k)
            retry.append(k)
        self._due = set()
        for k in dict.fromkeys([*retry, *candidates]):
            if k in accepted:
                continue
            self.gate_tests += 1
            self._rejected.discard(k)
            _, b = self._linearized(k)
            r2 = float(b @ b)
            if r2 <= gate:
                accepted.append(k)
                continue
            self.marginal_queries += 1
            b, c = self._innovation([k], marginal)
            stat = float(b @ np.linalg.solve(c, b))
            if stat > (self._innovation_gate or gate):
                self._reject(k)
                self._tested[k] = (r2, stat, self._n)
                continue
            partner = -1
            if self.require_support and not self._supported(k) and not self._selective(k, c):
                ek = self._edges[k]
                for h in reversed(self._held):
                    eh = self._edges[h]
                    if (
                        abs(min(eh.i, eh.j) - min(ek.i, ek.j)) > self.support_window
                        or abs(max(eh.i, eh.j) - max(ek.i, ek.j)) > self.support_window
                    ):
                        continue
                    # does k still fit once h is in? (conditional innovation, 3 dof)
                    self.marginal_queries += 1
                    b2, c2 = self._innovation([h, k], marginal)
                    joint = float(b2 @ np.linalg.solve(c2, b2))
                    alone = float(b2[:3] @ np.linalg.solve(c2[:3, :3], b2[:3]))
                    if joint - alone <= gate and alone <= gate:
                        partner = h
                        break
                if partner < 0:
                    # held in the pool until support arrives or the estimate decides it
                    self._held.append(k)
                    self._tested[k] = (r2, stat, self._n)
                    continue
                self._held.remove(partner)
                accepted.append(partner)
                self._trusted.add(partner)
            accepted.append(k)
            self._trusted.add(k)
            surprising = True
        for k in accepted:
            if self._tested.pop(k, None) is not None:
                self.late_accepts += 1
            self._note_closure(k)
        return accepted, surprising

    def _selective(self, k: int, innovation_cov: FloatArray) -> bool:
        """Whether edge k's gate is narrow enough to take it without a partner: a false match
        spread uniformly over ±``false_loop_extent`` would fall inside it with probability at
        most ``isolated_false_pass``.

        The gate is the ellipsoid eᵀ C⁻¹ e ≤ γ of the innovation, C = Σ^½ (I + A S Aᵀ) Σ^½ in
        metric units (Σ the edge covariance); its volume is (4/3)π γ^{3/2} √det C.
        """
        if self.isolated_false_pass is None or self._gate is None:
            return False
        det = float(np.linalg.det(self._edges[k].covariance) * np.linalg.det(innovation_cov))
        volume = 4.0 / 3.0 * math.pi * self._gate**1.5 * math.sqrt(max(det, 0.0))
        ex, ey, et = self.false_loop_extent
        return volume <= self.isolated_false_pass * 8.0 * ex * ey * et

    def _pool_residuals(self, pool: Sequence[int]) -> FloatArray:
        """eᵀ Ω e of edges ``pool`` at the current estimate (vectorised; GTSAM's Pose2 Logmap
        error, as `_linearized`)."""
        ii = np.array([self._edges[k].i for k in pool])
        jj = np.array([self._edges[k].j for k in pool])
        if self._stale and len(pool) > 32:
            self._sync()
        if self._stale:
            xi = np.array([self._current(int(v)) for v in ii])
            xj = np.array([self._current(int(v)) for v in jj])
        else:
            xi, xj = self._p[ii], self._p[jj]
        z = np.array([self._edges[k].measurement for k in pool])
        info = np.array([self._information(k) for k in pool])
        d = se2_between(z, se2_between(xi, xj))
        t = np.arctan2(np.sin(d[:, 2]), np.cos(d[:, 2]))
        h = 0.5 * t
        small = np.abs(t) < 1e-6
        a = np.where(small, 1.0 - h * h / 3.0, h / np.tan(np.where(small, 1.0, h)))
        e = np.stack([a * d[:, 0] + h * d[:, 1], -h * d[:, 0] + a * d[:, 1], t], axis=-1)
        return np.asarray(np.einsum("ni,nij,nj->n", e, info, e))

    def _information(self, k: int) -> FloatArray:
        info = self._info_cache.get(k)
        if info is None:
            info = self._info_cache[k] = self._edges[k].information
        return info

    def _retest_pool(
        self, marginal: Any, limit: int | None, *, every_held: bool = False
    ) -> tuple[list[int], bool]:
        """Deferred acceptance: send held and rejected edges back through the gate against the
        current estimate.

        Each pooled edge's residual is recomputed (cheap, no marginal). An edge whose residual
        is now within the gate on its own covariance agrees with the graph and is accepted
        outright. A rejected one whose residual has shrunk so far that its innovation statistic,
        scaled alike, would now pass (the estimate moved its way), or a held one whose residual
        has halved or doubled or that was not tested for ``retest_interval`` nodes (its marginal
        has shrunk since), is gated afresh — at most ``limit`` of those per call, largest
        relative change first, since each needs the joint marginal.
        """
        assert self._gate is not None
        pool = sorted(self._rejected.union(self._held))
        if not pool:
            return [], False
        held = set(self._held)
        r2 = self._pool_residuals(pool)
        chosen: list[int] = []
        ranked: list[tuple[float, int]] = []
        for k, r in zip(pool, r2.tolist()):
            last, stat, at = self._tested.get(k, (math.inf, math.inf, -self.retest_interval))
            if r <= self._gate:
                chosen.append(k)
            elif k not in held:
                if stat * r <= (self._innovation_gate or self._gate) * last:
                    ranked.append((r / last, k))
            elif every_held or self._n - at >= self.retest_interval or not 0.5 <= r / last <= 2.0:
                ranked.append((min(r / last, last / r), k))
        ranked.sort()
        chosen += [k for _, k in (ranked if limit is None else ranked[:limit])]
        if not chosen:
            return [], False
        for k in chosen:
            self._rejected.discard(k)
            if k in held:
                self._held.remove(k)
            self._dormant.get(self._last_end(k), set()).discard(k)
        return self._gate_edges(chosen, marginal)

    def _last_end(self, k: int) -> int:
        return max(self._edges[k].i, self._edges[k].j)

    def _reject(self, k: int) -> None:
        self._rejected.add(k)
        self._dormant.setdefault(self._last_end(k), set()).add(k)

    def _note_closure(self, k: int) -> None:
        e, w = self._edges[k], self.support_window
        lo, hi = min(e.i, e.j), max(e.i, e.j)
        self._closures.setdefault(hi, []).append(lo)
        for last in range(hi - w, hi + w + 1):
            for r in self._dormant.get(last, ()):
                if abs(min(self._edges[r].i, self._edges[r].j) - lo) <= w:
                    self._due.add(r)

    def _supported(self, k: int) -> bool:
        """Whether an accepted loop edge closes the same place (both ends within
        ``support_window`` nodes of k's ends)."""
        e, w = self._edges[k], self.support_window
        lo, hi = min(e.i, e.j), max(e.i, e.j)
        for last in range(hi - w, hi + w + 1):
            for first in self._closures.get(last, ()):
                if abs(first - lo) <= w:
                    return True
        return False

    # ------------------------------------------------------------------ solving
    def optimize(self, *, full: bool | None = None) -> bool:
        """Fold pending nodes/edges into the estimate; returns True if it ran.

        With iSAM2, a graph that received a loop edge since the last call gets extra
        relinearisation rounds (or ``full=True`` asks for them). With Levenberg–Marquardt
        the whole graph is re-solved when anything is pending. Pending robust edges are
        gated first (see the module docstring).
        """
        if not self._n:
            return False
        loop = self._needs_full_solve if full is None else full
        if not self._pending_nodes and not self._pending_edges and not loop:
            return False
        if self.optimizer == "levenberg_marquardt" or self._isam_broken:
            self._optimize_lm()
        else:
            try:
                self._solve_isam(loop, forced=full is True)
            except RuntimeError:
                try:
                    self._sync()
                except RuntimeError:
                    self._stale = False
                # GTSAM reports an ill-conditioned incremental update (e.g. a loop edge far
                # from the current linearisation) as IndeterminateSystemException: re-solve in
                # batch and restart iSAM2 from that optimum; if even that fails, stay batch.
                self._pending_nodes, self._pending_edges = [], []
                self._store(self._lm(self._inlier_graph()))
                self.isam_recoveries += 1
                if self.factorization != "qr":
                    self.factorization = "qr"
                    self.factorization_fallbacks += 1
                try:
                    self._restart_isam()
                except RuntimeError:
                    self._isam_broken = True
        self._pending_nodes = []
        self._pending_edges = []
        self._needs_full_solve = False
        self._solved = True
        return True

    def _split_pending(self) -> tuple[list[int], list[int]]:
        """Pending edges for the first pass (non-robust, plus robust ones a new node depends
        on) and the robust ones to gate against its result."""
        if self._gate is None:
            return list(self._pending_edges), []
        first = [k for k in self._pending_edges if not self._edges[k].robust]
        covered = set(self._isam_keys) if self.optimizer == "isam2" else set()
        if self.optimizer != "isam2":
            covered.update(range(self._n))
            covered.difference_update(self._pending_nodes)
        covered.add(0)
        for k in first:
            covered.add(self._edges[k].i)
            covered.add(self._edges[k].j)
        gated = []
        for k in self._pending_edges:
            e = self._edges[k]
            if not e.robust:
                continue
            if e.i in covered and e.j in covered and (self._solved or self.optimizer == "isam2"):
                gated.append(k)
            else:
                # nothing to test it against: straight in, with its kernel
                first.append(k)
                covered.add(e.i)
                covered.add(e.j)
        return sorted(first), gated

    def _solve_isam(self, loop: bool, *, forced: bool = False) -> None:
        assert self._isam is not None
        isam = self._isam
        first, gated = self._split_pending()
        # extra rounds after an ungated loop edge, on request, or after a surprising gated one
        surprising = forced or any(self._edges[k].kind is EdgeKind.LOOP for k in first)
        graph = gtsam.NonlinearFactorGraph()
        if 0 in self._pending_nodes:
            graph.add(self._prior())
        for k in first:
            if not self._is_out(k):
                graph.add(self._edge_factor(k))
                if self._edges[k].kind is EdgeKind.LOOP:
                    self._note_closure(k)
        new = [n for n in self._pending_nodes if n not in self._isam_keys]
        self._isam_update(graph, self._values(new))
        self._isam_keys.update(new)
        self._stale = True

        def marginal(keys: list[int]) -> FloatArray:
            return _joint(isam.jointMarginalCovariance(keys), keys)

        if gated:
            accepted, surprised = self._gate_edges(gated, marginal)
            surprising |= surprised
            if accepted:
                graph = gtsam.NonlinearFactorGraph()
                for k in accepted:
                    graph.add(self._edge_factor(k))
                self._isam_update(graph, gtsam.Values())
        if loop and surprising:
            self._relinearize()
        if (
            self._gate is not None
            and (self._rejected or self._held)
            and (surprising or self._n - self._last_retest >= self.retest_interval)
        ):
            # the estimate has moved materially (or a while has passed): deferred acceptance
            self._last_retest = self._n
            accepted, surprised = self._retest_pool(marginal, self.max_retests)
            if accepted:
                graph = gtsam.NonlinearFactorGraph()
                for k in accepted:
                    graph.add(self._edge_factor(k))
                self._isam_update(graph, gtsam.Values())
                if surprised:
                    self._relinearize()

    def _isam_update(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        """One iSAM2 update with these factors and new variables.

        With ``recent_last`` the newest nodes are ordered last among the variables the update
        re-eliminates. GTSAM's default orders the keys of the new factors last: an odometry
        span edge's far end goes to the root, while the nodes between it and the newest float
        lower in the tree, and the next node's span edge then re-eliminates the path from one of
        them to the root (70-100 variables once loops have closed, against 15 with the window).
        """
        assert self._isam is not None
        if self.recent_last <= 0 or self._n == 0:
            result = self._isam.update(graph, values)
        else:
            groups = gtsam.KeyGroupMap()
            for k in range(max(0, self._n - self.recent_last), self._n):
                if k in self._isam_keys or values.exists(k):
                    groups.insert2(k, 1)
            params = gtsam.ISAM2UpdateParams()
            params.constrainedKeys = groups
            result = self._isam.update(graph, values, params)
        self.variables_reeliminated += int(result.getVariablesReeliminated())

    def _relinearize(self) -> None:
        """Extra iSAM2 rounds until nothing is relinearised (at most ``_EXTRA_ROUNDS``)."""
        assert self._isam is not None
        for _ in range(_EXTRA_ROUNDS):
            if not self._isam.update().getVariablesRelinearized():
                break

    def _optimize_lm(self) -> None:
        self._sync()
        if not self._solved or self._gate is None:
            self._solve_batch()
            return
        _, gated = self._split_pending()
        if gated:
            # solve without the new robust edges, gate them against that optimum, then re-solve
            fresh = set(gated)
            graph = gtsam.NonlinearFactorGraph()
            graph.add(self._prior())
            for k in range(len(self._edges)):
                if k not in fresh and not self._is_out(k):
                    graph.add(self._edge_factor(k))
            self._store(self._lm(graph))
            marginals = gtsam.Marginals(graph, self._values(range(self._n)))

            def marginal(keys: list[int]) -> FloatArray:
                return _joint(marginals.jointMarginalCovariance(keys), keys)

            self._gate_edges(gated, marginal)
        self._store(self._lm(self._inlier_graph()))

    def _lm(self, graph: gtsam.NonlinearFactorGraph) -> gtsam.Values:
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(100)
        params.setRelativeErrorTol(1e-6)
        params.setAbsoluteErrorTol(1e-6)
        values = self._values(range(self._n))
        return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()

    def _solve_batch(self) -> None:
        """The whole graph from the current estimate, deciding every robust edge afresh.

        With the gate on, a sweep (`_sweep`) decides the robust edges. With the gate off, or
        with no chain to sweep along, the robust kernel is annealed: its width starts wide
        (1000σ, nearly least squares) and shrinks by 10× per solve down to ``kernel_width``,
        each solve starting from the last.
        """
        robust = [k for k, e in enumerate(self._edges) if e.robust]
        if robust and self._gate is not None and self._sweep():
            return
        widths = [self.kernel_width]
        if robust and self.robust_kernel != "none":
            widths = [w for w in (1000.0, 100.0, 10.0) if w > self.kernel_width] + widths
        for width in widths:
            graph = gtsam.NonlinearFactorGraph()
            graph.add(self._prior())
            for e in self._edges:
                graph.add(
                    gtsam.BetweenFactorPose2(e.i, e.j, _pose2(e.measurement), self._noise(e, width))
                )
            self._store(self._lm(graph))

    def _sweep(self) -> bool:
        """Replay the graph node by node through a gated iSAM2 graph, then polish with
        Levenberg–Marquardt on the accepted edges.

        Node k is placed from its first non-robust edge to an earlier node; returns False (and
        does nothing) when some node has none, i.e. there is no chain to sweep along.
        """
        n = self._n
        anchor: list[int] = [-1] * n
        by_last: list[list[int]] = [[] for _ in range(n)]
        for k, e in enumerate(self._edges):
            last = max(e.i, e.j)
            by_last[last].append(k)
            if not e.robust and anchor[last] < 0:
                anchor[last] = k
        if any(a < 0 for a in anchor[1:]):
            return False
        sub = PoseGraph(
            optimizer="isam2",
            robust_kernel=self.robust_kernel,
            kernel_width=self.kernel_width,
            gate_probability=self.gate_probability,
            require_support=self.require_support,
            support_window=self.support_window,
            isolated_false_pass=self.isolated_false_pass,
            false_loop_extent=self.false_loop_extent,
            retest_interval=self.retest_interval,
            max_retests=self.max_retests,
            factorization=self.factorization,
            relinearize_skip=self.relinearize_skip,
            wildfire_threshold=self.wildfire_threshold,
        )
        order: list[int] = []
        for node in range(n):
            if node == 0:
                sub.add_node(self._p[0])
            else:
                e = self._edges[anchor[node]]
                z = _pose2(e.measurement)
                if e.j == node:
                    guess = _pose2(sub.pose(e.i)).compose(z)
                else:
                    guess = _pose2(sub.pose(e.j)).compose(z.inverse())
                sub.add_node([guess.x(), guess.y(), guess.theta()])
            for k in by_last[node]:
                e = self._edges[k]
                sub.add_edge(e.i, e.j, e.measurement, e.covariance, kind=e.kind, robust=e.robust)
                order.append(k)
            sub.optimize()
        self._p[:n] = sub.poses
        self._rejected = {order[k] for k in sub.rejected + sub.held}
        self._trusted = {order[k] for k in sub._trusted}
        self._tested = {order[k]: v for k, v in sub._tested.items()}
        self._held = []
        self._closures, self._dormant, self._due = {}, {}, set()
        for k, e in enumerate(self._edges):
            if k in self._rejected:
                self._dormant.setdefault(self._last_end(k), set()).add(k)
            elif e.robust or e.kind is EdgeKind.LOOP:
                self._closures.setdefault(max(e.i, e.j), []).append(min(e.i, e.j))
        self.gate_tests += sub.gate_tests
        self.marginal_queries += sub.marginal_queries
        self.late_accepts += sub.late_accepts
        self._store(self._lm(self._inlier_graph()))
        return True

    def reconsider(self, *, polish: bool = True) -> int:
        """Final consistency pass: fold in anything pending, then send the held and rejected
        robust edges back through the gate against the current estimate (every held one, and
        each rejected one whose residual has shrunk enough to pass), until none is accepted.
        With ``polish`` the accepted edges are then solved to convergence by
        Levenberg–Marquardt (iSAM2 restarted from the result): the incremental estimate only
        relinearises what moved more than its threshold.

        The live gate decides each loop on its own, so over a session of N loops it turns
        away about N·(1 − ``gate_probability``) true ones by chance (two on a graph with 2,000
        loops at 0.999). This pass, which sees the whole session, tests innovations against
        the family-wise (Bonferroni) gate χ²₃(1 − (1 − ``gate_probability``)/N) instead, N the
        number of robust edges; acceptance on the edge's own covariance, the narrow-gate and
        support rules are unchanged.

        Returns how many edges it accepted.
        """
        if self._gate is None or self.gate_probability is None or not self._n:
            return 0
        self.optimize()
        before = self.late_accepts
        n_robust = max(1, sum(1 for e in self._edges if e.robust))
        self._innovation_gate = chi2_quantile(1.0 - (1.0 - self.gate_probability) / n_robust)
        try:
            self._settle_pool()
        finally:
            self._innovation_gate = None
        if polish:
            self._sync()
            self._store(self._lm(self._inlier_graph()))
            if self.optimizer == "isam2" and not self._isam_broken:
                self._restart_isam()
        return self.late_accepts - before

    def _settle_pool(self) -> None:
        """Re-test the pool (every held edge) until nothing more is accepted."""
        for _ in range(8):
            if self.optimizer == "isam2" and not self._isam_broken:
                isam = self._isam
                assert isam is not None
                accepted, _ = self._retest_pool(_marginal_fn(isam), None, every_held=True)
                if not accepted:
                    break
                graph = gtsam.NonlinearFactorGraph()
                for k in accepted:
                    graph.add(self._edge_factor(k))
                self._isam_update(graph, gtsam.Values())
                self._stale = True
                self._relinearize()
            else:
                self._sync()
                inliers = self._inlier_graph()
                marginals = gtsam.Marginals(inliers, self._values(range(self._n)))
                accepted, _ = self._retest_pool(_marginal_fn(marginals), None, every_held=True)
                if not accepted:
                    break
                self._store(self._lm(self._inlier_graph()))

    def optimize_batch(self) -> None:
        """Re-solve the whole graph from the current estimate, deciding every robust edge
        afresh (a gated sweep with the gate on, an annealed kernel without), then restart
        iSAM2 from the result."""
        if not self._n:
            return
        self._sync()
        self._pending_nodes, self._pending_edges = [], []
        self._solve_batch()
        self._solved = True
        if self.optimizer == "isam2":
            self._restart_isam()

    def _restart_isam(self) -> None:
        """iSAM2 afresh from the current estimate with the accepted edges (no gating: the
        batch solve has just decided every edge)."""
        self._reset_isam()
        gate, self._gate = self._gate, None
        try:
            self._solve_isam(False)
        finally:
            self._gate = gate
        self._pending_nodes = []
        self._pending_edges = []

    def half_chi2(self, *, include_rejected: bool = True) -> float:
        """½ Σ eᵀ Ω e over all edges (or the accepted ones) at the current estimate, without
        kernels or prior."""
        if not self._n:
            return 0.0
        self._sync()
        edges = self._edges if include_rejected else self._inliers()
        graph = self._graph(edges, robust=False, prior=False)
        return float(graph.error(self._values(range(self._n))))

    def set_poses(self, poses: npt.ArrayLike) -> None:
        """Replace every estimate (e.g. after loading a session) and restart iSAM2 from them."""
        arr = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if arr.shape[0] != self._n:
            raise ValueError(f"{arr.shape[0]} poses for {self._n} nodes")
        self._stale = False
        self._p[: self._n] = arr
        self._rejected = set()
        self._held = []
        self._trusted = set()
        self._closures = {}
        self._dormant = {}
        self._due = set()
        self._tested = {}
        self._solved = True
        self._reset_isam()
