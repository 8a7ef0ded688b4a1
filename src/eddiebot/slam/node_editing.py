"""The SLAM node's editing services: slam_toolbox's interactive mode, its merge tool's
``add_submap`` / ``merge_submaps``, and the map-and-localization node's
``set_localization_mode``, on a running `SlamNode`.

Interactive mode (slam_toolbox's ``LoopClosureAssistant``; ``enable_interactive_mode`` must be
true, and the node in mapping mode — upstream disables it in lifelong and refuses it in
localization):

* ``~/toggle_interactive_mode`` (slam_toolbox/ToggleInteractive) turns it on or off, sets the
  ``interactive_mode`` and ``paused_processing`` parameters, and drops the staged moves. While
  it is on, scans are dropped as when paused (upstream's sync node holds them in its queue
  instead), so the graph does not change under the user.
* ``~/get_interactive_markers`` (visualization_msgs/GetInteractiveMarkers) and ``~/update``
  (visualization_msgs/InteractiveMarkerUpdate): slam_toolbox's interactive marker server
  (`eddiebot.slam.interactive_markers`), so RViz2's InteractiveMarkers display set to
  ``<node>/update`` works unchanged. While interactive mode is on, every graph node is a
  marker named by its id (a sphere, a planar move control and a rotation control, as
  upstream's ``LoopClosureAssistant``); an update is published when the mode is toggled, when
  the staged moves are applied or dropped, and whenever the graph is republished (merges);
  turning the mode off erases them.
* ``~/feedback`` (visualization_msgs/InteractiveMarkerFeedback, what RViz's interactive marker
  client sends to slam_toolbox's marker server): ``marker_name`` is the node id; a
  ``MOUSE_UP`` stages the move of that node to ``mouse_point`` (x, y; ``pose.position`` when
  ``mouse_point_valid`` is false) with its heading turned by the yaw of ``pose.orientation``,
  as upstream (the marker starts unrotated, so its orientation is the turn the user gave). A
  later move of the same node replaces the earlier one. Refused moves (unknown node, node 0,
  not in interactive mode) are logged with the node id and dropped.
* ``~/manual_loop_closure`` (slam_toolbox/LoopClosure) applies the staged moves and
  re-optimises (`eddiebot.slam.editing`: each move is a constraint the graph keeps, where
  upstream's Ceres only re-seeds the node's estimate), then drops them.
* ``~/clear_changes`` (slam_toolbox/Clear) drops the staged moves and puts dragged markers
  back on their nodes; the graph is untouched.

Merging (slam_toolbox's ``merge_maps_kinematic`` tool, served here by the SLAM node itself and
merging graphs, not only grids; `eddiebot.slam.merge`):

* ``~/add_submap`` (slam_toolbox/AddSubmap): loads a saved session and places it in the
  current map by scan matching. One that does not relocalise stays pending at its own origin
  until placed by hand. The search (seconds to tens of seconds of CPU on a large map) runs in
  a spawned process (`eddiebot.slam.placement_process`; a thread would hold the GIL in the
  scan-matching kernels) against `eddiebot.slam.merge.map_snapshot` of the map at the request,
  driven from a worker thread that hands the result back through a guard condition, so scans
  go on being processed and map → odom published meanwhile; requests are placed one at a
  time, in order. The call is answered when the submap is added (or refused), as
  upstream's merge tool answers once the submap is loaded: a client that waits for the
  answer, then calls ``~/merge_submaps``, merges it.
* ``merge_maps_tool/feedback`` (InteractiveMarkerFeedback; upstream's merge tool's marker
  server): ``marker_name`` is the submap's number (1, 2, … in the order added); a
  ``MOUSE_UP`` places its map frame at ``pose`` (x, y, yaw) in this map.
* ``~/merge_submaps`` (slam_toolbox/MergeMaps): merges every pending submap into the graph
  as it is then (each placement re-expressed against it, `eddiebot.slam.merge.rebase_placement`;
  linked by scan matching near its placement) and publishes the merged map on the map topic.
  Submaps still being placed are not merged (logged).

``~/set_localization_mode`` (std_srvs/SetBool; slam_toolbox's experimental map-and-localization
node has it, the others do not): true switches a mapping or lifelong node into localization
on its current graph — the robot keeps its pose, ``initialpose`` and
``~/clear_localization_buffer`` appear, the graph stops growing; false switches it back to the
mode it was launched in, the next scan starting a new chain matched against the nodes near
the robot. ``success`` is false, with the reason in ``message``, when refused. Unlike
upstream, ``~/save_map`` stays available while localizing (the map is the graph's, unchanged).
"""

