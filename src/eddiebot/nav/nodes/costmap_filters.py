"""Costmap filters on the bus: Nav2's filter mask server, costmap filter info server, the
filters' topics inside a costmap, and the bring-up of the servers from a parameters file.

- :class:`FilterMaskServer` is ``nav2_map_server``'s map server run for a mask
  (``yaml_filename``, ``topic_name``, ``frame_id``): the mask goes out transient-local on
  ``topic_name`` (default ``filter_mask``, the info server's default ``mask_topic``).
- :class:`CostmapFilterInfoServer` (``nav2_map_server/costmap_filter_info_server``) publishes
  one ``nav2_msgs/CostmapFilterInfo`` transient-local on ``filter_info_topic``: ``type`` 0
  keepout, 1 speed limit in %, 2 speed limit in m/s, 3 binary; ``mask_topic``, ``base``,
  ``multiplier``.
- :class:`FilterHost` does for a costmap's filters what Nav2's ``CostmapFilter`` plugins do
  on their node: subscribe to ``filter_info_topic``, then to the info's mask topic, hand each
  filter the costmap-frame -> mask-frame transform before an update, and publish
  ``nav2_msgs/SpeedLimit`` on ``speed_limit_topic`` (the controller server takes it) and
  ``std_msgs/Bool`` on ``binary_state_topic`` after it. Each filter is switched on and off
  at run time by ``std_srvs/SetBool`` on ``/<costmap>/<filter>/toggle_filter`` (Nav2's
  ``<filter name>/toggle_filter`` in the costmap node's namespace, e.g.
  ``/global_costmap/keepout_filter/toggle_filter``); the costmap is updated at once.
- :func:`filter_server_sections` finds the servers a parameters file asks for (sections
  named ``*filter_mask_server`` with a ``yaml_filename`` and the ``*costmap_filter_info_server``
  sections pointing at their topics); :func:`add_filter_masks` adds a keepout or speed mask
  to a folded parameters document as ``eddie nav --keepout`` / ``--speed-mask`` do;
  :func:`check_mask` refuses a mask that cannot be used, naming the file; and
  :func:`build_filter_servers` makes the nodes and their lifecycle manager.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.core.tf import Buffer, TransformException
from eddiebot.maps import MapError, OccupancyMap, load_map, map_from_msg
from eddiebot.nav.costmap import LayeredCostmap
from eddiebot.nav.costmap.filters import (
    BASE_DEFAULT,
    BINARY_FILTER,
    KEEPOUT_FILTER,
    MULTIPLIER_DEFAULT,
    SPEED_FILTER_ABSOLUTE,
    SPEED_FILTER_PERCENT,
    BinaryFilter,
    CostmapFilter,
    CostmapFilterInfo,
    KeepoutFilter,
    SpeedFilter,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import NavServer
from eddiebot.nav.nodes.map_server import MapServer

__all__ = [
    "FILTER_QOS",
    "CostmapFilterInfoServer",
    "FilterHost",
    "FilterMaskServer",
    "MaskError",
    "add_filter_masks",
    "build_filter_servers",
    "check_mask",
    "filter_server_sections",
    "is_filter_info_server",
    "is_filter_mask_server",
]

#: what the info server publishes and the filters subscribe with (Nav2: depth 1, reliable,
#: transient-local): a filter brought up later still gets the info and the mask
FILTER_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)

_TYPES = {KEEPOUT_FILTER: "keepout", SPEED_FILTER_PERCENT: "speed limit in %",
          SPEED_FILTER_ABSOLUTE: "speed limit in m/s", BINARY_FILTER: "binary"}


def is_filter_mask_server(section: str) -> bool:
    """Whether a parameters-file section is a filter mask server (Nav2's sample files name
    them ``filter_mask_server``, ``keepout_filter_mask_server``, ``speed_filter_mask_server``)."""
    return section.strip("/").endswith("filter_mask_server")


def is_filter_info_server(section: str) -> bool:
    """Whether a section is a costmap filter info server (``costmap_filter_info_server``,
    ``keepout_costmap_filter_info_server``, ...)."""
    return section.strip("/").endswith("costmap_filter_info_server")


# --- servers ---------------------------------------------------------------------------------
class FilterMaskServer(MapServer):
    """The map server for a filter mask."""

    default_node_name = "filter_mask_server"
    PARAMETERS = {"yaml_filename": "", "topic_name": "filter_mask", "frame_id": "map"}

    def __init__(self, node_name: str = "filter_mask_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)


class CostmapFilterInfoServer(NavServer):
    """``nav2_map_server::CostmapFilterInfoServer``."""

    default_node_name = "costmap_filter_info_server"
    PARAMETERS = {"filter_info_topic": "costmap_filter_info", "type": 0,
                  "mask_topic": "filter_mask", "base": BASE_DEFAULT,
                  "multiplier": MULTIPLIER_DEFAULT}

    def __init__(self, node_name: str = "costmap_filter_info_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._pub: Any = None
        self.info: CostmapFilterInfo | None = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.nav2_msgs import CostmapFilterInfo as InfoMsg

            kind = self.param("type")
            if isinstance(kind, bool) or not isinstance(kind, int) or kind not in _TYPES:
                raise ParameterError(self.get_name(), "type", kind, "must be one of " + ", ".join(
                    f"{k} ({v})" for k, v in _TYPES.items()))
            for key in ("base", "multiplier"):
                value = self.param(key)
                if isinstance(value, bool) or not isinstance(value, (int, float)) \
                        or not math.isfinite(float(value)):
                    raise ParameterError(self.get_name(), key, value, "must be a finite number")
            if not str(self.param("mask_topic")):
                raise ParameterError(self.get_name(), "mask_topic", "", "must name the mask topic")
            self.info = CostmapFilterInfo(int(kind), float(self.param("base")),
                                          float(self.param("multiplier")),
                                          str(self.param("mask_topic")))
            self._pub = self.create_lifecycle_publisher(
                InfoMsg, str(self.param("filter_info_topic")), FILTER_QOS)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import CostmapFilterInfo as InfoMsg
        from eddiebot.msgs.std_msgs import Header

        assert self.info is not None
        self._pub.on_activate()
        self._pub.publish(InfoMsg(
            header=Header(stamp=self.now().to_msg(), frame_id=""), type=self.info.type,
            filter_mask_topic=self.info.filter_mask_topic, base=self.info.base,
            multiplier=self.info.multiplier))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._pub is not None:
            self._pub.on_deactivate()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self._pub is not None:
            self.destroy_lifecycle_publisher(self._pub)
        self._pub = None
        self.info = None
        return TransitionCallbackReturn.SUCCESS


# --- the filters of one costmap ---------------------------------------------------------------
class FilterHost:
    """The bus side of ``costmap``'s filters, run by its costmap host on ``node``."""

    def __init__(self, node: Any, costmap: LayeredCostmap, buffer: Buffer,
                 on_mask: Callable[[], None] | None = None) -> None:
        self.node = node
        self.costmap = costmap
        self.buffer = buffer
        self.on_mask = on_mask
        self.filters = [f for f in costmap.filters if isinstance(f, CostmapFilter)]
        self._info_subs: dict[str, Any] = {}
        self._mask_subs: dict[str, Any] = {}
        self._mask_frames: dict[str, str] = {}
        self._pubs: dict[str, Any] = {}
        self._services: list[Any] = []
        self._tf_failed: set[str] = set()
        self._tf_seen: set[str] = set()

    @property
    def global_frame(self) -> str:
        return self.costmap.config.global_frame

    def activate(self) -> None:
        from eddiebot.msgs.nav2_msgs import CostmapFilterInfo as InfoMsg
        from eddiebot.msgs.nav2_msgs import SpeedLimit
        from eddiebot.msgs.std_msgs import Bool
        from eddiebot.msgs.std_srvs import SetBool

        for f in self.filters:
            self._services.append(self.node.create_service(
                SetBool, self.toggle_service(f.name), self._toggle_cb(f)))
            topic = f.config.filter_info_topic
            if not topic:
                self.node.get_logger().warning(
                    f"{type(f).__name__} {f.name}: no filter_info_topic: it gets no mask")
                continue
            self._info_subs[f.name] = self.node.create_subscription(
                InfoMsg, topic, self._info_cb(f), FILTER_QOS)
            if isinstance(f, SpeedFilter):
                self._pubs[f.name] = self.node.create_publisher(
                    SpeedLimit, f.config.speed_limit_topic, 10)
            elif isinstance(f, BinaryFilter):
                self._pubs[f.name] = self.node.create_publisher(
                    Bool, f.config.binary_state_topic, 10)
        self.publish_changes()  # the binary filters' initial state

    def deactivate(self) -> None:
        for sub in (*self._info_subs.values(), *self._mask_subs.values()):
            self.node.destroy_subscription(sub)
        for pub in self._pubs.values():
            self.node.destroy_publisher(pub)
        for srv in self._services:
            self.node.destroy_service(srv)
        self._info_subs, self._mask_subs, self._pubs, self._services = {}, {}, {}, []

    def toggle_service(self, filter_name: str) -> str:
        """The ``toggle_filter`` service of the filter named ``filter_name``."""
        return f"/{self.costmap.name}/{filter_name}/toggle_filter"

    def _toggle_cb(self, f: CostmapFilter) -> Callable[[Any, Any], Any]:
        def callback(request: Any, response: Any) -> Any:
            response.message = f.set_enabled(bool(request.data))
            response.success = True
            self.node.get_logger().info(f"{type(f).__name__} {f.name}: {response.message}")
            if self.on_mask is not None:  # the costmap shows the switch without waiting
                self.on_mask()
            return response
        return callback

    def _info_cb(self, f: CostmapFilter) -> Callable[[Any], None]:
        from eddiebot.msgs.nav_msgs import OccupancyGrid

        def callback(msg: Any) -> None:
            log = self.node.get_logger()
            info = CostmapFilterInfo(int(msg.type), float(msg.base), float(msg.multiplier),
                                     str(msg.filter_mask_topic))
            problem = f.set_filter_info(info)
            if problem and not isinstance(f, KeepoutFilter):
                log.error(problem)
                return
            if problem:
                log.warning(problem)
            old = self._mask_subs.pop(f.name, None)
            if old is not None:
                log.warning(f"{type(f).__name__} {f.name}: new filter info: mask from "
                            f"{info.filter_mask_topic}")
                self.node.destroy_subscription(old)
            self._mask_subs[f.name] = self.node.create_subscription(
                OccupancyGrid, info.filter_mask_topic, self._mask_cb(f), FILTER_QOS)
        return callback

    def _mask_cb(self, f: CostmapFilter) -> Callable[[Any], None]:
        def callback(msg: Any) -> None:
            self._mask_frames[f.name] = str(msg.header.frame_id)
            f.set_mask(map_from_msg(msg))
            self.node.get_logger().info(
                f"{type(f).__name__} {f.name}: mask {msg.info.width}x{msg.info.height} at "
                f"{float(msg.info.resolution):g} m in frame {msg.header.frame_id or '?'}")
            if self.on_mask is not None:
                self.on_mask()
        return callback

    def before_update(self) -> None:
        """Hand each filter the transform of the costmap's frame into its mask's frame."""
        for f in self.filters:
            frame = self._mask_frames.get(f.name, "")
            if f.mask is None or frame in ("", self.global_frame):
                f.set_mask_transform(None)
                continue
            try:
                f.set_mask_transform(self.buffer.lookup_pose2d(frame, self.global_frame, 0))
                self._tf_failed.discard(f.name)
                self._tf_seen.add(f.name)
            except TransformException as exc:
                f.set_mask_transform(None, ok=False)
                if f.name not in self._tf_failed:  # once per outage
                    self._tf_failed.add(f.name)
                    what = (f"{type(f).__name__} {f.name}: no transform from the costmap frame "
                            f"{self.global_frame} to the mask frame {frame}")
                    if f.name in self._tf_seen:
                        self.node.get_logger().error(f"{what}: {exc}")
                    else:  # localization has not placed the map yet
                        self.node.get_logger().info(f"{what} yet: waiting for it")

    def publish_changes(self) -> None:
        """Publish the speed limits and binary states the last update changed."""
        from eddiebot.msgs.nav2_msgs import SpeedLimit
        from eddiebot.msgs.std_msgs import Bool, Header

        for f in self.filters:
            pub = self._pubs.get(f.name)
            if isinstance(f, SpeedFilter) and f.pending is not None:
                limit, f.pending = f.pending, None
                if pub is not None:
                    pub.publish(SpeedLimit(
                        header=Header(stamp=self.node.now().to_msg(), frame_id=self.global_frame),
                        percentage=bool(limit.percentage), speed_limit=float(limit.speed_limit)))
            elif isinstance(f, BinaryFilter) and f.pending:
                states, f.pending = f.pending, []
                if pub is not None:
                    for state in states:
                        pub.publish(Bool(data=bool(state)))


