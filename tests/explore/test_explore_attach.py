"""``eddie explore`` without ``--world``: attached to ``eddie sim`` on a private router."""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
from _procs import Proc, private_router

EDDIE = [sys.executable, "-m", "eddiebot.cli.main"]
SIM = [*EDDIE, "sim", "--world", "office", "--camera", "160x120@5"]
_domains = itertools.count(190)


@pytest.fixture(scope="module")
def graph_env() -> Iterator[dict[str, str]]:
    with private_router() as env:
        yield env


@pytest.fixture
def env(graph_env: dict[str, str]) -> dict[str, str]:
    return {**graph_env, "ROS_DOMAIN_ID": str(next(_domains))}


def test_without_a_robot_it_says_what_it_looked_for(env: dict[str, str], tmp_path: Path) -> None:
    run = subprocess.run([*EDDIE, "explore", "--attach-timeout", "1", "-o", str(tmp_path / "o")],
                         env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.startswith("eddie: error:")]
    assert len(lines) == 1, run.stderr
    assert f"eddie explore: no simulator or robot on ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}" \
        in lines[0]
    assert "eddie explore bring its own with --world office" in lines[0]
    assert not (tmp_path / "o").exists()  # nothing was built


def test_attaches_explores_and_writes_map_session_and_report(env: dict[str, str],
                                                             tmp_path: Path) -> None:
    sim = Proc(SIM, env)
    try:
        deadline = time.monotonic() + 60
        while "board on emulator" not in sim.stderr:
            assert sim.popen.poll() is None and time.monotonic() < deadline, sim.stderr
            time.sleep(0.1)
        time.sleep(1.0)  # the clock publisher is announced once the executor spins
        out = tmp_path / "run"
        run = subprocess.run([*EDDIE, "explore", "--time-limit", "20", "--no-return",
                              "-o", str(out)], env=env, capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 0, run.stderr
        assert "attached to the simulator" in run.stdout
        report = json.loads((out / "report.json").read_text())
        assert report["reason"] == "time limit"
        assert report["interrupted"] is False
        assert report["mapped_free_m2"] > 5.0  # the look-around alone maps more than this
        assert report["coverage"] is None  # no ground truth when attached
        for name in ("map.yaml", "map.pgm", "session.eslam", "report.md"):
            assert (out / name).is_file(), name
        assert sim.popen.poll() is None  # exploring left the simulator running
    finally:
        sim.popen.send_signal(signal.SIGINT)
        sim.finish(timeout=15)


def test_paused_with_a_world_of_its_own_is_refused(tmp_path: Path) -> None:
    # --world runs in a graph nobody else can reach, so nothing could ever resume it.
    run = subprocess.run([*EDDIE, "explore", "--world", "office", "--paused",
                          "-o", str(tmp_path / "o")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.startswith("eddie: error:")]
    assert len(lines) == 1 and "--paused" in lines[0] and "eddie explore --paused" in lines[0]
    assert not (tmp_path / "o").exists()


def test_paused_and_no_return_become_the_explore_node_parameters() -> None:
    import argparse

    from eddiebot.cli.explore import _explore_params, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert _explore_params(parser.parse_args([])) is None
    assert _explore_params(parser.parse_args(["--paused", "--no-return"])) == {
        "start_paused": True, "return_to_init": False}
