"""Session database: one SQLite file per map (schema in DATABASE.md).

Each kept node is written in its own transaction (node, data, features, words, links,
statistics), so a crash loses at most the frame being written. Opening checks the file before
writing anything: a file that is not an eddiebot session database, or fails SQLite's integrity
check, raises `DatabaseCorruptError`; a newer schema raises `DatabaseVersionError`; a file held
by another process raises `DatabaseLockedError`. The connection keeps an exclusive lock for as
long as it is open.
"""

from __future__ import annotations

import json
import sqlite3
import struct
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics, depth_to_meters
from eddiebot.vslam.errors import (
    DatabaseCorruptError,
    DatabaseError,
    DatabaseLockedError,
    DatabaseVersionError,
)
from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.memory import Link, LinkType, Node, NodeData
from eddiebot.vslam.occupancy import GlobalGrid, LocalGrid

if TYPE_CHECKING:
    from eddiebot.vslam.records import FrameRecord
    from eddiebot.vslam.rtabmap import Rtabmap

__all__ = ["SCHEMA_VERSION", "SessionDatabase", "is_session_database"]

SCHEMA_VERSION = 1
_APPLICATION_ID = 0x45444456  # "EDDV"
_CV_32F = 5
_CV_64F = 6
_CV_8U = 0
_TABLES = ("Admin", "Info", "Node", "Data", "Link", "Word", "Feature", "Statistics")

_SCHEMA = """
CREATE TABLE Admin (
  version TEXT NOT NULL, schema_version INTEGER NOT NULL,
  opt_ids BLOB, opt_poses BLOB, opt_map BLOB,
  opt_map_x_min REAL, opt_map_y_min REAL, opt_map_resolution REAL);
CREATE TABLE Info (
  session INTEGER PRIMARY KEY, map_id INTEGER NOT NULL, parameters TEXT NOT NULL,
  stm_size INTEGER, last_sign_added INTEGER, dictionary_size INTEGER);
CREATE TABLE Node (
  id INTEGER PRIMARY KEY, map_id INTEGER NOT NULL, weight INTEGER NOT NULL,
  stamp REAL NOT NULL, stamp_ns INTEGER NOT NULL, pose BLOB NOT NULL, label TEXT UNIQUE);
CREATE TABLE Data (
  id INTEGER PRIMARY KEY REFERENCES Node(id), image BLOB, depth BLOB, calibration TEXT,
  scan BLOB, scan_info BLOB, ground_cells BLOB, obstacle_cells BLOB, empty_cells BLOB,
  cell_size REAL, view_point_x REAL, view_point_y REAL, view_point_z REAL);
CREATE TABLE Link (
  from_id INTEGER NOT NULL, to_id INTEGER NOT NULL, type INTEGER NOT NULL,
  information_matrix BLOB NOT NULL, transform BLOB NOT NULL);
CREATE TABLE Word (id INTEGER PRIMARY KEY, descriptor_size INTEGER NOT NULL, descriptor BLOB NOT NULL);
CREATE TABLE Feature (
  node_id INTEGER NOT NULL, word_id INTEGER NOT NULL, pos_x REAL, pos_y REAL, size REAL,
  dir REAL, response REAL, octave INTEGER, depth_x REAL, depth_y REAL, depth_z REAL,
  descriptor_size INTEGER, descriptor BLOB);
CREATE TABLE Statistics (id INTEGER PRIMARY KEY, stamp REAL, data BLOB);
CREATE INDEX IDX_Feature_node_id ON Feature(node_id);
CREATE INDEX IDX_Link_from_id ON Link(from_id);
"""


# -- blob codecs ---------------------------------------------------------------------------
def pose_to_blob(t: NDArray[np.float64]) -> bytes:
    """4×4 → 12 float32, row-major [R|t] (RTAB-Map's pose blob)."""
    return np.asarray(t, np.float64)[:3, :4].astype("<f4").tobytes()


def blob_to_pose(b: bytes) -> NDArray[np.float64]:
    """12 float32 → 4×4."""
    t = np.eye(4)
    t[:3, :4] = np.frombuffer(b, "<f4").reshape(3, 4)
    return t


