"""nav2_waypoint_follower: ``follow_waypoints`` (nav2_msgs/FollowWaypoints).

Each waypoint is sent to ``navigate_to_pose`` in turn; on arrival the task executor plugin
(``waypoint_task_executor_plugin``) runs: ``nav2_waypoint_follower::WaitAtWaypoint``
(``waypoint_pause_duration`` ms) or ``nav2_waypoint_follower::PhotoAtWaypoint``, which saves
the latest image of ``camera_image_topic_name`` as ``<save_images_dir>/<index>_<stamp>.png``
(written to a temporary file, then renamed), or ``nav2_waypoint_follower::InputAtWaypoint``,
which waits for a ``std_msgs/Empty`` on ``input_topic`` (``input_at_waypoint/input``) for up to
``timeout`` whole seconds (10; upstream builds the duration from the integer part) and fails
the waypoint's task when none comes. ``stop_on_failure`` (true) ends the run at the first
missed waypoint; otherwise missed ones are listed in the result.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.action import ActionClient, ActionServer, CancelResponse, ServerGoalHandle, sleep
from eddiebot.core.lifecycle import State, TransitionCallbackReturn
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.nav.errors import ParameterError, UnsupportedPlugin
from eddiebot.nav.nodes._common import NavServer, pose_is_finite

__all__ = ["TASK_EXECUTOR_KEYS", "WaypointFollower", "image_to_bgr", "write_png_atomic"]

#: task executor plugins and the keys each one reads (besides ``plugin`` and ``enabled``)
TASK_EXECUTOR_KEYS: dict[str, frozenset[str]] = {
    "nav2_waypoint_follower::WaitAtWaypoint": frozenset({"waypoint_pause_duration"}),
    "nav2_waypoint_follower::PhotoAtWaypoint": frozenset(
        {"camera_image_topic_name", "save_images_dir", "image_format"}),
    "nav2_waypoint_follower::InputAtWaypoint": frozenset({"timeout", "input_topic"}),
}
_TASKS = tuple(TASK_EXECUTOR_KEYS)
#: FollowWaypoints' NO_VALID_WAYPOINTS (Kilted's code; Jazzy's message ends at 601)
NO_VALID_WAYPOINTS = 602


def image_to_bgr(msg: Any) -> np.ndarray:
    """sensor_msgs/Image (rgb8, bgr8, mono8, rgba8, bgra8) → an (H, W, 3|1) uint8 array for
    OpenCV."""
    import cv2

    h, w = int(msg.height), int(msg.width)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    enc = str(msg.encoding).lower()
    channels = {"rgb8": 3, "bgr8": 3, "mono8": 1, "rgba8": 4, "bgra8": 4}.get(enc)
    if channels is None:
        raise ValueError(f"unsupported image encoding {msg.encoding!r}")
    step = int(msg.step) or w * channels
    img = data.reshape(h, step)[:, : w * channels].reshape(h, w, channels)
    if enc == "rgb8":
        return cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    if enc == "rgba8":
        return cv2.cvtColor(img, cv2.COLOR_RGBA2BGR)
    if enc == "bgra8":
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img.copy()


def write_png_atomic(path: Path, image: np.ndarray) -> Path:
    import cv2

    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"cannot encode {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(buf.tobytes())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


class WaypointFollower(NavServer):
    default_node_name = "waypoint_follower"
    PARAMETERS = {
        "stop_on_failure": True, "loop_rate": 20, "global_frame_id": "map",
        "waypoint_task_executor_plugin": "wait_at_waypoint",
    }

    def __init__(self, node_name: str = "waypoint_follower", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self._task: dict[str, Any] = {}
        self._action: ActionServer | None = None
        self._nav: ActionClient | None = None
        self._image_sub: Any = None
        self._image: Any = None
        self.saved: list[Path] = []
        self._input_sub: Any = None
        self._input_received = False
        #: index of the waypoint whose InputAtWaypoint task is waiting for input, else None
        self.waiting_at: int | None = None

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def build() -> None:
            tree = self.params_tree()
            name = str(tree.get("waypoint_task_executor_plugin", "wait_at_waypoint"))
            sub = dict(tree.get(name) or {})
            default = "nav2_waypoint_follower::WaitAtWaypoint" if name == "wait_at_waypoint" else ""
            plugin = str(sub.get("plugin", default)).replace("/", "::")
            if plugin not in _TASKS:
                raise UnsupportedPlugin(self.get_name(), f"{name}.plugin", plugin or None,
                                     f"unknown task executor; known: {list(_TASKS)}")
            task: dict[str, Any] = {"plugin": plugin, "enabled": bool(sub.get("enabled", True))}
            if plugin.endswith("WaitAtWaypoint"):
                task["pause_s"] = float(sub.get("waypoint_pause_duration", 0)) / 1000.0
            elif plugin.endswith("PhotoAtWaypoint"):
                task["topic"] = str(sub.get("camera_image_topic_name", "/camera/color/image_raw"))
                task["dir"] = Path(str(sub.get("save_images_dir", "/tmp/waypoint_images"))).expanduser()
                fmt = str(sub.get("image_format", "png")).lower()
                if fmt != "png":
                    raise ParameterError(self.get_name(), f"{name}.image_format", fmt,
                                         "only png is written")
            elif plugin.endswith("InputAtWaypoint"):
                task["input_topic"] = str(sub.get("input_topic", "input_at_waypoint/input"))
                try:
                    timeout = float(sub.get("timeout", 10.0))
                except (TypeError, ValueError):
                    raise ParameterError(self.get_name(), f"{name}.timeout", sub.get("timeout"),
                                         "must be a number of seconds") from None
                task["timeout_ns"] = int(timeout) * 1_000_000_000
            self._task = task
        return self.configure_with(build)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        from eddiebot.msgs.nav2_msgs import FollowWaypoints, NavigateToPose
        from eddiebot.msgs.sensor_msgs import Image

        self._nav = ActionClient(self, NavigateToPose, "/navigate_to_pose")
        if "topic" in self._task:
            self._image_sub = self.create_subscription(Image, self._task["topic"], self._on_image,
                                                       qos_profile_sensor_data)
        if "input_topic" in self._task:
            from eddiebot.msgs.std_msgs import Empty

            self._input_sub = self.create_subscription(Empty, self._task["input_topic"],
                                                       self._on_input, 1)
        self._action = ActionServer(self, FollowWaypoints, "follow_waypoints", self._follow,
                                    cancel_callback=lambda _h: CancelResponse.ACCEPT)
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        if self._action is not None:
            self._action.destroy()
        if self._nav is not None:
            self._nav.destroy()
        for sub in (self._image_sub, self._input_sub):
            if sub is not None:
                self.destroy_subscription(sub)
        self._action = self._nav = self._image_sub = self._input_sub = None
        return TransitionCallbackReturn.SUCCESS

    def _on_image(self, msg: Any) -> None:
        self._image = msg

    def _on_input(self, _msg: Any) -> None:
        self._input_received = True

    async def _await_input(self, index: int) -> bool:
        """InputAtWaypoint: True once an input arrives after arrival, False at ``timeout``."""
        self._input_received = False
        self.waiting_at = index
        start = self.now().nanoseconds
        try:
            while self.now().nanoseconds - start < self._task["timeout_ns"]:
                if self._input_received:
                    return True
                await sleep(self, 0.02)  # upstream polls at 50 Hz
        finally:
            self.waiting_at = None
        self.get_logger().warning(f"Unable to get external input at wp {index}. Moving on.")
        return False

    async def _run_task(self, index: int) -> bool:
        task = self._task
        if not task.get("enabled", True):
            return True
        if "pause_s" in task:
            await sleep(self, task["pause_s"])
            return True
        if "input_topic" in task:
            return await self._await_input(index)
        if "dir" in task:
            if self._image is None:
                self.get_logger().error(f"waypoint {index}: no image on {task['topic']} to save")
                return False
            stamp = self.now().nanoseconds
            path = task["dir"] / f"{index}_{stamp}.png"
            try:
                write_png_atomic(path, image_to_bgr(self._image))
            except (OSError, ValueError) as exc:
                self.get_logger().error(f"waypoint {index}: {exc}")
                return False
            self.saved.append(path)
            self.get_logger().info(f"waypoint {index}: photo saved to {path}")
        return True

    async def _follow(self, handle: ServerGoalHandle) -> Any:
        from eddiebot.msgs.nav2_msgs import FollowWaypoints, MissedWaypoint, NavigateToPose

        assert self._nav is not None
        goal = handle.request
        result = FollowWaypoints.Result()
        poses = list(goal.poses)
        loops = int(getattr(goal, "number_of_loops", 0))
        start = int(getattr(goal, "goal_index", 0))
        stop_on_failure = bool(self.param("stop_on_failure"))
        bad = [i for i, ps in enumerate(poses) if not pose_is_finite(ps.pose)]
        if not poses or bad:
            result.error_code = NO_VALID_WAYPOINTS
            result.error_msg = (f"waypoints {bad} are not finite" if bad else "no waypoints given")
            self.get_logger().warning(f"follow_waypoints: {result.error_msg}")
            handle.abort()
            return result
        missed: list[Any] = []
        for loop in range(loops + 1):
            for i in range(start if loop == 0 else 0, len(poses)):
                handle.publish_feedback(FollowWaypoints.Feedback(current_waypoint=i))
                pose = poses[i]
                if not pose.header.frame_id:
                    pose.header.frame_id = str(self.param("global_frame_id"))
                send = self._nav.send_goal_async(NavigateToPose.Goal(pose=pose))
                while not send.done():
                    await sleep(self, 0.05)
                nav_handle = send.result()
                code = 0
                ok = bool(nav_handle.accepted)
                if ok:
                    res_future = nav_handle.get_result_async()
                    while not res_future.done():
                        if handle.is_cancel_requested:
                            nav_handle.cancel_goal_async()
                            while not res_future.done():
                                await sleep(self, 0.05)
                            handle.canceled()
                            result.missed_waypoints = missed
                            return result
                        await sleep(self, 1.0 / float(self.param("loop_rate")))
                    response = res_future.result()
                    ok = int(response.status) == 4
                    code = int(getattr(response.result, "error_code", 0))
                if ok and not await self._run_task(i):
                    ok = False
                    code = int(FollowWaypoints.Result.TASK_EXECUTOR_FAILED)
                if not ok:
                    self.get_logger().warning(f"waypoint {i} missed (error {code})")
                    missed.append(MissedWaypoint(index=i, goal=pose, error_code=code))
                    if stop_on_failure:
                        result.missed_waypoints = missed
                        result.error_code = code if code == FollowWaypoints.Result.TASK_EXECUTOR_FAILED \
                            else int(FollowWaypoints.Result.UNKNOWN)
                        result.error_msg = f"waypoint {i} missed"
                        handle.abort()
                        return result
        result.missed_waypoints = missed
        handle.succeed()
        return result
