"""Localization mode: the rolling buffer of recent scans, global relocalisation, kidnapping."""

from __future__ import annotations

import numpy as np
import pytest
from slam_world import CORRIDOR, ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between, se2_compose, wrap_angle
from eddiebot.slam import ProcessStatus, Scan, SlamConfig, SlamCore, load_session, save_session
from eddiebot.slam.scan import scan_points

CONFIG = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6, scan_buffer_size=4)


def _scan(pose: np.ndarray, stamp_ns: int, world: np.ndarray = ROOM) -> Scan:
    return Scan(raycast(world, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> tuple[object, np.ndarray]:
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(CONFIG)
    for k, (p, o) in enumerate(zip(truth, odom)):
        core.process(_scan(p, k * 100_000_000), o)
    path = save_session(core, tmp_path_factory.mktemp("loc") / "room.eslam")
    return path, truth


def _loaded(session: tuple[object, np.ndarray]) -> tuple[SlamCore, np.ndarray]:
    path, truth = session
    return load_session(path, mode="localization"), truth  # type: ignore[arg-type]


def _err(pose: np.ndarray | None, truth: np.ndarray) -> tuple[float, float]:
    assert pose is not None
    return float(np.hypot(*(pose[:2] - truth[:2]))), abs(float(wrap_angle(pose[2] - truth[2])))


def test_buffer_holds_the_last_scans_and_never_touches_the_graph(session) -> None:
    loc, truth = _loaded(session)
    poses0 = loc.node_poses().copy()
    edges0 = len(loc.graph.edges)
    loc.set_initial_pose(truth[8] + np.array([0.08, -0.06, 0.03]), np.zeros(3))
    for n, k in enumerate(range(8, 40, 2)):
        odom = se2_between(truth[8], truth[k])
        r = loc.process(_scan(truth[k], 10**9 + k), odom)
        assert r.status is ProcessStatus.LOCALIZED
        d, th = _err(r.pose, truth[k])
        assert d < 0.03 and th < 0.01
        assert len(loc._loc_buffer) == min(n + 1, CONFIG.scan_buffer_size)
    assert len(loc.graph.edges) == edges0
    assert np.array_equal(loc.node_poses(), poses0)
    loc.clear_localization_buffer()
    assert len(loc._loc_buffer) == 0


def test_initial_pose_clears_the_buffer(session) -> None:
    loc, truth = _loaded(session)
    loc.set_initial_pose(truth[4], np.zeros(3))
    loc.process(_scan(truth[4], 1), np.zeros(3))
    assert len(loc._loc_buffer) == 1
    loc.start_at(truth[20])
    assert len(loc._loc_buffer) == 0
    r = loc.process(_scan(truth[20], 2), np.array([3.0, -1.0, 0.4]))  # any odometry
    d, _ = _err(r.pose, truth[20])
    assert d < 0.03


@pytest.mark.parametrize("k", [6, 30, 55, 80])
def test_no_initial_pose_relocalises_over_the_whole_map(session, k: int) -> None:
    loc, truth = _loaded(session)
    r = loc.process(_scan(truth[k], 1), np.array([-4.0, 2.0, 1.0]))
    assert r.status is ProcessStatus.LOCALIZED
    assert [w.kind for w in r.warnings] == ["relocalized"]
    d, th = _err(r.pose, truth[k])
    assert d < 0.05 and th < 0.02
    (attempt,) = loc.relocalizations
    assert attempt.accepted
    assert attempt.response >= CONFIG.loop_match_minimum_response_fine
    assert r.response == attempt.response
    # tracking goes on from there
    odom2 = se2_compose(np.array([-4.0, 2.0, 1.0]), se2_between(truth[k], truth[k + 2]))
    r2 = loc.process(_scan(truth[k + 2], 2), odom2)
    assert r2.status is ProcessStatus.LOCALIZED and not r2.warnings
    assert _err(r2.pose, truth[k + 2])[0] < 0.03


def test_relocalisation_refuses_a_place_the_map_does_not_hold(session) -> None:
    loc, _ = _loaded(session)
    elsewhere = np.array([15.0, 1.0, 0.3])
    r = loc.process(_scan(elsewhere, 1, CORRIDOR), np.zeros(3))
    assert r.status is ProcessStatus.LOST
    assert r.pose is None
    assert r.warnings[-1].kind == "relocalization_failed"
    (attempt,) = loc.relocalizations
    assert not attempt.accepted
    assert attempt.coarse_variance > CONFIG.loop_match_maximum_variance_coarse  # ambiguous


def test_kidnapped_robot_is_relocalised_within_a_buffer_of_unsupported_scans(session) -> None:
    loc, truth = _loaded(session)
    loc.set_initial_pose(truth[10], np.zeros(3))
    odom = np.zeros(3)
    last = truth[10]
    loc.process(_scan(truth[10], 1), odom)
    # carried from the bottom edge to the top edge of the loop; odometry saw nothing, then
    # sees the robot drive on along the top edge
    kidnap = [60, 58, 56, 54, 52, 50, 48]
    seen = []
    for n, k in enumerate(kidnap):
        step = se2_between(last, truth[k]) if n else np.array([0.0, 0.0, 0.6])
        odom = se2_compose(odom, step)
        last = truth[k]
        r = loc.process(_scan(truth[k], 10 + n), odom)
        seen.append((r.status, {w.kind for w in r.warnings}))
    relocalised = [n for n, (_, kinds) in enumerate(seen) if "relocalized" in kinds]
    assert relocalised, seen
    # the first scans after the kidnap are placed through the buffer, which matches them
    # well; the map does not support them, so within scan_buffer_size scans the robot is
    # searched for over the whole map
    assert relocalised[0] <= CONFIG.scan_buffer_size
    assert all(status is ProcessStatus.LOCALIZED for status, _ in seen)
    d, th = _err(r.pose, truth[kidnap[-1]])
    assert d < 0.05 and th < 0.02


def test_relocalize_reports_the_best_pose_and_its_responses(session) -> None:
    loc, truth = _loaded(session)
    pts = scan_points(_scan(truth[40], 1), CONFIG.max_laser_range)
    found = loc.relocalize(pts)
    assert found.accepted
    assert found.coarse_response >= CONFIG.loop_match_minimum_response_coarse
    assert _err(found.pose, truth[40])[0] < 0.05
    # the tracked pose is left alone
    assert loc._state.last_pose is None
