"""What eddiebot does with each entry of a Nav2 parameters file, said once at start.

A parameters file written for Nav2 (``nav2_bringup/params/nav2_params.yaml`` of any
distribution) names servers eddiebot does not run (``docking_server``, ``route_server``, the
costmap-filter mask servers, ...) and keys no eddiebot server reads. ROS 2 would ignore both
without a word; :func:`audit_nav2_params` names each one once — ``not supported:
docking_server (whole section)``, ``ignored: controller_server.FollowPath.foo`` — and
returns the document without them, which the launch then accepts as is. A plugin the file
asks for that cannot be configured (``nav2_graceful_controller::GracefulController``, an MPPI
critic eddiebot does not have) is not a warning:
:class:`~eddiebot.nav.errors.UnsupportedPlugin` names it, the server and the key, and the
bring-up must stop.

The known keys of each server are its node's declared parameters plus the fields of the
config dataclass of each plugin the file loads, so the audit follows the code.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from eddiebot.nav.amcl import AmclConfig
from eddiebot.nav.behaviors import BEHAVIOR_PLUGINS, BehaviorServerConfig
from eddiebot.nav.collision_monitor import CollisionMonitorConfig, PolygonConfig
from eddiebot.nav.controllers import (
    CONTROLLER_PLUGINS,
    GOAL_CHECKER_PLUGINS,
    PROGRESS_CHECKER_PLUGINS,
    ControllerServerConfig,
)
from eddiebot.nav.controllers.checkers import (
    PoseProgressCheckerConfig,
    SimpleGoalCheckerConfig,
    SimpleProgressCheckerConfig,
)
from eddiebot.nav.controllers.dwb import DWBConfig
from eddiebot.nav.controllers.rpp import RegulatedPurePursuitConfig
from eddiebot.nav.costmap.layered import COSTMAP_PLUGINS, CostmapConfig
from eddiebot.nav.costmap.layers import (
    ObservationSourceConfig,
    ObstacleLayerConfig,
)
from eddiebot.nav.errors import UnsupportedPlugin
from eddiebot.nav.planners import PLANNER_PLUGINS, PlannerServerConfig
from eddiebot.nav.plugins import PluginRegistry, PluginType, plugin_key
from eddiebot.nav.smoother import SMOOTHERS
from eddiebot.nav.velocity_smoother import VelocitySmootherConfig

__all__ = ["ParamsAudit", "audit_nav2_params"]

#: keys every node takes (rclcpp's own)
_NODE_KEYS = frozenset({"use_sim_time", "bond_heartbeat_period", "qos_overrides"})


@dataclass(frozen=True)
class ParamsAudit:
    """``warnings``: one line per unsupported section or ignored key, in file order;
    ``supported``: the document without them (what the servers are given)."""

    warnings: tuple[str, ...]
    supported: dict[str, Any]


def _fields(*classes: type[Any]) -> set[str]:
    return {f.name for c in classes for f in dataclasses.fields(c)}


def _node_keys(name: str) -> set[str]:
    from eddiebot.nav.nodes import server_class

    return set(server_class(name).PARAMETERS) | _NODE_KEYS


def _names(value: Any) -> list[str]:
    """A plugin list as Nav2 writes it: a YAML list or one space-separated string."""
    if isinstance(value, str):
        return value.split()
    if isinstance(value, (list, tuple)):
        return [str(v) for v in value if str(v)]
    return []


class _Audit:
    """Walks one server's parameters, dropping and naming the keys nothing reads."""

    def __init__(self, warnings: list[str]) -> None:
        self.warnings = warnings

    def keys(self, where: str, params: dict[str, Any], known: Iterable[str],
             nested: Mapping[str, Callable[[str, dict[str, Any]], None]] | None = None) -> None:
        """Drop (and name) every key of ``params`` that is neither in ``known`` nor a nested
        section handled by ``nested[key]``; the nested handlers audit their own dicts."""
        known = set(known)
        nested = nested or {}
        for key in list(params):
            value = params[key]
            if key in nested and isinstance(value, dict):
                nested[key](f"{where}.{key}", value)
                continue
            if key in known and not (isinstance(value, dict) and key not in nested):
                continue
            self.warnings.append(f"ignored: {where}.{key}")
            del params[key]

    def plugins(self, where: str, params: dict[str, Any], names: Iterable[str],
                kinds: Mapping[str, Callable[[str, dict[str, Any]], None]],
                default: Mapping[str, str], registry: Iterable[str], server: str) -> dict[str, Any]:
        """Handlers for the plugin instances ``names``: each one's ``plugin`` type must be in
        ``registry`` (else :class:`UnsupportedPlugin`) and its keys are audited by
        ``kinds[type]``."""
        out: dict[str, Callable[[str, dict[str, Any]], None]] = {}
        for name in names:
            sub = params.get(name)
            sub = sub if isinstance(sub, dict) else {}
            plugin = plugin_key(str(sub.get("plugin", default.get(name, ""))))
            if plugin not in registry:
                raise UnsupportedPlugin(server, f"{name}.plugin", plugin or None,
                                        f"plugin not available; available: {sorted(registry)}")
            if plugin in kinds:
                out[name] = kinds[plugin]
            elif isinstance(registry, PluginRegistry):
                out[name] = self._config_keys(registry.resolve(plugin, server, f"{name}.plugin"))
        return out

    def _section_keys(self, config: type[Any]) -> Callable[[str, dict[str, Any]], None]:
        return lambda w, d: self.keys(w, d, _fields(config))

    def _config_keys(self, entry: PluginType) -> Callable[[str, dict[str, Any]], None]:
        """A registry type's keys: the fields of its config dataclass, or all of them kept
        when it names none (a plugin from another package: its own factory reads them)."""
        config = entry.config
        if config is None:
            return lambda w, d: None
        # sections a config reads into their own dataclass (SmacPlanner*'s ``smoother``)
        nested = {k: self._section_keys(c) for k, c in getattr(config, "NESTED", {}).items()}
        return lambda w, d: self.keys(w, d, _fields(config) | {"plugin"}, nested)


