"""The compiled 3D→3D RANSAC scoring (`Vis/EstimationType` 0) against the dense array form."""

from __future__ import annotations

import numpy as np
from numba import njit

from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration.rigid import _errors_3d3d, _pair_error, solve_3d3d


@njit(cache=True)
def _score_3d3d(rot, trans, valid, p, q, thr):  # type: ignore[no-untyped-def]
    """Every hypothesis's full score, pair by pair with the registration's `_pair_error`: the
    oracle of `_best_3d3d` (inliers, −1 when degenerate, less the capped error / thr·(n + 1))."""
    iters, n = rot.shape[0], p.shape[0]
    out = np.empty(iters)
    for h in range(iters):
        r = rot[h]
        count = 0
        total = 0.0
        for m in range(n):
            e = _pair_error(p, q, r, trans[h], m)
            if e <= thr:
                count += 1
                total += e
            else:
                total += thr
        out[h] = (count if valid[h] else -1) - total / (thr * (n + 1))
    return out


def _dense_scores(rot, trans, valid, p, q, thr):
    moved = np.einsum("nij,mj->nmi", rot, q) + trans[:, None, :]
    err = np.linalg.norm(p[None] - moved, axis=2)
    count = np.where(valid, (err <= thr).sum(axis=1), -1)
    return count - np.minimum(err, thr).sum(axis=1) / (thr * (p.shape[0] + 1)), err


def test_compiled_scores_match_the_dense_form():
    rng = np.random.default_rng(11)
    for n in (3, 40, 333):
        p = rng.uniform(-3.0, 3.0, (n, 3))
        q = p + rng.normal(0.0, 0.08, (n, 3))
        yaw = rng.uniform(-np.pi, np.pi, 50)
        rot = np.zeros((50, 3, 3))
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = (
            np.cos(yaw), -np.sin(yaw), np.sin(yaw), np.cos(yaw))
        rot[:, 2, 2] = 1.0
        rot[7] = np.eye(3)
        trans = rng.normal(0.0, 0.5, (50, 3))
        trans[7] = 0.0
        valid = rng.random(50) > 0.1
        valid[7] = True
        got = _score_3d3d(rot, trans, valid, p, q, 0.1)
        want, err = _dense_scores(rot, trans, valid, p, q, 0.1)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert int(np.argmax(got)) == int(np.argmax(want)) == 7
        np.testing.assert_allclose(_errors_3d3d(rot[7], trans[7], p, q), err[7], atol=1e-15)


def test_planar_ransac_recovers_the_motion_through_outliers():
    rng = np.random.default_rng(2)
    params = RtabmapParameters.from_dict({"Reg/Force3DoF": "true", "Vis/EstimationType": "0"})
    n = 300
    p = rng.uniform([0.5, -2.0, -0.5], [5.0, 2.0, 1.5], (n, 3))
    yaw, t = 0.2, np.array([0.3, -0.15, 0.0])
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    q = (p - t) @ r  # p = R q + t
    outliers = rng.random(n) < 0.6
    q[outliers] = rng.uniform([0.5, -2.0, -0.5], [5.0, 2.0, 1.5], (int(outliers.sum()), 3))
    transform, inliers = solve_3d3d(p, q, params)
    assert transform is not None
    np.testing.assert_allclose(transform[:3, 3], t, atol=1e-9)
    assert abs(np.arctan2(transform[1, 0], transform[0, 0]) - yaw) < 1e-9
    assert set(inliers.tolist()) >= set(np.flatnonzero(~outliers).tolist())
    assert inliers.size < n - 100  # the outliers stay out
