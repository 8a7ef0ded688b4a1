import numpy as np
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SessionDatabase
from eddiebot.vslam.export import read_ply, write_ply
from eddiebot.vslam.occupancy import Scan2D, local_grid_from_scan
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.rtabmap import Rtabmap

CAM = kinect_camera(320, 240)
BASE = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
        "Reg/Force3DoF": "true", "Vis/MinInliers": "12"}


def _turn(slam, n, start=0, seed=4):
    out = []
    for k in range(start, start + n):
        out.append(slam.process(*frame(seed, 4.0, 3.0, 0.26 * k), CAM,
                                planar_pose(0, 0, 0.26 * k), k * 1_000_000_000))
    return out


def test_memory_threshold_keeps_working_memory_bounded(tmp_path):
    with SessionDatabase(tmp_path / "m.db") as db:
        slam = Rtabmap({**BASE, "Mem/STMSize": "3", "Rtabmap/MemoryThr": "8"}, database=db)
        results = _turn(slam, 24)
        sizes = [r.statistics["Memory/Working_memory_size/"] for r in results]
        assert max(sizes) <= 8
        assert len(slam.memory.ltm) >= 10
        # transferred nodes left RAM (their data is in the database)
        assert all(slam.memory.nodes[i].data is None for i in slam.memory.ltm)
        assert slam.vocabulary.active_words < len(slam.vocabulary)
        assert len(db.node_ids()) == 24


def test_time_threshold_transfers_with_injected_timer():
    ticks = iter(np.arange(0.0, 1e6, 1.0))  # every timer read advances 1 s
    slam = Rtabmap({**BASE, "Mem/STMSize": "2", "Rtabmap/TimeThr": "700"},
                   timer=lambda: float(next(ticks)))
    results = _turn(slam, 8)
    assert sum(r.statistics["Memory/Transferred/"] for r in results) > 0
    assert len(slam.memory.ltm) > 0


def test_retrieval_brings_back_neighbours_of_a_revisited_place(tmp_path):
    with SessionDatabase(tmp_path / "r.db") as db:
        slam = Rtabmap({**BASE, "Mem/STMSize": "3", "Rtabmap/MemoryThr": "10"}, database=db)
        _turn(slam, 24)
        early = {1, 2, 3, 4, 5, 6}
        assert early & slam.memory.ltm
        results = _turn(slam, 4, start=24)  # the start of the turn again
        retrieved = sum(r.statistics["Memory/Retrieved/"] for r in results)
        assert retrieved > 0
        assert any(r.loop_closure_id for r in results)


def test_small_displacement_nodes_are_not_kept():
    slam = Rtabmap({**BASE, "RGBD/LinearUpdate": "0.1", "RGBD/AngularUpdate": "0.1"})
    rgb, depth = frame(3, 2.0, 3.0, 0.0)
    first = slam.process(rgb, depth, CAM, planar_pose(0, 0, 0), 0)
    second = slam.process(rgb, depth, CAM, planar_pose(0.05, 0, 0.05), 1)
    assert first.added and not second.added
    assert len(slam.memory.nodes) == 1
    third = slam.process(*frame(3, 2.2, 3.0, 0.0), CAM, planar_pose(0.2, 0, 0), 2)
    assert third.added and third.node_id == 3


def test_local_grids_and_global_map_and_cloud(tmp_path):
    slam = Rtabmap({**BASE, "RGBD/CreateOccupancyGrid": "true", "Grid/Sensor": "2",
                    "Grid/RangeMax": "8", "Grid/MaxObstacleHeight": "2.0"})
    ranges = np.full(181, 2.0, np.float32)
    scan = Scan2D(ranges, -np.pi / 2, np.pi / 180, 0.1, 10.0)
    for k in range(3):
        slam.process(*frame(3, 2.0 + 0.3 * k, 3.0, 0.0), CAM, planar_pose(0.3 * k, 0, 0),
                     k, scan=scan)
    grid = slam.occupancy_grid()
    assert grid is not None
    occupied = np.argwhere(grid.data == 100)
    free = np.argwhere(grid.data == 0)
    assert occupied.shape[0] > 50 and free.shape[0] > 50
    # the wall at x = 8 m in the room is 6 m ahead of the first pose (room x = 2 m)
    xs = (occupied[:, 1] + 0.5) * grid.resolution + grid.origin_x
    ys = (occupied[:, 0] + 0.5) * grid.resolution + grid.origin_y
    wall = np.abs(xs - 6.0) < 0.1
    assert wall.sum() >= 10
    # the scan's 2 m ring is there too
    assert np.any(np.abs(np.hypot(xs, ys) - 2.0) < 0.1)
    omap = grid.to_occupancy_map()
    assert omap.data.shape == grid.data.shape and omap.origin[0] == grid.origin_x
    xyz, rgb = slam.point_cloud(voxel_size=0.05)
    write_ply(tmp_path / "cloud.ply", xyz, rgb)
    back, colours = read_ply(tmp_path / "cloud.ply")
    assert back.shape == xyz.shape and colours is not None
    np.testing.assert_allclose(back, xyz, atol=1e-5)


