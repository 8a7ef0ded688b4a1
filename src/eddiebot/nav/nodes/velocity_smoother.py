"""nav2_velocity_smoother as a lifecycle node: ``cmd_vel`` → ``cmd_vel_smoothed``.

The algorithm is :class:`eddiebot.nav.velocity_smoother.VelocitySmoother` (Nav2's, step for
step); this node feeds it ``/cmd_vel_nav`` (remap ``cmd_vel``), odometry in CLOSED_LOOP,
and ticks it at ``smoothing_frequency`` on the node clock. Configure rejects what Nav2
rejects (naming the key) and warns when one smoothing period is longer than the base's
stale-command timeout (``stale_command_timeout``, 0.5 s for Eddie's board node).
"""

from __future__ import annotations

from typing import Any

from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.msgs.geometry_msgs import Twist
from eddiebot.nav.nodes._common import NavServer, twist_from_msg, twist_to_msg
from eddiebot.nav.params import from_params
from eddiebot.nav.types import Twist2D
from eddiebot.nav.velocity_smoother import (
    Feedback,
    VelocitySmoother,
    VelocitySmootherConfig,
    timing_warnings,
)

__all__ = ["VelocitySmootherNode"]


class VelocitySmootherNode(NavServer):
    default_node_name = "velocity_smoother"
    PARAMETERS = {
        "smoothing_frequency": 20.0, "feedback": "OPEN_LOOP", "scale_velocities": False,
        "max_velocity": [0.5, 0.0, 2.5], "min_velocity": [-0.5, 0.0, -2.5],
        "max_accel": [2.5, 0.0, 3.2], "max_decel": [-2.5, 0.0, -3.2],
        "deadband_velocity": [0.0, 0.0, 0.0], "velocity_timeout": 1.0, "odom_topic": "odom",
        "odom_duration": 0.1, "use_realtime_priority": False,
        "stamp_smoothed_velocity_with_smoothing_time": False, "enable_stamped_cmd_vel": False,
        # eddiebot: the base's stale-command timeout, for the configure-time warning
        "stale_command_timeout": 0.5,
    }

    def __init__(self, node_name: str = "velocity_smoother", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.smoother: VelocitySmoother | None = None
        self.warnings: list[str] = []
        self._pub: Any = None
        self._subs: list[Any] = []
        self._timer: Any = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            tree = self.params_tree()
            stale = float(tree.pop("stale_command_timeout"))
            cfg = from_params(VelocitySmootherConfig, tree, server=self.get_name())
            self.smoother = VelocitySmoother(cfg)
            self.warnings = timing_warnings(cfg, stale)
            for w in self.warnings:
                self.get_logger().warning(w)
            self._pub = self.create_lifecycle_publisher(Twist, "cmd_vel_smoothed", 1)
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav_msgs import Odometry

        assert self.smoother is not None
        cfg = self.smoother.config
        self.smoother.reset()
        self._subs = [self.create_subscription(Twist, "cmd_vel", self._on_cmd, 1)]
        if cfg.feedback == Feedback.CLOSED_LOOP:
            self._subs.append(self.create_subscription(Odometry, cfg.odom_topic, self._on_odom, 10))
        # Nav2: timer period int(1000 / f) ms; the step itself uses the nominal frequency.
        period_ms = int(1000.0 / cfg.smoothing_frequency)
        self._timer = self.create_timer(period_ms / 1000.0, self._tick)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        for s in self._subs:
            self.destroy_subscription(s)
        self._subs, self._timer = [], None
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        if self._pub is not None:
            self.destroy_lifecycle_publisher(self._pub)
        self._pub, self.smoother = None, None
        return TransitionCallbackReturn.SUCCESS

    def _on_cmd(self, msg: Any) -> None:
        assert self.smoother is not None
        if not self.smoother.set_command(twist_from_msg(msg), self.now().nanoseconds):
            self.get_logger().error("velocity command with NaN or Inf ignored")

    def _on_odom(self, msg: Any) -> None:
        assert self.smoother is not None
        t = msg.twist.twist
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.smoother.set_odometry(Twist2D(t.linear.x, t.linear.y, t.angular.z), stamp)

    def _tick(self) -> None:
        if self.smoother is None:
            return
        out = self.smoother.tick(self.now().nanoseconds)
        if out is not None:
            self._pub.publish(twist_to_msg(out))
