"""CARMEN, TUM and parameter-file io."""

from __future__ import annotations

import gzip
import math
from pathlib import Path

import numpy as np
import pytest
from slam_world import dataset

from eddiebot.slam import CarmenFormatError, ConfigError, SlamConfig, load_slam_config
from eddiebot.slam.io import carmen_beam_angles, read_carmen, read_tum, write_tum

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def test_carmen_slice_of_mit_csail() -> None:
    log = read_carmen(dataset("slam2d", "mit-csail", "mit-csail.clf"), max_lasers=20)
    assert len(log.lasers) == 20
    first = log.lasers[0]
    assert first.ranges.shape == (361,)
    assert first.angles[0] == pytest.approx(-math.pi / 2)
    assert first.angles[-1] == pytest.approx(math.pi / 2)
    assert first.ranges[0] == pytest.approx(1.40)
    assert first.timestamp == pytest.approx(1134864629.895182)
    assert first.logger_timestamp == pytest.approx(0.086295)
    assert first.laser_pose == pytest.approx([576.536523, 0.106594, -2.255213])
    assert np.all(np.diff([r.timestamp for r in log.lasers]) > 0)


def test_carmen_corrected_gz_with_odom_and_params() -> None:
    log = read_carmen(dataset("slam2d", "intel", "intel-corrected.log.gz"), max_lasers=3)
    assert log.params["robot_frontlaser_offset"] == "0.0"
    assert log.lasers[0].ranges.shape == (180,)
    assert log.lasers[0].angles[1] - log.lasers[0].angles[0] == pytest.approx(math.radians(1.0))
    assert len(log.odometry) > 0


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


GOOD_FLASER = "FLASER 4 1.0 2.0 3.0 4.0 0.1 0.2 0.3 0.1 0.2 0.3 12.5 host 0.5"


def test_carmen_malformed_lines(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "bad.log",
        [
            "# comment",
            "PARAM robot_frontlaser_offset 0.0 nohost 0",
            GOOD_FLASER,
            "FLASER 4 1.0 2.0",  # truncated
            "ODOM 1 2 3 0 0 0 13.0 host 1.0",
            "ODOM 1 two 3 0 0 0 13.5 host 1.5",
            "ROBOTLASER1 0 -1.5708 3.1416 0.0174 80 0.01 0 3 1.0 1.5 2.0 0 0 0 0 0.1 0.2 0.3 0 0 0 0 0 14.0 host 2.0",
            "SOMETHINGELSE 1 2 3",
        ],
    )
    with pytest.raises(CarmenFormatError, match=r"bad\.log:4"):
        read_carmen(path)
    log = read_carmen(path, strict=False)
    assert len(log.warnings) == 2
    assert "bad.log:4" in log.warnings[0]
    assert "bad.log:6" in log.warnings[1]
    assert [r.kind for r in log.lasers] == ["FLASER", "ROBOTLASER1"]
    assert log.lasers[1].angles == pytest.approx([-1.5708, -1.5534, -1.536])
    assert log.lasers[1].odom_pose == pytest.approx([0.1, 0.2, 0.3])
    assert log.lasers[1].timestamp == 14.0
    assert len(log.odometry) == 1


def test_carmen_gzip_and_missing_file(tmp_path: Path) -> None:
    gz = tmp_path / "x.log.gz"
    with gzip.open(gz, "wt") as handle:
        handle.write(GOOD_FLASER + "\n")
    assert len(read_carmen(gz).lasers) == 1
    with pytest.raises(CarmenFormatError, match="cannot open"):
        read_carmen(tmp_path / "nope.clf")


def test_flaser_angles() -> None:
    assert carmen_beam_angles(180)[-1] == pytest.approx(math.radians(89.0))
    assert carmen_beam_angles(361)[-1] == pytest.approx(math.radians(90.0))
    assert carmen_beam_angles(5)[-1] == pytest.approx(math.pi / 2)


def test_tum_round_trip(tmp_path: Path) -> None:
    stamps = np.array([1.0, 2.5])
    poses = np.array([[1.0, 2.0, 0.3], [-1.0, 0.5, -3.0]])
    write_tum(tmp_path / "t.txt", stamps, poses)
    lines = (tmp_path / "t.txt").read_text().splitlines()
    assert lines[0].split()[:4] == ["1.000000", "1.000000", "2.000000", "0"]
    t, p = read_tum(tmp_path / "t.txt")
    assert np.allclose(t, stamps)
    assert np.allclose(p, poses, atol=1e-6)


def test_config_defaults_are_upstream_code_defaults() -> None:
    c = SlamConfig()
    assert c.minimum_distance_penalty == 0.05
    assert c.max_laser_range == 25.0
    assert c.transform_publish_period == 0.05
    assert c.map_update_interval == 10.0
    assert c.correlation_search_space_dimension == 0.5


def test_config_files_load() -> None:
    defaults = load_slam_config(CONFIG_DIR / "slam_defaults.yaml")
    assert defaults.minimum_distance_penalty == 0.5
    assert defaults.max_laser_range == 20.0
    eddie = load_slam_config(CONFIG_DIR / "slam.yaml")
    assert eddie.max_laser_range == 12.0
    assert eddie.scan_buffer_size == 20
    assert eddie.scan_topic == "scan"
    assert eddie.optimizer == "isam2"


def test_config_errors_name_file_and_key(tmp_path: Path) -> None:
    bad = tmp_path / "p.yaml"
    bad.write_text("slam_toolbox:\n  ros__parameters:\n    resolution: fine\n")
    with pytest.raises(ConfigError, match=r"p\.yaml.*'resolution'"):
        load_slam_config(bad)
    bad.write_text("other_node:\n  ros__parameters: {}\n")
    with pytest.raises(ConfigError, match="slam_toolbox"):
        load_slam_config(bad)
    with pytest.raises(ConfigError, match="'mode'"):
        SlamConfig.from_parameters({"mode": "dreaming"})
    assert SlamConfig.from_parameters({"scan_buffer_size": 0}).scan_buffer_size == 10
    assert SlamConfig.from_parameters({"some_future_key": 1}).extra == {"some_future_key": 1}
