"""What the map gives out: the global occupancy grid, the assembled point cloud and the graph,
of the current map (with the maps merged into it), and the local grid of a new node."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.memory import Link, Node
from eddiebot.vslam.occupancy import (
    CloudImages,
    GlobalGrid,
    LocalGrid,
    Scan2D,
    assemble_cloud,
    assemble_grid,
    local_grid_from_points,
    local_grid_from_scan,
    merge_local_grids,
)
from eddiebot.vslam.rtabmap.multi_map import MultiMap
from eddiebot.vslam.rtabmap.state import F64

_CLOUD_VOXEL = 0.02


class MapOutputs(MultiMap):
    """Grid, cloud and graph of the map; nodes' clouds rebuilt from the database on demand."""

    # -- maps -------------------------------------------------------------------------------
    def occupancy_grid(self) -> GlobalGrid | None:
        """Global grid assembled from the local grids at the optimised poses, of the current
        map (with the maps merged into it; a map not merged yet is in a frame of its own)."""
        frame = self.current_frame
        grids = {i: n.data.grid for i, n in self.memory.nodes.items()
                 if n.data is not None and n.data.grid is not None and self.frame_of(i) == frame}
        return assemble_grid(grids, self.optimized_poses, self.params.grid_cell_size)

    def point_cloud(self, voxel_size: float = 0.05) -> tuple[F64, NDArray[np.uint8]]:
        """Assembled coloured cloud (map frame) of the current map's nodes in RAM."""
        frame = self.current_frame
        clouds = {}
        for i, n in self.memory.nodes.items():
            if n.data is None or self.frame_of(i) != frame or i not in self.optimized_poses:
                continue
            images = self._cloud_images(n)
            if images is not None:
                clouds[i] = images.cloud(_CLOUD_VOXEL)
        return assemble_cloud(clouds, self.optimized_poses, voxel_size)

    def _cloud_images(self, node: Node) -> CloudImages | None:
        """A node's cloud images; for a node loaded from the database (a reloaded map, a
        retrieval) they are made from its stored depth and colour the first time."""
        data = node.data
        if data is None:
            return None
        if data.cloud is None and self._db is not None:
            rgb, depth, camera = self._db.frame(node.id)
            if depth is not None and camera is not None:
                p = self.params
                data.cloud = CloudImages.from_frame(depth, rgb, camera, p.grid_depth_decimation,
                                                    p.grid_range_min, p.grid_range_max)
        return data.cloud

    def graph(self) -> tuple[dict[int, F64], list[Link]]:
        """Optimised poses and all links."""
        return dict(self.optimized_poses), self.memory.unique_links()

    # -- helpers ----------------------------------------------------------------------------
    def _local_grid(self, xyz: F64, camera: CameraIntrinsics,
                    scan: Scan2D | None) -> LocalGrid | None:
        p = self.params
        sensor = p.grid_sensor
        if sensor == 0:
            return local_grid_from_scan(scan, p) if scan is not None else None
        depth_grid = local_grid_from_points(xyz, camera.local_transform[:3, 3], p)
        if sensor == 2 and scan is not None:
            return merge_local_grids(depth_grid, local_grid_from_scan(scan, p))
        return depth_grid
