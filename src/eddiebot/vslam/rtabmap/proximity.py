"""Proximity detection by space (`RGBD/ProximityBySpace`): nodes near the current one in the
graph, grouped in paths, registered visually and then by their merged scans."""

from __future__ import annotations

import numpy as np

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.icp import icp_2d
from eddiebot.vslam.memory import Link, LinkType, Node
from eddiebot.vslam.rtabmap.state import F64
from eddiebot.vslam.rtabmap.verification import LoopVerification
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse, yaw_of


class ProximityDetection(LoopVerification):
    """Links a new node to nearby nodes of its map that appearance did not."""

    def _proximity_paths(self, node: Node, here: F64) -> list[list[int]]:
        """Proximity-by-space candidates grouped in paths (runs of consecutive ids, as the
        graph's odometry chains), nearest path first: WM nodes outside STM with an optimised
        pose within `RGBD/LocalRadius` of `here`, within `RGBD/ProximityMaxGraphDepth` links
        of the new node (0 = any depth), not linked to it, in its map."""
        p = self.params
        stm = set(self.memory.stm)
        linked = set(self.memory.links.get(node.id, ()))
        # in localization the frame is linked to nothing: every map node within the radius
        local = self.localization_mode
        reach = (self.memory.neighbours(node.id, p.rgbd_proximity_max_graph_depth,
                                        exclude_stm=False, wm_only=False)
                 if p.rgbd_proximity_max_graph_depth > 0 and not local else None)
        dist: dict[int, float] = {}
        for i in self.memory.wm:
            pose = self.optimized_poses.get(i)
            if i in stm or i in linked or pose is None or (reach is not None and i not in reach):
                continue
            if not local and self.frame_of(i) != self.frame_of(node.id):
                continue
            d = float(np.linalg.norm(pose[:2, 3] - here[:2, 3]))
            if p.rgbd_local_radius <= 0 or d <= p.rgbd_local_radius:
                dist[i] = d
        paths: list[list[int]] = []
        for i in sorted(dist):
            if paths and i - paths[-1][-1] == 1:
                paths[-1].append(i)
            else:
                paths.append([i])
        paths.sort(key=lambda path: min(dist[i] for i in path))
        return paths

    def _proximity(self, node: Node, camera: CameraIntrinsics) -> Link | None:
        """Proximity detection by space (`RGBD/ProximityBySpace`): per path (at most
        `RGBD/ProximityMaxPaths`), the nearest node facing within `RGBD/ProximityAngle` and
        within `RGBD/ProximityPathFilteringRadius` is registered visually; then, with
        `RGBD/ProximityPathMaxNeighbors` > 0 and a scan, the merged scans of the path are
        registered by 2D ICP (covariance × 100, as upstream)."""
        p = self.params
        if not self.optimized_poses:
            return None
        here = self.map_to_odom @ node.odom_pose
        radius = p.rgbd_proximity_path_filtering_radius
        max_angle = np.deg2rad(p.rgbd_proximity_angle)
        paths = self._proximity_paths(node, here)[: max(1, p.rgbd_proximity_max_paths)]
        for path in paths:
            best: tuple[float, int] | None = None
            for i in path:
                pose = self.optimized_poses[i]
                d = float(np.linalg.norm(pose[:2, 3] - here[:2, 3]))
                dyaw = abs(np.arctan2(np.sin(yaw_of(pose) - yaw_of(here)),
                                      np.cos(yaw_of(pose) - yaw_of(here))))
                if d <= radius and dyaw <= max_angle and (best is None or d < best[0]):
                    best = (d, i)
            if best is None:
                continue
            link = self._verify(self.memory.nodes[best[1]], node, camera,
                                LinkType.LOCAL_SPACE_CLOSURE).link
            if link is not None and float(np.linalg.norm(link.transform[:3, 3])) <= radius:
                return link
        if p.rgbd_proximity_path_max_neighbors > 0 and node.data is not None \
                and node.data.scan_points is not None:
            for path in paths:
                link = self._proximity_scan(node, here, path)
                if link is not None:
                    return link
        return None

    def _proximity_scan(self, node: Node, here: F64, path: list[int]) -> Link | None:
        """The scan pass of proximity detection on one path: the nearest node's scan merged
        with those of up to `RGBD/ProximityPathMaxNeighbors` path nodes around it (at their
        optimised poses, in the nearest node's frame), 2D ICP from the graph's guess."""
        scan = node.data.scan_points if node.data is not None else None
        if scan is None or scan.shape[0] < 10:
            return None
        poses = self.optimized_poses
        nearest = min(path, key=lambda i: float(np.linalg.norm(poses[i][:2, 3] - here[:2, 3])))
        k = path.index(nearest)
        half = self.params.rgbd_proximity_path_max_neighbors // 2
        lo = max(0, k - half)
        chosen = path[lo: lo + self.params.rgbd_proximity_path_max_neighbors + 1]
        ref_inv = se3_inverse(poses[nearest])
        parts = []
        for i in chosen:
            data = self.memory.nodes[i].data
            pts = None if data is None else data.scan_points
            if pts is None or pts.shape[0] == 0:
                continue
            rel = ref_inv @ poses[i]
            parts.append(pts @ rel[:2, :2].T + rel[:2, 3])
        if not parts:
            return None
        merged = np.concatenate(parts)
        if merged.shape[0] < 10:
            return None
        guess = ref_inv @ here
        result = icp_2d(merged, scan, np.array([guess[0, 3], guess[1, 3], yaw_of(guess)]))
        if result is None:
            return None
        t = from_xyz_yaw(result.x, result.y, result.theta)  # new node in the nearest's frame
        var = np.array([result.linear_variance, result.linear_variance, 1.0, 1.0, 1.0,
                        result.angular_variance]) * 100.0
        if float(np.linalg.norm(t[:2, 3] - guess[:2, 3])) > \
                self.params.rgbd_proximity_path_filtering_radius:
            return None
        return Link(node.id, nearest, LinkType.LOCAL_SPACE_CLOSURE, se3_inverse(t),
                    np.diag(1.0 / var))
