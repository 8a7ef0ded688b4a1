"""TUM trajectory files: one ``t x y z qx qy qz qw`` line per pose (evo's ``tum`` format)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import numpy as np
import numpy.typing as npt

from eddiebot.core.files import created_file_mode

__all__ = ["read_tum", "write_tum"]

FloatArray = npt.NDArray[np.float64]


def write_tum(path: str | os.PathLike[str], stamps_s: npt.ArrayLike, poses: npt.ArrayLike) -> None:
    """Write SE(2) poses (N, 3) with timestamps (N,) in seconds, atomically."""
    t = np.asarray(stamps_s, dtype=np.float64).reshape(-1)
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if t.size != p.shape[0]:
        raise ValueError(f"{t.size} timestamps for {p.shape[0]} poses")
    half = 0.5 * p[:, 2]
    lines = [
        f"{ti:.6f} {x:.6f} {y:.6f} 0 0 0 {np.sin(h):.9f} {np.cos(h):.9f}\n"
        for ti, x, y, h in zip(t, p[:, 0], p[:, 1], half)
    ]
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.writelines(lines)
            os.fchmod(handle.fileno(), created_file_mode())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def read_tum(path: str | os.PathLike[str]) -> tuple[FloatArray, FloatArray]:
    """(stamps (N,), SE(2) poses (N, 3)) from a TUM file (yaw from the quaternion)."""
    data = np.loadtxt(path, comments="#", ndmin=2)
    if data.shape[1] != 8:
        raise ValueError(f"{path}: expected 8 columns (t x y z qx qy qz qw), got {data.shape[1]}")
    qx, qy, qz, qw = data[:, 4], data[:, 5], data[:, 6], data[:, 7]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return data[:, 0], np.stack([data[:, 1], data[:, 2], yaw], axis=-1)
