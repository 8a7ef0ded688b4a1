"""ICP on the registered depth image: the geometric registration of RTAB-Map's odometry
(`Reg/Strategy` 1 = ICP, 2 = visual then ICP) with the ``Icp/*`` parameters.

The new frame's depth is turned into a cloud (every `Icp/DownsamplingStep`-th pixel, range
limits, `Icp/VoxelSize` uniform sampling) with normals from the image grid (a depth image is
an organised cloud: central differences two samples away; none at depth jumps and creases,
whose normal would blend two surfaces; `estimate_normals` is the k-nearest-neighbour version,
`Icp/PointToPlaneK`, for clouds without a grid), and registered to a local scan map
(`ScanMap`, in the odometry frame) by point-to-plane (`Icp/PointToPlane`) or point-to-point
Gauss-Newton, in x, y, yaw under `Reg/Force3DoF`. Under `Reg/Force3DoF` the floor and ceiling
points are dropped: a horizontal plane does not constrain x, y or yaw. Not upstream: the
correspondence gate starts at 4× `Icp/MaxCorrespondenceDistance` and halves each iteration
down to it, so a guess a few degrees off (the start of a turn) still converges.

Geometry that leaves a translation free (one wall, the two parallel walls of a corridor) is
detected as upstream does: the smallest eigenvalue of the normals' covariance (in the plane
under `Reg/Force3DoF`) below `Icp/PointToPlaneMinComplexity`, here of the matched points'
normals at each iteration (a second wall outside the overlap constrains nothing). With
`Icp/PointToPlaneLowComplexityStrategy` 1 the fit then corrects only the constrained axes; the
free translation stays at the guess (the visual result or the motion prediction) and the
covariance says so: along that axis it is the guess's variance, not the fit's.

Covariance as upstream's `RegistrationIcp` (`util3d::computeVarianceAndCorrespondences`):
v = 2.1981 · the median squared distance of the final correspondences (a robust estimate of
their variance), v / 10 on x, y, z and v / 100 on the rotations, so what the links claim is
the scatter of the points after the fit, not the fit's own σ² (JᵀJ)⁻¹, which treats thousands
of correlated points as independent and claimed 5–12× less than the error on real frames
(ICL-NUIM, TUM fr1/desk). Along a free translation the guess's variance is added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from eddiebot.geometry.grid import bucket_grid
from eddiebot.vslam.camera import CameraIntrinsics, depth_to_meters
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.common import LOST_VARIANCE, huge_covariance
from eddiebot.vslam.transforms import rotation_angle, se3_inverse

__all__ = [
    "IcpResult",
    "IcpSettings",
    "ScanCloud",
    "ScanMap",
    "correspondence_variance",
    "depth_cloud",
    "estimate_normals",
    "icp_covariance",
    "icp_register",
    "make_scan",
    "normals_complexity",
    "registration_covariance",
    "voxel_filter",
]

F64 = NDArray[np.float64]
_RESIDUAL_VARIANCE_FLOOR = 1e-6  # m², (1 mm)²
_ANGULAR_VARIANCE_FLOOR = 3e-8
_MIN_CORRESPONDENCES = 10
_VERTICAL_NORMAL = 0.9  # |n_z| above this: floor / ceiling (dropped under Reg/Force3DoF)
_DEFAULT_EPSILON = 1e-6
_THREE_DOF_AXES = np.array([0, 1, 5])
_MAX_SUBTRACT_CELLS = 4_000_000  # grid cells of the subtraction search; beyond, a k-d tree
_NORMAL_HALF_WINDOW = 2
_JUMP_RATIO = 0.05
_COARSE_GATE = 4.0
_CREASE_COS = float(np.cos(np.radians(20.0)))


@dataclass(frozen=True)
class IcpSettings:
    """The ``Icp/*`` parameters (upstream names in `RtabmapParameters`) and `Reg/Force3DoF`."""

    max_translation: float = 0.2
    max_rotation: float = 0.78
    voxel_size: float = 0.05
    downsampling_step: int = 1
    range_min: float = 0.0
    range_max: float = 0.0
    max_correspondence_distance: float = 0.05
    iterations: int = 30
    epsilon: float = 0.0
    correspondence_ratio: float = 0.1
    point_to_plane: bool = False
    point_to_plane_k: int = 5
    point_to_plane_radius: float = 0.0
    min_complexity: float = 0.02
    low_complexity_strategy: int = 1
    force_3dof: bool = False
    reciprocal_correspondences: bool = True

    @classmethod
    def from_parameters(cls, p: RtabmapParameters) -> IcpSettings:
        """Settings of a parameter table."""
        return cls(
            p.icp_max_translation, p.icp_max_rotation, p.icp_voxel_size,
            p.icp_downsampling_step, p.icp_range_min, p.icp_range_max,
            p.icp_max_correspondence_distance, p.icp_iterations, p.icp_epsilon,
            p.icp_correspondence_ratio, p.icp_point_to_plane, p.icp_point_to_plane_k,
            p.icp_point_to_plane_radius, p.icp_point_to_plane_min_complexity,
            p.icp_point_to_plane_low_complexity_strategy, p.reg_force_3dof,
            p.icp_reciprocal_correspondences,
        )


@dataclass(frozen=True)
class ScanCloud:
    """Points (N, 3) m and unit normals (N, 3) in one frame."""

    points: F64
    normals: F64

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def transformed(self, t: F64) -> ScanCloud:
        """The cloud expressed in the frame where `t` is this cloud's frame's pose."""
        r = t[:3, :3]
        return ScanCloud(self.points @ r.T + t[:3, 3], self.normals @ r.T)

    @staticmethod
    def empty() -> ScanCloud:
        """No points."""
        return ScanCloud(np.zeros((0, 3)), np.zeros((0, 3)))


def _organised_points(depth: NDArray[np.generic], camera: CameraIntrinsics,
                      step: int) -> F64:
    """(h, w, 3) camera-frame points of every `step`-th pixel; NaN where there is no depth."""
    d = depth_to_meters(np.asarray(depth)[::step, ::step]).astype(np.float64)
    d[d <= 0] = np.nan
    h, w = d.shape
    u = np.arange(w, dtype=np.float64) * step
    v = np.arange(h, dtype=np.float64) * step
    x = (u[None, :] - camera.cx) * d / camera.fx
    y = (v[:, None] - camera.cy) * d / camera.fy
    return np.stack([x, y, d], axis=2)


def _in_range(cam: F64, range_min: float, range_max: float) -> NDArray[np.bool_]:
    keep = np.isfinite(cam[..., 2])
    if range_min > 0 or range_max > 0:
        rng = np.linalg.norm(np.nan_to_num(cam), axis=-1)
        if range_min > 0:
            keep &= rng >= range_min
        if range_max > 0:
            keep &= rng <= range_max
    return keep


def depth_cloud(depth: NDArray[np.generic], camera: CameraIntrinsics, step: int = 1,
                range_min: float = 0.0, range_max: float = 0.0) -> F64:
    """3D points (robot base frame) of every `step`-th row and column of a registered depth
    image (uint16 mm or float m; 0 / NaN = no depth), within the range limits (0 = off)."""
    cam = _organised_points(depth, camera, step)
    pts = cam[_in_range(cam, range_min, range_max)]
    lt = camera.local_transform
    out: F64 = pts @ lt[:3, :3].T + lt[:3, 3]
    return out


def _grid_normals(cam: F64, half: int) -> F64:
    """Normals of an organised cloud from the neighbours `half` cells away along the rows and
    columns (central differences), towards the camera; NaN at depth jumps and borders.

    Inverse depth is affine in the pixel coordinates on a plane: its second difference beyond
    a share (`_JUMP_RATIO`) of the centre's marks a depth jump (not one surface). A crease (two
    walls meeting): the normals of the forward and the backward differences disagree by more
    than 20°; the central one would be a blend of both walls."""
    return _grid_normals_kernel(np.ascontiguousarray(cam, np.float64), half, _JUMP_RATIO,
                                _CREASE_COS)


@njit(cache=True)
def _cross_into(a0: float, a1: float, a2: float, b0: float, b1: float,
                b2: float) -> tuple[float, float, float]:
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, error_model="numpy")  # 0 / 0 is NaN, as in the array form
def _grid_normals_kernel(cam: F64, half: int, jump_ratio: float, crease_cos: float) -> F64:
    """`_grid_normals`, one pass per pixel (the operations of the array form, in its order)."""
    h, w, _ = cam.shape
    out = np.full((h, w, 3), np.nan)
    if h <= 2 * half or w <= 2 * half:
        return out
    for i in range(half, h - half):
        for j in range(half, w - half):
            c = cam[i, j]
            r, le = cam[i, j + half], cam[i, j - half]
            dn, up = cam[i + half, j], cam[i - half, j]
            n0, n1, n2 = _cross_into(r[0] - le[0], r[1] - le[1], r[2] - le[2],
                                     dn[0] - up[0], dn[1] - up[1], dn[2] - up[2])
            norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
            n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
            ic = 1.0 / c[2]
            d2u = 1.0 / r[2] + 1.0 / le[2] - 2 * ic
            d2v = 1.0 / dn[2] + 1.0 / up[2] - 2 * ic
            jump = abs(d2u) > jump_ratio * ic or abs(d2v) > jump_ratio * ic
            f0, f1, f2 = _cross_into(r[0] - c[0], r[1] - c[1], r[2] - c[2],
                                     dn[0] - c[0], dn[1] - c[1], dn[2] - c[2])
            b0, b1, b2 = _cross_into(c[0] - le[0], c[1] - le[1], c[2] - le[2],
                                     c[0] - up[0], c[1] - up[1], c[2] - up[2])
            cos_fb = (f0 * b0 + f1 * b1 + f2 * b2) / (
                math.sqrt(f0 * f0 + f1 * f1 + f2 * f2) * math.sqrt(b0 * b0 + b1 * b1 + b2 * b2))
            if jump or not cos_fb > crease_cos:
                continue
            if n0 * c[0] + n1 * c[1] + n2 * c[2] > 0:  # the camera is at the origin
                n0, n1, n2 = -n0, -n1, -n2
            out[i, j, 0], out[i, j, 1], out[i, j, 2] = n0, n1, n2
    return out


def voxel_filter(points: F64, voxel: float, normals: F64 | None = None) -> tuple[F64, F64 | None]:
    """Uniform sampling: the centroid of the points in each `voxel`-sized cube (0 = off), and
    the renormalised mean of their `normals` when given."""
    if voxel <= 0 or points.shape[0] == 0:
        return points, normals
    keys = np.floor(points / voxel).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    # per-voxel sums in input order (as np.add.at would add them, without its overhead)
    sums = np.stack([np.bincount(inverse, points[:, k], counts.size) for k in range(3)], axis=1)
    out: F64 = sums / counts[:, None]
    if normals is None:
        return out, None
    nsum = np.stack([np.bincount(inverse, normals[:, k], counts.size) for k in range(3)], axis=1)
    nrm: F64 = nsum / np.maximum(np.linalg.norm(nsum, axis=1, keepdims=True), 1e-12)
    return out, nrm


def estimate_normals(points: F64, k: int = 5, radius: float = 0.0,
                     viewpoint: F64 | None = None) -> F64:
    """Unit normals by PCA of each point's `k` nearest neighbours (or those within `radius`
    when > 0), turned towards `viewpoint`. Points with fewer than 3 neighbours get NaN."""
    n = points.shape[0]
    if n < 3:
        return np.full((n, 3), np.nan)
    tree = cKDTree(points)
    kk = min(max(k, 3), n)
    dist, idx = tree.query(points, k=kk)
    valid = np.ones((n, kk), bool)
    if radius > 0:
        valid = dist <= radius
    nb = points[idx]  # (n, k, 3)
    w = valid[..., None].astype(np.float64)
    cnt = w.sum(axis=1)
    mean = (nb * w).sum(axis=1) / np.maximum(cnt, 1.0)
    dev = (nb - mean[:, None, :]) * w
    cov = np.einsum("nki,nkj->nij", dev, dev)
    _, vecs = np.linalg.eigh(cov)
    normals: F64 = vecs[:, :, 0].copy()
    normals[cnt[:, 0] < 3] = np.nan
    if viewpoint is not None:
        flip = np.sum(normals * (viewpoint - points), axis=1) < 0
        normals[flip] *= -1.0
    return normals


def make_scan(depth: NDArray[np.generic], camera: CameraIntrinsics,
              settings: IcpSettings) -> ScanCloud:
    """The ICP cloud of one registered depth image, in the robot base frame. Normals come from
    the image grid (neighbours `_NORMAL_HALF_WINDOW` sampled pixels away: a depth image is an
    organised cloud), averaged per voxel."""
    cam = _organised_points(depth, camera, settings.downsampling_step)
    normals = _grid_normals(cam, _NORMAL_HALF_WINDOW)
    keep = _in_range(cam, settings.range_min, settings.range_max) & np.isfinite(normals[..., 0])
    lt = camera.local_transform
    pts = cam[keep] @ lt[:3, :3].T + lt[:3, 3]
    nrm = normals[keep] @ lt[:3, :3].T
    if settings.force_3dof:
        wall = np.abs(nrm[:, 2]) < _VERTICAL_NORMAL
        pts, nrm = pts[wall], nrm[wall]
    pts, nrm_v = voxel_filter(pts, settings.voxel_size, nrm)
    assert nrm_v is not None
    return ScanCloud(pts, nrm_v)


def normals_complexity(normals: F64, three_dof: bool) -> tuple[float, F64]:
    """Upstream's structural complexity: the smallest eigenvalue of the normals' covariance
    (of their horizontal part, renormalised, under 3 DoF), and its eigenvector: the translation
    the geometry constrains least (along one wall, along a corridor)."""
    if normals.shape[0] == 0:
        return 0.0, np.array([1.0, 0.0, 0.0])
    if three_dof:
        h = normals[:, :2]
        h = h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
        vals, vecs = np.linalg.eigh(h.T @ h / h.shape[0])
        return float(vals[0]), np.array([vecs[0, 0], vecs[1, 0], 0.0])
    vals, vecs = np.linalg.eigh(normals.T @ normals / normals.shape[0])
    return float(vals[0]), vecs[:, 0].copy()


@dataclass(frozen=True)
class IcpResult:
    """Outcome of `icp_register`: the new frame's pose in the map frame, None on failure."""

    transform: F64 | None
    covariance: F64 = field(default_factory=huge_covariance)
    correspondences: int = 0
    ratio: float = 0.0
    complexity: float = 0.0
    #: unit translation (map axes) left at the guess because the geometry does not fix it
    free_axis: F64 | None = None
    reason: str = ""
    iterations: int = 0

    @property
    def ok(self) -> bool:
        """True when a transform was found."""
        return self.transform is not None


def _rotation(w: F64) -> F64:
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    out: F64 = np.eye(3) + np.sin(th) * kx + (1.0 - np.cos(th)) * (kx @ kx)
    return out


def _linearise(src: F64, tgt: F64, tgt_normals: F64, centre: F64, point_to_plane: bool,
               axes: NDArray[np.intp]) -> tuple[F64, F64]:
    """Residuals and Jacobian (columns: `axes` of tx ty tz rx ry rz about `centre`)."""
    arm = src - centre
    if point_to_plane:
        r = np.sum(tgt_normals * (src - tgt), axis=1)
        jac = np.concatenate([tgt_normals, np.cross(arm, tgt_normals)], axis=1)
        return r, jac[:, axes]
    r3 = src - tgt
    m = src.shape[0]
    jac3 = np.zeros((m, 3, 6))
    jac3[:, 0, 0] = jac3[:, 1, 1] = jac3[:, 2, 2] = 1.0
    # d(ω × arm)/dω = -[arm]×
    jac3[:, 0, 4], jac3[:, 0, 5] = arm[:, 2], -arm[:, 1]
    jac3[:, 1, 3], jac3[:, 1, 5] = -arm[:, 2], arm[:, 0]
    jac3[:, 2, 3], jac3[:, 2, 4] = arm[:, 1], -arm[:, 0]
    rows = 2 if axes.size == 3 else 3  # under 3 DoF the z row carries nothing
    return r3[:, :rows].ravel(), jac3[:, :rows, :][:, :, axes].reshape(-1, axes.size)


def _complement(free: F64) -> F64:
    """Orthonormal basis (columns) of the space orthogonal to the unit vector `free`."""
    q, _ = np.linalg.qr(np.column_stack([free, np.eye(free.size)]))
    return q[:, 1:]


def icp_register(target: ScanCloud, source: ScanCloud, guess: F64, settings: IcpSettings,
                 guess_covariance: F64 | None = None,
                 tree: cKDTree | None = None) -> IcpResult:
    """Pose of `source`'s frame in `target`'s frame by ICP from `guess` (4×4).

    Rejected (``transform=None``) with fewer than 10 correspondences, a correspondence ratio
    below `Icp/CorrespondenceRatio`, a correction of the guess beyond `Icp/MaxTranslation` /
    `Icp/MaxRotation`, or low complexity with `Icp/PointToPlaneLowComplexityStrategy` 0.
    `guess_covariance` (6×6, default huge) is the variance given to a free translation.
    """
    if len(source) < _MIN_CORRESPONDENCES or len(target) < _MIN_CORRESPONDENCES:
        return IcpResult(None, reason="too few points")
    axes = _THREE_DOF_AXES if settings.force_3dof else np.arange(6)
    k = axes.size
    strategy = settings.low_complexity_strategy if settings.point_to_plane else 2

    def constrained(normals: F64) -> tuple[float, F64 | None, F64]:
        """Complexity of the matched normals (map axes), the free translation when it is
        below `Icp/PointToPlaneMinComplexity` and strategy 1 applies, and the basis of the
        parameters the fit corrects."""
        cplx, free = normals_complexity(normals, settings.force_3dof)
        if cplx >= settings.min_complexity or strategy != 1:
            return cplx, None, np.eye(k)
        fk = np.array([free[0], free[1], 0.0]) if k == 3 else np.concatenate([free, np.zeros(3)])
        return cplx, free, _complement(fk)

    if tree is None:
        tree = cKDTree(target.points)
    t = np.array(guess, dtype=np.float64, copy=True)
    eps = settings.epsilon if settings.epsilon > 0 else _DEFAULT_EPSILON
    gate = settings.max_correspondence_distance
    it = 0
    for it in range(1, max(1, settings.iterations) + 1):
        src = source.points @ t[:3, :3].T + t[:3, 3]
        # coarse to fine (not upstream): 4×, 2×, then the gate, so that a guess a few
        # degrees off (the start of a turn) still finds the far points' correspondences
        coarse = gate * max(1.0, _COARSE_GATE / 2 ** (it - 1))
        dist, idx = tree.query(src, distance_upper_bound=coarse)
        ok = np.isfinite(dist)
        if int(ok.sum()) < _MIN_CORRESPONDENCES:
            return IcpResult(None, reason="too few correspondences", iterations=it)
        r, jac = _linearise(src[ok], target.points[idx[ok]], target.normals[idx[ok]],
                            t[:3, 3], settings.point_to_plane, axes)
        complexity, free_axis, basis = constrained(target.normals[idx[ok]])
        jb = jac @ basis
        step_b, *_ = np.linalg.lstsq(jb.T @ jb, -(jb.T @ r), rcond=1e-10)
        step = np.zeros(6)
        step[axes] = basis @ step_b
        t[:3, :3] = _rotation(step[3:]) @ t[:3, :3]
        t[:3, 3] = t[:3, 3] + step[:3]
        if float(np.linalg.norm(step)) < eps and coarse <= gate:
            break
    src = source.points @ t[:3, :3].T + t[:3, 3]
    dist, idx = tree.query(src, distance_upper_bound=gate)
    ok = np.isfinite(dist)
    n_ok = int(ok.sum())
    ratio = n_ok / len(source)
    if n_ok < _MIN_CORRESPONDENCES or ratio < settings.correspondence_ratio:
        return IcpResult(None, correspondences=n_ok, ratio=ratio,
                         reason="correspondence ratio", iterations=it)
    complexity, free_axis, basis = constrained(target.normals[idx[ok]])
    if strategy == 0 and complexity < settings.min_complexity:
        return IcpResult(None, correspondences=n_ok, ratio=ratio, complexity=complexity,
                         reason="low structural complexity", iterations=it)
    correction = se3_inverse(guess) @ t
    if (settings.max_translation > 0
            and float(np.linalg.norm(correction[:3, 3])) > settings.max_translation):
        return IcpResult(None, correspondences=n_ok, ratio=ratio, complexity=complexity,
                         reason="translation correction too large", iterations=it)
    if settings.max_rotation > 0 and rotation_angle(correction) > settings.max_rotation:
        return IcpResult(None, correspondences=n_ok, ratio=ratio, complexity=complexity,
                         reason="rotation correction too large", iterations=it)
    cov = icp_covariance(_variance_distances(source, target, t, src, dist, idx, ok, settings))
    if free_axis is not None:
        g = huge_covariance() if guess_covariance is None else np.asarray(guess_covariance)
        var_free = float(free_axis @ g[:3, :3] @ free_axis)
        fk = (np.array([free_axis[0], free_axis[1], 0.0]) if k == 3
              else np.concatenate([free_axis, np.zeros(3)]))
        cov_k = cov[np.ix_(axes, axes)] + var_free * np.outer(fk, fk)
        cov[np.ix_(axes, axes)] = np.minimum(cov_k, LOST_VARIANCE)
    return IcpResult(t, cov, n_ok, ratio, complexity, free_axis, "", it)


def _variance_distances(source: ScanCloud, target: ScanCloud, t: F64, src: F64, dist: F64,
                        idx: NDArray[np.intp], ok: NDArray[np.bool_],
                        settings: IcpSettings) -> F64:
    """The correspondences upstream's variance is taken over: with
    `Icp/ReciprocalCorrespondences` only pairs that are each other's nearest point; with
    `Icp/PointToPlane` only pairs whose normals differ by less than `Icp/MaxRotation`."""
    keep = np.flatnonzero(ok)
    matched = idx[keep]
    if settings.reciprocal_correspondences:
        _, back = cKDTree(src).query(target.points[matched])
        mutual = back == keep
        keep, matched = keep[mutual], matched[mutual]
    if settings.point_to_plane and settings.max_rotation > 0:
        n_src = source.normals[keep] @ t[:3, :3].T
        cos = np.sum(n_src * target.normals[matched], axis=1)
        aligned = cos > math.cos(settings.max_rotation)
        keep = keep[aligned]
    return np.asarray(dist[keep], dtype=np.float64)


def registration_covariance(target: ScanCloud, source: ScanCloud, transform: F64,
                            settings: IcpSettings, tree: cKDTree | None = None) -> F64:
    """`icp_covariance` of `source` registered into `target`'s frame at `transform` (the
    correspondences within `Icp/MaxCorrespondenceDistance`, filtered as `icp_register`'s)."""
    src = source.points @ transform[:3, :3].T + transform[:3, 3]
    dist, idx = (tree or cKDTree(target.points)).query(
        src, distance_upper_bound=settings.max_correspondence_distance)
    ok = np.isfinite(dist)
    return icp_covariance(_variance_distances(source, target, transform, src, dist, idx, ok,
                                              settings))


def correspondence_variance(distances: F64) -> float:
    """Upstream's `computeVarianceAndCorrespondences`: 2.1981 · the median squared
    correspondence distance (m²; for Gaussian residuals the variance, robust to outliers),
    floored at `_RESIDUAL_VARIANCE_FLOOR` · 10 so that the translation's variance stays at
    least (1 mm)²."""
    d = np.asarray(distances, dtype=np.float64)
    if d.size == 0:
        return LOST_VARIANCE
    d2 = np.sort(d * d)
    return max(2.1981 * float(d2[d2.size >> 1]), 10.0 * _RESIDUAL_VARIANCE_FLOOR)


def icp_covariance(distances: F64) -> F64:
    """6×6 covariance of an ICP registration as upstream's `RegistrationIcp` sets it: the
    correspondence variance / 10 on x, y, z, / 100 on roll, pitch, yaw."""
    var = correspondence_variance(distances) / 10.0
    return np.diag([var, var, var, var / 10.0, var / 10.0, var / 10.0]).astype(np.float64)


@njit(cache=True)
def _far_from(reference: F64, query: F64, radius: float, x0: float, y0: float, nx: int, ny: int,
              start: NDArray[np.int64], order: NDArray[np.int64]) -> NDArray[np.bool_]:
    """True for the query points with no reference point closer than `radius` (3D distance;
    the reference bucketed by `bucket_grid` in cells of `radius`)."""
    r2 = radius * radius
    out = np.ones(query.shape[0], np.bool_)
    for i in range(query.shape[0]):
        fx = math.floor((query[i, 0] - x0) / radius)
        fy = math.floor((query[i, 1] - y0) / radius)
        if fx < -1 or fy < -1 or fx > nx or fy > ny:
            continue
        cx, cy = int(fx), int(fy)
        found = False
        for gy in range(max(cy - 1, 0), min(cy + 1, ny - 1) + 1):
            for gx in range(max(cx - 1, 0), min(cx + 1, nx - 1) + 1):
                k = gy * nx + gx
                for j in range(start[k], start[k + 1]):
                    m = order[j]
                    dx = query[i, 0] - reference[m, 0]
                    dy = query[i, 1] - reference[m, 1]
                    dz = query[i, 2] - reference[m, 2]
                    if dx * dx + dy * dy + dz * dz < r2:
                        found = True
                        break
                if found:
                    break
            if found:
                break
        out[i] = not found
    return out


class ScanMap:
    """Local scan map of the odometry (`OdomF2M/ScanMaxSize`, `OdomF2M/ScanSubtractRadius`):
    points of key-frame clouds in the odometry frame, the oldest dropped first."""

    def __init__(self, max_size: int = 2000, subtract_radius: float = 0.05) -> None:
        self.max_size = max_size
        self.subtract_radius = subtract_radius
        self.cloud = ScanCloud.empty()
        self._born = np.zeros(0, np.int64)
        self._tree: cKDTree | None = None

    def __len__(self) -> int:
        return len(self.cloud)

    @property
    def tree(self) -> cKDTree:
        """k-d tree of the map points (rebuilt after a change)."""
        if self._tree is None:
            self._tree = cKDTree(self.cloud.points)
        return self._tree

    def add(self, cloud: ScanCloud, stamp: int) -> int:
        """Add the points of `cloud` (odometry frame) farther than the subtract radius from the
        map; returns how many were added."""
        if len(cloud) == 0:
            return 0
        keep = np.ones(len(cloud), bool)
        if len(self.cloud) and self.subtract_radius > 0:
            keep = self._far(cloud.points)
        n = int(keep.sum())
        if n == 0:
            return 0
        pts = np.concatenate([self.cloud.points, cloud.points[keep]])
        nrm = np.concatenate([self.cloud.normals, cloud.normals[keep]])
        born = np.concatenate([self._born, np.full(n, stamp, np.int64)])
        if self.max_size > 0 and pts.shape[0] > self.max_size:
            order = np.argsort(born, kind="stable")[pts.shape[0] - self.max_size:]
            order.sort()
            pts, nrm, born = pts[order], nrm[order], born[order]
        self.cloud = ScanCloud(pts, nrm)
        self._born = born
        self._tree = None
        return n

    def _far(self, points: F64) -> NDArray[np.bool_]:
        """Points with no map point closer than the subtract radius. A grid of the map in
        cells of the radius (no k-d tree is built for it: the map changes at every key frame,
        the tree is needed only when ICP runs); the same test as the tree's query."""
        ref = self.cloud.points
        r = float(self.subtract_radius)
        lo, hi = ref[:, :2].min(axis=0), ref[:, :2].max(axis=0)
        if float(np.prod((hi - lo) / r + 1.0)) > _MAX_SUBTRACT_CELLS:
            d, _ = self.tree.query(points, distance_upper_bound=r)
            return ~np.isfinite(d)
        x0, y0, nx, ny, start, order = bucket_grid(ref, r)
        return _far_from(ref, np.ascontiguousarray(points, np.float64), r, x0, y0, nx, ny,
                         start, order)

    def reset(self, cloud: ScanCloud | None = None, stamp: int = 0) -> None:
        """Forget the map (and start it with `cloud`)."""
        self.cloud = ScanCloud.empty()
        self._born = np.zeros(0, np.int64)
        self._tree = None
        if cloud is not None:
            self.add(cloud, stamp)
