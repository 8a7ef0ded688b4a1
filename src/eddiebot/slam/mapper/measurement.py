"""The measurement model: scan-matcher parameters from the config, odometry and scan-range
covariances, and the fusion of a match with odometry."""


from __future__ import annotations

import math

import numpy as np

from eddiebot.slam.config import SlamConfig
from eddiebot.slam.mapper.results import FloatArray
from eddiebot.slam.mapper.se2_rows import _wrap1
from eddiebot.slam.scan_matcher import (
    MatcherParams,
)


def matcher_params(
    config: SlamConfig, *, loop: bool = False, penalize: bool = True
) -> MatcherParams:
    """Matcher set-up for sequential matching (or the coarse loop search) from a config."""
    if loop:
        return MatcherParams(
            search_dimension=config.loop_search_space_dimension,
            resolution=config.loop_search_space_resolution,
            smear_deviation=config.loop_search_space_smear_deviation,
            coarse_angle_offset=config.coarse_search_angle_offset,
            coarse_angle_resolution=config.coarse_angle_resolution,
            fine_angle_step=config.fine_search_angle_offset,
            penalize=False,
            use_response_expansion=config.use_response_expansion,
        )
    return MatcherParams(
        search_dimension=config.correlation_search_space_dimension,
        resolution=config.correlation_search_space_resolution,
        smear_deviation=config.correlation_search_space_smear_deviation,
        coarse_angle_offset=config.coarse_search_angle_offset,
        coarse_angle_resolution=config.coarse_angle_resolution,
        fine_angle_step=config.fine_search_angle_offset,
        penalize=penalize,
        distance_variance_penalty=config.distance_variance_penalty,
        angle_variance_penalty=config.angle_variance_penalty,
        minimum_distance_penalty=config.minimum_distance_penalty,
        minimum_angle_penalty=config.minimum_angle_penalty,
        use_response_expansion=config.use_response_expansion,
        coarse_heading_variance=config.match_coarse_heading_variance,
    )



_NO_HEADING_VARIANCE = 1.0e4
"""Odometry heading variance (rad²) standing for no heading information in a fused step."""


SEQUENTIAL_POSITION_VARIANCE_SCALE = 0.2
"""Factor on a sequential match's position covariance (Karto's) in its graph edge.

Karto's covariance is the response-weighted spread of the candidates within 0.1 of the best
response, divided by it: it measures the width of the smeared response peak (a fraction of
``correlation_search_space_smear_deviation``², however many points pin the pose), and along a
corridor the search window. Whitened against the corrected Intel and ACES logs (degraded
odometry), sequential edges with it had a median χ² of 0.75–0.78 (Intel) and 0.54 (ACES)
(χ²₃: 2.37), their position variance ~5× the true error's along both the weak and the strong
direction, the heading's close (median 0.15–0.31 against χ²₁'s 0.45); a false loop then fits
by stretching a few corridor edges cheaply. With the position block ×0.2 the medians are
1.7–2.0 and per direction 0.35–0.57. The match's own covariance (warnings, fusion thresholds,
results) stays Karto's; with ``fuse_odometry`` the match's information in the directions it
keeps is ×5 (docs/benchmarks/slam.md#slam-sequential-covariance)."""


def sequential_edge_covariance(covariance: FloatArray) -> FloatArray:
    """The covariance a sequential scan-match edge carries: Karto's match covariance with its
    position block scaled by `SEQUENTIAL_POSITION_VARIANCE_SCALE` (heading unchanged)."""
    out = np.array(covariance, dtype=np.float64)
    out[:2, :2] *= SEQUENTIAL_POSITION_VARIANCE_SCALE
    return out


def _odometry_covariance(delta: FloatArray, config: SlamConfig | None = None) -> FloatArray:
    """Covariance (x, y, theta) of an odometry increment under the config's noise model."""
    cfg = config or SlamConfig()
    d = math.hypot(float(delta[0]), float(delta[1]))
    sx = cfg.odometry_translation_sigma + cfg.odometry_translation_noise * d
    sth = (
        cfg.odometry_rotation_sigma
        + cfg.odometry_rotation_noise * abs(float(delta[2]))
        + cfg.odometry_rotation_noise_per_meter * d
    )
    return np.diag([sx * sx, sx * sx, sth * sth])


