"""Laser scans as value types, their validation and their conversion to points."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Scan", "ScanCheck", "check_scan", "scan_angles", "scan_points"]

FloatArray = npt.NDArray[np.float64]

#: A scan with fewer valid beams than this is skipped (too little to match or map).
MIN_VALID_BEAMS = 10


@dataclass(frozen=True)
class Scan:
    """One laser scan in its sensor frame.

    ``ranges`` and ``angles`` are (N,) arrays (m, rad); invalid beams (NaN, ±Inf, <=0,
    outside ``[range_min, range_max]``) are allowed here and ignored by `scan_points`.
    """

    ranges: FloatArray
    angles: FloatArray
    range_min: float = 0.0
    range_max: float = math.inf
    stamp_ns: int = 0

    @classmethod
    def from_laser_scan(cls, msg: object, stamp_ns: int | None = None) -> Scan:
        """From a ``sensor_msgs/LaserScan``-like object (angle_min, angle_increment, ranges...)."""
        ranges = np.asarray(msg.ranges, dtype=np.float64)  # type: ignore[attr-defined]
        angles = scan_angles(
            msg.angle_min,  # type: ignore[attr-defined]
            msg.angle_increment,  # type: ignore[attr-defined]
            ranges.size,
        )
        if stamp_ns is None:
            stamp = msg.header.stamp  # type: ignore[attr-defined]
            stamp_ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        return cls(
            ranges=ranges,
            angles=angles,
            range_min=float(msg.range_min),  # type: ignore[attr-defined]
            range_max=float(msg.range_max),  # type: ignore[attr-defined]
            stamp_ns=stamp_ns,
        )


def scan_angles(angle_min: float, angle_increment: float, count: int) -> FloatArray:
    """Beam angles of a scan (rad), as LaserScan defines them."""
    return angle_min + angle_increment * np.arange(count, dtype=np.float64)


def valid_beams(scan: Scan, max_laser_range: float = math.inf) -> npt.NDArray[np.bool_]:
    """Mask of beams with a finite range inside the sensor's and the mapper's limits."""
    r = scan.ranges
    limit = min(scan.range_max, max_laser_range) if max_laser_range > 0 else scan.range_max
    with np.errstate(invalid="ignore"):
        return np.isfinite(r) & (r > 0.0) & (r >= scan.range_min) & (r <= limit)


def scan_points(scan: Scan, max_laser_range: float = math.inf) -> FloatArray:
    """End points (M, 2) of the valid beams in the sensor frame, m."""
    ok = valid_beams(scan, max_laser_range)
    r = scan.ranges[ok]
    a = scan.angles[ok]
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


@dataclass(frozen=True)
class ScanCheck:
    """Outcome of `check_scan`: ``ok`` False means skip the scan, ``reason`` says why."""

    ok: bool
    reason: str = ""


def check_scan(
    scan: Scan,
    *,
    expected_beams: int | None = None,
    last_stamp_ns: int | None = None,
    max_laser_range: float = math.inf,
) -> ScanCheck:
    """Whether a scan can be processed: beam count, finite values, enough valid beams, time."""
    if scan.ranges.ndim != 1 or scan.angles.ndim != 1:
        return ScanCheck(False, "ranges and angles must be 1-D")
    if scan.ranges.size != scan.angles.size:
        return ScanCheck(False, f"{scan.ranges.size} ranges for {scan.angles.size} beam angles")
    if expected_beams is not None and scan.ranges.size < expected_beams:
        return ScanCheck(False, f"{scan.ranges.size} beams, {expected_beams} announced")
    if not np.all(np.isfinite(scan.angles)):
        return ScanCheck(False, "non-finite beam angles")
    if last_stamp_ns is not None and scan.stamp_ns < last_stamp_ns:
        return ScanCheck(
            False,
            f"time went backwards ({scan.stamp_ns} ns < last {last_stamp_ns} ns)",
        )
    n_valid = int(np.count_nonzero(valid_beams(scan, max_laser_range)))
    if n_valid < MIN_VALID_BEAMS:
        bad = int(np.count_nonzero(~np.isfinite(scan.ranges) | (scan.ranges <= 0)))
        return ScanCheck(
            False,
            f"only {n_valid} valid beams of {scan.ranges.size} ({bad} NaN/Inf/zero)",
        )
    return ScanCheck(True)
