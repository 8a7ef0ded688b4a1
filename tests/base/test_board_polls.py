"""Polls abandoned for a stop run again: the odometry sample never waits a whole poll cycle
per stop.

A stop jumps the board queue and abandons the exchange in flight. A controller hovering
around zero (MPPI stalled in a doorway, the velocity smoother's output rounding to 0 wheel
positions/s every other cycle) makes the board node alternate ``GOSPD 0 0`` holds and
``GOSPD`` commands at 20 Hz; when each stop threw away the ``DIST`` in flight, ``/joint_states``
(hence ``odom → base_footprint``) went 0.45 s without a sample, and the controller server,
which drives on no pose older than the local costmap's ``transform_tolerance`` (0.3 s), held
the robot (it aborted with "lost the robot pose" while it did not wait for a late pose).
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np
import pytest

from eddiebot.base.board_io import BoardOp, Priority, ThreadedBoardIO, TimedBoardIO
from eddiebot.base.board_node import BoardNode
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.time import stamp_to_ns
from eddiebot.msgs.eddiebot_msgs import Velocity
from eddiebot.msgs.sensor_msgs import JointState
from eddiebot.robot.errors import BoardInterrupted


def _joint_gaps(commands: list[tuple[float, float]], rate: float = 20.0) -> np.ndarray:
    """Seconds between /joint_states samples while ``commands`` go out at ``rate``."""
    ctx = Context(use_sim_time=True)
    try:
        board = BoardNode(context=ctx, parameter_overrides={"port": "emulator:1.1"})
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(board)
        probe = Node("probe", context=ctx)
        ex.add_node(probe)
        vel = probe.create_publisher(Velocity, "/eddie/simple_velocity", 10)
        stamps: list[int] = []
        probe.create_subscription(JointState, "/joint_states",
                                  lambda m: stamps.append(stamp_to_ns(m.header.stamp)), 50)
        ex.spin_for(2.2)  # the board's boot and handshake
        assert board.connected
        start = len(stamps)
        for v, w in commands:
            vel.publish(Velocity(linear=v, angular=w))
            ex.spin_for(1.0 / rate)
        return np.diff(np.array(stamps[start:], dtype=np.int64)) / 1e9
    finally:
        ctx.shutdown()


def test_odometry_keeps_its_rate_while_stops_and_commands_alternate():
    # 0.05 m/s and 0 in turn at 20 Hz for 6 s: a stop (GOSPD 0 0) every 0.1 s
    gaps = _joint_gaps([(0.05 if i % 2 else 0.0, 0.0) for i in range(120)])
    assert gaps.size > 25
    # a poll cycle (DIST + PING + ADC, ~0.08 s) plus the stop and the GOSPD between two
    # samples; losing the DIST to a stop gave 0.45 s
    assert gaps.max() < 0.25, f"longest /joint_states gap {gaps.max():.3f} s"


def test_a_steady_command_polls_at_the_poll_rate():
    gaps = _joint_gaps([(0.2, 0.0)] * 60)
    assert np.median(gaps) == pytest.approx(1.0 / 12.0, abs=0.005)


class _Core:
    def __init__(self) -> None:
        self.interrupted = threading.Event()

    def interrupt(self) -> None:
        self.interrupted.set()

    def clear_interrupt(self) -> None:
        self.interrupted.clear()


class _Board:
    def __init__(self) -> None:
        self.core = _Core()
        self.link = _Link()


class _Link:
    """Each exchange holds the wire 10 ms of sim time."""

    def take_elapsed_ns(self) -> int:
        return 10_000_000


def _timed_io() -> tuple[TimedBoardIO, list[tuple[int, Any]]]:
    later: list[tuple[int, Any]] = []
    io = TimedBoardIO(_Board(), lambda delay, fn: later.append((delay, fn)))  # type: ignore[arg-type]
    return io, later


def _finish(later: list[tuple[int, Any]]) -> None:
    while later:
        later.pop(0)[1]()


@pytest.mark.parametrize("rerun", [True, False])
def test_timed_io_reruns_a_query_a_stop_abandoned(rerun):
    io, later = _timed_io()
    runs: list[str] = []
    results: list[tuple[str, Any, Any]] = []

    def op(name: str, priority: Priority, rerun_after_stop: bool = False) -> BoardOp:
        def run(board: Any) -> str:
            runs.append(name)
            return f"{name} #{runs.count(name)}"
        return BoardOp(name, run, lambda r, e: results.append((name, r, type(e).__name__ if e else None)),
                       priority, rerun_after_stop=rerun_after_stop)

    io.submit(op("DIST", Priority.ROUTINE, rerun))
    io.submit(op("PING", Priority.ROUTINE, rerun))
    io.submit(op("STOP", Priority.STOP))  # DIST is on the wire: abandoned
    _finish(later)
    if rerun:
        assert runs == ["DIST", "STOP", "DIST", "PING"]
        assert results == [("STOP", "STOP #1", None), ("DIST", "DIST #2", None),
                           ("PING", "PING #1", None)]
    else:
        assert runs == ["DIST", "STOP", "PING"]
        assert results == [("DIST", None, "BoardInterrupted"), ("STOP", "STOP #1", None),
                           ("PING", "PING #1", None)]


def test_threaded_io_reruns_a_query_a_stop_abandoned():
    board = _Board()
    posted: list[Any] = []
    io = ThreadedBoardIO(board, posted.append)  # type: ignore[arg-type]
    started = threading.Event()
    attempts: list[int] = []
    order: list[str] = []

    def dist(b: Any) -> str:
        attempts.append(1)
        order.append("DIST")
        if len(attempts) == 1:  # the first exchange waits on a mute board until the stop
            started.set()
            if not b.core.interrupted.wait(5.0):
                raise AssertionError("never interrupted")
            raise BoardInterrupted("DIST")
        return "counts"

    results: list[tuple[str, Any, Any]] = []
    try:
        io.submit(BoardOp("DIST", dist, lambda r, e: results.append(("DIST", r, e)),
                          Priority.ROUTINE, rerun_after_stop=True))
        assert started.wait(5.0)
        io.submit(BoardOp("STOP", lambda b: order.append("STOP") or "ok",
                          lambda r, e: results.append(("STOP", r, e)), Priority.STOP))
        assert io.wait_idle(5.0)
    finally:
        io.close()
    for fn in posted:
        fn()
    assert order == ["DIST", "STOP", "DIST"]
    assert results == [("STOP", "ok", None), ("DIST", "counts", None)]
