"""Adaptive Monte Carlo localisation core (``nav2_amcl``): KLD-sampling particle filter,
differential-drive odometry motion model, likelihood-field laser models (``likelihood_field``:
Nav2's sum of cubed beam probabilities; ``likelihood_field_prob``: the product of beam
probabilities with optional beam skipping, ``do_beamskip``).

Pure core: the caller passes odometry poses (odom frame), laser scans with the laser's pose
in the base frame, and reads back the pose estimate (map frame) with its covariance.
Parameter names and defaults are Nav2's (``pf_err``/``pf_z`` are the KLD bound's error and
quantile, ROS 1's ``kld_err``/``kld_z``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import ndimage

from eddiebot.maps import OccupancyMap
from eddiebot.nav.errors import LocalizationError
from eddiebot.nav.params import require
from eddiebot.nav.types import wrap_angle


@dataclass(frozen=True)
class AmclConfig:
    """``amcl`` parameters (Jazzy code defaults)."""

    alpha1: float = 0.2
    alpha2: float = 0.2
    alpha3: float = 0.2
    alpha4: float = 0.2
    alpha5: float = 0.2
    base_frame_id: str = "base_footprint"
    beam_skip_distance: float = 0.5
    beam_skip_error_threshold: float = 0.9
    beam_skip_threshold: float = 0.3
    do_beamskip: bool = False
    global_frame_id: str = "map"
    lambda_short: float = 0.1
    laser_likelihood_max_dist: float = 2.0
    laser_max_range: float = 100.0
    laser_min_range: float = -1.0
    laser_model_type: str = "likelihood_field"
    max_beams: int = 60
    max_particles: int = 2000
    min_particles: int = 500
    odom_frame_id: str = "odom"
    pf_err: float = 0.05
    pf_z: float = 0.99
    recovery_alpha_fast: float = 0.0
    recovery_alpha_slow: float = 0.0
    resample_interval: int = 1
    robot_model_type: str = "nav2_amcl::DifferentialMotionModel"
    save_pose_rate: float = 0.5
    sigma_hit: float = 0.2
    tf_broadcast: bool = True
    transform_tolerance: float = 1.0
    update_min_a: float = 0.2
    update_min_d: float = 0.25
    z_hit: float = 0.5
    z_max: float = 0.05
    z_rand: float = 0.5
    z_short: float = 0.05
    scan_topic: str = "scan"
    map_topic: str = "map"
    set_initial_pose: bool = False
    always_reset_initial_pose: bool = False
    first_map_only: bool = False
    initial_pose_x: float = 0.0
    initial_pose_y: float = 0.0
    initial_pose_z: float = 0.0
    initial_pose_yaw: float = 0.0
    #: eddiebot's addition: "multinomial" (Nav2's pf) or "systematic" (lower resampling noise)
    resample_method: str = "multinomial"
    #: eddiebot's addition: build the likelihood field from the obstacles' surfaces (occupied
    #: cells with a non-occupied 4-neighbour) instead of every occupied cell (Nav2), so a beam
    #: endpoint inside a thick obstacle (a floor plan's wall, a solid shelf rack in a footprint
    #: map) scores by its depth below the surface instead of as a perfect hit
    laser_likelihood_surfaces_only: bool = False

    def validate(self, server: str = "amcl") -> None:
        require(self.min_particles > 0, server, "min_particles", self.min_particles, "must be > 0")
        require(self.max_particles >= self.min_particles, server, "max_particles",
                self.max_particles, "must be >= min_particles")
        require(self.laser_model_type in LASER_MODELS, server, "laser_model_type",
                self.laser_model_type, f"must be one of {list(LASER_MODELS)} (beam is not "
                "implemented)")
        require(self.robot_model_type.replace("/", "::").endswith("DifferentialMotionModel"),
                server, "robot_model_type", self.robot_model_type,
                "only the differential motion model is implemented")
        require(self.max_beams >= 2, server, "max_beams", self.max_beams, "must be >= 2")
        require(self.resample_interval >= 1, server, "resample_interval",
                self.resample_interval, "must be >= 1")
        require(0.0 < self.pf_err < 1.0, server, "pf_err", self.pf_err, "must be in (0, 1)")
        require(self.sigma_hit > 0.0, server, "sigma_hit", self.sigma_hit, "must be > 0")
        require(self.laser_likelihood_max_dist > 0.0, server, "laser_likelihood_max_dist",
                self.laser_likelihood_max_dist, "must be > 0")
        require(0.0 <= self.beam_skip_threshold <= 1.0, server, "beam_skip_threshold",
                self.beam_skip_threshold, "must be in [0, 1]")
        require(self.resample_method in ("multinomial", "systematic"), server, "resample_method",
                self.resample_method, "must be multinomial or systematic")
        require(self.update_min_d >= 0.0, server, "update_min_d", self.update_min_d, "must be >= 0")
        require(self.update_min_a >= 0.0, server, "update_min_a", self.update_min_a, "must be >= 0")


#: ``laser_model_type`` values implemented
LASER_MODELS = ("likelihood_field", "likelihood_field_prob")

#: Initial covariance of :meth:`Amcl.initialize` called without one (ROS 1 amcl's
#: initial_cov_xx/yy/aa). Nav2's ``initialpose`` and ``set_initial_pose`` pass theirs as
#: given: an all-zero covariance puts every particle on the pose.
DEFAULT_INITIAL_COV = np.diag([0.5 * 0.5, 0.5 * 0.5, (math.pi / 12.0) ** 2])

#: ``pf->dist_threshold``: the filter has converged when every particle is within this of
#: the mean in x and in y (m).
CONVERGED_DIST = 0.5

# KD-tree bin size of the KLD bound (pf_kdtree: 0.5 m, 0.5 m, 10 deg).
_BIN = (0.5, 0.5, math.radians(10.0))


def _angle_diff(a: npt.NDArray[np.float64] | float, b: npt.NDArray[np.float64] | float
                ) -> npt.NDArray[np.float64]:
    d = np.arctan2(np.sin(np.asarray(a) - b), np.cos(np.asarray(a) - b))
    return np.asarray(d)


def likelihood_field(occ_map: OccupancyMap, max_dist: float,
                     surfaces_only: bool = False) -> npt.NDArray[np.float64]:
    """Distance (m) from every cell to the nearest occupied (== 100) cell, capped at max_dist.
    ``surfaces_only``: to the nearest occupied cell that has a non-occupied 4-neighbour (cells
    on the map's edge count the outside as occupied), so the inside of a thick obstacle is
    as far from a surface as it is deep."""
    occupied = occ_map.data == 100
    if surfaces_only:
        interior = ndimage.binary_erosion(occupied, structure=ndimage.generate_binary_structure(2, 1),
                                          border_value=1)
        occupied &= ~interior
    if not occupied.any():
        return np.full(occupied.shape, max_dist)
    d = ndimage.distance_transform_edt(~occupied) * occ_map.resolution
    return np.minimum(d, max_dist)


@njit(cache=True)
def _endpoint_distance(px: float, py: float, angle: float, r: float, dist: np.ndarray,
                       ox: float, oy: float, res: float) -> float:
    """Likelihood-field distance at a beam's endpoint; -1 when it falls off the map."""
    h, w = dist.shape
    mi = math.floor((px + r * math.cos(angle) - ox) / res)
    mj = math.floor((py + r * math.sin(angle) - oy) / res)
    if mi < 0 or mj < 0 or mi >= w or mj >= h:
        return -1.0
    return float(dist[mj, mi])


@njit(cache=True)
def _laser_weights(
    particles: np.ndarray, weights: np.ndarray, ranges: np.ndarray, bearings: np.ndarray,
    lx: float, ly: float, lyaw: float, dist: np.ndarray, ox: float, oy: float, res: float,
    max_occ_dist: float, range_max: float, z_hit: float, z_rand: float, sigma_hit: float,
) -> float:
    """LikelihoodFieldModel::sensorFunction; multiplies ``weights`` in place, returns the sum."""
    denom = 2.0 * sigma_hit * sigma_hit
    rand_mult = 1.0 / range_max
    total = 0.0
    for k in range(particles.shape[0]):
        c = math.cos(particles[k, 2])
        s = math.sin(particles[k, 2])
        px = particles[k, 0] + c * lx - s * ly
        py = particles[k, 1] + s * lx + c * ly
        pth = particles[k, 2] + lyaw
        p = 1.0
        for i in range(ranges.shape[0]):
            r = ranges[i]
            if r >= range_max or r != r:
                continue
            z = _endpoint_distance(px, py, pth + bearings[i], r, dist, ox, oy, res)
            if z < 0.0:
                z = max_occ_dist
            pz = z_hit * math.exp(-(z * z) / denom) + z_rand * rand_mult
            p += pz * pz * pz
        weights[k] *= p
        total += weights[k]
    return total


@njit(cache=True)
def _laser_beam_probs(
    particles: np.ndarray, ranges: np.ndarray, bearings: np.ndarray,
    lx: float, ly: float, lyaw: float, dist: np.ndarray, ox: float, oy: float, res: float,
    max_occ_dist: float, range_max: float, z_hit: float, z_rand: float, sigma_hit: float,
    beam_skip_distance: float,
) -> tuple[np.ndarray, np.ndarray]:
    """LikelihoodFieldModelProb's per-beam probabilities ``pz`` (particles x beams; 1.0 for
    beams it ignores: max range, NaN) and per beam the number of particles whose endpoint lies
    within ``beam_skip_distance`` of an obstacle."""
    n, m = particles.shape[0], ranges.shape[0]
    denom = 2.0 * sigma_hit * sigma_hit
    rand_mult = 1.0 / range_max
    max_dist_prob = math.exp(-(max_occ_dist * max_occ_dist) / denom)
    pz = np.ones((n, m))
    count = np.zeros(m, dtype=np.int64)
    for k in range(n):
        c = math.cos(particles[k, 2])
        s = math.sin(particles[k, 2])
        px = particles[k, 0] + c * lx - s * ly
        py = particles[k, 1] + s * lx + c * ly
        pth = particles[k, 2] + lyaw
        for i in range(m):
            r = ranges[i]
            if r >= range_max or r != r:
                continue
            z = _endpoint_distance(px, py, pth + bearings[i], r, dist, ox, oy, res)
            if z < 0.0:
                p = z_hit * max_dist_prob
            else:
                if z < beam_skip_distance:
                    count[i] += 1
                p = z_hit * math.exp(-(z * z) / denom)
            pz[k, i] = p + z_rand * rand_mult
    return pz, count


def _resample_limit(k: int, pf_err: float, pf_z: float, n_min: int, n_max: int) -> int:
    """``pf_resample_limit``: KLD bound on the particle count for k occupied bins."""
    if k <= 1:
        return n_max
    a = 1.0
    b = 2.0 / (9.0 * (k - 1))
    c = math.sqrt(2.0 / (9.0 * (k - 1))) * pf_z
    x = a - b + c
    n = math.ceil((k - 1) / (2.0 * pf_err) * x * x * x)
    return int(min(max(n, n_min), n_max))


class Amcl:
    """The particle filter. ``rng`` seeds the sampling for reproducible runs."""

    def __init__(self, config: AmclConfig | None = None, occupancy_map: OccupancyMap | None = None,
                 seed: int | None = None) -> None:
        self.config = config or AmclConfig()
        self.config.validate()
        self.rng = np.random.default_rng(seed)
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        self._map: OccupancyMap | None = None
        self._dist = np.zeros((1, 1))
        self._free = np.zeros((0, 2))
        self._odom_last: npt.NDArray[np.float64] | None = None
        self._force_update = True
        self._resample_count = 0
        self.w_slow = 0.0
        self.w_fast = 0.0
        self._estimate = np.zeros(3)
        self._cov = np.zeros((3, 3))
        self.converged = False
        #: beams left out by the last beam-skipping update (0 when it was not used)
        self.skipped_beams = 0
        if occupancy_map is not None:
            self.set_map(occupancy_map)
        if self.config.set_initial_pose:
            c = self.config
            # Nav2 sends these as a PoseWithCovarianceStamped with a zero covariance
            self.initialize((c.initial_pose_x, c.initial_pose_y, c.initial_pose_yaw),
                            np.zeros((3, 3)))

    # --- setup ----------------------------------------------------------------------------
    def set_map(self, occupancy_map: OccupancyMap) -> None:
        self._map = occupancy_map
        self._dist = np.ascontiguousarray(
            likelihood_field(occupancy_map, self.config.laser_likelihood_max_dist,
                             self.config.laser_likelihood_surfaces_only))
        jj, ii = np.nonzero(occupancy_map.data == 0)
        res = occupancy_map.resolution
        self._free = np.stack([occupancy_map.origin[0] + (ii + 0.5) * res,
                               occupancy_map.origin[1] + (jj + 0.5) * res], axis=-1)

    def initialize(self, pose: npt.ArrayLike, cov: npt.ArrayLike | None = None) -> None:
        """Gaussian particle cloud around ``pose`` (``pf_init``; max_particles samples)."""
        mean = np.asarray(pose, dtype=np.float64)[:3]
        cov_m = DEFAULT_INITIAL_COV if cov is None else np.asarray(cov, dtype=np.float64)
        n = self.config.max_particles
        # pf_pdf_gaussian_sample: mean + eigenvectors * sqrt(eigenvalues) * N(0, 1); a zero
        # covariance gives n copies of the mean.
        vals, vecs = np.linalg.eigh(0.5 * (cov_m + cov_m.T))
        scale = vecs * np.sqrt(np.maximum(vals, 0.0))
        self.particles = mean + self.rng.standard_normal((n, 3)) @ scale.T
        self.particles[:, 2] = _angle_diff(self.particles[:, 2], 0.0)
        self.weights = np.full(n, 1.0 / n)
        self.w_slow = self.w_fast = 0.0
        self._force_update = True
        self._odom_last = None
        self.converged = False  # pf_init_converged: decided at the next resampling
        self._compute_estimate()

    def initialize_global(self) -> None:
        """Uniform particles over the free cells (``globalLocalizationCallback``)."""
        n = self.config.max_particles
        self.particles = self._random_poses(n)
        self.weights = np.full(n, 1.0 / n)
        self._force_update = True
        self.converged = False
        self._compute_estimate()

    def _random_poses(self, n: int) -> npt.NDArray[np.float64]:
        if self._free.shape[0] == 0:
            raise LocalizationError("no free cells in the map for random particles")
        idx = self.rng.integers(0, self._free.shape[0], n)
        out = np.empty((n, 3))
        out[:, :2] = self._free[idx]
        out[:, 2] = self.rng.uniform(-math.pi, math.pi, n)
        return out

    # --- filter steps ---------------------------------------------------------------------
    def motion_update(self, delta_odom: npt.ArrayLike, old_odom_yaw: float) -> None:
        """``DifferentialMotionModel::odometryUpdate`` with odometry delta (dx, dy, dyaw)
        expressed in the odom frame and the previous odometry yaw."""
        cfg = self.config
        d = np.asarray(delta_odom, dtype=np.float64)
        trans = math.hypot(d[0], d[1])
        rot1 = 0.0 if trans < 0.01 else float(_angle_diff(math.atan2(d[1], d[0]), old_odom_yaw))
        rot2 = float(_angle_diff(d[2], rot1))
        rot1_noise = min(abs(float(_angle_diff(rot1, 0.0))), abs(float(_angle_diff(rot1, math.pi))))
        rot2_noise = min(abs(float(_angle_diff(rot2, 0.0))), abs(float(_angle_diff(rot2, math.pi))))
        n = self.particles.shape[0]
        rng = self.rng
        s1 = math.sqrt(cfg.alpha1 * rot1_noise ** 2 + cfg.alpha2 * trans ** 2)
        st = math.sqrt(cfg.alpha3 * trans ** 2 + cfg.alpha4 * rot1_noise ** 2 + cfg.alpha4 * rot2_noise ** 2)
        s2 = math.sqrt(cfg.alpha1 * rot2_noise ** 2 + cfg.alpha2 * trans ** 2)
        rot1_hat = _angle_diff(rot1, rng.normal(0.0, 1.0, n) * s1)
        trans_hat = trans - rng.normal(0.0, 1.0, n) * st
        rot2_hat = _angle_diff(rot2, rng.normal(0.0, 1.0, n) * s2)
        p = self.particles
        p[:, 0] += trans_hat * np.cos(p[:, 2] + rot1_hat)
        p[:, 1] += trans_hat * np.sin(p[:, 2] + rot1_hat)
        p[:, 2] = _angle_diff(p[:, 2] + rot1_hat + rot2_hat, 0.0)

    def sensor_update(self, ranges: npt.ArrayLike, angle_min: float, angle_increment: float,
                      range_min: float, range_max: float,
                      laser_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """Likelihood-field update with ``max_beams`` evenly subsampled beams."""
        if self._map is None:
            raise LocalizationError("no map")
        cfg = self.config
        r = np.asarray(ranges, dtype=np.float64).copy()
        rmax = cfg.laser_max_range if cfg.laser_max_range > 0 else range_max
        rmin = cfg.laser_min_range if cfg.laser_min_range > 0 else range_min
        rmax = min(rmax, range_max) if cfg.laser_max_range > 0 else range_max
        r[~np.isfinite(r) | (r <= rmin)] = rmax
        bearings = angle_min + angle_increment * np.arange(r.shape[0])
        m = self._map
        self.skipped_beams = 0
        if cfg.laser_model_type == "likelihood_field":
            step = max(1, (r.shape[0] - 1) // (cfg.max_beams - 1))
            sel = np.arange(0, r.shape[0], step)
            total = _laser_weights(
                self.particles, self.weights, np.ascontiguousarray(r[sel]),
                np.ascontiguousarray(bearings[sel]), float(laser_pose[0]), float(laser_pose[1]),
                float(laser_pose[2]), self._dist, m.origin[0], m.origin[1], m.resolution,
                cfg.laser_likelihood_max_dist, rmax, cfg.z_hit, cfg.z_rand, cfg.sigma_hit,
            )
        else:
            total = self._prob_weights(r, np.asarray(bearings, dtype=np.float64), rmax, laser_pose)
        n = self.weights.shape[0]
        if total > 0.0:
            w_avg = total / n
            self.weights /= total
            if self.w_slow == 0.0:
                self.w_slow = w_avg
            else:
                self.w_slow += cfg.recovery_alpha_slow * (w_avg - self.w_slow)
            if self.w_fast == 0.0:
                self.w_fast = w_avg
            else:
                self.w_fast += cfg.recovery_alpha_fast * (w_avg - self.w_fast)
        else:
            self.weights[:] = 1.0 / n

    def _prob_weights(self, r: npt.NDArray[np.float64], bearings: npt.NDArray[np.float64],
                      rmax: float, laser_pose: tuple[float, float, float]) -> float:
        """``LikelihoodFieldModelProb::sensorFunction``: weight *= prod(pz) over the beams
        (every ``ceil(n / max_beams)``-th). With ``do_beamskip`` once the filter has
        converged, a beam counts only when more than ``beam_skip_threshold`` of the particles
        put its endpoint within ``beam_skip_distance`` of an obstacle (the others see
        something the map lacks: a person, a moved chair); if ``beam_skip_error_threshold``
        or more of the beams would be skipped, the pose is probably wrong and all count."""
        cfg = self.config
        assert self._map is not None
        m = self._map
        step = max(1, math.ceil(r.shape[0] / cfg.max_beams))
        sel = np.arange(0, r.shape[0], step)
        pz, count = _laser_beam_probs(
            self.particles, np.ascontiguousarray(r[sel]), np.ascontiguousarray(bearings[sel]),
            float(laser_pose[0]), float(laser_pose[1]), float(laser_pose[2]), self._dist,
            m.origin[0], m.origin[1], m.resolution, cfg.laser_likelihood_max_dist, rmax,
            cfg.z_hit, cfg.z_rand, cfg.sigma_hit, cfg.beam_skip_distance)
        logp = np.log(pz)
        if cfg.do_beamskip and self.converged:
            n = self.particles.shape[0]
            use = count / n > cfg.beam_skip_threshold
            # upstream counts every one of max_beams slots, including unused ones
            skipped = int(np.count_nonzero(~use)) + max(0, cfg.max_beams - sel.shape[0])
            if skipped < cfg.max_beams * cfg.beam_skip_error_threshold:
                logp = logp[:, use]
                self.skipped_beams = skipped
        self.weights *= np.exp(logp.sum(axis=1))
        return float(self.weights.sum())

    def _update_converged(self) -> bool:
        """``pf_update_converged``: every particle within CONVERGED_DIST of the (unweighted)
        mean in x and in y."""
        p = self.particles
        if p.shape[0] == 0:
            self.converged = False
        else:
            dev = np.abs(p[:, :2] - p[:, :2].mean(axis=0))
            self.converged = bool(np.all(dev <= CONVERGED_DIST))
        return self.converged

    def resample(self) -> None:
        """``pf_update_resample``: KLD-adaptive count, random-pose injection when w_fast < w_slow.
        The count comes from Nav2's sample-by-sample KLD bound (multinomial draws); with
        ``resample_method`` "systematic" the kept particles are then drawn by systematic
        resampling instead of those multinomial draws."""
        cfg = self.config
        w_diff = 0.0
        if self.w_slow > 0.0:
            w_diff = max(0.0, 1.0 - self.w_fast / self.w_slow)
        cum = np.cumsum(self.weights)
        cum /= cum[-1]
        n_max = cfg.max_particles
        draws = np.searchsorted(cum, self.rng.random(n_max), side="right")
        draws = np.minimum(draws, self.particles.shape[0] - 1)
        new = self.particles[draws].copy()
        inject = np.zeros(n_max, dtype=bool)
        if w_diff > 0.0:
            inject = self.rng.random(n_max) < w_diff
            if inject.any():
                new[inject] = self._random_poses(int(inject.sum()))
        # KLD: grow the set until its size exceeds the bound for its occupied bins.
        keys = np.floor(new / np.asarray(_BIN)).astype(np.int64)
        # Occupied-bin count after each sample: a bin is new at its first occurrence.
        _, first = np.unique(keys, axis=0, return_index=True)
        is_new = np.zeros(n_max, dtype=np.int64)
        is_new[first] = 1
        k = np.cumsum(is_new)
        limits = np.array([_resample_limit(int(v), cfg.pf_err, cfg.pf_z, cfg.min_particles, n_max)
                           for v in np.unique(k)])
        lim_of_k = dict(zip(np.unique(k).tolist(), limits.tolist()))
        over = np.nonzero(np.arange(1, n_max + 1) > np.array([lim_of_k[v] for v in k.tolist()]))[0]
        count = int(over[0]) + 1 if over.size else n_max
        if cfg.resample_method == "systematic":
            # Same size, drawn with one random offset on an even comb over the cumulative
            # weights: each particle gets floor or ceil of count * weight copies, so equal
            # weights reproduce the set instead of letting its mean wander.
            comb = (self.rng.random() + np.arange(count)) / count
            idx = np.minimum(np.searchsorted(cum, comb, side="right"), self.particles.shape[0] - 1)
            kept = self.particles[idx].copy()
            if w_diff > 0.0 and inject.any():
                sel = inject[:count]
                kept[sel] = new[:count][sel]
            new = self.rng.permutation(kept)
        self.particles = new[:count]
        self.weights = np.full(count, 1.0 / count)
        if w_diff > 0.0:
            self.w_slow = self.w_fast = 0.0
        self._update_converged()

    def update(
        self,
        odom_pose: npt.ArrayLike,
        ranges: npt.ArrayLike,
        angle_min: float,
        angle_increment: float,
        range_min: float,
        range_max: float,
        laser_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> bool:
        """One ``laserReceived``: motion update once the robot moved beyond ``update_min_d``
        (per axis) or ``update_min_a``, then sensor update and resampling every
        ``resample_interval`` updates. Returns True when the filter was updated."""
        if self.particles.shape[0] == 0:
            raise LocalizationError("filter not initialised (no initial pose)")
        cfg = self.config
        odom = np.asarray(odom_pose, dtype=np.float64)[:3].copy()
        if self._odom_last is None:
            self._odom_last = odom
            moved = True
        else:
            delta = odom - self._odom_last
            delta[2] = wrap_angle(float(delta[2]))
            moved = (abs(delta[0]) > cfg.update_min_d or abs(delta[1]) > cfg.update_min_d
                     or abs(delta[2]) > cfg.update_min_a)
            if moved:
                self.motion_update(delta, float(self._odom_last[2]))
                self._odom_last = odom
        if not (moved or self._force_update):
            return False
        self._force_update = False
        self.sensor_update(ranges, angle_min, angle_increment, range_min, range_max, laser_pose)
        self._resample_count += 1
        if self._resample_count % cfg.resample_interval == 0:
            self.resample()
        self._compute_estimate()
        return True

    # --- estimate -------------------------------------------------------------------------
    def _compute_estimate(self) -> None:
        """Mean and covariance of the heaviest cluster (particles in touching KD bins)."""
        p = self.particles
        w = self.weights
        keys = np.floor(p / np.asarray(_BIN)).astype(np.int64)
        keys -= keys.min(axis=0)
        shape = tuple(int(v) + 1 for v in keys.max(axis=0))
        grid = np.zeros(shape, dtype=bool)
        grid[keys[:, 0], keys[:, 1], keys[:, 2]] = True
        labels, nlab = ndimage.label(grid, structure=np.ones((3, 3, 3), dtype=bool))
        plabel = labels[keys[:, 0], keys[:, 1], keys[:, 2]] - 1
        cw = np.bincount(plabel, weights=w, minlength=nlab)
        best = int(np.argmax(cw))
        sel = plabel == best
        ws = w[sel] / max(cw[best], 1e-300)
        ps = p[sel]
        mx = float(ws @ ps[:, 0])
        my = float(ws @ ps[:, 1])
        mth = math.atan2(float(ws @ np.sin(ps[:, 2])), float(ws @ np.cos(ps[:, 2])))
        d = np.stack([ps[:, 0] - mx, ps[:, 1] - my, _angle_diff(ps[:, 2], mth)], axis=-1)
        cov = (d * ws[:, None]).T @ d
        # Yaw variance as upstream: -2 ln(R) of the mean resultant length.
        r = math.hypot(float(ws @ np.cos(ps[:, 2])), float(ws @ np.sin(ps[:, 2])))
        cov[2, 2] = -2.0 * math.log(max(r, 1e-12))
        cov[2, :2] = cov[:2, 2] = 0.0
        self._estimate = np.array([mx, my, mth])
        self._cov = cov

    @property
    def estimate(self) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(pose (x, y, yaw) in the map frame, 3 x 3 covariance)."""
        return self._estimate.copy(), self._cov.copy()


@dataclass(frozen=True)
class LocalizationLimits:
    """When a localization source can no longer be trusted to drive on (eddiebot's addition;
    Nav2 leaves it to the user). ``max_xy_std`` (m) and ``max_yaw_std`` (rad): largest
    standard deviation of the published pose (``amcl_pose``'s covariance); ``tf_timeout`` (s):
    largest age of the newest ``map → odom`` transform (AMCL future-dates it by its
    ``transform_tolerance``, so the age counts from that stamp). A static transform (stamp 0)
    never goes stale. Zero or negative disables a limit."""

    max_xy_std: float = 0.5
    max_yaw_std: float = 0.5
    tf_timeout: float = 1.0


def localization_problem(limits: LocalizationLimits, now_ns: int,
                         cov: npt.ArrayLike | None = None,
                         tf_stamp_ns: int | None = None) -> str:
    """Why the robot must not drive on its localization, or "" when it may.

    ``cov``: the last published pose covariance (3 x 3 over x, y, yaw, or the 6 x 6 /
    36-element ROS layout), None when no pose was published yet (not checked);
    ``tf_stamp_ns``: stamp of the newest ``map → odom``, None when there is none at all."""
    if tf_stamp_ns is None:
        return "no map -> odom transform (localization not running)"
    if limits.tf_timeout > 0.0 and tf_stamp_ns != 0:
        age = (now_ns - tf_stamp_ns) * 1e-9
        if age > limits.tf_timeout:
            return f"map -> odom is stale ({age:.2f} s old > {limits.tf_timeout:g} s)"
    if cov is not None:
        c = np.asarray(cov, dtype=np.float64)
        if c.size == 36:
            c6 = c.reshape(6, 6)
            c = np.array([[c6[0, 0], c6[0, 1], 0.0], [c6[1, 0], c6[1, 1], 0.0],
                          [0.0, 0.0, c6[5, 5]]])
        c = c.reshape(3, 3)
        if not np.all(np.isfinite(c)):
            return "localization covariance is not finite"
        xy = math.sqrt(max(float(np.linalg.eigvalsh(c[:2, :2]).max()), 0.0))
        yaw = math.sqrt(max(float(c[2, 2]), 0.0))
        if limits.max_xy_std > 0.0 and xy > limits.max_xy_std:
            return f"localization lost: position std {xy:.2f} m > {limits.max_xy_std:g} m"
        if limits.max_yaw_std > 0.0 and yaw > limits.max_yaw_std:
            return f"localization lost: heading std {yaw:.2f} rad > {limits.max_yaw_std:g} rad"
    return ""


__all__ = ["CONVERGED_DIST", "DEFAULT_INITIAL_COV", "LASER_MODELS", "Amcl", "AmclConfig",
           "LocalizationLimits", "likelihood_field", "localization_problem"]
