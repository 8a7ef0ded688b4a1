"""Multi-map within a session, as RTAB-Map: an odometry reset starts a new map in a frame of
its own; a loop closure between maps merges their frames (the oldest map's frame is kept)."""

from __future__ import annotations

import numpy as np

from eddiebot.vslam.memory import Link, Node
from eddiebot.vslam.rtabmap.state import F64, RtabmapState
from eddiebot.vslam.transforms import se3_inverse


class MultiMap(RtabmapState):
    """Map ids, their frames, new maps on odometry resets and merging by loop closures."""

    def restore_state(self, next_id: int, map_id: int) -> None:
        """Continue numbering after a database session (`map_id` is the new session's id);
        maps joined by links share the oldest one's frame."""
        self._next_id = max(self._next_id, next_id)
        self._map_id = map_id
        frames = {n.map_id: n.map_id for n in self.memory.nodes.values()}
        frames[map_id] = map_id
        changed = True
        while changed:
            changed = False
            for a, partners in self.memory.links.items():
                for b in partners:
                    na, nb = self.memory.nodes.get(a), self.memory.nodes.get(b)
                    if na is None or nb is None:
                        continue
                    fa, fb = frames[na.map_id], frames[nb.map_id]
                    if fa != fb:
                        low = min(fa, fb)
                        for m, f in frames.items():
                            if f in (fa, fb):
                                frames[m] = low
                        changed = True
        self._map_frames = frames

    def frame_of(self, node_id: int) -> int:
        """The map frame (the oldest map id of its merged group) a node's pose is in."""
        node = self.memory.nodes.get(node_id)
        map_id = self._map_id if node is None else node.map_id
        return self._map_frames.get(map_id, map_id)

    @property
    def current_frame(self) -> int:
        """The map frame of the current map (map→odom is in it)."""
        return self._map_frames.get(self._map_id, self._map_id)

    def map_frames(self) -> dict[int, list[int]]:
        """Node ids with an optimised pose, by map frame (maps not merged yet are apart)."""
        out: dict[int, list[int]] = {}
        for i in sorted(self.optimized_poses):
            out.setdefault(self.frame_of(i), []).append(i)
        return out

    def _odometry_reset(self, odom: F64, covariance: F64 | None) -> bool:
        """RTAB-Map's new-map triggers: the odometry's covariance at 9999 (lost, then
        re-initialised) or an identity pose after a non-identity one, once the current map has
        a node."""
        lost = (covariance is not None
                and float(np.asarray(covariance).reshape(6, 6)[0, 0]) >= 9999)
        if self.localization_mode:
            if lost and self._odom_cache is not None:
                self._odom_cache.clear()  # the odometry before the reset checks nothing now
            return False
        prev = self.memory.nodes.get(self._last_node_id)
        if prev is None or prev.map_id != self._map_id:
            return False
        if lost:
            return True
        eye = np.eye(4)
        return bool(np.allclose(odom, eye) and not np.allclose(prev.odom_pose, eye))

    def _start_new_map(self) -> None:
        """A new map in this session: no link to the previous node, its own frame (map→odom
        identity) until a loop closure merges it with another map."""
        self._map_id += 1
        self._map_frames[self._map_id] = self._map_id
        self.maps_started += 1
        self.map_to_odom = np.eye(4)
        self._graph_live = False
        self._last_had_loop = False

    def _merge_frames(self, node: Node, closure_links: list[Link]) -> bool:
        """Join the frames of maps a closure links: the newer frame's poses are moved into
        the older one through the closure (so the optimiser starts from a consistent guess).
        True if frames were merged."""
        merged = False
        for link in closure_links:
            new_id, old_id = link.from_id, link.to_id
            f_new, f_old = self.frame_of(new_id), self.frame_of(old_id)
            if f_new == f_old:
                continue
            p_new, p_old = self.optimized_poses[new_id], self.optimized_poses[old_id]
            if f_old < f_new:  # move the new node's frame: T_new(old frame) = T_old · link⁻¹
                moved, keep = f_new, f_old
                correction = p_old @ se3_inverse(link.transform) @ se3_inverse(p_new)
            else:
                moved, keep = f_old, f_new
                correction = p_new @ link.transform @ se3_inverse(p_old)
            for i in list(self.optimized_poses):
                if self.frame_of(i) == moved:
                    self.optimized_poses[i] = correction @ self.optimized_poses[i]
            if moved == self.current_frame:
                self.map_to_odom = correction @ self.map_to_odom
            for m, f in self._map_frames.items():
                if f == moved:
                    self._map_frames[m] = keep
            merged = True
        if merged:
            self._graph_live = False
            self._frame_poses = {}
        return merged
