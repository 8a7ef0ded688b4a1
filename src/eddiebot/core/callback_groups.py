"""Callback groups (rclpy.callback_groups): which callbacks may run at the same time in a
multi-threaded executor."""

from __future__ import annotations

import threading

__all__ = ["CallbackGroup", "MutuallyExclusiveCallbackGroup", "ReentrantCallbackGroup"]


class CallbackGroup:
    """Callbacks of one group obey the group's concurrency rule in a multi-threaded executor."""

    reentrant = False

    def __init__(self) -> None:
        self.lock = threading.Lock()


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    """At most one callback of the group runs at a time (the default)."""


class ReentrantCallbackGroup(CallbackGroup):
    """Callbacks of the group may run in parallel."""

    reentrant = True
