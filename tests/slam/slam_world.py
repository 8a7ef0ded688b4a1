"""Synthetic worlds for SLAM tests: polygons ray-cast into laser scans."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

FloatArray = npt.NDArray[np.float64]


def _box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


#: A 12 m × 8 m room with an inner wall stub and two boxes (segments x0, y0, x1, y1).
ROOM = np.array(
    [
        *_box(0.0, 0.0, 12.0, 8.0),
        (6.0, 0.0, 6.0, 3.0),
        *_box(2.0, 5.0, 3.0, 6.0),
        *_box(9.0, 2.0, 9.6, 2.4),
        (3.0, 2.0, 4.5, 2.6),
    ],
    dtype=np.float64,
)

#: A 30 m × 2 m corridor without features.
CORRIDOR = np.array(_box(0.0, 0.0, 30.0, 2.0), dtype=np.float64)


def raycast(
    segments: FloatArray, pose: FloatArray, angles: FloatArray, max_range: float = 30.0
) -> FloatArray:
    """Ranges from ``pose`` (x, y, theta) along beam ``angles``; inf where nothing is hit."""
    x, y, th = pose
    d = np.stack([np.cos(th + angles), np.sin(th + angles)], axis=-1)  # (B, 2)
    p = segments[:, :2]
    e = segments[:, 2:] - segments[:, :2]  # (S, 2)
    # solve x + t d = p + u e
    denom = d[:, None, 0] * (-e[None, :, 1]) - d[:, None, 1] * (-e[None, :, 0])
    rx = p[None, :, 0] - x
    ry = p[None, :, 1] - y
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (rx * (-e[None, :, 1]) - ry * (-e[None, :, 0])) / denom
        u = (d[:, None, 0] * ry - d[:, None, 1] * rx) / denom
    ok = (np.abs(denom) > 1e-12) & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
    t = np.where(ok, t, np.inf)
    r = t.min(axis=1)
    r[r > max_range] = np.inf
    return r


def dataset(*parts: str) -> Path:
    """Path to a file in the shared datasets (skips the test when absent)."""
    root = Path(
        os.environ.get(
            "EDDIE_DATASETS", Path(__file__).resolve().parents[3] / "shared" / "datasets"
        )
    )
    path = root.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"dataset {path} not available")
    return path


def loop_path(step: float = 0.25) -> FloatArray:
    """Poses (N, 3) driving once around a rectangle inside `ROOM` and back to the start."""
    corners = np.array([[1.5, 4.0], [10.5, 4.0], [10.5, 6.8], [1.5, 6.8], [1.5, 4.0]])
    poses = []
    for a, b in zip(corners[:-1], corners[1:]):
        n = round(np.hypot(*(b - a)) / step)
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        for k in range(n):
            p = a + (b - a) * k / n
            poses.append([p[0], p[1], heading])
    poses.append([*corners[-1], poses[-1][2]])
    return np.array(poses)


def drifting_odometry(truth: FloatArray, seed: int = 0, heading_bias: float = 0.01) -> FloatArray:
    """Odometry poses: the true increments with a heading bias per step and noise."""
    from eddiebot.geometry import se2_between, se2_compose

    rng = np.random.default_rng(seed)
    odom = [truth[0].copy()]
    for k in range(1, len(truth)):
        z = se2_between(truth[k - 1], truth[k])
        z = z + np.array(
            [rng.normal(0, 0.01), rng.normal(0, 0.01), heading_bias + rng.normal(0, 0.005)]
        )
        odom.append(se2_compose(odom[-1], z))
    return np.array(odom)


SCAN_ANGLES = np.linspace(-math.pi, math.pi, 360, endpoint=False)
