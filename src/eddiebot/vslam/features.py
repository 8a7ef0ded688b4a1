"""Keypoints, binary descriptors and keypoint depth of one registered RGB-D frame."""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics, depth_to_meters
from eddiebot.vslam.parameters import RtabmapParameters

__all__ = ["FeatureExtractor", "FrameFeatures", "keypoint_depths", "retain_freed_memory", "to_gray"]

_DETECTOR_ORB = 2
_DETECTOR_GFTT_ORB = 8
# 3×3 smoothing weights of the keypoint depth (centre 4, edges 2, corners 1).
_DEPTH_WEIGHTS = np.array([1.0, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0], dtype=np.float32)
_DEPTH_NEIGHBOUR_TOLERANCE = 0.02


@dataclass(frozen=True)
class FrameFeatures:
    """Features of one frame, sorted by decreasing detector response.

    `uv` pixels (N, 2) float32; `points` 3D positions in the robot base frame (N, 3) float64 m,
    NaN rows where the depth is missing; `descriptors` (N, 32) uint8 ORB.
    """

    uv: NDArray[np.float32]
    responses: NDArray[np.float32]
    sizes: NDArray[np.float32]
    angles: NDArray[np.float32]
    octaves: NDArray[np.int32]
    descriptors: NDArray[np.uint8]
    points: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.uv.shape[0])

    @property
    def has_depth(self) -> NDArray[np.bool_]:
        """Rows whose 3D point is valid."""
        return np.isfinite(self.points[:, 0])

    def subset(self, index: NDArray[np.intp]) -> FrameFeatures:
        """The features at `index`, in that order."""
        return FrameFeatures(
            self.uv[index], self.responses[index], self.sizes[index], self.angles[index],
            self.octaves[index], self.descriptors[index], self.points[index],
        )

    @staticmethod
    def empty() -> FrameFeatures:
        """No features."""
        return FrameFeatures(
            np.zeros((0, 2), np.float32), np.zeros(0, np.float32), np.zeros(0, np.float32),
            np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros((0, 32), np.uint8),
            np.zeros((0, 3), np.float64),
        )


_M_TRIM_THRESHOLD = -1  # glibc mallopt parameters
_M_MMAP_THRESHOLD = -3


def retain_freed_memory(mmap_threshold: int = 32 << 20, trim_threshold: int = 256 << 20) -> bool:
    """Keep freed blocks in the process heap (glibc ``mallopt``: M_MMAP_THRESHOLD,
    M_TRIM_THRESHOLD; what the MALLOC_MMAP_THRESHOLD_ / MALLOC_TRIM_THRESHOLD_ environment
    variables set). Per 640×480 frame, OpenCV's corner detector and the frame's arrays allocate
    blocks of a few MB. With glibc's defaults each is mapped from the system and handed back
    when freed, so every frame pays the page faults again (≈ 5 ms of system time per frame
    measured on the development machine). A process setting, for the program that runs the
    odometry to call once at start-up (`eddie vslam replay` and `eddie demo` do; the library
    itself leaves the process's allocator alone). Returns False without glibc."""
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, int(mmap_threshold))) and bool(
        mallopt(_M_TRIM_THRESHOLD, int(trim_threshold)))


def to_gray(image: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """8-bit grey image from mono8, rgb8 (H, W, 3) or rgba8."""
    if image.ndim == 2:
        return image
    code = cv2.COLOR_RGBA2GRAY if image.shape[2] == 4 else cv2.COLOR_RGB2GRAY
    return np.asarray(cv2.cvtColor(image, code), dtype=np.uint8)


def keypoint_depths(
    depth_m: NDArray[np.float32], uv: NDArray[np.floating]
) -> NDArray[np.float32]:
    """Depth (m) at keypoints: 3×3 weighted mean of neighbours within 2 % of the centre; NaN if none.

    `depth_m` may be smaller than the colour image by an integer factor; `uv` is in colour pixels
    scaled to depth pixels by the caller.
    """
    h, w = depth_m.shape
    n = uv.shape[0]
    if n == 0:
        return np.zeros(0, np.float32)
    u = np.clip(np.rint(uv[:, 0]).astype(np.intp), 0, w - 1)
    v = np.clip(np.rint(uv[:, 1]).astype(np.intp), 0, h - 1)
    if depth_m.dtype == np.float32:  # what `depth_to_meters` gives: the compiled form
        return _keypoint_depths_f32(np.ascontiguousarray(depth_m), u, v, _DEPTH_WEIGHTS,
                                    np.float32(_DEPTH_NEIGHBOUR_TOLERANCE))
    offsets = np.array([-1, 0, 1])
    uu = np.clip(u[:, None, None] + offsets[None, None, :], 0, w - 1)
    vv = np.clip(v[:, None, None] + offsets[None, :, None], 0, h - 1)
    patch = depth_m[vv, uu].reshape(n, 9)
    centre = patch[:, 4]
    valid = (patch > 0) & (np.abs(patch - centre[:, None]) <= _DEPTH_NEIGHBOUR_TOLERANCE * centre[:, None])
    weights = valid * _DEPTH_WEIGHTS[None, :]
    total = weights.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (patch * weights).sum(axis=1) / total
    z[~(centre > 0)] = np.nan
    return z.astype(np.float32)


@njit(cache=True, inline="always")
def _sum9(a: NDArray[np.float32]) -> np.float32:
    """Sum of 9 float32 values in the order of NumPy's pairwise summation along a row."""
    return ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7])) + a[8]


