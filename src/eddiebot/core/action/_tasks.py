"""Coroutine callbacks on a node's executor: a coroutine runs as a task stepped by the
executor, and ``sleep`` waits on the node clock (sim or wall) without blocking it."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import TYPE_CHECKING, Any

from eddiebot.core.task import Future, Task

if TYPE_CHECKING:
    from eddiebot.core.node import Node

class _Step:
    """Executor work item: one step of a task, or one call."""

    __slots__ = ("callback_group", "fn", "node")

    def __init__(self, node: Node, fn: Callable[[], Any]) -> None:
        self.node = node
        self.fn = fn
        self.callback_group = None

    def execute(self) -> None:
        self.fn()


def _run_as_task(node: Node, coro: Coroutine[Any, Any, Any]) -> Task:
    """Drive ``coro`` on whatever executor ``node`` is (or will be) added to."""

    def reschedule(task: Task) -> None:
        node._notify(_Step(node, task.step))

    task = Task(coro, reschedule)
    reschedule(task)
    return task


async def sleep(node: Node, seconds: float) -> None:
    """Wait ``seconds`` on ``node``'s clock (sim or wall) inside a coroutine callback."""
    if seconds <= 0:
        return
    done = Future()
    timers: list[Any] = []

    def fire() -> None:
        node.destroy_timer(timers[0])
        done.set_result(None)

    timers.append(node.create_timer(seconds, fire, oneshot=True))
    await done
