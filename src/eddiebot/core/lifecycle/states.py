"""The managed-node state machine: lifecycle_msgs' state and transition ids, and
which callback each transition runs."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any


class TransitionCallbackReturn(enum.IntEnum):
    """What a transition callback answers (lifecycle_msgs/Transition TRANSITION_CALLBACK_*)."""

    SUCCESS = 97
    FAILURE = 98
    ERROR = 99


class LifecycleState(enum.IntEnum):
    """lifecycle_msgs/State ids."""

    UNKNOWN = 0
    UNCONFIGURED = 1
    INACTIVE = 2
    ACTIVE = 3
    FINALIZED = 4
    CONFIGURING = 10
    CLEANINGUP = 11
    SHUTTINGDOWN = 12
    ACTIVATING = 13
    DEACTIVATING = 14
    ERRORPROCESSING = 15

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class State:
    """A lifecycle state as callbacks receive it (rclpy.lifecycle.State)."""

    state_id: int
    label: str

    @classmethod
    def of(cls, s: LifecycleState) -> State:
        return cls(int(s), s.label)

    def to_msg(self) -> Any:
        from eddiebot.msgs.lifecycle_msgs import State as StateMsg

        return StateMsg(id=self.state_id, label=self.label)


@dataclass(frozen=True)
class _Transition:
    id: int
    label: str
    start: LifecycleState
    via: LifecycleState
    callback: str
    on_success: LifecycleState
    on_failure: LifecycleState
    result_base: int  # lifecycle_msgs/Transition TRANSITION_ON_<X>_SUCCESS


_U, _I, _A, _F = (LifecycleState.UNCONFIGURED, LifecycleState.INACTIVE, LifecycleState.ACTIVE,
                  LifecycleState.FINALIZED)
_TRANSITIONS = (
    _Transition(1, "configure", _U, LifecycleState.CONFIGURING, "on_configure", _I, _U, 10),
    _Transition(2, "cleanup", _I, LifecycleState.CLEANINGUP, "on_cleanup", _U, _I, 20),
    _Transition(3, "activate", _I, LifecycleState.ACTIVATING, "on_activate", _A, _I, 30),
    _Transition(4, "deactivate", _A, LifecycleState.DEACTIVATING, "on_deactivate", _I, _A, 40),
    _Transition(5, "shutdown", _U, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
    _Transition(6, "shutdown", _I, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
    _Transition(7, "shutdown", _A, LifecycleState.SHUTTINGDOWN, "on_shutdown", _F, _F, 50),
)
_ERROR_RESULT_BASE = 60
