"""Parameters of the MPPI critics (``mppi::critics::*``, Jazzy): one frozen dataclass per
critic with upstream's names and defaults, each validating its own values."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from eddiebot.nav.params import require


def _check_common(cfg: Any, where: str) -> None:
    require(cfg.cost_power >= 1, where, "cost_power", cfg.cost_power, "must be >= 1")


@dataclass(frozen=True)
class ConstraintCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 4.0

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class CostCriticConfig:
    enabled: bool = True
    consider_footprint: bool = False
    cost_power: int = 1
    cost_weight: float = 3.81
    critical_cost: float = 300.0
    near_collision_cost: int = 253
    collision_cost: float = 1000000.0
    near_goal_distance: float = 0.5
    inflation_layer_name: str = ""
    trajectory_point_step: int = 2

    def validate(self, where: str) -> None:
        _check_common(self, where)
        require(self.trajectory_point_step >= 1, where, "trajectory_point_step",
                self.trajectory_point_step, "must be >= 1")


@dataclass(frozen=True)
class GoalCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 5.0
    threshold_to_consider: float = 1.4

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class GoalAngleCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 3.0
    threshold_to_consider: float = 0.5
    symmetric_yaw_tolerance: bool = False

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class PathAlignCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 10.0
    max_path_occupancy_ratio: float = 0.07
    offset_from_furthest: int = 20
    trajectory_point_step: int = 4
    threshold_to_consider: float = 0.5
    use_path_orientations: bool = False

    def validate(self, where: str) -> None:
        _check_common(self, where)
        require(self.trajectory_point_step >= 1, where, "trajectory_point_step",
                self.trajectory_point_step, "must be >= 1")
        require(self.offset_from_furthest >= 0, where, "offset_from_furthest",
                self.offset_from_furthest, "must be >= 0")


@dataclass(frozen=True)
class PathFollowCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 5.0
    offset_from_furthest: int = 6
    threshold_to_consider: float = 1.4

    def validate(self, where: str) -> None:
        _check_common(self, where)
        require(self.offset_from_furthest >= 0, where, "offset_from_furthest",
                self.offset_from_furthest, "must be >= 0")


class PathAngleMode(IntEnum):
    FORWARD_PREFERENCE = 0
    NO_DIRECTIONAL_PREFERENCE = 1
    CONSIDER_FEASIBLE_PATH_ORIENTATIONS = 2


@dataclass(frozen=True)
class PathAngleCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 2.2
    offset_from_furthest: int = 4
    threshold_to_consider: float = 0.5
    max_angle_to_furthest: float = 0.785398
    mode: int = 0

    def validate(self, where: str) -> None:
        _check_common(self, where)
        require(self.mode in (0, 1, 2), where, "mode", self.mode,
                "0 (forward preference), 1 (no directional preference) or 2 (consider feasible "
                "path orientations)")
        require(self.offset_from_furthest >= 0, where, "offset_from_furthest",
                self.offset_from_furthest, "must be >= 0")


@dataclass(frozen=True)
class PreferForwardCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 5.0
    threshold_to_consider: float = 0.5

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class ObstaclesCriticConfig:
    enabled: bool = True
    consider_footprint: bool = False
    cost_power: int = 1
    repulsion_weight: float = 1.5
    critical_weight: float = 20.0
    collision_cost: float = 100000.0
    collision_margin_distance: float = 0.10
    near_goal_distance: float = 0.5
    inflation_layer_name: str = ""

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class TwirlingCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 10.0

    def validate(self, where: str) -> None:
        _check_common(self, where)


@dataclass(frozen=True)
class VelocityDeadbandCriticConfig:
    enabled: bool = True
    cost_power: int = 1
    cost_weight: float = 35.0
    deadband_velocities: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def validate(self, where: str) -> None:
        _check_common(self, where)


__all__ = [
    "ConstraintCriticConfig",
    "CostCriticConfig",
    "GoalAngleCriticConfig",
    "GoalCriticConfig",
    "ObstaclesCriticConfig",
    "PathAlignCriticConfig",
    "PathAngleCriticConfig",
    "PathAngleMode",
    "PathFollowCriticConfig",
    "PreferForwardCriticConfig",
    "TwirlingCriticConfig",
    "VelocityDeadbandCriticConfig",
]