def _audit_costmap(a: _Audit, where: str, params: dict[str, Any], server: str) -> None:
    def obstacle(w: str, d: dict[str, Any]) -> None:
        sources = _names(d.get("observation_sources", ""))
        nested = {s: (lambda ww, dd: a.keys(ww, dd, _fields(ObservationSourceConfig)))
                  for s in sources}
        a.keys(w, d, (_fields(ObstacleLayerConfig) - {"sources"}) | {"plugin"}, nested)

    # the other layers' keys are their config dataclasses' fields (``_Audit._config_keys``)
    kinds = {"nav2_costmap_2d::ObstacleLayer": obstacle, "nav2_costmap_2d::VoxelLayer": obstacle}
    default = {"static_layer": "nav2_costmap_2d::StaticLayer",
               "obstacle_layer": "nav2_costmap_2d::ObstacleLayer",
               "inflation_layer": "nav2_costmap_2d::InflationLayer"}
    names = _names(params.get("plugins", list(CostmapConfig().plugins)))
    names += _names(params.get("filters", []))
    nested = a.plugins(where, params, names, kinds, default, COSTMAP_PLUGINS, server)
    a.keys(where, params, _fields(CostmapConfig) | _NODE_KEYS, nested)


def _audit_dwb(a: _Audit, where: str, params: dict[str, Any]) -> None:
    # DWB's critic parameters are ``<Critic>.<key>``, read as the flat field ``<Critic>_<key>``
    fields = _fields(DWBConfig) | {"plugin"}
    for key in list(params):
        value = params[key]
        if isinstance(value, dict):
            for sub in list(value):
                if f"{key}_{sub}" not in fields:
                    a.warnings.append(f"ignored: {where}.{key}.{sub}")
                    del value[sub]
            if not value:
                del params[key]
        elif key.replace(".", "_") not in fields:
            a.warnings.append(f"ignored: {where}.{key}")
            del params[key]