from __future__ import annotations

import dataclasses
import queue
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from eddiebot.core.action import _create_deferred_service
from eddiebot.geometry import quaternion_to_yaw
from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
from eddiebot.msgs.slam_toolbox import AddSubmap, Clear, LoopClosure, MergeMaps, ToggleInteractive
from eddiebot.msgs.std_srvs import Empty, SetBool
from eddiebot.msgs.visualization_msgs import InteractiveMarkerFeedback
from eddiebot.slam.editing import apply_node_moves, check_node_move
from eddiebot.slam.errors import GraphEditError, MergeError, SlamError
from eddiebot.slam.interactive_markers import MarkerServer, graph_node_marker
from eddiebot.slam.mapper import SlamCore
from eddiebot.slam.merge import (
    MapCopy,
    Placement,
    map_snapshot,
    merge_session,
    place_session,
    rebase_placement,
)
from eddiebot.slam.placement_process import PlacementProcess
from eddiebot.slam.session import load_session

if TYPE_CHECKING:
    from eddiebot.slam.node import SlamNode

__all__ = ["GraphEditing", "PendingSubmap"]

_Done = Callable[[Any, BaseException | None], None]


@dataclass
class PendingSubmap:
    """A session added with ``~/add_submap``, waiting for ``~/merge_submaps``."""

    filename: str
    core: SlamCore
    placement: Placement | None
    """Where scan matching put it; None while it sits at its own origin or was moved by hand."""
    transform: np.ndarray
    """Its map frame in this map (x, y, theta)."""
    searched: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 3)))
    """This map's node poses when it was placed (the links are relative to them)."""
    first_node: Any = None
    """This map's node 0 when it was placed: another one means the map was reset or
    replaced since, and the placement's links refer to nodes that are gone."""


@dataclass
class _Placed:
    """What the placement worker hands back to the executor."""

    core: SlamCore
    """The loaded session."""
    placement: Placement | None
    searched: np.ndarray
    """Node poses of the map snapshot the placement was searched on (N, 3)."""
    unplaced: str
    """Why scan matching did not place it ('' when it did)."""


def _load_and_place(
    filename: str, map_copy: MapCopy, place: Callable[[MapCopy, MapCopy], Placement]
) -> _Placed:
    """Load ``filename`` and place it on ``map_copy`` with ``place`` (on the worker thread:
    touches no live state); `MergeError` when it cannot be read or does not fit this map."""
    if not filename:
        raise MergeError("add_submap: no file name given")
    try:
        other = load_session(Path(filename).expanduser(), map_copy.config)
    except SlamError as exc:
        raise MergeError(f"add_submap: {exc}") from exc
    try:
        return _Placed(other, place(map_copy, map_snapshot(other)), map_copy.poses, "")
    except MergeError as exc:
        if not map_copy.nodes or not other.nodes or "mounted" in str(exc):
            raise MergeError(f"add_submap {filename}: {exc}") from exc
        return _Placed(other, None, map_copy.poses, str(exc))


