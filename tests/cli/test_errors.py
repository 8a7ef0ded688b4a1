"""Fatal start-up errors: one line ``eddie: error: ...`` on stderr, exit 2, no traceback."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from eddiebot.cli.main import fatal_message, main
from eddiebot.maps import OccupancyMap, save_map

SRC = Path(__file__).resolve().parents[2] / "src"
WORLDS = "corridor, depot, house, maze, office, warehouse"


def eddie(capsys: Any, *argv: str) -> tuple[int, list[str]]:
    """Run ``eddie ARGV`` in this process: (exit status, stderr lines)."""
    capsys.readouterr()
    code = main(list(argv))
    return code, capsys.readouterr().err.splitlines()


def assert_one_error_line(lines: list[str], *parts: str) -> str:
    errors = [line for line in lines if line.startswith("eddie: error: ")]
    assert len(errors) == 1, lines
    assert lines[-1] == errors[0]  # the last word, after any log line
    assert not any("Traceback" in line for line in lines)
    for part in parts:
        assert part in errors[0]
    return errors[0]


@pytest.fixture
def room_map(tmp_path: Path) -> Path:
    data = np.zeros((40, 60), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    return save_map(OccupancyMap(data=data, resolution=0.05), tmp_path / "room")


@pytest.mark.parametrize("command", [
    ["world", "show", "ofice"],
    ["sim", "--world", "ofice"],
    ["slam", "--world", "ofice"],
    ["vslam", "--world", "ofice"],
])
def test_misspelt_world_names_the_known_worlds(capsys: Any, command: list[str]) -> None:
    code, lines = eddie(capsys, *command)
    assert code == 2
    assert lines == [f"eddie: error: no built-in world 'ofice' (built-in: {WORLDS})"]


def test_nav_with_a_misspelt_world(capsys: Any, room_map: Path) -> None:
    code, lines = eddie(capsys, "nav", "--map", str(room_map), "--world", "ofice")
    assert code == 2
    assert lines == [f"eddie: error: no built-in world 'ofice' (built-in: {WORLDS})"]


def test_unknown_map_file(capsys: Any, tmp_path: Path) -> None:
    missing = tmp_path / "nope.yaml"
    code, lines = eddie(capsys, "nav", "--map", str(missing), "--world", "office")
    assert code == 2
    assert lines == [f"eddie: error: {missing}: no such map file"]


def test_map_file_that_is_not_yaml(capsys: Any, tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("image: m.pgm\nresolution: [0.05\norigin: [0, 0, 0]\n")
    code, lines = eddie(capsys, "nav", "--map", str(bad), "--world", "office")
    assert code == 2
    assert lines[0].startswith(f"eddie: error: {bad}:3:")
    assert len(lines) == 1


def test_params_file_with_a_syntax_error(capsys: Any, tmp_path: Path, room_map: Path) -> None:
    params = tmp_path / "nav2.yaml"
    params.write_text("amcl:\n  ros__parameters:\n    alpha1: [0.005\n    alpha2: 0.005\n")
    code, lines = eddie(capsys, "nav", "--map", str(room_map), "--world", "office",
                        "--params", str(params), "--run-dir", str(tmp_path / "run"))
    assert code == 2
    assert lines == [f"eddie: error: {params}:4:11: malformed YAML: expected ',' or ']', "
                     "but got ':'"]


def test_params_file_keys_no_server_reads_are_named_and_left_out(
        capsys: Any, tmp_path: Path) -> None:
    from eddiebot.cli.nav import resolve_params

    params = tmp_path / "nav2.yaml"
    params.write_text("amcl:\n  ros__parameters:\n    alpha1: 0.005\n    alpah2: 0.005\n"
                      "controller_server:\n  ros__parameters:\n    controller_frequency: 20.0\n"
                      "docking_server:\n  ros__parameters:\n    controller_frequency: 50.0\n")
    out = resolve_params(params, tmp_path / "run", None)
    err = capsys.readouterr().err.splitlines()
    assert f"eddie nav: {params}: ignored: amcl.alpah2" in err
    assert f"eddie nav: {params}: not supported: docking_server (whole section)" in err
    resolved = yaml.safe_load(out.read_text())
    assert "alpah2" not in resolved["amcl"]["ros__parameters"]
    assert resolved["amcl"]["ros__parameters"]["alpha1"] == 0.005
    assert "docking_server" not in resolved


def test_params_file_with_a_plugin_we_cannot_load(capsys: Any, tmp_path: Path,
                                                   room_map: Path) -> None:
    params = tmp_path / "nav2.yaml"
    params.write_text("controller_server:\n  ros__parameters:\n    controller_plugins: [FollowPath]\n"
                      "    FollowPath:\n      plugin: nav2_graceful_controller::GracefulController\n")
    code, lines = eddie(capsys, "nav", "--map", str(room_map), "--world", "office",
                        "--params", str(params), "--run-dir", str(tmp_path / "run"))
    assert code == 2
    assert lines[-1].startswith("eddie: error:")
    assert "nav2_graceful_controller::GracefulController" in lines[-1] and "FollowPath" in lines[-1]


def test_slam_params_file_with_a_syntax_error(capsys: Any, tmp_path: Path) -> None:
    params = tmp_path / "slam.yaml"
    params.write_text("slam_toolbox:\n  ros__parameters:\n    resolution: [0.05\n"
                      "    mode: mapping\n")
    code, lines = eddie(capsys, "slam", "--params", str(params))
    assert code == 2
    assert lines == [f"eddie: error: {params}:4:9: malformed YAML: expected ',' or ']', "
                     "but got ':'"]


def test_missing_params_file(capsys: Any, tmp_path: Path, room_map: Path) -> None:
    code, lines = eddie(capsys, "nav", "--map", str(room_map), "--world", "office",
                        "--params", str(tmp_path / "none.yaml"))
    assert code == 2
    assert_one_error_line(lines, "none.yaml", "No such file")


def test_lifecycle_bring_up_failure_ends_the_run(capsys: Any, tmp_path: Path) -> None:
    # a map whose image cannot be decoded: map_server fails to configure
    (tmp_path / "m.pgm").write_bytes(b"not an image")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n")
    code, lines = eddie(capsys, "nav", "--map", str(tmp_path / "m.yaml"), "--world", "office",
                        "--camera", "32x24@1", "--fast", "--duration", "60",
                        "--run-dir", str(tmp_path / "run"))
    assert code == 2
    assert_one_error_line(lines, "lifecycle_manager_localization could not bring its nodes up",
                          "map_server", "cannot decode image")


@pytest.fixture
def busy_port() -> Iterator[int]:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield int(sock.getsockname()[1])


def test_dashboard_port_in_use_exits_at_once(busy_port: int) -> None:
    env = {**os.environ, "EDDIE_TRANSPORT": "none",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run(
        [sys.executable, "-m", "eddiebot.cli.main", "sim", "--dashboard", "--dashboard-port",
         str(busy_port)], env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.splitlines() == [
        f"eddie: error: cannot serve the dashboard on 127.0.0.1:{busy_port}: Address already "
        "in use (choose another with --dashboard-port)"]


def test_which_errors_are_fatal_lines() -> None:
    from eddiebot.cli.errors import ParamsFileError
    from eddiebot.core.launch import LaunchError
    from eddiebot.sim.errors import UnknownWorldError

    assert fatal_message(UnknownWorldError("no built-in world 'x'")) == "no built-in world 'x'"
    assert fatal_message(LaunchError("a.yaml:3: bad\n  detail")) == "a.yaml:3: bad detail"
    assert fatal_message(ParamsFileError("p.yaml:2: oops")) == "p.yaml:2: oops"
    assert fatal_message(FileNotFoundError(2, "No such file or directory", "x.bag")) == (
        "x.bag: No such file or directory")
    assert fatal_message(ValueError("a bug")) is None  # a traceback says where
    assert fatal_message(KeyError("k")) is None
