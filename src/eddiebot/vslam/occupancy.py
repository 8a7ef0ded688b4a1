"""Local occupancy grids per node (from depth or a 2D scan), global grid and cloud assembly.

Local grids are cell-centre lists in the node's base frame (m): ``ground`` and ``empty`` cells
are free, ``obstacles`` are occupied. The global grid fuses them at optimised poses with
log-odds (hit 0.7, miss 0.4, clamped to [0.1192, 0.971], occupied at ≥ 0.5).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.maps import OccupancyMap
from eddiebot.vslam.camera import CameraIntrinsics, depth_to_meters
from eddiebot.vslam.parameters import RtabmapParameters

__all__ = [
    "CloudImages",
    "GlobalGrid",
    "LocalGrid",
    "Scan2D",
    "assemble_cloud",
    "assemble_grid",
    "depth_cloud",
    "local_grid_from_depth",
    "local_grid_from_points",
    "local_grid_from_scan",
    "merge_local_grids",
    "ray_cells",
    "voxel_first_indices",
]

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]


def _logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


@dataclass(frozen=True)
class Scan2D:
    """A planar laser scan (sensor_msgs/LaserScan fields) and the laser's pose in the base frame."""

    ranges: F32
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    local_transform: F64 = field(default_factory=lambda: np.eye(4))

    def points_in_base(self) -> F64:
        """Valid returns as (N, 2) points in the base frame."""
        r = np.asarray(self.ranges, dtype=np.float64)
        ang = self.angle_min + self.angle_increment * np.arange(r.size)
        ok = np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max) & (r > 0)
        pts = np.stack([r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok]), np.zeros(ok.sum())], 1)
        lt = self.local_transform
        return (pts @ lt[:3, :3].T + lt[:3, 3])[:, :2]


@dataclass(frozen=True)
class LocalGrid:
    """Cells seen by one node, (N, 2) float32 cell centres in its base frame (m)."""

    ground: F32
    obstacles: F32
    empty: F32
    cell_size: float
    view_point: F32

    @staticmethod
    def empty_grid(cell_size: float) -> LocalGrid:
        """A grid with no cells."""
        z = np.zeros((0, 2), np.float32)
        return LocalGrid(z, z, z, cell_size, np.zeros(3, np.float32))


@dataclass(frozen=True)
class GlobalGrid:
    """Fused map: int8 (H, W), row 0 = lowest y (nav_msgs/OccupancyGrid), −1/0/100."""

    data: NDArray[np.int8]
    resolution: float
    origin_x: float
    origin_y: float

    def to_occupancy_map(self, frame_id: str = "map") -> OccupancyMap:
        """As the shared `eddiebot.maps.OccupancyMap` (for /map and map_server files)."""
        return OccupancyMap(self.data, self.resolution, (self.origin_x, self.origin_y, 0.0),
                            frame_id=frame_id)


_KEY_OFFSET = 1 << 20


def _cell_keys(pts: NDArray[np.floating], cell: float) -> NDArray[np.int64]:
    """One int64 per cell (2 or 3 axes of ±2^20 cells)."""
    k = np.floor(pts / cell).astype(np.int64) + _KEY_OFFSET
    key = k[:, 0]
    for axis in range(1, pts.shape[1]):
        key = key * (2 * _KEY_OFFSET) + k[:, axis]
    return key


def voxel_first_indices(pts: NDArray[np.floating], size: float) -> NDArray[np.intp]:
    """Index of the first point in each occupied voxel (or 2D cell)."""
    if pts.shape[0] == 0:
        return np.zeros(0, np.intp)
    _, first = np.unique(_cell_keys(pts, size), return_index=True)
    return first.astype(np.intp)


