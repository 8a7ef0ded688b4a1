"""BehaviorTree.CPP v4's decorators (``Inverter``, ``ForceSuccess``, ``ForceFailure``,
``KeepRunningUntilFailure``, ``Repeat``, ``RetryUntilSuccessful``, ``Timeout``, ``Delay``)
and leaves (``AlwaysSuccess``, ``AlwaysFailure``, ``SetBlackboard``), each following its
upstream ``tick()``/``halt()``.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import DecoratorNode, LeafNode, Port, PortDirection, Status, input_port

__all__ = [
    "AlwaysFailure", "AlwaysSuccess", "Delay", "ForceFailure", "ForceSuccess", "Inverter",
    "KeepRunningUntilFailure", "Repeat", "RetryUntilSuccessful", "SetBlackboard", "Timeout",
]

S, F, R, K = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.SKIPPED


class Inverter(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return {S: F, F: S}.get(s, s)


class ForceSuccess(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return S if s in (S, F) else s


class ForceFailure(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        return F if s in (S, F) else s


class KeepRunningUntilFailure(DecoratorNode):
    def tick(self) -> Status:
        self.status = R
        s = self.child.execute_tick()
        if s == S:
            self.reset_child()
            return R
        if s == F:
            self.reset_child()
        return s


class Repeat(DecoratorNode):
    """Ticks the child until it succeeded ``num_cycles`` times (-1: forever)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "num_cycles": input_port(int, description="repetitions (-1: infinite)")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.count = 0

    def tick(self) -> Status:
        n = int(self.get_input("num_cycles", 1))
        self.status = R
        while self.count < n or n == -1:
            s = self.child.execute_tick()
            if s == S:
                self.count += 1
                self.reset_child()
            elif s == F:
                self.count = 0
                self.reset_child()
                return F
            elif s == K:
                self.reset_child()
                return K
            else:
                return R
        self.count = 0
        return S

    def halt(self) -> None:
        self.count = 0
        super().halt()


class RetryUntilSuccessful(DecoratorNode):
    """Ticks the child again after a failure, ``num_attempts`` times in all (-1: forever)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "num_attempts": input_port(int, description="attempts (-1: infinite)")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.tries = 0

    def tick(self) -> Status:
        n = int(self.get_input("num_attempts", 1))
        self.status = R
        while self.tries < n or n == -1:
            s = self.child.execute_tick()
            if s == S:
                self.tries = 0
                self.reset_child()
                return S
            if s == F:
                self.tries += 1
                self.reset_child()
                continue
            if s == K:
                self.reset_child()
            return s
        self.tries = 0
        return F

    def halt(self) -> None:
        self.tries = 0
        super().halt()


class Timeout(DecoratorNode):
    """BT.CPP Timeout: halts the child and fails once it ran ``msec`` ms."""

    PORTS: ClassVar[dict[str, Port]] = {
        "msec": input_port(int, description="After a certain amount of time, halt() the child "
                           "if it is still running.")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start = 0

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, K):
            self.start = now
        self.status = R
        if now - self.start >= int(self.get_input("msec", 0)) * 1_000_000:
            self.reset_child()
            return F
        s = self.child.execute_tick()
        if s != R:
            self.reset_child()
        return s


class Delay(DecoratorNode):
    """BT.CPP Delay: RUNNING for ``delay_msec`` ms, then ticks the child."""

    PORTS: ClassVar[dict[str, Port]] = {
        "delay_msec": input_port(int, description="Tick the child after a few milliseconds")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.start = 0

    def tick(self) -> Status:
        now = self.context.now_ns()
        if self.status in (Status.IDLE, K):
            self.start = now
        self.status = R
        if now - self.start < int(self.get_input("delay_msec", 0)) * 1_000_000:
            return R
        s = self.child.execute_tick()
        if s != R:
            self.reset_child()
        return s


# -- BT.CPP leaves -------------------------------------------------------------------------
class AlwaysSuccess(LeafNode):
    def tick(self) -> Status:
        return S


class AlwaysFailure(LeafNode):
    def tick(self) -> Status:
        return F


class SetBlackboard(LeafNode):
    PORTS: ClassVar[dict[str, Port]] = {
        "value": input_port(str, description="value to write"),
        "output_key": Port(PortDirection.INOUT, object, description="entry to write"),
    }

    def tick(self) -> Status:
        raw = self.config.ports.get("value", "")
        from eddiebot.nav.bt.core import blackboard_key

        key = blackboard_key(raw)
        value = self.config.blackboard.get(key) if key else raw
        self.set_output("output_key", value)
        return S
