"""depthimage_to_laserscan as a pure function.

Same parameter names, defaults and semantics as ROS 2's ``depthimage_to_laserscan``
(ros-perception/depthimage_to_laserscan, branch ros2): bins uniform in angle between the
angles of image columns 0 and ``width - 1`` through the principal row, each column's bin
fixed by its angle ``-atan((u - cx) / fx)`` (column 0 is the most positive angle), a range
``sqrt(x² + z²)`` in the horizontal plane of the optical frame, and the upstream selection
rule: a bin keeps the smallest range within ``[range_min, range_max]``; with none in range it
keeps the last ±Inf seen (row-major order), else NaN. Out-of-range values are dropped, not
clamped; 16UC1 zeros (no return) never produce a value unless ``range_min <= 0``.

One deliberate difference: upstream does not compare the image size with camera_info; here a
disagreement raises `ImageSizeError` naming both.

One option of eddiebot's own, off by default: ``row_selection: nearest_surface``. Upstream's
rule keeps the nearest of the ``scan_height`` rows. Where the rows see one surface, that is
the minimum of several noisy readings of one range, which is short by a multiple of the
sensor's noise: with a Kinect's σ = 1.425e-3·r² and 10 independent rows, ≈ 1.5 σ, i.e.
2.2e-3·r² (−10 cm at 7 m), growing with range (docs/benchmarks/sim.md#sim-depth-noise). A
scan matcher reads that as a building that shrinks around the robot as it walks away. With
``nearest_surface`` a bin keeps the mean of the readings that lie within a tolerance
(``surface_tolerance`` + ``surface_tolerance_quadratic``·r², a few σ of the sensor's noise
at the nearest reading's range r) of its nearest reading: the nearest surface still wins —
a table edge seen by two rows in front of a wall seen by the rest gives the edge's range —
but its range is the mean of its readings, not their minimum. Bins whose readings are all
out of range behave as upstream's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.msgs.sensor_msgs import LaserScan
from eddiebot.perception._image import DEPTH_ENCODINGS, check_size, image_to_array
from eddiebot.perception.errors import ScanHeightError

__all__ = ["ROW_SELECTIONS", "DepthToScanParams", "ScanGeometry", "depth_image_to_laserscan", "scan_geometry"]


@dataclass(frozen=True)
class DepthToScanParams:
    """Node parameters of ``depthimage_to_laserscan`` with the upstream defaults."""

    scan_time: float = 0.033
    """Copied into ``LaserScan.scan_time`` (s)."""
    range_min: float = 0.45
    """Smallest accepted range (m); also copied to the message."""
    range_max: float = 10.0
    """Largest accepted range (m); also copied to the message."""
    scan_height: int = 1
    """Number of image rows, centred on the principal row, that feed the scan."""
    output_frame: str = "camera_depth_frame"
    """frame_id of the scan; empty keeps the image's frame_id."""
    row_selection: str = "nearest"
    """eddiebot's: ``nearest`` (upstream: the smallest range of the bin's rows and columns) or
    ``nearest_surface`` (the mean of the readings within the surface tolerance of the smallest)."""
    surface_tolerance: float = 0.02
    """``nearest_surface``: constant part of the tolerance (m)."""
    surface_tolerance_quadratic: float = 0.006
    """``nearest_surface``: part of the tolerance growing with the nearest range squared (1/m);
    0.006 ≈ 4 σ of the Kinect's disparity noise (1.425e-3·r²)."""

    def __post_init__(self) -> None:
        if self.row_selection not in ROW_SELECTIONS:
            raise ValueError(f"row_selection: {self.row_selection!r} is not one of "
                             f"{', '.join(ROW_SELECTIONS)}")
        if not (self.surface_tolerance >= 0.0 and self.surface_tolerance_quadratic >= 0.0):
            raise ValueError("surface_tolerance and surface_tolerance_quadratic must be >= 0, got "
                             f"{self.surface_tolerance} and {self.surface_tolerance_quadratic}")


#: Values of ``DepthToScanParams.row_selection``.
ROW_SELECTIONS = ("nearest", "nearest_surface")


