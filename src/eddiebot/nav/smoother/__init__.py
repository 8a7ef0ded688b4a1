"""Nav2's path smoothers: ``nav2_smoother``'s ``SimpleSmoother`` and ``SavitzkyGolaySmoother``,
and ``nav2_constrained_smoother::ConstrainedSmoother``.

``SimpleSmoother``: gradient smoothing that never enters collision.

Each interior point moves by ``w_data·(original - current) + w_smooth·(next + prev -
2·current)`` per iteration until the total change falls below ``tolerance``; if a moved point
lands on a cost above ``MAX_NON_OBSTACLE`` (unknown excepted) the path of the previous
iteration is returned. Segments between cusps are smoothed separately with fixed ends;
``do_refinement`` reruns the smoother ``refinement_num`` times on its own output.

``SavitzkyGolaySmoother``: a 7-point Savitzky-Golay filter (quadratic fit, coefficients
(-2, 3, 6, 7, 6, 3, -2)/21) over each directional segment longer than 10 poses, the window
padded with the segment's first and last points, both ends fixed; ``do_refinement`` filters
the result ``refinement_num`` more times. It does not check collisions, as upstream.

``ConstrainedSmoother``: the path as a least-squares problem over its poses (smoothness,
minimum turning radius, distance to the original, costmap cost), solved by a
Levenberg-Marquardt trust region as Nav2's Ceres set-up; see :class:`ConstrainedSmoother`.

One smoother per module (:mod:`.simple`, :mod:`.savitzky_golay`, :mod:`.constrained`;
:class:`SmoothResult` and the :class:`Smoother` interface in :mod:`.base`); this package holds
the ``smoothers`` registry and re-exports them all.
"""

from __future__ import annotations

from typing import Any

from eddiebot.nav.params import from_params
from eddiebot.nav.plugins import PluginContext, PluginFactory, registry
from eddiebot.nav.smoother.base import Smoother, SmoothResult
from eddiebot.nav.smoother.constrained import (
    ConstrainedOptimizerConfig,
    ConstrainedSmoother,
    ConstrainedSmootherConfig,
    bicubic_cost,
)
from eddiebot.nav.smoother.savitzky_golay import SavitzkyGolaySmoother, SavitzkyGolaySmootherConfig
from eddiebot.nav.smoother.simple import SimpleSmoother, SimpleSmootherConfig

SMOOTHERS = registry("smoothers")


def register_smoother(type_name: str, cls: type[Any], config_cls: type[Any]) -> None:
    """Register a smoother built as ``cls(config, name)`` with its config dataclass
    ``config_cls`` read from the instance's parameters."""

    def factory(params: dict[str, Any], name: str, context: PluginContext) -> Any:
        return cls(from_params(config_cls, params, server=context.where), name)

    f: PluginFactory = factory
    SMOOTHERS.register(type_name, f, config_cls, source="built-in")


register_smoother("nav2_smoother::SimpleSmoother", SimpleSmoother, SimpleSmootherConfig)
register_smoother("nav2_smoother::SavitzkyGolaySmoother", SavitzkyGolaySmoother,
                  SavitzkyGolaySmootherConfig)
register_smoother("nav2_constrained_smoother::ConstrainedSmoother", ConstrainedSmoother,
                  ConstrainedSmootherConfig)


def build_smoother(name: str, params: dict[str, Any], server: str = "smoother_server"
                   ) -> Smoother:
    """The smoother instance ``name`` from its parameter block (``plugin`` defaults to
    SimpleSmoother, as in Nav2's sample files)."""
    plugin = str(params.get("plugin", "nav2_smoother::SimpleSmoother"))
    smoother: Smoother = SMOOTHERS.create(plugin, params, name, PluginContext(server, name))
    return smoother



__all__ = ["SMOOTHERS", "ConstrainedOptimizerConfig", "ConstrainedSmoother",
           "ConstrainedSmootherConfig", "SavitzkyGolaySmoother", "SavitzkyGolaySmootherConfig",
           "SimpleSmoother", "SimpleSmootherConfig", "SmoothResult", "Smoother", "bicubic_cost",
           "build_smoother", "register_smoother"]
