"""The graph update's cached pieces give what they replace: `OdometryFrames` (the odometry-frame
links kept between calls) returns the links `odometry_frame_graph` builds afresh, link for link,
on a graph that grows, changes links and root between calls."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from eddiebot.vslam.memory import Link, LinkType
from eddiebot.vslam.odometry_frames import (
    ODOM_FRAME_ID_OFFSET,
    OdometryFrames,
    odometry_frame_graph,
)
from eddiebot.vslam.transforms import from_xyz_yaw


def _same(a, b) -> bool:
    return (a.from_id == b.from_id and a.to_id == b.to_id
            and np.array_equal(a.transform, b.transform)
            and np.array_equal(a.information, b.information))


def test_cached_frame_links_equal_the_fresh_ones():
    rng = np.random.default_rng(4)
    frames = OdometryFrames()
    poses: dict[int, np.ndarray] = {}
    links: dict[tuple[int, int], Link] = {}
    known: dict[int, np.ndarray] = {}
    checked = 0
    for step in range(1, 120):
        poses[step] = from_xyz_yaw(0.25 * step, rng.normal(0, 0.1), rng.normal(0, 0.2))
        if step > 1:
            links[(step - 1, step)] = Link(step - 1, step, LinkType.NEIGHBOR,
                                           from_xyz_yaw(0.25, 0.0, 0.01), np.eye(6) * 1e3)
        if step > 10 and rng.random() < 0.4:  # a closure, sometimes replacing one
            a = int(rng.integers(1, step - 5))
            links[(a, step)] = Link(a, step, LinkType.GLOBAL_CLOSURE,
                                    from_xyz_yaw(*rng.normal(0, 0.1, 3)),
                                    np.eye(6) * float(rng.uniform(10, 1e4)))
        if step > 20 and rng.random() < 0.1:  # a closure rejected and removed
            loops = [k for k, lk in links.items() if lk.type == LinkType.GLOBAL_CLOSURE]
            if loops:
                del links[loops[int(rng.integers(len(loops)))]]
        root = 1 if step < 80 else 2  # the root moves once (a node left)
        if step == 80:
            del poses[1]
            links = {k: v for k, v in links.items() if 1 not in k}
        sigma = 0.0314 if step < 100 else 0.05
        if step % 7 == 0:
            known = {ODOM_FRAME_ID_OFFSET + i: p @ from_xyz_yaw(0, 0, 0.01)
                     for i, p in poses.items()}
        given = list(links.values())
        want_poses, want = odometry_frame_graph(poses, given, root, sigma, known)
        got_poses, got = frames.graph(poses, given, root, sigma, known)
        assert list(got_poses) == list(want_poses)
        assert all(got_poses[i] is want_poses[i] for i in want_poses)
        assert len(got) == len(want) and all(_same(a, b) for a, b in zip(got, want))
        checked += len(got)
    assert checked > 15_000


def _ratios_reference(d, rot, info):
    """`graph._ratios` as written before (row reductions with `.min/.max(axis=1)`), with the
    rotation angle from scipy."""
    lin_info = np.where(info[:, :3] > 1e-4, info[:, :3], np.inf)
    ang_info = np.where(info[:, 3:] > 1e-4, info[:, 3:], np.inf)
    lin_sigma = np.sqrt(np.maximum(1.0 / lin_info.min(axis=1), 1e-6))
    ang_sigma = np.sqrt(np.maximum(1.0 / ang_info.min(axis=1), 1e-6))
    lin = np.where(np.isfinite(lin_info), d, 0.0).max(axis=1)
    ang = Rotation.from_matrix(rot).magnitude()
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.where(lin_sigma > 0, lin / lin_sigma, 0.0),
                np.where(ang_sigma > 0, ang / ang_sigma, 0.0))


def test_link_error_ratios_equal_the_row_reduction_form():
    from eddiebot.vslam.graph import _ratios

    rng = np.random.default_rng(9)
    n = 5000
    info = 10.0 ** rng.uniform(-6, 8, (n, 6))
    info[rng.random((n, 6)) < 0.2] = 1e-5  # ignored terms (planar z, roll, pitch)
    info[rng.random(n) < 0.05, :3] = 0.0  # no usable linear term
    d = np.abs(rng.normal(0, 0.1, (n, 3)))
    # rotation errors from 1e-12 rad (where arccos of the trace reads 0 or 2e-8) to π
    angles = np.concatenate([10.0 ** rng.uniform(-12, -6, n // 2),
                             rng.uniform(0.0, np.pi, n - n // 2)])
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    rot = Rotation.from_rotvec(dirs * angles[:, None]).as_matrix()
    axis = np.stack([rot[:, 2, 1] - rot[:, 1, 2], rot[:, 0, 2] - rot[:, 2, 0],
                     rot[:, 1, 0] - rot[:, 0, 1]], axis=1)
    two_sin = np.linalg.norm(axis, axis=1)
    trace = np.trace(rot, axis1=1, axis2=2)
    got, want = _ratios(d, two_sin, trace, info), _ratios_reference(d, rot, info)
    assert np.array_equal(got[0], want[0])
    assert np.allclose(got[1], want[1], rtol=1e-9, atol=1e-15)
    assert np.count_nonzero(got[0]) > 4000 and np.count_nonzero(got[0] == 0.0) > 100
