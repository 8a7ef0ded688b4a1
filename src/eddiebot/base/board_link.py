"""Reaching the control board: the link and I/O queue for a ``port``, and bringing it up.

``open_board`` makes the :class:`~eddiebot.robot.board.Board` for the board node's ``port``
— the in-process firmware emulator (``emulator``, ``emulator:1.1``, ``emulator:1.3``) on the
node clock with the real wire's timing, or a serial device, pty or ``socket://`` URL on a
worker thread — with the :mod:`board_io` queue that fits it. ``BoardConnector`` brings the
board up: open the port, wait out the Propeller's boot (opening raises DTR, which reboots
it), run the handshake; all on the I/O side, never on the executor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.base.board_io import BoardIO, BoardOp, Priority, ThreadedBoardIO, TimedBoardIO
from eddiebot.robot.board import Board
from eddiebot.robot.constants import FirmwareProfile, profile_for_name
from eddiebot.robot.errors import LinkLost, RobotError

if TYPE_CHECKING:
    from eddiebot.base.board_node import BoardNode

__all__ = ["BoardConnector", "acc_min", "open_board", "stop_retrying"]


def open_board(node: BoardNode, emulator_timing: bool) -> tuple[Board, BoardIO]:
    """The board on ``node.port`` and the queue its transactions go through (not yet open).

    ``emulator`` uses the emulator the simulator put in the context (or makes one, as
    ``emulator:<firmware>`` always does); ``emulator_timing`` false drops the wire's timing.
    """
    from eddiebot.robot.links import SerialLink, TimedEmulatorLink
    from eddiebot.robot.timing import NO_TIMING, LinkTiming

    if node.port.startswith("emulator"):
        emulator = node.context.resources.get("emulator")
        if emulator is None or ":" in node.port:
            from eddiebot.robot.emulator import FirmwareEmulator

            profile = profile_for_name(node.port.partition(":")[2] or "1.1")
            emulator = FirmwareEmulator(profile, start_ns=node.get_clock().now_ns(),
                                        counts_per_rev=node.counts_per_rev)
            node.context.resources["emulator"] = emulator
        clock = node.get_clock()
        link = TimedEmulatorLink(emulator, clock_ns=clock.now_ns,
                                 timing=LinkTiming() if emulator_timing else NO_TIMING,
                                 reply_timeout_s=node.reply_timeout)
        node.context.resources["board_link"] = link
        board = Board(link, clock=clock.now_ns, timeout_s=node.reply_timeout,
                      on_event=node._on_board_event)
        io: BoardIO = TimedBoardIO(board, node._call_later)
    else:
        board = Board(SerialLink(node.port), clock=time.monotonic_ns,
                      timeout_s=node.reply_timeout, on_event=node._on_board_event)
        posted: list[Callable[[], None]] = []

        def drain() -> None:  # on the executor: results the worker thread handed over
            while posted:
                posted.pop(0)()

        guard = node.create_guard_condition(drain)

        def post(fn: Callable[[], None]) -> None:
            posted.append(fn)
            guard.trigger()

        io = ThreadedBoardIO(board, post)
    if node.firmware != "auto":
        board.forced_profile = profile_for_name(node.firmware)
    return board, io


class BoardConnector:
    """Open, boot, handshake — at most once a second of node time; ``on_up(profile)`` when
    the board answered. A board that does not answer is logged once, with what to check,
    then every 30 s."""

    def __init__(self, node: BoardNode, boot_s: float,
                 on_up: Callable[[FirmwareProfile], None]) -> None:
        self._node = node
        #: how long the Propeller is deaf after the port opens (s)
        self.boot_s = boot_s
        self._on_up = on_up
        self._next_attempt_ns = 0
        self._booting = False
        self._failure_logged_ns: int | None = None

    def connect(self) -> None:
        """Start bringing the board up, unless an attempt is under way or came too recently."""
        node = self._node
        now = node.get_clock().now_ns()
        if (node.io.pending("open") or node.io.pending("connect") or self._booting
                or now < self._next_attempt_ns):
            return
        self._next_attempt_ns = now + 1_000_000_000
        if node.board.link.generation == 0:
            node.io.submit(BoardOp("open", lambda b: b.link.open(), self._on_opened,
                                   Priority.STOP))
        else:
            self._handshake()

    def _on_opened(self, _: Any, error: BaseException | None) -> None:
        if error is not None:
            self._on_handshake(None, error)
            return
        # opening the port raises DTR, which reboots the Propeller: it is deaf until it booted
        self._booting = True

        def booted() -> None:
            self._booting = False
            self._handshake()

        self._node._call_later(round(self.boot_s * 1e9), booted)

    def _handshake(self) -> None:
        node = self._node
        acceleration = node.acceleration

        def run(board: Board) -> FirmwareProfile:
            profile = board.start(ping_mask=node.ping_mask)
            board.stop_now()
            if acceleration is not None:
                board.set_acceleration(min(max(acceleration, acc_min(profile)), profile.acc_max))
            return profile

        node.io.submit(BoardOp("connect", run, self._on_handshake, Priority.STOP))

    def _on_handshake(self, profile: Any, error: BaseException | None) -> None:
        if error is not None:
            self._node.connected = False
            self._log_failure(error)
            return
        self._failure_logged_ns = None
        self._on_up(profile)

    def _log_failure(self, error: BaseException) -> None:
        node = self._node
        now = node.get_clock().now_ns()
        last = self._failure_logged_ns
        if last is None:
            hint = ""
            if isinstance(error, LinkLost) and not node.port.startswith(("emulator", "socket:")):
                hint = (" — check the cable and the board's power, that the port exists "
                        "(ls /dev/ttyUSB* /dev/eddie) and that you may open it "
                        "(the dialout group: sudo usermod -aG dialout $USER, then log in again)")
            node.get_logger().error(f"board on {node.port} not answering: {error}{hint}; "
                                    f"will keep trying")
            self._failure_logged_ns = now
        elif now - last > 30_000_000_000:
            node.get_logger().warning(f"board on {node.port} still not answering ({error})")
            self._failure_logged_ns = now


def acc_min(profile: FirmwareProfile) -> int:
    """The lowest ``ACC`` we send: ACC 0 on FW 1.1 freezes every later GOSPD change."""
    return max(profile.acc_min, 1)


def stop_retrying(board: Board, attempts: int = 3) -> None:
    """``STOP 0`` until one is acknowledged (shutdown); a lost link ends the attempts."""
    for _ in range(attempts):
        try:
            board.stop_now()
            return
        except LinkLost:
            return
        except RobotError:
            continue
