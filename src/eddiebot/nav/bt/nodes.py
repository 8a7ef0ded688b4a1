"""Nav2's BT nodes (nav2_behavior_tree plugins) by the names their XML uses.

:mod:`~eddiebot.nav.bt.actions` has the action nodes (``BtActionNode``: the first tick
sends the goal, later ticks poll it and never block, halting cancels it) and the cancel
nodes, :mod:`~eddiebot.nav.bt.services` the service nodes (``ClearEntireCostmap``,
``IsPathValid``), :mod:`~eddiebot.nav.bt.remote` the server names and timeouts both share,
:mod:`~eddiebot.nav.bt.selectors` the controller/planner/… selectors,
:mod:`~eddiebot.nav.bt.path_tools` the goal and path tools and
:mod:`~eddiebot.nav.bt.conditions` the condition nodes. ``NAV2_NODES`` registers them all.
"""

from __future__ import annotations

from eddiebot.nav.bt.actions import (
    RECOVERIES_KEY,
    AssistedTeleop,
    BackUp,
    CancelAssistedTeleop,
    CancelBackUp,
    CancelControl,
    CancelDriveOnHeading,
    CancelSpin,
    CancelWait,
    ComputePathThroughPoses,
    ComputePathToPose,
    DriveOnHeading,
    FollowPath,
    SmoothPath,
    Spin,
    Wait,
)
from eddiebot.nav.bt.conditions import (
    AreErrorCodesPresent,
    DistanceTraveled,
    GlobalUpdatedGoal,
    GoalReached,
    GoalUpdated,
    InitialPoseReceived,
    IsBatteryCharging,
    IsBatteryLow,
    PathExpiringTimer,
    TimeExpired,
    TransformAvailable,
    WouldAControllerRecoveryHelp,
    WouldAPlannerRecoveryHelp,
    WouldASmootherRecoveryHelp,
)
from eddiebot.nav.bt.path_tools import (
    GetPoseFromPath,
    RemovePassedGoals,
    TruncatePath,
    path_length_from,
)
from eddiebot.nav.bt.selectors import SELECTOR_NODES
from eddiebot.nav.bt.services import (
    ClearCostmapAroundRobot,
    ClearCostmapExceptRegion,
    ClearEntireCostmap,
    IsPathValid,
    ReinitializeGlobalLocalization,
)

__all__ = ["NAV2_NODES", "RECOVERIES_KEY", "path_length_from"]

NAV2_NODES: dict[str, type] = {
    cls.__name__: cls
    for cls in (
        ComputePathToPose, ComputePathThroughPoses, FollowPath, SmoothPath, Spin, BackUp,
        DriveOnHeading, Wait, AssistedTeleop, CancelControl, CancelSpin, CancelBackUp,
        CancelWait, CancelDriveOnHeading, CancelAssistedTeleop, ClearEntireCostmap,
        ClearCostmapAroundRobot, ClearCostmapExceptRegion, ReinitializeGlobalLocalization,
        IsPathValid, *SELECTOR_NODES, RemovePassedGoals, TruncatePath, GetPoseFromPath,
        GoalUpdated, GlobalUpdatedGoal, AreErrorCodesPresent, WouldAControllerRecoveryHelp,
        WouldAPlannerRecoveryHelp, WouldASmootherRecoveryHelp, PathExpiringTimer, TimeExpired,
        DistanceTraveled, GoalReached, InitialPoseReceived, IsBatteryLow, IsBatteryCharging,
        TransformAvailable)
}
