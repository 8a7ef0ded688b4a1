"""The explore node's state and its record of each frontier goal."""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["ExploreState", "GoalRecord"]


class ExploreState(enum.Enum):
    WAITING = "waiting"
    LOOK_AROUND = "look_around"
    EXPLORING = "exploring"
    RETURNING = "returning"
    DONE = "done"


@dataclass
class GoalRecord:
    """One frontier goal: where (map frame, m/rad), when (s, node clock), how it ended."""

    frontier_id: int
    viewpoint: tuple[float, float, float]
    centroid: tuple[float, float]
    sent_s: float
    outcome: str = "active"
