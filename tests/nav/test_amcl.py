"""AMCL: convergence from a wrong-but-near initial pose on a synthetic map; KLD bound; the
probabilistic likelihood field with beam skipping; initial covariance; systematic resampling;
the lost-localization check."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.maps import OccupancyMap
from eddiebot.nav.amcl import (
    Amcl,
    AmclConfig,
    LocalizationLimits,
    _resample_limit,
    localization_problem,
)
from eddiebot.nav.config import _flatten_amcl
from eddiebot.nav.errors import LocalizationError, ParameterError
from eddiebot.nav.params import from_params

RES = 0.05


def _world() -> np.ndarray:
    occ = np.zeros((200, 200), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 100
    occ[60:70, 40:120] = 100
    occ[120:180, 150:155] = 100
    occ[140:150, 30:60] = 100
    return occ


def _raycast(occ: np.ndarray, pose: np.ndarray, n: int = 120, rmax: float = 8.0):
    ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
    r = np.arange(0.02, rmax, 0.01)
    x = pose[0] + r[None, :] * np.cos(pose[2] + ang)[:, None]
    y = pose[1] + r[None, :] * np.sin(pose[2] + ang)[:, None]
    mi = np.clip((x / RES).astype(int), 0, occ.shape[1] - 1)
    mj = np.clip((y / RES).astype(int), 0, occ.shape[0] - 1)
    hit = occ[mj, mi] == 100
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), len(r) - 1)
    return float(ang[0]), float(ang[1] - ang[0]), r[first]


def test_converges_from_near_initial_pose() -> None:
    occ = _world()
    # Odometry noise alphas for a decent wheel odometry (upstream's 0.2 spreads the cloud by
    # ~0.13 m per 0.3 m step, more than the likelihood field pulls it back).
    cfg = AmclConfig(max_particles=800, min_particles=200, alpha1=0.05, alpha2=0.05,
                     alpha3=0.05, alpha4=0.05)
    amcl = Amcl(cfg, OccupancyMap(occ, RES), seed=3)
    true = np.array([5.0, 5.0, 0.3])
    amcl.initialize(true + np.array([0.35, -0.3, 0.15]))
    odom = np.zeros(3)
    rng = np.random.default_rng(0)
    for _ in range(40):
        true[0] += 0.1 * math.cos(true[2])
        true[1] += 0.1 * math.sin(true[2])
        true[2] += 0.02
        # Odometry with 2 % scale error.
        odom[0] += 0.102 * math.cos(odom[2])
        odom[1] += 0.102 * math.sin(odom[2])
        odom[2] += 0.02
        a0, inc, r = _raycast(occ, true)
        if amcl.update(odom, r + rng.normal(0, 0.01, r.shape), a0, inc, 0.05, 8.0):
            at_update = true.copy()
    # The estimate refers to the last filter update (odometry carries it in between).
    true = at_update
    est, cov = amcl.estimate
    assert math.hypot(est[0] - true[0], est[1] - true[1]) < 0.1
    assert abs((est[2] - true[2] + math.pi) % (2 * math.pi) - math.pi) < 0.05
    assert cov.shape == (3, 3) and cov[0, 0] < 0.05
    # KLD shrank the particle set once the cloud concentrated.
    assert amcl.particles.shape[0] < 800


def test_no_update_without_motion_after_first() -> None:
    occ = _world()
    amcl = Amcl(AmclConfig(max_particles=300, min_particles=100), OccupancyMap(occ, RES), seed=1)
    amcl.initialize((5.0, 5.0, 0.0))
    a0, inc, r = _raycast(occ, np.array([5.0, 5.0, 0.0]))
    assert amcl.update((0.0, 0.0, 0.0), r, a0, inc, 0.05, 8.0)
    assert not amcl.update((0.1, 0.0, 0.0), r, a0, inc, 0.05, 8.0)  # below update_min_d
    assert amcl.update((0.3, 0.0, 0.0), r, a0, inc, 0.05, 8.0)


def test_kld_limit_and_errors() -> None:
    assert _resample_limit(1, 0.05, 0.99, 500, 2000) == 2000
    assert _resample_limit(2, 0.05, 0.99, 500, 2000) == 500
    k = 50
    x = 1 - 2 / (9 * (k - 1)) + math.sqrt(2 / (9 * (k - 1))) * 0.99
    assert _resample_limit(k, 0.05, 0.99, 10, 100000) == math.ceil((k - 1) / 0.1 * x ** 3)
    with pytest.raises(LocalizationError):
        Amcl(AmclConfig()).update((0, 0, 0), [1.0], 0.0, 0.1, 0.0, 5.0)
    with pytest.raises(ParameterError) as exc:
        from_params(AmclConfig, {"min_particles": 600, "max_particles": 500}, server="amcl")
    assert exc.value.key == "max_particles"
    cfg = from_params(AmclConfig, _flatten_amcl({"initial_pose": {"x": 1.0, "yaw": 0.5},
                                                 "kld_err": 0.02}), server="amcl")
    assert (cfg.initial_pose_x, cfg.initial_pose_yaw, cfg.pf_err) == (1.0, 0.5, 0.02)


def _cloud_at(amcl: Amcl, pose: np.ndarray, n: int, spread: float, rng: np.random.Generator) -> None:
    amcl.particles = pose + rng.normal(0.0, 1.0, (n, 3)) * np.array([spread, spread, spread / 5])
    amcl.weights = np.full(n, 1.0 / n)
    amcl._update_converged()


def test_prob_model_prefers_the_true_pose_and_beam_skipping_ignores_a_person() -> None:
    occ = _world()
    true = np.array([5.0, 5.0, 0.3])
    a0, inc, r = _raycast(occ, true)
    # a person 0.6 m away covers 20 of the 120 beams: not in the map
    person = r.copy()
    person[10:30] = 0.6
    rng = np.random.default_rng(0)
    for skip in (False, True):
        cfg = AmclConfig(laser_model_type="likelihood_field_prob", do_beamskip=skip,
                         max_particles=400, min_particles=100, sigma_hit=0.1)
        amcl = Amcl(cfg, OccupancyMap(occ, RES), seed=1)
        _cloud_at(amcl, true, 400, 0.05, rng)
        assert amcl.converged
        amcl.sensor_update(person, a0, inc, 0.05, 8.0)
        best = amcl.particles[np.argmax(amcl.weights)]
        err = math.hypot(best[0] - true[0], best[1] - true[1])
        if skip:
            # every 2nd beam is used (120 / max_beams 60): 10 of them hit the person
            assert amcl.skipped_beams == 10
            assert err < 0.06
        else:
            assert amcl.skipped_beams == 0
    # a cloud that has not converged (spread over metres) never skips beams
    amcl = Amcl(AmclConfig(laser_model_type="likelihood_field_prob", do_beamskip=True,
                           max_particles=400, min_particles=100), OccupancyMap(occ, RES), seed=1)
    _cloud_at(amcl, true, 400, 1.0, rng)
    assert not amcl.converged
    amcl.sensor_update(person, a0, inc, 0.05, 8.0)
    assert amcl.skipped_beams == 0
    # most beams disagreeing with the map means a wrong pose: all beams count again
    amcl = Amcl(AmclConfig(laser_model_type="likelihood_field_prob", do_beamskip=True,
                           max_particles=400, min_particles=100), OccupancyMap(occ, RES), seed=1)
    _cloud_at(amcl, true, 400, 0.05, rng)
    amcl.sensor_update(np.full_like(r, 0.7), a0, inc, 0.05, 8.0)
    assert amcl.skipped_beams == 0


def test_prob_model_weights_are_the_product_of_beam_probabilities() -> None:
    occ = _world()
    true = np.array([5.0, 5.0, 0.0])
    a0, inc, r = _raycast(occ, true, n=10)
    cfg = AmclConfig(laser_model_type="likelihood_field_prob", max_beams=10, sigma_hit=0.2,
                     z_hit=0.5, z_rand=0.5, laser_likelihood_max_dist=2.0)
    amcl = Amcl(cfg, OccupancyMap(occ, RES), seed=1)
    shifted = true + np.array([0.3, 0.0, 0.0])
    amcl.particles = np.stack([true, shifted])
    amcl.weights = np.ones(2)
    amcl.sensor_update(r, a0, inc, 0.05, 8.0)
    dist = amcl._dist
    expect = []
    for p in (true, shifted):
        prod = 1.0
        for i in range(10):
            if r[i] >= 8.0:
                continue
            hx = p[0] + r[i] * math.cos(p[2] + a0 + i * inc)
            hy = p[1] + r[i] * math.sin(p[2] + a0 + i * inc)
            i_, j_ = int(hx // RES), int(hy // RES)
            inside = 0 <= i_ < occ.shape[1] and 0 <= j_ < occ.shape[0]
            z = dist[j_, i_] if inside else 2.0  # off the map: max distance
            prod *= 0.5 * math.exp(-z * z / (2 * 0.2 * 0.2)) + 0.5 / 8.0
        expect.append(prod)
    assert amcl.weights / amcl.weights.sum() == pytest.approx(np.array(expect) / sum(expect), rel=1e-9)
    assert amcl.weights[0] > 2 * amcl.weights[1]


def test_initial_pose_covariance_is_used_as_given() -> None:
    occ = _world()
    amcl = Amcl(AmclConfig(max_particles=500, min_particles=100, set_initial_pose=True,
                           initial_pose_x=5.0, initial_pose_y=4.0, initial_pose_yaw=1.0),
                OccupancyMap(occ, RES), seed=2)
    # set_initial_pose: Nav2's zero covariance puts every particle on the pose
    assert np.allclose(amcl.particles, [5.0, 4.0, 1.0])
    assert not amcl.converged  # as pf_init: decided at the next resampling
    amcl.resample()
    assert amcl.converged
    cov = np.array([[0.04, 0.03, 0.0], [0.03, 0.09, 0.0], [0.0, 0.0, 0.01]])
    amcl.initialize((5.0, 4.0, 1.0), cov)
    emp = np.cov(amcl.particles.T)
    assert emp == pytest.approx(cov, abs=0.012)


def test_systematic_resampling_keeps_an_evenly_weighted_set() -> None:
    occ = _world()
    for method, expect_same in (("systematic", True), ("multinomial", False)):
        amcl = Amcl(AmclConfig(max_particles=400, min_particles=400, resample_method=method),
                    OccupancyMap(occ, RES), seed=4)
        amcl.initialize((5.0, 5.0, 0.0), np.diag([0.04, 0.04, 0.01]))
        before = np.sort(amcl.particles[:, 0])
        amcl.resample()
        after = np.sort(amcl.particles[:, 0])
        assert after.shape == before.shape
        assert np.array_equal(before, after) == expect_same
    # uneven weights: each particle gets floor/ceil of n * w copies
    amcl = Amcl(AmclConfig(max_particles=100, min_particles=100, resample_method="systematic"),
                OccupancyMap(occ, RES), seed=4)
    amcl.particles = np.array([[1.0, 1, 0], [2.0, 1, 0], [3.0, 1, 0], [4.0, 1, 0]])
    amcl.weights = np.array([0.5, 0.25, 0.2, 0.05])
    amcl.resample()
    counts = [int(np.sum(amcl.particles[:, 0] == v)) for v in (1.0, 2.0, 3.0, 4.0)]
    assert counts == [50, 25, 20, 5]


def test_localization_problem() -> None:
    lim = LocalizationLimits(max_xy_std=0.5, max_yaw_std=0.5, tf_timeout=1.0)
    s = 1_000_000_000
    assert localization_problem(lim, 10 * s, None, None).startswith("no map -> odom")
    assert localization_problem(lim, 10 * s, None, 0) == ""  # static transform
    assert localization_problem(lim, 10 * s, None, 9 * s) == ""
    assert "stale" in localization_problem(lim, 10 * s, None, 8 * s)
    ok = np.diag([0.01, 0.01, 0.01])
    assert localization_problem(lim, 10 * s, ok, 10 * s) == ""
    # a correlated covariance: the largest std is along the diagonal direction
    corr = np.array([[0.15, 0.14, 0.0], [0.14, 0.15, 0.0], [0.0, 0.0, 0.01]])
    assert "position std 0.54 m" in localization_problem(lim, 10 * s, corr, 10 * s)
    ros = np.zeros(36)
    ros[0] = ros[7] = 0.01
    ros[35] = 0.5
    assert "heading std 0.71 rad" in localization_problem(lim, 10 * s, ros, 10 * s)
    assert "not finite" in localization_problem(lim, 10 * s, np.full((3, 3), np.nan), 10 * s)
    assert localization_problem(LocalizationLimits(0.0, 0.0, 0.0), 100 * s, np.eye(3) * 9, 1) == ""
