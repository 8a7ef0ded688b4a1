"""Node removal by marginalisation: the Schur complement of a node's edges, sparsified into
relative-pose edges between its neighbours.

A node ``m`` with edges to neighbours ``n_1 < … < n_k`` is linearised at the current estimate
(GTSAM's right perturbation ``x ∘ exp(δ)``); eliminating ``δ_m`` from the stacked whitened
system leaves the dense information ``Λ`` (and vector ``η``) over the neighbours: everything
the node's edges said about them. ``Λ`` is relative (its null space is the global gauge), so
with ``δ_{n_1} = 0`` it is a proper Gaussian over the other neighbours, whose mean moves them
to where the removed edges alone would put them relative to ``n_1``.

That joint Gaussian is stored as a chain of ``k − 1`` relative-pose edges
``n_1 → n_2 → … → n_k``, each carrying its pair's exact marginal (mean and covariance):
for ``k = 2`` — a node inside an odometry chain — this *is* the Schur complement (one edge
composing the two), for larger ``k`` the correlations between non-adjacent pairs of the chain
are dropped (a tree sparsification of the dense factor, as in Carlevaris-Bianco et al.'s
generic node removal, with the chain in node order as the tree). A node with a single
neighbour is a leaf: its edges say nothing about the rest, and go without replacement.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from eddiebot.slam.pose_graph.edges import Edge, EdgeKind, FloatArray, _pose2

__all__ = ["MarginalEdge", "marginal_edges"]


@dataclass(frozen=True)
class MarginalEdge:
    """A relative-pose measurement ``inv(x_i) ∘ x_j`` left by a marginalised node."""

    i: int
    j: int
    measurement: FloatArray
    covariance: FloatArray
    kind: EdgeKind


def _whitened(
    edge: Edge, factor: gtsam.BetweenFactorPose2 | None, values: gtsam.Values
) -> tuple[FloatArray, FloatArray]:
    if factor is None:
        factor = gtsam.BetweenFactorPose2(
            edge.i, edge.j, _pose2(edge.measurement),
            gtsam.noiseModel.Gaussian.Covariance(edge.covariance),
        )
    a, b = factor.linearize(values).jacobian()
    return np.asarray(a), np.asarray(b)


def _adjoint_inverse(z: gtsam.Pose2) -> FloatArray:
    return np.asarray(z.inverse().AdjointMap())


def marginal_edges(
    node: int,
    edges: Sequence[Edge],
    poses: dict[int, FloatArray],
    factors: Sequence[gtsam.BetweenFactorPose2] | None = None,
) -> list[MarginalEdge]:
    """The edges that replace ``node``'s ``edges`` once it is marginalised out.

    ``poses`` holds the current estimate (map frame) of ``node`` and of every neighbour.
    ``factors``, parallel to ``edges``, are the factors the graph solves with: a robust edge
    is linearised with its kernel's weight at the estimate (without them, every edge is
    taken as Gaussian).
    The new edges' kind is ``ODOMETRY`` when every removed edge was odometry, else
    ``SCAN_MATCH``.
    """
    neighbours = sorted({e.j if e.i == node else e.i for e in edges})
    if len(neighbours) < 2:
        return []
    keys = [node, *neighbours]
    col = {k: 3 * c for c, k in enumerate(keys)}
    values = gtsam.Values()
    for k in keys:
        values.insert(k, _pose2(poses[k]))
    dim = 3 * len(keys)
    h = np.zeros((dim, dim))
    g = np.zeros(dim)
    for k, e in enumerate(edges):
        a, b = _whitened(e, None if factors is None else factors[k], values)
        cols = np.r_[col[e.i] : col[e.i] + 3, col[e.j] : col[e.j] + 3]
        h[np.ix_(cols, cols)] += a.T @ a
        g[cols] += a.T @ b
    # eliminate the node, then fix the first neighbour (the gauge): a Gaussian over the rest
    hmm, hmr, hrr = h[:3, :3], h[:3, 3:], h[3:, 3:]
    solve = np.linalg.solve(hmm, np.column_stack([hmr, g[:3]]))
    lam = hrr - hmr.T @ solve[:, :-1]
    eta = g[3:] - hmr.T @ solve[:, -1]
    cov = np.linalg.inv(lam[3:, 3:])
    cov = 0.5 * (cov + cov.T)
    delta = np.concatenate([np.zeros(3), cov @ eta[3:]])
    full = np.zeros((dim - 3, dim - 3))
    full[3:, 3:] = cov
    moved = [
        _pose2(poses[n]).compose(gtsam.Pose2.Expmap(delta[3 * c : 3 * c + 3]))
        for c, n in enumerate(neighbours)
    ]
    kind = (
        EdgeKind.ODOMETRY if all(e.kind is EdgeKind.ODOMETRY for e in edges)
        else EdgeKind.SCAN_MATCH
    )
    out = []
    for c in range(len(neighbours) - 1):
        z = moved[c].between(moved[c + 1])
        # δ_rel ≈ δ_b' − Ad(z⁻¹) δ_b  for  z = inv(x_b) ∘ x_b'
        jac = np.hstack([-_adjoint_inverse(z), np.eye(3)])
        block = full[3 * c : 3 * c + 6, 3 * c : 3 * c + 6]
        rel = jac @ block @ jac.T
        out.append(
            MarginalEdge(
                neighbours[c], neighbours[c + 1],
                np.array([z.x(), z.y(), z.theta()]), 0.5 * (rel + rel.T), kind,
            )
        )
    return out