def test_scan_grid_marks_free_rays_and_obstacles():
    params = RtabmapParameters()
    scan = Scan2D(np.array([1.0, 1.0, 1.0], np.float32), -0.1, 0.1, 0.1, 5.0)
    g = local_grid_from_scan(scan, params)
    assert g.obstacles.shape[0] >= 1
    assert np.all(np.abs(np.hypot(g.obstacles[:, 0], g.obstacles[:, 1]) - 1.0) < 0.08)
    assert g.empty.shape[0] >= 15


def _box_scan(x, y, yaw, size=(8.0, 6.0)):
    angles = -np.pi / 2 + np.arange(181) * np.pi / 180
    d = np.stack([np.cos(angles + yaw), np.sin(angles + yaw)], axis=1)
    with np.errstate(divide="ignore"):
        tx = np.where(d[:, 0] > 0, (size[0] - x) / d[:, 0], -x / d[:, 0])
        ty = np.where(d[:, 1] > 0, (size[1] - y) / d[:, 1], -y / d[:, 1])
    ranges = np.minimum(np.abs(tx), np.abs(ty)).astype(np.float32)
    return Scan2D(ranges, -np.pi / 2, np.pi / 180, 0.1, 10.0)


def test_neighbour_link_refined_by_scan_matching():
    slam = Rtabmap({**BASE, "RGBD/NeighborLinkRefining": "true"})
    slam.process(*frame(3, 2.0, 3.0, 0.0), CAM, planar_pose(0, 0, 0), 0,
                 scan=_box_scan(2.0, 3.0, 0.0))
    # odometry under-reports the motion (0.25 m, no turn) of a true (0.3 m, 0.05 rad) step
    slam.process(*frame(3, 2.3, 3.0, 0.05), CAM, planar_pose(0.25, 0.0, 0.0), 1,
                 scan=_box_scan(2.3, 3.0, 0.05))
    link = slam.memory.links[1][2]
    assert abs(link.transform[0, 3] - 0.3) < 0.02
    assert abs(np.arctan2(link.transform[1, 0], link.transform[0, 0]) - 0.05) < 0.01


def test_node_data_keeps_points_in_float32_and_hands_out_float64():
    from eddiebot.vslam.features import FrameFeatures
    from eddiebot.vslam.nodes import NodeData

    rng = np.random.default_rng(3)
    n = 900
    points = rng.uniform(-4.0, 4.0, (n, 3))
    points[::10] = np.nan  # no depth
    feats = FrameFeatures(rng.uniform(0, 640, (n, 2)).astype(np.float32),
                          np.ones(n, np.float32), np.full(n, 31.0, np.float32),
                          np.zeros(n, np.float32), np.zeros(n, np.int32),
                          rng.integers(0, 256, (n, 32), dtype=np.uint8), points)
    data = NodeData(feats, np.arange(n, dtype=np.int64))
    out = data.features
    assert out.points.dtype == np.float64
    np.testing.assert_array_equal(np.isnan(out.points), np.isnan(points))
    assert np.nanmax(np.abs(out.points - points)) < 3e-7  # float32 within 4 m
    np.testing.assert_array_equal(out.descriptors, feats.descriptors)
    # a feature costs 8 (uv) + 16 (response, size, angle, octave) + 32 (ORB) + 12 (point)
    # + 8 (word id) bytes: 76 kB for 1,000 features
    assert data.nbytes == n * 76
    out.points[:] = 0.0  # handed-out arrays are the caller's
    assert np.nanmax(np.abs(data.features.points - points)) < 3e-7
