"""SlamCore: mapping a synthetic room, gating, bad input, localization, lifelong."""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest
from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

from eddiebot.maps import load_map, save_map
from eddiebot.slam import ProcessStatus, Scan, SlamConfig, SlamCore, load_session, save_session

CONFIG = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)


def _scan(pose: np.ndarray, stamp_ns: int) -> Scan:
    return Scan(raycast(ROOM, pose, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0, stamp_ns)


@pytest.fixture(scope="module")
def mapped() -> tuple[SlamCore, np.ndarray, np.ndarray, list]:
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(CONFIG)
    results = [
        core.process(_scan(p, k * 100_000_000), o) for k, (p, o) in enumerate(zip(truth, odom))
    ]
    return core, truth, odom, results


def test_mapping_tracks_truth_better_than_odometry(mapped) -> None:
    core, truth, odom, results = mapped
    added = [k for k, r in enumerate(results) if r.status is ProcessStatus.ADDED]
    assert 30 < len(added) < len(truth)
    est = core.node_poses()
    err = np.hypot(*(est[:, :2] - truth[added, :2]).T)
    odo_err = np.hypot(*(odom[added, :2] - truth[added, :2]).T)
    assert odo_err.max() > 0.5
    assert err.max() < 0.08
    assert err.mean() < 0.04
    assert err.max() < 0.1 * odo_err.max()
    # map→odom maps the last odometry pose onto the estimate
    last = results[added[-1]]
    assert last.pose is not None
    from eddiebot.geometry import se2_compose

    assert np.allclose(se2_compose(last.map_to_odom, odom[added[-1]]), last.pose, atol=1e-9)


def test_sequential_edges_carry_a_fifth_of_the_match_position_variance(mapped) -> None:
    # Karto's response-spread covariance is ~5x the true error's variance in position on the
    # corrected Intel / ACES logs (docs/benchmarks/slam.md#slam-sequential-covariance): the
    # edge keeps its shape and heading, the match's own reported covariance stays Karto's
    from eddiebot.slam.pose_graph import EdgeKind

    core, _, _, results = mapped
    by_node = {r.node_id: r for r in results if r.status is ProcessStatus.ADDED}
    checked = 0
    for e in core.graph.edges:
        if e.kind is not EdgeKind.SCAN_MATCH or e.j != e.i + 1:
            continue
        match = by_node[e.j].covariance
        assert match is not None
        edge_w = np.linalg.eigvalsh(e.covariance[:2, :2])
        match_w = np.linalg.eigvalsh(match[:2, :2])
        assert np.allclose(edge_w, 0.2 * match_w, rtol=1e-6)
        assert e.covariance[2, 2] == pytest.approx(match[2, 2], rel=1e-9)
        checked += 1
    assert checked > 25


def test_processing_rule_distance_or_heading(mapped) -> None:
    core, truth, _, results = mapped
    statuses = [r.status for r in results]
    assert statuses[0] is ProcessStatus.ADDED
    assert statuses[1] is ProcessStatus.NOT_MOVED  # 0.25 m < 0.5 m
    # turning on the spot is processed (upstream's sync gate would refuse it)
    core2 = SlamCore(CONFIG)
    pose = np.array([5.0, 5.0, 0.0])
    assert core2.process(_scan(pose, 0), pose).status is ProcessStatus.ADDED
    turned = pose + np.array([0.0, 0.0, 0.6])
    assert core2.process(_scan(turned, 1), turned).status is ProcessStatus.ADDED


def test_occupancy_map_export(mapped, tmp_path) -> None:
    core, *_ = mapped
    grid = core.occupancy_map()
    assert grid.resolution == CONFIG.resolution
    # the wall at x = 12 is occupied, the robot's path free
    from eddiebot.maps import world_to_map

    c, r = world_to_map(grid, [11.99, 5.0])
    assert grid.data[r - 1 : r + 2, c - 1 : c + 2].max() == 100
    c, r = world_to_map(grid, [5.0, 5.0])
    assert grid.data[r, c] == 0
    yaml_path = save_map(grid, tmp_path / "room")
    assert load_map(yaml_path).data.shape == grid.data.shape


def test_bad_scans_are_skipped_with_one_warning_each() -> None:
    seen = []
    core = SlamCore(CONFIG, on_warning=seen.append)
    pose = np.array([5.0, 5.0, 0.0])
    assert core.process(_scan(pose, 1_000), pose).status is ProcessStatus.ADDED
    moved = pose + np.array([1.0, 0.0, 0.0])
    bad_cases = [
        Scan(np.full(360, np.nan), SCAN_ANGLES, 0.05, 12.0, 2_000),
        Scan(np.zeros(360), SCAN_ANGLES, 0.05, 12.0, 2_000),
        Scan(np.full(360, np.inf), SCAN_ANGLES, 0.05, 12.0, 2_000),
        Scan(np.ones(200), SCAN_ANGLES, 0.05, 12.0, 2_000),  # fewer ranges than angles
        _scan(moved, 500),  # time went backwards
    ]
    for scan in bad_cases:
        result = core.process(scan, moved)
        assert result.status is ProcessStatus.SKIPPED
        assert len(result.warnings) == 1
    # fewer beams than announced
    r = core.process(_scan(moved, 3_000), moved, expected_beams=720)
    assert r.status is ProcessStatus.SKIPPED
    assert "announced" in r.warnings[0].message
    r = core.process(_scan(moved, 3_000), [np.nan, 0.0, 0.0])
    assert r.status is ProcessStatus.SKIPPED
    assert len(seen) == 7
    assert len(core.nodes) == 1
    assert len(core.graph) == 1
    assert core.process(_scan(moved, 4_000), moved).status is ProcessStatus.ADDED
    assert len(core.graph.edges) == 1


def test_corridor_warning_hook() -> None:
    from slam_world import CORRIDOR

    seen = []
    core = SlamCore(SlamConfig(corridor_covariance_threshold=0.002), on_warning=seen.append)
    for k in range(4):
        pose = np.array([10.0 + 0.5 * k, 1.0, 0.0])
        r = raycast(CORRIDOR, pose, SCAN_ANGLES, 5.0)
        core.process(Scan(r, SCAN_ANGLES.copy(), 0.05, 5.0, k), pose)
    assert any(w.kind == "low_feature" for w in seen)


def test_session_round_trip_and_localization(mapped, tmp_path) -> None:
    core, truth, *_ = mapped
    path = save_session(core, tmp_path / "room.eslam")
    loaded = load_session(path)
    assert np.allclose(loaded.node_poses(), core.node_poses())
    assert len(loaded.graph.edges) == len(core.graph.edges)
    assert [e.kind for e in loaded.graph.edges] == [e.kind for e in core.graph.edges]
    for a, b in zip(loaded.nodes, core.nodes):
        assert np.array_equal(a.scan.ranges, b.scan.ranges, equal_nan=True)
        assert a.scan.stamp_ns == b.scan.stamp_ns
    assert np.array_equal(loaded.occupancy_map().data, core.occupancy_map().data)
    # localization: odometry starts at zero somewhere on the map
    loc = load_session(path, mode="localization")
    start = truth[10]
    loc.set_initial_pose(start + np.array([0.1, -0.1, 0.05]))
    nodes_before = len(loc.graph)
    odom0 = np.zeros(3)
    from eddiebot.geometry import se2_between, se2_compose

    for k in (10, 14, 18):
        odom = se2_compose(odom0, se2_between(start, truth[k]))
        r = loc.process(_scan(truth[k], 10**9 + k), odom)
        assert r.status is ProcessStatus.LOCALIZED
        assert r.pose is not None
        assert np.hypot(*(r.pose[:2] - truth[k, :2])) < 0.03
    assert len(loc.graph) == nodes_before


def test_lifelong_continues_and_retires(mapped, tmp_path) -> None:
    core, truth, *_ = mapped
    path = save_session(core, tmp_path / "room.eslam")
    life = load_session(path, mode="lifelong")
    n0 = len(life.graph)
    life.set_initial_pose(truth[0])
    for k in range(0, 20, 2):
        from eddiebot.geometry import se2_between

        life.process(_scan(truth[k], 10**9 + k), se2_between(truth[0], truth[k]))
    assert len(life.graph) > n0
    assert not life.active_mask().all()  # the old scans of the revisited stretch retired
    assert np.hypot(*(life.node_poses()[-1, :2] - truth[18, :2])) < 0.05


def test_corrupt_and_wrong_version_sessions(mapped, tmp_path) -> None:
    import json
    import zipfile

    from eddiebot.slam import SessionError, SessionVersionError

    core, *_ = mapped
    bad = tmp_path / "bad.eslam"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(SessionError, match=r"bad\.eslam"):
        load_session(bad)
    good = save_session(core, tmp_path / "good.eslam")
    newer = tmp_path / "newer.eslam"
    with zipfile.ZipFile(good) as zin, zipfile.ZipFile(newer, "w") as zout:
        header = json.loads(zin.read("header.json"))
        header["version"] = 99
        zout.writestr("header.json", json.dumps(header))
        zout.writestr("arrays.npz", zin.read("arrays.npz"))
    with pytest.raises(SessionVersionError, match="version 99"):
        load_session(newer)
    # a failed save leaves the previous file intact
    before = good.read_bytes()
    with pytest.raises(SessionError):
        save_session(core, tmp_path / "missing-dir" / "good.eslam")
    assert good.read_bytes() == before
    truncated = tmp_path / "truncated.eslam"
    truncated.write_bytes(before[: len(before) // 2])
    with pytest.raises(SessionError):
        load_session(truncated)


def test_clear_forgets_everything(mapped) -> None:
    core = SlamCore(CONFIG)
    pose = np.array([5.0, 5.0, 0.0])
    core.process(_scan(pose, 0), pose)
    core.clear()
    assert len(core.graph) == 0
    assert core.nodes == []
    assert np.allclose(core.map_to_odom, 0.0)
    assert math.isclose(float(core.process(_scan(pose, 0), pose).map_to_odom[0]), 0.0, abs_tol=1e-9)


def test_map_max_laser_range_cuts_only_the_grid() -> None:
    from eddiebot.slam.errors import ConfigError

    truth = loop_path()[:12]
    full = SlamCore(CONFIG)
    short = SlamCore(SlamConfig(minimum_travel_distance=0.5, map_max_laser_range=2.0))
    for k, p in enumerate(truth):
        full.process(_scan(p, k * 100_000_000), p)
        short.process(_scan(p, k * 100_000_000), p)
    assert np.allclose(full.node_poses(), short.node_poses(), atol=1e-6)
    occ_full = int(np.count_nonzero(full.occupancy_map().data >= 65))
    occ_short = int(np.count_nonzero(short.occupancy_map().data >= 65))
    assert occ_short < occ_full
    with pytest.raises(ConfigError):
        SlamConfig(map_max_laser_range=-1.0).validated()


# -- degeneracy handling along a featureless corridor (57° scans, as Eddie's Kinect)

NARROW = np.linspace(-0.5, 0.5, 120)


def _corridor_scan(pose: np.ndarray, stamp_ns: int, range_bias: float = 0.0) -> Scan:
    from slam_world import CORRIDOR

    r = raycast(CORRIDOR, pose, NARROW, 8.0)
    # a depth camera's scan taken as the nearest of several rows reads short by ~k·r²
    seen = np.isfinite(r)
    r[seen] -= range_bias * r[seen] ** 2
    return Scan(r, NARROW.copy(), 0.05, 8.0, stamp_ns)


def test_scan_geometry_shows_the_corridor_degeneracy() -> None:
    from eddiebot.slam.mapper import scan_position_covariance
    from eddiebot.slam.scan import scan_points
    from eddiebot.slam.scan_matcher import point_normals

    def cov_at(x: float, quadratic: float) -> np.ndarray:
        pts = scan_points(_corridor_scan(np.array([x, 1.0, 0.0]), 0), 8.0)
        return scan_position_covariance(pts, point_normals(pts), 0.01, quadratic)

    # side walls only (the end wall 20 m away): nothing pins the position along the corridor
    mid = cov_at(10.0, 2.5e-3)
    assert mid[0, 0] > 1.0e3
    assert mid[1, 1] < 2.0e-3
    assert abs(mid[0, 1]) < 1e-6
    # the end wall 7 m ahead pins it, but only as well as its range error there (σ ≈ 0.13 m)
    far = cov_at(23.0, 2.5e-3)
    assert 0.01 < far[0, 0] < 0.05
    assert far[1, 1] < 2.0e-3
    # 2.5 m ahead it pins it well; without range growth every wall does
    assert cov_at(27.5, 2.5e-3)[0, 0] < 2.0e-3
    assert cov_at(23.0, 0.0)[0, 0] < 2.0e-3


def test_corridor_graph_fused_with_odometry_keeps_the_walls_across() -> None:
    # Approaching the corridor's end wall from 13 to 6.5 m: scans read it short by 2.5e-3·r²
    # (0.12 m at 7 m) and the wheel odometry is exact along the corridor but slips 1 cm
    # sideways per step. Across the corridor the walls win over the odometry; along it the
    # match is pulled towards the end wall by the bias.
    truth = np.array([[17.0 + 0.5 * k, 1.0, 0.0] for k in range(14)])
    odom = truth + np.array([[0.0, 0.01 * k, 0.0] for k in range(14)])
    core = SlamCore(
        SlamConfig(
            fuse_odometry=True,
            max_laser_range=8.0,
            do_loop_closing=False,
        )
    )
    for k, (p, o) in enumerate(zip(truth, odom)):
        assert core.process(_corridor_scan(p, k * 100_000_000, 2.5e-3), o).processed
    err = core.node_poses() - truth
    assert np.abs(err[:, 1]).max() < 0.04 < np.abs(odom[:, 1] - truth[:, 1]).max()
    assert err[-1, 0] < -0.015


def test_range_bias_slows_a_corridor_approach() -> None:
    # The match alone (slam_toolbox's behaviour) sets each pose: with the end wall read
    # short (7.5 m to 5 m ahead) the robot seems to approach it more slowly than it does.
    truth = np.array([[22.5 + 0.5 * k, 1.0, 0.0] for k in range(6)])
    core = SlamCore(
        SlamConfig(
            max_laser_range=8.0,
            do_loop_closing=False,
        )
    )
    for k, p in enumerate(truth):
        assert core.process(_corridor_scan(p, k * 100_000_000, 2.5e-3), p).processed
    err = core.node_poses() - truth
    assert err[-1, 0] < -0.03


@pytest.mark.parametrize("cap", [0, 1])
def test_loop_match_maximum_chains_bounds_the_verifications_per_scan(
    cap: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    import eddiebot.slam.mapper.mapping as mapper_module

    per_scan: list[int] = []
    plain = mapper_module.verify_loop

    def counting(*args: object, **kwargs: object) -> None:
        # every candidate fails: each scan tries all it is allowed
        per_scan[-1] += 1
        plain(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(mapper_module, "verify_loop", counting)
    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(
        SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=2,
                   loop_match_maximum_chains=cap)
    )
    for k, (p, o) in enumerate(zip(truth, odom)):
        per_scan.append(0)
        core.process(_scan(p, k * 100_000_000), o)
    assert not core.loop_closures
    if cap == 0:
        assert max(per_scan) >= 2  # several candidate chains at once on the second lap
    else:
        assert max(per_scan) == cap


def test_loop_match_maximum_chains_is_checked() -> None:
    from eddiebot.slam.errors import ConfigError

    with pytest.raises(ConfigError, match="loop_match_maximum_chains"):
        SlamConfig(loop_match_maximum_chains=-1).validated()


def _out_and_back_with_spins() -> np.ndarray:
    """Spin in place, drive 8 m down the room, spin, drive back, spin at the start again."""
    def spin(x: float, y: float, th0: float, n: int = 14) -> list[list[float]]:
        return [[x, y, th0 + 0.3 * k] for k in range(n)]

    out = [[1.5 + 0.25 * k, 4.0, 0.0] for k in range(1, 33)]
    back = [[9.5 - 0.25 * k, 4.0, math.pi] for k in range(1, 33)]
    truth = np.array(spin(1.5, 4.0, -14 * 0.3) + out + spin(9.5, 4.0, 0.0)[1:] + back
                     + spin(1.5, 4.0, math.pi)[1:])
    truth[:, 2] = np.arctan2(np.sin(truth[:, 2]), np.cos(truth[:, 2]))
    return truth


@pytest.mark.parametrize("distance", [1.5, 0.0])
def test_near_chains_tie_a_revisit_to_the_first_pass(distance: float) -> None:
    from eddiebot.geometry import se2_between
    from eddiebot.slam import EdgeKind

    truth = _out_and_back_with_spins()
    odom = drifting_odometry(truth, heading_bias=0.004)
    core = SlamCore(SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6,
                               link_scan_maximum_distance=distance))
    results = [core.process(_scan(p, k * 100_000_000), o)
               for k, (p, o) in enumerate(zip(truth, odom))]
    added = [k for k, r in enumerate(results) if r.status is ProcessStatus.ADDED]
    links = [e for e in core.graph.edges if e.robust and e.kind is EdgeKind.SCAN_MATCH]
    assert core.near_chain_links == len(links)
    if distance == 0.0:
        assert not links  # Karto's near-chain linking off
        return
    # Karto's LinkNearChains: once the graph ties a revisit to an earlier pass, the scans
    # there are matched against that pass and linked to it (the final spin to the first)
    first_spin = {n for n, k in enumerate(added) if k < 14}
    final_spin = {n for n, k in enumerate(added) if k >= len(truth) - 13}
    assert sum(e.i in first_spin and e.j in final_spin for e in links) >= 5
    for e in links:
        assert e.i < e.j - core.config.loop_match_minimum_chain_size
        true = se2_between(truth[added[e.i]], truth[added[e.j]])
        err = e.measurement - true
        assert math.hypot(err[0], err[1]) < 0.03
        assert abs(math.remainder(err[2], 2 * math.pi)) < math.radians(1.0)
    err = np.hypot(*(core.node_poses()[:, :2] - truth[added, :2]).T)
    assert err.max() < 0.01


def _slipping_drive(config: SlamConfig) -> tuple[SlamCore, np.ndarray, list[int], list, int]:
    """The loop drive with exact odometry that jumps 0.6 m forward (a wheel slip, beyond the
    ±0.25 m sequential window) at the 30th pose; counts the wide re-searches."""
    truth = loop_path()
    odom = truth.copy()
    odom[30:, 0] += 0.6
    seen: list = []
    core = SlamCore(config, on_warning=seen.append)
    wide = 0
    plain = core._match_against

    def counting(nodes, points, prior, params, **kwargs):  # type: ignore[no-untyped-def]
        nonlocal wide
        wide += params is core._slip_params
        return plain(nodes, points, prior, params, **kwargs)

    core._match_against = counting  # type: ignore[method-assign]
    added = [
        k
        for k, (p, o) in enumerate(zip(truth, odom))
        if core.process(_scan(p, k * 100_000_000), o).processed
    ]
    return core, truth, added, seen, wide


def test_a_wheel_slip_beyond_the_window_is_found_by_the_wide_search() -> None:
    core, truth, added, seen, wide = _slipping_drive(CONFIG)
    slips = [w for w in seen if w.kind == "slip"]
    assert len(slips) == 1 and "odometry off by 0.6" in slips[0].message
    err = np.hypot(*(core.node_poses()[:, :2] - truth[added, :2]).T)
    assert err.max() < 0.03
    assert 1 <= wide < len(added) // 2
    core_off, _, added_off, seen_off, _ = _slipping_drive(
        dataclasses.replace(CONFIG, slip_search_dimension=0.0)
    )
    err_off = np.hypot(*(core_off.node_poses()[:, :2] - truth[added_off, :2]).T)
    # without it, part of the jump stays in the map even after the loop closes (0.11 m here)
    assert not any(w.kind == "slip" for w in seen_off)
    assert err_off.max() > 0.08 and err_off.max() > 4 * err.max()


def test_slip_search_minimum_response_decouples_the_re_search_from_loop_acceptance() -> None:
    # a strict loop threshold alone makes every sequential match "weak" and re-searched
    # widely; slip_search_minimum_response keeps the re-search for weak matches only
    _, _, added, _, wide_default = _slipping_drive(CONFIG)
    strict = dataclasses.replace(CONFIG, loop_match_minimum_response_fine=0.999)
    _, _, _, _, wide_coupled = _slipping_drive(strict)
    _, truth, added_dec, seen, wide_decoupled = _slipping_drive(
        dataclasses.replace(strict, slip_search_minimum_response=0.45)
    )
    assert wide_coupled > len(added) // 2 > wide_default
    assert wide_decoupled == wide_default
    assert sum(w.kind == "slip" for w in seen) == 1


def test_warm_up_compiles_what_a_mapping_run_needs() -> None:
    # a fresh process with an empty numba cache: the warm-up compiles the kernels, and a
    # mapping run afterwards compiles nothing more (numba's compile events are counted)
    import subprocess
    import sys
    import tempfile
    import textwrap

    code = textwrap.dedent(
        """
        from numba.core import event
        from slam_world import ROOM, SCAN_ANGLES, loop_path, raycast
        from eddiebot.slam import Scan, SlamConfig, SlamCore
        from eddiebot.slam.mapper import warm_up

        class Compiles(event.Listener):
            def __init__(self):
                self.names = []
            def on_start(self, ev):
                self.names.append(getattr(ev.data.get("dispatcher"), "__name__", "?"))
            def on_end(self, ev):
                pass

        config = SlamConfig(minimum_travel_distance=0.5, loop_match_minimum_chain_size=6)
        during_warm_up = Compiles()
        with event.install_listener("numba:compile", during_warm_up):
            warm_up(config)
        after = Compiles()
        with event.install_listener("numba:compile", after):
            core = SlamCore(config)
            for k, p in enumerate(loop_path()):
                scan = Scan(raycast(ROOM, p, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0,
                            k * 100_000_000)
                core.process(scan, p)
            core.update_map()
        print(len(during_warm_up.names), len(core.loop_closures), ",".join(after.names) or "-")
        """
    )
    here = Path(__file__).resolve().parent
    with tempfile.TemporaryDirectory() as cache:
        out = subprocess.run(
            [sys.executable, "-c", code],
            cwd=here,
            env={**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(here)},
            capture_output=True,
            text=True,
            timeout=600,
            check=True,
        ).stdout.split()
    compiled, loops, later = int(out[0]), int(out[1]), out[2]
    assert compiled >= 5  # it compiled (an empty cache)
    assert loops >= 1  # the run closed a loop, so the loop matcher ran too
    assert later == "-", f"compiled during the mapping run, after the warm-up: {later}"
