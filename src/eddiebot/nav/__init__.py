"""Autonomous navigation cores after Nav2: costmaps, planners, smoother, controllers,
velocity smoother, collision monitor, behaviours and AMCL.

Every module here is a pure core: arrays and dataclasses in, arrays and dataclasses out, no
bus, clock or files (``config.load_nav2_config`` may read one YAML file). Poses are
``(x, y, yaw)`` arrays in the costmap's global frame, paths ``(N, 3)`` arrays, velocities
:class:`Twist2D`. Parameter names and defaults are Nav2's (Jazzy); plugin registries map
Nav2 plugin type names to classes; failures are typed (:mod:`eddiebot.nav.errors`) and carry
Nav2 action result codes. Entry points: :mod:`eddiebot.nav.costmap` (``build_costmap``),
:mod:`eddiebot.nav.planners` (``build_planners``), :mod:`eddiebot.nav.controllers`
(``build_controller_server``), :mod:`eddiebot.nav.smoother`, :mod:`eddiebot.nav.velocity_smoother`,
:mod:`eddiebot.nav.collision_monitor`, :mod:`eddiebot.nav.behaviors`, :mod:`eddiebot.nav.amcl`,
and :func:`eddiebot.nav.config.load_nav2_config` for a whole parameters file.
"""

from eddiebot.nav import cost_values, errors
from eddiebot.nav.errors import NavError, ParameterError
from eddiebot.nav.types import Twist2D

__all__ = ["NavError", "ParameterError", "Twist2D", "cost_values", "errors"]
