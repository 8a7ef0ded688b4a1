"""Whole-stack navigation configuration from a Nav2 parameters file.

:func:`load_nav2_config` takes the parsed YAML (or a path; the only file access in the
package) and builds every server's config and plugins, so a bad key fails at configure
with a :class:`~eddiebot.nav.errors.ParameterError` naming server, key and value. It also
returns warnings about values upstream accepts silently but that cannot work on the robot.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from eddiebot.nav.amcl import AmclConfig
from eddiebot.nav.behaviors import BehaviorServerConfig, build_behaviors
from eddiebot.nav.collision_monitor import CollisionMonitor, build_collision_monitor
from eddiebot.nav.controllers import ControllerServer, build_controller_server
from eddiebot.nav.costmap.layered import LayeredCostmap, build_costmap
from eddiebot.nav.params import from_params
from eddiebot.nav.planners import GlobalPlanner, build_planners
from eddiebot.nav.smoother import Smoother, build_smoother
from eddiebot.nav.velocity_smoother import VelocitySmootherConfig, timing_warnings

#: Parallax Eddie's no-load top speed (m/s), reference/eddie_hardware.md.
EDDIE_TOP_SPEED = 1.2


@dataclass
class Nav2Config:
    amcl: AmclConfig | None = None
    global_costmap: LayeredCostmap | None = None
    local_costmap: LayeredCostmap | None = None
    planners: dict[str, GlobalPlanner] = field(default_factory=dict)
    controller_server: ControllerServer | None = None
    smoothers: dict[str, Smoother] = field(default_factory=dict)
    behavior_server: BehaviorServerConfig | None = None
    behaviors: dict[str, Any] = field(default_factory=dict)
    velocity_smoother: VelocitySmootherConfig | None = None
    collision_monitor: CollisionMonitor | None = None
    warnings: list[str] = field(default_factory=list)


def _params(doc: Mapping[str, Any], *path: str) -> dict[str, Any] | None:
    node: Any = doc
    for p in path:
        if not isinstance(node, Mapping) or p not in node:
            return None
        node = node[p]
    if isinstance(node, Mapping) and "ros__parameters" in node:
        return dict(node["ros__parameters"] or {})
    return None


def _flatten_amcl(p: dict[str, Any]) -> dict[str, Any]:
    out = dict(p)
    init = out.pop("initial_pose", None)
    if isinstance(init, Mapping):
        for k in ("x", "y", "z", "yaw"):
            if k in init:
                out[f"initial_pose_{k}"] = init[k]
    # ROS 1 spellings of the KLD parameters.
    if "kld_err" in out:
        out.setdefault("pf_err", out.pop("kld_err"))
    if "kld_z" in out:
        out.setdefault("pf_z", out.pop("kld_z"))
    return out


def load_nav2_config(
    source: str | os.PathLike[str] | Mapping[str, Any],
    *,
    stale_command_timeout: float | None = None,
    top_speed: float = EDDIE_TOP_SPEED,
) -> Nav2Config:
    """Build every server present in a Nav2 params document (path or parsed dict)."""
    if isinstance(source, (str, os.PathLike)):
        doc = yaml.safe_load(Path(source).read_text()) or {}
    else:
        doc = dict(source)
    out = Nav2Config()
    if (p := _params(doc, "amcl")) is not None:
        out.amcl = from_params(AmclConfig, _flatten_amcl(p), server="amcl")
    if (p := _params(doc, "global_costmap", "global_costmap")) is not None:
        out.global_costmap = build_costmap(p, "global_costmap")
    if (p := _params(doc, "local_costmap", "local_costmap")) is not None:
        out.local_costmap = build_costmap(p, "local_costmap")
    if (p := _params(doc, "planner_server")) is not None:
        out.planners = build_planners(p)
    if (p := _params(doc, "controller_server")) is not None:
        out.controller_server = build_controller_server(p)
    if (p := _params(doc, "smoother_server")) is not None:
        names = p.get("smoother_plugins", ["simple_smoother"])
        for name in names:
            out.smoothers[name] = build_smoother(name, dict(p.get(name, {}) or {}))
    if (p := _params(doc, "behavior_server")) is not None:
        out.behavior_server, out.behaviors = build_behaviors(p)
    if (p := _params(doc, "velocity_smoother")) is not None:
        vs = from_params(VelocitySmootherConfig, p, server="velocity_smoother")
        out.velocity_smoother = vs
        out.warnings.extend(timing_warnings(vs, stale_command_timeout))
        if max(vs.max_velocity[0], -vs.min_velocity[0]) > top_speed:
            out.warnings.append(
                f"velocity_smoother: |vx| limit {max(vs.max_velocity[0], -vs.min_velocity[0])} m/s "
                f"exceeds the robot's top speed {top_speed} m/s")
    if (p := _params(doc, "collision_monitor")) is not None:
        fp = out.local_costmap.footprint if out.local_costmap is not None else None
        out.collision_monitor = build_collision_monitor(p, fp)
    return out


__all__ = ["EDDIE_TOP_SPEED", "Nav2Config", "load_nav2_config"]
