"""slam_toolbox users' parameter files launch the SLAM node, and what it does not use it says."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from eddiebot.core.context import Context
from eddiebot.core.launch import LaunchDescription, NodeSpec, build_nodes
from eddiebot.registry import NODES
from eddiebot.slam.config import load_slam_config
from eddiebot.slam.node import SlamNode

UPSTREAM = Path(__file__).resolve().parents[1] / "data" / "slam_toolbox"

CERES = (
    "ignored: solver_plugin, ceres_linear_solver, ceres_preconditioner, ceres_trust_strategy, "
    "ceres_dogleg_type, ceres_loss_function (GTSAM replaces Ceres: the pose graph is optimised "
    "with isam2, see the 'optimizer' parameter)"
)
STACK = "ignored: stack_size_to_use (the Python (de)serialisation needs no larger stack)"
LIFELONG = (
    "ignored: lifelong_search_use_tree, lifelong_minimum_score, lifelong_iou_match, "
    "lifelong_node_removal_score, lifelong_overlap_score_scale, lifelong_constraint_multiplier, "
    "lifelong_nearby_penalty, lifelong_candidates_scale (read in lifelong mode only, and mode "
    "is mapping)"
)

EXPECTED = {
    "mapper_params_online_async.yaml": [CERES, STACK],
    "mapper_params_online_sync.yaml": [CERES, STACK],
    "mapper_params_offline.yaml": [CERES, STACK],
    "mapper_params_localization.yaml": [CERES, STACK],
    "mapper_params_lifelong.yaml": [CERES, LIFELONG, STACK],
}


def _launch(context: Context, param_file: Path, **params: object) -> SlamNode:
    """Build the node as `eddie launch` does: registry type, parameter file, inline params."""
    spec = NodeSpec(
        type="eddiebot.slam.slam_toolbox",
        param_files=[param_file],
        params={"use_sim_time": True, **params},
        where="test",
    )
    (node,) = build_nodes(LaunchDescription(nodes=[spec]), context, NODES)
    assert isinstance(node, SlamNode)
    return node


def test_every_upstream_sample_file_is_in_the_test_data() -> None:
    assert sorted(p.name for p in UPSTREAM.glob("mapper_params_*.yaml")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_upstream_sample_launches_with_named_warnings(
    name: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    context = Context(use_sim_time=True)
    node = _launch(context, UPSTREAM / name)
    try:
        assert node.startup_warnings == EXPECTED[name]
        logged = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
        for line in EXPECTED[name]:
            assert logged.count(line) == 1  # once, at start
        # the file's values reach the core, as the CLI's loader reads them
        assert node.core.config == load_slam_config(UPSTREAM / name)
        assert node.config.scan_topic == "/scan"
        assert node.config.transform_timeout == 0.2
    finally:
        node.destroy_node()
        context.shutdown()


def test_unknown_and_inert_keys(tmp_path: Path) -> None:
    params = tmp_path / "p.yaml"
    params.write_text(
        "slam_toolbox:\n  ros__parameters:\n"
        "    mode: lifelong\n"
        "    lifelong_iou_match: 0.8\n"
        "    enable_interactive_mode: false\n"
        "    position_covariance_scale: 1.0\n"
        "    yaw_covariance_scale: 2.0\n"
        "    use_lifecycle_manager: true\n"
        "    scan_queue_size: 3\n"
        "    map_name: /slam_map\n"
        "    minimum_travle_distance: 0.3\n"
    )
    context = Context(use_sim_time=True)
    node = _launch(context, params)
    try:
        assert node.startup_warnings == [
            "ignored: yaw_covariance_scale (no ~/pose topic is published)",
            "ignored: use_lifecycle_manager (the node is not a lifecycle node: it starts active)",
            "unknown parameter: minimum_travle_distance (neither slam_toolbox's nor eddiebot's; "
            "ignored)",
        ]
        assert node.config.scan_queue_size == 3
        assert node.map_pub.topic == "/slam_map"
        assert node.meta_pub.topic == "/slam_map_metadata"
        assert node.config.extra == {"minimum_travle_distance": 0.3}
    finally:
        node.destroy_node()
        context.shutdown()


def test_use_map_saver_and_debug_logging(tmp_path: Path) -> None:
    params = tmp_path / "p.yaml"
    params.write_text(
        "slam_toolbox:\n  ros__parameters:\n    use_map_saver: false\n    debug_logging: true\n"
    )
    context = Context(use_sim_time=True)
    node = _launch(context, params)
    try:
        names = [s.service_name for s in node.services]
        assert not any(n.endswith("/save_map") for n in names)
        assert any(n.endswith("/serialize_map") for n in names)
        assert logging.getLogger(node.get_logger().name).level == logging.DEBUG
        assert node.startup_warnings == []
    finally:
        node.destroy_node()
        context.shutdown()


def test_bad_map_start_pose_names_the_key(tmp_path: Path) -> None:
    params = tmp_path / "p.yaml"
    params.write_text("slam_toolbox:\n  ros__parameters:\n    map_start_pose: [1.0, 2.0]\n")
    context = Context(use_sim_time=True)
    try:
        with pytest.raises(ValueError, match="map_start_pose"):
            _launch(context, params)
    finally:
        context.shutdown()