# --- bring-up from a parameters file ---------------------------------------------------------
class MaskError(ValueError):
    """A filter mask that cannot be used; the message names the file."""


@dataclass(frozen=True)
class FilterServerSection:
    """One filter server a parameters document asks for."""

    node_name: str
    server: type[NavServer]
    params: dict[str, Any]


def _params(doc: Mapping[str, Any], section: str) -> dict[str, Any]:
    body = doc.get(section)
    params = body.get("ros__parameters") if isinstance(body, dict) else None
    return dict(params) if isinstance(params, dict) else {}


def _topic(name: Any) -> str:
    return "/" + str(name).strip("/")


def filter_server_sections(doc: Mapping[str, Any], base_dir: Path | None = None
                           ) -> list[FilterServerSection]:
    """The filter servers ``doc`` asks for: each ``*filter_mask_server`` section with a
    ``yaml_filename`` (a relative one is taken from ``base_dir``), and each
    ``*costmap_filter_info_server`` whose ``mask_topic`` one of those publishes."""
    out: list[FilterServerSection] = []
    mask_topics: set[str] = set()
    for section in doc:
        if not is_filter_mask_server(str(section)):
            continue
        params = _params(doc, section)
        filename = str(params.get("yaml_filename") or "")
        if not filename:
            continue
        path = Path(filename).expanduser()
        if not path.is_absolute() and base_dir is not None and (base_dir / path).exists():
            path = base_dir / path
        params["yaml_filename"] = str(path)
        mask_topics.add(_topic(params.get("topic_name", FilterMaskServer.PARAMETERS["topic_name"])))
        out.append(FilterServerSection(str(section).strip("/"), FilterMaskServer, params))
    for section in doc:
        if not is_filter_info_server(str(section)):
            continue
        params = _params(doc, section)
        topic = _topic(params.get("mask_topic", CostmapFilterInfoServer.PARAMETERS["mask_topic"]))
        if topic in mask_topics:
            out.append(FilterServerSection(str(section).strip("/"), CostmapFilterInfoServer, params))
    return out


