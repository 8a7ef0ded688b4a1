"""Nav2's control nodes (nav2_behavior_tree): ``PipelineSequence``, ``RecoveryNode``,
``RoundRobin``, each following its upstream ``tick()``/``halt()``.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import ControlNode, Port, Status, input_port

__all__ = ["PipelineSequence", "RecoveryNode", "RoundRobin"]

S, F, R, K = Status.SUCCESS, Status.FAILURE, Status.RUNNING, Status.SKIPPED


class PipelineSequence(ControlNode):
    """nav2 PipelineSequence: re-ticks every child up to the furthest one running."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.last_child_ticked = 0

    def tick(self) -> Status:
        skipped = 0
        for i, child in enumerate(self.children):
            s = child.execute_tick()
            if s == F:
                self.reset_children()
                self.last_child_ticked = 0
                return F
            if s == K:
                skipped += 1
            elif s == R and i >= self.last_child_ticked:
                self.last_child_ticked = i
                return R
        self.reset_children()
        self.last_child_ticked = 0
        return K if skipped == len(self.children) else S

    def halt(self) -> None:
        super().halt()
        self.last_child_ticked = 0


class RecoveryNode(ControlNode):
    """nav2 RecoveryNode: on the first child's failure tick the second (the recovery); if
    it succeeds, retry the first — at most ``number_of_retries`` times."""

    MIN_CHILDREN = 2
    MAX_CHILDREN = 2
    PORTS: ClassVar[dict[str, Port]] = {
        "number_of_retries": input_port(int, 1, "Number of retries")}

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.retry_count = 0

    def tick(self) -> Status:
        retries = int(self.get_input("number_of_retries"))
        self.status = R
        while self.current < 2 and self.retry_count <= retries:
            s = self.children[self.current].execute_tick()
            if self.current == 0:
                if s == K:
                    self.halt()
                    return K
                if s == S:
                    self.halt()
                    return S
                if s == R:
                    return R
                if self.retry_count < retries:
                    self.halt_child(0)
                    self.current = 1
                    continue
                self.halt()
                return F
            if s == K:
                self.current = 0
                self.halt_child(1)
                return F
            if s == R:
                return R
            if s == S:
                self.halt_child(1)
                self.retry_count += 1
                self.current = 0
                continue
            self.halt()
            return F
        self.halt()
        return F

    def halt(self) -> None:
        super().halt()
        self.retry_count = 0
        self.current = 0


class RoundRobin(ControlNode):
    """nav2 RoundRobin: ticks the current child; when it ends, the next one is current, so
    each recovery in turn gets its chance; FAILURE only when every child failed in a row."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.current = 0
        self.failed = 0

    def tick(self) -> Status:
        n = len(self.children)
        self.status = R
        skipped = 0
        while self.failed + skipped < n:
            s = self.children[self.current].execute_tick()
            if s != R:
                self.current = (self.current + 1) % n
            if s == S:
                self.failed = 0
                self.reset_children()
                return S
            if s == F:
                self.failed += 1
            elif s == K:
                skipped += 1
            else:
                return R
        self.halt()
        return K if skipped == n else F

    def halt(self) -> None:
        super().halt()
        self.current = 0
        self.failed = 0
