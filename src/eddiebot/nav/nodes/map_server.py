"""nav2_map_server: ``map_server`` publishes a map file, ``map_saver`` writes ``/map`` to one.

``MapServer`` (Nav2 parameters ``yaml_filename``, ``topic_name`` "map", ``frame_id`` "map")
loads the map at configure (a missing or malformed file fails the transition, naming the
file), publishes it transient-local on activate and serves ``~/load_map``
(nav2_msgs/LoadMap). ``MapSaver`` serves ``~/save_map`` (nav2_msgs/SaveMap): it takes the
latest (transient-local) map on ``map_topic`` and writes ``.pgm``/``.png`` + ``.yaml``
atomically with :func:`eddiebot.maps.save_map`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import DurabilityPolicy, QoSProfile
from eddiebot.maps import (
    DEFAULT_FREE_THRESH,
    DEFAULT_OCCUPIED_THRESH,
    OccupancyMap,
    load_map,
    map_from_msg,
    map_to_msg,
    save_map,
)
from eddiebot.nav.errors import ParameterError
from eddiebot.nav.nodes._common import NavServer

__all__ = ["MAP_QOS", "MapSaver", "MapServer"]

MAP_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class MapServer(NavServer):
    default_node_name = "map_server"
    PARAMETERS = {"yaml_filename": "", "topic_name": "map", "frame_id": "map"}

    def __init__(self, node_name: str = "map_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        from eddiebot.msgs.nav2_msgs import LoadMap

        self.map: OccupancyMap | None = None
        self._pub: Any = None
        self.create_service(LoadMap, "~/load_map", self._on_load_map)

    def _load(self, path: str) -> OccupancyMap:
        if not path:
            raise ParameterError(self.get_name(), "yaml_filename", path, "no map file given")
        try:
            return load_map(path)
        except (OSError, ValueError) as exc:
            raise ParameterError(self.get_name(), "yaml_filename", path, str(exc)) from exc

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.nav_msgs import OccupancyGrid

            self.map = self._load(str(self.param("yaml_filename")))
            self._pub = self.create_lifecycle_publisher(OccupancyGrid, str(self.param("topic_name")),
                                                        MAP_QOS)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        self._pub.on_activate()
        self._publish()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self._pub is not None:
            self.destroy_lifecycle_publisher(self._pub)
        self._pub = None
        self.map = None
        return TransitionCallbackReturn.SUCCESS

    def _publish(self) -> None:
        if self.map is not None and self._pub is not None:
            self._pub.publish(map_to_msg(self.map, frame_id=str(self.param("frame_id")),
                                         stamp_ns=self.now().nanoseconds))

    def _on_load_map(self, request: Any, response: Any) -> Any:
        codes = type(response)
        if self._state_label() != "active":
            response.result = codes.RESULT_UNDEFINED_FAILURE
            return response
        if not Path(request.map_url).is_file():
            response.result = codes.RESULT_MAP_DOES_NOT_EXIST
            return response
        try:
            self.map = load_map(request.map_url)
        except (OSError, ValueError) as exc:
            self.get_logger().error(f"load_map {request.map_url}: {exc}")
            response.result = codes.RESULT_INVALID_MAP_DATA
            return response
        self._publish()
        response.map = map_to_msg(self.map, frame_id=str(self.param("frame_id")),
                                  stamp_ns=self.now().nanoseconds)
        response.result = codes.RESULT_SUCCESS
        return response

    def _state_label(self) -> str:
        return self.current_state.label


class MapSaver(NavServer):
    default_node_name = "map_saver"
    # eddiebot.maps' thresholds (free 0.196: unknown grey 205 reloads as unknown, as Nav2
    # saves since navigation2 #5278) for requests that leave them 0 (the dashboard's button)
    PARAMETERS = {"save_map_timeout": 2.0, "free_thresh_default": DEFAULT_FREE_THRESH,
                  "occupied_thresh_default": DEFAULT_OCCUPIED_THRESH,
                  "map_subscribe_transient_local": True}

    def __init__(self, node_name: str = "map_saver", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._srv: Any = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            free = float(self.param("free_thresh_default"))
            occ = float(self.param("occupied_thresh_default"))
            if not 0.0 <= free <= occ <= 1.0:
                raise ParameterError(self.get_name(), "free_thresh_default", free,
                                     f"must satisfy 0 <= free <= occupied ({occ}) <= 1")
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import SaveMap

        self._srv = self.create_service(SaveMap, "~/save_map", self._on_save_map)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._srv is not None:
            self.destroy_service(self._srv)
        self._srv = None
        return TransitionCallbackReturn.SUCCESS

    def _on_save_map(self, request: Any, response: Any) -> Any:
        from eddiebot.msgs.nav_msgs import OccupancyGrid

        topic = request.map_topic or "map"
        got: list[Any] = []
        qos = MAP_QOS if self.param("map_subscribe_transient_local") else QoSProfile(depth=1)
        # Transient-local: the last map is handed over as the subscription is made.
        sub = self.create_subscription(OccupancyGrid, topic, got.append, qos)
        try:
            while (msg := sub.take()) is not None:
                got.append(msg)
        finally:
            self.destroy_subscription(sub)
        if not got:
            self.get_logger().error(f"save_map: no map on {topic!r}")
            response.result = False
            return response
        free = request.free_thresh or float(self.param("free_thresh_default"))
        occ = request.occupied_thresh or float(self.param("occupied_thresh_default"))
        url = request.map_url or "map"
        try:
            path = save_map(map_from_msg(got[-1]), url, mode=request.map_mode or "trinary",
                            image_format=request.image_format or "pgm",
                            occupied_thresh=occ, free_thresh=free)
        except (OSError, ValueError) as exc:
            self.get_logger().error(f"save_map {url}: {exc}")
            response.result = False
            return response
        self.get_logger().info(f"map saved to {path}")
        response.result = True
        return response
