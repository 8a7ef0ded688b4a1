"""Localization mode: the rolling buffer of recent scans, global relocalisation, kidnapping;
and its bounded cost: attempts back off while the map does not cover the place, and a
whole-map search run off the scan's call never holds up tracking."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from slam_world import CORRIDOR, ROOM, SCAN_ANGLES, dataset, drifting_odometry, loop_path, raycast

from eddiebot.geometry import se2_between, se2_compose, wrap_angle
from eddiebot.slam import (
    ProcessStatus,
    Scan,
    SlamConfig,
    SlamCore,
    load_session,
    load_slam_config,
    save_session,
)
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper.global_search import CANDIDATES, SEPARATION, scan_candidates
from eddiebot.slam.mapper.localization import GlobalMap
from eddiebot.slam.relocalization_process import RelocalizationProcess
from eddiebot.slam.replay import replay_lasers
from eddiebot.slam.scan import scan_points
from eddiebot.slam.scan_matcher import MatchResult

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


# --- bounded relocalisation -----------------------------------------------------------

def _corridor_walk(n: int) -> list[np.ndarray]:
    """Poses driving up and down the corridor (which the room's map does not hold), 0.6 m
    apart."""
    xs = np.concatenate([np.arange(3.0, 27.0, 0.6), np.arange(27.0, 3.0, -0.6)])
    return [np.array([xs[k % xs.size], 1.0, 0.0 if k % xs.size < xs.size // 2 else np.pi])
            for k in range(n)]


class HeldSearch:
    """A `GlobalSearch` whose answers come only when the test releases them (the search
    itself runs in the test's process, on release)."""

    def __init__(self) -> None:
        self.requests: list[
            tuple[int, GlobalMap, np.ndarray, np.ndarray | None, np.ndarray | None]
        ] = []
        self.ready: list[tuple[int, MatchResult]] = []

    def submit(
        self,
        source: GlobalMap,
        points: np.ndarray,
        view: np.ndarray | None = None,
        tracked: np.ndarray | None = None,
    ) -> int:
        self.requests.append((len(self.requests) + 1, source, points.copy(), view, tracked))
        return len(self.requests)

    def poll(self) -> tuple[int, MatchResult] | None:
        return self.ready.pop(0) if self.ready else None

    def release(self) -> None:
        ticket, source, points, view, tracked = self.requests[-1]
        self.ready.append((ticket, source.search(points, view=view, tracked=tracked)))


def test_a_tracked_robot_off_the_map_is_searched_for_every_scan_buffer_size_scans(
    session,
) -> None:
    loc, truth = _loaded(session)
    search = HeldSearch()
    loc.global_search = search
    loc.set_initial_pose(truth[10], np.zeros(3))
    loc.process(_scan(truth[10], 1), np.zeros(3))
    # carried into a corridor the map does not hold; odometry follows the walk from there
    walk = _corridor_walk(30)
    submitted_at = []
    for n, pose in enumerate(walk):
        # odometry saw a turn while the robot was carried, then the walk
        odom = se2_compose(np.array([0.0, 0.0, 0.7]), se2_between(walk[0], pose))
        before = len(search.requests)
        if n == 14:  # the first search answers (refused) after the robot drove on
            search.release()
        r = loc.process(_scan(pose, 10 + n, CORRIDOR), odom)
        assert r.status is ProcessStatus.LOCALIZED  # tracked on, never lost
        if len(search.requests) > before:
            submitted_at.append(n + 1)
    b = CONFIG.scan_buffer_size
    # one search at a time: none while the first runs (scans 4 to 14); after its answer the
    # next after scan_buffer_size more unsupported scans (the second one never answers here)
    assert submitted_at == [b, 15 + b - 1]
    assert [a.accepted for a in loc.relocalizations] == [False]


def test_lost_robot_retries_after_1_3_then_scan_buffer_size_scans(session) -> None:
    loc, _ = _loaded(session)
    attempts_at = []
    # mid-corridor, both ends beyond the laser's range: the map fits it nowhere for sure
    elsewhere = np.array([15.0, 1.0, 0.3])
    for n in range(20):
        before = len(loc.relocalizations)
        r = loc.process(_scan(elsewhere, 1 + n, CORRIDOR), np.array([0.6 * n, 0.0, 0.0]))
        assert r.status is ProcessStatus.LOST and r.pose is None
        if len(loc.relocalizations) > before:
            attempts_at.append(n)
    # refused searches wait 1, 3, then min(7, scan_buffer_size = 4) scans
    assert attempts_at == [0, 2, 6, 11, 16]


def test_a_lost_scan_returns_while_its_search_runs_and_a_later_scan_takes_the_answer(
    session,
) -> None:
    loc, truth = _loaded(session)
    search = HeldSearch()
    loc.global_search = search
    odom0 = np.array([-4.0, 2.0, 1.0])
    r = loc.process(_scan(truth[30], 1), odom0)
    # handed over, not searched in the call
    assert r.status is ProcessStatus.LOST and r.pose is None
    assert len(search.requests) == 1 and loc.relocalizations == []
    # the robot drives on; no second search while the first runs
    for n, k in enumerate((32, 34), start=2):
        odom = se2_compose(odom0, se2_between(truth[30], truth[k]))
        r = loc.process(_scan(truth[k], n), odom)
        assert r.status is ProcessStatus.LOST
    assert len(search.requests) == 1
    search.release()
    odom = se2_compose(odom0, se2_between(truth[30], truth[36]))
    r = loc.process(_scan(truth[36], 4), odom)
    # the answer places scan 30; odometry carries it to scan 36, whose match then tracks
    assert r.status is ProcessStatus.LOCALIZED
    assert "relocalized" in {w.kind for w in r.warnings}
    (attempt,) = loc.relocalizations
    assert attempt.accepted and _err(attempt.pose, truth[30])[0] < 0.05
    d, th = _err(r.pose, truth[36])
    assert d < 0.05 and th < 0.02


def test_tracking_goes_on_while_the_search_for_a_kidnapped_robot_runs(session) -> None:
    loc, truth = _loaded(session)
    search = HeldSearch()
    loc.global_search = search
    loc.set_initial_pose(truth[10], np.zeros(3))
    odom = np.zeros(3)
    last = truth[10]
    loc.process(_scan(truth[10], 1), odom)
    kidnap = [60, 58, 56, 54, 52, 50, 48, 46, 44]
    statuses = []
    for n, k in enumerate(kidnap):
        step = se2_between(last, truth[k]) if n else np.array([0.0, 0.0, 0.6])
        odom = se2_compose(odom, step)
        last = truth[k]
        if n == 6:
            assert len(search.requests) == 1
            search.release()
        r = loc.process(_scan(truth[k], 10 + n), odom)
        statuses.append(r.status)
        if n < 6:  # every scan is tracked (on the wrong pose) while the search runs
            assert not any(w.kind == "relocalized" for w in r.warnings)
    assert all(s is ProcessStatus.LOCALIZED for s in statuses)
    assert len(search.requests) == 1
    (attempt,) = loc.relocalizations
    assert attempt.accepted
    d, th = _err(r.pose, truth[kidnap[-1]])
    assert d < 0.05 and th < 0.02


def test_a_stale_answer_is_dropped_after_a_new_initial_pose(session) -> None:
    loc, truth = _loaded(session)
    search = HeldSearch()
    loc.global_search = search
    loc.process(_scan(truth[30], 1), np.zeros(3))
    search.release()
    loc.start_at(truth[50])
    r = loc.process(_scan(truth[50], 2), np.array([1.0, 0.0, 0.0]))
    assert r.status is ProcessStatus.LOCALIZED
    assert loc.relocalizations == []  # the old search's answer is not applied
    assert _err(r.pose, truth[50])[0] < 0.03


def test_the_search_process_answers_without_the_scan_call_waiting(session) -> None:
    loc, truth = _loaded(session)
    search = RelocalizationProcess()
    loc.global_search = search
    try:
        odom0 = np.array([2.0, -1.0, 0.3])
        r = loc.process(_scan(truth[45], 1), odom0)
        assert r.status is ProcessStatus.LOST and loc.relocalizations == []
        assert search.busy()
        assert search.wait(120.0)
        odom = se2_compose(odom0, se2_between(truth[45], truth[47]))
        r = loc.process(_scan(truth[47], 2), odom)
        assert r.status is ProcessStatus.LOCALIZED
        assert _err(r.pose, truth[47])[0] < 0.05
        assert len(search.search_cpu_s) == 1 and search.search_cpu_s[0] > 0.0
        # the map is sent once: a second search reuses the child's grid
        key = loc._global_source().key
        search.submit(loc._global_source(), scan_points(_scan(truth[47], 3), 12.0))
        assert loc._global_source().key == key
        assert search.wait(120.0)
        ticket, match = search.poll()  # type: ignore[misc]
        assert ticket == 2 and isinstance(match, MatchResult)
    finally:
        search.close()
    assert not search.busy()


# --- a kidnapped robot on a recorded log ----------------------------------------------

INTEL_MAPPED = 200
"""The Intel log's first scans, mapped (slam_toolbox's sample parameters, corrected poses as
odometry); the robot is then carried from scan 20's place to scan 100's (9.4 m away) and
drives on to scan 130 with odometry that never saw the carry."""


@pytest.fixture(scope="module")
def intel(
    tmp_path_factory: pytest.TempPathFactory,
) -> tuple[object, list[Scan], np.ndarray, np.ndarray]:
    log = read_carmen(dataset("slam2d", "intel", "intel-corrected.log.gz"))
    lasers = log.lasers[:INTEL_MAPPED]
    truth = np.array([r.laser_pose for r in lasers])
    config = dataclasses.replace(
        load_slam_config(Path(__file__).resolve().parents[2] / "config" / "slam_defaults.yaml"),
        max_odometry_jump=2.0,  # one scan per ~0.6 m of travel, up to 1.3 m
    )
    mapped = replay_lasers(lasers, config, odometry=list(truth))
    path = save_session(mapped.core, tmp_path_factory.mktemp("intel") / "intel.eslam")
    scans = [Scan(r.ranges, r.angles, 0.0, r.range_max, round(r.timestamp * 1e9)) for r in lasers]
    # the map's own pose of each scan (NaN where the scan made no node): the session's poses
    # lie ~0.26 m off the corrected log's around scans 95-130, and a localization can only
    # be as right as the map it is in
    index = {scan.stamp_ns: i for i, scan in enumerate(scans)}
    in_map = np.full((len(scans), 3), np.nan)
    for node, pose in zip(mapped.core.nodes, mapped.core.node_poses()):
        in_map[index[node.scan.stamp_ns]] = pose
    return path, scans, truth, in_map


def _kidnapped_errors(
    intel: tuple[object, list[Scan], np.ndarray, np.ndarray], search: RelocalizationProcess | None
) -> tuple[list[float], SlamCore]:
    path, scans, truth, in_map = intel
    assert not np.isnan(in_map[100:130]).any()
    loc = load_session(path, mode="localization")  # type: ignore[arg-type]
    loc.global_search = search
    loc.set_initial_pose(truth[20], truth[100])
    errors = []
    for k in range(100, 130):
        if search is not None and search.busy():
            assert search.wait(120.0)  # an idle core: the answer comes before the next scan
        r = loc.process(scans[k], truth[k], expected_beams=scans[k].ranges.size)
        assert r.pose is not None
        errors.append(float(np.hypot(*(r.pose[:2] - in_map[k][:2]))))
    return errors, loc


@pytest.mark.parametrize("in_process", [False, True])
def test_kidnapped_robot_on_a_recorded_log_is_back_a_scan_after_the_search(
    intel, in_process: bool
) -> None:
    search = RelocalizationProcess() if in_process else None
    try:
        errors, loc = _kidnapped_errors(intel, search)
    finally:
        if search is not None:
            search.close()
    # tracked on the wrong pose (the map supports the first scans there) until
    # scan_buffer_size scans in a row are not supported; the view of the buffered scans is
    # then checked at the newest scan's best places, and the answer is right
    back = next(n for n, e in enumerate(errors) if e < 0.3)
    assert min(errors[:back]) > 1.0
    size = loc.config.scan_buffer_size
    assert back <= 2 * size + 1 + int(in_process)
    assert max(errors[back:]) < 0.1  # the scans are in the map: found where it has them
    accepted = [a for a in loc.relocalizations if a.accepted]
    assert len(accepted) == 1 and accepted[0].response >= loc.config.loop_match_minimum_response_fine


def test_the_newest_scan_proposes_distinct_places_best_first(intel) -> None:
    path, scans, _, in_map = intel
    loc = load_session(path, mode="localization")  # type: ignore[arg-type]
    grid, source = loc._global_grid()
    points = scan_points(scans[100], loc.config.max_laser_range)
    poses, responses = scan_candidates(points, grid, source.prior, source.params)
    assert 1 < len(poses) <= CANDIDATES
    assert np.all(np.diff(responses) <= 0.0)
    # the true place is the best (on the coarse search's 5 cm and 2° steps); the others are
    # at least 0.5 m or two heading steps away from each other (one per place)
    assert np.hypot(*(poses[0][:2] - in_map[100][:2])) < 0.1
    assert abs(float(wrap_angle(poses[0][2] - in_map[100][2]))) < 0.05
    step = source.params.coarse_angle_resolution
    for i in range(len(poses)):
        for j in range(i):
            apart = np.abs(poses[i][:2] - poses[j][:2]).max()
            turn = abs(float(wrap_angle(poses[i][2] - poses[j][2])))
            assert apart > 0.5 - grid.resolution or turn > 2.5 * step
    # the single best of the plain whole-map search is the same place
    best = source.search(points, grid)
    assert np.hypot(*(best.pose[:2] - poses[0][:2])) < 0.3



def test_candidates_stay_distinct_in_a_cluttered_map() -> None:
    """However the branch and bound meets the leaves, no two kept candidates are one place:
    a better leaf within reach of several kept ones takes the place of all of them (when it
    replaced only the first, that one could move next to another, as on the third map)."""
    from eddiebot.slam.scan_matcher import MatcherParams
    from eddiebot.slam.scan_matcher.grid import build_correlation_grid

    step = 0.0349
    sep = round(SEPARATION / 0.05)
    checked = 0
    for seed in range(30):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(50, 800))
        smear = float(rng.choice([0.03, 0.05, 0.1]))
        params = MatcherParams(search_dimension=8.0, resolution=0.05, smear_deviation=smear,
                               coarse_angle_offset=0.35, coarse_angle_resolution=step)
        world = rng.uniform(-5.0, 5.0, (n, 2))
        grid = build_correlation_grid(world, (-6.0, -6.0, 6.0, 6.0), 0.05, smear, 6)
        seen = world[rng.choice(n, int(rng.integers(10, min(200, n))), replace=False)]
        th = rng.uniform(-0.3, 0.3)
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        points = (seen - rng.uniform(-2.0, 2.0, 2)) @ rot + rng.normal(0.0, 0.03, seen.shape)
        poses, responses = scan_candidates(points, grid, np.zeros(3), params,
                                           margin=float(rng.choice([0.1, 0.3, 1.0])))
        assert np.all(np.diff(responses) <= 0.0)
        for i in range(len(poses)):
            for j in range(i):
                cells = np.round(np.abs(poses[i][:2] - poses[j][:2]) / 0.05).max()
                turns = round(abs(float(wrap_angle(poses[i][2] - poses[j][2]))) / step)
                assert cells > sep or turns > 2, (seed, poses[i], poses[j])
                checked += 1
    assert checked > 100
