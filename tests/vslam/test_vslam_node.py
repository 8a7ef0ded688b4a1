"""The ``rtabmap`` node on a sim context with synthetic RGB-D frames and TF odometry."""

import logging
import shutil

import numpy as np
from vslam_synthetic import frame, kinect_camera

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_latched
from eddiebot.core.tf import Buffer, TransformListener, make_transform, make_transform_2d
from eddiebot.geometry import matrix_to_quaternion
from eddiebot.msgs.sensor_msgs import CameraInfo, Image
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.sim.camera import camera_info_msg, depth_image_msg, rgb_image_msg
from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.node import RtabmapNode, parse_rtabmap_args

CAM = kinect_camera(320, 240)
OPTICAL = "camera_rgb_optical_frame"
SEC = 1_000_000_000


class Rig:
    """A sim context with the node, a sensor publisher and a TF listener."""

    def __init__(self, tmp_path, **params):
        self.context = Context(use_sim_time=True)
        overrides = {"use_sim_time": True, "database_path": str(tmp_path / "rtabmap.db"),
                     "delete_db_on_start": True, "Rtabmap/DetectionRate": "0",
                     "Reg/Force3DoF": "true", "RGBD/LinearUpdate": "0.05",
                     "RGBD/ProximityBySpace": "false", "Vis/MinInliers": "12"}
        overrides.update(params)
        self.slam = RtabmapNode(context=self.context, parameter_overrides=overrides)
        self.pub = Node("sensors", context=self.context)
        self.rgb = self.pub.create_publisher(Image, "/image_raw", 10)
        self.info = self.pub.create_publisher(CameraInfo, "/camera_info", 10)
        self.depth = self.pub.create_publisher(Image, "/depth/image_raw", 10)
        self.tf = self.pub.create_publisher(TFMessage, "/tf", 100)
        self.tf_static = self.pub.create_publisher(TFMessage, "/tf_static", qos_profile_latched)
        lt = CAM.local_transform
        q = matrix_to_quaternion(lt[:3, :3])
        self.tf_static.publish(TFMessage(transforms=[make_transform(
            "base_footprint", OPTICAL, 0, *(float(v) for v in lt[:3, 3]), *(float(v) for v in q))]))
        self.listener_node = Node("listener", context=self.context)
        self.buffer = Buffer(node=self.listener_node)
        self.listener = TransformListener(self.buffer, self.listener_node)
        self.ex = SingleThreadedExecutor(context=self.context)
        for n in (self.slam, self.pub, self.listener_node):
            self.ex.add_node(n)

    def odom(self, t, x, y=0.0, yaw=0.0):
        self.tf.publish(TFMessage(transforms=[
            make_transform_2d("odom", "base_footprint", t, x, y, yaw)]))

    def frame(self, t, x, *, rgb=None, depth=None, info=True, odom=True, encoding=None):
        if t > self.context.sim_clock.now_ns():
            self.ex.spin_until(t)
        if odom:
            self.odom(t, x)
        r, d = frame(3, 2.0 + x, 3.0, 0.0)
        rgb_msg = rgb_image_msg(r if rgb is None else rgb, t, OPTICAL)
        if encoding:
            rgb_msg.encoding = encoding
        if info:
            self.info.publish(camera_info_msg(CAM, t, OPTICAL))
        self.rgb.publish(rgb_msg)
        self.depth.publish(depth_image_msg(d if depth is None else depth, t, OPTICAL))
        self.ex.spin_until_idle()
        if odom:
            self.odom(t + SEC // 10, x)  # odometry just after the image, as a real driver
        self.ex.spin_for(0.3)

    def close(self):
        for n in (self.listener_node, self.pub, self.slam):
            n.destroy_node()
        self.context.shutdown()


def _nodes(rig):
    return len(rig.slam.core.memory.nodes)


def test_maps_frames_publishes_map_to_odom_and_leaves_a_reopenable_database(tmp_path):
    rig = Rig(tmp_path)
    try:
        for k in range(6):
            rig.frame(SEC + k * SEC, 0.2 * k)
        assert rig.slam.frames_processed == 6
        assert _nodes(rig) >= 5
        rig.ex.spin_for(0.2)
        tf = rig.buffer.lookup_transform("map", "odom", 0)
        # odometry is exact here: the correction stays (close to) identity
        assert abs(tf.transform.translation.x) < 0.05 and abs(tf.transform.translation.y) < 0.05
        stamps, poses = rig.slam.trajectory()
        assert len(stamps) == _nodes(rig)
        np.testing.assert_allclose(poses[-1][0, 3], 1.0, atol=0.05)
        # a killed process leaves what was committed: a copy taken now reopens with every node
        shutil.copy(tmp_path / "rtabmap.db", tmp_path / "copy.db")
        with SessionDatabase(tmp_path / "copy.db") as db:
            assert len(db.node_ids()) == _nodes(rig)
    finally:
        rig.close()
    with SessionDatabase(tmp_path / "rtabmap.db") as db:
        assert len(db.optimized_poses()) >= 5  # the clean shutdown saved the optimised graph


def test_bad_input_is_skipped_with_one_warning_each(tmp_path, caplog):
    rig = Rig(tmp_path)
    caplog.set_level(logging.WARNING)
    try:
        rig.frame(SEC, 0.0)
        n0 = _nodes(rig)
        t = 2 * SEC
        for _ in range(2):  # every kind twice: one warning only
            rig.frame(t, 0.2, encoding="bgra8")  # unsupported encoding
            t += SEC
            rig.frame(t, 0.2, rgb=np.zeros((100, 100, 3), np.uint8))  # size ≠ camera_info
            t += SEC
            rig.frame(t, 0.2, depth=np.zeros((120, 100), np.uint16))  # depth size mismatch
            t += SEC
            rig.frame(t, 0.2, odom=False)  # no odometry at the image's time
            t += SEC
        assert _nodes(rig) == n0, "no node from bad input"
        rig.frame(SEC // 2, 0.0)  # time going backwards
        rig.frame(SEC // 2 + 1, 0.0)
        messages = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
        for kind in ("bad_rgb", "size_mismatch", "no_odom_tf", "time_backwards"):
            assert sum(f"'{kind}'" in m for m in messages) == 1, (kind, messages)
        assert _nodes(rig) == n0
        # good frames after all that are mapped again
        rig.frame(t, 0.4)
        rig.frame(t + SEC, 0.6)
        assert _nodes(rig) == n0 + 2
    finally:
        rig.close()


def test_lost_odometry_never_becomes_a_pose(tmp_path, caplog):
    from eddiebot.msgs.nav_msgs import Odometry
    from eddiebot.msgs.std_msgs import Header

    rig = Rig(tmp_path)
    caplog.set_level(logging.WARNING)
    odom_pub = rig.pub.create_publisher(Odometry, "/odom", 10)
    try:
        rig.frame(SEC, 0.0)
        n0 = _nodes(rig)
        lost = Odometry(header=Header(frame_id="odom"))
        lost.header.stamp.sec = 2
        lost.pose.pose.orientation.w = 0.0  # rtabmap_odom's "lost" message: null pose
        lost.pose.covariance = np.full(36, 9999.0)
        odom_pub.publish(lost)
        rig.frame(2 * SEC, 0.2)
        assert _nodes(rig) == n0
        assert any("'odom_lost'" in r.getMessage() for r in caplog.records)
        # odometry back (TF again): the next node starts a new map, with no link to the last
        rig.frame(3 * SEC, 0.4)
        result = rig.slam.last_result
        assert result is not None and result.new_map and result.map_id == 1
        assert _nodes(rig) == n0 + 1
        assert not rig.slam.core.memory.links.get(result.node_id)
        rig.frame(4 * SEC, 0.6)
        assert rig.slam.last_result.map_id == 1 and not rig.slam.last_result.new_map
    finally:
        rig.close()


def test_parameters_from_args_nested_keys_and_localization(tmp_path):
    params, delete, ignored = parse_rtabmap_args("-d --Reg/Force3DoF true --Vis/MinInliers=15 --udebug")
    assert params == {"Reg/Force3DoF": "true", "Vis/MinInliers": "15"} and delete
    assert ignored == ["--udebug"]
    rig = Rig(tmp_path, **{"Reg.Force3DoF": False, "rtabmap_args": "--Vis/MinInliers 15",
                           "Optimizer/Strategy": "1"})
    try:
        p = rig.slam.core.params
        assert p.reg_force_3dof is False and p.vis_min_inliers == 15
        assert p.rgbd_create_occupancy_grid  # forced by the ROS node
    finally:
        rig.close()
    # localization on the map just made: the database's nodes are loaded, none added
    rig = Rig(tmp_path, delete_db_on_start=False, localization=True)
    try:
        assert rig.slam.core.localization_mode
        assert rig.slam.core.params.mem_init_wm_with_all_nodes
    finally:
        rig.close()


def test_pause_resume_and_reset_services(tmp_path):
    from eddiebot.msgs.std_srvs import Empty

    rig = Rig(tmp_path)
    try:
        rig.frame(SEC, 0.0)
        rig.slam._srv_pause(Empty.Request(), Empty.Response())
        rig.frame(2 * SEC, 0.2)
        rig.frame(3 * SEC, 0.4)
        assert rig.slam.frames_processed == 1
        rig.slam._srv_resume(Empty.Request(), Empty.Response())
        rig.frame(4 * SEC, 0.6)
        assert rig.slam.frames_processed == 2
        rig.slam._srv_reset(Empty.Request(), Empty.Response())
        assert _nodes(rig) == 0
    finally:
        rig.close()


def test_incremental_graph_matches_batch_and_survives_a_removed_closure():
    """The Force3DoF back end (iSAM2 on the 2D SLAM's PoseGraph) against gtsam batch LM."""
    from eddiebot.vslam.graph import GraphLink, GtsamPoseGraph, IncrementalPose2Graph
    from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

    lap = 40

    def truth(k):
        a = 2 * np.pi * (k % lap) / lap
        return from_xyz_yaw(3 * np.cos(a), 3 * np.sin(a), a + np.pi / 2)

    info = np.diag([1e3, 1e3, 1.0, 1.0, 1.0, 1e3])
    inc, batch = IncrementalPose2Graph(), GtsamPoseGraph(True, incremental=False)
    poses = {1: truth(0)}
    dead = truth(0)
    links = []
    for k in range(1, 100):
        step = se3_inverse(truth(k - 1)) @ truth(k)
        step = step @ from_xyz_yaw(0.0, 0.0, 0.01)  # odometry heading drifts
        links.append(GraphLink(k, k + 1, step, info))
        poses[k + 1] = poses[k] @ step
        dead = dead @ step
        if k > lap and k % 5 == 0:
            links.append(GraphLink(k + 1, k + 1 - lap, se3_inverse(truth(k)) @ truth(k - lap), info))
            poses.update(inc.optimize(poses, links, 1, 20))
    ref = batch.optimize(poses, links, 1, 100)
    out = inc.optimize(poses, links, 1, 20)
    assert max(np.linalg.norm(out[i][:2, 3] - ref[i][:2, 3]) for i in ref) < 0.01
    err = np.linalg.norm(out[100][:2, 3] - truth(99)[:2, 3])
    assert err < 0.5 * np.linalg.norm(dead[:2, 3] - truth(99)[:2, 3])
    # a closure the core rejected after the fact (OptimizeMaxError) is gone on the next call
    bad = GraphLink(100, 50, from_xyz_yaw(5.0, 0.0, 0.0), info)
    inc.optimize(poses, [*links, bad], 1, 20)
    again = inc.optimize(poses, links, 1, 20)
    assert inc.rebuilds >= 1
    assert max(np.linalg.norm(again[i][:2, 3] - ref[i][:2, 3]) for i in ref) < 0.01


def test_publishes_grid_on_map_graph_data_and_info(tmp_path):
    from eddiebot.msgs import serialize
    from eddiebot.msgs.nav_msgs import OccupancyGrid
    from eddiebot.msgs.rtabmap_msgs import Info, MapData, MapGraph

    rig = Rig(tmp_path, **{"Grid/RayTracing": "true", "map_update_interval": 0.5})
    got: dict[str, list] = {"map": [], "graph": [], "data": [], "info": []}
    sub = Node("viewer", context=rig.context)
    rig.ex.add_node(sub)
    try:
        for k in range(5):
            rig.frame(SEC + k * SEC, 0.2 * k)
        assert rig.slam.map_topic == "/map"
        # late subscribers of the latched topics get the last message
        sub.create_subscription(OccupancyGrid, "/map", got["map"].append, qos_profile_latched)
        sub.create_subscription(MapGraph, "/rtabmap/mapGraph", got["graph"].append,
                                qos_profile_latched)
        sub.create_subscription(MapData, "/rtabmap/mapData", got["data"].append,
                                qos_profile_latched)
        sub.create_subscription(Info, "/rtabmap/info", got["info"].append, 10)
        rig.frame(6 * SEC, 1.0)
        rig.ex.spin_for(1.0)
        assert got["map"] and got["map"][-1].header.frame_id == "map"
        grid = np.asarray(got["map"][-1].data)
        assert (grid == 0).sum() > 100 and (grid == 100).sum() > 20
        graph = got["graph"][-1]
        ids = [int(i) for i in graph.poses_id]
        assert ids == sorted(rig.slam.core.optimized_poses)
        assert len(graph.links) == len(ids) - 1  # a chain of neighbour links
        assert all(lk.type == 0 and lk.to_id == lk.from_id + 1 for lk in graph.links)
        assert abs(graph.poses[-1].position.x - 1.0) < 0.05
        # every node went out once in mapData
        sent = [n.id for m in got["data"] for n in m.nodes]
        assert len(sent) == len(set(sent))
        info = got["info"][-1]
        assert info.ref_id == ids[-1]
        assert "Timing/Total/ms" in info.stats_keys
        assert sorted(info.wm_state) == ids
        for msg, name in ((graph, "rtabmap_msgs/msg/MapGraph"), (info, "rtabmap_msgs/msg/Info"),
                          (got["data"][-1], "rtabmap_msgs/msg/MapData")):
            assert len(serialize(msg, name)) > 100
    finally:
        sub.destroy_node()
        rig.close()


def test_localization_publishes_localization_pose(tmp_path):
    from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped

    rig = Rig(tmp_path)
    try:
        for k in range(6):
            rig.frame(SEC + k * SEC, 0.2 * k)
    finally:
        rig.close()
    rig = Rig(tmp_path, delete_db_on_start=False, localization=True,
              **{"Rtabmap/LoopThr": "0.05", "RGBD/LinearUpdate": "0"})
    poses: list = []
    sub = Node("viewer", context=rig.context)
    sub.create_subscription(PoseWithCovarianceStamped, "/rtabmap/localization_pose",
                            poses.append, 10)
    rig.ex.add_node(sub)
    try:
        for k in range(4):
            rig.frame(10 * SEC + k * SEC, 0.4)
        assert len(poses) == 4 and rig.slam.core.localized
        last = poses[-1]
        assert last.header.frame_id == "map"
        assert abs(last.pose.pose.position.x - 0.4) < 0.03
        cov = np.asarray(last.pose.covariance).reshape(6, 6)
        assert 0 < cov[0, 0] < 0.01  # the localization's, not 9999
    finally:
        sub.destroy_node()
        rig.close()
