"""Typed navigation failures, each carrying the Nav2 action result code it maps to.

Planner codes follow ``nav2_msgs/action/ComputePathToPose`` (200..208), controller codes
``FollowPath`` (100..106), smoother codes ``SmoothPath`` (500..505) and behaviour codes the
Jazzy behaviour actions (700..704). A server catches :class:`NavError` and copies
``error.result_code`` and ``str(error)`` into the action result.
"""

from __future__ import annotations

from typing import Any


class NavError(Exception):
    """Base class of every navigation failure."""

    result_code: int = 0


class ParameterError(NavError, ValueError):
    """A parameter value rejected at configure time, named by server, key and value."""

    def __init__(self, server: str, key: str, value: Any, reason: str) -> None:
        self.server = server
        self.key = key
        self.value = value
        self.reason = reason
        super().__init__(f"{server}: parameter {key!r} = {value!r}: {reason}")


class UnsupportedPlugin(ParameterError):
    """A plugin type named in the parameters that eddiebot cannot load (``key`` is
    ``<instance>.plugin``, ``value`` the type); the bring-up must not go on without it."""

    @property
    def plugin(self) -> str:
        return str(self.value)


class CostmapError(NavError):
    """Invalid costmap operation (bad geometry, unknown layer)."""


# --- planner server (ComputePathToPose) -------------------------------------------------
class PlannerError(NavError):
    """Planning failed for a reason not covered below (``UNKNOWN``)."""

    result_code = 200


class InvalidPlanner(PlannerError):
    result_code = 201


class PlannerTFError(PlannerError):
    result_code = 202


class StartOutsideMapBounds(PlannerError):
    result_code = 203


class GoalOutsideMapBounds(PlannerError):
    result_code = 204


class StartOccupied(PlannerError):
    result_code = 205


class GoalOccupied(PlannerError):
    result_code = 206


class PlannerTimedOut(PlannerError):
    result_code = 207


class NoValidPath(PlannerError):
    result_code = 208


# --- controller server (FollowPath) -----------------------------------------------------
class ControllerError(NavError):
    """Control failed for a reason not covered below (``UNKNOWN``)."""

    result_code = 100


class InvalidController(ControllerError):
    result_code = 101


class ControllerTFError(ControllerError):
    result_code = 102


class InvalidPath(ControllerError):
    result_code = 103


class PatienceExceeded(ControllerError):
    result_code = 104


class FailedToMakeProgress(ControllerError):
    result_code = 105


class NoValidControl(ControllerError):
    """No admissible command (e.g. collision imminent, every sample scored invalid)."""

    result_code = 106


# --- smoother server (SmoothPath) -------------------------------------------------------
class SmootherError(NavError):
    result_code = 500


class InvalidSmoother(SmootherError):
    result_code = 501


class SmootherTimedOut(SmootherError):
    result_code = 502


class SmoothedPathInCollision(SmootherError):
    result_code = 503


class FailedToSmoothPath(SmootherError):
    result_code = 504


class InvalidPathForSmoothing(SmootherError):
    result_code = 505


# --- behaviour server -------------------------------------------------------------------
class BehaviorError(NavError):
    result_code = 700


class BehaviorTimedOut(BehaviorError):
    result_code = 701


class CollisionAhead(BehaviorError):
    result_code = 703


class InvalidBehaviorInput(BehaviorError):
    result_code = 704


# --- localization -----------------------------------------------------------------------
class LocalizationError(NavError):
    """AMCL cannot proceed (no map, no initial pose)."""


__all__ = [
    "BehaviorError",
    "BehaviorTimedOut",
    "CollisionAhead",
    "ControllerError",
    "ControllerTFError",
    "CostmapError",
    "FailedToMakeProgress",
    "FailedToSmoothPath",
    "GoalOccupied",
    "GoalOutsideMapBounds",
    "InvalidBehaviorInput",
    "InvalidController",
    "InvalidPath",
    "InvalidPathForSmoothing",
    "InvalidPlanner",
    "InvalidSmoother",
    "LocalizationError",
    "NavError",
    "NoValidControl",
    "NoValidPath",
    "ParameterError",
    "PatienceExceeded",
    "PlannerError",
    "PlannerTFError",
    "PlannerTimedOut",
    "SmoothedPathInCollision",
    "SmootherError",
    "SmootherTimedOut",
    "StartOccupied",
    "StartOutsideMapBounds",
    "UnsupportedPlugin",
]