def compress_matrix(m: NDArray[Any], cv_type: int) -> bytes:
    """zlib(raw bytes + int32 rows, cols, OpenCV type), RTAB-Map's compressed-matrix layout."""
    cols = int(np.prod(m.shape[1:])) if m.ndim > 1 else 1
    m2 = m.reshape(m.shape[0], cols)
    raw = np.ascontiguousarray(m2).tobytes() + struct.pack("<3i", m2.shape[0], m2.shape[1], cv_type)
    return zlib.compress(raw)


def decompress_matrix(b: bytes | None, dtype: type) -> NDArray[Any] | None:
    """Inverse of `compress_matrix` (None stays None)."""
    if b is None:
        return None
    raw = zlib.decompress(b)
    rows, cols, _ = struct.unpack("<3i", raw[-12:])
    return np.frombuffer(raw[:-12], dtype).reshape(rows, cols).copy()


def encode_image(rgb: NDArray[np.uint8], fmt: str) -> bytes:
    """RGB/mono image → JPEG or PNG bytes."""
    img = rgb if rgb.ndim == 2 else cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(fmt, img)
    if not ok:
        raise DatabaseError(f"cannot encode image as {fmt}")
    return bytes(buf)


def decode_image(b: bytes) -> NDArray[np.uint8]:
    """JPEG/PNG bytes → RGB (or mono) image."""
    img = cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DatabaseCorruptError("undecodable image blob")
    out = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.asarray(out, dtype=np.uint8)


def encode_depth(depth: NDArray[np.generic]) -> bytes:
    """Depth → 16-bit PNG in millimetres (float metres are converted)."""
    d = depth if depth.dtype == np.uint16 else np.clip(
        np.rint(depth_to_meters(depth) * 1000.0), 0, 65535).astype(np.uint16)
    ok, buf = cv2.imencode(".png", np.asarray(d, dtype=np.uint16))
    if not ok:
        raise DatabaseError("cannot encode depth")
    return bytes(buf)


def decode_depth(b: bytes) -> NDArray[np.uint16]:
    """16-bit PNG → uint16 millimetres."""
    d = cv2.imdecode(np.frombuffer(b, np.uint8), cv2.IMREAD_UNCHANGED)
    if d is None:
        raise DatabaseCorruptError("undecodable depth blob")
    return d.astype(np.uint16)


def camera_to_json(c: CameraIntrinsics) -> str:
    """Calibration as JSON (fx, fy, cx, cy, width, height, local_transform 4×4)."""
    return json.dumps({
        "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "width": c.width, "height": c.height,
        "local_transform": np.asarray(c.local_transform).tolist(),
    })


def camera_from_json(s: str) -> CameraIntrinsics:
    """Inverse of `camera_to_json`."""
    d = json.loads(s)
    return CameraIntrinsics(d["fx"], d["fy"], d["cx"], d["cy"], d["width"], d["height"],
                            np.asarray(d["local_transform"], np.float64))


def is_session_database(path: str | Path) -> bool:
    """Whether `path` is an SQLite file carrying our application id (read-only look; an empty
    file counts, as a database that was created and never written)."""
    p = Path(path)
    if not p.is_file():
        return False
    if p.stat().st_size == 0:
        return True
    try:
        conn = sqlite3.connect(f"{p.resolve().as_uri()}?mode=ro", uri=True, timeout=0.0)
    except sqlite3.Error:
        return False
    try:
        return int(conn.execute("PRAGMA application_id").fetchone()[0]) == _APPLICATION_ID
    except sqlite3.OperationalError as exc:
        if "locked" in str(exc) or "busy" in str(exc):
            raise DatabaseLockedError(f"{p}: locked by another process") from exc
        return False
    except sqlite3.Error:
        return False
    finally:
        conn.close()


