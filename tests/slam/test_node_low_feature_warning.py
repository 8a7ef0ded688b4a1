"""The SLAM node logs a low-feature warning once per episode."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from _support.slam_scans import kinect_scan
from eddiebot.core.context import Context
from eddiebot.slam.mapper import ProcessResult, ProcessStatus, SlamWarning
from eddiebot.slam.node import LOW_FEATURE_CLEAR_MATCHES, SlamNode


def _result(kinds: tuple[str, ...]) -> ProcessResult:
    warnings = tuple(SlamWarning(k, f"{k} here") for k in kinds)
    return ProcessResult(ProcessStatus.ADDED, np.zeros(3), pose=np.zeros(3), node_id=0,
                         response=0.6, covariance=np.eye(3) * 1e-4, warnings=warnings)


def _step(node: SlamNode, kinds: tuple[str, ...]) -> None:
    """What `SlamNode._process` does with one processed scan's outcome."""
    for w in _result(kinds).warnings:
        node._on_warning(w)
    node._track_low_feature(_result(kinds))


def test_low_feature_warning_once_per_episode(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    context = Context(use_sim_time=True)
    node = SlamNode(context=context)
    try:
        corridor = ("low_feature",)
        # episode 1: ten poorly constrained matches, a door (one good match) in the middle
        for k in range(10):
            _step(node, () if k == 5 else corridor)
        # the corridor ends: well-constrained matches close the episode...
        for _ in range(LOW_FEATURE_CLEAR_MATCHES):
            _step(node, ())
        # ...a weak match (odometry only) neither closes nor opens one
        _step(node, ("weak_match",))
        # episode 2
        for _ in range(4):
            _step(node, corridor)
    finally:
        node.destroy_node()
        context.shutdown()
    logged = [r for r in caplog.records
              if r.levelno == logging.WARNING and "corridor_covariance_threshold" in r.getMessage()]
    assert len(logged) == 2
    assert node.low_feature_episodes == 2
    assert node.low_feature_matches == 13
    again = [r for r in caplog.records if "well constrained again" in r.getMessage()]
    assert len(again) == 1


def test_core_flags_a_corridor_scan_the_node_counts() -> None:
    """End to end through the core: a featureless corridor drive raises low_feature warnings
    that the node turns into one episode."""
    from eddiebot.geometry import se2_compose

    context = Context(use_sim_time=True)
    node = SlamNode(context=context)
    try:
        rng = np.random.default_rng(0)
        core = node.core
        for k in range(30):
            truth = np.array([3.0 + 0.2 * k, 1.0, 0.0])
            scan = kinect_scan(truth, k * 200_000_000, rng)
            result = core.process(scan, se2_compose(np.zeros(3), truth))
            if result.processed:
                node._track_low_feature(result)
    finally:
        node.destroy_node()
        context.shutdown()
    assert node.low_feature_matches >= 5
    assert node.low_feature_episodes == 1
