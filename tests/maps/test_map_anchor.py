"""eddiebot's keys in a map YAML: where the map frame stood against odometry when saved."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from eddiebot.maps import MapAnchor, MapFormatError, OccupancyMap, load_map, read_map_yaml, save_map


def _grid() -> OccupancyMap:
    return OccupancyMap(np.zeros((4, 5), np.int8), 0.1, origin=(-0.2, -0.2, 0.0))


def test_anchor_round_trips_and_map_server_keys_are_unchanged(tmp_path):
    anchor = MapAnchor((1.5, -0.25, 0.3), "0a1b2c3d/eddie_odom")
    path = save_map(_grid(), tmp_path / "office", anchor=anchor)
    doc = yaml.safe_load(path.read_text())
    assert doc["map_to_odom"] == [1.5, -0.25, 0.3]
    assert doc["odom_session"] == "0a1b2c3d/eddie_odom"
    meta = read_map_yaml(path)
    assert meta.anchor == anchor
    plain = read_map_yaml(save_map(_grid(), tmp_path / "plain"))
    assert plain.anchor is None
    # everything map_server reads is the same with or without the keys
    assert (meta.resolution, meta.origin, meta.mode) == (plain.resolution, plain.origin, plain.mode)
    assert load_map(path) == load_map(tmp_path / "plain.yaml")


def test_a_session_name_that_needs_quoting_survives(tmp_path):
    anchor = MapAnchor((0.0, 0.0, 0.0), "7: odd/name")
    assert read_map_yaml(save_map(_grid(), tmp_path / "m", anchor=anchor)).anchor == anchor


@pytest.mark.parametrize(("extra", "key"), [
    ("map_to_odom: [1, 2]\nodom_session: s\n", "map_to_odom"),
    ("map_to_odom: [1, 2, 3]\n", "odom_session"),
    ("odom_session: s\n", "map_to_odom"),
    ("map_to_odom: [1, 2, 3]\nodom_session: ''\n", "odom_session"),
])
def test_a_malformed_anchor_names_the_key(tmp_path, extra, key):
    path = save_map(_grid(), tmp_path / "m")
    path.write_text(path.read_text() + extra)
    with pytest.raises(MapFormatError, match=key):
        read_map_yaml(path)
