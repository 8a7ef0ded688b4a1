"""CARMEN log reader (``.clf``, ``.log``, ``.log.gz``): FLASER, ROBOTLASER1, ODOM, PARAM.

Line formats::

    FLASER n r1..rn x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp
    ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
        n r1..rn m rem1..remm laser_x laser_y laser_theta robot_x robot_y robot_theta
        tv rv forward_safety side_safety turn_axis ipc_timestamp ipc_hostname logger_timestamp
    ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp
    PARAM name value [ipc_timestamp ipc_hostname logger_timestamp]

``#`` lines and other message types are ignored. FLASER carries no angles: as CARMEN and
GMapping do, it spans 180° from -90°, at 1° for 180/181 beams, 0.5° for 360/361, else
π/(n-1). Ranges at or above the laser's maximum (SICK's 81.91 m) mean "no return".

A malformed line raises `CarmenFormatError` naming the file and line (``strict=True``), or
is skipped with one warning in `CarmenLog.warnings` (``strict=False``).
"""

from __future__ import annotations

import gzip
import io
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from eddiebot.slam.errors import CarmenFormatError

__all__ = [
    "CarmenLog",
    "LaserRecord",
    "OdomRecord",
    "carmen_beam_angles",
    "iter_carmen",
    "read_carmen",
]

FloatArray = npt.NDArray[np.float64]

#: SICK LMS "no return" value in CARMEN logs is 81.91 m; anything from here up is invalid.
DEFAULT_FLASER_RANGE_MAX = 80.0


@dataclass(frozen=True)
class LaserRecord:
    """One laser scan: ranges (m), beam angles (rad, laser frame), poses (x, y, theta).

    ``laser_pose`` is the first pose triplet (the laser's pose as logged — corrected, in a
    corrected log); ``odom_pose`` the robot's odometry. ``timestamp`` is the IPC timestamp (s),
    ``logger_timestamp`` the logger's.
    """

    ranges: FloatArray
    angles: FloatArray
    laser_pose: FloatArray
    odom_pose: FloatArray
    timestamp: float
    logger_timestamp: float
    range_max: float
    line: int
    kind: str = "FLASER"


@dataclass(frozen=True)
class OdomRecord:
    """One odometry message: pose (x, y, theta), tv (m/s), rv (rad/s), timestamps (s)."""

    pose: FloatArray
    tv: float
    rv: float
    timestamp: float
    logger_timestamp: float
    line: int


