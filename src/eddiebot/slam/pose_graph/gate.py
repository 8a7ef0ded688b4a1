"""The false-loop gate of the pose graph: residual, χ² innovation gate, support and the
re-tests of held and rejected edges (steps 1–3 of the `eddiebot.slam.pose_graph` docstring)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np

from eddiebot.geometry import se2_between
from eddiebot.slam.pose_graph.core import PoseGraphCore
from eddiebot.slam.pose_graph.edges import (
    FloatArray,
    _pose2,
)


class GatedPoseGraph(PoseGraphCore):
    """`PoseGraphCore` with the χ² gate, the support rule and the pool of held and rejected
    edges."""

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
