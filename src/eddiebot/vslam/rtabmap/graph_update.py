"""Graph optimisation after a change: the whole component of the current node, or only what
was added since the incremental graph last took it, with the `RGBD/OptimizeMaxError` check."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from eddiebot.vslam.graph import (
    GraphLink,
    GtsamPoseGraph,
    IncrementalPose2Graph,
    optimized_link_errors,
)
from eddiebot.vslam.memory import Link
from eddiebot.vslam.odometry_frames import ODOM_FRAME_ID_OFFSET, _worst_link_error
from eddiebot.vslam.rtabmap.state import F64, RtabmapState


class GraphUpdate(RtabmapState):
    """Optimises the graph and rejects a change whose links the optimum strains too much."""

    @property
    def _optimize_max_error(self) -> float:
        """`RGBD/OptimizeMaxError`, ignored (0) under `Optimizer/Robust`: a wrong closure is
        switched off by the optimiser instead of rejected after it."""
        return 0.0 if self.params.optimizer_robust else self.params.rgbd_optimize_max_error

    def _incremental(self) -> IncrementalPose2Graph | None:
        inner = (self.optimizer.incremental if isinstance(self.optimizer, GtsamPoseGraph)
                 else self.optimizer)
        return inner if isinstance(inner, IncrementalPose2Graph) else None

    def _whole_graph(self, current: int) -> tuple[dict[int, F64], list[Link] | list[GraphLink], int]:
        """The graph to optimise: poses, links and root of the component of `current`."""
        mem = self.memory
        in_ram = set(mem.wm) | set(mem.stm)
        comp = mem.component(current, in_ram)
        known = self.optimized_poses
        poses = {i: known[i] if i in known else self.map_to_odom @ mem.nodes[i].odom_pose
                 for i in comp}
        links: list[Link] | list[GraphLink] = mem.unique_links(comp)
        if self.params.rgbd_optimize_from_graph_end:
            root = current
            poses[root] = mem.nodes[root].odom_pose
        else:
            root = min(comp)
        sigma = self.params.rgbd_odom_heading_sigma
        if sigma > 0:
            poses, links = self._frames.graph(poses, links, root, sigma, self._frame_poses)
        return poses, links, root

    def _optimize(self, current: int, new_links: list[Link]) -> bool:
        log = self.memory.take_link_log()
        live, self._graph_live = self._graph_live, False
        if live and log is not None:
            done = self._optimize_added(current, new_links, log)
            if done is not None:
                self._graph_live = done
                return done
        poses, links, root = self._whole_graph(current)
        sigma = self.params.rgbd_odom_heading_sigma
        optimized = self.optimizer.optimize(poses, links, root, self.params.optimizer_iterations)
        thr = self._optimize_max_error
        if thr > 0 and new_links:
            ids, lin, ang = optimized_link_errors(self.optimizer, optimized, links)
            if _worst_link_error(ids, lin, ang, sigma) > thr:
                return False
        if sigma > 0:
            self._frame_poses = {i: p for i, p in optimized.items() if i >= ODOM_FRAME_ID_OFFSET}
            optimized = {i: p for i, p in optimized.items() if i < ODOM_FRAME_ID_OFFSET}
        self.optimized_poses.update(optimized)
        self._graph_live = (self._incremental() is not None
                            and not self.params.rgbd_optimize_from_graph_end)
        return True

    def _optimize_added(self, current: int, new_links: list[Link],
                        log: list[tuple[int, int]]) -> bool | None:
        """`_optimize` when the memory graph only grew (by the links of `log`) since the
        incremental graph last took it: hands the graph the new nodes and links instead of
        the whole component. The same update, estimate and check as the whole-graph call;
        None (nothing changed) when the additions do not fit that case."""
        g = self._incremental()
        if g is None or self.params.rgbd_optimize_from_graph_end:
            return None
        mem = self.memory
        pairs = list(dict.fromkeys(log))
        pair_set = set(pairs)
        new = {i for pair in pairs for i in pair if not g.knows(i)}
        if not g.knows(current) and current not in new:
            return None
        for n in new:  # entered RAM as new nodes: every link they have was logged
            if n not in mem.nodes or not (n in mem.wm or n in mem.stm):
                return None
            for m in mem.links.get(n, ()):
                if ((n, m) if n < m else (m, n)) not in pair_set:
                    return None
        # the component of `current` grows by the new nodes the logged links reach
        reach: set[int] = set()
        grew = True
        while grew:
            grew = False
            for a, b in pairs:
                ina, inb = g.knows(a) or a in reach, g.knows(b) or b in reach
                if ina != inb:
                    reach.add(b if ina else a)
                    grew = True
        if (not g.knows(current) and current not in reach) or (reach and min(reach) < g.root_id):
            return None
        sigma = self.params.rgbd_odom_heading_sigma
        root = g.root_id
        if sigma > 0 and not self._frames.fits(root, sigma):
            return None
        known = self.optimized_poses
        m2o = self.map_to_odom
        poses: dict[int, F64] = {i: known[i] if i in known else m2o @ mem.nodes[i].odom_pose
                                 for i in reach}
        root_pose = known[root] if root in known else m2o @ mem.nodes[root].odom_pose
        links: list[Link] | list[GraphLink] = [
            mem.links[a][b] for a, b in pairs
            if (g.knows(a) or a in reach) and (g.knows(b) or b in reach)]
        if sigma > 0:
            poses, links = self._frames.extend(poses, links, root, sigma, self._frame_poses)

        def whole() -> tuple[Mapping[int, F64], list[Link] | list[GraphLink]]:
            p, lk, _ = self._whole_graph(current)
            return p, lk

        if not g.extend(poses, links, root, root_pose, self.params.optimizer_iterations, whole):
            return None
        thr = self._optimize_max_error
        if thr > 0 and new_links:
            ids, lin, ang = g.link_error_ratios()
            if _worst_link_error(ids, lin, ang, sigma) > thr:
                return False
        mats = g.poses_array()
        ids_all = np.asarray(g.node_ids, np.int64)
        if sigma > 0:
            # as splitting the {id: pose} dict of the whole-graph call (graph order kept)
            frame = ids_all >= ODOM_FRAME_ID_OFFSET
            self._frame_poses = dict(zip(ids_all[frame].tolist(), mats[frame]))
            node = ~frame
            self.optimized_poses.update(zip(ids_all[node].tolist(), mats[node]))
        else:
            self.optimized_poses.update(zip(ids_all.tolist(), mats))
        return True