def _audit_mppi(a: _Audit, where: str, params: dict[str, Any]) -> None:
    from eddiebot.nav.controllers.mppi import CRITICS, mppi_known_keys

    server, _, name = where.partition(".")
    for critic in _names(params.get("critics", [])):
        if critic not in CRITICS:
            raise UnsupportedPlugin(server, f"{name}.critics", critic,
                                    f"unknown MPPI critic; available: {sorted(CRITICS)}")
    flat, blocks = mppi_known_keys(params)
    nested = {b: (lambda k: lambda w, d: a.keys(w, d, k))(keys) for b, keys in blocks.items()}
    a.keys(where, params, flat, nested)


def _audit_rotation_shim(a: _Audit, where: str, params: dict[str, Any],
                         kinds: Mapping[str, Callable[[str, dict[str, Any]], None]]) -> None:
    # the shim's keys and its primary's share the block: the primary's are audited as its own
    from eddiebot.nav.controllers.rotation_shim import split_params

    server, _, name = where.partition(".")
    own, primary, rest = split_params(params, server, name, CONTROLLER_PLUGINS)
    if "plugin" in params:
        rest["plugin"] = params["plugin"]
    audit = kinds.get(primary) or a._config_keys(CONTROLLER_PLUGINS[primary])
    audit(where, rest)
    params.clear()
    params.update({**rest, **own})


def _audit_controller_server(a: _Audit, params: dict[str, Any]) -> None:
    server = "controller_server"
    cfg = ControllerServerConfig()
    kinds: dict[str, Callable[[str, dict[str, Any]], None]] = {
        "nav2_regulated_pure_pursuit_controller::RegulatedPurePursuitController":
            lambda w, d: a.keys(w, d, _fields(RegulatedPurePursuitConfig) | {"plugin"}),
        "dwb_core::DWBLocalPlanner": lambda w, d: _audit_dwb(a, w, d),
        "nav2_mppi_controller::MPPIController": lambda w, d: _audit_mppi(a, w, d),
        "nav2_rotation_shim_controller::RotationShimController":
            lambda w, d: _audit_rotation_shim(a, w, d, kinds),
        "nav2_controller::SimpleProgressChecker":
            lambda w, d: a.keys(w, d, _fields(SimpleProgressCheckerConfig) | {"plugin"}),
        "nav2_controller::PoseProgressChecker":
            lambda w, d: a.keys(w, d, _fields(PoseProgressCheckerConfig) | {"plugin"}),
        "nav2_controller::SimpleGoalChecker":
            lambda w, d: a.keys(w, d, _fields(SimpleGoalCheckerConfig) | {"plugin"}),
    }
    default = {"FollowPath": "dwb_core::DWBLocalPlanner",
               "progress_checker": "nav2_controller::SimpleProgressChecker",
               "goal_checker": "nav2_controller::SimpleGoalChecker"}
    nested: dict[str, Callable[[str, dict[str, Any]], None]] = {}
    for list_key, registry in (("controller_plugins", CONTROLLER_PLUGINS),
                               ("progress_checker_plugins", PROGRESS_CHECKER_PLUGINS),
                               ("goal_checker_plugins", GOAL_CHECKER_PLUGINS)):
        names = _names(params.get(list_key, list(getattr(cfg, list_key))))
        nested.update(a.plugins(server, params, names, kinds, default, registry, server))
    if isinstance(params.get("local_costmap"), dict):
        nested["local_costmap"] = lambda w, d: _audit_costmap(a, w, d, "local_costmap")
    a.keys(server, params, _node_keys(server), nested)


