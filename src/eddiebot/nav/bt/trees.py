"""Factories for Nav2's default navigation trees (``navigate_to_pose_w_replanning_and_recovery``
and its through-poses twin), built from :mod:`eddiebot.nav.bt.nodes`::

    RecoveryNode(number_of_retries=6)
      PipelineSequence
        RateController(1 Hz)
          ComputePathToPose | Sequence(RemovePassedGoals(0.7 m), ComputePathThroughPoses)
        FollowPath
      Sequence
        WouldARecoveryHelp              (goals outside the map / occupied abort at once)
        ReactiveFallback
          GoalUpdated
          RoundRobin
            Sequence(ClearLocalCostmap, ClearGlobalCostmap)
            Spin(1.57)
            Wait(5 s)
            BackUp(0.30 m, 0.05 m/s)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from py_trees.behaviour import Behaviour

from eddiebot.nav.bt.nodes import (
    BackUp,
    ClearEntireCostmap,
    ComputePathThroughPoses,
    ComputePathToPose,
    FollowPath,
    GoalUpdated,
    NavBlackboard,
    PipelineSequence,
    RateController,
    ReactiveFallback,
    RecoveryNode,
    RemovePassedGoals,
    RoundRobin,
    SequenceWithMemory,
    Spin,
    Wait,
    WouldARecoveryHelp,
)

__all__ = ["NavClients", "TreeOptions", "navigate_through_poses_tree", "navigate_to_pose_tree"]


@dataclass
class NavClients:
    """The action and service clients the trees use (made once by the navigator)."""

    compute_path_to_pose: Any
    compute_path_through_poses: Any
    follow_path: Any
    spin: Any
    backup: Any
    wait: Any
    clear_local_costmap: Any
    clear_global_costmap: Any


@dataclass(frozen=True)
class TreeOptions:
    replanning_frequency: float = 1.0
    number_of_retries: int = 6
    spin_dist: float = 1.57
    wait_duration: float = 5.0
    backup_dist: float = 0.30
    backup_speed: float = 0.05
    server_timeout: float = 1.0
    passed_goal_radius: float = 0.7


def _recovery_branch(bb: NavBlackboard, c: NavClients, clock: Callable[[], int],
                     o: TreeOptions) -> Behaviour:
    t = o.server_timeout
    actions = RoundRobin("RecoveryActions", [
        SequenceWithMemory("ClearingActions", [
            ClearEntireCostmap("ClearLocalCostmap-Subtree", c.clear_local_costmap, bb),
            ClearEntireCostmap("ClearGlobalCostmap-Subtree", c.clear_global_costmap, bb),
        ]),
        Spin("Spin", c.spin, bb, clock, t, spin_dist=o.spin_dist),
        Wait("Wait", c.wait, bb, clock, t, wait_duration=o.wait_duration),
        BackUp("BackUp", c.backup, bb, clock, t, backup_dist=o.backup_dist,
               backup_speed=o.backup_speed),
    ])
    return SequenceWithMemory("RecoveryGuard", [
        WouldARecoveryHelp(bb),
        ReactiveFallback("RecoveryFallback", [GoalUpdated(bb), actions]),
    ])


def _tree(planner: Behaviour, bb: NavBlackboard, c: NavClients, clock: Callable[[], int],
          o: TreeOptions) -> Behaviour:
    pipeline = PipelineSequence("NavigateWithReplanning", [
        RateController("RateController", planner, o.replanning_frequency, clock),
        FollowPath("FollowPath", c.follow_path, bb, clock, o.server_timeout),
    ])
    return RecoveryNode("NavigateRecovery", pipeline, _recovery_branch(bb, c, clock, o),
                        o.number_of_retries)


def navigate_to_pose_tree(bb: NavBlackboard, clients: NavClients, clock: Callable[[], int],
                          options: TreeOptions | None = None) -> Behaviour:
    """Nav2's ``navigate_to_pose_w_replanning_and_recovery`` tree; ``clock()`` gives ns."""
    o = options or TreeOptions()
    planner = ComputePathToPose("ComputePathToPose", clients.compute_path_to_pose, bb, clock,
                                o.server_timeout)
    return _tree(planner, bb, clients, clock, o)


def navigate_through_poses_tree(bb: NavBlackboard, clients: NavClients, clock: Callable[[], int],
                                options: TreeOptions | None = None) -> Behaviour:
    """Nav2's ``navigate_through_poses_w_replanning_and_recovery`` tree."""
    o = options or TreeOptions()
    planner = SequenceWithMemory("PlanThroughPoses", [
        RemovePassedGoals(bb, o.passed_goal_radius),
        ComputePathThroughPoses("ComputePathThroughPoses", clients.compute_path_through_poses,
                                bb, clock, o.server_timeout),
    ])
    return _tree(planner, bb, clients, clock, o)
