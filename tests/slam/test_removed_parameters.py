"""eddiebot options removed in the parameter audit: an old file that sets one still loads, the
key is named once as not supported, and the SLAM runs as without it."""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path

from eddiebot.slam import SlamConfig, load_slam_config
from eddiebot.slam.config import REMOVED_PARAMETERS, parameter_warnings

OLD_FILE = """\
slam_toolbox:
  ros__parameters:
    resolution: 0.05
    match_covariance: icp
    icp_covariance_floor_translation: 0.01
    loop_match_range_bias_quadratic: 0.0025
    odometry_span_batch: 5
    not_a_parameter: 3
"""


def test_removed_keys_are_not_fields() -> None:
    names = {f.name for f in fields(SlamConfig)}
    assert len(REMOVED_PARAMETERS) == 9
    assert not names & set(REMOVED_PARAMETERS)


def test_an_old_file_loads_and_names_each_removed_key(tmp_path: Path) -> None:
    path = tmp_path / "old_slam.yaml"
    path.write_text(OLD_FILE, encoding="utf-8")
    config = load_slam_config(path)
    assert config.resolution == 0.05
    assert config.extra["match_covariance"] == "icp"
    given = {**config.extra, "resolution": 0.05}
    lines = parameter_warnings(given, config)
    assert len(lines) == 4
    assert lines[0] == (
        "not supported: match_covariance, icp_covariance_floor_translation (removed eddiebot "
        "option: a match's covariance is the correlative search's, as Karto's; ignored)"
    )
    assert lines[1].startswith("not supported: loop_match_range_bias_quadratic (")
    assert lines[2].startswith("not supported: odometry_span_batch (")
    assert lines[3].startswith("unknown parameter: not_a_parameter (")
    assert config == load_slam_config(path, overrides={}) == SlamConfig(resolution=0.05)
