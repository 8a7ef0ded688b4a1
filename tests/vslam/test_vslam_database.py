import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from vslam_synthetic import frame, kinect_camera, planar_pose

from eddiebot.vslam.database import SCHEMA_VERSION, SessionDatabase
from eddiebot.vslam.errors import (
    DatabaseCorruptError,
    DatabaseLockedError,
    DatabaseVersionError,
)
from eddiebot.vslam.rtabmap import Rtabmap

CAM = kinect_camera(320, 240)
PARAMS = {"RGBD/LinearUpdate": "0.05", "RGBD/ProximityBySpace": "false",
          "Reg/Force3DoF": "true", "Vis/MinInliers": "12", "RGBD/CreateOccupancyGrid": "true"}
HERE = Path(__file__).resolve().parent


def _map(db_path, n=6, delete=True):
    db = SessionDatabase(db_path, delete_on_start=delete)
    slam = Rtabmap(PARAMS, database=db)
    for k in range(n):
        slam.process(*frame(3, 2.0 + 0.2 * k, 3.0, 0.0), CAM, planar_pose(0.2 * k, 0, 0),
                     k * 1_000_000_000)
    return db, slam


def test_round_trip(tmp_path):
    path = tmp_path / "map.db"
    db, slam = _map(path)
    node2 = slam.memory.nodes[2].data
    db.close(slam)
    with SessionDatabase(path) as db2:
        assert db2.node_ids() == [1, 2, 3, 4, 5, 6]
        links = db2.links()
        assert sorted((lk.from_id, lk.to_id) for lk in links if lk.type == 0) == [
            (1, 2), (2, 3), (3, 4), (4, 5), (5, 6)]
        assert db2.last_parameters()["Vis/MinInliers"] == "12"
        poses = db2.optimized_poses()
        np.testing.assert_allclose(poses[6][:2, 3], [1.0, 0.0], atol=1e-5)
        data = db2.load_node_data(2)
        np.testing.assert_array_equal(data.words, node2.words)
        np.testing.assert_array_equal(data.features.descriptors, node2.features.descriptors)
        np.testing.assert_allclose(data.features.points, node2.features.points, atol=1e-9)
        assert data.grid is not None and data.grid.obstacles.shape[0] > 10
        rgb, depth = db2.image(2)
        assert rgb.shape == (240, 320, 3) and depth.dtype == np.uint16
        np.testing.assert_array_equal(depth, frame(3, 2.2, 3.0, 0.0)[1])


def test_reopen_continues_mapping_with_new_session(tmp_path):
    path = tmp_path / "map.db"
    db, slam = _map(path)
    db.close(slam)
    db = SessionDatabase(path)
    slam = Rtabmap(PARAMS, database=db)
    assert slam.map_id == 1 and len(slam.memory.wm) == 6
    r = slam.process(*frame(3, 2.6, 3.0, 0.0), CAM, planar_pose(0, 0, 0), 10_000_000_000)
    assert r.node_id == 7
    # the new session is joined to the old map by a loop closure to the same place
    r = slam.process(*frame(3, 2.61, 3.0, 0.0), CAM, planar_pose(0.0, 0.0, 0.0), 11_000_000_000)
    db.close(slam)
    with SessionDatabase(path) as db2:
        maps = {n.id: n.map_id for n in db2.nodes()}
        assert maps[7] == 1 and maps[1] == 0


def test_localization_mode_writes_nothing(tmp_path):
    path = tmp_path / "map.db"
    db, slam = _map(path)
    db.close(slam)
    size = path.stat().st_size
    db = SessionDatabase(path)
    loc = Rtabmap({**PARAMS, "Mem/IncrementalMemory": "false", "Rtabmap/LoopThr": "0.05"},
                  database=db)
    results = [loc.process(*frame(3, 2.4 + 0.01 * k, 3.05, 0.0), CAM,
                           planar_pose(0.01 * k, 0, 0), k) for k in range(4)]
    assert all(not r.added for r in results)
    assert any(r.localized for r in results)
    loc_pose = [r for r in results if r.localized][-1].pose
    np.testing.assert_allclose(loc_pose[:2, 3], [0.43, 0.05], atol=0.03)
    assert len(db.node_ids()) == 6
    db.close(loc)
    assert path.stat().st_size == size


def test_uncommitted_frame_is_lost_and_reopen_works(tmp_path):
    path = tmp_path / "crash.db"
    script = textwrap.dedent(f"""
        import os, sys
        sys.path.insert(0, {str(HERE)!r})
        from vslam_synthetic import frame, kinect_camera, planar_pose
        from eddiebot.vslam.database import SessionDatabase
        from eddiebot.vslam.rtabmap import Rtabmap
        cam = kinect_camera(320, 240)
        db = SessionDatabase({str(path)!r}, delete_on_start=True)
        slam = Rtabmap({PARAMS!r}, database=db)
        for k in range(3):
            slam.process(*frame(3, 2.0 + 0.2 * k, 3.0, 0.0), cam, planar_pose(0.2 * k, 0, 0), k)
        conn = db._conn
        conn.execute("BEGIN IMMEDIATE")
        conn.execute("INSERT INTO Node (id, map_id, weight, stamp, stamp_ns, pose) "
                     "VALUES (99, 0, 0, 0, 0, zeroblob(48))")
        os._exit(3)  # crash mid-transaction
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 3, proc.stderr
    with SessionDatabase(path) as db:
        assert db.node_ids() == [1, 2, 3]
        slam = Rtabmap(PARAMS, database=db)
        r = slam.process(*frame(3, 2.6, 3.0, 0.0), CAM, planar_pose(0, 0, 0), 10)
        assert r.node_id == 4


def test_newer_version_is_refused_and_untouched(tmp_path):
    path = tmp_path / "new.db"
    db, slam = _map(path, n=2)
    db.close(slam)
    conn = sqlite3.connect(path)
    conn.execute(f"PRAGMA user_version={SCHEMA_VERSION + 1}")
    conn.close()
    before = path.read_bytes()
    with pytest.raises(DatabaseVersionError, match="newer"):
        SessionDatabase(path)
    assert path.read_bytes() == before


def test_corrupt_and_foreign_files_are_refused(tmp_path):
    garbage = tmp_path / "garbage.db"
    garbage.write_bytes(b"this is not sqlite" * 100)
    before = garbage.read_bytes()
    with pytest.raises(DatabaseCorruptError):
        SessionDatabase(garbage)
    assert garbage.read_bytes() == before
    foreign = tmp_path / "foreign.db"
    conn = sqlite3.connect(foreign)
    conn.execute("CREATE TABLE t (x)")
    conn.commit()
    conn.close()
    with pytest.raises(DatabaseCorruptError, match="not an eddiebot"):
        SessionDatabase(foreign)
    # a valid database with a damaged page
    damaged = tmp_path / "damaged.db"
    db, slam = _map(damaged, n=3)
    db.close(slam)
    raw = bytearray(damaged.read_bytes())
    raw[len(raw) // 2: len(raw) // 2 + 4096] = b"\xff" * 4096
    damaged.write_bytes(bytes(raw))
    with pytest.raises(DatabaseCorruptError):
        SessionDatabase(damaged)


def test_locked_database_and_delete_on_start(tmp_path):
    path = tmp_path / "lock.db"
    db, slam = _map(path, n=2)
    with pytest.raises(DatabaseLockedError):
        SessionDatabase(path)
    db.close(slam)
    with SessionDatabase(path, delete_on_start=True) as fresh:
        assert fresh.node_ids() == []
