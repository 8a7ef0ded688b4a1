"""Control and decorator nodes by the names their XML uses: BehaviorTree.CPP v4's built-ins
and Nav2's own.

:mod:`~eddiebot.nav.bt.btcpp_controls` has BT.CPP's control nodes,
:mod:`~eddiebot.nav.bt.btcpp_decorators` its decorators and leaves,
:mod:`~eddiebot.nav.bt.nav2_controls` and :mod:`~eddiebot.nav.bt.nav2_decorators` Nav2's
(nav2_behavior_tree). ``CONTROL_NODES`` registers them all.
"""

from __future__ import annotations

from eddiebot.nav.bt.btcpp_controls import (
    Fallback,
    IfThenElse,
    Parallel,
    ReactiveFallback,
    ReactiveSequence,
    Sequence,
    SequenceWithMemory,
    WhileDoElse,
)
from eddiebot.nav.bt.btcpp_decorators import (
    AlwaysFailure,
    AlwaysSuccess,
    Delay,
    ForceFailure,
    ForceSuccess,
    Inverter,
    KeepRunningUntilFailure,
    Repeat,
    RetryUntilSuccessful,
    SetBlackboard,
    Timeout,
)
from eddiebot.nav.bt.nav2_controls import PipelineSequence, RecoveryNode, RoundRobin
from eddiebot.nav.bt.nav2_decorators import (
    DistanceController,
    GoalUpdatedController,
    GoalUpdater,
    PathLongerOnApproach,
    RateController,
    SingleTrigger,
    SpeedController,
)

__all__ = ["CONTROL_NODES"]

CONTROL_NODES: dict[str, type] = {
    cls.__name__: cls
    for cls in (Sequence, SequenceWithMemory, ReactiveSequence, Fallback, ReactiveFallback,
                Parallel, IfThenElse, WhileDoElse, Inverter, ForceSuccess, ForceFailure,
                KeepRunningUntilFailure, Repeat, RetryUntilSuccessful, Timeout, Delay,
                AlwaysSuccess,
                AlwaysFailure, SetBlackboard, PipelineSequence, RecoveryNode, RoundRobin,
                RateController, DistanceController, SpeedController, GoalUpdatedController,
                GoalUpdater, PathLongerOnApproach, SingleTrigger)
}