@dataclass(frozen=True)
class CloudImages:
    """What a node keeps of its frame to rebuild its cloud on demand: the depth (16-bit PNG,
    mm) and colour (JPEG) images decimated by `Grid/DepthDecimation` (a few kB each instead of
    the cloud's few hundred); `camera` is the decimated images' (same points as the full
    image's every `decimation`-th pixel)."""

    depth_png: bytes
    rgb_jpeg: bytes
    camera: CameraIntrinsics
    range_min: float = 0.0
    range_max: float = 0.0

    @classmethod
    def from_frame(cls, depth: NDArray[np.generic], rgb: NDArray[np.uint8] | None,
                   camera: CameraIntrinsics, decimation: int, range_min: float = 0.0,
                   range_max: float = 0.0) -> CloudImages:
        """Decimate and compress one registered frame (depth in any `depth_to_meters` unit)."""
        step = max(1, decimation)
        d = np.asarray(depth)[::step, ::step]
        mm = d if d.dtype == np.uint16 else np.clip(
            np.rint(depth_to_meters(d) * 1000.0), 0, 65535).astype(np.uint16)
        ok, dbuf = cv2.imencode(".png", np.ascontiguousarray(mm))
        if rgb is None:
            small = np.full((*mm.shape, 3), 255, np.uint8)
        else:
            small = np.asarray(rgb)[::step, ::step]
            if small.ndim == 2:
                small = np.repeat(small[..., None], 3, axis=2)
        ok2, cbuf = cv2.imencode(".jpg", np.ascontiguousarray(small[..., ::-1]))
        if not (ok and ok2):
            raise ValueError("cannot compress the node's cloud images")
        small_camera = CameraIntrinsics(camera.fx / step, camera.fy / step, camera.cx / step,
                                        camera.cy / step, int(mm.shape[1]), int(mm.shape[0]),
                                        camera.local_transform)
        return cls(bytes(dbuf), bytes(cbuf), small_camera, range_min, range_max)

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return len(self.depth_png) + len(self.rgb_jpeg)

    def depth(self) -> NDArray[np.uint16]:
        """The decimated depth (mm), in `camera`'s pixels."""
        depth = cv2.imdecode(np.frombuffer(self.depth_png, np.uint8), cv2.IMREAD_UNCHANGED)
        if depth is None:
            raise ValueError("undecodable cloud depth")
        return np.asarray(depth, dtype=np.uint16)

    def cloud(self, voxel: float = 0.0) -> tuple[F64, NDArray[np.uint8]]:
        """The coloured cloud (base frame), voxel-filtered (first point per voxel) if > 0."""
        depth = self.depth()
        bgr = cv2.imdecode(np.frombuffer(self.rgb_jpeg, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError("undecodable cloud colours")
        xyz, colors = depth_cloud(depth, self.camera, 1, self.range_min,
                                  self.range_max, np.ascontiguousarray(bgr[..., ::-1]))
        if voxel > 0:
            first = voxel_first_indices(xyz, voxel)
            xyz, colors = xyz[first], colors[first]
        return xyz, colors


def _unique_cells(xy: NDArray[np.floating], cell: float) -> F32:
    if xy.shape[0] == 0:
        return np.zeros((0, 2), np.float32)
    first = voxel_first_indices(xy, cell)
    return ((np.floor(xy[first] / cell) + 0.5) * cell).astype(np.float32)


def _without(cells: F32, blocked: F32, cell: float) -> F32:
    """`cells` minus those also in `blocked` (same cell size)."""
    if cells.shape[0] == 0 or blocked.shape[0] == 0:
        return cells.reshape(-1, 2)
    keep = ~np.isin(_cell_keys(cells, cell), _cell_keys(blocked, cell))
    return cells[keep].reshape(-1, 2)


def ray_cells(origin: NDArray[np.floating], ends: NDArray[np.floating], cell: float) -> F32:
    """Centres of the cells the segments `origin` → each of `ends` (N, 2) cross, the end
    cells excluded (2D ray tracing, half-cell steps; m)."""
    o = np.asarray(origin, np.float64)[:2]
    e = np.asarray(ends, np.float64).reshape(-1, 2)
    if e.shape[0] == 0:
        return np.zeros((0, 2), np.float32)
    steps = np.maximum(1, np.ceil(np.linalg.norm(e - o, axis=1) / (cell * 0.5))).astype(np.int64)
    ray = np.repeat(np.arange(e.shape[0]), steps)
    start = np.cumsum(steps) - steps
    k = np.arange(int(steps.sum())) - np.repeat(start, steps)
    frac = (k / np.repeat(steps, steps))[:, None]
    pts = o + (e[ray] - o) * frac
    return _without(_unique_cells(pts, cell), _unique_cells(e, cell), cell)


def depth_cloud(
    depth: NDArray[np.generic],
    camera: CameraIntrinsics,
    decimation: int,
    range_min: float = 0.0,
    range_max: float = 0.0,
    rgb: NDArray[np.uint8] | None = None,
) -> tuple[F64, NDArray[np.uint8]]:
    """Decimated depth back-projected into the base frame: xyz (N, 3) and colour (N, 3)."""
    d = depth_to_meters(depth)
    step = max(1, decimation)
    scale = camera.width / d.shape[1]
    sub = d[::step, ::step]
    v, u = np.nonzero(sub > 0)
    z = sub[v, u].astype(np.float64)
    uu = (u * step) * scale
    vv = (v * step) * scale
    x = (uu - camera.cx) * z / camera.fx
    y = (vv - camera.cy) * z / camera.fy
    cam = np.stack([x, y, z], axis=1)
    rng = np.linalg.norm(cam, axis=1)
    ok = np.ones(z.size, bool)
    if range_min > 0:
        ok &= rng >= range_min
    if range_max > 0:
        ok &= rng <= range_max
    cam = cam[ok]
    lt = camera.local_transform
    xyz = cam @ lt[:3, :3].T + lt[:3, 3]
    if rgb is not None:  # (the colour image may be smaller than the camera's: decimated)
        rr = np.clip(np.rint(vv[ok] * (rgb.shape[0] / camera.height)).astype(np.intp), 0,
                     rgb.shape[0] - 1)
        cc = np.clip(np.rint(uu[ok] * (rgb.shape[1] / camera.width)).astype(np.intp), 0,
                     rgb.shape[1] - 1)
        colors = rgb[rr, cc] if rgb.ndim == 3 else np.repeat(rgb[rr, cc][:, None], 3, axis=1)
    else:
        colors = np.full((xyz.shape[0], 3), 255, np.uint8)
    return xyz, colors.astype(np.uint8)


def local_grid_from_depth(
    depth: NDArray[np.generic], camera: CameraIntrinsics, params: RtabmapParameters
) -> LocalGrid:
    """Ground/obstacle (and, with `Grid/RayTracing`, empty) cells from depth (z-band
    segmentation)."""
    xyz, _ = depth_cloud(depth, camera, params.grid_depth_decimation,
                         params.grid_range_min, params.grid_range_max)
    return local_grid_from_points(xyz, camera.local_transform[:3, 3], params)


def local_grid_from_points(
    xyz: F64, view_point: NDArray[np.float64], params: RtabmapParameters
) -> LocalGrid:
    """Ground/obstacle cells from a base-frame cloud (already range-filtered); with
    `Grid/RayTracing` (2D, `Grid/3D` false) the cells between the view point and each obstacle
    cell are empty, as upstream's 2D ray tracing of the projected obstacles."""
    cell = params.grid_cell_size
    if xyz.shape[0]:
        first = voxel_first_indices(xyz, cell)
        xyz = (np.floor(xyz[first] / cell) + 0.5) * cell
    z = xyz[:, 2]
    keep = np.ones(z.size, bool)
    if params.grid_max_obstacle_height > 0:
        keep &= z <= params.grid_max_obstacle_height
    if params.grid_min_ground_height != 0:
        keep &= z >= params.grid_min_ground_height
    xyz, z = xyz[keep], z[keep]
    ground_max = params.grid_max_ground_height if params.grid_max_ground_height > 0 else cell
    ground_mask = z <= ground_max
    obstacles = _unique_cells(xyz[~ground_mask, :2], cell)
    ground = _without(_unique_cells(xyz[ground_mask, :2], cell), obstacles, cell)
    vp = np.asarray(view_point, np.float32)
    empty = np.zeros((0, 2), np.float32)
    if params.grid_ray_tracing and obstacles.shape[0]:
        traced = _without(ray_cells(vp[:2], obstacles, cell), obstacles, cell)
        empty = _without(traced, ground, cell)
    return LocalGrid(ground.reshape(-1, 2), obstacles.reshape(-1, 2), empty.reshape(-1, 2),
                     cell, vp)


def local_grid_from_scan(scan: Scan2D, params: RtabmapParameters) -> LocalGrid:
    """Obstacle at each return, empty cells along each ray (2D ray tracing in the base frame)."""
    cell = params.grid_cell_size
    pts = scan.points_in_base()
    origin = scan.local_transform[:2, 3]
    rng = np.linalg.norm(pts - origin, axis=1)
    ok = rng >= params.grid_range_min
    rmax = params.grid_range_max if params.grid_range_max > 0 else scan.range_max
    ok &= rng <= min(rmax, scan.range_max)
    pts = pts[ok]
    obstacles = _unique_cells(pts, cell)
    free = _without(ray_cells(origin, pts, cell), obstacles, cell)
    vp = scan.local_transform[:3, 3].astype(np.float32)
    return LocalGrid(np.zeros((0, 2), np.float32), obstacles, free, cell, vp)


def merge_local_grids(a: LocalGrid, b: LocalGrid) -> LocalGrid:
    """Union of two local grids of one node (`Grid/Sensor` 2); obstacles win over free cells."""
    cell = a.cell_size
    obstacles = _unique_cells(np.concatenate([a.obstacles, b.obstacles]), cell)
    ground = _without(_unique_cells(np.concatenate([a.ground, b.ground]), cell), obstacles, cell)
    empty = _without(_unique_cells(np.concatenate([a.empty, b.empty]), cell), obstacles, cell)
    return LocalGrid(ground, obstacles, empty, cell, a.view_point)


def assemble_grid(
    grids: Mapping[int, LocalGrid],
    poses: Mapping[int, F64],
    cell_size: float,
    prob_hit: float = 0.7,
    prob_miss: float = 0.4,
    clamp_min: float = 0.1192,
    clamp_max: float = 0.971,
    occupancy_thr: float = 0.5,
) -> GlobalGrid | None:
    """Fuse local grids at their (optimised) poses, oldest node first; None if nothing to fuse."""
    ids = sorted(i for i in grids if i in poses)
    world: list[tuple[F64, F64]] = []
    for i in ids:
        g = grids[i]
        t = poses[i]
        r = t[:2, :2]
        free = np.concatenate([g.ground, g.empty]).astype(np.float64) @ r.T + t[:2, 3]
        occ = g.obstacles.astype(np.float64) @ r.T + t[:2, 3]
        world.append((free, occ))
    allpts = [p for f, o in world for p in (f, o) if p.shape[0]]
    if not allpts:
        return None
    stacked = np.concatenate(allpts)
    lo = np.floor(stacked.min(axis=0) / cell_size) - 1
    hi = np.floor(stacked.max(axis=0) / cell_size) + 2
    w, h = (hi - lo).astype(int)
    logodds = np.zeros((h, w))
    seen = np.zeros((h, w), bool)
    l_hit, l_miss = _logit(prob_hit), _logit(prob_miss)
    l_min, l_max = _logit(clamp_min), _logit(clamp_max)
    for free, occ in world:
        for pts, delta in ((free, l_miss), (occ, l_hit)):
            if pts.shape[0] == 0:
                continue
            cells = (np.floor(pts[voxel_first_indices(pts, cell_size)] / cell_size) - lo).astype(int)
            logodds[cells[:, 1], cells[:, 0]] = np.clip(
                logodds[cells[:, 1], cells[:, 0]] + delta, l_min, l_max
            )
            seen[cells[:, 1], cells[:, 0]] = True
    data = np.full((h, w), -1, np.int8)
    data[seen] = 0
    data[seen & (logodds >= _logit(occupancy_thr))] = 100
    return GlobalGrid(data, cell_size, float(lo[0] * cell_size), float(lo[1] * cell_size))


def assemble_cloud(
    clouds: Mapping[int, tuple[F64, NDArray[np.uint8]]],
    poses: Mapping[int, F64],
    voxel_size: float = 0.0,
) -> tuple[F64, NDArray[np.uint8]]:
    """Per-node clouds (base frame) moved to their poses and optionally voxel-filtered."""
    xyz_parts = []
    rgb_parts = []
    for i in sorted(clouds):
        if i not in poses:
            continue
        xyz, rgb = clouds[i]
        t = poses[i]
        xyz_parts.append(xyz @ t[:3, :3].T + t[:3, 3])
        rgb_parts.append(rgb)
    if not xyz_parts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    xyz = np.concatenate(xyz_parts)
    rgb = np.concatenate(rgb_parts)
    if voxel_size > 0 and xyz.shape[0]:
        first = voxel_first_indices(xyz, voxel_size)
        xyz, rgb = xyz[first], rgb[first]
    return xyz, rgb
