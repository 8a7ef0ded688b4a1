"""One simulator per graph, and SLAM attached to it: ``eddie`` processes on a private router.

Each test runs ``eddie`` as programs against a router of its own on a random loopback port
and a ROS_DOMAIN_ID of its own, with subprocess timeouts, so a hang fails the test.
"""

from __future__ import annotations

import itertools
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
from _procs import Proc, private_router

EDDIE = [sys.executable, "-m", "eddiebot.cli.main"]
SIM = [*EDDIE, "sim", "--world", "office", "--camera", "160x120@5"]
_domains = itertools.count(150)


@pytest.fixture(scope="module")
def graph_env() -> Iterator[dict[str, str]]:
    with private_router() as env:
        yield env


@pytest.fixture
def env(graph_env: dict[str, str]) -> dict[str, str]:
    return {**graph_env, "ROS_DOMAIN_ID": str(next(_domains))}


@pytest.fixture
def sim(env: dict[str, str]) -> Iterator[Proc]:
    """``eddie sim`` on the test's domain, once it spins (its board answered)."""
    proc = Proc(SIM, env)
    deadline = time.monotonic() + 60
    while "board on emulator" not in proc.stderr:
        if proc.popen.poll() is not None or time.monotonic() > deadline:
            proc.popen.kill()
            pytest.fail(f"eddie sim did not start: {proc.stderr}")
        time.sleep(0.1)
    time.sleep(1.0)  # the clock publisher is announced once the executor spins
    yield proc
    proc.popen.send_signal(signal.SIGINT)
    proc.finish(timeout=15)


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("eddie: error:")]


def test_a_second_simulator_is_refused_within_seconds(sim: Proc, env: dict[str, str]) -> None:
    domain = env["ROS_DOMAIN_ID"]
    t0 = time.monotonic()
    second = subprocess.run([*SIM, "--fast", "--duration", "1"], env=env, capture_output=True,
                            text=True, timeout=30)
    assert second.returncode == 2, second.stderr
    assert time.monotonic() - t0 < 20.0  # seconds, not the 10 s attach wait (loaded CI)
    lines = _error_lines(second.stderr)
    assert len(lines) == 1, second.stderr
    line = lines[0]
    assert f"a simulator already runs on ROS_DOMAIN_ID {domain}" in line
    assert "/sim_clock beside /simulator" in line
    assert f"ROS_DOMAIN_ID={int(domain) + 1} eddie sim" in line
    # slam with its own simulator would publish /clock too
    slam = subprocess.run([*EDDIE, "slam", "--world", "office", "--duration", "1"], env=env,
                          capture_output=True, text=True, timeout=30)
    assert slam.returncode == 2, slam.stderr
    assert "eddie slam: a simulator already runs" in slam.stderr
    # so would `eddie launch sim` and `eddie run` of the simulator on sim time
    for command, name in (
            (["launch", "sim", "camera_width:=160", "camera_height:=120", "camera_rate:=5",
              "--duration", "1"], "eddie launch sim"),
            (["run", "eddiebot.sim.simulator", "--use-sim-time"],
             "eddie run eddiebot.sim.simulator")):
        t0 = time.monotonic()
        other = subprocess.run([*EDDIE, *command], env=env, capture_output=True, text=True,
                               timeout=30)
        assert other.returncode == 2, other.stderr
        assert time.monotonic() - t0 < 20.0
        lines = _error_lines(other.stderr)
        assert len(lines) == 1, other.stderr
        assert f"{name}: a simulator already runs on ROS_DOMAIN_ID {domain}" in lines[0]
        assert f"ROS_DOMAIN_ID={int(domain) + 1} {name} …" in lines[0]
        assert "board on emulator" not in other.stderr  # refused before anything was built
    assert sim.popen.poll() is None  # the first one runs on


def test_which_launches_would_publish_the_clock() -> None:
    from eddiebot.cli._attach import publishes_clock
    from eddiebot.core.launch import find_launch_file, parse_launch_file
    from eddiebot.registry import NODES

    sim = [spec.type for spec in parse_launch_file(find_launch_file("sim"), {}).nodes]
    bringup = [spec.type for spec in parse_launch_file(find_launch_file("bringup"), {}).nodes]
    assert publishes_clock(sim, True, NODES)
    assert not publishes_clock(sim, False, NODES)  # a simulator on the wall clock: no /clock
    assert not publishes_clock(bringup, True, NODES)
    assert not publishes_clock(["eddiebot.demo.talker"], True, NODES)
    assert publishes_clock(["eddiebot.sim.simulator"], True, NODES)


