"""nav2_smoother: ``smooth_path`` (nav2_msgs/SmoothPath) with ``smoother_plugins``.

Plugins: ``nav2_smoother::SimpleSmoother`` and ``nav2_smoother::SavitzkyGolaySmoother``.
Collision checks (SimpleSmoother) use the latest
``/global_costmap/costmap_raw`` when ``check_for_collisions`` is set.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from eddiebot.core.action import ActionServer, CancelResponse, ServerGoalHandle
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.time import Duration
from eddiebot.nav.costmap import Costmap2D
from eddiebot.nav.errors import (
    FailedToSmoothPath,
    InvalidSmoother,
    NavError,
    SmootherError,
    SmootherTimedOut,
)
from eddiebot.nav.nodes._common import NavServer, path_from_msg, path_to_msg
from eddiebot.nav.smoother import Smoother, build_smoother

__all__ = ["SmootherServer", "costmap_from_raw"]


def costmap_from_raw(msg: Any) -> Costmap2D:
    """A :class:`Costmap2D` from nav2_msgs/Costmap (raw 0..255 costs)."""
    md = msg.metadata
    cm = Costmap2D(int(md.size_x), int(md.size_y), float(md.resolution),
                   float(md.origin.position.x), float(md.origin.position.y), 0)
    cm.data[:, :] = np.asarray(msg.data, dtype=np.uint8).reshape(int(md.size_y), int(md.size_x))
    return cm


class SmootherServer(NavServer):
    default_node_name = "smoother_server"
    PARAMETERS = {"smoother_plugins": ["simple_smoother"], "costmap_topic": "global_costmap/costmap_raw",
                  "footprint_topic": "global_costmap/published_footprint",
                  "robot_base_frame": "base_link", "transform_tolerance": 0.1}

    def __init__(self, node_name: str = "smoother_server", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.smoothers: dict[str, Smoother] = {}
        self._costmap: Costmap2D | None = None
        self._action: ActionServer | None = None
        self._sub: Any = None
        self._plan_pub: Any = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            from eddiebot.msgs.nav_msgs import Path

            tree = self.params_tree()
            self.smoothers = {}
            for name in [n for n in tree.get("smoother_plugins", []) if n]:
                self.smoothers[name] = build_smoother(name, dict(tree.get(name) or {}),
                                                      self.get_name())
            self._plan_pub = self.create_lifecycle_publisher(Path, "plan_smoothed", 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import Costmap, SmoothPath

        self._sub = self.create_subscription(Costmap, str(self.param("costmap_topic")),
                                             self._on_costmap, 1)
        self._action = ActionServer(self, SmoothPath, "smooth_path", self._smooth,
                                    cancel_callback=lambda _h: CancelResponse.ACCEPT)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._action is not None:
            self._action.destroy()
        if self._sub is not None:
            self.destroy_subscription(self._sub)
        self._action = self._sub = None
        return TransitionCallbackReturn.SUCCESS

    def _on_costmap(self, msg: Any) -> None:
        self._costmap = costmap_from_raw(msg)

    def _smooth(self, handle: ServerGoalHandle) -> Any:
        from eddiebot.msgs.nav2_msgs import SmoothPath

        goal = handle.request
        result = SmoothPath.Result()
        t0 = self.now().nanoseconds
        try:
            sid = goal.smoother_id or (next(iter(self.smoothers)) if len(self.smoothers) == 1 else "")
            if sid not in self.smoothers:
                raise InvalidSmoother(f"smoother {sid!r} not loaded; have {sorted(self.smoothers)}")
            out = self.smoothers[sid].smooth(path_from_msg(goal.path),
                                             self._costmap if goal.check_for_collisions else None)
            took = self.now().nanoseconds - t0
            limit = Duration.from_msg(goal.max_smoothing_duration).nanoseconds
            if limit > 0 and took > limit:
                raise SmootherTimedOut("smoothing took longer than max_smoothing_duration")
            if not out.converged and goal.check_for_collisions:
                raise FailedToSmoothPath("smoothing stopped (collision or iteration limit)")
        except NavError as err:
            result.error_code = int(err.result_code or SmootherError.result_code)
            result.error_msg = str(err)
            handle.abort()
            return result
        frame = goal.path.header.frame_id
        result.path = path_to_msg(out.path, frame, self.now().nanoseconds)
        result.was_completed = bool(out.converged)
        result.smoothing_duration = Duration(self.now().nanoseconds - t0).to_msg()
        self._plan_pub.publish(result.path)
        handle.succeed()
        return result