@njit(cache=True, error_model="numpy")  # 0 / 0 is NaN, as in the array form
def _keypoint_depths_f32(depth_m: NDArray[np.float32], u: NDArray[np.intp], v: NDArray[np.intp],
                         weights: NDArray[np.float32], tol: np.float32) -> NDArray[np.float32]:
    """`keypoint_depths` on float32 depth: the array form's float32 operations in its order."""
    h, w = depth_m.shape
    out = np.empty(u.shape[0], np.float32)
    patch = np.empty(9, np.float32)
    wts = np.empty(9, np.float32)
    prod = np.empty(9, np.float32)
    for i in range(u.shape[0]):
        for dy in range(3):
            yy = min(max(v[i] + dy - 1, 0), h - 1)
            for dx in range(3):
                xx = min(max(u[i] + dx - 1, 0), w - 1)
                patch[3 * dy + dx] = depth_m[yy, xx]
        c = patch[4]
        for k in range(9):
            ok = patch[k] > 0 and abs(patch[k] - c) <= tol * c
            wts[k] = weights[k] if ok else np.float32(0.0)
            prod[k] = patch[k] * wts[k]
        out[i] = _sum9(prod) / _sum9(wts) if c > 0 else np.float32(np.nan)
    return out


class FeatureExtractor:
    """GFTT/ORB (`Kp/DetectorStrategy` 8) or ORB (2) keypoints with depth from the registered image."""

    def __init__(self, params: RtabmapParameters, *, max_features: int, strategy: int) -> None:
        self._params = params
        self._max_features = max_features
        self._strategy = strategy
        limit = max_features if max_features > 0 else 100000
        # fastThreshold/edge values follow RTAB-Map's ORB defaults (scale 2, 3 levels, edge 19).
        self._orb = cv2.ORB.create(
            nfeatures=limit, scaleFactor=2.0, nlevels=3, edgeThreshold=19, patchSize=31,
            fastThreshold=20,
        )
        self._gftt = cv2.GFTTDetector.create(
            maxCorners=limit,
            qualityLevel=params.gftt_quality_level,
            minDistance=params.gftt_min_distance,
            blockSize=params.gftt_block_size,
        )

    def extract(
        self,
        image: NDArray[np.uint8],
        depth: NDArray[np.generic] | None,
        camera: CameraIntrinsics,
        *,
        depth_as_mask: bool | None = None,
    ) -> FrameFeatures:
        """Detect, describe and back-project the features of one frame (points in base frame)."""
        gray = to_gray(image)
        depth_m = depth_to_meters(depth) if depth is not None else None
        use_mask = self._params.mem_depth_as_mask if depth_as_mask is None else depth_as_mask
        mask = None
        scale = 1
        if depth_m is not None:
            scale = max(1, gray.shape[1] // depth_m.shape[1])
            if use_mask:
                valid = (depth_m > 0).astype(np.uint8) * 255
                mask = valid if scale == 1 else cv2.resize(
                    valid, (gray.shape[1], gray.shape[0]), interpolation=cv2.INTER_NEAREST
                )
        detector = self._gftt if self._strategy == _DETECTOR_GFTT_ORB else self._orb
        keypoints = detector.detect(gray, mask)
        if not keypoints:
            return FrameFeatures.empty()
        if self._strategy == _DETECTOR_GFTT_ORB:
            for kp in keypoints:
                kp.size = 31.0
        keypoints, descriptors = self._orb.compute(gray, keypoints)
        if descriptors is None or len(keypoints) == 0:
            return FrameFeatures.empty()
        uv = np.asarray(cv2.KeyPoint.convert(keypoints), dtype=np.float32).reshape(-1, 2)
        # one pass over the keypoint objects (float32 values and small ints: exact in float64)
        attrs = np.array([(kp.response, kp.size, kp.angle, kp.octave) for kp in keypoints],
                         dtype=np.float64).reshape(-1, 4)
        responses = attrs[:, 0].astype(np.float32)
        order = np.argsort(-responses, kind="stable")
        if self._max_features > 0:
            order = order[: self._max_features]
        uv = uv[order]
        responses = responses[order]
        attrs = attrs[order]
        sizes = attrs[:, 1].astype(np.float32)
        angles = attrs[:, 2].astype(np.float32)
        octaves = attrs[:, 3].astype(np.int32)
        desc: NDArray[np.uint8] = np.ascontiguousarray(np.asarray(descriptors, np.uint8)[order])
        points = np.full((uv.shape[0], 3), np.nan)
        if depth_m is not None:
            z = keypoint_depths(depth_m, uv / scale).astype(np.float64)
            x = (uv[:, 0] - camera.cx) * z / camera.fx
            y = (uv[:, 1] - camera.cy) * z / camera.fy
            cam = np.stack([x, y, z], axis=1)
            lt = camera.local_transform
            points = cam @ lt[:3, :3].T + lt[:3, 3]
            keep = np.ones(uv.shape[0], dtype=bool)
            if self._params.kp_min_depth > 0:
                keep &= ~(z < self._params.kp_min_depth)
            if self._params.kp_max_depth > 0:
                keep &= ~(z > self._params.kp_max_depth)
            if not keep.all():
                idx = np.flatnonzero(keep)
                return FrameFeatures(uv[idx], responses[idx], sizes[idx], angles[idx],
                                     octaves[idx], desc[idx], points[idx])
        return FrameFeatures(uv, responses, sizes, angles, octaves, desc, points)
