"""Saved SLAM sessions: pose graph + scans in one versioned file.

Format (``.eslam``, version 1): a ZIP archive holding

* ``header.json``: ``{"format": "eddiebot-slam-session", "version": 1, "nodes": N,
  "edges": E, "sensor_offset": [x, y, theta], "parameters": {...}}``;
* ``arrays.npz``: ``poses`` (N, 3) node poses in the map frame; ``odom_poses`` (N, 3);
  ``stamps_ns`` (N,) int64; ``retired`` (N,) bool; ``range_min``, ``range_max`` (N,);
  ``beam_offsets`` (N+1,) int64 into the concatenated ``ranges`` / ``angles`` (float64);
  ``edge_ij`` (E, 2) int64; ``edge_measurement`` (E, 3); ``edge_covariance`` (E, 3, 3);
  ``edge_kind`` (E,) int8 (0 odometry, 1 scan match, 2 loop); ``edge_robust`` (E,) bool;
  ``edge_rejected`` (E,) bool, the edges the estimate was solved without (rejected or held
  by the loop gate; optional: without it every loop is gated again on loading);
  ``lifelong_scores`` (N,) the nodes' lifelong scores, kept between sessions as slam_toolbox
  keeps its vertex scores (optional: 1 when absent).

Writing goes to a temporary file renamed over the target, so a failure never leaves a
half-written session; the file gets the mode the user's umask gives new files. Reading checks the format tag, the version and every array's shape; a
mismatch raises `SessionVersionError`, anything else wrong `SessionError`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.files import created_file_mode
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.errors import SessionError, SessionVersionError
from eddiebot.slam.mapper import NodeRecord, SlamCore
from eddiebot.slam.pose_graph import EdgeKind
from eddiebot.slam.scan import Scan, scan_points

__all__ = ["SESSION_FORMAT", "SESSION_VERSION", "load_session", "save_session"]

SESSION_FORMAT = "eddiebot-slam-session"
SESSION_VERSION = 1
_KINDS = [EdgeKind.ODOMETRY, EdgeKind.SCAN_MATCH, EdgeKind.LOOP]


def save_session(core: SlamCore, path: str | os.PathLike[str]) -> Path:
    """Write the core's graph and scans to ``path`` atomically; returns the path."""
    target = Path(path)
    poses = core.node_poses()  # first: folds in nodes still pending
    # nodes lifelong mode marginalised out are left behind, their edges with them
    gone = set(core.graph.removed_nodes)
    keep = [k for k in range(len(core.nodes)) if k not in gone]
    new_id = {old: new for new, old in enumerate(keep)}
    nodes = [core.nodes[k] for k in keep]
    poses = poses[keep]
    dropped = set(core.graph.removed_edges)
    out = set(core.graph.rejected) | set(core.graph.held)
    live_edges = [k for k in range(len(core.graph.edges)) if k not in dropped]
    edges = [
        dataclasses.replace(e, i=new_id[e.i], j=new_id[e.j])
        for e in (core.graph.edges[k] for k in live_edges)
    ]
    lengths = np.array([n.scan.ranges.size for n in nodes], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    arrays: dict[str, Any] = {
        "poses": poses.reshape(-1, 3),
        "odom_poses": np.array([n.odom_pose for n in nodes]).reshape(-1, 3),
        "stamps_ns": np.array([n.scan.stamp_ns for n in nodes], dtype=np.int64),
        "retired": np.array([n.retired for n in nodes], dtype=bool),
        "range_min": np.array([n.scan.range_min for n in nodes], dtype=np.float64),
        "range_max": np.array([n.scan.range_max for n in nodes], dtype=np.float64),
        "beam_offsets": offsets,
        "ranges": np.concatenate([n.scan.ranges for n in nodes]) if nodes else np.zeros(0),
        "angles": np.concatenate([n.scan.angles for n in nodes]) if nodes else np.zeros(0),
        "edge_ij": np.array([[e.i, e.j] for e in edges], dtype=np.int64).reshape(-1, 2),
        "edge_measurement": np.array([e.measurement for e in edges]).reshape(-1, 3),
        "edge_covariance": np.array([e.covariance for e in edges]).reshape(-1, 3, 3),
        "edge_kind": np.array([_KINDS.index(e.kind) for e in edges], dtype=np.int8),
        "edge_robust": np.array([e.robust for e in edges], dtype=bool),
        "lifelong_scores": np.array([core.lifelong_scores.get(k, 1.0) for k in keep]),
        "edge_rejected": np.array([k in out for k in live_edges], dtype=bool),
    }
    params = {k: v for k, v in core.config.to_parameters().items() if _jsonable(v)}
    header = {
        "format": SESSION_FORMAT,
        "version": SESSION_VERSION,
        "nodes": len(nodes),
        "edges": len(edges),
        "sensor_offset": [float(v) for v in core.sensor_offset],
        "parameters": params,
    }
    npz = io.BytesIO()
    np.savez_compressed(npz, **arrays)
    fd = -1
    tmp = ""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
        with os.fdopen(fd, "wb") as raw:
            fd = -1
            with zipfile.ZipFile(raw, "w", compression=zipfile.ZIP_STORED) as zf:
                zf.writestr("header.json", json.dumps(header, indent=1))
                zf.writestr("arrays.npz", npz.getvalue())
            raw.flush()
            os.fchmod(raw.fileno(), created_file_mode())
            os.fsync(raw.fileno())
        os.replace(tmp, target)
        tmp = ""
    except OSError as exc:
        raise SessionError(f"{target}: cannot write session: {exc.strerror or exc}") from exc
    finally:
        if fd >= 0:
            os.close(fd)
        if tmp:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
    return target


def _jsonable(v: Any) -> bool:
    return isinstance(v, (str, int, float, bool)) or v is None


def load_session(
    path: str | os.PathLike[str],
    config: SlamConfig | None = None,
    *,
    mode: str | None = None,
) -> SlamCore:
    """A `SlamCore` holding a saved session, in ``mode`` (default: the config's mode).

    ``config`` defaults to the parameters stored in the file.
    """
    src = Path(path)
    try:
        with zipfile.ZipFile(src) as zf:
            header = json.loads(zf.read("header.json").decode("utf-8"))
            npz_bytes = zf.read("arrays.npz")
    except FileNotFoundError as exc:
        raise SessionError(f"{src}: no such session file") from exc
    except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SessionError(f"{src}: not a readable SLAM session ({exc})") from exc
    if not isinstance(header, dict) or header.get("format") != SESSION_FORMAT:
        raise SessionError(
            f"{src}: not a SLAM session (format tag {header.get('format') if isinstance(header, dict) else None!r})"
        )
    version = header.get("version")
    if version != SESSION_VERSION:
        raise SessionVersionError(
            f"{src}: session format version {version!r}; this eddiebot reads version {SESSION_VERSION}"
        )
    try:
        with np.load(io.BytesIO(npz_bytes), allow_pickle=False) as data:
            arr = {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise SessionError(f"{src}: corrupt arrays ({exc})") from exc
    try:
        n = int(header["nodes"])
        e = int(header["edges"])
        offsets = arr["beam_offsets"]
        checks = {
            "poses": (n, 3),
            "odom_poses": (n, 3),
            "stamps_ns": (n,),
            "retired": (n,),
            "range_min": (n,),
            "range_max": (n,),
            "beam_offsets": (n + 1,),
            "edge_ij": (e, 2),
            "edge_measurement": (e, 3),
            "edge_covariance": (e, 3, 3),
            "edge_kind": (e,),
            "edge_robust": (e,),
        }
        for key, shape in checks.items():
            if arr[key].shape != shape:
                raise SessionError(
                    f"{src}: array '{key}' has shape {arr[key].shape}, expected {shape}"
                )
        total = int(offsets[-1]) if n else 0
        if arr["ranges"].shape != (total,) or arr["angles"].shape != (total,):
            raise SessionError(
                f"{src}: scan arrays hold {arr['ranges'].shape} beams, expected {total}"
            )
        scores = arr.get("lifelong_scores", np.ones(n))  # absent before lifelong scores
        flags = arr.get("edge_rejected")  # absent in older files: every loop is gated again
        if flags is not None and flags.shape != (e,):
            raise SessionError(f"{src}: array 'edge_rejected' has shape {flags.shape}, expected {(e,)}")
        if scores.shape != (n,):
            raise SessionError(
                f"{src}: array 'lifelong_scores' has shape {scores.shape}, expected {(n,)}"
            )
        if e and (arr["edge_ij"].min() < 0 or arr["edge_ij"].max() >= n):
            raise SessionError(f"{src}: an edge refers to a node that does not exist")
        if not np.all(np.isfinite(arr["poses"])):
            raise SessionError(f"{src}: non-finite node poses")
        sensor_offset = np.asarray(
            header.get("sensor_offset", [0, 0, 0]), dtype=np.float64
        ).reshape(3)
    except KeyError as exc:
        raise SessionError(f"{src}: missing entry {exc}") from exc
    except (TypeError, ValueError) as exc:
        raise SessionError(f"{src}: malformed header ({exc})") from exc
    if config is None:
        config = SlamConfig.from_parameters(header.get("parameters", {}), source=str(src))
    if mode is not None:
        config = SlamConfig.from_parameters(
            {**config.to_parameters(), "mode": mode}, source=str(src)
        )
    core = SlamCore(config, sensor_offset=sensor_offset)
    nodes: list[NodeRecord] = []
    for k in range(n):
        a, b = int(offsets[k]), int(offsets[k + 1])
        scan = Scan(
            arr["ranges"][a:b].astype(np.float64),
            arr["angles"][a:b].astype(np.float64),
            float(arr["range_min"][k]),
            float(arr["range_max"][k]),
            int(arr["stamps_ns"][k]),
        )
        nodes.append(
            NodeRecord(
                scan,
                scan_points(scan, config.max_laser_range),
                arr["odom_poses"][k].copy(),
                bool(arr["retired"][k]),
            )
        )
    edges = [
        (
            int(arr["edge_ij"][q, 0]),
            int(arr["edge_ij"][q, 1]),
            arr["edge_measurement"][q],
            arr["edge_covariance"][q],
            _KINDS[int(arr["edge_kind"][q])],
            bool(arr["edge_robust"][q]),
        )
        for q in range(e)
    ]
    rejected = None if flags is None else np.flatnonzero(flags).tolist()
    core._restore(nodes, arr["poses"], edges, rejected)
    core.lifelong_scores = {k: float(v) for k, v in enumerate(scores.tolist()) if v != 1.0}
    return core