def _audit_planner_server(a: _Audit, params: dict[str, Any]) -> None:
    server = "planner_server"
    kinds: dict[str, Callable[[str, dict[str, Any]], None]] = {}
    names = _names(params.get("planner_plugins", list(PlannerServerConfig().planner_plugins)))
    nested = a.plugins(server, params, names, kinds,
                       {"GridBased": "nav2_navfn_planner::NavfnPlanner"}, PLANNER_PLUGINS, server)
    if isinstance(params.get("global_costmap"), dict):
        nested["global_costmap"] = lambda w, d: _audit_costmap(a, w, d, "global_costmap")
    a.keys(server, params, _node_keys(server), nested)


def _audit_smoother_server(a: _Audit, params: dict[str, Any]) -> None:
    server = "smoother_server"
    names = _names(params.get("smoother_plugins", ["simple_smoother"]))
    nested = a.plugins(server, params, names, {},
                       dict.fromkeys(names, "nav2_smoother::SimpleSmoother"), SMOOTHERS, server)
    a.keys(server, params, _node_keys(server), nested)


def _audit_behavior_server(a: _Audit, params: dict[str, Any]) -> None:
    server = "behavior_server"
    names = _names(params.get("behavior_plugins", list(BehaviorServerConfig().behavior_plugins)))
    nested = a.plugins(server, params, names, {}, {}, BEHAVIOR_PLUGINS, server)
    a.keys(server, params, _node_keys(server) | _fields(BehaviorServerConfig), nested)


def _audit_bt_navigator(a: _Audit, params: dict[str, Any]) -> None:
    server = "bt_navigator"
    navigators = {"nav2_bt_navigator::NavigateToPoseNavigator",
                  "nav2_bt_navigator::NavigateThroughPosesNavigator"}
    # the navigators' own keys (their tree XML, blackboard ids) are read at the top level
    kinds = {p: (lambda w, d: a.keys(w, d, {"plugin"})) for p in navigators}
    names = _names(params.get("navigators", ["navigate_to_pose", "navigate_through_poses"]))
    default = {"navigate_to_pose": "nav2_bt_navigator::NavigateToPoseNavigator",
               "navigate_through_poses": "nav2_bt_navigator::NavigateThroughPosesNavigator"}
    nested = a.plugins(server, params, names, kinds, default, navigators, server)
    a.keys(server, params, _node_keys(server), nested)


def _audit_waypoint_follower(a: _Audit, params: dict[str, Any]) -> None:
    from eddiebot.nav.nodes.waypoint_follower import TASK_EXECUTOR_KEYS

    server = "waypoint_follower"
    kinds = {p: (lambda k: lambda w, d: a.keys(w, d, k | {"plugin", "enabled"}))(set(keys))
             for p, keys in TASK_EXECUTOR_KEYS.items()}
    name = str(params.get("waypoint_task_executor_plugin", "wait_at_waypoint"))
    nested = a.plugins(server, params, [name], kinds,
                       {"wait_at_waypoint": "nav2_waypoint_follower::WaitAtWaypoint"},
                       TASK_EXECUTOR_KEYS, server)
    a.keys(server, params, _node_keys(server), nested)


def _audit_collision_monitor(a: _Audit, params: dict[str, Any]) -> None:
    from eddiebot.nav.nodes.collision_monitor import SOURCE_KEYS

    server = "collision_monitor"
    nested: dict[str, Callable[[str, dict[str, Any]], None]] = {}

    def polygon(w: str, d: dict[str, Any]) -> None:
        subs = {s: (lambda ww, dd: a.keys(ww, dd, {
            "points", "linear_min", "linear_max", "theta_min", "theta_max",
            "direction_end_angle", "direction_start_angle"}))
            for s in _names(d.get("velocity_polygons", []))}
        a.keys(w, d, _fields(PolygonConfig), subs)

    def source(w: str, d: dict[str, Any]) -> None:
        a.keys(w, d, SOURCE_KEYS.get(str(d.get("type", "scan")), set()))

    for name in _names(params.get("polygons", [])):
        nested[name] = polygon
    for name in _names(params.get("observation_sources", [])):
        nested[name] = source
    a.keys(server, params, _node_keys(server) | _fields(CollisionMonitorConfig), nested)


