"""The SLAM node's session and map files: ``~/save_map`` (nav2 map_server files),
``~/serialize_map`` / ``~/deserialize_map`` (the session file), ``map_file_name`` at start-up
and `SlamSessionFiles.save_outputs`."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.maps import MapAnchor, save_anchor, save_map
from eddiebot.msgs.slam_toolbox import DeserializePoseGraph, SaveMap, SerializePoseGraph
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.mapper import SlamCore, SlamWarning
from eddiebot.slam.session import load_session, save_session

__all__ = ["SlamSessionFiles"]


class SlamSessionFiles(Node):
    """The session and map file services of the SLAM node (a base of `SlamNode`, which sets
    the attributes below)."""

    core: SlamCore
    config: SlamConfig
    odom_session: str
    _laser: tuple[str, np.ndarray] | None
    _last_scan_ns: int | None
    _map_dirty: bool
    _on_warning: Callable[[SlamWarning], None]

    def _save_map(self, req: Any, res: Any) -> Any:
        name = str(req.name.data) or "map"
        if len(self.core.nodes) == 0:
            res.result = SaveMap.Response.RESULT_NO_MAP_RECEIEVD
            return res
        try:
            self.core.update_map()
            base = Path(name).expanduser()
            save_map(self.core.occupancy_map(), base, anchor=self.map_anchor())
            res.result = SaveMap.Response.RESULT_SUCCESS
            self.get_logger().info(f"saved the map to {name}.yaml / {name}.pgm")
        except Exception as exc:
            self.get_logger().error(f"save_map {name!r} failed: {exc}")
            res.result = SaveMap.Response.RESULT_UNDEFINED_FAILURE
        return res

    def map_anchor(self) -> MapAnchor | None:
        """Where the map frame stands against the odometry now (None without
        ``odom_session``)."""
        if not self.odom_session:
            return None
        x, y, th = (float(v) for v in self.core.map_to_odom)
        return MapAnchor((x, y, th), self.odom_session)

    def save_outputs(self, folder: Path) -> dict[str, Path]:
        """Write the session (``session.eslam``, with the anchor beside it as
        ``session.eslam.anchor.yaml``) and the map (``map.yaml`` + ``map.pgm``) into
        ``folder``, each file atomically; returns them by kind (only the session while no
        scan is processed yet)."""
        folder.mkdir(parents=True, exist_ok=True)
        out = {"session": save_session(self.core, folder / "session.eslam")}
        anchor = self.map_anchor()
        if anchor is not None:
            side = folder / "session.eslam.anchor.yaml"
            out["anchor"] = save_anchor(side, anchor)
        if len(self.core.nodes):
            self.core.update_map()
            out["map"] = save_map(self.core.occupancy_map(), folder / "map", anchor=anchor)
        return out

    def _serialize(self, req: Any, res: Any) -> Any:
        try:
            path = save_session(self.core, Path(str(req.filename)).expanduser())
            self.get_logger().info(f"serialized the session to {path}")
            res.result = SerializePoseGraph.Response.RESULT_SUCCESS
        except Exception as exc:
            self.get_logger().error(f"serialize_map {req.filename!r} failed: {exc}")
            res.result = SerializePoseGraph.Response.RESULT_FAILED_TO_WRITE_FILE
        return res

    def _deserialize(self, req: Any, res: Any) -> Any:
        p = req.initial_pose
        self.load_session_file(
            str(req.filename), int(req.match_type), (float(p.x), float(p.y), float(p.theta))
        )
        return res

    def _load_at_start(self) -> None:
        """slam_toolbox's ``loadPoseGraphByParams``: ``map_file_name`` at start-up."""
        cfg = self.config
        request = DeserializePoseGraph.Request
        pose: tuple[float, ...] | None = tuple(cfg.map_start_pose or (0.0, 0.0, 0.0))
        if cfg.mode == "localization":
            if not cfg.map_start_pose:
                pose = None  # relocalised globally on the first scan
            if cfg.map_start_at_dock and not cfg.map_start_pose:
                self.get_logger().warning(
                    "map_start_at_dock: localization does not start at the first node; "
                    "starting at map_start_pose (the origin when unset)"
                )
            match = request.LOCALIZE_AT_POSE
        elif cfg.map_start_pose:
            match = request.START_AT_GIVEN_POSE
        elif cfg.map_start_at_dock:
            match = request.START_AT_FIRST_NODE
        else:
            match = request.START_AT_GIVEN_POSE
            self.get_logger().info(
                "map_file_name without map_start_pose or map_start_at_dock: starting at the "
                "map origin"
            )
        if not self.load_session_file(cfg.map_file_name, match, pose):
            self.get_logger().error(
                f"map_file_name {cfg.map_file_name!r} not loaded; starting with an empty map"
            )

    def load_session_file(
        self, filename: str, match_type: int, pose: tuple[float, ...] | None = (0.0, 0.0, 0.0)
    ) -> bool:
        """Load a saved session as ``~/deserialize_map`` does; False (and a log line) when
        refused or unreadable, the current session kept.

        ``match_type``: START_AT_FIRST_NODE (the robot is at the session's first node),
        START_AT_GIVEN_POSE (at ``pose``, map frame x, y, theta) — mapping and lifelong;
        LOCALIZE_AT_POSE (at ``pose``) — localization only. The next scan is placed there,
        whatever its odometry, and matched against the nodes near it. LOCALIZE_AT_POSE with
        ``pose`` None: the next scan is relocalised over the whole map."""
        request = DeserializePoseGraph.Request
        names = {
            request.START_AT_FIRST_NODE: "START_AT_FIRST_NODE",
            request.START_AT_GIVEN_POSE: "START_AT_GIVEN_POSE",
            request.LOCALIZE_AT_POSE: "LOCALIZE_AT_POSE",
        }
        mode = self.config.mode
        if match_type not in names:
            self.get_logger().error(
                f"deserialize_map {filename!r}: match_type {match_type} is not set "
                "(START_AT_FIRST_NODE 1, START_AT_GIVEN_POSE 2, LOCALIZE_AT_POSE 3); not loaded"
            )
            return False
        if mode == "localization" and match_type != request.LOCALIZE_AT_POSE:
            self.get_logger().error(
                f"deserialize_map {filename!r}: {names[match_type]} refused in localization "
                "mode (use LOCALIZE_AT_POSE); not loaded"
            )
            return False
        if mode != "localization" and match_type == request.LOCALIZE_AT_POSE:
            self.get_logger().error(
                f"deserialize_map {filename!r}: LOCALIZE_AT_POSE refused in {mode} mode (it "
                "needs mode localization; use START_AT_GIVEN_POSE); not loaded"
            )
            return False
        if not filename:
            self.get_logger().warning("deserialize_map: no map file given")
            return False
        try:
            core = load_session(Path(filename).expanduser(), self.config, mode=mode)
        except Exception as exc:
            self.get_logger().error(
                f"deserialize_map {filename!r} failed: {exc}; kept the current session"
            )
            return False
        if self._laser is not None and not _same_mount(core.sensor_offset, self._laser[1]):
            self.get_logger().error(
                f"deserialize_map {filename!r}: the session's laser was mounted at "
                f"{_fmt_pose(core.sensor_offset)}, {self._laser[0]} is at "
                f"{_fmt_pose(self._laser[1])}; not loaded"
            )
            return False
        core.on_warning = self._on_warning
        core.global_search = self.core.global_search
        where = "at the pose global relocalisation finds"
        if match_type == request.START_AT_FIRST_NODE and core.nodes:
            start = core.node_poses()[0]
        elif pose is not None:
            start = np.asarray(pose, dtype=np.float64)
        else:
            start = None
        if start is not None:
            core.start_at(start)
            where = f"at {_fmt_pose(start)}"
        self.core = core
        self._last_scan_ns = None
        self._map_dirty = True
        self.get_logger().info(
            f"loaded session {filename} ({len(core.nodes)} nodes), {names[match_type]} {where}"
        )
        return True


def _same_mount(a: np.ndarray, b: np.ndarray) -> bool:
    """Two laser mounts (x, y, yaw) equal to within 1 mm and 1 mrad."""
    dx, dy = float(a[0] - b[0]), float(a[1] - b[1])
    dyaw = math.remainder(float(a[2] - b[2]), math.tau)
    return math.hypot(dx, dy) <= 1e-3 and abs(dyaw) <= 1e-3


def _fmt_pose(p: Any) -> str:
    return f"({float(p[0]):.3f}, {float(p[1]):.3f}, {float(p[2]):.3f})"
