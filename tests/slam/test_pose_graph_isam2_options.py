"""iSAM2 elimination choices: Cholesky reaches QR's optimum, and falls back to QR when it fails."""

from __future__ import annotations

import numpy as np
import pytest

from _support.pose_graphs import LOOP_COV, ODO_COV, chained, incremental, two_laps
from eddiebot.geometry import se2_between, se2_compose
from eddiebot.slam import EdgeKind, PoseGraph
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.errors import ConfigError
from eddiebot.slam.mapper import SlamCore


@pytest.mark.parametrize(("skip", "tol"), [(1, 1e-4), (10, 2e-3)])
def test_cholesky_reaches_the_qr_optimum_with_the_same_verdicts(skip: int, tol: float) -> None:
    truth, edges = two_laps(3)
    qr = incremental(edges, truth)
    chol = incremental(edges, truth, factorization="cholesky", relinearize_skip=skip)
    assert chol.factorization == "cholesky" and chol.factorization_fallbacks == 0
    assert sorted(chol.rejected) == sorted(qr.rejected)
    assert len(chol.rejected) + len(chol.held) >= 8  # the false closures stay out
    # both at the same optimum: far below the 2 cm odometry noise
    assert float(np.max(np.abs(chol.poses - qr.poses))) < tol
    assert chol.half_chi2(include_rejected=False) == pytest.approx(
        qr.half_chi2(include_rejected=False), rel=10 * tol
    )


class _FailingOnce:
    """An iSAM2 stand-in whose next ``update`` with factors raises, as GTSAM does on an
    indeterminate system; everything else goes to the real one."""

    def __init__(self, inner: object) -> None:
        self._inner = inner
        self.failed = False

    def update(self, *args: object) -> object:
        if not self.failed and args:
            self.failed = True
            raise RuntimeError("Indeterminant linear system detected while working near variable 7")
        return self._inner.update(*args)  # type: ignore[attr-defined]

    def __getattr__(self, name: str) -> object:
        return getattr(self._inner, name)


def test_a_failing_cholesky_update_is_solved_in_batch_and_the_graph_stays_on_qr() -> None:
    truth, edges = two_laps(3)
    first = [e for e in edges if max(e[0], e[1]) < 20]
    graph = chained(truth[:20], first, factorization="cholesky")
    graph.optimize()
    failing = _FailingOnce(graph._isam)
    graph._isam = failing  # type: ignore[assignment]
    k = 20
    graph.add_node(se2_compose(graph.pose(k - 1), next(e for e in edges if e[:2] == (19, 20))[2]))
    graph.add_edge(19, 20, next(e for e in edges if e[:2] == (19, 20))[2], edges[0][3],
                   kind=EdgeKind.ODOMETRY)
    assert graph.optimize()
    assert failing.failed
    assert graph.isam_recoveries == 1
    assert graph.factorization == "qr" and graph.factorization_fallbacks == 1
    assert graph._isam is not failing  # restarted from the batch optimum, on QR
    # the estimate is the batch optimum of the same edges
    reference = chained(truth[:21], [e for e in edges if max(e[0], e[1]) <= 20],
                         optimizer="levenberg_marquardt")
    reference.optimize()
    assert float(np.max(np.abs(graph.poses[:, :2] - reference.poses[:, :2]))) < 1e-3
    # and it goes on incrementally
    graph.add_node(se2_compose(graph.pose(20), [1.0, 0.0, 0.0]))
    graph.add_edge(20, 21, [1.0, 0.0, 0.0], edges[0][3], kind=EdgeKind.ODOMETRY)
    graph.optimize()
    assert graph.isam_recoveries == 1
    assert np.allclose(se2_compose(graph.pose(20), [1.0, 0.0, 0.0]), graph.pose(21), atol=1e-6)


def test_factorization_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="factorization"):
        PoseGraph(factorization="lu")
    with pytest.raises(ValueError, match="relinearize_skip"):
        PoseGraph(relinearize_skip=0)
    with pytest.raises(ConfigError, match="isam2_factorization"):
        SlamConfig(isam2_factorization="LDL").validated()
    with pytest.raises(ConfigError, match="isam2_relinearize_skip"):
        SlamConfig(isam2_relinearize_skip=0).validated()


def test_slam_core_builds_its_graph_with_the_configured_elimination() -> None:
    core = SlamCore(SlamConfig(isam2_factorization="cholesky", isam2_relinearize_skip=10))
    assert core.graph.factorization == "cholesky"
    assert core.graph.relinearize_skip == 10
    core.clear()
    assert core.graph.factorization == "cholesky"


