"""A synthetic 4 × 3 m box room for the odometry tests: depth images ray-cast from a pose
(a 320×240 Kinect-like camera at Eddie's mount, depth in mm), textured points on its walls,
and a spin in place through it with the depth-ICP odometry settings."""

import numpy as np
from vslam_synthetic import eddie_kinect_320

from eddiebot.vslam.features import FrameFeatures
from eddiebot.vslam.odometry import VisualOdometry
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.transforms import from_xyz_yaw, se3_inverse

CAM = eddie_kinect_320()
#: a 4 × 3 m room, 2.5 m high: planes (normal, offset) with normal · x = offset
ROOM = [((1.0, 0.0, 0.0), 2.0), ((1.0, 0.0, 0.0), -2.0), ((0.0, 1.0, 0.0), 1.5),
        ((0.0, 1.0, 0.0), -1.5), ((0.0, 0.0, 1.0), 0.0), ((0.0, 0.0, 1.0), 2.5)]
ICP_VO = {"Reg/Force3DoF": "true", "Icp/PointToPlane": "true", "Icp/DownsamplingStep": "4",
          "Icp/MaxCorrespondenceDistance": "0.1", "Icp/RangeMax": "3",
          "OdomF2M/ScanMaxSize": "10000"}


def render_room(pose: np.ndarray, planes=ROOM, noise: float = 0.0,
            rng: np.random.Generator | None = None) -> np.ndarray:
    """uint16 mm depth image of the nearest plane along each pixel ray from base `pose`."""
    cam = pose @ CAM.local_transform
    u, v = np.meshgrid(np.arange(CAM.width), np.arange(CAM.height))
    rays = np.stack([(u - CAM.cx) / CAM.fx, (v - CAM.cy) / CAM.fy, np.ones(u.shape)], axis=2)
    d = rays @ cam[:3, :3].T
    o = cam[:3, 3]
    best = np.full(u.shape, np.inf)
    for n, c in planes:
        nn = np.asarray(n)
        den = d @ nn
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (c - o @ nn) / den
        t[~np.isfinite(t) | (t <= 0.05)] = np.inf
        best = np.minimum(best, t)
    if noise > 0 and rng is not None:
        best = best * (1.0 + rng.normal(0.0, noise, best.shape))
    out = np.where(np.isfinite(best) & (best < 8.0), np.round(best * 1000.0), 0)
    return out.astype(np.uint16)




def wall_features(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Textured points on the room's walls, 0.2–2.2 m high."""
    side = rng.integers(0, 4, n)
    s = rng.uniform(-1.0, 1.0, n)
    x = np.select([side == 0, side == 1, side == 2], [2.0, -2.0, 2.0 * s], 2.0 * s)
    y = np.select([side == 0, side == 1, side == 2], [1.5 * s, 1.5 * s, 1.5], -1.5)
    pts = np.stack([x, y, rng.uniform(0.2, 2.2, n)], axis=1)
    return pts, rng.integers(0, 256, (n, 32), dtype=np.uint8)


def observe(world: np.ndarray, desc: np.ndarray, pose: np.ndarray,
             rng: np.random.Generator) -> FrameFeatures:
    cam_from_world = se3_inverse(pose @ CAM.local_transform)
    pc = world @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = CAM.fx * pc[:, 0] / z + CAM.cx
        v = CAM.fy * pc[:, 1] / z + CAM.cy
    seen = np.flatnonzero((z > 0.3) & (u >= 0) & (u < CAM.width) & (v >= 0) & (v < CAM.height))
    uv = np.stack([u[seen], v[seen]], axis=1) + rng.normal(0, 0.3, (seen.size, 2))
    base_from_world = se3_inverse(pose)
    pts = world[seen] @ base_from_world[:3, :3].T + base_from_world[:3, 3]
    n = seen.size
    return FrameFeatures(uv.astype(np.float32), rng.uniform(1, 2, n).astype(np.float32),
                         np.full(n, 31, np.float32), np.zeros(n, np.float32),
                         np.zeros(n, np.int32), desc[seen], pts)


def spin_in_room(params: dict[str, str], blank: range, frames: int = 40):
    """A spin in place at 0.5 rad/s (10 Hz) in the room; features vanish during `blank`."""
    rng = np.random.default_rng(4)
    world, desc = wall_features(rng, 1500)
    vo = VisualOdometry(RtabmapParameters.from_dict(params))
    start = from_xyz_yaw(0.3, -0.2, 0.2)
    results, truths = [], []
    for k in range(frames):
        truth = start @ from_xyz_yaw(0.0, 0.0, 0.05 * k)
        feats = FrameFeatures.empty() if k in blank else observe(world, desc, truth, rng)
        r = vo.process_features(feats, CAM, k * 100_000_000, depth=render_room(truth))
        results.append(r)
        truths.append(se3_inverse(start) @ truth)
    return results, truths
