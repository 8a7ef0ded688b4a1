"""BehaviorTree.CPP v4's control nodes: ``Sequence``, ``SequenceWithMemory`` (v3
``SequenceStar``), ``ReactiveSequence``, ``Fallback``, ``ReactiveFallback``, ``Parallel``,
``IfThenElse``, ``WhileDoElse``. Each follows its upstream ``tick()``/``halt()`` line by
line; the reactive nodes halt every other child when one is running, as BT.CPP v4 does.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import ControlNode, Port, Status, input_port

__all__ = [
    "Fallback", "IfThenElse", "Parallel", "ReactiveFallback", "ReactiveSequence",
    "Sequence", "SequenceWithMemory", "WhileDoElse",
]

S, F, R, K = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.SKIPPED


class Sequence(ControlNode):
    """Ticks children in order; resumes at the running child; a failure restarts it."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.all_skipped = True

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == F:
                self.reset_children()
                self.current = 0
                return F
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else S

    def halt(self) -> None:
        self.current = 0
        super().halt()


class SequenceWithMemory(Sequence):
    """A failure does not restart the sequence: the next tick retries the failed child."""

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == F:
                self.reset_children(self.current)
                return F
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else S


class ReactiveSequence(ControlNode):
    """Every tick from the first child; the running child halts every other one."""

    def tick(self) -> Status:
        all_skipped = True
        self.status = R
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            all_skipped = all_skipped and s == K
            if s == R:
                for j in range(len(self.children)):
                    if j != i:
                        self.halt_child(j)
                return R
            if s == F:
                self.reset_children()
                return F
            if s == K:
                self.halt_child(i)
        self.reset_children()
        return K if all_skipped else S


class Fallback(ControlNode):
    """Ticks children in order until one does not fail."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.all_skipped = True

    def tick(self) -> Status:
        if self.status == Status.IDLE:
            self.all_skipped = True
        self.status = R
        while self.current < len(self.children):
            s = self.children[self.current].execute_tick()
            self.all_skipped = self.all_skipped and s == K
            if s == R:
                return R
            if s == S:
                self.reset_children()
                self.current = 0
                return S
            self.current += 1
        self.reset_children()
        self.current = 0
        return K if self.all_skipped else F

    def halt(self) -> None:
        self.current = 0
        super().halt()


class ReactiveFallback(ControlNode):
    """Every tick from the first child; the first one not failing decides."""

    def tick(self) -> Status:
        all_skipped = True
        self.status = R
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            all_skipped = all_skipped and s == K
            if s == R:
                for j in range(len(self.children)):
                    if j != i:
                        self.halt_child(j)
                return R
            if s == S:
                self.reset_children()
                return S
            if s == K:
                self.halt_child(i)
        self.reset_children()
        return K if all_skipped else F


class Parallel(ControlNode):
    """Ticks every unfinished child each tick; SUCCESS once ``success_count`` children
    succeeded, FAILURE once ``failure_count`` failed (-1: all of them)."""

    PORTS: ClassVar[dict[str, Port]] = {
        "success_count": input_port(int, -1, "children that must succeed (-1: all)"),
        "failure_count": input_port(int, 1, "children that fail the node (-1: all)"),
    }

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.done: set[int] = set()
        self.successes = 0
        self.failures = 0

    def _threshold(self, name: str) -> int:
        n = int(self.get_input(name))
        return len(self.children) + n + 1 if n < 0 else n

    def tick(self) -> Status:
        need_s, need_f = self._threshold("success_count"), self._threshold("failure_count")
        self.status = R
        for i, child in enumerate(self.children):
            if i in self.done:
                continue
            s = child.execute_tick()
            if s == S:
                self.done.add(i)
                self.successes += 1
            elif s == F:
                self.done.add(i)
                self.failures += 1
            if self.successes >= need_s:
                self._clear()
                return S
            if self.failures >= need_f or len(self.children) - self.failures < need_s:
                self._clear()
                return F
        return R

    def _clear(self) -> None:
        self.reset_children()
        self.done.clear()
        self.successes = self.failures = 0

    def halt(self) -> None:
        self._clear()


class IfThenElse(ControlNode):
    """Child 1 is the condition; child 2 runs on its SUCCESS, child 3 (or FAILURE) else."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 3

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0

    def tick(self) -> Status:
        self.status = R
        if self.current == 0:
            c = self.children[0].execute_tick()
            if c == R:
                return R
            if c == S:
                self.current = 1
            elif len(self.children) == 3:
                self.current = 2
            else:
                self.reset_children()
                return F
        s = self.children[self.current].execute_tick()
        if s == R:
            return R
        self.reset_children()
        self.current = 0
        return s

    def halt(self) -> None:
        self.current = 0
        super().halt()


class WhileDoElse(ControlNode):
    """Reactive IfThenElse: the condition is ticked every time; a change halts the branch
    that was running."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 3

    def tick(self) -> Status:
        self.status = R
        c = self.children[0].execute_tick()
        if c == R:
            return R
        if c == S:
            if len(self.children) == 3:
                self.halt_child(2)
            s = self.children[1].execute_tick()
        elif len(self.children) == 3:
            self.halt_child(1)
            s = self.children[2].execute_tick()
        else:
            s = F
        if s != R:
            self.reset_children()
        return s
