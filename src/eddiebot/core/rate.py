"""``Rate``: a loop outside the executor paced by a node's clock (rclpy's ``Node.create_rate``).

A timer on the node's executor ticks every period; :meth:`Rate.sleep` blocks the calling
thread until the next tick. On sim time the ticks follow the sim clock, so a loop paced by a
rate runs as fast as the simulation does. Like rclpy's, a rate must not sleep on the thread
that spins its node's executor (the tick could never come): that raises.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from eddiebot.core.node import Node, Timer
    from eddiebot.core.time import Clock

__all__ = ["Rate"]


class Rate:
    """Sleeps until the next tick of a ``frequency`` Hz timer on ``node``."""

    def __init__(self, node: Node, frequency: float, clock: Clock | None = None) -> None:
        if not frequency > 0:
            raise ValueError(f"rate frequency must be positive, got {frequency} Hz")
        self.node = node
        self.frequency = float(frequency)
        self._cond = threading.Condition()
        self._ticks = 0
        self._destroyed = False
        self._timer: Timer = node.create_timer(1.0 / frequency, self._tick, clock=clock)

    def _tick(self) -> None:
        with self._cond:
            self._ticks += 1
            self._cond.notify_all()

    def sleep(self) -> None:
        """Block until the next tick (the executor must spin in another thread)."""
        executor = self.node.executor
        if executor is not None and executor.is_current_thread_spinning():
            raise RuntimeError(
                f"node {self.node.fully_qualified_name}: Rate.sleep() on the thread that spins "
                "its executor would never wake; spin in another thread")
        with self._cond:
            if self._destroyed:
                raise RuntimeError("Rate.sleep() on a destroyed rate")
            start = self._ticks
            while self._ticks == start and not self._destroyed and self.node.context.ok():
                self._cond.wait(0.1)

    def destroy(self) -> None:
        """Stop the timer and wake a sleeping thread."""
        with self._cond:
            self._destroyed = True
            self._cond.notify_all()
        self.node.destroy_timer(self._timer)