def build_filter_servers(sections: list[FilterServerSection], context: Any, *,
                         use_sim_time: bool = True, autostart: bool = True) -> list[Any]:
    """The nodes of ``sections`` and ``lifecycle_manager_costmap_filters`` bringing them up
    (as Nav2's costmap filter launch does); no nodes when there are no sections."""
    from eddiebot.core.lifecycle import LifecycleManager
    from eddiebot.nav.nodes._common import flatten_params

    if not sections:
        return []
    nodes: list[Any] = []
    for s in sections:
        overrides = flatten_params({**s.params, "use_sim_time": use_sim_time})
        nodes.append(s.server(s.node_name, context=context, parameter_overrides=overrides))
    nodes.append(LifecycleManager("lifecycle_manager_costmap_filters", context=context,
                                  parameter_overrides={
                                      "node_names": [s.node_name for s in sections],
                                      "autostart": autostart, "use_sim_time": use_sim_time}))
    return nodes


def _costmap(doc: dict[str, Any], server: str, name: str) -> dict[str, Any] | None:
    params = doc.get(server, {}).get("ros__parameters") if isinstance(doc.get(server), dict) else None
    if not isinstance(params, dict):
        return None
    cm = params.get(name)
    return cm if isinstance(cm, dict) else None


def _add_filter(costmap: dict[str, Any], plugin: str, default_name: str, info_topic: str) -> None:
    """Enable the costmap's filter of type ``plugin`` (or add ``default_name``) and point it
    at ``info_topic``."""
    filters = costmap.get("filters", [])
    names = filters.split() if isinstance(filters, str) else [str(f) for f in filters]
    for name in names:
        sub = costmap.get(name)
        if isinstance(sub, dict) and sub.get("plugin") == plugin:
            sub["enabled"] = True
            sub["filter_info_topic"] = info_topic
            return
    names.append(default_name)
    costmap["filters"] = names
    costmap[default_name] = {"plugin": plugin, "enabled": True, "filter_info_topic": info_topic}


