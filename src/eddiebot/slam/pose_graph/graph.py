"""`PoseGraph`: the gated pose graph with its solvers (iSAM2, Levenberg–Marquardt, the
node-by-node sweep and the final consistency pass)."""

from __future__ import annotations

from collections.abc import Iterable

import gtsam
import numpy as np
import numpy.typing as npt

from eddiebot.slam.pose_graph.edges import (
    _EXTRA_ROUNDS,
    EdgeKind,
    FloatArray,
    _joint,
    _marginal_fn,
    _pose2,
    chi2_quantile,
)
from eddiebot.slam.pose_graph.gate import GatedPoseGraph
from eddiebot.slam.pose_graph.marginal import marginal_edges


class PoseGraph(GatedPoseGraph):
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
        new = [
            n for n in self._pending_nodes if n not in self._isam_keys and n not in self._removed
        ]
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
            for k, e in enumerate(self._edges):
                if k in self._dropped:
                    continue
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
            if k in self._dropped:
                continue
            last = max(e.i, e.j)
            by_last[last].append(k)
            if not e.robust and anchor[last] < 0:
                anchor[last] = k
        if any(a < 0 for k, a in enumerate(anchor) if k and k not in self._removed):
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
            if node in self._removed:
                sub.add_node(self._p[node])
                sub._removed.add(node)  # a placeholder keeping the ids aligned
                continue
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
        edges = (
            [e for k, e in enumerate(self._edges) if k not in self._dropped]
            if include_rejected else self._inliers()
        )
        graph = self._graph(edges, robust=False, prior=False)
        return float(graph.error(self._values(range(self._n))))

    def marginalize(self, nodes: Iterable[int]) -> int:
        """Remove ``nodes`` from the graph, keeping what their edges said about the rest.

        Each node in turn (ascending) is linearised at the current estimate (robust edges with
        their kernel's weight there) and eliminated: its accepted edges are replaced by relative-pose edges between its neighbours
        carrying the Schur complement (`eddiebot.slam.pose_graph.marginal`: exact for a node
        with two neighbours, a chain sparsification beyond); its held and rejected edges go
        without replacement. The node keeps its last pose (`pose` still answers) but leaves
        the estimate, the solvers and `neighbours`. iSAM2 restarts once, from the current
        estimate, after the whole batch. Node 0 (the anchor) cannot be removed. Returns the
        number of edges added.
        """
        todo = sorted({int(k) for k in nodes} - self._removed)
        if not todo:
            return 0
        for k in todo:
            if not 0 < k < self._n:
                raise ValueError(f"cannot marginalise node {k} (have {self._n}; node 0 is the anchor)")
        self.optimize()
        self._sync()
        added = 0
        touching: dict[int, list[int]] = {}
        for k, e in enumerate(self._edges):
            if k not in self._dropped:
                touching.setdefault(e.i, []).append(k)
                touching.setdefault(e.j, []).append(k)
        for node in todo:
            ks = [k for k in touching.get(node, []) if k not in self._dropped]
            kept_ids = [k for k in ks if not self._is_out(k)]
            kept = [self._edges[k] for k in kept_ids]
            ends = {node} | {e.i for e in kept} | {e.j for e in kept}
            replacement = marginal_edges(
                node, kept, {n: self._p[n].copy() for n in ends},
                [self._edge_factor(k) for k in kept_ids],
            )
            for k in ks:
                self._drop_edge(k)
            for other in self._adjacency[node]:
                self._adjacency[other].discard(node)
            self._adjacency[node] = set()
            self._removed.add(node)
            for m in replacement:
                self.add_edge(m.i, m.j, m.measurement, m.covariance, kind=m.kind)
                k_new = len(self._edges) - 1
                touching.setdefault(m.i, []).append(k_new)
                touching.setdefault(m.j, []).append(k_new)
                added += 1
        if self.optimizer == "isam2" and not self._isam_broken:
            try:
                self._restart_isam()
            except RuntimeError:
                # as in `optimize`: a batch solve, then iSAM2 from it, or batch from now on
                self._store(self._lm(self._inlier_graph()))
                self.isam_recoveries += 1
                try:
                    self._restart_isam()
                except RuntimeError:
                    self._isam_broken = True
        return added

    def _drop_edge(self, k: int) -> None:
        """Take edge k out of the graph for good (its node was marginalised)."""
        self._dropped.add(k)
        self._rejected.discard(k)
        if k in self._held:
            self._held.remove(k)
        self._trusted.discard(k)
        self._due.discard(k)
        self._tested.pop(k, None)
        self._info_cache.pop(k, None)
        self._dormant.get(self._last_end(k), set()).discard(k)

    def set_poses(self, poses: npt.ArrayLike, *, rejected: Iterable[int] | None = None) -> None:
        """Replace every estimate (e.g. after loading a session) and restart iSAM2 from them.

        Without ``rejected`` every robust edge goes through the gate again at the next update.
        With it (indices into `edges`: the edges the estimate was solved without), those stay
        rejected, the other robust edges stay accepted, and iSAM2 restarts from the estimate
        at once with the accepted edges: gating them all again would test each loop against an
        estimate of the graph without any loop, whose wide marginals let false loops in.
        """
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
        if rejected is None:
            self._reset_isam()
            return
        out = {int(k) for k in rejected}
        for k, e in enumerate(self._edges):
            if k in self._dropped:
                continue
            if k in out:
                self._reject(k)
            elif e.robust or e.kind is EdgeKind.LOOP:
                self._closures.setdefault(max(e.i, e.j), []).append(min(e.i, e.j))
        if self.optimizer == "isam2":
            self._restart_isam()
        else:
            self._pending_nodes, self._pending_edges = [], []
