"""The oracle tour of a world: a route that sees every reachable free cell, from the ground truth.

What exploration is measured against (issue "Map a building by itself": simulated time within
1.5x of an oracle tour). The oracle knows the world before it starts:

1. *Floor*: the reachable free floor as ``bench_explore``'s coverage counts it
   (`eddiebot.explore.mission.reachable_free_area`: the footprint ground truth, robot-centre
   positions at least the footprint radius from it and connected to the start, grown back by
   that radius). Those cells are the ones to see.
2. *Viewpoints*: robot-centre positions on a lattice (``spacing``) over the centres the robot
   can reach, each with ``headings`` headings. From each position rays (``rays`` per turn) are
   marched through the scan-height ground truth (the plane the Kinect's scan lies in) and
   stop at the first occupied cell; a floor cell is seen from (position, heading) when a ray
   within half the field of view (57°) of the heading reaches it between the usable
   ``min_range`` and ``max_range`` (0.5-4.5 m). The sensor is taken at the robot's centre.
3. *Cover*: greedy set cover (the viewpoint that sees the most cells not yet seen, evaluated
   lazily) until 95 % of the seeable floor is seen, then on to all of it. Floor that no
   candidate sees (closer than ``min_range`` to every position in a tight spot) is reported
   (`OracleTour.unseeable`), not chased.
4. *Order*: nearest neighbour from the start pose, then 2-opt and or-opt, on the driving
   times between the viewpoints through the footprint-free centres (8-connected grid,
   Dijkstra).
5. *Time*: each leg driven at the controller's speed (``desired_linear_vel``, capped by the
   velocity smoother's ``max_velocity``), held to the collision monitor's ``limit`` circle's
   speed where the robot's centre is within its radius of an obstacle (``NearWallLimit``:
   0.2 m/s within 0.5 m), slowing over the last ``approach_velocity_scaling_dist`` as RPP
   does until the goal checker's ``xy_goal_tolerance`` is left, with the smoother's
   acceleration and deceleration from and to standstill (`path_drive_time`); routes are
   the fastest at those speeds. At each viewpoint the robot turns in place from the way it
   came to the viewpoint's heading and then to the way it leaves, at the controller's
   ``rotate_to_heading_angular_vel`` with the angular acceleration the smoother and the
   controller allow. Values from ``config/nav2.yaml`` (`speed_limits`).

It is an upper bound of the best tour, not the best tour: the robot sees nothing while it
drives between viewpoints here (the real one maps on the way), and greedy cover plus 2-opt are
heuristics. It is a lower bound of what exploration can do in that it knows where to look.

    .venv/bin/python benchmarks/explore_oracle.py [--worlds office maze ...]
"""

from __future__ import annotations

import argparse
import heapq
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = ["OracleParams", "OracleTour", "SpeedLimits", "greedy_cover", "leg_time",
           "oracle_for_world", "oracle_tour", "order_tour", "path_drive_time", "speed_limits",
           "turn_time", "visibility"]

Pose = tuple[float, float, float]