_KINDS = {
    # kind: (plugin, filter name, info type, base, multiplier, costmaps)
    "keepout": ("nav2_costmap_2d::KeepoutFilter", "keepout_filter", KEEPOUT_FILTER, 0.0, 1.0,
                (("planner_server", "global_costmap"), ("controller_server", "local_costmap"))),
    "speed": ("nav2_costmap_2d::SpeedFilter", "speed_filter", SPEED_FILTER_PERCENT, 100.0, -1.0,
              (("planner_server", "global_costmap"),)),
}


def add_filter_masks(doc: dict[str, Any], *, keepout: Path | None = None,
                     speed: Path | None = None) -> None:
    """Add a keepout and/or speed mask to a folded parameters document, in place.

    Each mask gets a ``<kind>_filter_mask_server`` (topic ``/<kind>_filter_mask``) and a
    ``<kind>_costmap_filter_info_server``, and the filter is enabled in the costmaps (keepout:
    global and local, as Nav2's tutorial; speed: global). Sections the document already has
    keep their values (a speed zone's ``type``, ``base``, ``multiplier``), the mask file aside.
    """
    for kind, path in (("keepout", keepout), ("speed", speed)):
        if path is None:
            continue
        plugin, fname, kind_type, base, multiplier, costmaps = _KINDS[kind]
        mask_sec, info_sec = f"{kind}_filter_mask_server", f"{kind}_costmap_filter_info_server"
        mask = doc.setdefault(mask_sec, {}).setdefault("ros__parameters", {})
        mask["yaml_filename"] = str(Path(path).resolve())
        mask.setdefault("topic_name", f"/{kind}_filter_mask")
        mask.setdefault("frame_id", "map")
        info = doc.setdefault(info_sec, {}).setdefault("ros__parameters", {})
        for key, value in (("type", kind_type), ("filter_info_topic", f"/{kind}_costmap_filter_info"),
                           ("base", base), ("multiplier", multiplier)):
            info.setdefault(key, value)
        info["mask_topic"] = mask["topic_name"]
        for server, name in costmaps:
            cm = _costmap(doc, server, name)
            if cm is not None:
                _add_filter(cm, plugin, fname, str(info["filter_info_topic"]))


