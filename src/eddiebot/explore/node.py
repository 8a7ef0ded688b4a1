"""explore_lite's node: frontiers from ``/map`` become ``navigate_to_pose`` goals.

Subscribes ``/map`` (transient-local) and ``explore/resume`` (std_msgs/Bool: false pauses
and cancels the goal, true resumes; the same as a std_srvs/SetBool service, and
``start_paused`` waits for it); publishes its progress on ``explore/status``
(`eddiebot.explore.status`); reads the robot's pose from TF ``map`` →
``robot_base_frame``; publishes ``explore/frontiers`` (visualization_msgs/MarkerArray) when
``visualize``. Goals go through Nav2's ``navigate_to_pose``, so the planner, controller,
recoveries, velocity smoother and collision monitor stay in charge of the motion; the
look-around at the start is the behaviour server's ``spin`` (one full turn: the Kinect
sees 57°). With no frontier left, or after ``time_limit``, the robot is sent back to where
it started when ``return_to_init``, through ``navigate_to_pose`` (via a pose facing the start
when the map does not know the start's floor as free); a failed goal home is tried again,
up to four attempts, each after a recovery (both costmaps cleared through
``clear_entirely_*``, the behaviour server's ``backup``, a 5 s wait) and by way of the path
the robot drove while exploring, retraced from its point nearest the robot towards the
start (2, 4, 6 m of it: through a door it drove through the other way), and the last
failure's reason is kept (`home_failure`). `stop` cancels everything at once and never
sends the robot home (Ctrl-C).

Where the camera has looked from, and which way, is remembered (`looks`): the Kinect's
no-return beams are NaN and clear nothing, so a viewpoint gains nothing along a direction
already looked along from the same spot (`eddiebot.explore.frontiers.looked_mask`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from eddiebot.core.action import ActionClient
from eddiebot.core.node import Node
from eddiebot.core.qos import qos_profile_latched
from eddiebot.core.tf import Buffer, TransformException, TransformListener
from eddiebot.explore.config import ExploreConfig
from eddiebot.explore.frontiers import Frontier, FrontierSearch, mark_swept, search_frontiers
from eddiebot.explore.homing import path_back, retrace, staging_pose
from eddiebot.explore.markers import frontier_markers
from eddiebot.explore.obstacles import add_costmap_obstacles
from eddiebot.explore.records import ExploreState, GoalRecord
from eddiebot.explore.tracking import Blacklist, FrontierTracker, ProgressMonitor, choose_frontier
from eddiebot.geometry import yaw_to_quaternion
from eddiebot.maps import OccupancyMap, map_from_msg

__all__ = ["ExploreNode", "ExploreState", "GoalRecord"]

_SUCCEEDED, _CANCELED, _ABORTED = 4, 5, 6
#: Failures that say nothing about the goal: the robot's pose was not to be had (FollowPath's
#: and ComputePathToPose's TF_ERROR). The frontier is kept and planned again after a pause.
_TRANSIENT_CODES = frozenset({102, 202})
_TRANSIENT_PAUSE_S = 2.0
#: A kept target's goal is re-sent when its viewpoint moved this far (the frontier changed), m.
_RESEND_DISTANCE = 0.5
#: A frontier whose arrivals promised little is abandoned after this many times
#: ``max_visits`` arrivals in a row that showed nothing.
_IDLE_VISITS = 3
#: The look memory keeps a pose every this many metres or radians.
_LOOK_STEP = 0.1
_LOOK_TURN = 0.15
#: A goal without progress marks the spot this far ahead of the robot as blocked (m).
_BLOCK_AHEAD = 0.4
#: After an arrival the next plan waits for a map whose content changed since, at most this
#: long (s) ...
_MAP_WAIT_S = 10.0
#: ... or, once the map's period is known, this many periods plus _MAP_WAIT_SLACK_S: SLAM
#: adds the last node of an arrival within a scan or two of the stop, and maps it at its
#: next update; later maps are the same map sent again (slam_toolbox sends one every
#: map_update_interval, changed or not).
_MAP_WAIT_PERIODS = 1.5
_MAP_WAIT_SLACK_S = 0.5
#: Attempts at getting home (each after a recovery but the first) before giving up.
_HOME_ATTEMPTS = 4
#: The recovery between attempts backs up this far (m) at this speed (m/s), as the
#: recovery subtree of Nav2's navigate_to_pose tree.
_BACKUP_DISTANCE = 0.30
_BACKUP_SPEED = 0.15
#: ... and then waits this long (s, node clock) before the next attempt.
_RECOVERY_WAIT_S = 5.0
#: Attempts after the first retrace this many metres more of the driven path each
#: (`eddiebot.explore.homing.retrace`).
_RETRACE_LENGTH = 2.0


class ExploreNode(Node):
    default_node_name = "explore_node"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        values = {f.name: self.declare_parameter(f.name, f.default).value
                  for f in dataclasses.fields(ExploreConfig)}
        self.config = ExploreConfig.from_mapping(values)
        from eddiebot.msgs.nav2_msgs import BackUp, ClearEntireCostmap, NavigateToPose, Spin
        from eddiebot.msgs.nav_msgs import OccupancyGrid
        from eddiebot.msgs.std_msgs import Bool
        from eddiebot.msgs.visualization_msgs import MarkerArray

        self.tf_buffer = Buffer(node=self)
        self.tf_listener = TransformListener(self.tf_buffer, self)
        self.create_subscription(OccupancyGrid, "/map", self._on_map, qos_profile_latched)
        self.create_subscription(Bool, "explore/resume", self._on_resume, 10)
        self.costmap: OccupancyMap | None = None
        """The latest ``costmap_topic`` grid; its lethal cells join the map's obstacles."""
        if self.config.costmap_topic:
            self.create_subscription(OccupancyGrid, self.config.costmap_topic,
                                     self._on_costmap, 1)
        self._marker_pub = (self.create_publisher(MarkerArray, "explore/frontiers", 10)
                            if self.config.visualize else None)
        self._nav = ActionClient(self, NavigateToPose, "navigate_to_pose")
        self._spin = ActionClient(self, Spin, "spin")
        self._backup = ActionClient(self, BackUp, "backup")
        self._clear_clients = [
            self.create_client(ClearEntireCostmap, f"/{name}/clear_entirely_{name}")
            for name in ("global_costmap", "local_costmap")]
        self.grid: OccupancyMap | None = None
        self.state = ExploreState.WAITING
        self.paused = False
        self.finish_reason = ""
        self.initial_pose: tuple[float, float, float] | None = None
        self.tracker = FrontierTracker(self.config.frontier_match_tolerance)
        self.blacklist = Blacklist(self.config.blacklist_radius)
        self.goals: list[GoalRecord] = []
        self.last_search: FrontierSearch | None = None
        self.returned_home: bool | None = None
        self.searches = 0
        self._progress = ProgressMonitor(self.config.progress_timeout)
        self._target: int | None = None
        self._goal_handle: Any = None
        self._generation = 0
        self._started_s: float | None = None
        self._last_plan_s = -math.inf
        self._replan = False
        self._last_marker_count = 0
        self._map_stamp_s = -math.inf
        self._map_changed_s = -math.inf
        """Stamp of the latest map whose cells differ from the one before (s)."""
        self._map_period_s: float | None = None
        """Time between the latest two maps (s)."""
        self._fresh_map_after: float | None = None
        self.looks: list[tuple[float, float, float]] = []
        """The robot's poses (map frame, m, rad) every ``_LOOK_STEP`` m or ``_LOOK_TURN`` rad
        since the look-around began: where the camera has looked from."""
        self.path: list[tuple[float, float, float]] = []
        """The robot's positions (map frame, m) and times (s), every 0.1 m."""
        self._home_attempts = 0
        self._outbound = 0
        """Points of ``path`` driven while exploring (before the way home)."""
        self.home_failure = ""
        """Why the last goal home failed ("" once home)."""
        self.recoveries = 0
        self._resume_at: tuple[float, Any] | None = None
        self.avoid: list[tuple[float, float]] = []
        """Goal spots given up for no progress; later goals keep ``avoid_radius`` from them."""
        self.blocked: list[tuple[float, float]] = []
        """Spots just ahead of the robot where a goal made no progress (an obstacle the map
        may not show); viewpoints whose path passes there are avoided when others exist."""
        self.vanished: list[tuple[float, float]] = []
        """Centroids of targets dropped on the way because they no longer showed
        ``min_gain`` (still frontiers, not reached)."""
        self.retries = 0
        self.transient_failures = 0
        """Goals failed for want of the robot's pose (TF), not blamed on their frontier."""
        self.paused = bool(self.declare_parameter("start_paused", False).value)
        """Paused until resumed (``explore/resume``); ``start_paused`` starts it so."""
        from eddiebot.explore.status import ExploreStatus

        self.status = ExploreStatus(self)
        """``explore/status`` and the ``explore/resume`` service."""
        self.create_timer(0.1, self._tick)

    # -- inputs -------------------------------------------------------------------------------
    def _on_map(self, msg: Any) -> None:
        grid = map_from_msg(msg)
        stamp = msg.header.stamp
        stamp_s = int(stamp.sec) + int(stamp.nanosec) * 1e-9
        old = self.grid
        if old is None or old.data.shape != grid.data.shape or old.origin != grid.origin \
                or not np.array_equal(old.data, grid.data):
            self._map_changed_s = stamp_s
        if stamp_s > self._map_stamp_s > -math.inf:
            self._map_period_s = stamp_s - self._map_stamp_s
        self.grid = grid
        self._map_stamp_s = stamp_s

    def _on_costmap(self, msg: Any) -> None:
        self.costmap = map_from_msg(msg)

    def _on_resume(self, msg: Any) -> None:
        if bool(msg.data):
            was_paused = self.paused
            if self.paused:
                self.get_logger().info("exploration resumed")
            self.paused = False
            self._replan = True
            # a pause cancelled the look-around's spin or the goal home: go on from there
            if was_paused and self.state is ExploreState.LOOK_AROUND:
                self.state = ExploreState.EXPLORING
            elif was_paused and self.state is ExploreState.RETURNING and self._resume_at is None:
                self._go_home()
        else:
            if not self.paused:
                self.get_logger().info("exploration paused")
            self.paused = True
            self._cancel_goal()

    @property
    def started_s(self) -> float | None:
        """When exploring began (s, node clock: the look-around), or None before."""
        return self._started_s

    def _now_s(self) -> float:
        return self.get_clock().now_ns() / 1e9

    def robot_pose(self) -> tuple[float, float, float] | None:
        """The robot in the map frame (m, rad), or None while TF cannot tell."""
        frame = self.grid.frame_id if self.grid is not None else "map"
        try:
            return self.tf_buffer.lookup_pose2d(frame or "map", self.config.robot_base_frame, 0)
        except TransformException:
            return None

    # -- the loop -----------------------------------------------------------------------------
    def _tick(self) -> None:
        self.status.tick()
        if self.state is ExploreState.DONE or self.paused:
            return
        now = self._now_s()
        pose = self.robot_pose()
        if pose is not None and self.state is not ExploreState.WAITING:
            self._record_look(pose)
        if self._resume_at is not None:
            if now < self._resume_at[0]:
                return
            then = self._resume_at[1]
            self._resume_at = None
            then()
            return
        if not self._replan and now - self._last_plan_s < 1.0 / self.config.planner_frequency:
            return
        if pose is None or self.grid is None:
            return
        self._replan = False
        self._last_plan_s = now
        if not self.path or math.hypot(pose[0] - self.path[-1][0], pose[1] - self.path[-1][1]) > 0.1:
            self.path.append((pose[0], pose[1], now))
        if self.initial_pose is None:
            self.initial_pose = pose
        if self.state is ExploreState.WAITING:
            if not self._nav.server_is_ready():
                return
            self._started_s = now
            if self.config.look_around and self._spin.server_is_ready():
                self._look_around()
            else:
                self.state = ExploreState.EXPLORING
        if self.state is ExploreState.EXPLORING:
            assert self._started_s is not None
            if self.config.time_limit > 0 and now - self._started_s >= self.config.time_limit:
                self._finish("time limit", pose)
                return
            if self._fresh_map_after is not None:
                if self._waiting_for_map(now):
                    self._replan = True
                    return
                self._fresh_map_after = None
            self._explore(pose, now)

    def _waiting_for_map(self, now: float) -> bool:
        """After an arrival, whether the next plan still waits: a frontier just looked at
        is judged on a map whose cells changed since, or — SLAM adds no node for a robot
        that stands still — once ``_MAP_WAIT_PERIODS`` map periods (+ slack) have passed
        (``_MAP_WAIT_S`` while the period is unknown)."""
        assert self._fresh_map_after is not None
        waited = now - self._fresh_map_after
        bound = _MAP_WAIT_S if self._map_period_s is None else min(
            _MAP_WAIT_S, _MAP_WAIT_PERIODS * self._map_period_s + _MAP_WAIT_SLACK_S)
        return self._map_changed_s <= self._fresh_map_after and waited < bound

    def _record_look(self, pose: tuple[float, float, float]) -> None:
        """Keep the pose when the robot moved ``_LOOK_STEP`` m or turned ``_LOOK_TURN`` rad
        since the last one kept: where the camera has looked from, and which way."""
        if self.looks:
            x, y, yaw = self.looks[-1]
            if (math.hypot(pose[0] - x, pose[1] - y) < _LOOK_STEP
                    and abs(math.remainder(pose[2] - yaw, 2 * math.pi)) < _LOOK_TURN):
                return
        self.looks.append(pose)

    def _look_around(self) -> None:
        from eddiebot.msgs.builtin_interfaces import Duration
        from eddiebot.msgs.nav2_msgs import Spin

        self.state = ExploreState.LOOK_AROUND
        goal = Spin.Goal(target_yaw=2 * math.pi, time_allowance=Duration(sec=30, nanosec=0))
        self.get_logger().info("looking around: one full turn in place")
        self._generation += 1
        generation = self._generation

        def done(result: Any) -> None:
            if generation == self._generation and self.state is ExploreState.LOOK_AROUND:
                self.state = ExploreState.EXPLORING
                self._replan = True

        self._send(self._spin, goal, done)

    def _explore(self, pose: tuple[float, float, float], now: float) -> None:
        assert self.grid is not None
        # a goal given up for no progress first: the search below then avoids its spot
        if self._target is not None and self._goal_handle is not None:
            goal = self.goals[-1].viewpoint
            if self._progress.update(math.hypot(goal[0] - pose[0], goal[1] - pose[1]), now):
                stuck = self.tracker.tracks.get(self._target)
                strikes = 1
                if stuck is not None:
                    stuck.stuck += 1
                    strikes = stuck.stuck
                if strikes >= self.config.stuck_strikes:
                    self._abandon(self.goals[-1].centroid,
                                  f"no progress for {self.config.progress_timeout:.0f} s",
                                  retryable=True)
                else:
                    self.get_logger().info(f"no progress for {self.config.progress_timeout:.0f} s "
                                           f"towards ({goal[0]:.2f}, {goal[1]:.2f}): avoiding it")
                self.avoid.append((goal[0], goal[1]))
                # what held the robot is most likely just ahead of it (the range veto stops
                # forward motion within 0.25 m of its front): later viewpoints are chosen
                # among those whose path does not pass there
                self.blocked.append((pose[0] + _BLOCK_AHEAD * math.cos(pose[2]),
                                     pose[1] + _BLOCK_AHEAD * math.sin(pose[2])))
                self.goals[-1].outcome = "no progress"
                self._cancel_goal()
        swept = mark_swept(self.grid, [(x, y) for x, y, _ in self.path], self.config.robot_radius)
        obstacles = None
        if self.costmap is not None:
            try:
                marked = add_costmap_obstacles(swept, self.costmap)
                obstacles = marked.data >= self.config.occupied_threshold
            except ValueError as exc:
                self.get_logger().warn(f"{self.config.costmap_topic}: {exc}; not used")
                self.costmap = None
        search = search_frontiers(swept, pose, self.config, avoid=self.avoid, looked=self.looks,
                                  blocked=self.blocked, obstacles=obstacles)
        unseen = [f for f in search.frontiers if not self.blacklist.contains(f.centroid)]
        if unseen and all(f.gain < self.config.min_gain for f in unseen):
            # nothing to see from the standoff band of any frontier left: before ending,
            # look from nearer (across a corridor's unknown middle, `search_frontiers`)
            search = search_frontiers(swept, pose, self.config, avoid=self.avoid,
                                      looked=self.looks, blocked=self.blocked,
                                      obstacles=obstacles, near_views=True)
        self.last_search = search
        self.searches += 1
        known = float(np.count_nonzero(self.grid.data >= 0)) * self.grid.resolution**2
        ids = self.tracker.update([f.centroid for f in search.frontiers],
                                  [f.size for f in search.frontiers])
        for f, tid in zip(search.frontiers, ids, strict=True):
            track = self.tracker.tracks[tid]
            track.judge_visit(known)
            if ((track.visits >= self.config.max_visits
                 or track.idle >= _IDLE_VISITS * self.config.max_visits)
                    and not self.blacklist.contains(f.centroid)):
                self._abandon(f.centroid, f"unproductive: reached {track.idle} times, "
                                          "nothing new seen")
        if self._target is not None and self._target not in ids:
            self._target = None  # its frontier is gone: explored on the way
            if self.goals:
                self.goals[-1].outcome = "explored on the way"
        self._note_vanished(search.frontiers, ids)
        choice = choose_frontier(search.frontiers, ids, self.blacklist, self._target, self.config)
        if choice is None and self.retries < self.config.retry_rounds:
            forgiven = self.blacklist.forgive()
            if forgiven:
                self.retries += 1
                self.avoid.clear()
                for t in self.tracker.tracks.values():
                    t.stuck = 0
                self.get_logger().info(f"nothing else left: trying the {forgiven} frontiers "
                                       "the robot could not get to again")
                choice = choose_frontier(search.frontiers, ids, self.blacklist, self._target,
                                         self.config)
        self._publish_markers(search.frontiers, ids)
        if choice is None:
            low = sum(f.gain < self.config.min_gain for f in search.frontiers)
            self._finish(f"no reachable frontier left ({search.unreachable} unreachable, "
                         f"{search.too_small} too small, {low} with nothing to see, "
                         f"{len(self.blacklist)} abandoned)", pose)
            return
        frontier, tid = choice
        if tid == self._target and self._goal_handle is not None:
            old, new = self.goals[-1].viewpoint, self._goal_for(frontier, tid)
            if math.hypot(old[0] - new[0], old[1] - new[1]) < _RESEND_DISTANCE:
                return
        self._go_to(frontier, tid, now)

    def _note_vanished(self, frontiers: Sequence[Frontier], ids: Sequence[int]) -> None:
        """The target still a frontier but showing less than ``min_gain``: the next choice
        goes elsewhere, and the view it promised from afar (a pocket past furniture, an
        edge that flickers) may come back once the robot has left. A place dropped as
        often as an idle frontier is reached (``_IDLE_VISITS`` · ``max_visits``) is
        abandoned as unproductive, or the robot can shuttle between two such places until
        ``time_limit`` (the office, seed 4: 35 switches in 1800 s, 421 m driven)."""
        if self._target is None:
            return
        target = next((f for f, i in zip(frontiers, ids, strict=True) if i == self._target), None)
        if target is None or target.gain >= self.config.min_gain \
                or self.blacklist.contains(target.centroid):
            return
        cx, cy = target.centroid
        self.vanished.append((cx, cy))
        times = sum(math.hypot(x - cx, y - cy) <= self.blacklist.radius for x, y in self.vanished)
        if times >= _IDLE_VISITS * self.config.max_visits:
            self._abandon(target.centroid, f"unproductive: showed nothing on the way {times} times")

    def _goal_for(self, frontier: Frontier, tid: int) -> tuple[float, float, float]:
        """The frontier's viewpoint. After an arrival that showed nothing new, the look
        memory (`looks`) makes the next search's viewpoint another spot or heading."""
        return frontier.viewpoint

    def _go_to(self, frontier: Frontier, tid: int, now: float) -> None:
        from eddiebot.msgs.nav2_msgs import NavigateToPose

        self._progress.reset(now)  # a new goal, or the same frontier's goal moved
        if tid != self._target:
            track = self.tracker.tracks.get(tid)
            if track is not None and self.grid is not None:
                track.known_at_goal = float(np.count_nonzero(self.grid.data >= 0)) \
                    * self.grid.resolution**2
                track.expected = frontier.gain
        self._target = tid
        x, y, yaw = self._goal_for(frontier, tid)
        record = GoalRecord(tid, (x, y, yaw), frontier.centroid, now)
        if self.goals and self.goals[-1].outcome == "active":
            self.goals[-1].outcome = "replaced"
        self.goals.append(record)
        self.get_logger().info(
            f"frontier {tid}: {frontier.size:.1f} m at ({frontier.centroid[0]:.2f}, "
            f"{frontier.centroid[1]:.2f}), goal ({x:.2f}, {y:.2f}), path {frontier.distance:.1f} m, "
            f"gain {frontier.gain:.1f} m², cost {frontier.cost:.2f}")
        self._generation += 1
        generation = self._generation

        def done(result: Any) -> None:
            if generation != self._generation:
                return
            status = int(getattr(result, "status", 0))
            code = int(getattr(getattr(result, "result", None), "error_code", 0))
            self._goal_handle = None
            if status == _SUCCEEDED:
                record.outcome = "reached"
                # the robot stands within the goal checker's tolerance of the viewpoint:
                # count the view from the viewpoint itself as taken
                self.looks.append((x, y, yaw))
                self._fresh_map_after = self._now_s()
                track = self.tracker.tracks.get(tid)
                if track is not None:
                    track.arrived = True
            elif code in _TRANSIENT_CODES:
                record.outcome = f"failed ({status}, code {code}), kept"
                self.transient_failures += 1
                self.get_logger().info(f"navigation failed (code {code}: no robot pose); "
                                       f"planning again in {_TRANSIENT_PAUSE_S:.0f} s")
                self._resume_at = (self._now_s() + _TRANSIENT_PAUSE_S, lambda: None)
            else:
                record.outcome = f"failed ({status}, code {code})"
                self._abandon(frontier.centroid, f"navigation failed (status {status}, code {code})",
                              retryable=True)
            self._target = None
            self._replan = True

        self._send(self._nav, NavigateToPose.Goal(pose=self._pose_stamped(x, y, yaw)), done)

    def _abandon(self, point: tuple[float, float], reason: str, retryable: bool = False) -> None:
        self.get_logger().info(f"abandoning the frontier at ({point[0]:.2f}, {point[1]:.2f}): {reason}")
        self.blacklist.add(point, reason, retryable)

    def _finish(self, reason: str, pose: tuple[float, float, float]) -> None:
        self._cancel_goal()
        self.finish_reason = reason
        self._outbound = len(self.path)
        self.get_logger().info(f"exploration finished: {reason}")
        if not self.config.return_to_init or self.initial_pose is None:
            self.state = ExploreState.DONE
            return
        self.state = ExploreState.RETURNING
        self._go_home()

    def _go_home(self) -> None:
        """Send the robot to its start through ``navigate_to_pose``. When the floor at the
        start is not known free (the Kinect sees nothing nearer than 0.5 m, so the spot the
        robot started on may never have been seen), the first goal is a *staging* pose
        facing it, where the camera sees the start, then the start itself. A failed goal
        is tried again (``_HOME_ATTEMPTS`` in all) after a recovery: both costmaps cleared
        and a short back-up, as Nav2's recovery subtree does."""
        assert self.initial_pose is not None
        self._home_attempts += 1
        goals: list[tuple[float, float, float]] = []
        if self._home_attempts > 1:
            # through what stopped the last attempt the way the robot came while exploring
            # (it drove there, the other way); else away from it, where it has driven
            goals = self._retrace((self._home_attempts - 1) * _RETRACE_LENGTH)
            back = self._path_back() if not goals else None
            if back is not None:
                goals.append(back)
        staging = self._staging_pose()
        if staging is not None:
            goals.append(staging)
        goals.append(self.initial_pose)
        x, y, _ = self.initial_pose
        via = len(goals) - 1 - (staging is not None)
        self.get_logger().info(f"returning to the start ({x:.2f}, {y:.2f}), attempt "
                               f"{self._home_attempts} of {_HOME_ATTEMPTS}"
                               + (f" by way of {via} point{'s' * (via > 1)} of the driven path" if via else "")
                               + (" via a pose facing it" if staging is not None else ""))
        self._home_leg(goals)

    def _home_leg(self, goals: list[tuple[float, float, float]]) -> None:
        from eddiebot.msgs.nav2_msgs import NavigateToPose

        x, y, yaw = goals[0]
        self._generation += 1
        generation = self._generation

        def done(result: Any) -> None:
            if generation != self._generation:
                return
            self._goal_handle = None
            status = int(getattr(result, "status", 0)) if result is not None else 0
            if status == _SUCCEEDED:
                if len(goals) > 1:
                    self._home_leg(goals[1:])
                    return
                self.returned_home = True
                self.home_failure = ""
                self.get_logger().info("back at the start")
                self.state = ExploreState.DONE
                return
            inner = getattr(result, "result", None) if result is not None else None
            msg = str(getattr(inner, "error_msg", "") or "")
            why = ("goal rejected" if result is None else
                   f"status {status}, code {int(getattr(inner, 'error_code', 0))}"
                   + (f": {msg}" if msg else ""))
            self.home_failure = (f"attempt {self._home_attempts}: goal ({x:.2f}, {y:.2f}) "
                                 f"failed ({why})")
            self.get_logger().warning(f"going home: {self.home_failure}")
            self.returned_home = False
            if self._home_attempts >= _HOME_ATTEMPTS:
                self.get_logger().error(f"could not get home after {_HOME_ATTEMPTS} attempts; "
                                        f"last: {self.home_failure}")
                self.state = ExploreState.DONE
                return
            self._recover(self._go_home)

        self._send(self._nav, NavigateToPose.Goal(pose=self._pose_stamped(x, y, yaw)), done)

    def _recover(self, then: Any) -> None:
        """Clear both costmaps (stale obstacles, a person who walked on), back up
        ``_BACKUP_DISTANCE`` m, then call ``then``, whatever the back-up's outcome."""
        from eddiebot.msgs.builtin_interfaces import Duration
        from eddiebot.msgs.geometry_msgs import Point
        from eddiebot.msgs.nav2_msgs import BackUp, ClearEntireCostmap

        self.recoveries += 1
        for client in self._clear_clients:
            if client.service_is_ready():
                client.call_async(ClearEntireCostmap.Request())
        goal = BackUp.Goal(target=Point(x=-_BACKUP_DISTANCE, y=0.0, z=0.0),
                           speed=_BACKUP_SPEED, time_allowance=Duration(sec=10, nanosec=0))
        self.get_logger().info(f"recovery: costmaps cleared, backing up {_BACKUP_DISTANCE:.2f} m")
        self._generation += 1
        generation = self._generation

        def done(_result: Any) -> None:
            if generation != self._generation:
                return
            self._goal_handle = None
            # then wait, as Nav2's recovery subtree: a person in the way walks on
            self._resume_at = (self._now_s() + _RECOVERY_WAIT_S, then)

        if self._backup.server_is_ready():
            self._send(self._backup, goal, done)
        else:
            done(None)

    def _retrace(self, length: float) -> list[tuple[float, float, float]]:
        """`retrace` of the path driven while exploring, from where the robot is."""
        return retrace(self.path, self._outbound, length)

    def _path_back(self) -> tuple[float, float, float] | None:
        """`path_back` of the robot's own path."""
        return path_back(self.path)

    def _staging_pose(self) -> tuple[float, float, float] | None:
        """`staging_pose` for the start, on the current map."""
        if self.grid is None or self.initial_pose is None:
            return None
        return staging_pose(self.grid, self.initial_pose, self.config)

    def stop(self, reason: str = "stopped") -> None:
        """Cancel the running goal and explore no more; the robot is not sent home."""
        self._cancel_goal()
        if self.state is not ExploreState.DONE:
            self.finish_reason = self.finish_reason or reason
        self.state = ExploreState.DONE

    # -- plumbing -----------------------------------------------------------------------------
    def _pose_stamped(self, x: float, y: float, yaw: float) -> Any:
        from eddiebot.msgs.geometry_msgs import PoseStamped

        msg = PoseStamped()
        msg.header.frame_id = self.grid.frame_id if self.grid is not None else "map"
        msg.pose.position.x, msg.pose.position.y = float(x), float(y)
        q = yaw_to_quaternion(yaw)
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in q)
        return msg

    def _send(self, client: ActionClient, goal: Any, on_result: Any) -> None:
        generation = self._generation
        future = client.send_goal_async(goal)

        def accepted(f: Any) -> None:
            handle = f.result() if f.exception() is None else None
            if generation != self._generation:
                if handle is not None and handle.accepted:
                    handle.cancel_goal_async()
                return
            if handle is None or not handle.accepted:
                on_result(None)
                return
            self._goal_handle = handle
            handle.get_result_async().add_done_callback(
                lambda r: on_result(r.result() if r.exception() is None else None))

        future.add_done_callback(accepted)

    def _cancel_goal(self) -> None:
        self._generation += 1
        if self._goal_handle is not None:
            self._goal_handle.cancel_goal_async()
        self._goal_handle = None
        self._target = None

    def _publish_markers(self, frontiers: tuple[Frontier, ...], ids: list[int]) -> None:
        if self._marker_pub is None or self.grid is None:
            return
        msg = frontier_markers(frontiers, ids, self.blacklist, self._target, self.grid,
                               self.get_clock().now().to_msg(), self._last_marker_count)
        self._last_marker_count = 2 * len(frontiers)
        self._marker_pub.publish(msg)