def _audit_amcl(a: _Audit, params: dict[str, Any]) -> None:
    keys = _fields(AmclConfig) | _node_keys("amcl") | {"kld_err", "kld_z"}
    a.keys("amcl", params, keys,
           {"initial_pose": lambda w, d: a.keys(w, d, {"x", "y", "z", "yaw"})})


def _flat_server(name: str, extra: set[str] | None = None) -> Callable[[_Audit, dict[str, Any]], None]:
    return lambda a, p: a.keys(name, p, _node_keys(name) | (extra or set()))


_SERVERS: dict[str, Callable[[_Audit, dict[str, Any]], None]] = {
    "amcl": _audit_amcl,
    "map_server": _flat_server("map_server"),
    "map_saver": _flat_server("map_saver"),
    "planner_server": _audit_planner_server,
    "controller_server": _audit_controller_server,
    "smoother_server": _audit_smoother_server,
    "behavior_server": _audit_behavior_server,
    "bt_navigator": _audit_bt_navigator,
    "waypoint_follower": _audit_waypoint_follower,
    "velocity_smoother": _flat_server("velocity_smoother", _fields(VelocitySmootherConfig)),
    "collision_monitor": _audit_collision_monitor,
}


def _filter_server_audit(name: str) -> Callable[[_Audit, dict[str, Any]], None] | None:
    """Filter mask and info servers go by any name ending as Nav2's sample files' do."""
    from eddiebot.nav.nodes import costmap_filters as cf

    if cf.is_filter_mask_server(name):
        return lambda a, p: a.keys(name, p, set(cf.FilterMaskServer.PARAMETERS) | _NODE_KEYS)
    if cf.is_filter_info_server(name):
        return lambda a, p: a.keys(name, p, set(cf.CostmapFilterInfoServer.PARAMETERS) | _NODE_KEYS)
    return None


#: lifecycle managers are launched with their node lists; a file's values are not read
_COSTMAP_NODES = {"global_costmap": "planner_server", "local_costmap": "controller_server"}


def audit_nav2_params(doc: Mapping[str, Any]) -> ParamsAudit:
    """Check a parsed Nav2 parameters document against what eddiebot's servers read.

    Costmaps may sit as Nav2 writes them (``local_costmap: local_costmap:
    ros__parameters``) or folded into their servers. Raises
    :class:`~eddiebot.nav.errors.UnsupportedPlugin` for a plugin that cannot be configured.
    """
    out = copy.deepcopy(dict(doc))
    warnings: list[str] = []
    a = _Audit(warnings)
    for section in list(out):
        body = out[section]
        name = str(section).strip("/")
        if name in _COSTMAP_NODES and isinstance(body, dict) and isinstance(body.get(name), dict):
            inner = body[name]
            params = inner.get("ros__parameters")
            if isinstance(params, dict):
                _audit_costmap(a, name, params, name)
            for key in [k for k in inner if k != "ros__parameters"]:
                warnings.append(f"ignored: {name}.{key}")
                del inner[key]
            for key in [k for k in body if k != name]:
                warnings.append(f"not supported: {name}/{key} (whole section)")
                del body[key]
            continue
        audit = _SERVERS.get(name) or _filter_server_audit(name)
        if audit is None or not isinstance(body, dict):
            warnings.append(f"not supported: {name} (whole section)")
            del out[section]
            continue
        params = body.get("ros__parameters")
        if isinstance(params, dict):
            audit(a, params)
        for key in [k for k in body if k != "ros__parameters"]:
            warnings.append(f"ignored: {name}.{key}")
            del body[key]
    return ParamsAudit(tuple(warnings), out)