@dataclass(frozen=True)
class SpeedLimits:
    """Eddie's driving limits as the nav config has them (m/s, m/s², rad/s, rad/s²)."""

    linear: float = 0.4
    accel: float = 0.8
    decel: float = 1.0
    angular: float = 1.2
    angular_accel: float = 2.0
    near_wall_radius: float = 0.0
    """The collision monitor's ``limit`` circle (``NearWallLimit``): within this distance of
    an obstacle (m) the speed is held to ``near_wall_linear``; 0: no such zone."""
    near_wall_linear: float = math.inf
    approach_dist: float = 0.0
    """RPP's ``approach_velocity_scaling_dist``: over a path's last metres the speed falls
    in proportion to what is left, to ``approach_min`` (``min_approach_linear_velocity``),
    until the goal checker's ``goal_tolerance`` (``xy_goal_tolerance``); 0: none."""
    approach_min: float = 0.0
    goal_tolerance: float = 0.0

    def cap(self, clearance_m: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """The driving speed (m/s) at robot centres ``clearance_m`` from the nearest obstacle."""
        return np.where(np.asarray(clearance_m) < self.near_wall_radius,
                        min(self.linear, self.near_wall_linear), self.linear)


def speed_limits(nav2_yaml: Path | None = None) -> SpeedLimits:
    """The limits from ``config/nav2.yaml``: the controller's ``FollowPath``
    (``desired_linear_vel``, ``rotate_to_heading_angular_vel``, ``max_angular_accel``, and
    RPP's approach slowdown) capped by the velocity smoother's ``max_velocity``,
    ``max_accel``, ``max_decel``; the collision monitor's enabled ``limit`` circles (the
    lowest ``linear_limit``, the widest ``radius``); the goal checker's
    ``xy_goal_tolerance``."""
    import yaml

    if nav2_yaml is None:
        from eddiebot.nav.params_file import default_params

        nav2_yaml = default_params()
    doc = yaml.safe_load(Path(nav2_yaml).read_text()) or {}
    ctrl = doc["controller_server"]["ros__parameters"]
    plugin = ctrl[ctrl["controller_plugins"][0]]
    smooth = doc["velocity_smoother"]["ros__parameters"]
    vmax, amax, dmax = smooth["max_velocity"], smooth["max_accel"], smooth["max_decel"]
    monitor = (doc.get("collision_monitor") or {}).get("ros__parameters") or {}
    radius, limit = 0.0, math.inf
    for name in monitor.get("polygons") or []:
        poly = monitor.get(name) or {}
        if poly.get("type") == "circle" and poly.get("action_type") == "limit" \
                and poly.get("enabled", True):
            radius = max(radius, float(poly["radius"]))
            limit = min(limit, float(poly.get("linear_limit", math.inf)))
    approach = 0.0
    if "RegulatedPurePursuit" in str(plugin.get("plugin", "")):
        approach = float(plugin.get("approach_velocity_scaling_dist", 0.6))
    checkers = ctrl.get("goal_checker_plugins") or []
    checker = ctrl.get(checkers[0], {}) if checkers else {}
    return SpeedLimits(
        linear=min(float(plugin.get("desired_linear_vel", vmax[0])), float(vmax[0])),
        accel=float(amax[0]), decel=abs(float(dmax[0])),
        angular=min(float(plugin.get("rotate_to_heading_angular_vel", vmax[2])), float(vmax[2])),
        angular_accel=min(float(plugin.get("max_angular_accel", amax[2])), float(amax[2])),
        near_wall_radius=radius, near_wall_linear=limit, approach_dist=approach,
        approach_min=float(plugin.get("min_approach_linear_velocity", 0.05)) if approach else 0.0,
        goal_tolerance=float(checker.get("xy_goal_tolerance", 0.25)) if approach else 0.0)


def _trapezoid(distance: float, vmax: float, accel: float, decel: float) -> float:
    """Time (s) to cover ``distance`` from rest to rest with these limits."""
    d = abs(distance)
    if d == 0.0:
        return 0.0
    ramps = vmax * vmax / 2 * (1 / accel + 1 / decel)
    if d >= ramps:
        return d / vmax + vmax / 2 * (1 / accel + 1 / decel)
    peak = math.sqrt(2 * d / (1 / accel + 1 / decel))
    return peak / accel + peak / decel


def leg_time(length_m: float, limits: SpeedLimits) -> float:
    """Time (s) to drive a leg of ``length_m`` from standstill to standstill."""
    return _trapezoid(length_m, limits.linear, limits.accel, limits.decel)


def path_drive_time(lengths: npt.ArrayLike, caps: npt.ArrayLike, limits: SpeedLimits) -> float:
    """Time (s) to drive a path of steps ``lengths`` (m) at speed caps ``caps`` (m/s, one per
    step), from standstill to standstill: each step at its cap, the approach slowdown over
    the last ``approach_dist`` until ``goal_tolerance`` is left, and the time the
    acceleration from standstill and the deceleration to it lose. Steps at one cap with no
    approach slowdown are `leg_time` (the trapezoid)."""
    ln = np.asarray(lengths, dtype=np.float64)
    v = np.asarray(caps, dtype=np.float64)
    total = float(ln.sum())
    if total <= 0.0:
        return 0.0
    if limits.approach_dist <= 0.0 and np.all(v == v[0]):
        return _trapezoid(total, float(v[0]), limits.accel, limits.decel)
    left = total - np.cumsum(ln) + ln / 2  # path left at each step's middle
    if limits.approach_dist > 0.0:
        scale = np.clip(left / limits.approach_dist, 0.0, 1.0)
        v = np.where(left < limits.approach_dist, np.maximum(v * scale, limits.approach_min), v)
        ln = np.where(left < limits.goal_tolerance, 0.0, ln)  # the goal checker's tolerance
    driven = ln > 0
    if not driven.any():
        return 0.0
    first, last = float(v[driven][0]), float(v[driven][-1])
    cruise = float(np.sum(ln[driven] / v[driven]))
    ramps = first / (2 * limits.accel) + last / (2 * limits.decel)
    if float(ln.sum()) < first**2 / (2 * limits.accel) + last**2 / (2 * limits.decel):
        return _trapezoid(float(ln.sum()), min(first, last), limits.accel, limits.decel)
    return cruise + ramps


def turn_time(angle_rad: float, limits: SpeedLimits) -> float:
    """Time (s) to turn in place by ``angle_rad`` (either way; the short way is the caller's)."""
    return _trapezoid(angle_rad, limits.angular, limits.angular_accel, limits.angular_accel)


@dataclass(frozen=True)
class OracleParams:
    """The sensor and the candidate viewpoints (m, rad)."""

    robot_radius: float = 0.2245
    min_range: float = 0.5
    max_range: float = 4.5
    return_range: float | None = 8.0
    """A ray sees only if it comes back: it must end on the scan-height ground truth within
    this range (the simulated Kinect's farthest return). A beam with no return is NaN in the
    scan (REP 117) and SLAM clears nothing along it, as slam_toolbox. None: every ray sees
    out to ``max_range``."""
    fov: float = math.radians(57.0)
    spacing: float = 0.4
    """Lattice step of the candidate positions (m)."""
    headings: int = 12
    rays: int = 720
    """Rays per full turn from each candidate position (720: 0.5°, under a cell at 4.5 m)."""
    targets: tuple[float, ...] = (0.95, 1.0)
    """Shares of the seeable floor each tour sees."""


@dataclass
class Leg:
    """One viewpoint of a tour and the way there."""

    pose: Pose
    path_m: float
    drive_s: float
    turn_s: float


@dataclass
class OracleTour:
    """The tour for one target share: its viewpoints in order, and its length and time."""

    target: float
    method: str = "views"
    """``views``: greedy cover by single views; ``places``: by places, then headings."""
    legs: list[Leg] = field(default_factory=list)
    seen: float = 0.0
    """Share of the reachable floor the tour's viewpoints see."""
    path_m: float = 0.0
    drive_s: float = 0.0
    turn_s: float = 0.0
    time_s: float = 0.0
    """Start → last viewpoint (s)."""
    home_path_m: float = 0.0
    home_s: float = 0.0
    """Last viewpoint → the start pose, turned to the start's heading (s)."""

    @property
    def round_trip_s(self) -> float:
        return self.time_s + self.home_s

    def summary(self) -> dict[str, Any]:
        return {"target": self.target, "method": self.method, "seen": round(self.seen, 4), "viewpoints": len(self.legs),
                "path_m": round(self.path_m, 2), "drive_s": round(self.drive_s, 1),
                "turn_s": round(self.turn_s, 1), "time_s": round(self.time_s, 1),
                "round_trip_s": round(self.round_trip_s, 1)}


@dataclass
class OracleResult:
    """Every tour of a world, with the floor they are measured on."""

    tours: list[OracleTour]
    reachable_cells: int
    unseeable: float
    """Share of the reachable floor no candidate viewpoint sees."""
    candidates: int
    resolution: float

    def tour(self, target: float) -> OracleTour:
        return next(t for t in self.tours if abs(t.target - target) < 1e-9)


# -- visibility ---------------------------------------------------------------------------------
def _centres(footprint_occupied: npt.NDArray[np.bool_], resolution: float, robot_radius: float,
             start_cell: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """Robot-centre cells clear of the footprint by ``robot_radius`` and connected to the start."""
    clearance = ndimage.distance_transform_edt(~footprint_occupied) * resolution
    labels, _ = ndimage.label(clearance >= robot_radius, structure=np.ones((3, 3), bool))
    r, c = start_cell
    if not (0 <= r < labels.shape[0] and 0 <= c < labels.shape[1]) or labels[r, c] == 0:
        return np.zeros_like(footprint_occupied)
    return np.asarray(labels == labels[r, c])


def visibility(blocked: npt.NDArray[np.bool_], resolution: float, cell: tuple[int, int],
               params: OracleParams) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Cells (flat indices) seen from the centre of ``cell`` (row, col) in any direction, and
    the bearing (rad, grid frame) of the ray that saw each; rays stop at ``blocked`` cells and
    at the grid's edge, cells nearer than ``min_range`` are not seen."""
    h, w = blocked.shape
    step = resolution / 2
    reach = params.max_range if params.return_range is None else max(params.max_range,
                                                                      params.return_range)
    radii = np.arange(step, reach + 1e-9, step)
    angles = np.arange(params.rays) * (2 * math.pi / params.rays)
    r0, c0 = cell
    cols = np.floor(c0 + 0.5 + np.cos(angles)[:, None] * radii[None, :] / resolution).astype(np.int64)
    rows = np.floor(r0 + 0.5 + np.sin(angles)[:, None] * radii[None, :] / resolution).astype(np.int64)
    outside = (rows < 0) | (rows >= h) | (cols < 0) | (cols >= w)
    rows_c, cols_c = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    stop = outside | blocked[rows_c, cols_c]
    stopped = np.maximum.accumulate(stop, axis=1)
    ok = ~stopped & (radii[None, :] >= params.min_range) & (radii[None, :] <= params.max_range)
    if params.return_range is not None:
        # the ray's first stop is a blocked cell (not the grid's edge) within return_range
        first = np.argmax(stop, axis=1)
        hit = stop.any(axis=1)
        ray = np.arange(stop.shape[0])
        comes_back = hit & ~outside[ray, first] & (radii[first] >= params.min_range)
        ok &= comes_back[:, None]
    flat = (rows_c * w + cols_c)[ok]
    bearing = np.broadcast_to(angles[:, None], ok.shape)[ok]
    return flat, bearing


def _candidate_sets(centres: npt.NDArray[np.bool_], blocked: npt.NDArray[np.bool_],
                    target_index: npt.NDArray[np.int64], resolution: float,
                    params: OracleParams, grid_yaw: float,
                    ) -> tuple[list[tuple[int, int, float]], list[npt.NDArray[np.int64]]]:
    """Candidate viewpoints (row, col, heading in the grid frame) and the target indices
    each sees."""
    k = max(1, round(params.spacing / resolution))
    rows, cols = np.nonzero(centres)
    # the lattice, plus the most central cell of each lattice square the lattice missed
    # (a narrow passage between lattice points)
    on = (rows % k == 0) & (cols % k == 0)
    picked = set(zip(rows[on].tolist(), cols[on].tolist(), strict=True))
    squares = set(zip((rows[on] // k).tolist(), (cols[on] // k).tolist(), strict=True))
    off = ~on
    for r, c in zip(rows[off].tolist(), cols[off].tolist(), strict=True):
        key = (r // k, c // k)
        if key not in squares:
            squares.add(key)
            picked.add((r, c))
    half = params.fov / 2
    headings = np.arange(params.headings) * (2 * math.pi / params.headings)
    views: list[tuple[int, int, float]] = []
    sets: list[npt.NDArray[np.int64]] = []
    for r, c in sorted(picked):
        flat, bearing = visibility(blocked, resolution, (r, c), params)
        tidx = target_index[flat]
        keep = tidx >= 0
        tidx, bearing = tidx[keep], bearing[keep]
        for hd in headings:
            off_axis = np.abs(np.remainder(bearing - hd + math.pi, 2 * math.pi) - math.pi)
            seen = np.unique(tidx[off_axis <= half])
            if seen.size:
                views.append((r, c, float(hd) + grid_yaw))
                sets.append(seen)
    return views, sets


def greedy_cover(sets: list[npt.NDArray[np.int64]], n_targets: int,
                 targets: tuple[float, ...]) -> tuple[list[list[int]], npt.NDArray[np.bool_]]:
    """Greedy set cover (lazy evaluation): for each share in ``targets`` (ascending), the
    sets chosen until that share of the coverable elements is covered, and the coverable
    elements (the union of all sets)."""
    coverable = np.zeros(n_targets, bool)
    for s in sets:
        coverable[s] = True
    total = int(coverable.sum())
    covered = np.zeros(n_targets, bool)
    heap = [(-int(s.size), i) for i, s in enumerate(sets)]
    heapq.heapify(heap)
    chosen: list[int] = []
    out: list[list[int]] = []
    count = 0
    for share in sorted(targets):
        need = math.ceil(share * total - 1e-9)
        while count < need and heap:
            _, i = heapq.heappop(heap)
            gain = int(np.count_nonzero(~covered[sets[i]]))
            if gain == 0:
                continue
            if heap and gain < -heap[0][0]:
                heapq.heappush(heap, (-gain, i))
                continue
            covered[sets[i]] = True
            count += gain
            chosen.append(i)
        out.append(list(chosen))
    return out, coverable


def _cover_by_places(views: list[tuple[int, int, float]], sets: list[npt.NDArray[np.int64]],
                     n_targets: int, targets: tuple[float, ...]) -> list[list[int]]:
    """Greedy cover by places first (what a full turn there sees), then at each chosen place
    the headings that see what it was chosen for (greedy again): few stops, each a sweep."""
    places: dict[tuple[int, int], list[int]] = {}
    for i, (r, c, _) in enumerate(views):
        places.setdefault((r, c), []).append(i)
    keys = list(places)
    place_sets = [np.unique(np.concatenate([sets[i] for i in places[k]])) for k in keys]
    chosen_per, _ = greedy_cover(place_sets, n_targets, targets)
    covered = np.zeros(n_targets, bool)
    picks: dict[int, list[int]] = {}
    for p in chosen_per[-1]:  # the last list holds every earlier one as its prefix
        mine = place_sets[p][~covered[place_sets[p]]]
        covered[mine] = True
        local = np.full(n_targets, False)
        local[mine] = True
        idx = places[keys[p]]
        remap = np.full(n_targets, -1, np.int64)
        remap[mine] = np.arange(mine.size)
        sub = [remap[sets[i][local[sets[i]]]] for i in idx]
        got, _ = greedy_cover(sub, int(mine.size), (1.0,))
        picks[p] = [idx[j] for j in got[0]]
    return [[i for p in chosen for i in picks[p]] for chosen in chosen_per]


# -- order --------------------------------------------------------------------------------------
def _graph(centres: npt.NDArray[np.bool_], resolution: float,
           speed: npt.NDArray[np.float64] | None = None) -> tuple[csr_matrix, npt.NDArray[np.int64]]:
    """The 8-connected graph of the centre cells (edge lengths in m, or with ``speed`` per
    cell, m/s, the time to drive them: half the step at each end's speed) and the node of
    each cell."""
    h, w = centres.shape
    node = np.full(centres.shape, -1, np.int64)
    rows, cols = np.nonzero(centres)
    node[rows, cols] = np.arange(rows.size)
    src, dst, length = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r2, c2 = rows + dr, cols + dc
        ok = (r2 >= 0) & (r2 < h) & (c2 >= 0) & (c2 < w)
        ok[ok] &= centres[r2[ok], c2[ok]]
        if dr and dc:  # no corner cutting: both orthogonal neighbours too
            ok[ok] &= centres[rows[ok], c2[ok]] & centres[r2[ok], cols[ok]]
        src.append(node[rows[ok], cols[ok]])
        dst.append(node[r2[ok], c2[ok]])
        step = np.full(int(ok.sum()), resolution * math.hypot(dr, dc))
        if speed is not None:
            step = step / 2 / speed[rows[ok], cols[ok]] + step / 2 / speed[r2[ok], c2[ok]]
        length.append(step)
    s, d, ln = np.concatenate(src), np.concatenate(dst), np.concatenate(length)
    n = rows.size
    graph = csr_matrix((np.concatenate([ln, ln]), (np.concatenate([s, d]), np.concatenate([d, s]))),
                       shape=(n, n))
    return graph, node


def order_tour(dist: npt.NDArray[np.float64], closed: bool = False) -> list[int]:
    """An order of nodes 1..n-1 after node 0 (the start): nearest neighbour, then 2-opt on
    the path length (returning to node 0 when ``closed``)."""
    n = dist.shape[0]
    if n <= 1:
        return []
    left = set(range(1, n))
    order = [0]
    while left:
        here = order[-1]
        nxt = min(left, key=lambda j: (dist[here, j], j))
        order.append(nxt)
        left.remove(nxt)
    if closed:
        order.append(0)

    last = len(order) - (1 if closed else 0)
    improved = True
    while improved:
        improved = _two_opt(order, dist, last)
        improved = _or_opt(order, dist, last) or improved
    return order[1:last] if closed else order[1:]


def _two_opt(order: list[int], dist: npt.NDArray[np.float64], last: int) -> bool:
    """Reverse segments of ``order[1:last]`` while that shortens it (in place)."""
    improved, any_change = True, False
    while improved:
        improved = False
        for i in range(1, last - 1):
            for j in range(i + 1, last):
                a, b = order[i - 1], order[i]
                c = order[j]
                d = order[j + 1] if j + 1 < len(order) else None
                before = dist[a, b] + (dist[c, d] if d is not None else 0.0)
                after = dist[a, c] + (dist[b, d] if d is not None else 0.0)
                if after < before - 1e-9:
                    order[i:j + 1] = order[i:j + 1][::-1]
                    improved = any_change = True
    return any_change


def _or_opt(order: list[int], dist: npt.NDArray[np.float64], last: int) -> bool:
    """Move runs of one to three nodes of ``order[1:last]`` elsewhere (either way round)
    while that shortens it (in place): what 2-opt cannot do on an open path."""
    changed = False
    for run in (1, 2, 3):
        i = 1
        while i + run <= last:
            seg = order[i:i + run]
            p = order[i - 1]
            q = order[i + run] if i + run < len(order) else None
            gain = dist[p, seg[0]] + (dist[seg[-1], q] - dist[p, q] if q is not None else 0.0)
            rest = order[:i] + order[i + run:]
            best: tuple[float, int, list[int]] | None = None
            for k in range(1, last - run + 1):
                if k == i:
                    continue
                u = rest[k - 1]
                v = rest[k] if k < len(rest) else None
                for piece in (seg, seg[::-1]):
                    cost = dist[u, piece[0]] + (dist[piece[-1], v] - dist[u, v] if v is not None else 0.0)
                    if cost < gain - 1e-9 and (best is None or cost < best[0]):
                        best = (float(cost), k, piece)
            if best is None:
                i += 1
                continue
            _, k, piece = best
            order[:] = rest[:k] + piece + rest[k:]
            changed = True
    return changed


def _direction(path: list[int], cells: npt.NDArray[np.int64], resolution: float,
               from_end: bool, reach_m: float = 0.3) -> float | None:
    """Heading (grid frame) of a node path's first (or last) ``reach_m``; None when shorter
    than a cell."""
    if len(path) < 2:
        return None
    seq = path[::-1] if from_end else path
    r0, c0 = cells[seq[0]]
    k = min(len(seq) - 1, max(1, round(reach_m / resolution)))
    r1, c1 = cells[seq[k]]
    if from_end:
        return math.atan2(r0 - r1, c0 - c1)
    return math.atan2(r1 - r0, c1 - c0)


def _path(pred: npt.NDArray[np.int32], src_row: int, dst: int) -> list[int]:
    out = [dst]
    while True:
        p = int(pred[src_row, out[-1]])
        if p < 0:
            break
        out.append(p)
    return out[::-1]


def _wrap(a: float) -> float:
    return abs(math.remainder(a, 2 * math.pi))


def _sweep(heading: float, yaws: list[float]) -> tuple[float, list[float]]:
    """The shorter one-way sweep (counter-clockwise or clockwise) from ``heading`` through
    every yaw: its angle (rad) and the yaws in the order it passes them."""
    ccw = [(yaw - heading) % (2 * math.pi) for yaw in yaws]
    cw = [(heading - yaw) % (2 * math.pi) for yaw in yaws]
    # an offset of almost a full turn is the heading itself
    ccw = [0.0 if o > 2 * math.pi - 1e-9 else o for o in ccw]
    cw = [0.0 if o > 2 * math.pi - 1e-9 else o for o in cw]
    if max(ccw) <= max(cw):
        return max(ccw), [y for _, y in sorted(zip(ccw, yaws, strict=True))]
    return max(cw), [y for _, y in sorted(zip(cw, yaws, strict=True))]


# -- the whole ----------------------------------------------------------------------------------
def oracle_tour(scan: Any, footprint: Any, start: Pose, params: OracleParams | None = None,
                limits: SpeedLimits | None = None) -> OracleResult:
    """Oracle tours on the ground truth (`eddiebot.maps.OccupancyMap` ``scan`` and
    ``footprint`` on one grid, world frame) from ``start`` (x, y, yaw; m, rad)."""
    from eddiebot.explore.mission import reachable_free_area
    from eddiebot.maps import map_to_world, world_to_map

    params = params or OracleParams()
    limits = limits or SpeedLimits()
    if scan.data.shape != footprint.data.shape or scan.origin != footprint.origin:
        raise ValueError(f"the scan ({scan.data.shape}, origin {scan.origin}) and footprint "
                         f"({footprint.data.shape}, origin {footprint.origin}) ground truths "
                         "must share one grid")
    res = float(footprint.resolution)
    grid_yaw = float(footprint.origin[2])
    floor = reachable_free_area(footprint, (start[0], start[1]), params.robot_radius)
    sc, sr = (int(v) for v in world_to_map(footprint, np.array(start[:2])))
    centres = _centres(footprint.data >= 65, res, params.robot_radius, (sr, sc))
    if not floor.any() or not centres.any():
        raise ValueError(f"the start ({start[0]:.2f}, {start[1]:.2f}) has no reachable floor "
                         f"(robot radius {params.robot_radius} m)")
    target_index = np.full(floor.size, -1, np.int64)
    flat_floor = np.flatnonzero(floor)
    target_index[flat_floor] = np.arange(flat_floor.size)
    views, sets = _candidate_sets(centres, scan.data >= 65, target_index, res, params, grid_yaw)
    by_view, coverable = greedy_cover(sets, flat_floor.size, params.targets)
    by_place = _cover_by_places(views, sets, flat_floor.size, params.targets)

    # the speed at each centre: the collision monitor's limit near what its sources see
    # (the scan's plane and the range sensors' low obstacles: both ground truths)
    obstacles = (scan.data >= 65) | (footprint.data >= 65)
    speed = limits.cap(ndimage.distance_transform_edt(~obstacles) * res)
    graph, node = _graph(centres, res, speed)  # edge weights: seconds at cruise
    cells = np.argwhere(centres)  # node k is cells[k] (row-major, as np.nonzero)
    start_node = int(node[sr, sc])

    def drive(path: list[int]) -> tuple[float, float]:
        """Length (m) and time (s) of a node path, from standstill to standstill."""
        if len(path) < 2:
            return 0.0, 0.0
        rc = cells[path]
        steps = np.hypot(*np.diff(rc, axis=0).T) * res
        v = speed[rc[:, 0], rc[:, 1]]
        caps = 2.0 / (1.0 / v[:-1] + 1.0 / v[1:])
        return float(steps.sum()), path_drive_time(steps, caps, limits)

    def build(share: float, chosen: list[int], method: str) -> OracleTour:
        poses = [views[i] for i in chosen]
        at: dict[int, list[int]] = {}  # the chosen views at each position (graph node)
        for i, (r, c, _) in enumerate(poses):
            at.setdefault(int(node[r, c]), []).append(i)
        nodes = [start_node, *at]
        uniq = sorted(set(nodes))
        dist_all, pred = dijkstra(graph, directed=False, indices=uniq, return_predecessors=True)
        row_of = {n: k for k, n in enumerate(uniq)}
        dist = np.array([[dist_all[row_of[a], b] for b in nodes] for a in nodes])
        order = order_tour(dist, closed=False)
        tour = OracleTour(target=share, method=method)
        seen = np.zeros(flat_floor.size, bool)
        for i in chosen:
            seen[sets[i]] = True
        tour.seen = float(seen.mean())
        heading = float(start[2])
        here = 0
        for k in order:
            # the views at one position: one sweep through their headings
            group = at[nodes[k]]
            a, b = nodes[here], nodes[k]
            length, drive_s = 0.0, 0.0
            turn = 0.0
            if a != b:
                path = _path(pred, row_of[a], b)
                length, drive_s = drive(path)
                out_dir = _direction(path, cells, res, from_end=False)
                in_dir = _direction(path, cells, res, from_end=True)
                if out_dir is not None and in_dir is not None:
                    turn += turn_time(_wrap(out_dir + grid_yaw - heading), limits)
                    heading = in_dir + grid_yaw
            yaws = [poses[j][2] for j in group]
            sweep, yaws = _sweep(heading, yaws)
            turn += turn_time(sweep, limits)
            heading = yaws[-1]
            r, c, _ = poses[group[0]]
            wx, wy = (float(v) for v in map_to_world(footprint, np.array([c, r])))
            for n, yaw in enumerate(yaws):
                tour.legs.append(Leg((wx, wy, yaw), length if n == 0 else 0.0,
                                     drive_s if n == 0 else 0.0, turn if n == 0 else 0.0))
            tour.path_m += length
            tour.drive_s += drive_s
            tour.turn_s += turn
            here = k
        tour.time_s = tour.drive_s + tour.turn_s
        # and home: to the start's cell, turned to the start's heading
        a = nodes[here]
        if a != start_node:
            path = _path(pred, row_of[start_node], a)[::-1]
            out_dir = _direction(path, cells, res, from_end=False)
            in_dir = _direction(path, cells, res, from_end=True)
            tour.home_path_m, tour.home_s = drive(path)
            if out_dir is not None and in_dir is not None:
                tour.home_s += turn_time(_wrap(out_dir + grid_yaw - heading), limits)
                heading = in_dir + grid_yaw
        tour.home_s += turn_time(_wrap(float(start[2]) - heading), limits)
        return tour

    tours: list[OracleTour] = []
    for share, one, other in zip(sorted(params.targets), by_view, by_place, strict=True):
        tours.append(min(build(share, one, "views"), build(share, other, "places"),
                         key=lambda t: t.time_s))
    return OracleResult(tours=tours, reachable_cells=int(flat_floor.size),
                        unseeable=float(1.0 - coverable.mean()), candidates=len(views),
                        resolution=res)


def oracle_for_world(world: str, params: OracleParams | None = None,
                     limits: SpeedLimits | None = None) -> OracleResult:
    """The oracle tours of a built-in world or world file (its cached ground truth)."""
    from eddiebot.sim.ground_truth import cached_ground_truth
    from eddiebot.sim.world import ROBOT_RADIUS
    from eddiebot.sim.worlds import load_world

    w = load_world(world)
    gt = cached_ground_truth(w)
    params = params or OracleParams(robot_radius=ROBOT_RADIUS)
    start = (float(w.start[0]), float(w.start[1]), float(w.start[2]))
    return oracle_tour(gt.scan, gt.footprint, start, params, limits or speed_limits())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--worlds", nargs="*", default=None, help="default: every built-in world")
    args = parser.parse_args(argv)
    from eddiebot.sim.worlds import list_worlds

    limits = speed_limits()
    print(f"limits: {limits}")
    for world in args.worlds or list_worlds():
        result = oracle_for_world(world, limits=limits)
        floor = result.reachable_cells * result.resolution**2
        print(f"{world}: reachable floor {floor:.1f} m², {100 * result.unseeable:.2f} % unseeable, "
              f"{result.candidates} candidate views")
        for t in result.tours:
            s = t.summary()
            print(f"  {100 * t.target:.0f} % (by {t.method}): {s['viewpoints']} views, seen {100 * t.seen:.1f} %, "
                  f"path {s['path_m']} m, drive {s['drive_s']} s + turn {s['turn_s']} s = "
                  f"{s['time_s']} s; with the way home {s['round_trip_s']} s")
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
