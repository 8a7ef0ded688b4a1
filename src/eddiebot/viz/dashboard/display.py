"""The display frame and what the dashboard's layer groups share.

Everything the browser draws is expressed in one *display frame*: ``map`` when TF links
``map`` to ``base_footprint``, else ``odom``. :class:`DisplayNode` holds the TF buffer, the
problems per topic, the receipt rates, the throttle and the layers that are re-placed when
the display frame changes or when TF for them arrives after their message did (grids,
plans, the lookahead point).
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.node import Node
from eddiebot.core.tf import Buffer, TransformException
from eddiebot.viz.dashboard.core import GridMeta, TileCache, text_frame
from eddiebot.viz.dashboard.hub import Hub
from eddiebot.viz.dashboard.topics import DashboardTopics

__all__ = ["GRID_LAYERS", "DisplayNode"]

#: layer name → topic (vslam_map: rtabmap's grid at its default ``map_topic``)
GRID_LAYERS = {"map": "/map", "global_costmap": "/global_costmap/costmap",
               "local_costmap": "/local_costmap/costmap", "vslam_map": "/rtabmap/map"}
_NS = 1_000_000_000


def _yaw(q: Any) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _compose(a: tuple[float, float, float], x: float, y: float, yaw: float) -> tuple[float, float, float]:
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * x - s * y, a[1] + s * x + c * y, math.remainder(a[2] + yaw, 2 * math.pi))


def _r(v: float, nd: int = 4) -> float:
    return round(float(v), nd) if math.isfinite(v) else 0.0


class _Rate:
    """Receipt times of one topic (wall ns) for a rate over the last two seconds."""

    __slots__ = ("last_ns", "times")

    def __init__(self) -> None:
        self.times: deque[int] = deque(maxlen=200)
        self.last_ns: int | None = None

    def tick(self, now_ns: int) -> None:
        self.times.append(now_ns)
        self.last_ns = now_ns

    def hz(self, now_ns: int) -> float:
        recent = [t for t in self.times if now_ns - t <= 2 * _NS]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) * _NS / max(1, recent[-1] - recent[0])


class DisplayNode(Node):
    """The dashboard node's shared state and plumbing; the layer groups build on it."""

    hub: Hub
    topics: DashboardTopics
    tf: Buffer
    display_frame: str
    _wall: Any
    _cmd_lock: threading.RLock
    _rates: dict[str, _Rate]
    _problems: dict[str, str]
    _tiles: dict[str, TileCache]
    _grid_meta: dict[str, GridMeta]
    _grid_placed: dict[str, tuple[str, tuple[float, float, float]] | None]
    _last_layer_ns: dict[str, int]
    #: latched-style layers (plans, lookahead): the newest message, re-placed when the
    #: display frame changes or when TF for it arrives after the message did
    _replay: dict[str, tuple[Callable[[Any], None], Any]]
    _unplaced: set[str]
    _twist_cls: Any
    _bool_cls: Any

    def _sub(self, cls: Any, topic: str, cb: Callable[[Any], None], qos: Any) -> None:
        def counted(m: Any, topic: str = topic) -> None:
            self._rates.setdefault(topic, _Rate()).tick(self._wall.now_ns())
            cb(m)

        try:
            self.create_subscription(cls, topic, counted, qos)
        except TopicTypeMismatchError as exc:
            self._problems[topic] = str(exc)
            self.get_logger().warning(f"dashboard cannot show {topic}: {exc}")

    def _to_display(self, frame: str) -> tuple[float, float, float] | None:
        """Pose of ``frame`` in the display frame at the latest time, or None."""
        frame = frame.lstrip("/") or self.display_frame
        if frame == self.display_frame:
            return (0.0, 0.0, 0.0)
        try:
            return self.tf.lookup_pose2d(self.display_frame, frame)
        except TransformException:
            return None

    def _choose_display_frame(self) -> None:
        base = self.topics.base_frame
        frame = "map" if self.tf.can_transform("map", base) else "odom"
        if frame != self.display_frame:
            self.display_frame = frame
            self._place_grids()
            self.hub.drop_prefix("path:")
            self.hub.drop_prefix("range:")
            self._unplaced.update(self._replay)

    def _replay_unplaced(self) -> None:
        for key in list(self._unplaced):
            handler, msg = self._replay[key]
            self._last_layer_ns.pop(key, None)
            handler(msg)

    def _throttled(self, key: str, period_ns: int) -> bool:
        """True when ``key`` was sent less than ``period_ns`` ago; else marks it sent now."""
        now = self._wall.now_ns()
        if now - self._last_layer_ns.get(key, -period_ns) < period_ns:
            return True
        self._last_layer_ns[key] = now
        return False

    def _post_grid_meta(self, layer: str) -> None:
        meta = self._grid_meta[layer]
        where = self._to_display(meta.frame_id)
        origin = None if where is None else _compose(where, *meta.origin)
        self._grid_placed[layer] = None if origin is None else (self.display_frame, origin)
        self.hub.post(f"grid:{layer}", text_frame(
            "grid", layer=layer, gen=self._tiles[layer].generation, w=meta.width, h=meta.height,
            res=meta.resolution, tile=self._tiles[layer].tile, frame=meta.frame_id,
            origin=None if origin is None else [_r(v, 5) for v in origin]))

    def _place_grids(self) -> None:
        """Re-send grid placements whose transform into the display frame moved."""
        for layer, meta in self._grid_meta.items():
            where = self._to_display(meta.frame_id)
            origin = None if where is None else _compose(where, *meta.origin)
            placed = self._grid_placed.get(layer)
            if origin is None and placed is None:
                continue
            if (placed is None or origin is None or placed[0] != self.display_frame
                    or max(abs(a - b) for a, b in zip(placed[1], origin, strict=True)) > 1e-3):
                self._post_grid_meta(layer)
