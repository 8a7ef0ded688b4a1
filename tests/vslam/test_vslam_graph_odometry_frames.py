"""`RGBD/OdomHeadingSigma`: per-node odometry frames for a heading error that does not accumulate.

The graph update's cached pieces give what they replace: `OdometryFrames` (the odometry-frame
links kept between calls) returns the links `odometry_frame_graph` builds afresh, link for link,
on a graph that grows, changes links and root between calls."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from vslam_synthetic import frame, kinect_camera, link_adjacency, planar_pose

from eddiebot.vslam.closure_check import closure_mahalanobis, path_covariance
from eddiebot.vslam.errors import ParameterError
from eddiebot.vslam.graph import GtsamPoseGraph
from eddiebot.vslam.memory import Link, LinkType
from eddiebot.vslam.odometry_frames import (
    ODOM_FRAME_ID_OFFSET,
    OdometryFrames,
    odometry_frame_graph,
)
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

CAM = kinect_camera(320, 240)
SIGMA = 0.0314  # rad (1.8°), as demo.vslam_stage.SLAM_PARAMETERS


def _info(lin: float, ang: float) -> np.ndarray:
    return np.diag([1 / lin, 1 / lin, 1 / lin, 1 / ang, 1 / ang, 1 / ang])


def _route() -> tuple[np.ndarray, np.ndarray]:
    """Out 12 m, turn back in 30° steps, return to the start, out again 6 m: a node every
    0.35 m; the straight stretch each pose belongs to."""
    poses, legs = [], []
    x, th, leg = 0.0, 0.0, 0
    poses.append((x, 0.0, th))
    legs.append(leg)
    for target, heading in ((12.0, 0.0), (0.0, np.pi), (6.0, 0.0)):
        while abs(th - heading) > 1e-9:
            th += float(np.clip(heading - th, -np.pi / 6, np.pi / 6))
            poses.append((x, 0.0, th))
            legs.append(leg)
        leg += 1
        while abs(target - x) > 1e-9:
            x += float(np.clip(target - x, -0.35, 0.35))
            poses.append((x, 0.0, th))
            legs.append(leg)
        leg += 1
    return np.array(poses), np.array(legs)


def _quantised_odometry(seed: int) -> tuple[np.ndarray, list[np.ndarray], list[Link]]:
    """Ground truth, odometry poses whose heading is off by a per-stretch offset of up to 1.5°
    (encoder quantisation: the positions follow the true direction) and true loop closures
    (2 cm, 0.2°) from the return and second outward legs to the first."""
    truth, legs = _route()
    rng = np.random.default_rng(seed)
    q = np.radians(rng.choice([-1.5, -0.8, 0.0, 0.8, 1.5], legs.max() + 1))[legs]
    q += np.radians(rng.normal(0.0, 0.2, len(truth)))
    q[0] = 0.0
    odo = truth.copy()
    odo[:, 2] += q
    odo[1:, :2] += np.cumsum(rng.normal(0.0, 0.001, (len(truth) - 1, 2)), axis=0)
    mats = [from_xyz_yaw(*p) for p in odo]
    true_mats = [from_xyz_yaw(*p) for p in truth]
    closures = []
    for b in range(len(truth)):
        if b % 4:
            continue
        for a in range(b - 15):
            same = np.hypot(*(truth[a, :2] - truth[b, :2])) < 0.2
            if same and abs(np.angle(np.exp(1j * (truth[a, 2] - truth[b, 2])))) < 0.3:
                closures.append(Link(b + 1, a + 1, LinkType.GLOBAL_CLOSURE,
                                     se3_inverse(true_mats[b]) @ true_mats[a],
                                     np.diag([2500, 2500, 1, 1, 1, 1 / np.radians(0.2) ** 2])))
                break
    return truth, mats, closures


def _ate(truth: np.ndarray, poses: dict[int, np.ndarray]) -> float:
    est = np.array([[poses[i + 1][0, 3], poses[i + 1][1, 3]] for i in range(len(truth))])
    return float(np.sqrt(np.mean(np.sum((est - truth[:, :2]) ** 2, axis=1))))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_odometry_frames_keep_the_path_when_the_heading_is_quantised(seed):
    truth, mats, closures = _quantised_odometry(seed)
    assert len(closures) >= 4
    poses = {i + 1: m for i, m in enumerate(mats)}

    def chain(ang: float) -> list[Link]:
        return [Link(i, i + 1, LinkType.NEIGHBOR, se3_inverse(mats[i - 1]) @ mats[i],
                     _info(1e-5, ang)) for i in range(1, len(mats))]

    # per-link noise (σ 0.7° per link): the heading looks like a random walk, and the true
    # closures turn whole stretches of the path
    per_link = GtsamPoseGraph(True).optimize(poses, chain(1.5e-4) + closures, 1, 20)
    # per-node odometry frames: 1.8° of non-accumulating heading error, 0.18° per link of drift
    frame_poses, links = odometry_frame_graph(poses, chain(1e-5) + closures, 1, SIGMA)
    framed = GtsamPoseGraph(True).optimize(frame_poses, links, 1, 20)
    assert _ate(truth, per_link) > 0.05
    assert _ate(truth, framed) < 0.02
    assert _ate(truth, framed) < 0.25 * _ate(truth, per_link)


def test_odometry_frame_graph_moves_the_neighbour_links_onto_the_frames():
    step = planar_pose(0.3, 0.0, 0.0)
    poses = {1: planar_pose(0, 0, 0), 2: step, 3: step @ step}
    odo = [Link(1, 2, LinkType.NEIGHBOR, step, _info(1e-5, 1e-5)),
           Link(2, 3, LinkType.NEIGHBOR_MERGED, step, _info(1e-5, 1e-5))]
    closure = Link(3, 1, LinkType.GLOBAL_CLOSURE, planar_pose(-0.6, 0.0, 0.0), _info(1e-4, 1e-4))
    known = {ODOM_FRAME_ID_OFFSET + 2: planar_pose(0.3, 0.01, 0.02)}
    out_poses, links = odometry_frame_graph(poses, [*odo, closure], 1, SIGMA, known)
    off = ODOM_FRAME_ID_OFFSET
    assert set(out_poses) == {1, 2, 3, off + 1, off + 2, off + 3}
    np.testing.assert_array_equal(out_poses[off + 2], known[off + 2])  # last optimum as guess
    np.testing.assert_array_equal(out_poses[off + 3], poses[3])
    pairs = {(lk.from_id, lk.to_id): lk for lk in links}
    assert set(pairs) == {(1, off + 1), (2, off + 2), (3, off + 3), (off + 1, off + 2),
                          (off + 2, off + 3), (3, 1)}
    # a node's frame: same position, heading free by σ; the root's frame is the root
    tie = np.diag(pairs[(2, off + 2)].information)
    assert tie[0] >= 1e8 and tie[1] >= 1e8
    assert tie[5] == pytest.approx(1 / SIGMA**2)
    assert np.diag(pairs[(1, off + 1)].information)[5] >= 1e8
    np.testing.assert_array_equal(pairs[(off + 1, off + 2)].transform, step)
    np.testing.assert_array_equal(pairs[(3, 1)].information, closure.information)


def test_path_covariance_adds_the_frame_heading_offset_at_both_ends_of_odometry():
    sx, st, s = 0.01, 0.003, 0.02
    step = planar_pose(1.0, 0.0, 0.0)
    info = np.diag([1 / sx**2, 1 / sx**2, 1.0, 1.0, 1.0, 1 / st**2])
    adj = link_adjacency([Link(1, 2, LinkType.NEIGHBOR, step, info),
                      Link(2, 3, LinkType.NEIGHBOR, step, info)])
    plain = path_covariance(adj, 1, 3)
    framed = path_covariance(adj, 1, 3, heading_sigma=s)
    assert plain is not None and framed is not None
    # the start frame's heading offset turns the 2 m chain sideways; the end adds its own
    np.testing.assert_allclose(framed[1] - plain[1],
                               [[0, 0, 0], [0, 4 * s**2, 2 * s**2], [0, 2 * s**2, 2 * s**2]],
                               rtol=1e-9, atol=1e-15)
    # a path of loop closures only has no odometry frames
    closure = Link(1, 3, LinkType.GLOBAL_CLOSURE, step @ step, info)
    only = link_adjacency([closure])
    a = path_covariance(only, 1, 3)
    b = path_covariance(only, 1, 3, heading_sigma=s)
    assert a is not None and b is not None
    np.testing.assert_allclose(a[1], b[1])
    # the gate takes it into account: a 2° closure error on a 2-link chain is 6.6σ without the
    # frames' offsets (σ 0.17° per link), 1.6σ with them
    here, there = planar_pose(2.0, 0.0, 0.0), planar_pose(0.0, 0.0, 0.0)
    turned = Link(3, 1, LinkType.GLOBAL_CLOSURE, planar_pose(-2.0, 0.0, np.radians(2.0)),
                  np.diag([1e4, 1e4, 1.0, 1.0, 1.0, 1e5]))
    d_plain = closure_mahalanobis(turned, here, there, adj)
    d_framed = closure_mahalanobis(turned, here, there, adj, heading_sigma=s)
    assert d_plain is not None and d_framed is not None
    assert d_plain > 6.0 and d_framed < 2.0


def test_parameter_default_off_and_validated():
    assert RtabmapParameters().rgbd_odom_heading_sigma == 0.0
    assert RtabmapParameters.from_dict(
        {"RGBD/OdomHeadingSigma": "0.0314"}).rgbd_odom_heading_sigma == pytest.approx(0.0314)
    with pytest.raises(ParameterError):
        RtabmapParameters.from_dict({"RGBD/OdomHeadingSigma": "-0.1"})


def test_core_optimises_with_frames_and_reports_only_nodes():
    slam = Rtabmap({"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
                    "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "Mem/STMSize": "2",
                    "Rtabmap/LoopThr": "0.05", "RGBD/OdomHeadingSigma": str(SIGMA)})
    cov = np.diag([1e-5, 1e-5, 1e-5, 1e-5, 1e-5, 1e-5])
    for k in range(5):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k * 1_000_000_000, odom_covariance=cov)
    # back at the start; the odometry's heading is off by 1°, its position by 2 cm
    r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0.02, 0.0, np.radians(1.0)),
                     5_000_000_000, odom_covariance=cov)
    assert r.loop_closure_id == 1
    poses, _ = slam.graph()
    assert set(poses) == set(range(1, 7))  # no frame ids leak into the map
    assert r.pose is not None
    # the closure puts node 6 back on node 1: position and heading
    assert np.hypot(r.pose[0, 3], r.pose[1, 3]) < 0.01
    assert abs(np.degrees(np.arctan2(r.pose[1, 0], r.pose[0, 0]))) < 0.2
    assert set(slam._frame_poses) == {ODOM_FRAME_ID_OFFSET + i for i in range(1, 7)}


class _ShiftNode:
    """Optimiser that moves one node sideways after solving."""

    def __init__(self, node: int, shift: float) -> None:
        self.inner = GtsamPoseGraph(True, incremental=False)
        self.node = node
        self.shift = shift

    def optimize(self, poses, links, root_id, iterations):  # type: ignore[no-untyped-def]
        out = self.inner.optimize(poses, links, root_id, iterations)
        out[self.node] = out[self.node].copy()
        out[self.node][1, 3] += self.shift
        return out


@pytest.mark.parametrize(("sigma", "accepted"), [(SIGMA, True), (0.0, False)])
def test_optimize_max_error_judges_only_the_heading_of_frame_links(sigma, accepted):
    # With frames the odometry links join the frames and a node is tied to its frame: the
    # tie's position is a constraint of the model, not a measurement, so 2 cm of slack there
    # does not reject the closure; without frames the same 2 cm break the node's odometry links.
    slam = Rtabmap({"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
                    "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "Mem/STMSize": "2",
                    "Rtabmap/LoopThr": "0.05", "RGBD/OdomHeadingSigma": str(sigma),
                    "RGBD/OptimizeMaxError": "3"},
                   optimizer=_ShiftNode(3, 0.02))
    cov = np.diag([1e-5, 1e-5, 1e-5, 1e-5, 1e-5, 1e-5])
    for k in range(5):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k * 1_000_000_000, odom_covariance=cov)
    r = slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0.02, 0.0, 0.0),
                     5_000_000_000, odom_covariance=cov)
    assert (r.loop_closure_id == 1) is accepted
    if not accepted:
        assert r.rejected_loop_id == 1
        assert r.rejection_reason == "RGBD/OptimizeMaxError exceeded"


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
    from eddiebot.vslam.graph_links import _ratios

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
