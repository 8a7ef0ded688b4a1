"""``eddie nav --keepout`` / ``--speed-mask``: the masks go into the resolved parameters with
their servers, and a mask that cannot be used stops the run with one line naming it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from eddiebot.cli.main import main
from eddiebot.cli.nav import filter_sections, resolve_params
from eddiebot.maps import OccupancyMap, load_map, save_map
from eddiebot.nav.params_file import default_params


def _room(tmp_path: Path) -> Path:
    data = np.zeros((80, 80), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    return save_map(OccupancyMap(data, 0.05), tmp_path / "room")


def _mask(tmp_path: Path, name: str, origin=(0.0, 0.0, 0.0), res: float = 0.05) -> Path:
    data = np.zeros((40, 40), dtype=np.int8)
    data[10:20, 10:20] = 100
    return save_map(OccupancyMap(data, res, origin), tmp_path / name)


def _args(tmp_path: Path, **kw: Any) -> argparse.Namespace:
    return argparse.Namespace(map=_room(tmp_path), params=None, localization="amcl", **kw)


def test_masks_are_added_to_the_resolved_parameters(tmp_path: Path) -> None:
    resolved = resolve_params(default_params(), tmp_path / "run", (1.0, 1.0, 0.0))
    keepout, speed = _mask(tmp_path, "keepout"), _mask(tmp_path, "speed")
    sections = filter_sections(_args(tmp_path, keepout=keepout, speed_mask=speed), resolved)
    assert [s.node_name for s in sections] == [
        "keepout_filter_mask_server", "speed_filter_mask_server",
        "keepout_costmap_filter_info_server", "speed_costmap_filter_info_server"]
    doc = yaml.safe_load(resolved.read_text())
    assert resolved.read_text().startswith("# resolved from")
    gc = doc["planner_server"]["ros__parameters"]["global_costmap"]
    assert gc["filters"] == ["keepout_filter", "speed_filter"]
    assert gc["speed_filter"]["filter_info_topic"] == "/speed_costmap_filter_info"
    lc = doc["controller_server"]["ros__parameters"]["local_costmap"]
    assert lc["filters"] == ["keepout_filter"]
    # the servers' own sections are in a file beside it (the launch does not run them)
    assert not [k for k in doc if k.endswith("_server") and "filter" in k]
    servers = yaml.safe_load((resolved.parent / "costmap_filters.yaml").read_text())
    assert servers["keepout_filter_mask_server"]["ros__parameters"]["yaml_filename"] == str(keepout)
    assert servers["speed_costmap_filter_info_server"]["ros__parameters"]["type"] == 1


def test_without_masks_nothing_starts(tmp_path: Path) -> None:
    resolved = resolve_params(default_params(), tmp_path / "run", None)
    before = resolved.read_text()
    args = _args(tmp_path, keepout=None, speed_mask=None, dashboard=False)
    assert filter_sections(args, resolved) == []
    assert resolved.read_text() == before


def test_the_dashboard_gets_an_empty_keepout_mask_to_paint_on(tmp_path: Path) -> None:
    resolved = resolve_params(default_params(), tmp_path / "run", None)
    args = _args(tmp_path, keepout=None, speed_mask=None, dashboard=True)
    sections = filter_sections(args, resolved)
    assert [s.node_name for s in sections] == ["keepout_filter_mask_server",
                                               "keepout_costmap_filter_info_server"]
    mask = load_map(sections[0].params["yaml_filename"])
    room = load_map(args.map)
    assert mask.data.shape == room.data.shape and mask.origin == room.origin
    assert not mask.data.any()


def test_a_mask_off_the_map_stops_eddie_nav_naming_it(capsys: Any, tmp_path: Path) -> None:
    mask = _mask(tmp_path, "elsewhere", origin=(40.0, 40.0, 0.0))
    code = main(["nav", "--map", str(_room(tmp_path)), "--world", "office", "--initial-pose",
                 "1", "1", "0", "--keepout", str(mask), "--run-dir", str(tmp_path / "run"),
                 "--no-transport"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2
    errors = [line for line in err if line.startswith("eddie: error: ")]
    assert len(errors) == 1 and err[-1] == errors[0], err
    assert str(mask) in errors[0] and "does not overlap the map" in errors[0]
    assert not any("Traceback" in line for line in err)


def test_a_missing_mask_file_is_named(capsys: Any, tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    code = main(["nav", "--map", str(_room(tmp_path)), "--world", "office", "--initial-pose",
                 "1", "1", "0", "--speed-mask", str(missing), "--run-dir", str(tmp_path / "run"),
                 "--no-transport"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2
    assert err[-1] == f"eddie: error: eddie nav: {missing}: no such mask file"
