"""AMCL: convergence from a wrong-but-near initial pose on a synthetic map; KLD bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.maps import OccupancyMap
from eddiebot.nav.amcl import Amcl, AmclConfig, _resample_limit
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
