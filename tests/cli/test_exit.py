"""How ``eddie`` commands end: a closed stdout, Ctrl-C, and a graph with a stalled process.

Each test runs ``eddie`` as a program (``python -m eddiebot.cli.main``) against a router of
its own on a random loopback port, with a subprocess timeout, so a hang fails the test
instead of hanging it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
from _procs import PEER, Proc, private_router

from eddiebot.cli.main import main

EDDIE = [sys.executable, "-m", "eddiebot.cli.main"]


@pytest.fixture(scope="module")
def graph_env() -> Iterator[dict[str, str]]:
    with private_router() as env:
        yield env


@pytest.fixture
def stalled_peer(graph_env: dict[str, str]) -> Iterator[Proc]:
    """A peer process in the graph that stops answering (SIGSTOP), as a process stalled by
    the machine's load or suspended with Ctrl-Z; the router drops it after its 10 s lease."""
    peer = Proc([sys.executable, str(PEER), "hub"], {**graph_env, "PEER_TIMEOUT": "60"})
    if not peer.wait_for("READY", timeout=30):
        peer.finish(timeout=5)
        pytest.fail(f"the peer process did not start: {peer.stderr}")
    os.kill(peer.popen.pid, signal.SIGSTOP)
    try:
        yield peer
    finally:
        os.kill(peer.popen.pid, signal.SIGCONT)
        peer.finish(timeout=10)


def test_closed_stdout_in_process(capsys: pytest.CaptureFixture[str],
                                  monkeypatch: pytest.MonkeyPatch) -> None:
    class ClosedPipe:
        def write(self, _text: str) -> int:
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self) -> None:
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert main(["interface", "show", "sensor_msgs/msg/LaserScan"]) == 141
    assert capsys.readouterr().err == ""


def test_echo_into_a_closed_pipe_exits_at_once(graph_env: dict[str, str]) -> None:
    """``eddie topic echo /chatter | head -3``: the echo exits after head does, quietly."""
    talker = subprocess.Popen(
        [*EDDIE, "topic", "pub", "/chatter", "std_msgs/msg/String", "{data: hi}", "-r", "50",
         "-p", "0"], env=graph_env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    echo = subprocess.Popen([*EDDIE, "topic", "echo", "/chatter"], env=graph_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert echo.stdout is not None
        lines = [echo.stdout.readline() for _ in range(3)]
        assert lines == [b"data: hi\n", b"---\n", b"data: hi\n"]
        echo.stdout.close()  # what head does after its third line
        t0 = time.monotonic()
        _, err = echo.communicate(timeout=10)
        assert time.monotonic() - t0 < 3.0
        assert echo.returncode == 141
        assert err == b""  # no BrokenPipeError, no traceback
    finally:
        for p in (echo, talker):
            if p.poll() is None:
                p.kill()
                p.wait()


def test_node_list_does_not_hang_on_a_stalled_peer(graph_env: dict[str, str],
                                                   stalled_peer: Proc) -> None:
    """Each call used to wait Zenoh's 10 s handshake timeout while closing its session
    (a peer links to every process, the stalled one too), deaf to Ctrl-C."""
    times = []
    for _ in range(4):
        t0 = time.monotonic()
        done = subprocess.run([*EDDIE, "node", "list"], env=graph_env, capture_output=True,
                              text=True, timeout=8)
        times.append(time.monotonic() - t0)
        assert done.returncode == 0, done.stderr
        assert "Traceback" not in done.stderr
    assert max(times) < 5.0, times


@pytest.mark.parametrize("mode", ["client", "peer"])
def test_ctrl_c_during_session_set_up_exits_130(graph_env: dict[str, str], stalled_peer: Proc,
                                                mode: str) -> None:
    """SIGINT at several moments of start-up (imports, router check, session, graph query,
    close): exit 130 within about a second, no traceback — also as a peer, whose closing
    session waits for the stalled process."""
    env = {**graph_env, "EDDIE_ZENOH_MODE": mode}
    # a SIGINT before the interpreter reaches eddie's code is Python's own (runpy prints the
    # KeyboardInterrupt): the moments count from a bare interpreter's start-up time, which a
    # loaded machine stretches from ~20 ms to a good part of a second
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", "import runpy"], env=env, check=True)
    startup = time.monotonic() - t0
    for delay in (0.3, 0.6, 0.9, 1.2):
        proc = subprocess.Popen([*EDDIE, "topic", "echo", "/nobody_publishes_this"], env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        time.sleep(startup + delay)
        proc.send_signal(signal.SIGINT)
        t0 = time.monotonic()
        try:
            _, err = proc.communicate(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            pytest.fail(f"{mode}: still running 5 s after SIGINT sent {delay} s in")
        waited = time.monotonic() - t0
        assert proc.returncode in (130, -signal.SIGINT), (delay, err)
        assert b"Traceback" not in err, (delay, err)
        assert waited < 1.5, (mode, delay, waited)
