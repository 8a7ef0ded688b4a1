"""slam_toolbox's node: ``/scan`` + TF ``odom → base_footprint`` → ``/map`` and TF
``map → odom``, on `SlamCore`.

Parameters are slam_toolbox's names (every field of `SlamConfig`, declared with the
upstream node's code defaults); ``mode`` is ``mapping``, ``localization`` or ``lifelong``.
Every slam_toolbox key is accepted; at start the node logs once each one it does not honour
(``ignored: <key> (<why>)``, Ceres' keys in one line: GTSAM replaces Ceres) and each key that
is neither slam_toolbox's nor eddiebot's (`eddiebot.slam.config.parameter_warnings`);
``startup_warnings`` keeps the lines. ``processing`` chooses between slam_toolbox's sync node
(every scan queued and processed, none dropped) and async node (at most ``scan_queue_size``
scans wait; older ones are dropped).

``map_file_name`` loads a saved session at start-up in every mode, as slam_toolbox: in
localization mode with LOCALIZE_AT_POSE at ``map_start_pose`` — without it the first scan is
relocalised globally over the whole map (slam_toolbox starts at the origin); otherwise at ``map_start_pose``
(START_AT_GIVEN_POSE) or, with ``map_start_at_dock``, at the session's first node
(START_AT_FIRST_NODE); neither set: at the map origin. ``~/deserialize_map`` takes the same
match types: LOCALIZE_AT_POSE only in localization mode (and only it there), UNSET refused.

One laser: the map is built from the first laser frame's scans; a scan from another frame
whose mount differs is refused (one warning; ``scans_refused_frame`` counts them), so earlier
scans are never re-placed under another mount. ``transform_publish_period`` 0 publishes no
map → odom transform. ``paused_new_measurements`` starts paused.

Localization mode (slam_toolbox's localization node; `eddiebot.slam.mapper.localization`):
``initialpose`` (geometry_msgs/PoseWithCovarianceStamped, in ``map_frame``) places the next scan
at that pose and clears the localization buffer; ``~/clear_localization_buffer``
(std_srvs/Empty) clears it; a robot lost for ``scan_buffer_size`` scans is relocalised globally,
attempts backing off while the map does not cover the place. The whole-map search runs in a
process of its own (`eddiebot.slam.relocalization_process`): the scan callback hands it over
and returns, tracking goes on, and a later scan takes the answer.
Every processed scan's pose is published on ``pose`` (geometry_msgs/PoseWithCovarianceStamped,
the match's x, y, yaw covariance) in every mode, as upstream.

Services (under the node's name, as slam_toolbox): ``~/save_map`` (slam_toolbox/SaveMap:
nav2 map_server files), ``~/serialize_map`` and ``~/deserialize_map`` (the session file),
``~/pause_new_measurements`` (toggle), ``~/reset``, ``~/clear_queue``. The graph is published
as markers on ``~/graph_visualization`` (node ``i`` is point ``i`` of the sphere list).
Interactive editing (``~/toggle_interactive_mode``, ``~/feedback``, ``~/manual_loop_closure``,
``~/clear_changes``), merging a second session (``~/add_submap``, ``~/merge_submaps``) and
``~/set_localization_mode``: `eddiebot.slam.node_editing`. The publishing (TF, ``pose``, the
map, the graph markers) is in `eddiebot.slam.node_outputs`, the session and map files
(``~/save_map``, ``~/serialize_map``, ``~/deserialize_map``, ``map_file_name``) in
`eddiebot.slam.node_session`; both are bases of `SlamNode`.

``odom_session`` (eddiebot) names the odometry the node maps on (the ``/odom`` publisher's
process and node, set by ``eddie slam``); with it, a map written by ``~/save_map`` or
`SlamNode.save_outputs` records the map → odom transform and that name as the map YAML's
``map_to_odom`` / ``odom_session`` keys (`eddiebot.maps.MapAnchor`), so navigation on the
same running robot starts where the robot is.

A scan is processed when the robot moved ``minimum_travel_distance`` **or** turned
``minimum_travel_heading`` — in every mode (upstream's sync and localization modes ignore
pure rotation; with a 57° Kinect scan, turning in place is how Eddie sees a room).

Low-feature places (a corridor): when a scan match's position variance along its weakest
direction exceeds ``corridor_covariance_threshold`` (m²), one warning is logged per
*episode* — the first such match starts one; it ends after `LOW_FEATURE_CLEAR_MATCHES`
consecutive well-constrained matches, and the next poorly constrained match logs again.
``low_feature_episodes`` and ``low_feature_matches`` count them.

``scan_cpu_s`` holds the CPU time (this thread's, ``time.thread_time``) the core spent on
each processed scan (matching, loop closure, optimisation); ``map_update_cpu_s`` the time
of each occupancy-grid refresh for ``/map``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import deque
from typing import Any

import numpy as np

from eddiebot.core.qos import (
    HistoryPolicy,
    QoSProfile,
    qos_profile_latched,
    qos_profile_sensor_data,
)
from eddiebot.core.tf import Buffer, TransformBroadcaster, TransformListener
from eddiebot.core.time import stamp_to_ns
from eddiebot.geometry import quaternion_to_yaw, yaw_to_quaternion
from eddiebot.maps import OccupancyMap
from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
from eddiebot.msgs.nav_msgs import MapMetaData, OccupancyGrid
from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.msgs.slam_toolbox import (
    ClearQueue,
    DeserializePoseGraph,
    Pause,
    Reset,
    SaveMap,
    SerializePoseGraph,
)
from eddiebot.msgs.std_srvs import Empty
from eddiebot.msgs.visualization_msgs import MarkerArray
from eddiebot.slam.config import SlamConfig, parameter_warnings
from eddiebot.slam.mapper import ProcessStatus, SlamCore, SlamWarning, warm_up
from eddiebot.slam.node_editing import GraphEditing
from eddiebot.slam.node_outputs import SlamOutputs
from eddiebot.slam.node_session import SlamSessionFiles, _fmt_pose, _same_mount
from eddiebot.slam.relocalization_process import RelocalizationProcess
from eddiebot.slam.scan import Scan

__all__ = ["LOW_FEATURE_CLEAR_MATCHES", "SlamNode"]

_NODE_ONLY = {"extra"}

#: Consecutive well-constrained matches that end a low-feature episode (hysteresis: a door
#: in a corridor wall does not end the corridor).
LOW_FEATURE_CLEAR_MATCHES = 3


class SlamNode(SlamOutputs, SlamSessionFiles):
    default_node_name = "slam_toolbox"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        values: dict[str, Any] = {}
        for f in dataclasses.fields(SlamConfig):
            if f.name in _NODE_ONLY:
                continue
            default = f.default if f.default is not dataclasses.MISSING else None
            values[f.name] = self.declare_parameter(f.name, default).value
        self.processing = str(self.declare_parameter("processing", "async").value)
        self.odom_session = str(self.declare_parameter("odom_session", "").value)
        if self.processing not in ("sync", "async"):
            raise ValueError(f"{self.fully_qualified_name}: processing must be sync or async")
        # slam_toolbox keys that are no field (and unknown keys) are declared, so a user's
        # file launches; parameter_warnings names each
        extra: dict[str, Any] = {}
        for o in self.undeclared_overrides():
            extra[o.name] = self.declare_parameter(o.name, o.value).value
        self.config = SlamConfig(**values, extra=extra).validated()
        given = {name: o.value for name, o in self._overrides.items()}
        self.startup_warnings = parameter_warnings(given, self.config)
        for line in self.startup_warnings:
            self.get_logger().warning(line)
        if self.config.debug_logging:
            self.get_logger().set_level(logging.DEBUG)
        self._warned: set[str] = set()
        self.low_feature_episodes = 0
        self.low_feature_matches = 0
        self._low_feature_active = False
        self._well_constrained_run = 0
        self.scan_cpu_s: deque[float] = deque(maxlen=100_000)
        self.map_update_cpu_s: deque[float] = deque(maxlen=100_000)
        self.relocalization_search = RelocalizationProcess()
        """Runs localization's whole-map searches off the scan callback."""
        self.core = SlamCore(self.config, on_warning=self._on_warning)
        self.core.global_search = self.relocalization_search
        # numba compiles the kernels on their first call: now, not on the first real scan
        seconds = warm_up(self.config)
        if seconds > 2.0:
            self.get_logger().info(
                f"compiled the scan-matching kernels in {seconds:.1f} s "
                "(once after an install; numba caches them)"
            )
        self.paused = self.config.paused_new_measurements
        self._laser: tuple[str, np.ndarray] | None = None
        """The laser frame the map is built from and its mount (x, y, yaw in base_frame)."""
        # sync: every scan waits its turn; async: at most scan_queue_size wait (upstream's
        # tf2 MessageFilter queue), older ones are dropped
        queue_size = None if self.processing == "sync" else self.config.scan_queue_size
        self._scan_queue: deque[Any] = deque(maxlen=queue_size)
        self._last_scan_ns: int | None = None
        self._scan_count = 0
        self._map_dirty = False
        self._last_map: OccupancyMap | None = None
        """The map last built and published (sent again while the graph is unchanged)."""
        self.scans_received = 0
        """Scans delivered to the node (before throttling, pausing and queueing)."""
        self.scans_dropped = 0
        """Scans dropped from a full async queue, or by ``~/clear_queue``."""
        self.scans_processed = 0
        """Scans handed to the SLAM core."""
        self.scans_refused_frame = 0
        """Scans refused because they came from a second laser with another mount."""
        self.tf_buffer = Buffer(self.config.tf_buffer_duration, node=self)
        self.tf_listener = TransformListener(self.tf_buffer, self)
        self.tf_broadcaster = TransformBroadcaster(self)
        map_topic = self.config.map_name
        self.map_pub = self.create_publisher(OccupancyGrid, map_topic, qos_profile_latched)
        self.meta_pub = self.create_publisher(
            MapMetaData, f"{map_topic}_metadata", qos_profile_latched
        )
        self.graph_pub = self.create_publisher(MarkerArray, "~/graph_visualization", 1)
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, "pose", 10)
        if self.config.mode == "localization":
            self.create_subscription(
                PoseWithCovarianceStamped, "initialpose", self._on_initial_pose, 1
            )
            self.create_service(
                Empty, "~/clear_localization_buffer", self._clear_localization_buffer
            )
        if self.processing == "sync":
            scan_qos = QoSProfile(
                history=HistoryPolicy.KEEP_ALL, reliability=qos_profile_sensor_data.reliability
            )
        else:
            scan_qos = QoSProfile(
                depth=self.config.scan_queue_size,
                reliability=qos_profile_sensor_data.reliability,
            )
        self.create_subscription(LaserScan, self.config.scan_topic, self._on_scan, scan_qos)
        if self.config.transform_publish_period > 0:
            self.create_timer(self.config.transform_publish_period, self._publish_transform)
        self.create_timer(0.02, self._drain)
        self.create_timer(self.config.map_update_interval, self._publish_map)
        # as slam_toolbox: no map saver when use_map_saver is false or when localizing
        if self.config.use_map_saver and self.config.mode != "localization":
            self.create_service(SaveMap, "~/save_map", self._save_map)
        self.create_service(SerializePoseGraph, "~/serialize_map", self._serialize)
        self.create_service(DeserializePoseGraph, "~/deserialize_map", self._deserialize)
        self.create_service(Pause, "~/pause_new_measurements", self._pause)
        self.create_service(Reset, "~/reset", self._reset)
        self.create_service(ClearQueue, "~/clear_queue", self._clear_queue)
        self.editing = GraphEditing(self)
        self.get_logger().info(
            f"slam in {self.config.mode} mode ({self.processing}), resolution {self.config.resolution} m"
        )
        if self.config.map_file_name:
            self._load_at_start()

    # -- warnings --------------------------------------------------------------------------
    def _on_warning(self, w: SlamWarning) -> None:
        if w.kind == "low_feature":
            self.low_feature_matches += 1
            self._well_constrained_run = 0
            if not self._low_feature_active:
                # once per episode: it is about this place, not about every scan in it
                self._low_feature_active = True
                self.low_feature_episodes += 1
                self.get_logger().warning(
                    f"{w.message} (variance above corridor_covariance_threshold "
                    f"{self.config.corridor_covariance_threshold} m²; not repeated until "
                    f"{LOW_FEATURE_CLEAR_MATCHES} well-constrained matches)"
                )
            return
        if w.kind not in self._warned:
            self._warned.add(w.kind)
            self.get_logger().warning(f"{w.message} (further '{w.kind}' warnings suppressed)")

    def _warn_once(self, kind: str, text: str) -> None:
        if kind not in self._warned:
            self._warned.add(kind)
            self.get_logger().warning(text)

    # -- scans -----------------------------------------------------------------------------
    def _sensor_pose(self, frame: str) -> np.ndarray | None:
        """The laser's mount; None (scan refused) when unknown or not the map's laser's."""
        if self._laser is not None and self._laser[0] == frame:
            return self._laser[1]
        try:
            x, y, yaw = self.tf_buffer.lookup_pose2d(self.config.base_frame, frame, 0)
        except Exception as exc:
            self._warn_once(
                "no_sensor_tf", f"no transform {self.config.base_frame} → {frame}: {exc}"
            )
            return None
        offset = np.array([x, y, yaw])
        # the core holds one mount for all its scans: a scan under another mount would
        # re-place every earlier one, so it is refused (a loaded session fixes the mount too)
        reference = self._laser[1] if self._laser is not None else (
            self.core.sensor_offset if self.core.nodes else None
        )
        if reference is not None and not _same_mount(reference, offset):
            self.scans_refused_frame += 1
            first = self._laser[0] if self._laser is not None else "the loaded session's laser"
            self._warn_once(
                f"second_laser:{frame}",
                f"scans from {frame} refused: mounted at {_fmt_pose(offset)}, the map is "
                f"built from {first} at {_fmt_pose(reference)} (one laser per map; further "
                "scans from it are refused silently, counted in scans_refused_frame)",
            )
            return None
        if self._laser is None:
            self._laser = (frame, offset)
            self.core.sensor_offset = offset
        return offset

    def _on_scan(self, msg: Any) -> None:
        self.scans_received += 1
        if self.paused or self.editing.interactive_mode:
            return
        self._scan_count += 1
        if self.config.throttle_scans > 1 and self._scan_count % self.config.throttle_scans:
            return
        # tf2 MessageFilter's role: a scan waits (up to transform_timeout) for the odometry
        # of its time, which may be published just after it
        if self._scan_queue.maxlen is not None and len(self._scan_queue) == self._scan_queue.maxlen:
            self.scans_dropped += 1
        self._scan_queue.append(msg)
        self._drain()

    def _drain(self) -> None:
        now = self.get_clock().now_ns()
        timeout = round(self.config.transform_timeout * 1e9)
        while self._scan_queue:
            msg = self._scan_queue[0]
            stamp = stamp_to_ns(msg.header.stamp)
            if not self.tf_buffer.can_transform(
                self.config.odom_frame, self.config.base_frame, stamp
            ):
                if now - stamp <= timeout:
                    return  # wait for newer odometry
                self._scan_queue.popleft()
                self._warn_once(
                    "no_odom_tf",
                    f"no odometry at a scan's time within "
                    f"transform_timeout {self.config.transform_timeout} s: scan dropped",
                )
                continue
            self._scan_queue.popleft()
            self._process(msg)

    def _process(self, msg: Any) -> None:
        stamp = stamp_to_ns(msg.header.stamp)
        if self._last_scan_ns is not None:
            if stamp < self._last_scan_ns:
                self._warn_once(
                    "time_backwards",
                    f"scan time went backwards ({stamp * 1e-9:.3f} s after "
                    f"{self._last_scan_ns * 1e-9:.3f} s; bag restarted?): skipped",
                )
                return
            if stamp - self._last_scan_ns < self.config.minimum_time_interval * 1e9 * 0.999:
                return
        if self._sensor_pose(msg.header.frame_id) is None:
            return
        try:
            odom = self.tf_buffer.lookup_pose2d(
                self.config.odom_frame, self.config.base_frame, stamp
            )
        except Exception as exc:
            self._warn_once("no_odom_tf", f"no odometry at the scan's time: {exc}")
            return
        scan = Scan.from_laser_scan(msg, stamp)
        cpu0 = time.thread_time()
        self.scans_processed += 1
        result = self.core.process(scan, np.array(odom))
        cpu = time.thread_time() - cpu0
        for w in result.warnings:
            if w.kind in ("relocalized", "relocalization_failed"):
                self.get_logger().info(w.message)
        if result.pose is not None:
            self._publish_pose(result.pose, result.covariance, stamp)
        if result.status in (ProcessStatus.ADDED, ProcessStatus.LOCALIZED):
            self.scan_cpu_s.append(cpu)
            self._track_low_feature(result)
            self._last_scan_ns = stamp
            self._map_dirty = self._map_dirty or result.status == ProcessStatus.ADDED
            if result.loop_closed:
                self.get_logger().info(f"loop closed at node {result.node_id}")
                self._map_dirty = True

    def _track_low_feature(self, result: Any) -> None:
        """End a low-feature episode after enough well-constrained matches."""
        if result.covariance is None or any(w.kind == "low_feature" for w in result.warnings):
            return
        if any(w.kind == "weak_match" for w in result.warnings):
            return  # odometry only: says nothing about the place
        self._well_constrained_run += 1
        if self._low_feature_active and self._well_constrained_run >= LOW_FEATURE_CLEAR_MATCHES:
            self._low_feature_active = False
            self.get_logger().info("scan matches well constrained again")

    # -- localization ----------------------------------------------------------------------
    def _on_initial_pose(self, msg: Any) -> None:
        """slam_toolbox's ``localizePoseCallback``: the next scan starts at this pose."""
        frame = msg.header.frame_id
        if frame and frame != self.config.map_frame:
            self.get_logger().warning(
                f"initialpose in frame {frame!r}, expected map_frame "
                f"{self.config.map_frame!r}; ignored"
            )
            return
        p = msg.pose.pose
        o = p.orientation
        yaw = quaternion_to_yaw(o.x, o.y, o.z, o.w)
        pose = np.array([float(p.position.x), float(p.position.y), yaw])
        if not np.all(np.isfinite(pose)):
            self.get_logger().warning(f"initialpose {pose} is not finite; ignored")
            return
        self.core.start_at(pose)
        self.get_logger().info(
            f"initialpose: localizing to ({pose[0]:.2f}, {pose[1]:.2f}), theta={pose[2]:.2f}"
        )

    def _clear_localization_buffer(self, req: Any, res: Any) -> Any:
        self.core.clear_localization_buffer()
        self.get_logger().info("clearing the localization buffer")
        return res

    # -- services --------------------------------------------------------------------------
    def _pause(self, req: Any, res: Any) -> Any:
        self.paused = not self.paused
        if not self.paused:
            # the robot may have moved any distance meanwhile: not an odometry jump
            self.core.forget_odometry()
        self.set_parameter("paused_new_measurements", self.paused)
        res.status = True
        self.get_logger().info(
            "paused new measurements" if self.paused else "resumed new measurements"
        )
        return res

    def _reset(self, req: Any, res: Any) -> Any:
        self.core.clear()
        self._last_scan_ns = None
        self._scan_queue.clear()
        self.paused = bool(req.pause_new_measurements)
        self._map_dirty = True
        res.result = Reset.Response.RESULT_SUCCESS
        return res

    def _clear_queue(self, req: Any, res: Any) -> Any:
        dropped = len(self._scan_queue)
        self._scan_queue.clear()
        self.scans_dropped += dropped
        self.get_logger().info(f"clear_queue: dropped {dropped} queued scans")
        res.status = True
        return res

    def destroy_node(self) -> None:
        editing = getattr(self, "editing", None)  # None when __init__ failed before it
        if editing is not None:
            editing.close()
        search = getattr(self, "relocalization_search", None)
        if search is not None:
            search.close()
        super().destroy_node()

    def mark_map_dirty(self) -> None:
        """Re-render and publish the map and graph at the next map update."""
        self._map_dirty = True

    def map_to_odom_quaternion(self) -> tuple[float, float, float, float]:
        return yaw_to_quaternion(float(self.core.map_to_odom[2]))
