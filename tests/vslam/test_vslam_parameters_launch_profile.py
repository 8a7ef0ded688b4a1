"""The product runs the measured configuration: `launch/vslam.yaml` (what `eddie vslam` starts)
and `demo.vslam_stage.SLAM_PARAMETERS` (what `eddie demo` and the benchmarks pass) agree."""

from __future__ import annotations

from eddiebot.core.context import Context
from eddiebot.core.launch import find_launch_file, parse_launch_file
from eddiebot.demo.vslam_stage import SLAM_PARAMETERS
from eddiebot.vslam.node import RtabmapNode
from eddiebot.vslam.parameters import RtabmapParameters, parameter_names


def _launch_params() -> dict[str, object]:
    desc = parse_launch_file(find_launch_file("vslam"), {})
    spec = next(n for n in desc.nodes if n.type == "eddiebot.vslam.rtabmap")
    return dict(spec.params)


def test_launch_file_carries_slam_parameters():
    launch = _launch_params()
    missing = sorted(set(SLAM_PARAMETERS) - set(launch))
    assert not missing, f"launch/vslam.yaml lacks {missing}"
    for name, value in SLAM_PARAMETERS.items():
        if "/" in name:  # RTAB-Map names are strings in both
            assert str(launch[name]) == str(value), name
        else:
            assert float(launch[name]) == float(value), name  # type: ignore[arg-type]
    # the profile's RTAB-Map names are ones this implementation reads, every known value valid
    # (the report's Optimizer/Strategy is accepted and reported as unused by the node)
    known = set(parameter_names())
    assert {k for k in SLAM_PARAMETERS if "/" in k} <= known
    RtabmapParameters.from_dict({k: str(v) for k, v in launch.items() if k in known})


def test_node_started_from_the_launch_file_runs_the_profile(tmp_path):
    launch = _launch_params()
    launch.update({"database_path": str(tmp_path / "rtabmap.db"), "rtabmap_args": ""})
    context = Context(use_sim_time=True)
    node = RtabmapNode(context=context, parameter_overrides=launch)
    try:
        p = node.core.params
        want = RtabmapParameters().replace({k: str(v) for k, v in SLAM_PARAMETERS.items()
                                            if "/" in k})
        for name in (k for k in SLAM_PARAMETERS if "/" in k):
            assert p.to_dict()[name] == want.to_dict()[name], name
        assert p.rtabmap_loop_thr == float(SLAM_PARAMETERS.get("Rtabmap/LoopThr", 0.11))
        assert node.odom_tf_linear_variance == float(SLAM_PARAMETERS["odom_tf_linear_variance"])
        assert node.odom_tf_angular_variance == float(SLAM_PARAMETERS["odom_tf_angular_variance"])
        assert p.rgbd_loop_closure_max_mahalanobis == 4.0  # the gate the profile was measured with
    finally:
        node.destroy_node()
        context.shutdown()


def test_vslam_launch_is_the_simulator_plus_rgbd_mapping(tmp_path):
    """`eddie vslam` without --world runs rgbd_mapping.yaml alone: the same node, the same
    parameters, on the robot's clock; without /scan it maps without it."""
    full = parse_launch_file(find_launch_file("vslam"), {})
    alone = parse_launch_file(find_launch_file("rgbd_mapping"),
                              {"use_sim_time": "false", "subscribe_scan": "false"})
    assert [n.type for n in alone.nodes] == ["eddiebot.vslam.rtabmap"]
    assert "eddiebot.sim.simulator" in [n.type for n in full.nodes]
    spec = alone.nodes[0].params
    assert spec["use_sim_time"] is False and spec["subscribe_scan"] is False
    ran = {**spec, "use_sim_time": True, "subscribe_scan": True}
    assert ran == _launch_params()