def test_slam_without_a_simulator_says_what_it_looked_for(env: dict[str, str]) -> None:
    domain = env["ROS_DOMAIN_ID"]
    t0 = time.monotonic()
    run = subprocess.run([*EDDIE, "slam", "--attach-timeout", "1.5"], env=env,
                         capture_output=True, text=True, timeout=30)
    assert run.returncode == 2, run.stderr
    assert time.monotonic() - t0 < 20.0
    lines = _error_lines(run.stderr)
    assert len(lines) == 1, run.stderr
    line = lines[0]
    assert f"no simulator or robot on ROS_DOMAIN_ID {domain}" in line
    assert "/clock or /odom publisher within 1.5 s" in line
    assert "eddie sim --world" in line and "--world office" in line


def test_slam_attaches_and_ctrl_c_saves_the_map(sim: Proc, env: dict[str, str],
                                                tmp_path: Path) -> None:
    out = tmp_path / "run"
    slam = Proc([*EDDIE, "slam", "--output", str(out)], env)
    assert slam.wait_for("attached to the simulator", timeout=30), slam.stderr
    # a loaded machine can take a minute or more to bring SLAM up; Ctrl-C before that exits 130
    deadline = time.monotonic() + 240
    while "slam in mapping mode" not in slam.stderr and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "slam in mapping mode" in slam.stderr, slam.stderr
    time.sleep(3.0)  # a few scans
    slam.popen.send_signal(signal.SIGINT)
    assert slam.popen.wait(timeout=30) == 0, slam.stderr
    assert any(f"saved the session and the map to {out}/" in line for line in slam.lines)
    assert (out / "session.eslam").is_file()
    doc = yaml.safe_load((out / "map.yaml").read_text())
    assert doc["odom_session"].endswith("/eddie_odom")
    assert len(doc["map_to_odom"]) == 3
    assert sim.popen.poll() is None  # stopping SLAM left the simulator running
    # the same running odometry: the session continues where the robot is
    again = subprocess.run([*EDDIE, "slam", "--session", str(out / "session.eslam"),
                            "--output", str(tmp_path / "again"), "--duration", "1"],
                           env=env, capture_output=True, text=True, timeout=60)
    assert again.returncode == 0, again.stderr
    assert "where the robot is in it (the same running odometry)" in again.stdout


def test_nav_without_a_simulator_says_what_it_looked_for(env: dict[str, str],
                                                         tmp_path: Path) -> None:
    import numpy as np

    from eddiebot.maps import OccupancyMap, save_map

    path = save_map(OccupancyMap(np.zeros((10, 10), np.int8), 0.1), tmp_path / "m")
    run = subprocess.run([*EDDIE, "nav", "--map", str(path), "--attach-timeout", "1"],
                         env=env, capture_output=True, text=True, timeout=30)
    assert run.returncode == 2, run.stderr
    lines = _error_lines(run.stderr)
    assert len(lines) == 1, run.stderr
    assert f"no simulator or robot on ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}" in lines[0]
    assert "eddie nav bring its own with --world office" in lines[0]


def test_vslam_without_a_simulator_says_what_it_looked_for(env: dict[str, str],
                                                           tmp_path: Path) -> None:
    t0 = time.monotonic()
    run = subprocess.run([*EDDIE, "vslam", "--attach-timeout", "1.5", "--database",
                          str(tmp_path / "rtabmap.db")], env=env, capture_output=True,
                         text=True, timeout=30)
    assert run.returncode == 2, run.stderr
    assert time.monotonic() - t0 < 20.0
    lines = _error_lines(run.stderr)
    assert len(lines) == 1, run.stderr
    assert f"eddie vslam: no simulator or robot on ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}" in lines[0]
    assert "/clock or /odom publisher within 1.5 s" in lines[0]
    assert "eddie vslam bring its own with --world office" in lines[0]
    assert not (tmp_path / "rtabmap.db").exists()  # nothing was built


def test_vslam_attaches_and_ctrl_c_leaves_the_simulator(sim: Proc, env: dict[str, str],
                                                        tmp_path: Path) -> None:
    from eddiebot.vslam.database import SessionDatabase

    database = tmp_path / "rtabmap.db"
    vslam = Proc([*EDDIE, "vslam", "--database", str(database)], env)
    assert vslam.wait_for("attached to the simulator", timeout=30), vslam.stderr
    attached = [line for line in vslam.lines if line.startswith("attached to")]
    assert attached == [attached[0]] and "no /scan" not in attached[0]
    deadline = time.monotonic() + 30
    while "rtabmap in mapping mode" not in vslam.stderr and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "rtabmap in mapping mode" in vslam.stderr, vslam.stderr
    time.sleep(4.0)  # a few Kinect frames
    vslam.popen.send_signal(signal.SIGINT)
    assert vslam.popen.wait(timeout=30) == 0, vslam.stderr
    assert sim.popen.poll() is None  # stopping vSLAM left the simulator running
    # the rtabmap node alone, on the simulator's sensors: no second simulator, no base stack
    assert "board on emulator" not in vslam.stderr and "already runs" not in vslam.stderr
    with SessionDatabase(database, read_only=True) as db:
        assert db.node_ids(), vslam.stderr  # frames were mapped
