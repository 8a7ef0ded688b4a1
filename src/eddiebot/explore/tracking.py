"""Frontiers across searches: identities, the blacklist, progress, and the choice of target.

A frontier's cells change with every map update and a frontier can vanish for one update
and come back (a wall cell flickering between free and occupied); `FrontierTracker` keeps
an identity for each by matching centroids within ``frontier_match_tolerance``, so a
flickering frontier is one frontier with one visit count. `Blacklist` holds the places
given up on (navigation failed, no progress for ``progress_timeout``, or visited
``max_visits`` times without the frontier going away). `ProgressMonitor` is explore_lite's
progress rule: the goal counts as progressing while the distance to it keeps shrinking.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from eddiebot.explore.config import ExploreConfig
from eddiebot.explore.frontiers import Frontier

__all__ = ["Blacklist", "BlacklistEntry", "FrontierTracker", "ProgressMonitor", "Track",
           "choose_frontier"]


@dataclass
class Track:
    """A frontier followed across searches (centroid in the map frame, m)."""

    id: int
    centroid: tuple[float, float]
    visits: int = 0
    """Arrivals in a row that revealed (almost) nothing."""
    seen: int = 1
    size: float = 0.0
    known_at_goal: float = 0.0
    """Known map area (m²) when the robot set off to this frontier."""
    arrived: bool = False
    stuck: int = 0
    """Goals towards this frontier given up for no progress."""

    expected: float = 0.0
    """The gain (m²) the viewpoint of the last trip promised."""
    idle: int = 0
    """Arrivals in a row that revealed (almost) nothing, whatever they promised."""

    def judge_visit(self, known_now: float, min_revealed: float = 0.5) -> None:
        """After an arrival, on a map made since: a trip that promised at least twice
        ``min_revealed`` m² and added less than ``min_revealed`` m² of known map counts as
        unproductive; one that added more clears the count. A trip that promised little
        and showed little counts only in ``idle``."""
        if not self.arrived:
            return
        self.arrived = False
        revealed = known_now - self.known_at_goal
        if revealed >= min_revealed:
            self.visits = self.idle = 0
            return
        self.idle += 1
        if self.expected >= 2 * min_revealed:
            self.visits += 1


class FrontierTracker:
    """Gives each frontier of a search the identity of the nearest previous one (one to
    one, closest pairs first) within ``tolerance`` m; others get new identities. Tracks not
    seen in a search are kept for ``memory`` searches, so a frontier that flickers out for
    an update keeps its identity and visit count."""

    def __init__(self, tolerance: float, memory: int = 5) -> None:
        self.tolerance = tolerance
        self.memory = memory
        self.tracks: dict[int, Track] = {}
        self._missing: dict[int, int] = {}
        self._next = 0

    def update(self, centroids: Sequence[tuple[float, float]],
               sizes: Sequence[float] | None = None) -> list[int]:
        """Identities for ``centroids`` (with their ``sizes``, m), in their order."""
        pairs = sorted(
            (math.hypot(c[0] - t.centroid[0], c[1] - t.centroid[1]), i, t.id)
            for i, c in enumerate(centroids) for t in self.tracks.values())
        ids: list[int | None] = [None] * len(centroids)
        used: set[int] = set()
        for d, i, tid in pairs:
            if d > self.tolerance:
                break
            if ids[i] is None and tid not in used:
                ids[i] = tid
                used.add(tid)
        out: list[int] = []
        for i, c in enumerate(centroids):
            matched = ids[i]
            if matched is None:
                tid = self._next
                self._next += 1
                self.tracks[tid] = Track(tid, (float(c[0]), float(c[1])))
            else:
                tid = matched
                t = self.tracks[tid]
                t.centroid = (float(c[0]), float(c[1]))
                t.seen += 1
            if sizes is not None:
                self.tracks[tid].size = float(sizes[i])
            self._missing[tid] = 0
            out.append(tid)
        for tid in list(self.tracks):
            if tid not in out:
                self._missing[tid] = self._missing.get(tid, 0) + 1
                if self._missing[tid] > self.memory:
                    del self.tracks[tid]
                    del self._missing[tid]
        return out


@dataclass(frozen=True)
class BlacklistEntry:
    point: tuple[float, float]
    reason: str
    retryable: bool = False
    """Abandoned because the robot could not get there (no progress, goal failed), not
    because looking showed nothing: worth another try once the map around it has grown."""


@dataclass
class Blacklist:
    """Places (map frame, m) given up on; a frontier within ``radius`` of one is skipped."""

    radius: float
    entries: list[BlacklistEntry] = field(default_factory=list)

    def add(self, point: Sequence[float], reason: str, retryable: bool = False) -> None:
        self.entries.append(BlacklistEntry((float(point[0]), float(point[1])), reason, retryable))

    def forgive(self) -> int:
        """Drop the retryable entries; returns how many."""
        kept = [e for e in self.entries if not e.retryable]
        dropped = len(self.entries) - len(kept)
        self.entries = kept
        return dropped

    def contains(self, point: Sequence[float]) -> bool:
        return any(math.hypot(point[0] - e.point[0], point[1] - e.point[1]) <= self.radius
                   for e in self.entries)

    def __len__(self) -> int:
        return len(self.entries)


class ProgressMonitor:
    """No progress for ``timeout`` s (the distance to the goal has not shrunk by
    ``min_step`` m below its best) means the goal is stuck."""

    def __init__(self, timeout: float, min_step: float = 0.05) -> None:
        self.timeout = timeout
        self.min_step = min_step
        self._best = math.inf
        self._since: float | None = None

    def reset(self, now: float) -> None:
        self._best = math.inf
        self._since = now

    def update(self, distance: float, now: float) -> bool:
        """Record the distance to the goal at time ``now`` (s); True when stuck."""
        if self._since is None:
            self.reset(now)
        if distance < self._best - self.min_step:
            self._best = distance
            self._since = now
        assert self._since is not None
        return now - self._since > self.timeout


def choose_frontier(frontiers: Sequence[Frontier], ids: Sequence[int], blacklist: Blacklist,
                    current: int | None = None, config: ExploreConfig | None = None
                    ) -> tuple[Frontier, int] | None:
    """The cheapest frontier whose centroid is not blacklisted and whose gain reaches
    ``config.min_gain``; the current
    target (``current``) is kept while it is still found and not blacklisted, so the robot
    does not dither between frontiers of nearly equal cost."""
    min_gain = config.min_gain if config is not None else 0.0
    allowed = [(f, i) for f, i in zip(frontiers, ids, strict=True)
               if not blacklist.contains(f.centroid) and f.gain >= min_gain]
    if not allowed:
        return None
    if current is not None:
        for f, i in allowed:
            if i == current:
                return f, i
    return min(allowed, key=lambda fi: fi[0].cost)