@dataclass(frozen=True)
class ScanGeometry:
    """Angles and per-column bin indices derived from the camera model (rad)."""

    angle_min: float
    angle_max: float
    angle_increment: float
    fx: float
    cx: float
    cy: float
    bin_of_column: npt.NDArray[np.int64]
    """Bin index of every column; columns whose index falls outside the scan are -1."""


def _camera(camera_info: Any) -> tuple[float, float, float, float, float, float]:
    p = np.asarray(camera_info.p, dtype=np.float64)
    if p.size == 12 and p[0] != 0.0:
        return float(p[0]), float(p[5]), float(p[2]), float(p[6]), float(p[3]), float(p[7])
    k = np.asarray(camera_info.k, dtype=np.float64)
    return float(k[0]), float(k[4]), float(k[2]), float(k[5]), 0.0, 0.0


def _rectify(camera_info: Any, pts: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    d = np.asarray(camera_info.d, dtype=np.float64)
    if d.size == 0 or not np.any(d):
        return pts
    import cv2

    k = np.asarray(camera_info.k, dtype=np.float64).reshape(3, 3)
    r = np.asarray(camera_info.r, dtype=np.float64).reshape(3, 3)
    p = np.asarray(camera_info.p, dtype=np.float64).reshape(3, 4)
    out = cv2.undistortPoints(pts.reshape(-1, 1, 2), k, d, R=r, P=p)
    return np.asarray(out, dtype=np.float64).reshape(-1, 2)


def _angle_between(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> float:
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.acos(min(1.0, max(-1.0, c)))


def scan_geometry(camera_info: Any) -> ScanGeometry:
    """Scan angles for a camera model, exactly as upstream computes them (float32-rounded)."""
    fx, fy, cx, cy, tx, ty = _camera(camera_info)
    width = int(camera_info.width)
    raw = np.array([[0.0, cy], [width - 1.0, cy], [cx, cy]])
    rect = _rectify(camera_info, raw)
    rays = np.column_stack(
        [(rect[:, 0] - cx - tx) / fx, (rect[:, 1] - cy - ty) / fy, np.ones(3)]
    )
    angle_max = _angle_between(rays[0], rays[2])
    angle_min = -_angle_between(rays[2], rays[1])
    angle_increment = (angle_max - angle_min) / (width - 1)
    # Upstream bins with the float32 message fields and a float32 centre and scale.
    a_min = float(np.float32(angle_min))
    a_inc = float(np.float32(angle_increment))
    cx32 = np.float32(cx)
    u = np.arange(width, dtype=np.uint32).astype(np.float32)
    k = float(np.float32(0.001 / fx))
    theta = -np.arctan2((u - cx32).astype(np.float64) * k, 0.001)
    scaled = (theta - a_min) / a_inc
    index = np.trunc(scaled).astype(np.int64)  # C++ int conversion truncates toward zero
    index[(index < 0) | (index >= width)] = -1  # upstream has no bound check (UB); drop
    return ScanGeometry(angle_min, angle_max, angle_increment, fx, cx, cy, index)


def _ranges(
    depth: npt.NDArray[Any], geom: ScanGeometry, params: DepthToScanParams
) -> npt.NDArray[np.float64]:
    height, width = depth.shape
    scan_height = int(params.scan_height)
    if scan_height / 2.0 > geom.cy or scan_height / 2.0 > height - geom.cy:
        raise ScanHeightError(
            f"scan_height ({scan_height} pixels) is too large for the image height "
            f"({height}) and principal row cy={geom.cy:.2f}"
        )
    offset = int(geom.cy - scan_height / 2.0)
    band = depth[offset : offset + scan_height]
    if band.dtype == np.uint16:
        # depth_traits: toMeters(uint16) is depth * 0.001f, a float
        z = (band.astype(np.float32) * np.float32(0.001)).astype(np.float64)
        valid = band != 0
    else:
        z = band.astype(np.float64)
        valid = np.isfinite(z)
    # float32 centre and scale and a float32 x, as upstream computes them
    unit = 0.001 if band.dtype == np.uint16 else 1.0
    du = np.arange(width, dtype=np.uint32).astype(np.float32) - np.float32(geom.cx)
    raw = band.astype(np.float32)
    with np.errstate(invalid="ignore", over="ignore"):
        x = (du * raw * np.float32(unit / geom.fx)).astype(np.float64)
        r = np.where(valid, np.sqrt(x * x + z * z), z)  # invalid: raw value (0, NaN, ±Inf)

    rmin, rmax = float(np.float32(params.range_min)), float(np.float32(params.range_max))
    in_range = (r >= rmin) & (r <= rmax)
    col_min = np.where(in_range, r, np.inf).min(axis=0)
    col_has = in_range.any(axis=0)
    # Last ±Inf per column in row-major order (rows increase downwards).
    is_inf = np.isinf(r)
    rows_rev = np.argmax(is_inf[::-1], axis=0)
    last_row = band.shape[0] - 1 - rows_rev
    col_inf_key = np.where(is_inf.any(axis=0), last_row * width + np.arange(width), -1)

    bins = geom.bin_of_column
    ok = bins >= 0
    best = np.full(width, np.inf)
    np.minimum.at(best, bins[ok & col_has], col_min[ok & col_has])
    has = np.zeros(width, dtype=bool)
    has[bins[ok & col_has]] = True
    inf_key = np.full(width, -1, dtype=np.int64)
    np.maximum.at(inf_key, bins[ok], col_inf_key[ok])

    ranges = np.full(width, np.nan)
    with_inf = inf_key >= 0
    flat = r.reshape(-1)
    ranges[with_inf] = flat[inf_key[with_inf]]
    if params.row_selection == "nearest_surface":
        best = _nearest_surface(r, in_range, bins, best, params)
    ranges[has] = best[has]
    return ranges


def _nearest_surface(r: npt.NDArray[np.float64], in_range: npt.NDArray[np.bool_],
                     bins: npt.NDArray[np.int64], best: npt.NDArray[np.float64],
                     params: DepthToScanParams) -> npt.NDArray[np.float64]:
    """Per bin, the mean of the in-range readings within the surface tolerance of its nearest."""
    n_bins = best.size
    sample_bin = np.broadcast_to(bins, r.shape)
    ok = in_range & (sample_bin >= 0)
    b = sample_bin[ok]
    v = r[ok]
    near = best[b]
    keep = v <= near + params.surface_tolerance + params.surface_tolerance_quadratic * near * near
    total = np.bincount(b[keep], weights=v[keep], minlength=n_bins)
    count = np.bincount(b[keep], minlength=n_bins)
    out = best.copy()
    found = count > 0
    out[found] = total[found] / count[found]
    return out


def depth_image_to_laserscan(
    image: Any, camera_info: Any, params: DepthToScanParams | None = None
) -> Any:
    """Convert a depth ``sensor_msgs/Image`` (16UC1 mm or 32FC1 m) to a ``LaserScan``.

    The scan's header is the image's, with frame_id replaced by ``params.output_frame`` when
    that is not empty. Raises `UnsupportedEncodingError`, `ImageSizeError` (image vs
    camera_info, naming both) or `ScanHeightError`.
    """
    params = params or DepthToScanParams()
    check_size(image, camera_info)
    depth = image_to_array(image, DEPTH_ENCODINGS)
    geom = scan_geometry(camera_info)
    ranges = _ranges(depth, geom, params)
    header = type(image.header)(
        stamp=image.header.stamp,
        frame_id=params.output_frame or image.header.frame_id,
    )
    return LaserScan(
        header=header,
        angle_min=float(np.float32(geom.angle_min)),
        angle_max=float(np.float32(geom.angle_max)),
        angle_increment=float(np.float32(geom.angle_increment)),
        time_increment=0.0,
        scan_time=float(np.float32(params.scan_time)),
        range_min=float(np.float32(params.range_min)),
        range_max=float(np.float32(params.range_max)),
        ranges=ranges.astype(np.float32),
        intensities=np.zeros(0, dtype=np.float32),
    )