class _Worker:
    """Runs jobs one at a time, in order, on a thread of its own; each result is handed back
    to the node's executor through a guard condition (the board node's transaction queue,
    `eddiebot.base.board_io`), so ``done(result, error)`` runs where the node's state lives."""

    def __init__(self, node: SlamNode, name: str) -> None:
        self._name = name
        self._jobs: queue.SimpleQueue[tuple[Callable[[], Any], _Done] | None] = queue.SimpleQueue()
        self._results: deque[tuple[_Done, Any, BaseException | None]] = deque()
        self._guard = node.create_guard_condition(self._deliver)
        self._thread: threading.Thread | None = None
        self.pending = 0
        """Jobs submitted whose ``done`` has not run yet (read on the executor)."""

    def submit(self, work: Callable[[], Any], done: _Done) -> None:
        self.pending += 1
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
            self._thread.start()
        self._jobs.put((work, done))

    def _run(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            work, done = job
            result: Any = None
            error: BaseException | None = None
            try:
                result = work()
            except Exception as exc:  # handed to done, on the executor
                error = exc
            self._results.append((done, result, error))
            self._guard.trigger()

    def _deliver(self) -> None:
        while self._results:
            done, result, error = self._results.popleft()
            self.pending -= 1
            done(result, error)

    def close(self, timeout_s: float = 1.0) -> None:
        """Stop after the job in flight (waiting up to ``timeout_s`` for it); queued jobs are
        dropped."""
        if self._thread is None:
            return
        while True:
            try:
                self._jobs.get_nowait()
            except queue.Empty:
                break
        self._jobs.put(None)
        self._thread.join(timeout_s)
        self._thread = None


def _feedback_yaw(msg: Any) -> float:
    o = msg.pose.orientation
    if o.x == 0.0 and o.y == 0.0 and o.z == 0.0 and o.w == 0.0:
        return 0.0  # an unset quaternion: no turn
    return quaternion_to_yaw(o.x, o.y, o.z, o.w)


class GraphEditing:
    """The editing services of one `SlamNode` (see the module docstring)."""

    def __init__(self, node: SlamNode) -> None:
        self.node = node
        self.interactive_mode = False
        self.staged: dict[int, np.ndarray] = {}
        """Moves waiting for ``manual_loop_closure``: node id → robot pose (map frame)."""
        self.submaps: list[PendingSubmap] = []
        self.launched_mode = node.config.mode
        self._initial_pose_sub: Any = None
        self._clear_buffer_srv: Any = None
        self._placer = _Worker(node, "slam-add-submap")
        self._process = PlacementProcess()
        self.place_copies: Callable[[MapCopy, MapCopy], Placement] = self._process.run
        """How the worker thread places a session copy on a map copy: in a spawned process
        (`eddiebot.slam.placement_process`)."""
        self.markers = MarkerServer(node, "~")
        """slam_toolbox's interactive marker server: a marker per graph node in interactive mode."""
        self._markers_shown: tuple[tuple[int, float, float], ...] | None = None
        for name, default in (("interactive_mode", False), ("paused_processing", False)):
            if not node.has_parameter(name):
                node.declare_parameter(name, default)
            node.set_parameter(name, default)
        node.create_service(ToggleInteractive, "~/toggle_interactive_mode", self._toggle)
        node.create_service(LoopClosure, "~/manual_loop_closure", self._manual_loop_closure)
        node.create_service(Clear, "~/clear_changes", self._clear_changes)
        node.create_subscription(InteractiveMarkerFeedback, "~/feedback", self._on_feedback, 10)
        _create_deferred_service(node, AddSubmap, "~/add_submap", self._add_submap, None)
        node.create_service(MergeMaps, "~/merge_submaps", self._merge_submaps)
        node.create_subscription(
            InteractiveMarkerFeedback, "merge_maps_tool/feedback", self._on_submap_feedback, 10
        )
        node.create_service(SetBool, "~/set_localization_mode", self._set_localization_mode)

    @property
    def _log(self) -> Any:
        return self.node.get_logger()

    # -- interactive mode ----------------------------------------------------------------
    def _refusal(self, what: str) -> str:
        """Why ``what`` is refused now ('' when it is allowed)."""
        cfg = self.node.config
        if not cfg.enable_interactive_mode:
            return f"{what}: enable_interactive_mode is false; ignored"
        if cfg.mode != "mapping":
            return f"{what}: interactive mode works in mapping mode only (mode is {cfg.mode}); ignored"
        return ""

    def _toggle(self, req: Any, res: Any) -> Any:
        why = self._refusal("toggle_interactive_mode")
        if why:
            self._log.warning(why)
            return res
        self.set_interactive(not self.interactive_mode)
        return res

    def set_interactive(self, on: bool) -> None:
        """Turn interactive mode on or off (staged moves are dropped either way)."""
        self.interactive_mode = on
        self.staged.clear()
        self.node.set_parameter("interactive_mode", on)
        self.node.set_parameter("paused_processing", on)
        self.node.mark_map_dirty()
        self.publish_markers()
        self._log.info(f"interactive mode {'on' if on else 'off'}")

    def publish_markers(self) -> None:
        """Publish the graph's interactive markers: one per active node while interactive mode
        is on, none otherwise (an update only when they changed, or a client moved one)."""
        if not self.interactive_mode:
            self._markers_shown = None
            self.markers.replace_all([])
            return
        core = self.node.core
        poses = core.node_poses()
        ids = [int(i) for i in np.flatnonzero(core.active_mask())]
        shown = tuple((i, float(poses[i, 0]), float(poses[i, 1])) for i in ids)
        if shown == self._markers_shown:
            return
        self._markers_shown = shown
        stamp = self.node.get_clock().now_ns()
        frame = self.node.config.map_frame
        self.markers.replace_all([graph_node_marker(i, poses[i], frame, stamp) for i in ids])

    def stage_move(self, node_id: int, pose: Any) -> np.ndarray:
        """Stage the move of ``node_id`` to ``pose`` (robot pose, map frame);
        `GraphEditError` when refused."""
        why = self._refusal(f"move of node {node_id}")
        if why:
            raise GraphEditError(why)
        if not self.interactive_mode:
            raise GraphEditError(
                f"move of node {node_id}: interactive mode is off (call "
                "~/toggle_interactive_mode first); ignored"
            )
        target = check_node_move(self.node.core, node_id, pose)
        self.staged[node_id] = target
        return target

    def _on_feedback(self, msg: Any) -> None:
        if msg.event_type == InteractiveMarkerFeedback.POSE_UPDATE:
            if self.markers.set_pose(str(msg.marker_name), msg.pose):
                self._markers_shown = None  # the next publication puts it back on its node
            return
        if msg.event_type != InteractiveMarkerFeedback.MOUSE_UP:
            return
        try:
            node_id = int(str(msg.marker_name).strip())
        except ValueError:
            self._log.warning(
                f"interactive feedback for marker {msg.marker_name!r}: not a node id; ignored"
            )
            return
        point = msg.mouse_point if msg.mouse_point_valid else msg.pose.position
        try:
            if not 0 <= node_id < len(self.node.core.nodes):
                check_node_move(self.node.core, node_id, (0.0, 0.0, 0.0))
            heading = float(self.node.core.node_poses()[node_id][2])
            target = self.stage_move(
                node_id, (float(point.x), float(point.y), heading + _feedback_yaw(msg))
            )
        except GraphEditError as exc:
            self._log.warning(str(exc))
            return
        self._log.info(
            f"staged the move of node {node_id} to ({target[0]:.2f}, {target[1]:.2f}, "
            f"{target[2]:.2f}); {len(self.staged)} staged"
        )

    def _manual_loop_closure(self, req: Any, res: Any) -> Any:
        why = self._refusal("manual_loop_closure")
        if why:
            self._log.warning(why)
            return res
        if not self.staged:
            self._log.warning("manual_loop_closure: no moved nodes to close loops with")
            return res
        try:
            n = apply_node_moves(self.node.core, self.staged)
        except GraphEditError as exc:  # a node retired since it was staged
            self._log.warning(f"manual_loop_closure: {exc}; nothing applied")
            return res
        finally:
            self.staged.clear()
        self.node.mark_map_dirty()
        self.publish_markers()
        self._log.info(f"manual_loop_closure: applied {n} moved nodes and re-optimised")
        return res

    def _clear_changes(self, req: Any, res: Any) -> Any:
        why = self._refusal("clear_changes")
        if why:
            self._log.warning(why)
            return res
        self._log.info(f"clear_changes: dropped {len(self.staged)} staged moves")
        self.staged.clear()
        # as upstream: the markers go back onto their nodes
        self._markers_shown = None
        self.publish_markers()
        return res

    # -- merging -------------------------------------------------------------------------
    def add_submap(
        self, filename: str, on_added: Callable[[PendingSubmap | None], None] | None = None
    ) -> None:
        """Load ``filename`` and place it by scan matching (at its own origin when that
        fails) on the worker thread, against the map as it is now; then, on the executor, the
        submap joins `submaps` and ``on_added(submap)`` runs (``on_added(None)``, the reason
        logged, when it cannot be read or does not fit this map)."""
        core = self.node.core
        map_copy = map_snapshot(core)
        first = core.nodes[0] if core.nodes else None
        place = self.place_copies

        def done(placed: _Placed | None, error: BaseException | None) -> None:
            sub = None
            if placed is not None:
                sub = self._accept(filename, placed, first)
            elif isinstance(error, MergeError):
                self._log.error(f"{error}; not added")
            else:
                self._log.error(
                    f"add_submap {filename}: {type(error).__name__}: {error}; not added"
                )
            if on_added is not None:
                on_added(sub)

        self._placer.submit(lambda: _load_and_place(filename, map_copy, place), done)

    def _accept(self, filename: str, placed: _Placed, first: Any) -> PendingSubmap:
        """A placed session joins the pending submaps."""
        placement = placed.placement
        if placed.unplaced:
            self._log.warning(
                f"add_submap {filename}: {placed.unplaced}; it waits at its own origin "
                "(place it on merge_maps_tool/feedback, then call ~/merge_submaps)"
            )
        transform = placement.transform if placement is not None else np.zeros(3)
        sub = PendingSubmap(
            filename, placed.core, placement, transform.copy(), placed.searched, first
        )
        self.submaps.append(sub)
        t = sub.transform
        how = (
            f"placed by scan matching ({len(placement.links)} matched nodes)"
            if placement is not None
            else "not placed"
        )
        self._log.info(
            f"add_submap: submap {len(self.submaps)} from {filename} ({len(sub.core.nodes)} "
            f"nodes) at ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}), {how}"
        )
        return sub

    def _add_submap(self, req: Any, done: _Done) -> None:
        # answered once the submap is added or refused: the executor serves scans meanwhile
        self.add_submap(str(req.filename), lambda _sub: done(AddSubmap.Response(), None))

    def close(self) -> None:
        """Stop the placement worker (a search in flight is abandoned)."""
        self._process.stop()
        self._placer.close()

    def _on_submap_feedback(self, msg: Any) -> None:
        if msg.event_type != InteractiveMarkerFeedback.MOUSE_UP:
            return
        try:
            number = int(str(msg.marker_name).strip())
        except ValueError:
            number = 0
        if not 1 <= number <= len(self.submaps):
            self._log.warning(
                f"merge_maps_tool feedback for marker {msg.marker_name!r}: no such submap "
                f"({len(self.submaps)} pending, numbered from 1); ignored"
            )
            return
        p = msg.pose.position
        pose = np.array([float(p.x), float(p.y), _feedback_yaw(msg)])
        if not np.all(np.isfinite(pose)):
            self._log.warning(f"submap {number}: pose {pose.tolist()} is not finite; ignored")
            return
        sub = self.submaps[number - 1]
        sub.transform, sub.placement = pose, None
        self._log.info(f"submap {number} placed by hand at ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f})")

    def merge_submaps(self) -> int:
        """Merge every pending submap into the graph as it is now; returns the nodes added."""
        core = self.node.core
        added = 0
        while self.submaps:
            sub = self.submaps[0]
            placement = sub.placement
            if placement is not None and (not core.nodes or core.nodes[0] is not sub.first_node):
                self._log.warning(
                    f"merge_submaps: the map was reset or replaced since {sub.filename} was "
                    "placed; placing it again near where it was"
                )
                placement = None
            if placement is not None:
                placement = rebase_placement(placement, sub.core, sub.searched, core)
            else:
                placement = place_session(core, sub.core, transform=sub.transform)
            ids = merge_session(core, sub.core, placement)
            added += len(ids)
            self.submaps.pop(0)
            self._log.info(
                f"merged {sub.filename}: nodes {ids.start}..{ids.stop - 1}, "
                f"{len(placement.links) or 'no'} scan-matched links"
            )
        return added

    def _merge_submaps(self, req: Any, res: Any) -> Any:
        if self._placer.pending:
            self._log.warning(
                f"merge_submaps: {self._placer.pending} submaps are still being placed; they "
                "are not merged now (call ~/merge_submaps again once ~/add_submap answered)"
            )
        if not self.submaps:
            if not self._placer.pending:
                self._log.warning("merge_submaps: no submaps added (call ~/add_submap first)")
            return res
        try:
            self.merge_submaps()
        except MergeError as exc:
            self._log.error(f"merge_submaps: {exc}")
        self.node.mark_map_dirty()
        return res

    # -- localization mode ---------------------------------------------------------------
    def set_localization_mode(self, enable: bool) -> tuple[bool, str]:
        """Switch between localization and the launched mapping mode; (success, message)."""
        node = self.node
        core = node.core
        current = node.config.mode
        if enable == (current == "localization"):
            return True, f"already in {current} mode"
        if enable:
            if not core.nodes:
                return False, "no map to localize on: the graph is empty"
            target = "localization"
        else:
            if self.launched_mode == "localization":
                return False, "launched in localization mode: there is no mapping mode to return to"
            target = self.launched_mode
        if self.interactive_mode:
            self.set_interactive(False)
        pose = core._state.last_pose
        if pose is None:
            pose = core.node_poses()[-1]
        node.config = dataclasses.replace(node.config, mode=target)
        core.config = dataclasses.replace(core.config, mode=target)
        core._global = None  # the whole-map grid is rebuilt from the graph as it is now
        if enable:
            # tracking goes on from the last pose through the odometry
            core.clear_localization_buffer()
            self._initial_pose_sub = node.create_subscription(
                PoseWithCovarianceStamped, "initialpose", node._on_initial_pose, 1
            )
            self._clear_buffer_srv = node.create_service(
                Empty, "~/clear_localization_buffer", node._clear_localization_buffer
            )
        else:
            # a new chain: matched against the nodes near the robot, not linked to the last
            # node by odometry (the robot has moved since), its prior from map → odom
            core.start_at(pose)
            core._state.pending_start = None
            self._drop_localization_entities()
        message = (
            f"{current} → {target} mode at ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f}) "
            f"on {len(core.nodes)} nodes"
        )
        self._log.info(message)
        return True, message

    def _drop_localization_entities(self) -> None:
        if self._initial_pose_sub is not None:
            self.node.destroy_subscription(self._initial_pose_sub)
        if self._clear_buffer_srv is not None:
            self.node.destroy_service(self._clear_buffer_srv)
        self._initial_pose_sub = self._clear_buffer_srv = None

    def _set_localization_mode(self, req: Any, res: Any) -> Any:
        res.success, res.message = self.set_localization_mode(bool(req.data))
        if not res.success:
            self._log.warning(f"set_localization_mode: {res.message}")
        return res
