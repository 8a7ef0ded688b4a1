"""Tiny pinhole ray-caster of a textured box room: RGB-D frames with exact ground truth."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.memory import Link
from eddiebot.vslam.occupancy import Scan2D
from eddiebot.vslam.transforms import OPTICAL_ROTATION, from_xyz_yaw

TEXELS_PER_M = 100.0
CAMERA_HEIGHT = 0.5


def make_texture(width_m: float, height_m: float, rng: np.random.Generator) -> NDArray[np.uint8]:
    """Random rectangles, discs and noise: corners at several scales, unique per seed."""
    w = int(width_m * TEXELS_PER_M)
    h = int(height_m * TEXELS_PER_M)
    img = rng.integers(90, 166, size=(h // 8 + 1, w // 8 + 1)).astype(np.uint8)
    img = cv2.resize(img, (w, h), interpolation=cv2.INTER_CUBIC)
    n_shapes = int(width_m * height_m * 40)
    for _ in range(n_shapes):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        size = int(rng.integers(3, 25))
        color = int(rng.integers(0, 256))
        if rng.random() < 0.6:
            cv2.rectangle(img, (x, y), (x + size, y + int(rng.integers(3, 25))), color, -1)
        else:
            cv2.circle(img, (x, y), size // 2 + 1, color, -1)
    return cv2.GaussianBlur(img, (0, 0), 0.8)


@dataclass
class BoxRoom:
    """Axis-aligned room [0, size_x] × [0, size_y] × [0, height], textured on all six faces."""

    size_x: float = 8.0
    size_y: float = 6.0
    height: float = 2.5
    seed: int = 0

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        sx, sy, hz = self.size_x, self.size_y, self.height
        # faces: (axis, value, (u axis, v axis), texture)
        self.faces = [
            (0, 0.0, (1, 2), make_texture(sy, hz, rng)),
            (0, sx, (1, 2), make_texture(sy, hz, rng)),
            (1, 0.0, (0, 2), make_texture(sx, hz, rng)),
            (1, sy, (0, 2), make_texture(sx, hz, rng)),
            (2, 0.0, (0, 1), make_texture(sx, sy, rng)),
            (2, hz, (0, 1), make_texture(sx, sy, rng)),
        ]


def kinect_camera(width: int = 640, height: int = 480) -> CameraIntrinsics:
    """Kinect-like intrinsics with the camera 0.5 m above the base origin looking along +x."""
    lt = OPTICAL_ROTATION.copy()
    lt[2, 3] = CAMERA_HEIGHT
    s = width / 640.0
    return CameraIntrinsics(525.0 * s, 525.0 * s, 319.5 * s, 239.5 * s, width, height, lt)


def render(
    room: BoxRoom, base_pose: NDArray[np.float64], camera: CameraIntrinsics
) -> tuple[NDArray[np.uint8], NDArray[np.uint16]]:
    """RGB (H, W, 3) uint8 and depth (H, W) uint16 mm seen from a 4×4 base pose in the room."""
    t_wc = base_pose @ camera.local_transform
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64),
                       np.arange(camera.height, dtype=np.float64))
    d_cam = np.stack([(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy,
                      np.ones_like(u)], axis=-1)
    d = d_cam @ t_wc[:3, :3].T
    o = t_wc[:3, 3]
    best_t = np.full(u.shape, np.inf)
    best_face = np.full(u.shape, -1, dtype=np.int64)
    for k, (axis, value, _, _) in enumerate(room.faces):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (value - o[axis]) / d[..., axis]
        better = (t > 1e-6) & (t < best_t)
        best_t[better] = t[better]
        best_face[better] = k
    hit = o + d * best_t[..., None]
    gray = np.zeros(u.shape, np.uint8)
    for k, (_, _, (ua, va), tex) in enumerate(room.faces):
        sel = best_face == k
        if not sel.any():
            continue
        mx = (hit[..., ua] * TEXELS_PER_M).astype(np.float32)
        my = (hit[..., va] * TEXELS_PER_M).astype(np.float32)
        sampled = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        gray[sel] = sampled[sel]
    depth = np.clip(np.rint(best_t * 1000.0), 0, 65535).astype(np.uint16)
    return np.repeat(gray[..., None], 3, axis=2), depth


def eddie_kinect_320() -> CameraIntrinsics:
    """Eddie's Kinect at 320×240 as the simulator mounts it on base_footprint."""
    lt = OPTICAL_ROTATION.copy()
    lt[:3, 3] = (-0.12, -0.0125, 0.61)
    return CameraIntrinsics(263.3, 263.3, 159.0, 120.3, 320, 240, lt)


def link_adjacency(links: list[Link]) -> dict[int, dict[int, Link]]:
    """Both directions of each link, keyed by node id, as `rtabmap.path_covariance` reads them."""
    adj: dict[int, dict[int, Link]] = {}
    for lk in links:
        adj.setdefault(lk.from_id, {})[lk.to_id] = lk
        adj.setdefault(lk.to_id, {})[lk.from_id] = lk.inverse()
    return adj


def planar_pose(x: float, y: float, yaw: float) -> NDArray[np.float64]:
    """Base pose on the floor."""
    return from_xyz_yaw(x, y, yaw)


_FRAME_CACHE: dict[tuple[int, int, float, float, float], tuple[NDArray[np.uint8], NDArray[np.uint16]]] = {}
_ROOMS: dict[int, BoxRoom] = {}


def room(seed: int) -> BoxRoom:
    """Cached room per seed."""
    if seed not in _ROOMS:
        _ROOMS[seed] = BoxRoom(seed=seed)
    return _ROOMS[seed]


def frame(seed: int, x: float, y: float, yaw: float, width: int = 320
          ) -> tuple[NDArray[np.uint8], NDArray[np.uint16]]:
    """Cached render of room `seed` from base pose (x, y, yaw)."""
    key = (seed, width, round(x, 6), round(y, 6), round(yaw, 6))
    if key not in _FRAME_CACHE:
        _FRAME_CACHE[key] = render(room(seed), planar_pose(x, y, yaw),
                                   kinect_camera(width, width * 3 // 4))
    return _FRAME_CACHE[key]


def graph_neighbours(links: dict[int, set[int]], wm: set[int], i: int, depth_max: int) -> dict[int, int]:
    """Nodes of ``wm`` within ``depth_max`` links of ``i`` (breadth first), with their depth."""
    out: dict[int, int] = {}
    frontier, seen = [i], {i}
    for depth in range(1, depth_max + 1):
        nxt = []
        for n in frontier:
            for m in links.get(n, ()):
                if m not in seen and m in wm:
                    seen.add(m)
                    out[m] = depth
                    nxt.append(m)
        frontier = nxt
    return out


def box_scan(x: float, y: float, yaw: float, size: tuple[float, float] = (8.0, 6.0)) -> Scan2D:
    """A 181-ray, 180° scan from (x, y, yaw) inside an axis-aligned box room (m)."""
    angles = -np.pi / 2 + np.arange(181) * np.pi / 180
    d = np.stack([np.cos(angles + yaw), np.sin(angles + yaw)], axis=1)
    with np.errstate(divide="ignore"):
        tx = np.where(d[:, 0] > 0, (size[0] - x) / d[:, 0], -x / d[:, 0])
        ty = np.where(d[:, 1] > 0, (size[1] - y) / d[:, 1], -y / d[:, 1])
    ranges = np.minimum(np.abs(tx), np.abs(ty)).astype(np.float32)
    return Scan2D(ranges, -np.pi / 2, np.pi / 180, 0.1, 10.0)
