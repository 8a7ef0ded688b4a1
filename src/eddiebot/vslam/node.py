"""rtabmap_ros's ``rtabmap`` node on the `Rtabmap` core: RGB-D (+ scan) + TF odometry → graph,
``map → odom``, occupancy grid, session database.

Parameters are rtabmap_ros's: ``frame_id`` (base_footprint), ``map_frame_id``, ``odom_frame_id``,
``subscribe_depth``, ``subscribe_scan``, ``approx_sync``, ``sync_queue_size`` (``queue_size`` is
the deprecated alias), ``wait_for_transform`` (s), ``tf_delay``/``tf_tolerance``,
``odom_tf_linear_variance``/``odom_tf_angular_variance``, ``database_path``,
``odom_stamp_offset`` (s, not upstream: TF odometry is read at the image stamp plus this, to
compensate a known odometry latency; default 0),
``delete_db_on_start`` (``-d``), ``localization`` (``Mem/IncrementalMemory`` false and
``Mem/InitWMWithAllNodes`` true). Every RTAB-Map ``Group/Name`` parameter is accepted as a string
parameter under that name (``Reg/Force3DoF: "true"`` under ``ros__parameters``; the nested YAML form
``Reg: {Force3DoF: true}`` arrives as ``Reg.Force3DoF`` and is accepted too), and
``rtabmap_args`` takes upstream's command line (``-d --Reg/Force3DoF true``). Without ``-d`` the
database's last session parameters are re-applied unless set explicitly, as upstream.

Input: ``/image_raw`` + ``/camera_info``, ``/depth/image_raw`` + ``/depth/camera_info`` (depth in
another frame than the RGB camera is registered to it first, as the Kinect publishes it
unregistered), ``/scan``, ``/odom`` (only to notice lost odometry). Sets are paired by stamp
(``approx_sync``: within ``approx_sync_max_interval``, default 0.05 s), throttled by
``Rtabmap/DetectionRate`` and wait up to ``wait_for_transform`` for TF ``odom → frame_id`` at the
image stamp; the camera's and the laser's poses in ``frame_id`` come from TF.

Output: TF ``map → odom`` every ``tf_delay``; ``map_topic`` (default ``/map``, latched: vSLAM is
the mapper; ``/rtabmap/map`` to run beside 2D SLAM), the 2D grid (``Grid/RayTracing``,
``Grid/3D`` false); ``~/mapGraph`` (rtabmap_msgs/MapGraph) and ``~/mapData``
(rtabmap_msgs/MapData: the graph and the nodes added since the last one) with the map,
``~/info`` (rtabmap_msgs/Info) after every processed frame, ``~/localization_pose``
(PoseWithCovarianceStamped, localization mode: covariance 9999 until localized), ``~/graph_markers`` (MarkerArray:
nodes, neighbour and loop links; not upstream, for viewers without rtabmap's plugins);
``~/cloud_map`` (PointCloud2, on ``~/publish_map``). Services (std_srvs/Empty unless named):
``~/reset`` (empties memory and database), ``~/pause``, ``~/resume``, ``~/publish_map``,
``~/set_mode_localization``, ``~/set_mode_mapping``, ``~/save_map`` (nav2_msgs/SaveMap:
map_server files at ``map_url``), ``~/export_cloud`` (slam_toolbox/SaveMap: a PLY file at
``name``).

Bad input (an image without depth or camera_info, mismatched sizes, unsupported encodings, time
going backwards, missing odometry, lost odometry) is skipped with one warning per kind; a frame
is never processed with a made-up pose.

The input synchronisation is `eddiebot.vslam.node_sync.RgbdSync`, the publishers
`eddiebot.vslam.node_outputs.RtabmapOutputs` (bases of `RtabmapNode`). With `frame_track` set
(replays), every input colour frame is recorded with its odometry and key frame (throttled ones
too), or as lost.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.parameters import ParameterDescriptor
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.core.tf import Buffer, TransformListener
from eddiebot.maps import save_map
from eddiebot.msgs.nav2_msgs import SaveMap as Nav2SaveMap
from eddiebot.msgs.nav_msgs import Odometry
from eddiebot.msgs.sensor_msgs import CameraInfo, Image, LaserScan
from eddiebot.msgs.slam_toolbox import SaveMap as PathRequest
from eddiebot.msgs.std_srvs import Empty
from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.errors import DatabaseError
from eddiebot.vslam.errors import ParameterError as VslamParameterError
from eddiebot.vslam.export import write_ply
from eddiebot.vslam.frame_track import FrameTrack
from eddiebot.vslam.node_outputs import RtabmapOutputs
from eddiebot.vslam.node_sync import RgbdSync, tf_matrix
from eddiebot.vslam.occupancy import Scan2D
from eddiebot.vslam.parameters import (
    RTABMAP_NAME,
    RtabmapParameters,
    parameter_names,
    parameter_text,
    parse_rtabmap_args,
)
from eddiebot.vslam.rtabmap import ProcessResult, Rtabmap

__all__ = ["DEFAULT_DATABASE_PATH", "RtabmapNode", "parse_rtabmap_args"]

DEFAULT_DATABASE_PATH = "~/.local/share/eddiebot/rtabmap.db"
_RGB_ENCODINGS = ("rgb8", "bgr8", "mono8")
_DEPTH_ENCODINGS = ("16UC1", "32FC1")
_SEC = 1_000_000_000


def _image_array(msg: Any, accepted: tuple[str, ...]) -> np.ndarray:
    from eddiebot.perception._image import image_to_array

    return image_to_array(msg, accepted)


class RtabmapNode(RgbdSync, RtabmapOutputs):
    """The ``rtabmap`` node (mapping or localization) on `Rtabmap`."""

    default_node_name = "rtabmap"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)

        def p(name: str, default: Any) -> Any:
            return self.declare_parameter(name, default).value

        self.frame_id = str(p("frame_id", "base_footprint"))
        self.map_frame_id = str(p("map_frame_id", "map"))
        self.odom_frame_id = str(p("odom_frame_id", "odom"))
        self.subscribe_depth = bool(p("subscribe_depth", True))
        self.subscribe_scan = bool(p("subscribe_scan", False))
        self.subscribe_odom = bool(p("subscribe_odom", True))
        self.approx_sync = bool(p("approx_sync", True))
        self.approx_sync_max_interval = float(p("approx_sync_max_interval", 0.05))
        queue_size = int(p("queue_size", 0))
        self.sync_queue_size = int(p("sync_queue_size", 10))
        if queue_size > 0:
            self.get_logger().warning(
                "parameter 'queue_size' is deprecated, use 'sync_queue_size' (copied)")
            self.sync_queue_size = queue_size
        self.wait_for_transform = float(p("wait_for_transform", 0.2))
        self.tf_delay = float(p("tf_delay", 0.05))
        self.tf_tolerance = float(p("tf_tolerance", 0.1))
        self.publish_tf = bool(p("publish_tf", True))
        # not upstream: odometry latency compensation (s), TF odometry is read at stamp + this
        self.odom_stamp_offset = float(p("odom_stamp_offset", 0.0))
        self.odom_tf_linear_variance = float(p("odom_tf_linear_variance", 0.001))
        self.odom_tf_angular_variance = float(p("odom_tf_angular_variance", 0.001))
        self.map_topic = str(p("map_topic", "/map"))
        self.map_update_interval = float(p("map_update_interval", 1.0))
        self.cloud_voxel_size = float(p("cloud_voxel_size", 0.05))
        self.database_path = str(p("database_path", DEFAULT_DATABASE_PATH))
        self.delete_db_on_start = bool(p("delete_db_on_start", False))
        self.localization = bool(p("localization", False))
        self.rtabmap_args = str(p("rtabmap_args", ""))
        rgb_topic = str(p("rgb_topic", "/image_raw"))
        rgb_info_topic = str(p("rgb_camera_info_topic", "/camera_info"))
        depth_topic = str(p("depth_topic", "/depth/image_raw"))
        depth_info_topic = str(p("depth_camera_info_topic", "/depth/camera_info"))
        scan_topic = str(p("scan_topic", "/scan"))
        odom_topic = str(p("odom_topic", "/odom"))

        self._init_sync()
        self.explicit_parameters = self._explicit_rtabmap_parameters()
        args, delete, ignored = parse_rtabmap_args(self.rtabmap_args)
        if ignored:
            self.get_logger().warning(f"rtabmap_args: ignored {' '.join(ignored)}")
        self.explicit_parameters.update(args)
        self.delete_db_on_start = self.delete_db_on_start or delete

        self.paused = False
        self.frames_processed = 0
        self.loop_closures = 0
        self.last_result: ProcessResult | None = None
        self.node_stamps: dict[int, int] = {}
        #: every input colour frame's place (set it to a `FrameTrack` to record: replays)
        self.frame_track: FrameTrack | None = None
        #: base → colour optical frame of the last processed image
        self.camera_transform: np.ndarray | None = None
        self._last_processed_ns: int | None = None
        self._map_dirty = True
        self._odom_reset_pending = False

        self.db: SessionDatabase | None = None
        self.core = self._make_core(self.delete_db_on_start)

        self.tf_buffer = Buffer(10.0, node=self)
        self.tf_listener = TransformListener(self.tf_buffer, self)
        self._create_outputs(self.map_topic)
        sensor = qos_profile_sensor_data
        self.create_subscription(Image, rgb_topic, self._on_rgb, sensor)
        self.create_subscription(CameraInfo, rgb_info_topic, self._rgb_info.append, sensor)
        if self.subscribe_depth:
            self.create_subscription(Image, depth_topic, self._on_depth, sensor)
            self.create_subscription(CameraInfo, depth_info_topic, self._depth_info.append, sensor)
        if self.subscribe_scan:
            self.create_subscription(LaserScan, scan_topic, self._on_scan, sensor)
        if self.subscribe_odom:
            self.create_subscription(Odometry, odom_topic, self._odom.append, 50)
        if self.publish_tf:
            self.create_timer(self.tf_delay, self._publish_tf)
        self.create_timer(0.02, self._drain)
        self.create_timer(self.map_update_interval, self._publish_map)
        self.create_service(Empty, "~/reset", self._srv_reset)
        self.create_service(Empty, "~/pause", self._srv_pause)
        self.create_service(Empty, "~/resume", self._srv_resume)
        self.create_service(Empty, "~/publish_map", self._srv_publish_map)
        self.create_service(Empty, "~/set_mode_localization", self._srv_localization)
        self.create_service(Empty, "~/set_mode_mapping", self._srv_mapping)
        self.create_service(Nav2SaveMap, "~/save_map", self._srv_save_map)
        self.create_service(PathRequest, "~/export_cloud", self._srv_export_cloud)
        mode = "localization" if self.core.localization_mode else "mapping"
        where = self.db.path if self.db is not None else "no database"
        self.get_logger().info(
            f"rtabmap in {mode} mode ({len(self.core.memory.nodes)} nodes loaded from {where}), "
            f"Reg/Force3DoF {self.core.params.reg_force_3dof}")

    # -- parameters & core -----------------------------------------------------------------
    def _explicit_rtabmap_parameters(self) -> dict[str, str]:
        """Declare every ``Group/Name`` parameter (string, unset by default); return those set.

        Names this implementation does not use are accepted (declared, so launch files written
        for upstream still load) and reported once."""
        names = parameter_names()
        out: dict[str, str] = {}
        desc = ParameterDescriptor(description="RTAB-Map parameter (string)", dynamic_typing=True)
        for name in names:
            value = self.declare_parameter(name, None, desc).value
            if value is not None:
                out[name] = parameter_text(value)
        dotted = {n.replace("/", "."): n for n in names}
        for o in self.undeclared_overrides():
            if o.name in dotted:
                out[dotted[o.name]] = parameter_text(o.value)
                self.declare_parameter(o.name, None, desc)
            elif RTABMAP_NAME.match(o.name):
                name = o.name.replace(".", "/", 1) if "/" not in o.name else o.name
                self.declare_parameter(o.name, None, desc)
                out[name] = parameter_text(o.value)
        return out

    def effective_parameters(self, stored: dict[str, str]) -> dict[str, str]:
        """Defaults the ROS node forces < database's last session < explicit < mode; only
        names this implementation knows, each value checked (a bad one is dropped, reported)."""
        values: dict[str, str] = {"RGBD/CreateOccupancyGrid": "true"}
        if self.subscribe_scan:
            values["Grid/Sensor"] = "0"
        known = set(parameter_names())
        values.update({k: v for k, v in stored.items() if k in known})
        unused = sorted(k for k in self.explicit_parameters if k not in known)
        if unused:
            self._warn_once("unused_parameters",
                            f"RTAB-Map parameters not used by this implementation: {', '.join(unused)}")
        for k, v in self.explicit_parameters.items():
            if k not in known:
                continue
            try:
                RtabmapParameters.from_dict({k: v})
            except VslamParameterError as exc:
                self.get_logger().error(f"{exc}: default kept")
                continue
            values[k] = v
        if self.localization:
            values["Mem/IncrementalMemory"] = "false"
            values["Mem/InitWMWithAllNodes"] = "true"
        return values

    def _make_core(self, delete: bool) -> Rtabmap:
        stored: dict[str, str] = {}
        self.db = None
        if self.database_path:
            path = Path(self.database_path).expanduser()
            # The database is the user's map: a file that is not ours, damaged or locked stops
            # the node instead of being replaced or silently mapped without.
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                self.db = SessionDatabase(path, delete_on_start=delete)
                stored = self.db.last_parameters()
            except OSError as exc:
                raise DatabaseError(f"database {path}: {exc}") from exc
            except DatabaseError as exc:
                self.get_logger().error(f"database {path}: {exc}")
                raise
        params = RtabmapParameters.from_dict(self.effective_parameters(stored))
        core = Rtabmap(params, database=self.db)
        self.node_stamps = {n.id: n.stamp_ns for n in core.memory.nodes.values()}
        return core

    def _close_db(self) -> None:
        if self.db is not None:
            try:
                self.db.close(self.core)
            except Exception as exc:  # a failing close must not hide the shutdown
                self.get_logger().error(f"closing the database failed: {exc}")
            self.db = None

    def destroy_node(self) -> None:
        self._close_db()
        super().destroy_node()

    # -- processing ------------------------------------------------------------------------
    def _process(self, t: int, img: Any, depth_msg: Any | None, scan_msg: Any | None) -> bool:
        """Process one set; False when it was skipped (bad input, no odometry)."""
        from eddiebot.perception.errors import ImageSizeError, UnsupportedEncodingError

        if self._last_processed_ns is not None:
            if t <= self._last_processed_ns:
                self._warn_once("time_backwards",
                                "image time went backwards (bag restarted?): skipped")
                return False
            gap = (t - self._last_processed_ns) / _SEC
            if gap > 30.0:
                self._warn_once("time_jump", f"time jumped {gap:.1f} s forward")
        rgb_info = self._info_for(self._rgb_info, t, img.header.frame_id)
        if rgb_info is None:
            self._warn_once("no_camera_info", "an image arrived without camera_info: skipped")
            return False
        try:
            rgb = _image_array(img, _RGB_ENCODINGS)
        except (UnsupportedEncodingError, ImageSizeError) as exc:
            self._warn_once("bad_rgb", f"RGB image skipped: {exc}")
            return False
        if (int(img.width), int(img.height)) != (int(rgb_info.width), int(rgb_info.height)):
            self._warn_once("size_mismatch", f"RGB image {img.width}x{img.height} does not match "
                            f"camera_info {rgb_info.width}x{rgb_info.height}: skipped")
            return False
        if rgb.ndim == 2:
            rgb = np.repeat(rgb[:, :, None], 3, axis=2)
        elif img.encoding == "bgr8":
            rgb = np.ascontiguousarray(rgb[:, :, ::-1])
        rgb_frame = str(rgb_info.header.frame_id or img.header.frame_id)
        if depth_msg is None:
            self._warn_once("no_depth", "no depth image (subscribe_depth false): skipped")
            return False
        depth = self._depth_array(depth_msg, rgb_info, rgb_frame, t)
        if depth is None:
            return False
        if depth.shape[:2] != rgb.shape[:2]:
            fy, fx = rgb.shape[0] / depth.shape[0], rgb.shape[1] / depth.shape[1]
            if fx != fy or fx < 1 or fx != int(fx):
                self._warn_once("size_mismatch", f"depth {depth.shape[1]}x{depth.shape[0]} and "
                                f"RGB {rgb.shape[1]}x{rgb.shape[0]} differ: skipped")
                return False
            depth = np.repeat(np.repeat(depth, int(fx), axis=0), int(fx), axis=1)
        cam_pose = self._static_tf(self.frame_id, rgb_frame)
        if cam_pose is None:
            return False
        camera = CameraIntrinsics.from_k(rgb_info.k, int(rgb_info.width), int(rgb_info.height),
                                         cam_pose)
        odom_state = self._odometry_state(t)
        if odom_state == "lost":
            # RTAB-Map: the frames after lost odometry start a new map (nothing welds the jump)
            self._odom_reset_pending = True
            self._warn_once("odom_lost", "odometry is lost at an image's time: skipped; a new "
                            "map starts when it is back")
            return False
        try:
            odom = tf_matrix(self.tf_buffer.lookup_transform(
                self.odom_frame_id, self.frame_id, t + self._odom_offset_ns))
        except Exception as exc:
            self._warn_once("no_odom_tf", f"no odometry at an image's time: {exc}")
            return False
        scan = self._scan(scan_msg) if scan_msg is not None else None
        lin, ang = self.odom_tf_linear_variance, self.odom_tf_angular_variance
        cov = np.diag([lin, lin, lin, ang, ang, ang])
        if odom_state == "reset" or self._odom_reset_pending:
            cov = np.diag([9999.0] * 6)
            self._odom_reset_pending = False
        result = self.core.process(rgb, depth, camera, odom, t, scan, odom_covariance=cov)
        self.camera_transform = cam_pose
        if self.frame_track is not None:
            self.frame_track.tracked(t / _SEC, result, self._core_odometry(odom))
        self._last_processed_ns = t
        self.frames_processed += 1
        self.last_result = result
        self._publish_info(result, t)
        if self.core.localization_mode and result.pose is not None:
            self._publish_localization_pose(result.pose, t)
        if result.pose is None:
            self._warn_once("rejected", f"frame rejected: {result.rejection_reason}")
            return True
        if result.new_map:
            self.get_logger().info(f"odometry reset: map {result.map_id} started (its own "
                                   "frame until a loop closure merges it)")
        if result.maps_merged:
            self.get_logger().info(f"maps merged by the loop closure {result.node_id} → "
                                   f"{result.loop_closure_id or result.proximity_id}")
        if result.added:
            self.node_stamps[result.node_id] = t
            self._map_dirty = True
        if result.loop_closure_id or result.proximity_id:
            self.loop_closures += 1
            self._map_dirty = True
            self.get_logger().info(
                f"loop closure {result.node_id} → {result.loop_closure_id or result.proximity_id}")
        return True

    def _depth_array(self, depth_msg: Any, rgb_info: Any, rgb_frame: str, t: int
                     ) -> np.ndarray | None:
        from eddiebot.perception.errors import ImageSizeError, UnsupportedEncodingError
        from eddiebot.perception.register import register_depth

        depth_frame = str(depth_msg.header.frame_id)
        try:
            if depth_frame and depth_frame != rgb_frame:
                depth_info = self._info_for(self._depth_info, t, depth_frame)
                if depth_info is None:
                    self._warn_once("no_depth_info",
                                    "unregistered depth without depth camera_info: skipped")
                    return None
                t_rgb_depth = self._static_tf(rgb_frame, depth_frame)
                if t_rgb_depth is None:
                    return None
                depth_msg = register_depth(depth_msg, depth_info, rgb_info, t_rgb_depth)
            return _image_array(depth_msg, _DEPTH_ENCODINGS)
        except UnsupportedEncodingError as exc:
            self._warn_once("bad_depth", f"depth image skipped: {exc}")
        except ImageSizeError as exc:
            self._warn_once("size_mismatch", f"depth image skipped: {exc}")
        return None

    def _scan(self, msg: Any) -> Scan2D | None:
        lt = self._static_tf(self.frame_id, str(msg.header.frame_id))
        if lt is None:
            return None
        return Scan2D(np.asarray(msg.ranges, dtype=np.float32), float(msg.angle_min),
                      float(msg.angle_increment), float(msg.range_min), float(msg.range_max), lt)

    # -- services --------------------------------------------------------------------------
    def _srv_reset(self, req: Any, res: Any) -> Any:
        self._close_db()
        self.core = self._make_core(True)
        self._published_nodes.clear()
        self._pending.clear()
        self._unprocessed.clear()
        self._last_set_ns = self._last_processed_ns = None
        self._map_dirty = True
        self.get_logger().info("map reset (memory and database emptied)")
        return res

    def _srv_pause(self, req: Any, res: Any) -> Any:
        self.paused = True
        self.get_logger().info("paused")
        return res

    def _srv_resume(self, req: Any, res: Any) -> Any:
        self.paused = False
        self._last_set_ns = None
        self.get_logger().info("resumed")
        return res

    def _srv_publish_map(self, req: Any, res: Any) -> Any:
        self._publish_map(force=True)
        self.cloud_pub.publish(self.cloud_message())
        return res

    def _switch_mode(self, localization: bool) -> None:
        if localization == self.core.localization_mode:
            return
        self.localization = localization
        if not localization:
            for k in ("Mem/IncrementalMemory", "Mem/InitWMWithAllNodes"):
                self.explicit_parameters.pop(k, None)
        self._close_db()
        self.core = self._make_core(False)
        self._map_dirty = True
        self.get_logger().info("localization mode" if localization else "mapping mode")

    def _srv_localization(self, req: Any, res: Any) -> Any:
        self._switch_mode(True)
        return res

    def _srv_mapping(self, req: Any, res: Any) -> Any:
        self._switch_mode(False)
        return res

    def _srv_save_map(self, req: Any, res: Any) -> Any:
        grid = self.core.occupancy_grid()
        name = str(req.map_url) or "map"
        if grid is None:
            self.get_logger().error("save_map: no map yet")
            res.result = False
            return res
        try:
            save_map(grid.to_occupancy_map(self.map_frame_id), Path(name).expanduser())
            res.result = True
            self.get_logger().info(f"saved the map to {name}.yaml / {name}.pgm")
        except Exception as exc:
            self.get_logger().error(f"save_map {name!r} failed: {exc}")
            res.result = False
        return res

    def _srv_export_cloud(self, req: Any, res: Any) -> Any:
        name = str(req.name.data) or str(Path(self.database_path).expanduser().with_suffix(".ply"))
        try:
            xyz, colors = self.core.point_cloud(self.cloud_voxel_size)
            write_ply(Path(name).expanduser(), xyz, colors)
            res.result = PathRequest.Response.RESULT_SUCCESS
            self.get_logger().info(f"exported {xyz.shape[0]} points to {name}")
        except Exception as exc:
            self.get_logger().error(f"export_cloud {name!r} failed: {exc}")
            res.result = PathRequest.Response.RESULT_UNDEFINED_FAILURE
        return res

    # -- helpers for callers in the same process -------------------------------------------
    def trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """(stamps ns (N,), optimised base poses in the map frame (N, 4, 4)) of the kept nodes."""
        poses, _ = self.core.graph()
        ids = sorted(i for i in poses if i in self.node_stamps)
        if not ids:
            return np.zeros(0, np.int64), np.zeros((0, 4, 4))
        return (np.array([self.node_stamps[i] for i in ids], np.int64),
                np.stack([poses[i] for i in ids]))