def _room_run(config: SlamConfig) -> tuple[SlamCore, np.ndarray, list]:
    from slam_world import ROOM, SCAN_ANGLES, drifting_odometry, loop_path, raycast

    from eddiebot.slam import Scan

    truth = loop_path()
    odom = drifting_odometry(truth)
    core = SlamCore(config)
    results = []
    for k, (p, o) in enumerate(zip(truth, odom)):
        scan = Scan(raycast(ROOM, p, SCAN_ANGLES, 12.0), SCAN_ANGLES.copy(), 0.05, 12.0,
                    k * 100_000_000)
        results.append(core.process(scan, o))
    return core, truth, results


def _with_spans(edges: list, truth: np.ndarray, span: int) -> list:
    """``edges`` plus an odometry edge from every node to the node ``span`` back (the chained
    noisy steps between them, with their summed covariance), as `odometry_span_nodes` adds."""
    odo = {e[1]: e for e in edges if not e[4] and e[1] == e[0] + 1}
    out = list(edges)
    for k in range(span, len(truth)):
        z = np.zeros(3)
        for m in range(k - span + 1, k + 1):
            z = se2_compose(z, odo[m][2])
        out.append((k - span, k, z, span * odo[k][3], False))
    out.sort(key=lambda e: max(e[0], e[1]))
    return out


def _long_laps(per_lap: int = 200, laps: int = 2, every: int = 25, seed: int = 1) -> tuple:
    """Laps of a 6 m square, ``per_lap`` nodes each, noisy odometry; every ``every``-th node
    after the first lap closes onto the first (sparse loops, as a building's revisits)."""
    rng = np.random.default_rng(seed)
    side = per_lap // 4
    corners = [(0.0, 0.0), (6.0, 0.0), (6.0, 6.0), (0.0, 6.0)]
    lap = np.array([
        (cx + 6.0 * i / side * np.cos(s * np.pi / 2), cy + 6.0 * i / side * np.sin(s * np.pi / 2),
         s * np.pi / 2)
        for s, (cx, cy) in enumerate(corners) for i in range(side)
    ])
    truth = np.concatenate([lap] * laps)
    edges = [(k - 1, k, se2_between(truth[k - 1], truth[k]) + rng.normal(0.0, [0.02, 0.02, 0.01]),
              ODO_COV, False) for k in range(1, len(truth))]
    edges += [(k % per_lap, k, se2_between(truth[k % per_lap], truth[k]), LOOP_COV, True)
              for k in range(per_lap, len(truth), every)]
    edges.sort(key=lambda e: max(e[0], e[1]))
    return truth, edges


def test_recent_nodes_last_keeps_the_optimum_and_re_eliminates_less() -> None:
    truth, edges = _long_laps()
    edges = _with_spans(edges, truth, 10)
    plain = incremental(edges, truth, factorization="cholesky")
    recent = incremental(edges, truth, factorization="cholesky", recent_last=11)
    assert sorted(recent.rejected) == sorted(plain.rejected)
    assert float(np.max(np.abs(recent.poses - plain.poses))) < 1e-4
    # the span edges' far ends stay at the root: about half the variables re-eliminated
    assert recent.variables_reeliminated < 0.6 * plain.variables_reeliminated
    with pytest.raises(ValueError, match="recent_last"):
        PoseGraph(recent_last=-1)


def test_recent_nodes_last_is_a_checked_config_parameter() -> None:
    core = SlamCore(SlamConfig(isam2_recent_nodes_last=11).validated())
    assert core.graph.recent_last == 11
    with pytest.raises(ConfigError, match="isam2_recent_nodes_last"):
        SlamConfig(isam2_recent_nodes_last=-1).validated()


def test_wildfire_threshold_reaches_isam2_and_keeps_the_optimum() -> None:
    truth, edges = _long_laps(per_lap=120, every=15)
    batch = chained(truth, edges, optimizer="levenberg_marquardt")
    batch.optimize()
    default = incremental(edges, truth, factorization="cholesky")
    exact = incremental(edges, truth, factorization="cholesky", wildfire_threshold=0.0)
    assert "wildfireThreshold: 0.001" in repr(default._isam.params())
    assert "wildfireThreshold: 0\n" in repr(exact._isam.params())
    assert sorted(exact.rejected) == sorted(default.rejected) == sorted(batch.rejected)
    # both at the batch optimum, well inside iSAM2's relinearisation threshold (0.01)
    for graph in (default, exact):
        assert float(np.max(np.abs(graph.poses - batch.poses))) < 1e-3
    with pytest.raises(ValueError, match="wildfire_threshold"):
        PoseGraph(wildfire_threshold=-0.1)
    core = SlamCore(SlamConfig(isam2_wildfire_threshold=0.0).validated())
    assert core.graph.wildfire_threshold == 0.0
    assert "wildfireThreshold: 0\n" in repr(core.graph._isam.params())
    with pytest.raises(ConfigError, match="isam2_wildfire_threshold"):
        SlamConfig(isam2_wildfire_threshold=float("nan")).validated()
