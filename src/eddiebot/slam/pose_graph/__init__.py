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

``marginalize`` removes nodes for good (lifelong mapping): each node's accepted edges are
replaced by relative-pose edges between its neighbours carrying their Schur complement
(exact for a node inside a chain, a chain sparsification of the dense factor beyond;
``marginal.py``); the node keeps its last pose but leaves the estimate and the solvers.

``half_chi2`` reports ½ Σ eᵀ Ω e with every kernel removed (the figure the g2o benchmarks
quote), whatever optimiser produced the estimate.
"""


from eddiebot.slam.pose_graph.edges import FACTORIZATIONS, Edge, EdgeKind, chi2_quantile
from eddiebot.slam.pose_graph.graph import PoseGraph

__all__ = ["FACTORIZATIONS", "Edge", "EdgeKind", "PoseGraph", "chi2_quantile"]
