"""Behaviour-tree control nodes with Nav2 semantics, on scripted leaves."""

from py_trees.behaviour import Behaviour
from py_trees.common import Status

from eddiebot.nav.bt.nodes import (
    GoalUpdated,
    NavBlackboard,
    PipelineSequence,
    RateController,
    ReactiveFallback,
    RecoveryNode,
    RoundRobin,
    WouldARecoveryHelp,
    tick_child,
)


class Scripted(Behaviour):
    """Returns the statuses of ``script`` in turn (the last one forever)."""

    def __init__(self, name, *script):
        super().__init__(name)
        self.script = list(script)
        self.ticks = 0
        self.halts = 0

    def update(self):
        s = self.script[min(self.ticks, len(self.script) - 1)]
        self.ticks += 1
        return s

    def terminate(self, new_status):
        if new_status == Status.INVALID:
            self.halts += 1


S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


def test_recovery_node_bounded_retries():
    main = Scripted("main", F)
    recovery = Scripted("recovery", S)
    node = RecoveryNode("r", main, recovery, number_of_retries=6)
    assert tick_child(node) == F
    assert main.ticks == 7 and recovery.ticks == 6


def test_recovery_node_succeeds_after_a_recovery():
    main = Scripted("main", F, R, S)
    node = RecoveryNode("r", main, Scripted("rec", S), number_of_retries=2)
    assert tick_child(node) == R
    assert tick_child(node) == S


def test_round_robin_rotates_and_fails_when_all_fail():
    a, b, c = Scripted("a", S), Scripted("b", F), Scripted("c", S)
    rr = RoundRobin("rr", [a, b, c])
    assert tick_child(rr) == S and (a.ticks, b.ticks, c.ticks) == (1, 0, 0)
    assert tick_child(rr) == S and (a.ticks, b.ticks, c.ticks) == (1, 1, 1)  # b failed, c ran
    assert tick_child(RoundRobin("all", [Scripted("x", F), Scripted("y", F)])) == F


def test_pipeline_sequence_reticks_earlier_running_children():
    plan = Scripted("plan", S)
    follow = Scripted("follow", R, R, S)
    p = PipelineSequence("p", [plan, follow])
    assert tick_child(p) == R
    assert tick_child(p) == R
    assert plan.ticks == 2 and follow.ticks == 2
    assert tick_child(p) == S


def test_rate_controller_ticks_child_at_rate():
    now = [0]
    child = Scripted("plan", S)
    rc = RateController("rc", child, 1.0, lambda: now[0])
    for _ in range(10):  # 10 ticks within 0.9 s: only the first reaches the child
        tick_child(rc)
        now[0] += 100_000_000
    assert child.ticks == 1
    now[0] = 1_100_000_000
    tick_child(rc)
    assert child.ticks == 2


def test_goal_updated_and_hopeless_errors():
    bb = NavBlackboard()
    fallback = ReactiveFallback("f", [GoalUpdated(bb), Scripted("recover", R)])
    assert tick_child(fallback) == R
    bb.set_goal(object())
    assert tick_child(fallback) == S
    helper = WouldARecoveryHelp(bb)
    bb.fail(208, "no valid path")
    assert tick_child(helper) == S
    bb.fail(206, "goal occupied")
    assert tick_child(helper) == F
