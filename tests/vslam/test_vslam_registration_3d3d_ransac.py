"""The compiled 3D→3D RANSAC scoring (`Vis/EstimationType` 0) against the dense array form.

The 3D→3D RANSAC's sample selection in one compiled pass per row gives the samples of the
numpy form it replaces (`argpartition` + `argsort`), index for index, and `solve_3d3d` returns
the same transform and inliers either way, with its samples drawn afresh or from the cache."""

from __future__ import annotations

import numpy as np
from numba import njit

from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.registration import rigid
from eddiebot.vslam.registration.rigid import (
    _errors_3d3d,
    _pair_error,
    _ransac_samples,
    _smallest_sorted,
    solve_3d3d,
)
from eddiebot.vslam.transforms import from_xyz_yaw


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


def _numpy_samples(draws: np.ndarray, k: int) -> np.ndarray:
    part = np.argpartition(draws, k - 1, axis=1)[:, :k]
    return np.take_along_axis(
        part, np.argsort(np.take_along_axis(draws, part, axis=1), axis=1), axis=1)


def test_compiled_samples_equal_numpy_ones():
    checked = 0
    for n in (3, 4, 5, 17, 64, 251, 600):
        for k in (2, 3):
            if n <= k:
                continue
            draws = np.random.default_rng(n).random((300, n))
            got = _smallest_sorted(draws, k)
            assert got is not None
            want = _numpy_samples(draws, k)
            assert got.dtype == want.dtype and got.shape == want.shape == (300, k)
            assert np.array_equal(got, want)
            checked += 1
    assert checked == 13


def test_tied_draws_are_left_to_numpy():
    draws = np.random.default_rng(1).random((50, 40))
    assert _smallest_sorted(draws, 2) is not None
    row = draws[7]
    order = np.argsort(row)
    row[order[1]] = row[order[0]]  # the two smallest equal
    assert _smallest_sorted(draws, 2) is None
    draws = np.random.default_rng(2).random((50, 40))
    row = draws[3]
    order = np.argsort(row)
    row[order[3]] = row[order[2]]  # the 3rd and 4th smallest equal: decides membership for k=3
    assert _smallest_sorted(draws, 3) is None
    assert _smallest_sorted(np.zeros((4, 2)), 2) is None  # no choice to make


def test_solve_3d3d_unchanged(monkeypatch):
    rng = np.random.default_rng(7)
    truth = from_xyz_yaw(0.4, -0.2, 0.3)
    to_pts = rng.uniform([-2, -2, 0.2], [2, 2, 1.5], (180, 3))
    from_pts = to_pts @ truth[:3, :3].T + truth[:3, 3] + rng.normal(0, 0.01, (180, 3))
    from_pts[:50] = rng.uniform(-2, 2, (50, 3))  # outliers
    for force in (True, False):
        params = RtabmapParameters(reg_force_3dof=force)
        _ransac_samples.cache_clear()
        t_new, inl_new = solve_3d3d(from_pts, to_pts, params)
        t_again, inl_again = solve_3d3d(from_pts, to_pts, params)  # samples from the cache
        assert _ransac_samples.cache_info().hits == 1
        assert np.array_equal(t_again, t_new) and np.array_equal(inl_again, inl_new)
        _ransac_samples.cache_clear()
        monkeypatch.setattr(rigid, "_smallest_sorted", lambda d, k: None)
        t_old, inl_old = solve_3d3d(from_pts, to_pts, params)
        monkeypatch.undo()
        _ransac_samples.cache_clear()
        assert t_new is not None and t_old is not None
        assert np.array_equal(t_new, t_old) and np.array_equal(inl_new, inl_old)
        assert inl_new.size >= 120
        assert np.abs(t_new[:3, 3] - truth[:3, 3]).max() < 0.02


def test_pruned_best_hypothesis_is_the_scores_argmax():
    rng = np.random.default_rng(11)
    checked = 0
    for n in (3, 31, 32, 33, 97, 400, 900):
        truth = from_xyz_yaw(*rng.normal(0, 0.5, 3))
        q = rng.uniform([-3, -3, 0.2], [3, 3, 2], (n, 3))
        p = q @ truth[:3, :3].T + truth[:3, 3] + rng.normal(0, 0.03, (n, 3))
        p[: n // 2] = rng.uniform(-3, 3, (n // 2, 3))  # half outliers
        for trial in range(6):
            iters = 300
            yaw = rng.uniform(-np.pi, np.pi, iters)
            rot = np.zeros((iters, 3, 3))
            rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = (
                np.cos(yaw), -np.sin(yaw), np.sin(yaw), np.cos(yaw))
            rot[:, 2, 2] = 1.0
            trans = rng.normal(0.0, 1.0, (iters, 3))
            good = rng.choice(iters, 5, replace=False)
            rot[good] = truth[:3, :3]
            trans[good] = truth[:3, 3] + rng.normal(0, 0.01, (5, 3))
            if trial % 2:
                rot[good[1]], trans[good[1]] = rot[good[0]], trans[good[0]]  # a tie
                rot[-1], trans[-1] = rot[good[0]], trans[good[0]]
            valid = rng.random(iters) > 0.1
            if trial == 5:
                valid[:] = False  # every score is -1 - error: the least error wins
            score = _score_3d3d(rot, trans, valid, p, q, 0.1)
            best = rigid._best_3d3d(rot, trans, valid, p, q, 0.1)
            assert best == int(np.argmax(score))
            checked += 1
    assert checked == 42