class SessionDatabase:
    """One map's SQLite file. Use as a context manager or call `close()`."""

    def __init__(self, path: str | Path, *, delete_on_start: bool = False,
                 image_format: str = ".jpg", read_only: bool = False) -> None:
        """Open (or create) the map at `path`.

        `delete_on_start` (RTAB-Map's ``delete_db_on_start``) erases an existing file first,
        but only one of ours: anything else raises `DatabaseCorruptError` and stays as it is.
        `read_only` opens an existing database without creating, locking for writing or
        changing anything (a missing file raises `DatabaseError`).
        """
        self.path = Path(path)
        self.image_format = image_format
        self.read_only = read_only
        if read_only and delete_on_start:
            raise ValueError("a read-only database cannot be deleted on start")
        if read_only and not self.path.is_file():
            raise DatabaseError(f"{self.path}: no such database")
        if delete_on_start:
            if self.path.exists() and not is_session_database(self.path):
                raise DatabaseCorruptError(
                    f"{self.path}: not an eddiebot vslam session database; refusing to delete "
                    "it (choose another database path)")
            for suffix in ("", "-journal", "-wal", "-shm"):
                p = Path(str(self.path) + suffix)
                if p.exists():
                    p.unlink()
        self._conn = self._open()
        self._session = 0

    # -- opening ----------------------------------------------------------------------------
    def _open(self) -> sqlite3.Connection:
        existed = self.path.exists() and self.path.stat().st_size > 0
        if self.read_only and not existed:
            raise DatabaseCorruptError(f"{self.path}: empty file, not a session database")
        try:
            if self.read_only:
                conn = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True,
                                       timeout=0.0, isolation_level=None)
            else:
                conn = sqlite3.connect(str(self.path), timeout=0.0, isolation_level=None)
        except sqlite3.Error as exc:
            raise DatabaseError(f"{self.path}: cannot open: {exc}") from exc
        try:
            if self.read_only:
                self._check(conn)
                return conn
            conn.execute("PRAGMA locking_mode=EXCLUSIVE")
            version = self._check(conn) if existed else None
            conn.execute("PRAGMA synchronous=NORMAL")
            if version is None:
                conn.executescript(
                    "BEGIN IMMEDIATE;" + _SCHEMA
                    + "INSERT INTO Admin (version, schema_version) VALUES"
                    f" ('eddiebot-vslam', {SCHEMA_VERSION});"
                    f"PRAGMA user_version={SCHEMA_VERSION};"
                    f"PRAGMA application_id={_APPLICATION_ID};COMMIT;"
                )
            else:
                # a write takes (and, in exclusive locking mode, keeps) the file lock
                conn.execute("BEGIN IMMEDIATE")
                conn.execute("UPDATE Admin SET version=version")
                conn.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            conn.close()
            if "locked" in str(exc) or "busy" in str(exc):
                raise DatabaseLockedError(f"{self.path}: locked by another process") from exc
            raise DatabaseError(f"{self.path}: {exc}") from exc
        except sqlite3.DatabaseError as exc:
            conn.close()
            raise DatabaseCorruptError(f"{self.path}: not a readable database: {exc}") from exc
        except DatabaseError:
            conn.close()
            raise
        return conn

    def _check(self, conn: sqlite3.Connection) -> int:
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        app = int(conn.execute("PRAGMA application_id").fetchone()[0])
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        if app != _APPLICATION_ID or not set(_TABLES) <= tables:
            raise DatabaseCorruptError(f"{self.path}: not an eddiebot vslam session database")
        if version > SCHEMA_VERSION:
            raise DatabaseVersionError(
                f"{self.path}: schema version {version} is newer than supported {SCHEMA_VERSION}"
            )
        result = conn.execute("PRAGMA quick_check").fetchone()[0]
        if result != "ok":
            raise DatabaseCorruptError(f"{self.path}: integrity check failed: {result}")
        return version

    # -- context --------------------------------------------------------------------------
    def __enter__(self) -> SessionDatabase:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self, rtabmap: Rtabmap | None = None) -> None:
        """Save the optimised graph/map of `rtabmap` (if given) in Admin and close the file."""
        if self._conn is None:
            return
        if rtabmap is not None and rtabmap.params.mem_incremental_memory:
            self.save_optimized(rtabmap.optimized_poses, rtabmap.occupancy_grid())
            self.save_weights({i: n.weight for i, n in rtabmap.memory.nodes.items()})
        self._conn.close()
        self._conn = None  # type: ignore[assignment]

    # -- reading ----------------------------------------------------------------------------
    def last_parameters(self) -> dict[str, str]:
        """Parameters of the last session ("Key:value;..." in Info)."""
        row = self._conn.execute("SELECT parameters FROM Info ORDER BY session DESC LIMIT 1").fetchone()
        if row is None or not row[0]:
            return {}
        out = {}
        for item in row[0].split(";"):
            if ":" in item:
                k, v = item.split(":", 1)
                out[k] = v
        return out

    def word_count(self) -> int:
        """Visual words stored (the dictionary)."""
        return int(self._conn.execute("SELECT COUNT(*) FROM Word").fetchone()[0])

    def node_ids(self) -> list[int]:
        """All stored node ids."""
        return [r[0] for r in self._conn.execute("SELECT id FROM Node ORDER BY id")]

    def nodes(self) -> list[Node]:
        """All nodes (poses only, no data)."""
        return [
            Node(int(i), int(m), int(ns), blob_to_pose(p), weight=int(w), label=label or "")
            for i, m, w, ns, p, label in self._conn.execute(
                "SELECT id, map_id, weight, stamp_ns, pose, label FROM Node ORDER BY id")
        ]

    def links(self) -> list[Link]:
        """All stored links."""
        out = []
        for f, t, ty, info, tr in self._conn.execute(
                "SELECT from_id, to_id, type, information_matrix, transform FROM Link"):
            out.append(Link(int(f), int(t), LinkType(int(ty)), blob_to_pose(tr),
                            np.frombuffer(info, "<f8").reshape(6, 6).copy()))
        return out

    def optimized_poses(self) -> dict[int, NDArray[np.float64]]:
        """Admin.opt_poses saved at the last close (empty if none)."""
        row = self._conn.execute("SELECT opt_ids, opt_poses FROM Admin").fetchone()
        if row is None or row[0] is None:
            return {}
        ids = np.frombuffer(row[0], "<i8")
        poses = np.frombuffer(row[1], "<f4").reshape(-1, 3, 4)
        out = {}
        for i, p in zip(ids, poses):
            t = np.eye(4)
            t[:3, :4] = p
            out[int(i)] = t
        return out

    def image(self, node_id: int) -> tuple[NDArray[np.uint8] | None, NDArray[np.uint16] | None]:
        """Decoded RGB image and depth (mm) of a node."""
        row = self._conn.execute("SELECT image, depth FROM Data WHERE id=?", (node_id,)).fetchone()
        if row is None:
            return None, None
        return (decode_image(row[0]) if row[0] else None,
                decode_depth(row[1]) if row[1] else None)

    def frame(self, node_id: int) -> tuple[NDArray[np.uint8] | None, NDArray[np.uint16] | None,
                                           CameraIntrinsics | None]:
        """Decoded RGB image, depth (mm) and camera of a node (None where not stored)."""
        row = self._conn.execute("SELECT image, depth, calibration FROM Data WHERE id=?",
                                 (node_id,)).fetchone()
        if row is None:
            return None, None, None
        return (decode_image(row[0]) if row[0] else None,
                decode_depth(row[1]) if row[1] else None,
                camera_from_json(row[2]) if row[2] else None)

    def load_node_data(self, node_id: int) -> NodeData | None:
        """Features, word ids, local grid and scan of a node (for retrieval from LTM)."""
        rows = self._conn.execute(
            "SELECT word_id, pos_x, pos_y, size, dir, response, octave, depth_x, depth_y, depth_z,"
            " descriptor FROM Feature WHERE node_id=? ORDER BY rowid", (node_id,)).fetchall()
        data = self._conn.execute(
            "SELECT ground_cells, obstacle_cells, empty_cells, cell_size, view_point_x,"
            " view_point_y, view_point_z, scan FROM Data WHERE id=?", (node_id,)).fetchone()
        if data is None:
            return None
        n = len(rows)
        if n:
            # SQLite stores NaN (no depth) as NULL
            arr = np.array([[np.nan if v is None else v for v in r[:10]] for r in rows],
                           dtype=np.float64)
            desc = np.frombuffer(b"".join(r[10] for r in rows), np.uint8).reshape(n, 32).copy()
        else:
            arr = np.zeros((0, 10))
            desc = np.zeros((0, 32), np.uint8)
        feats = FrameFeatures(
            arr[:, 1:3].astype(np.float32), arr[:, 5].astype(np.float32),
            arr[:, 3].astype(np.float32), arr[:, 4].astype(np.float32),
            arr[:, 6].astype(np.int32), desc, arr[:, 7:10].copy(),
        )
        grid = None
        if data[3] is not None:
            def cells(b: bytes | None) -> NDArray[np.float32]:
                m = decompress_matrix(b, np.float32)
                return np.zeros((0, 2), np.float32) if m is None else m.reshape(-1, 2)
            grid = LocalGrid(cells(data[0]), cells(data[1]), cells(data[2]), float(data[3]),
                             np.array(data[4:7], np.float32))
        scan = decompress_matrix(data[7], np.float64)
        return NodeData(feats, arr[:, 0].astype(np.int64), grid, None,
                        None if scan is None else scan.reshape(-1, 2))

    # -- writing ----------------------------------------------------------------------------
    def begin_session(self, map_id: int, parameters: dict[str, str]) -> int:
        """Record a new session's parameters; returns the session number."""
        text = ";".join(f"{k}:{v}" for k, v in sorted(parameters.items()))
        with self._transaction():
            cur = self._conn.execute(
                "INSERT INTO Info (map_id, parameters) VALUES (?, ?)", (map_id, text))
        self._session = int(cur.lastrowid or 0)
        return self._session

    def write_frame(self, record: FrameRecord) -> None:
        """Write one kept node and its links in a single transaction."""
        node = record.node
        data = node.data
        with self._transaction():
            c = self._conn
            c.execute(
                "INSERT INTO Node (id, map_id, weight, stamp, stamp_ns, pose, label) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                (node.id, node.map_id, node.weight, node.stamp_ns * 1e-9, node.stamp_ns,
                 pose_to_blob(node.odom_pose), node.label or None))
            grid = data.grid if data is not None else None
            scan_blob = None
            if data is not None and data.scan_points is not None:
                scan_blob = compress_matrix(data.scan_points.astype(np.float64), _CV_64F)
            c.execute(
                "INSERT INTO Data (id, image, depth, calibration, scan, ground_cells,"
                " obstacle_cells, empty_cells, cell_size, view_point_x, view_point_y,"
                " view_point_z) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (node.id,
                 encode_image(record.image, self.image_format) if record.image is not None else None,
                 encode_depth(record.depth) if record.depth is not None else None,
                 camera_to_json(record.camera), scan_blob,
                 compress_matrix(grid.ground, _CV_32F) if grid else None,
                 compress_matrix(grid.obstacles, _CV_32F) if grid else None,
                 compress_matrix(grid.empty, _CV_32F) if grid else None,
                 grid.cell_size if grid else None,
                 *(float(v) for v in (grid.view_point if grid else (0.0, 0.0, 0.0)))))
            if data is not None:
                f = data.features
                n = len(f)
                c.executemany(
                    "INSERT INTO Feature (node_id, word_id, pos_x, pos_y, size, dir, response,"
                    " octave, depth_x, depth_y, depth_z, descriptor_size, descriptor)"
                    " VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, 32, ?)",
                    zip([node.id] * n, data.words.tolist(), f.uv[:, 0].tolist(),
                        f.uv[:, 1].tolist(), f.sizes.tolist(), f.angles.tolist(),
                        f.responses.tolist(), f.octaves.tolist(), f.points[:, 0].tolist(),
                        f.points[:, 1].tolist(), f.points[:, 2].tolist(),
                        [bytes(row) for row in f.descriptors]))
            c.executemany(
                "INSERT OR IGNORE INTO Word (id, descriptor_size, descriptor) VALUES (?, 32, ?)",
                [(int(w), d.tobytes()) for w, d in zip(record.word_ids, record.word_descriptors)])
            c.executemany(
                "INSERT INTO Link (from_id, to_id, type, information_matrix, transform)"
                " VALUES (?, ?, ?, ?, ?)",
                [(lk.from_id, lk.to_id, int(lk.type),
                  np.asarray(lk.information, "<f8").tobytes(), pose_to_blob(lk.transform))
                 for lk in record.links])
            c.executemany("UPDATE Node SET weight=? WHERE id=?",
                          [(w, i) for i, w in record.weights])
            stats = ";".join(f"{k}:{v:g}" for k, v in record.statistics.items())
            c.execute("INSERT INTO Statistics (id, stamp, data) VALUES (?, ?, ?)",
                      (node.id, node.stamp_ns * 1e-9, zlib.compress(stats.encode())))

    def save_weights(self, weights: dict[int, int]) -> None:
        """Node weights (rehearsal and loop closures change them after a node is written)."""
        with self._transaction() as c:
            c.executemany("UPDATE Node SET weight=? WHERE id=?",
                          [(int(w), int(i)) for i, w in weights.items()])

    def save_optimized(self, poses: dict[int, NDArray[np.float64]], grid: GlobalGrid | None) -> None:
        """Admin.opt_ids/opt_poses and the assembled grid (opt_map)."""
        ids = np.array(sorted(poses), dtype="<i8")
        blob = b"".join(pose_to_blob(poses[int(i)]) for i in ids)
        with self._transaction():
            self._conn.execute("UPDATE Admin SET opt_ids=?, opt_poses=?", (ids.tobytes(), blob))
            if grid is not None:
                self._conn.execute(
                    "UPDATE Admin SET opt_map=?, opt_map_x_min=?, opt_map_y_min=?,"
                    " opt_map_resolution=?",
                    (compress_matrix(grid.data, _CV_8U), grid.origin_x, grid.origin_y,
                     grid.resolution))

    def _transaction(self) -> _Transaction:
        if self._conn is None:
            raise DatabaseError(f"{self.path}: database is closed")
        return _Transaction(self._conn)

    # -- loading a core -------------------------------------------------------------------
    def load_into(self, rtabmap: Rtabmap) -> None:
        """Fill a fresh core: words, nodes (WM or LTM), links, optimised poses; new session."""
        c = self._conn
        for wid, desc in c.execute("SELECT id, descriptor FROM Word ORDER BY id"):
            rtabmap.vocabulary.add_word(int(wid), np.frombuffer(desc, np.uint8))
        nodes = self.nodes()
        last_map = max((n.map_id for n in nodes), default=-1)
        all_in_wm = (rtabmap.params.mem_init_wm_with_all_nodes
                     or not rtabmap.params.mem_incremental_memory)
        mem = rtabmap.memory
        for n in nodes:
            if all_in_wm or n.map_id == last_map:
                data = self.load_node_data(n.id)
                n.data = data
                n.word_counts = data.word_counts() if data is not None else {}
                mem.add_to_wm(n)
            else:
                mem.add_ltm_node(n)
        for lk in self.links():
            if lk.from_id in mem.nodes and lk.to_id in mem.nodes:
                mem.add_link(lk)
        saved = self.optimized_poses()
        poses = {n.id: saved.get(n.id, n.odom_pose) for n in nodes}
        if nodes and len(saved) < len(nodes):
            poses = _optimize_components(rtabmap, poses)
        rtabmap.optimized_poses.update(poses)
        next_id = max((n.id for n in nodes), default=0) + 1
        new_map = last_map + 1 if rtabmap.params.mem_incremental_memory else max(last_map, 0)
        rtabmap.restore_state(next_id, new_map)
        if rtabmap.params.mem_incremental_memory:
            self.begin_session(new_map, rtabmap.params.to_dict())


def _optimize_components(rtabmap: Rtabmap, poses: dict[int, NDArray[np.float64]]
                         ) -> dict[int, NDArray[np.float64]]:
    from eddiebot.vslam.graph import GraphLink

    mem = rtabmap.memory
    remaining = set(poses)
    out = dict(poses)
    links = [GraphLink(lk.from_id, lk.to_id, lk.transform, lk.information, lk.switchable)
             for lk in mem.unique_links()]
    while remaining:
        root = min(remaining)
        comp = mem.component(root, set(poses))
        remaining -= comp
        if len(comp) < 2:
            continue
        # chain the odometry of the component from its root before optimising
        out.update(rtabmap.optimizer.optimize(
            {i: poses[i] for i in comp}, [lk for lk in links if lk.from_id in comp], root,
            rtabmap.params.optimizer_iterations))
    return out


class _Transaction:
    def __init__(self, conn: sqlite3.Connection) -> None:
        self._conn = conn

    def __enter__(self) -> sqlite3.Connection:
        self._conn.execute("BEGIN IMMEDIATE")
        return self._conn

    def __exit__(self, exc_type: object, *rest: object) -> None:
        if exc_type is None:
            self._conn.execute("COMMIT")
        else:
            self._conn.execute("ROLLBACK")
