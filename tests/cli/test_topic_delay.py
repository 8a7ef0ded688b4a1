"""``eddie topic delay``: receipt time minus header stamp, as ``ros2 topic delay``."""

from __future__ import annotations

import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
from _procs import private_router

from eddiebot.cli.topic import DelayStats

S = 1_000_000_000


def test_delay_figures_over_the_window() -> None:
    stats = DelayStats(window=3)
    assert stats.report() is None
    stats.add(100 * S, 99 * S)  # the first message starts the window, as ros2's does
    assert stats.report() is None
    for now, delay in ((101, 0.5), (102, 0.25), (103, 0.75), (104, 1.0)):
        stats.add(now * S, now * S - int(delay * S))
    mean, lo, hi, std, n = stats.figures() or (0, 0, 0, 0, 0)
    # the window keeps the last three: 0.25, 0.75, 1.0
    assert n == 3
    assert (round(lo, 9), round(hi, 9)) == (0.25, 1.0)
    assert mean == pytest.approx(2.0 / 3.0)
    assert std == pytest.approx(((0.25 - 2 / 3) ** 2 + (0.75 - 2 / 3) ** 2
                                 + (1.0 - 2 / 3) ** 2) ** 0.5 / 3 ** 0.5)
    assert stats.report() == ("average delay: 0.667\n\tmin: 0.250s max: 1.000s "
                              "std dev: 0.31180s window: 3")
    assert stats.report() == "no new messages"


def test_time_going_backwards_restarts_the_window() -> None:
    stats = DelayStats()
    stats.add(50 * S, 49 * S)
    stats.add(51 * S, 50 * S)
    assert stats.figures() is not None
    stats.add(10 * S, 9 * S)  # a bag replayed in a loop
    assert stats.figures() is None and stats.resets == 1
    stats.add(11 * S, 10 * S - S // 2)
    assert stats.figures() == pytest.approx((1.5, 1.5, 1.5, 0.0, 1))
    stats.add(0, 0)  # sim time not started: not counted, the window cleared
    assert stats.figures() is None


@pytest.fixture(scope="module")
def graph() -> Iterator[dict[str, str]]:
    with private_router() as env:
        yield env


@pytest.fixture
def publishing(graph: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """This process publishes ``/stamped`` (PointStamped, stamps 5 s old) at 20 Hz and
    ``/plain`` (String, no header)."""
    from eddiebot.core import Context, Node
    from eddiebot.msgs.geometry_msgs import PointStamped
    from eddiebot.msgs.std_msgs import String
    from eddiebot.transport import ZenohConfig, connect

    monkeypatch.delenv("EDDIE_TRANSPORT", raising=False)
    ctx = Context()
    node = Node("delay_source", context=ctx)
    connect(ctx, ZenohConfig.from_env(graph), required=True)
    stamped = node.create_publisher(PointStamped, "/stamped", 10)
    plain = node.create_publisher(String, "/plain", 10)
    stop = threading.Event()

    def run() -> None:
        while not stop.wait(0.05):
            msg = PointStamped()
            now = ctx.system_clock.now_ns() - 5 * S
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now, S)
            stamped.publish(msg)
            plain.publish(String(data="x"))

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    yield graph
    stop.set()
    thread.join(2)
    ctx.shutdown()


def _eddie(env: dict[str, str], *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "eddiebot.cli.main", *argv], env=env,
                          capture_output=True, text=True, timeout=60)


def test_delay_of_a_stamped_topic_in_another_process(publishing: dict[str, str]) -> None:
    out = _eddie(publishing, "topic", "delay", "/stamped", "--duration", "3")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    averages = [float(line.split()[-1]) for line in lines if line.startswith("average delay")]
    assert averages, out.stdout
    # stamps are 5 s old when published; the transport adds far less than a second
    assert 5.0 <= averages[-1] < 6.0
    last = [line for line in lines if "window:" in line][-1].split()
    assert float(last[1].rstrip("s")) >= 5.0  # min
    assert int(last[-1]) >= 5  # ~60 messages in 3 s, minus discovery


def test_a_topic_without_header_is_one_line(publishing: dict[str, str]) -> None:
    out = _eddie(publishing, "topic", "delay", "/plain", "--duration", "3")
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        "eddie topic delay: std_msgs/msg/String has no header: the delay is measured from "
        "header.stamp"]
