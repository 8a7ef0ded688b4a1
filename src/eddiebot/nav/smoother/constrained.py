"""``nav2_constrained_smoother::ConstrainedSmoother``: the path as a least-squares problem
over its poses (smoothness, minimum turning radius, distance to the original, costmap cost),
solved by a Levenberg-Marquardt trust region as Nav2's Ceres set-up; see
:class:`ConstrainedSmoother`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from eddiebot.nav.costmap.costmap2d import Costmap2D
from eddiebot.nav.errors import FailedToSmoothPath, InvalidPathForSmoothing, ParameterError
from eddiebot.nav.params import from_params, require
from eddiebot.nav.smoother.base import SmoothResult
from eddiebot.nav.types import as_path


@dataclass(frozen=True)
class ConstrainedOptimizerConfig:
    """``optimizer.*`` of ``nav2_constrained_smoother::ConstrainedSmoother`` (OptimizerParams,
    Jazzy code defaults). Upstream hands them to Ceres; here they bound scipy's trust-region
    least squares: ``max_iterations`` function evaluations, ``fn_tol`` / ``param_tol`` /
    ``gradient_tol`` its ``ftol`` / ``xtol`` / ``gtol``."""

    max_iterations: int = 100
    debug_optimizer: bool = False
    linear_solver_type: str = "SPARSE_NORMAL_CHOLESKY"
    fn_tol: float = 1.0e-7
    param_tol: float = 1.0e-15
    gradient_tol: float = 1.0e-10

    def validate(self, server: str = "smoother_server") -> None:
        require(self.linear_solver_type in ("DENSE_QR", "SPARSE_NORMAL_CHOLESKY"), server,
                "optimizer.linear_solver_type", self.linear_solver_type,
                "valid values are DENSE_QR, SPARSE_NORMAL_CHOLESKY")
        require(self.max_iterations >= 1, server, "optimizer.max_iterations",
                self.max_iterations, "must be >= 1")
        for key in ("fn_tol", "param_tol", "gradient_tol"):
            value = getattr(self, key)
            require(value >= 0.0, server, f"optimizer.{key}", value, "must be >= 0")


@dataclass(frozen=True)
class ConstrainedSmootherConfig:
    """``nav2_constrained_smoother::ConstrainedSmoother`` parameters (SmootherParams, Jazzy
    code defaults); ``optimizer`` is the ``optimizer.*`` block."""

    reversing_enabled: bool = True
    path_downsampling_factor: int = 1
    path_upsampling_factor: int = 1
    keep_start_orientation: bool = True
    keep_goal_orientation: bool = True
    minimum_turning_radius: float = 0.4
    w_curve: float = 30.0
    w_dist: float = 0.0
    w_smooth: float = 2000000.0
    w_cost: float = 0.015
    w_cost_cusp_multiplier: float = 3.0
    cusp_zone_length: float = 2.5
    cost_check_points: tuple[float, ...] = ()
    optimizer: Any = field(default_factory=ConstrainedOptimizerConfig)
    #: sections of the plugin's parameters read into their own config (``optimizer.*``)
    NESTED: ClassVar[dict[str, type]] = {"optimizer": ConstrainedOptimizerConfig}

    def validate(self, server: str = "smoother_server") -> None:
        require(len(self.cost_check_points) % 3 == 0, server, "cost_check_points",
                list(self.cost_check_points),
                "must contain values as follows: [x1, y1, weight1, x2, y2, weight2, ...]")
        if self.cost_check_points:
            require(sum(self.cost_check_points[2::3]) != 0.0, server, "cost_check_points",
                    list(self.cost_check_points), "the weights must not sum to 0")
        require(self.path_downsampling_factor >= 1, server, "path_downsampling_factor",
                self.path_downsampling_factor, "must be >= 1")
        require(self.path_upsampling_factor >= 0, server, "path_upsampling_factor",
                self.path_upsampling_factor, "must be >= 0")
        require(self.minimum_turning_radius >= 0.0, server, "minimum_turning_radius",
                self.minimum_turning_radius, "must be >= 0")
        value = self.optimizer
        if isinstance(value, ConstrainedOptimizerConfig):
            value.validate(server)
            return
        if not isinstance(value, Mapping):
            raise ParameterError(server, "optimizer", value,
                                 "expected a mapping of optimizer keys")
        known = ConstrainedOptimizerConfig.__dataclass_fields__
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ParameterError(server, f"optimizer.{unknown[0]}", value[unknown[0]],
                                 f"unknown optimizer parameter; known: {sorted(known)}")
        opt = from_params(ConstrainedOptimizerConfig, dict(value), server=server)
        object.__setattr__(self, "optimizer", opt)


_CS_EPSILON = 0.0001  # nav2_smac_planner's EPSILON, which the constrained smoother uses


def _catmull_rom(p0: npt.NDArray[np.float64], p1: npt.NDArray[np.float64],
                 p2: npt.NDArray[np.float64], p3: npt.NDArray[np.float64],
                 x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``ceres::CubicHermiteSpline`` (Catmull-Rom) through p1 (x = 0) and p2 (x = 1)."""
    a = 0.5 * (-p0 + 3.0 * p1 - 3.0 * p2 + p3)
    b = 0.5 * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3)
    c = 0.5 * (-p0 + p2)
    return p1 + x * (c + x * (b + x * a))