def _rotate_covariance(cov: FloatArray, theta: float) -> FloatArray:
    """Express a map-frame (x, y, theta) covariance in a frame turned by ``theta``."""
    rot = np.eye(3)
    c, s = math.cos(theta), math.sin(theta)
    rot[:2, :2] = [[c, s], [-s, c]]
    return np.asarray(rot @ cov @ rot.T)


def constrained_information(
    covariance: FloatArray, max_variance: float
) -> tuple[FloatArray, int]:
    """Information matrix of a match keeping only its well-observed position directions.

    The position block's eigen-directions with a variance above ``max_variance`` (m²) carry
    no information (a corridor match says nothing about the position along the corridor; the
    correlative search's window only bounds that variance). Returns the (3, 3) information
    and the number of position directions dropped (0, 1 or 2).
    """
    cov = 0.5 * (covariance + covariance.T)
    w, v = np.linalg.eigh(cov[:2, :2])
    w = np.maximum(w, 1e-12)
    keep = w <= max_variance
    info = np.zeros((3, 3))
    # position block from the kept directions; the heading kept as Karto reports it (no
    # cross terms: the search estimates the two separately)
    info[:2, :2] = (v[:, keep] / w[keep]) @ v[:, keep].T
    info[2, 2] = 1.0 / max(float(cov[2, 2]), 1e-12)
    return info, int(np.count_nonzero(~keep))


def scan_position_covariance(
    points: FloatArray,
    normals: FloatArray,
    range_sigma: float,
    range_sigma_quadratic: float = 0.0,
) -> FloatArray:
    """Position covariance (2, 2; the points' frame, m²) a scan's geometry allows a match.

    Degeneracy analysis of the point-to-line fit (Zhang, Kaess and Singh 2016, "On degeneracy
    of optimization-based state estimation problems"): the position block of its Hessian,
    ``H = Σ n nᵀ / σ²`` over the points with a normal (``σ = range_sigma +
    range_sigma_quadratic · r²``, each point's range error at range r), has eigen-directions
    ``d`` with information ``λ_d``. The variance along ``d`` is ``(Σ (n·d)² + 1) / λ_d``:
    the information-weighted mean range variance of the points whose normals pin ``d`` — an
    error they share, such as a depth camera's range bias, does not average out over many
    points — plus one point's worth of random error. Along a direction no line observes (a
    corridor's length) λ_d is near zero and the variance unbounded; along one only far points
    pin (a corridor's end wall seen from metres away) it is their range variance.
    """
    ok = np.isfinite(normals[:, 0])
    n = normals[ok]
    if n.shape[0] == 0:
        return np.eye(2) * 1.0e6
    r2 = np.einsum("ij,ij->i", points[ok], points[ok])
    sigma = range_sigma + range_sigma_quadratic * r2
    w = 1.0 / np.maximum(sigma * sigma, 1e-12)
    h = (n * w[:, None]).T @ n
    lam, v = np.linalg.eigh(0.5 * (h + h.T))
    count = np.sum((n @ v) ** 2, axis=0)
    var = np.minimum((count + 1.0) / np.maximum(lam, 1e-12), 1.0e6)
    return np.asarray((v * var) @ v.T)


def fuse_increments(
    z_odom: FloatArray, cov_odom: FloatArray, z_match: FloatArray, info_match: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Information-weighted mean of two measurements of one SE(2) increment (x, y, theta).

    Linearised about the odometry increment; returns the fused increment and its covariance.
    """
    info_odom = np.linalg.inv(cov_odom)
    dz = np.asarray(z_match, dtype=np.float64) - z_odom
    dz[2] = float(_wrap1(dz[2]))
    info = info_odom + info_match
    cov = np.linalg.inv(info)
    fused = np.asarray(z_odom, dtype=np.float64) + cov @ (info_match @ dz)
    fused[2] = float(_wrap1(fused[2]))
    return fused, 0.5 * (cov + cov.T)