def _frames(doc: Mapping[str, Any]) -> dict[str, str]:
    out = {}
    for server, name, default in (("planner_server", "global_costmap", "map"),
                                  ("controller_server", "local_costmap", "odom")):
        cm = _costmap(dict(doc), server, name) or {}
        out[name] = str(cm.get("global_frame", default))
    return out


def check_mask(section: FilterServerSection, doc: Mapping[str, Any],
               nav_map: OccupancyMap | None = None) -> OccupancyMap:
    """Load a mask server's mask and refuse one that cannot be used, with one message naming
    the file: it does not load; its ``frame_id`` is neither costmap's frame (no transform
    would place it); it does not overlap the navigation map ``nav_map`` (drawn for another
    map or frame); or, for a keepout mask, its cells are finer than the global costmap's
    (the costmap samples one mask point per cell: a thin wall drawn in it would leak)."""
    path = Path(str(section.params.get("yaml_filename", "")))
    try:
        mask = load_map(path)
    except (MapError, OSError, ValueError) as exc:
        raise MaskError(f"{path}: filter mask does not load: {exc}") from exc
    frame = str(section.params.get("frame_id", FilterMaskServer.PARAMETERS["frame_id"]))
    frames = _frames(doc)
    if frame not in frames.values():
        raise MaskError(f"{path}: {section.node_name}.frame_id {frame!r} is neither the global "
                        f"costmap's frame {frames['global_costmap']!r} nor the local costmap's "
                        f"{frames['local_costmap']!r}: no transform places the mask")
    if nav_map is not None and frame == frames["global_costmap"]:
        ax0, ay0, ax1, ay1 = _extent(mask)
        bx0, by0, bx1, by1 = _extent(nav_map)
        if ax1 <= bx0 or bx1 <= ax0 or ay1 <= by0 or by1 <= ay0:
            raise MaskError(
                f"{path}: the mask (x {ax0:.2f}..{ax1:.2f}, y {ay0:.2f}..{ay1:.2f} m) does not "
                f"overlap the map (x {bx0:.2f}..{bx1:.2f}, y {by0:.2f}..{by1:.2f} m): was it "
                "drawn for another map or frame?")
    topic = _topic(section.params.get("topic_name", FilterMaskServer.PARAMETERS["topic_name"]))
    if _is_keepout_mask(doc, topic):
        cm = _costmap(dict(doc), "planner_server", "global_costmap") or {}
        res = float(cm.get("resolution", 0.1))
        if mask.resolution < res - 1e-9:
            raise MaskError(
                f"{path}: keepout mask resolution {mask.resolution:g} m is finer than the global "
                f"costmap's {res:g} m: the costmap reads one mask point per cell and would miss "
                f"thin zones; save the mask at {res:g} m or coarser")
    return mask


def _extent(grid: OccupancyMap) -> tuple[float, float, float, float]:
    w, h = grid.width * grid.resolution, grid.height * grid.resolution
    c, s = math.cos(grid.origin[2]), math.sin(grid.origin[2])
    xs = [grid.origin[0] + c * u - s * v for u, v in ((0, 0), (w, 0), (0, h), (w, h))]
    ys = [grid.origin[1] + s * u + c * v for u, v in ((0, 0), (w, 0), (0, h), (w, h))]
    return min(xs), min(ys), max(xs), max(ys)


def _is_keepout_mask(doc: Mapping[str, Any], mask_topic: str) -> bool:
    for section in doc:
        if is_filter_info_server(str(section)):
            p = _params(doc, section)
            if _topic(p.get("mask_topic", "filter_mask")) == mask_topic \
                    and int(p.get("type", 0)) == KEEPOUT_FILTER:
                return True
    return False