def bicubic_cost(grid: npt.NDArray[np.uint8], r: npt.NDArray[np.float64],
                 c: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``ceres::BiCubicInterpolator`` over ``ceres::Grid2D`` (row ``r``, column ``c``; the
    grid's edge values extend beyond it)."""
    h, w = grid.shape
    row = np.floor(r).astype(np.int64)
    col = np.floor(c).astype(np.int64)
    fr, fc = (r - row)[:, None], c - col
    k = np.arange(-1, 3)
    rr = np.clip(row[:, None] + k, 0, h - 1)
    cc = np.clip(col[:, None] + k, 0, w - 1)
    v = grid[rr[:, :, None], cc[:, None, :]].astype(np.float64)  # (n, 4 rows, 4 columns)
    along = _catmull_rom(v[..., 0], v[..., 1], v[..., 2], v[..., 3], fc[:, None])
    out: npt.NDArray[np.float64] = _catmull_rom(along[:, 0:1], along[:, 1:2], along[:, 2:3],
                                                along[:, 3:4], fr)[:, 0]
    return out


def _arc_center(prev: npt.NDArray[np.float64], pt: npt.NDArray[np.float64],
                nxt: npt.NDArray[np.float64], cusp: npt.NDArray[np.bool_]
                ) -> npt.NDArray[np.float64]:
    """``arcCenter`` per row: the centre of the circle through (prev, pt, nxt) (nxt mirrored
    about pt at a cusp); inf on a straight line."""
    d1 = pt - prev
    d2 = np.where(cusp[:, None], -(nxt - pt), nxt - pt)
    nxt = pt + d2
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    straight = np.abs(det) < 1e-4
    det = np.where(straight, 1.0, det)
    mid1, mid2 = (prev + pt) / 2.0, (pt + nxt) / 2.0
    n1 = np.stack([-d1[:, 1], d1[:, 0]], axis=1)
    n2 = np.stack([-d2[:, 1], d2[:, 0]], axis=1)
    det1 = (mid1[:, 0] + n1[:, 0]) * mid1[:, 1] - (mid1[:, 1] + n1[:, 1]) * mid1[:, 0]
    det2 = (mid2[:, 0] + n2[:, 0]) * mid2[:, 1] - (mid2[:, 1] + n2[:, 1]) * mid2[:, 0]
    center = np.stack([(det1 * n2[:, 0] - det2 * n1[:, 0]) / det,
                       (det1 * n2[:, 1] - det2 * n1[:, 1]) / det], axis=1)
    center[straight] = np.inf
    return center


def _tangent_dir(prev: npt.NDArray[np.float64], pt: npt.NDArray[np.float64],
                 nxt: npt.NDArray[np.float64], cusp: npt.NDArray[np.bool_]
                 ) -> npt.NDArray[np.float64]:
    """``tangentDir`` per row (unnormalised, sign left to the caller)."""
    center = _arc_center(prev, pt, nxt, cusp)
    out = np.stack([center[:, 1] - pt[:, 1], pt[:, 0] - center[:, 0]], axis=1)
    straight = ~np.isfinite(center[:, 0])
    if straight.any():
        d1 = pt - prev
        d2 = np.where(cusp[:, None], -(nxt - pt), nxt - pt)
        chord = (pt + d2) - prev
        zero = (chord[:, 0] == 0.0) & (chord[:, 1] == 0.0)
        chord[zero] = np.stack([d1[zero, 1], -d1[zero, 0]], axis=1)
        out[straight] = chord[straight]
    return out


def _cubic_bezier(p0: npt.NDArray[np.float64], p1: npt.NDArray[np.float64],
                  p2: npt.NDArray[np.float64], p3: npt.NDArray[np.float64],
                  mu: float) -> npt.NDArray[np.float64]:
    c = 3.0 * (p1 - p0)
    b = 3.0 * (p2 - p1) - c
    a = p3 - p0 - c - b
    out: npt.NDArray[np.float64] = a * mu ** 3 + b * mu ** 2 + c * mu + p0
    return out


@dataclass
class _Problem:
    """The residual blocks of ``Smoother::buildProblem``: block k ties point ``mid[k]`` to its
    neighbours ``nxt[k]`` and ``prev[k]``."""

    mid: npt.NDArray[np.int64]
    nxt: npt.NDArray[np.int64]
    prev: npt.NDArray[np.int64]
    ratio: npt.NDArray[np.float64]       # next-to-last length ratio, negative at a cusp
    reversing: npt.NDArray[np.bool_]
    cost_weight: npt.NDArray[np.float64]
    optimized: npt.NDArray[np.bool_]     # points kept by the downsampling
    free: npt.NDArray[np.int64]          # points the optimiser moves


def _jacobian_groups(pb: _Problem) -> list[tuple[npt.NDArray[np.int64], npt.NDArray[np.int64],
                                                  npt.NDArray[np.int64]]]:
    """Column groups for a finite-difference Jacobian: a block ties three consecutive kept
    poses, so free poses three apart never share a block and are perturbed together. Per
    group: the free poses moved, and per block touched the block and the pose's column."""
    kept = np.nonzero(pb.optimized)[0]
    order = np.full(pb.optimized.shape[0], -1, dtype=np.int64)
    order[kept] = np.arange(kept.size)
    col = np.full(pb.optimized.shape[0], -1, dtype=np.int64)
    col[pb.free] = np.arange(pb.free.size)
    groups = []
    for c in range(3):
        moved = np.nonzero(order[pb.free] % 3 == c)[0]
        blocks, cols = [], []
        for idx in (pb.mid, pb.nxt, pb.prev):
            hit = (order[idx] % 3 == c) & (col[idx] >= 0)
            blocks.append(np.nonzero(hit)[0])
            cols.append(col[idx][hit])
        groups.append((moved, np.concatenate(blocks), np.concatenate(cols)))
    return groups


def _levenberg_marquardt(fun: Any, x0: npt.NDArray[np.float64], pb: _Problem,
                         opt: ConstrainedOptimizerConfig
                         ) -> tuple[npt.NDArray[np.float64], float, float, bool, int]:
    """Minimise ``0.5·|fun(x)|²`` as Ceres' Levenberg-Marquardt trust region does (Jacobi
    scaled columns, damping by the clamped diagonal of JᵀJ over the radius, radius grown by
    ``1 / max(1/3, 1 - (2ρ - 1)³)`` on a step kept), with a central-difference
    Jacobian over :func:`_jacobian_groups`. Stops on Ceres' function, gradient and parameter
    tolerances or after ``max_iterations``; returns (x, initial cost, final cost, converged,
    iterations)."""
    from scipy.sparse import coo_matrix, diags
    from scipy.sparse.linalg import spsolve

    groups = _jacobian_groups(pb)
    n = x0.size
    x = x0.copy()
    r = fun(x)
    cost = 0.5 * float(r @ r)
    initial = cost
    radius, v = 1.0e4, 2.0
    converged = False
    iterations = 0

    def jacobian(x: npt.NDArray[np.float64]) -> Any:
        rows, cols, vals = [], [], []
        h = np.cbrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
        for moved, blocks, pcols in groups:
            for d in (0, 1):
                idx = 2 * moved + d
                xp, xm = x.copy(), x.copy()
                xp[idx] += h[idx]
                xm[idx] -= h[idx]
                step = np.zeros(n)
                step[idx] = h[idx]
                dr = (fun(xp) - fun(xm)).reshape(-1, 4)
                if blocks.size == 0:
                    continue
                hc = step[2 * pcols + d]
                vals.append((dr[blocks] / (2.0 * hc[:, None])).ravel())
                rows.append((4 * blocks[:, None] + np.arange(4)).ravel())
                cols.append(np.repeat(2 * pcols + d, 4))
        if not rows:
            return coo_matrix((r.size, n)).tocsr()
        return coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(r.size, n)).tocsr()

    jac = jacobian(x)
    # Ceres' jacobi_scaling: columns scaled by 1 / (1 + their norm at the start)
    scale = 1.0 / (1.0 + np.sqrt(np.asarray(jac.multiply(jac).sum(axis=0)).ravel()))
    s_mat = diags(scale)
    while iterations < opt.max_iterations:
        g = jac.T @ r
        if float(np.max(np.abs(g))) <= opt.gradient_tol:
            converged = True
            break
        js = jac @ s_mat
        a = (js.T @ js).tocsc()
        diag = np.clip(a.diagonal(), 1e-6, 1e32)
        delta = scale * spsolve(a + diags(diag / radius), -(js.T @ r))
        iterations += 1
        if not np.all(np.isfinite(delta)):
            radius /= v
            v *= 2.0
            continue
        if float(np.linalg.norm(delta)) <= opt.param_tol * (float(np.linalg.norm(x))
                                                            + opt.param_tol):
            converged = True
            break
        jd = jac @ delta
        model = -(float(r @ jd) + 0.5 * float(jd @ jd))
        x_new = x + delta
        r_new = fun(x_new)
        cost_new = 0.5 * float(r_new @ r_new)
        rho = (cost - cost_new) / model if model > 0.0 else -1.0
        if rho > 1e-3 and np.isfinite(cost_new):
            change = cost - cost_new
            x, r, cost = x_new, r_new, cost_new
            radius = min(radius / max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e16)
            v = 2.0
            if change <= opt.fn_tol * max(cost + change, 1e-300):
                converged = True
                break
            jac = jacobian(x)
        else:
            radius /= v
            v *= 2.0
            if radius < 1e-32:
                break
        if opt.debug_optimizer:
            print(f"constrained smoother: iteration {iterations} cost {cost:.6g} "
                  f"radius {radius:.3g}")
    return x, initial, cost, converged, iterations


class ConstrainedSmoother:
    """``nav2_constrained_smoother::ConstrainedSmoother``: the path as a least-squares problem
    (upstream solves it with Ceres, here scipy's trust-region reflective solver with a sparse
    finite-difference Jacobian). Per kept pose i with neighbours i-1, i+1 four residuals, each
    a weight times a square as upstream: smoothness ``w_smooth·|r·(x[i+1]-x[i]) - (x[i]-x[i-1])|²``
    (r the ratio of the segment lengths, negative at a cusp), curvature
    ``w_curve·(1/R - 1/minimum_turning_radius)²`` where the circle through the three points is
    tighter than allowed, distance ``w_dist·|x[i] - original|²`` and cost ``w_cost·c²`` with c
    the costmap's bicubic interpolation at the pose (or the weighted ``cost_check_points``
    around it); the weight rises to ``w_cost·w_cost_cusp_multiplier`` towards a cusp over
    ``cusp_zone_length``. The first and last pose stay, and the second and second-to-last too
    with ``keep_start_orientation`` / ``keep_goal_orientation``; every
    ``path_downsampling_factor``-th pose is optimised (cusps always) and the rest are filled
    back with cubic Bézier segments, ``path_upsampling_factor`` points per kept segment;
    headings follow the tangent of the circle through neighbouring poses."""

    def __init__(self, config: ConstrainedSmootherConfig | None = None,
                 name: str = "constrained_smoother") -> None:
        self.config = config or ConstrainedSmootherConfig()
        self.config.validate()
        self.name = name
        self.last_cost: tuple[float, float] = (0.0, 0.0)
        """(initial, final) value of the objective at the last :meth:`smooth`."""
        self.last_evaluations = 0

    # --- problem ---------------------------------------------------------------------------
    def _directions(self, p: npt.NDArray[np.float64]
                    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                               npt.NDArray[np.float64]]:
        """(x, y, ±1 forward/reverse) per pose, and the start and goal heading vectors."""
        cfg = self.config
        n = p.shape[0]
        heading = np.stack([np.cos(p[:, 2]), np.sin(p[:, 2])], axis=1)
        mvmt = np.diff(p[:, :2], axis=0)
        reversing = cfg.reversing_enabled & (np.einsum("ij,ij->i", heading[:-1], mvmt) < 0.0)
        world = np.empty((n, 3))
        world[:, :2] = p[:, :2]
        world[:-1, 2] = np.where(reversing, -1.0, 1.0)
        world[-1, 2] = world[-2, 2]
        if not cfg.keep_start_orientation and n > 2:
            world[0, 2] = world[1, 2]
        return world, heading[0], heading[-1]

    def _build(self, path: npt.NDArray[np.float64]) -> _Problem:
        cfg = self.config
        n = path.shape[0]
        cost_w = cfg.w_cost
        cusp_w = cfg.w_cost * cfg.w_cost_cusp_multiplier
        half = cfg.cusp_zone_length / 2.0
        optimized = np.zeros(n, dtype=bool)
        optimized[0] = True
        mid: list[int] = []
        nxt: list[int] = []
        prev: list[int] = []
        ratio: list[float] = []
        rev: list[bool] = []
        weight: list[float] = []
        potential: list[tuple[float, int]] = []  # (segment length, block) near a coming cusp
        potential_len = 0.0
        prelast_i, last_i = -1, 0
        last_direction = path[0, 2]
        last_was_cusp = last_is_reversing = False
        last_segment_len = _CS_EPSILON
        len_since_cusp = math.inf
        for i in range(1, n):
            is_cusp = False
            if i != n - 1:
                is_cusp = bool(path[i, 2] * last_direction < 0)
                last_direction = path[i, 2]
                if (not is_cusp and i > (1 if cfg.keep_start_orientation else 0)
                        and i < n - (2 if cfg.keep_goal_orientation else 1)
                        and i - last_i < cfg.path_downsampling_factor):
                    continue
            seg_len = float(np.hypot(*(path[i, :2] - path[last_i, :2])))
            potential_len += seg_len
            while potential and potential_len > half:
                potential_len -= potential.pop(0)[0]
            if is_cusp:
                to_cusp = seg_len
                for length, k in reversed(potential):
                    w = cusp_w * (1.0 - to_cusp / half) + cost_w * to_cusp / half
                    if abs(w - cusp_w) < abs(weight[k] - cusp_w):
                        weight[k] = w
                    to_cusp += length
                potential_len = 0.0
                potential.clear()
                len_since_cusp = 0.0
            optimized[i] = True
            if prelast_i != -1:
                w = cost_w
                if len_since_cusp <= half:
                    w = cusp_w * (1.0 - len_since_cusp / half) + cost_w * len_since_cusp / half
                mid.append(last_i)
                nxt.append(i)
                prev.append(prelast_i)
                ratio.append((-1.0 if last_was_cusp else 1.0) * last_segment_len / seg_len)
                rev.append(last_is_reversing)
                weight.append(w)
                potential.append((seg_len, len(mid) - 1))
            last_was_cusp = is_cusp
            last_is_reversing = bool(last_direction < 0)
            prelast_i, last_i = last_i, i
            len_since_cusp += seg_len
            last_segment_len = max(_CS_EPSILON, seg_len)
        fixed = {0, n - 1}
        if cfg.keep_start_orientation:
            fixed.add(1)
        if cfg.keep_goal_orientation:
            fixed.add(n - 2)
        in_problem = sorted(set(mid) | set(nxt) | set(prev))
        free = np.array([i for i in in_problem if i not in fixed], dtype=np.int64)
        return _Problem(np.array(mid, dtype=np.int64), np.array(nxt, dtype=np.int64),
                        np.array(prev, dtype=np.int64), np.array(ratio), np.array(rev, dtype=bool),
                        np.array(weight), optimized, free)

    def _residuals(self, xy: npt.NDArray[np.float64], pb: _Problem, original: npt.NDArray[np.float64],
                   costmap: Costmap2D | None) -> npt.NDArray[np.float64]:
        """``SmootherCostFunction`` for every block: (B, 4) smoothing, curvature, distance,
        cost."""
        cfg = self.config
        pt, nx, pv = xy[pb.mid], xy[pb.nxt], xy[pb.prev]
        out = np.zeros((pb.mid.shape[0], 4))
        d = pb.ratio[:, None] * (nx - pt) - (pt - pv)
        out[:, 0] = cfg.w_smooth * np.einsum("ij,ij->i", d, d)
        if cfg.w_curve != 0.0 and cfg.minimum_turning_radius > 0.0:
            center = _arc_center(pv, pt, nx, pb.ratio < 0)
            ok = np.isfinite(center[:, 0])
            radius = np.hypot(*(pt - np.where(ok[:, None], center, 0.0)).T)
            k = np.where(ok, 1.0 / np.maximum(radius, 1e-12) - 1.0 / cfg.minimum_turning_radius,
                         0.0)
            out[:, 1] = np.where(k > _CS_EPSILON, cfg.w_curve * k * k, 0.0)
        if cfg.w_dist != 0.0:
            e = pt - original[pb.mid]
            out[:, 2] = cfg.w_dist * np.einsum("ij,ij->i", e, e)
        if costmap is not None and np.any(pb.cost_weight != 0.0):
            out[:, 3] = pb.cost_weight * self._cost_term(pt, nx, pv, pb, costmap)
        return out

    def _cost_term(self, pt: npt.NDArray[np.float64], nx: npt.NDArray[np.float64],
                   pv: npt.NDArray[np.float64], pb: _Problem, costmap: Costmap2D
                   ) -> npt.NDArray[np.float64]:
        def value(q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            gx = (q[:, 0] - costmap.origin_x) / costmap.resolution
            gy = (q[:, 1] - costmap.origin_y) / costmap.resolution
            return bicubic_cost(costmap.data, gy - 0.5, gx - 0.5)

        ccp = self.config.cost_check_points
        if not ccp:
            v = value(pt)
            out: npt.NDArray[np.float64] = v * v
            return out
        pts = np.asarray(ccp, dtype=np.float64).reshape(-1, 3)
        weights = pts[:, 2] / pts[:, 2].sum()
        direction = _tangent_dir(pv, pt, nx, pb.ratio < 0)
        direction /= np.maximum(np.hypot(direction[:, 0], direction[:, 1]), 1e-12)[:, None]
        flip = (np.einsum("ij,ij->i", nx - pt, direction) < 0.0) != pb.reversing
        direction[flip] *= -1.0
        total = np.zeros(pt.shape[0])
        for (cx, cy, _), w in zip(pts, weights, strict=True):
            q = np.stack([pt[:, 0] + direction[:, 0] * cx - direction[:, 1] * cy,
                          pt[:, 1] + direction[:, 1] * cx + direction[:, 0] * cy], axis=1)
            v = value(q)
            total += w * v * v
        return total

    # --- smoothing -------------------------------------------------------------------------
    def smooth(self, path: npt.ArrayLike, costmap: Costmap2D | None = None) -> SmoothResult:
        """The smoothed path; raises :class:`FailedToSmoothPath` when the optimisation ends
        worse than it started. Without a costmap the cost term is left out."""

        p = as_path(path)
        if p.shape[0] == 0:
            raise InvalidPathForSmoothing("empty path")
        if p.shape[0] < 2:
            return SmoothResult(p.copy(), True)
        if not np.all(np.isfinite(p)):
            raise InvalidPathForSmoothing("path has non-finite poses")
        world, start_dir, end_dir = self._directions(p)
        pb = self._build(world)
        xy = world[:, :2].copy()
        original = p[:, :2]
        opt = self.config.optimizer
        converged = True
        self.last_evaluations = 0
        if pb.free.size > 0 and pb.mid.size > 0:
            def fun(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
                q = xy.copy()
                q[pb.free] = x.reshape(-1, 2)
                return self._residuals(q, pb, original, costmap).ravel()

            x, initial, final, converged, evals = _levenberg_marquardt(
                fun, xy[pb.free].ravel(), pb, opt)
            self.last_cost = (initial, final)
            self.last_evaluations = evals
            if not np.all(np.isfinite(x)) or final > initial:
                raise FailedToSmoothPath(f"{self.name}: solution is not usable "
                                         f"(cost {initial:.6g} -> {final:.6g})")
            xy[pb.free] = x.reshape(-1, 2)
        world[:, :2] = xy
        return SmoothResult(self._populate(world, pb.optimized, start_dir, end_dir), converged)

    def _populate(self, world: npt.NDArray[np.float64], optimized: npt.NDArray[np.bool_],
                  start_dir: npt.NDArray[np.float64], end_dir: npt.NDArray[np.float64]
                  ) -> npt.NDArray[np.float64]:
        """``Smoother::upsampleAndPopulate``: headings of the kept poses from the circle
        through their neighbours, skipped poses (times ``path_upsampling_factor``) refilled by
        cubic Bézier segments."""
        cfg = self.config
        n = world.shape[0]
        out: list[list[float]] = []
        last_i, prelast_i = 0, -1
        prelast_dir = np.zeros(2)
        for i in range(1, n + 1):
            if i < n and not optimized[i]:
                continue
            if prelast_i != -1:
                prelast, last = world[prelast_i], world[last_i]
                if i < n:
                    cur = world[i]
                    t = _tangent_dir(prelast[None, :2], last[None, :2], cur[None, :2],
                                     np.array([prelast[2] * last[2] < 0]))[0]
                    last_dir = t if t @ ((cur[:2] - last[:2]) * last[2]) >= 0 else -t
                    last_dir = last_dir / max(float(np.hypot(*last_dir)), 1e-12)
                elif cfg.keep_goal_orientation:
                    last_dir = end_dir
                else:
                    last_dir = (last[:2] - prelast[:2]) * last[2]
                    last_dir = last_dir / max(float(np.hypot(*last_dir)), 1e-12)
                interp_cnt = (last_i - prelast_i) * cfg.path_upsampling_factor - 1
                if interp_cnt > 0:
                    dist = float(np.hypot(*(last[:2] - prelast[:2])))
                    pt1 = prelast[:2] + prelast_dir * dist * 0.4 * prelast[2]
                    pt2 = last[:2] - last_dir * dist * 0.4 * prelast[2]
                    for j in range(1, interp_cnt + 1):
                        q = _cubic_bezier(prelast[:2], pt1, pt2, last[:2], j / (interp_cnt + 1))
                        out.append([float(q[0]), float(q[1]), 0.0])
                out.append([float(last[0]), float(last[1]),
                            math.atan2(float(last_dir[1]), float(last_dir[0]))])
                if interp_cnt > 0:
                    arr = np.asarray(out)
                    for j in range(len(out) - 1 - interp_cnt, len(out) - 1):
                        t = _tangent_dir(arr[j - 1:j, :2], arr[j:j + 1, :2], arr[j + 1:j + 2, :2],
                                         np.array([False]))[0]
                        if t @ ((arr[j + 1, :2] - arr[j, :2]) * prelast[2]) < 0:
                            t = -t
                        out[j][2] = math.atan2(float(t[1]), float(t[0]))
                prelast_dir = last_dir
            else:
                start = world[0]
                if cfg.keep_start_orientation:
                    d = start_dir
                else:
                    d = (world[i, :2] - start[:2]) * start[2]
                    d = d / max(float(np.hypot(*d)), 1e-12)
                out.append([float(start[0]), float(start[1]), math.atan2(float(d[1]), float(d[0]))])
                prelast_dir = d
            prelast_i, last_i = last_i, i
        return np.asarray(out, dtype=np.float64)



__all__ = ["ConstrainedOptimizerConfig", "ConstrainedSmoother", "ConstrainedSmootherConfig", "bicubic_cost"]
