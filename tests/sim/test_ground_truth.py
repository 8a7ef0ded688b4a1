"""Ground-truth maps: office corridor free, walls occupied, tables, caching."""

from __future__ import annotations

import numpy as np

from eddiebot.maps import world_to_map
from eddiebot.sim import cached_ground_truth, footprint_map, load_world, scan_slice_map


def _at(grid, x, y):
    c = world_to_map(grid, np.array([[x, y]]))[0]
    return int(grid.data[c[1], c[0]])


def test_office_corridor_free_walls_occupied():
    w = load_world("office")
    scan, foot = scan_slice_map(w), footprint_map(w)
    assert scan.resolution == 0.05
    for grid in (scan, foot):
        for x in np.arange(0.5, 19.5, 0.25):
            assert _at(grid, x, 7.5) == 0  # corridor
        for x in np.arange(0.2, 19.8, 0.5):
            assert _at(grid, x, 0.0) == 100 and _at(grid, x, 15.0) == 100  # outer walls
        assert _at(grid, 1.0, 6.5) == 100  # corridor wall
        assert _at(grid, 2.45, 6.5) == 0  # an open doorway (its door swung into the room)
        assert _at(grid, 12.45, 6.5) == 100  # a closed door
    assert 0.05 < (scan.data == 100).mean() < 0.3


def test_tables_and_low_things():
    w = load_world("house")
    scan, foot = scan_slice_map(w), footprint_map(w)
    # dining table (top 0.71–0.75 m) at (4.5, 1.6): both the scan and the robot (0.65 m)
    # pass under its top; its 5 cm legs are in both maps
    assert _at(scan, 4.5, 1.6) == 0 and _at(foot, 4.5, 1.6) == 0
    assert _at(scan, 4.5 - 0.775, 1.6 - 0.425) == 100
    assert _at(foot, 4.5 - 0.775, 1.6 - 0.425) == 100
    # the coffee table (0.42 m) and the bed (0.5 m) are only in the footprint
    assert _at(scan, 2.6, 4.2) == 0 and _at(foot, 2.6, 4.2) == 100
    assert _at(scan, 2.0, 8.6) == 0 and _at(foot, 2.0, 8.6) == 100


def test_cache_round_trip(tmp_path):
    w = load_world("maze")
    a = cached_ground_truth(w, directory=tmp_path)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert len(files) == 4 and any(f.endswith("-scan.yaml") for f in files)
    b = cached_ground_truth(w, directory=tmp_path)
    assert np.array_equal(a.scan.data, b.scan.data) and np.array_equal(a.footprint.data, b.footprint.data)
    assert a.scan.origin == b.scan.origin


def test_simulated_scan_lands_on_the_scan_ground_truth():
    """Render → depthimage_to_laserscan → world points fall on the scan-slice map."""
    import math

    from scipy.ndimage import binary_dilation

    from eddiebot.perception import DepthToScanParams, depth_image_to_laserscan
    from eddiebot.sim import KinectConfig, Renderer, camera_info_msg, depth_image_msg

    w = load_world("office")
    cfg = KinectConfig(noise_disparity_sigma=0.0, dropout=0.0, edge_dropout=0.0)
    scan_map = scan_slice_map(w)
    occupied = binary_dilation(scan_map.data == 100, iterations=1)
    r = Renderer(w, cfg)
    for pose in (w.start, (6.0, 3.0, 1.0), (15.0, 12.0, -2.0)):
        depth = r.depth(pose)
        scan = depth_image_to_laserscan(depth_image_msg(depth), camera_info_msg(cfg.depth),
                                        DepthToScanParams(scan_height=1, range_max=8.0))
        ang = scan.angle_min + np.arange(len(scan.ranges)) * scan.angle_increment
        ok = np.isfinite(scan.ranges)
        x, y, th = pose
        px, py, _ = cfg.depth_position
        cx = x + math.cos(th) * px - math.sin(th) * py
        cy = y + math.sin(th) * px + math.cos(th) * py
        wx = cx + scan.ranges[ok] * np.cos(th + ang[ok])
        wy = cy + scan.ranges[ok] * np.sin(th + ang[ok])
        cells = world_to_map(scan_map, np.column_stack([wx, wy]))
        hits = occupied[cells[:, 1], cells[:, 0]]
        assert ok.sum() > 300, pose
        assert hits.mean() > 0.97, (pose, hits.mean())