@dataclass
class CarmenLog:
    """Everything read from a log, in file order per message type."""

    path: Path
    lasers: list[LaserRecord] = field(default_factory=list)
    odometry: list[OdomRecord] = field(default_factory=list)
    params: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last laser scan."""
        if len(self.lasers) < 2:
            return 0.0
        return self.lasers[-1].timestamp - self.lasers[0].timestamp


def carmen_beam_angles(n: int, fov: float = math.pi, start: float | None = None) -> FloatArray:
    """FLASER beam angles (rad) for ``n`` beams."""
    if start is None:
        start = -0.5 * fov
    if abs(fov - math.pi) < 1e-9 and n in (180, 181):
        step = math.pi / 180.0
    elif abs(fov - math.pi) < 1e-9 and n in (360, 361):
        step = math.pi / 360.0
    else:
        step = fov / max(n - 1, 1)
    return start + step * np.arange(n, dtype=np.float64)


def _open_text(path: Path) -> io.TextIOBase:
    if path.suffix == ".gz":
        return io.TextIOWrapper(gzip.open(path, "rb"), encoding="utf-8", errors="replace")
    return open(path, encoding="utf-8", errors="replace")


def _floats(tokens: list[str], start: int, count: int) -> FloatArray:
    if start + count > len(tokens):
        raise ValueError(
            f"expected {count} numbers from field {start + 1}, line has {len(tokens)} fields"
        )
    return np.array([float(t) for t in tokens[start : start + count]], dtype=np.float64)


def _parse_flaser(tokens: list[str], line: int, range_max: float) -> LaserRecord:
    n = int(tokens[1])
    if n <= 0:
        raise ValueError(f"beam count {n} must be positive")
    ranges = _floats(tokens, 2, n)
    rest = _floats(tokens, 2 + n, 6)
    if len(tokens) < 2 + n + 6 + 1:
        raise ValueError("missing timestamp")
    ts = float(tokens[2 + n + 6])
    logger = float(tokens[2 + n + 8]) if len(tokens) > 2 + n + 8 else ts
    return LaserRecord(
        ranges, carmen_beam_angles(n), rest[:3], rest[3:], ts, logger, range_max, line, "FLASER"
    )


def _parse_robotlaser1(tokens: list[str], line: int) -> LaserRecord:
    head = _floats(tokens, 1, 7)
    start, fov, res, max_range = head[1], head[2], head[3], head[4]
    n = int(tokens[8])
    ranges = _floats(tokens, 9, n)
    k = 9 + n
    m = int(tokens[k])
    k += 1 + m
    poses = _floats(tokens, k, 6)
    k += 6 + 5
    if len(tokens) <= k:
        raise ValueError("missing timestamp")
    ts = float(tokens[k])
    logger = float(tokens[k + 2]) if len(tokens) > k + 2 else ts
    angles = start + res * np.arange(n, dtype=np.float64)
    del fov
    return LaserRecord(
        ranges, angles, poses[:3], poses[3:], ts, logger, float(max_range), line, "ROBOTLASER1"
    )


def _parse_odom(tokens: list[str], line: int) -> OdomRecord:
    v = _floats(tokens, 1, 7)
    logger = float(tokens[9]) if len(tokens) > 9 else v[6]
    return OdomRecord(v[:3], float(v[3]), float(v[4]), float(v[6]), logger, line)


def iter_carmen(
    path: str | os.PathLike[str], *, strict: bool = True, warnings: list[str] | None = None
) -> Iterator[LaserRecord | OdomRecord | tuple[str, str]]:
    """Yield records in file order (PARAM lines as ``(name, value)``)."""
    p = Path(path)
    range_max = DEFAULT_FLASER_RANGE_MAX
    try:
        handle = _open_text(p)
    except OSError as exc:
        raise CarmenFormatError(f"{p}: cannot open: {exc.strerror or exc}") from exc
    with handle:
        lineno = 0
        while True:
            try:
                raw = handle.readline()
            except (OSError, EOFError) as exc:
                raise CarmenFormatError(f"{p}:{lineno + 1}: cannot read: {exc}") from exc
            if not raw:
                break
            lineno += 1
            tokens = raw.split()
            if not tokens or tokens[0].startswith("#"):
                continue
            kind = tokens[0]
            try:
                if kind == "FLASER":
                    rec: LaserRecord | OdomRecord | tuple[str, str] = _parse_flaser(
                        tokens, lineno, range_max
                    )
                elif kind == "ROBOTLASER1":
                    rec = _parse_robotlaser1(tokens, lineno)
                elif kind == "ODOM":
                    rec = _parse_odom(tokens, lineno)
                elif kind == "PARAM":
                    if len(tokens) < 3:
                        raise ValueError("PARAM needs a name and a value")
                    rec = (tokens[1], tokens[2])
                    if tokens[1] in ("laser_front_laser_max_range", "robot_front_laser_max"):
                        range_max = float(tokens[2])
                else:
                    continue
                if isinstance(rec, (LaserRecord, OdomRecord)):
                    values = rec.ranges if isinstance(rec, LaserRecord) else rec.pose
                    if not np.all(np.isfinite(values)):
                        raise ValueError("non-finite value")
            except (ValueError, IndexError) as exc:
                message = f"{p}:{lineno}: bad {kind} line: {exc}"
                if strict:
                    raise CarmenFormatError(message) from exc
                if warnings is not None:
                    warnings.append(message)
                continue
            yield rec


def read_carmen(
    path: str | os.PathLike[str], *, strict: bool = True, max_lasers: int | None = None
) -> CarmenLog:
    """Read a whole CARMEN log (or its first ``max_lasers`` scans)."""
    log = CarmenLog(Path(path))
    for rec in iter_carmen(path, strict=strict, warnings=log.warnings):
        if isinstance(rec, LaserRecord):
            log.lasers.append(rec)
            if max_lasers is not None and len(log.lasers) >= max_lasers:
                break
        elif isinstance(rec, OdomRecord):
            log.odometry.append(rec)
        else:
            log.params[rec[0]] = rec[1]
    return log
