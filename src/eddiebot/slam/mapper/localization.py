"""Localization against a loaded graph: slam_toolbox's rolling buffer of recent scans, and a
global relocalisation over the whole map when there is no pose to track from.

Tracking (slam_toolbox's ``ProcessLocalization``): the scan is placed by odometry from the
last localised scan and matched (the sequential matcher, with its odometry penalty) against
the loaded graph's scans near that prior *and* the localization buffer — the last
``scan_buffer_size`` localised scans at their localised poses. The buffer plays the part of
upstream's running scans: it carries the pose through places the map's scans see poorly or
that changed since mapping. Unlike upstream, buffered scans never enter the pose graph (no
temporary vertices to remove again); the graph, its nodes and the map stay exactly as loaded.
A match below ``link_match_minimum_response_fine`` leaves the odometry pose (``weak_match``)
and that scan does not enter the buffer; a match below the slip re-search's threshold
(``slip_search_minimum_response``, else ``loop_match_minimum_response_fine``) is first
searched again over the loop-closure window against the map's scans alone.

The buffer's scans match each other whatever the map says, so a pose that went wrong (a
kidnapped robot, a failed match) would carry on confidently: each placed scan is also scored
against the map's scans alone, and a scan whose *map support* is below that same threshold
counts as unsupported.

Relocalisation: with no pose (localization started without ``map_start_pose`` or
``/initialpose``), or after ``scan_buffer_size`` consecutive unsupported scans (a place the map
does not cover is tracked through the buffer meanwhile), the scan is searched over the whole
map: one correlation grid of every active node's scan at the loop search's resolution and
smear, every heading, every translation where the map's scans were taken or what they saw
(branch and bound), then the loop closer's fine match against the nodes near the best pose. It is accepted as a loop closure is (Karto's two-stage
check): the coarse response reaches ``loop_match_minimum_response_coarse`` with x and y
variances below ``loop_match_maximum_variance_coarse`` (a scan that fits several places of the
map spreads its candidates: refused as ambiguous), and the fine response reaches
``loop_match_minimum_response_fine``. When tracking was lost (rather than never had), the
view of the buffered scans together (their poses relative to the newest hold even when the
map frame went wrong) decides: the newest scan's best distinct places over the whole map are
the candidates, the view is matched around each and fits best at the answer
(`eddiebot.slam.mapper.global_search`), which must also fit that view better than the
tracked pose does (the loop closer's fine match there). Otherwise it is refused: status
``LOST`` without a pose to keep, else the tracked pose is kept. ``relocalizations`` records
each attempt.

Bounded cost: a whole-map search costs as much as tens of tracked scans (0.1–1 s of CPU). Without a pose, refused attempts back off: the next after 1, 3, 7 … scans, at most
``scan_buffer_size``. (Backing off tracked attempts too — doubling the unsupported scans before
each — cost ACES its relocalisations that correct the track: median error 0.13 → 0.56 m.)
With a `global_search` (the node's spawned
process) the whole-map search runs off the scan's call: the scan returns at once (``LOST``,
or tracked on at its pose), no second search starts while one runs, and the first scan after
the answer takes it — accepted, the searched scan's pose carried by odometry to this one is
its prior. A new pose or a cleared buffer drops a search in flight.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_compose, se2_inverse
from eddiebot.slam.mapper.global_search import search_view
from eddiebot.slam.mapper.mapping import Mapping
from eddiebot.slam.mapper.results import FloatArray, ProcessResult, ProcessStatus, SlamWarning
from eddiebot.slam.mapper.se2_rows import _compose1
from eddiebot.slam.scan import Scan, scan_points
from eddiebot.slam.scan_matcher import (
    CorrelationGrid,
    MatcherParams,
    MatchResult,
    build_correlation_grid,
    match_scan,
    point_normals,
    pyramid_levels,
    score_pose,
)


@dataclass(frozen=True)
class Relocalization:
    """One global relocalisation attempt: the robot pose found (map frame), the coarse and
    fine responses, the coarse match's larger position variance (m²), and whether it passed
    the loop-closure thresholds."""

    pose: FloatArray
    coarse_response: float
    response: float
    accepted: bool
    coarse_variance: float = math.inf
    stamp_ns: int = 0


@dataclass(frozen=True)
class GlobalMap:
    """What a whole-map search matches against: every active node's end points (map frame)
    inside ``bounds``, searched from ``prior`` (the map's centre) with ``params``; a view's
    candidate places need a scan response above ``minimum_response``. ``key`` changes
    whenever the graph does."""

    key: int
    reference: FloatArray
    bounds: tuple[float, float, float, float]
    prior: FloatArray
    params: MatcherParams
    minimum_response: float = 0.0

    def grid(self) -> CorrelationGrid:
        """The correlation grid (with the pyramid branch and bound reads), padded by the
        coarsest level's block: a level's cell bounds the block of finer cells above and to
        the right of it, so a point that falls off the grid under a block's corner while
        some of the block's candidates bring it onto the map would otherwise count 0."""
        p = self.params
        levels = pyramid_levels(p)
        pad = (1 << (levels - 1)) * p.resolution
        lo_x, lo_y, hi_x, hi_y = self.bounds
        return build_correlation_grid(
            self.reference,
            (lo_x - pad, lo_y - pad, hi_x + pad, hi_y + pad),
            p.resolution,
            p.smear_deviation,
            levels,
        )

    def search(
        self,
        points: FloatArray,
        grid: CorrelationGrid | None = None,
        view: FloatArray | None = None,
        tracked: FloatArray | None = None,
    ) -> MatchResult:
        """The best sensor pose of ``points`` (sensor frame) over the whole map; with a
        ``view`` (``points`` and the scans before them, same frame), the view's, found at the
        scan's best places and at ``tracked``, the sensor pose tracking holds
        (`eddiebot.slam.mapper.global_search.search_view`)."""
        grid = grid if grid is not None else self.grid()
        if view is not None:
            return search_view(
                points, view, grid, self.prior, self.params, self.minimum_response, tracked
            )
        return match_scan(points, grid, self.prior, self.params)


class GlobalSearch(Protocol):
    """Runs `GlobalMap.search` away from the scan's call (a process of its own)."""

    def submit(
        self,
        source: GlobalMap,
        points: FloatArray,
        view: FloatArray | None = None,
        tracked: FloatArray | None = None,
    ) -> int:
        """Start ``source.search(points, view=view, tracked=tracked)``; its ticket."""
        ...

    def poll(self) -> tuple[int, MatchResult] | None:
        """A finished search's ticket and match, without waiting; None while none is ready."""
        ...


@dataclass
class _Pending:
    """A relocalisation whose whole-map search runs off the scan's call."""

    points: FloatArray
    """The scan's end points, sensor frame."""
    view: FloatArray
    """What is searched: the scan with the buffer's scans (tracked), sensor frame."""
    odom: FloatArray
    stamp: int
    why: str
    fallback: FloatArray | None
    """The tracked pose at that scan (None: there was none)."""
    ticket: int = -1


@dataclass
class _Buffered:
    points: FloatArray
    """End points, sensor frame (M, 2)."""
    normals: FloatArray
    """Their normals, sensor frame (M, 2)."""
    pose: FloatArray
    """Localised robot pose, map frame."""


class Localization(Mapping):
    """`Mapping` with localization mode (see the module docstring)."""

    global_search: GlobalSearch | None = None
    """Runs the whole-map search of a relocalisation off the scan's call (the node's
    `eddiebot.slam.relocalization_process.RelocalizationProcess`); None: in the call. Kept
    by `clear`."""

    def clear(self) -> None:
        super().clear()
        self._loc_buffer: deque[_Buffered] = deque()
        self._weak_run = 0
        self._lost_wait = 0
        self._lost_refusals = 0
        self._pending: _Pending | None = None
        self._global: tuple[CorrelationGrid, GlobalMap] | None = None
        self._global_map: tuple[int, GlobalMap] | None = None
        self._global_key = 0
        self.relocalizations: list[Relocalization] = []
        """Every global relocalisation attempt, accepted or refused, in order."""

    def clear_localization_buffer(self) -> None:
        """Forget the recent localised scans (slam_toolbox's ``clear_localization_buffer``)
        and any relocalisation in flight; the next lost scans attempt one again at once."""
        self._loc_buffer.clear()
        self._weak_run = 0
        self._lost_wait = 0
        self._lost_refusals = 0
        self._pending = None

    def set_initial_pose(
        self, pose: npt.ArrayLike, odom_pose: npt.ArrayLike | None = None
    ) -> None:
        super().set_initial_pose(pose, odom_pose)
        self.clear_localization_buffer()

    def start_at(self, pose: npt.ArrayLike) -> None:
        super().start_at(pose)
        self.clear_localization_buffer()

    # -- tracking
    def _localize(self, scan: Scan, odom: FloatArray, warnings: list[SlamWarning]) -> ProcessResult:
        cfg = self.config
        st = self._state
        stamp = int(scan.stamp_ns)
        if not self.nodes:
            self._warn(warnings, "no_map", "localization mode without a loaded session", stamp)
            return ProcessResult(ProcessStatus.SKIPPED, self.map_to_odom, warnings=tuple(warnings))
        points = scan_points(scan, cfg.max_laser_range)
        self._collect_search(warnings, stamp)
        if st.last_pose is None:
            return self._lost(points, odom, stamp, warnings)
        prior = self._prior(odom)
        prior_sensor = _compose1(prior, self.sensor_offset)
        ref_nodes = self._nodes_near(prior_sensor[:2])
        extra = self._buffer_reference()
        pose = prior
        response = 0.0
        covariance = None
        matched = False
        support = 0.0
        if ref_nodes or extra is not None:
            match = self._match_against(
                ref_nodes, points, prior_sensor, self._seq_params, extra=extra
            )
            if match.response < self._weak_response and ref_nodes:
                wide = self._match_against(ref_nodes, points, prior_sensor, self._loop_coarse)
                if wide.response > match.response:
                    fine = self._match_against(ref_nodes, points, wide.pose, self._loop_fine)
                    if fine.response > match.response:
                        match = fine
            response, covariance = match.response, match.covariance
            if match.response >= cfg.link_match_minimum_response_fine:
                pose = se2_compose(match.pose, se2_inverse(self.sensor_offset))
                matched = True
                self._check_covariance(match, warnings, stamp)
                support = self._map_support(ref_nodes, points, match.pose)
            else:
                self._warn(
                    warnings,
                    "weak_match",
                    f"localization match response {match.response:.2f} below "
                    f"link_match_minimum_response_fine {cfg.link_match_minimum_response_fine}; "
                    "using odometry",
                    stamp,
                )
        else:
            self._warn(
                warnings, "off_map", "no map nodes near the predicted pose; using odometry", stamp
            )
        if matched:
            self._buffer(points, pose)
        if support >= self._weak_response:
            self._weak_run = 0
        else:
            self._weak_run += 1
            if self._weak_run >= cfg.scan_buffer_size and self._pending is None:
                run, self._weak_run = self._weak_run, 0
                return self._relocalize_scan(
                    points, odom, stamp, warnings,
                    f"{run} consecutive scans the map does not support",
                    fallback=pose, covariance=covariance,
                )
        return self._localized(pose, odom, response, covariance, warnings)

    def _lost(
        self, points: FloatArray, odom: FloatArray, stamp: int, warnings: list[SlamWarning]
    ) -> ProcessResult:
        """A scan with no pose to track from: a whole-map search, unless one is running or
        the last ones were refused (the next after 1, 3, 7 … scans, at most
        ``scan_buffer_size``)."""
        if self._pending is not None or self._lost_wait > 0:
            self._lost_wait = max(0, self._lost_wait - 1)
            return ProcessResult(ProcessStatus.LOST, self.map_to_odom, warnings=tuple(warnings))
        return self._relocalize_scan(points, odom, stamp, warnings, "no initial pose")

    def _map_support(self, nodes: list[int], points: FloatArray, sensor: FloatArray) -> float:
        """Response of the scan at sensor pose ``sensor`` against the map's ``nodes`` alone
        (the loop search's grid): how far the map, not the buffer, backs the pose."""
        if not nodes:
            return 0.0
        ref, _ = self._reference(nodes, self.graph.poses)
        params = self._loop_fine
        c, s = math.cos(sensor[2]), math.sin(sensor[2])
        wx = sensor[0] + c * points[:, 0] - s * points[:, 1]
        wy = sensor[1] + s * points[:, 0] + c * points[:, 1]
        grid = build_correlation_grid(
            ref,
            (float(wx.min()), float(wy.min()), float(wx.max()), float(wy.max())),
            params.resolution,
            params.smear_deviation,
        )
        return score_pose(points, sensor, grid)

    def _localized(
        self,
        pose: FloatArray,
        odom: FloatArray,
        response: float,
        covariance: FloatArray | None,
        warnings: list[SlamWarning],
        status: ProcessStatus = ProcessStatus.LOCALIZED,
    ) -> ProcessResult:
        st = self._state
        st.last_pose = pose.copy()
        st.last_processed_odom = odom.copy()
        st.map_to_odom = se2_compose(pose, se2_inverse(odom))
        return ProcessResult(
            status,
            self.map_to_odom,
            pose=pose.copy(),
            response=response,
            covariance=covariance,
            warnings=tuple(warnings),
        )

    def _nodes_near(self, xy: FloatArray) -> list[int]:
        """Active map nodes within ``scan_buffer_maximum_scan_distance`` of ``xy``, nearest
        first, at most 2 × ``scan_buffer_size``."""
        cfg = self.config
        positions = self._positions()
        active = np.flatnonzero(self.active_mask())
        d = np.hypot(positions[active, 0] - xy[0], positions[active, 1] - xy[1])
        keep = d <= cfg.scan_buffer_maximum_scan_distance
        near = active[keep][np.argsort(d[keep], kind="stable")]
        return [int(i) for i in near[: 2 * cfg.scan_buffer_size]]

    def _buffer(self, points: FloatArray, pose: FloatArray) -> None:
        self._loc_buffer.append(_Buffered(points, point_normals(points), pose.copy()))
        while len(self._loc_buffer) > self.config.scan_buffer_size:
            self._loc_buffer.popleft()

    def _buffer_reference(self) -> tuple[FloatArray, FloatArray] | None:
        """The buffer's end points and normals in the map frame (None when empty)."""
        if not self._loc_buffer:
            return None
        pts, nrm = [], []
        for b in self._loc_buffer:
            sensor = _compose1(b.pose, self.sensor_offset)
            c, s = math.cos(sensor[2]), math.sin(sensor[2])
            rot = np.array([[c, -s], [s, c]])
            pts.append(b.points @ rot.T + sensor[:2])
            nrm.append(b.normals @ rot.T)
        return np.concatenate(pts), np.concatenate(nrm)

    # -- global relocalisation
    def _relocalize_scan(
        self,
        points: FloatArray,
        odom: FloatArray,
        stamp: int,
        warnings: list[SlamWarning],
        why: str,
        *,
        fallback: FloatArray | None = None,
        covariance: FloatArray | None = None,
    ) -> ProcessResult:
        # lost while tracking: the scan's best places are checked with the view of the recent
        # scans (their poses relative to this one hold even when the map frame went wrong): a
        # wider view fits fewer wrong places; and it must fit the map better than where the
        # robot is tracked now
        view = tracked = None
        if fallback is not None:
            view = self._recent_view(points, fallback)
            tracked = _compose1(fallback, self.sensor_offset)
        pending = _Pending(points, points if view is None else view, odom.copy(), stamp, why, fallback)
        if self.global_search is not None:
            self._pending = pending
            pending.ticket = self.global_search.submit(
                self._global_source(), points, view, tracked
            )
            if fallback is None:
                return ProcessResult(ProcessStatus.LOST, self.map_to_odom, warnings=tuple(warnings))
            return self._localized(fallback, odom, 0.0, covariance, warnings)
        grid, source = self._global_grid()
        found = self._conclude(pending, source.search(points, grid, view, tracked), warnings)
        if found.accepted:
            self._restart_buffer(points, found.pose)
            return self._localized(found.pose, odom, found.response, None, warnings)
        if fallback is None:
            return ProcessResult(ProcessStatus.LOST, self.map_to_odom, warnings=tuple(warnings))
        return self._localized(fallback, odom, found.response, covariance, warnings)

    def _collect_search(self, warnings: list[SlamWarning], stamp: int) -> None:
        """Take the answer of a whole-map search running off the scan's call, if it came:
        accepted, the robot is placed there at the searched scan's odometry (this scan is
        then tracked from it)."""
        pending, search = self._pending, self.global_search
        if pending is None or search is None:
            return
        answer = search.poll()
        if answer is None:
            return
        ticket, coarse = answer
        if ticket != pending.ticket:
            return  # a search whose request was dropped since (new pose, cleared buffer)
        self._pending = None
        found = self._conclude(pending, coarse, warnings)
        if not found.accepted:
            self._weak_run = 0  # as in the call: the next after scan_buffer_size more
            return
        st = self._state
        if pending.fallback is not None and st.last_pose is not None:
            # tracked on since the searched scan: the buffer's poses hold relative to each
            # other, so the correction the search found moves them all (a robot that drove
            # on meanwhile is not dead-reckoned from there)
            fix = se2_compose(found.pose, se2_inverse(pending.fallback))
            st.last_pose = se2_compose(fix, st.last_pose)
            st.map_to_odom = se2_compose(fix, st.map_to_odom)
            for b in self._loc_buffer:
                b.pose = se2_compose(fix, b.pose)
            self._weak_run = 0
            return
        self._restart_buffer(pending.points, found.pose)
        st.last_pose = found.pose.copy()
        st.last_processed_odom = pending.odom.copy()
        st.map_to_odom = se2_compose(found.pose, se2_inverse(pending.odom))

    def _conclude(
        self, pending: _Pending, coarse: MatchResult, warnings: list[SlamWarning]
    ) -> Relocalization:
        """The loop closer's fine match after a whole-map ``coarse`` match of
        ``pending.view``, the acceptance checks, the record and the warning."""
        cfg = self.config
        found = self._finish_relocalization(coarse, pending.view, pending.stamp)
        tracked = 0.0
        if pending.fallback is not None:
            sensor = _compose1(pending.fallback, self.sensor_offset)
            near = self._nodes_near(sensor[:2])
            if near:
                tracked = self._match_against(near, pending.view, sensor, self._loop_fine).response
            if found.accepted and found.response <= tracked:
                found = dataclasses.replace(found, accepted=False)
                self.relocalizations[-1] = found
        stamp, why = pending.stamp, pending.why
        if found.accepted:
            self._warn(
                warnings,
                "relocalized",
                f"{why}: relocalised globally at ({found.pose[0]:.2f}, {found.pose[1]:.2f}, "
                f"{found.pose[2]:.2f}), response {found.response:.2f}",
                stamp,
            )
            self._lost_refusals = 0
            return found
        if pending.fallback is None:
            # no pose: the next attempts after 1, 3, 7 … scans, at most scan_buffer_size
            self._lost_refusals += 1
            self._lost_wait = min(2**self._lost_refusals - 1, cfg.scan_buffer_size)
        self._warn(
            warnings,
            "relocalization_failed",
            f"{why}: global relocalisation refused (best: coarse response "
            f"{found.coarse_response:.2f}, variance {found.coarse_variance:.3g} m², fine "
            f"response {found.response:.2f}; needs >= {cfg.loop_match_minimum_response_coarse}, "
            f"< {cfg.loop_match_maximum_variance_coarse} m², >= "
            f"{cfg.loop_match_minimum_response_fine}, and above the tracked pose's {tracked:.2f})",
            stamp,
        )
        return found

    def _restart_buffer(self, points: FloatArray, pose: FloatArray) -> None:
        """The buffer holds only ``points`` at robot pose ``pose`` (after a relocalisation)."""
        self.clear_localization_buffer()
        self._buffer(points, pose)

    def _recent_view(self, points: FloatArray, pose: FloatArray) -> FloatArray:
        """The buffer's scans and ``points`` (taken at robot pose ``pose``), all in this
        scan's sensor frame."""
        here = _compose1(pose, self.sensor_offset)
        c, s = math.cos(here[2]), math.sin(here[2])
        parts = [points]
        for b in self._loc_buffer:
            if np.array_equal(b.pose, pose) and b.points is points:
                continue
            sensor = _compose1(b.pose, self.sensor_offset)
            rel_x = c * (sensor[0] - here[0]) + s * (sensor[1] - here[1])
            rel_y = -s * (sensor[0] - here[0]) + c * (sensor[1] - here[1])
            th = sensor[2] - here[2]
            cb, sb = math.cos(th), math.sin(th)
            moved = np.empty_like(b.points)
            moved[:, 0] = rel_x + cb * b.points[:, 0] - sb * b.points[:, 1]
            moved[:, 1] = rel_y + sb * b.points[:, 0] + cb * b.points[:, 1]
            parts.append(moved)
        return np.ascontiguousarray(np.concatenate(parts))

    def _global_source(self) -> GlobalMap:
        """What the whole-map search matches against: every active node's scan at its pose
        (cached while the graph's nodes and poses stay as they are)."""
        poses = self.graph.poses
        active = np.flatnonzero(self.active_mask())
        fingerprint = hash((len(self.nodes), active.tobytes(), poses.tobytes()))
        cached = self._global_map
        if cached is not None and cached[0] == fingerprint:
            return cached[1]
        ref, _ = self._reference([int(i) for i in active], poses)
        lo, hi = ref.min(axis=0), ref.max(axis=0)
        # the robot stands where the map's scans were taken or what they saw: its sensor is
        # searched for over both, not beyond (a laser's range outside the map is empty)
        sensors = se2_compose(
            poses[active], np.broadcast_to(self.sensor_offset, (active.size, 3))
        )[:, :2]
        where_lo = np.minimum(lo, sensors.min(axis=0))
        where_hi = np.maximum(hi, sensors.max(axis=0))
        centre = 0.5 * (where_lo + where_hi)
        side = float(max(where_hi - where_lo))
        self._global_key += 1
        source = GlobalMap(
            key=self._global_key,
            reference=np.ascontiguousarray(ref),
            bounds=(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])),
            prior=np.array([centre[0], centre[1], 0.0]),
            params=self._global_params(side),
            minimum_response=self.config.loop_match_minimum_response_coarse,
        )
        self._global_map = (fingerprint, source)
        self._global = None
        return source

    def _global_grid(self) -> tuple[CorrelationGrid, GlobalMap]:
        """`_global_source` and its correlation grid (built once per source)."""
        source = self._global_source()
        if self._global is None or self._global[1] is not source:
            self._global = (source.grid(), source)
        return self._global

    def _global_params(self, side: float) -> MatcherParams:
        return dataclasses.replace(
            self._loop_coarse,
            search_dimension=side,
            coarse_angle_offset=math.pi,
            use_response_expansion=False,
            penalize=False,
        )

    def relocalize(self, points: FloatArray, *, stamp_ns: int = 0) -> Relocalization:
        """Search the whole map for scan end points ``points`` (sensor frame): the best robot
        pose, its responses, and whether it passes the loop-closure thresholds. Recorded in
        ``relocalizations``; the tracked pose is not changed. Runs in the call (also with a
        `global_search`)."""
        if not self.nodes or points.shape[0] == 0:
            out = Relocalization(np.zeros(3), 0.0, 0.0, False, math.inf, stamp_ns)
            self.relocalizations.append(out)
            return out
        grid, source = self._global_grid()
        return self._finish_relocalization(source.search(points, grid), points, stamp_ns)

    def _finish_relocalization(
        self, coarse: MatchResult, points: FloatArray, stamp_ns: int
    ) -> Relocalization:
        """The fine match after a whole-map ``coarse`` match and the loop-closure checks;
        recorded in ``relocalizations``."""
        cfg = self.config
        fine = coarse
        near = self._nodes_near(coarse.pose[:2])
        if near and points.shape[0]:
            fine = self._match_against(near, points, coarse.pose, self._loop_fine)
        variance = float(max(coarse.covariance[0, 0], coarse.covariance[1, 1]))
        accepted = (
            coarse.response >= cfg.loop_match_minimum_response_coarse
            and variance < cfg.loop_match_maximum_variance_coarse
            and fine.response >= cfg.loop_match_minimum_response_fine
        )
        pose = se2_compose(fine.pose, se2_inverse(self.sensor_offset))
        out = Relocalization(
            pose, float(coarse.response), float(fine.response), accepted, variance, stamp_ns
        )
        self.relocalizations.append(out)
        return out
