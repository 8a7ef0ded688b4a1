"""Robot footprints (``nav2_costmap_2d/footprint.cpp``): polygons in the robot frame (m)."""

from __future__ import annotations

import ast
import math

import numpy as np
import numpy.typing as npt

from eddiebot.nav.errors import ParameterError

Polygon = npt.NDArray[np.float64]


def make_footprint_from_radius(radius: float, points: int = 16) -> Polygon:
    """Regular 16-gon approximating a circular robot, as Nav2's ``makeFootprintFromRadius``."""
    angles = np.arange(points) * 2.0 * math.pi / points
    return np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)


def parse_footprint(text: str, server: str = "costmap") -> Polygon | None:
    """Parse Nav2's ``footprint`` string ``"[[x, y], ...]"``; "[]" or "" -> None."""
    t = text.strip()
    if t in ("", "[]"):
        return None
    try:
        value = ast.literal_eval(t)
        arr = np.asarray(value, dtype=np.float64)
    except (ValueError, SyntaxError) as exc:
        raise ParameterError(server, "footprint", text, f"not a list of points: {exc}") from exc
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise ParameterError(server, "footprint", text, "needs at least 3 [x, y] points")
    return arr


def pad_footprint(footprint: Polygon, padding: float) -> Polygon:
    """``padFootprint``: push every vertex away from the origin by ``padding`` per axis."""
    fp = np.asarray(footprint, dtype=np.float64).copy()
    fp[:, 0] += np.sign(fp[:, 0]) * padding
    fp[:, 1] += np.sign(fp[:, 1]) * padding
    return fp


def _point_segment_distance(px: float, py: float, a: Polygon, b: Polygon) -> float:
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom == 0.0 else max(0.0, min(1.0, float((np.array([px, py]) - a) @ ab) / denom))
    proj = a + t * ab
    return math.hypot(px - proj[0], py - proj[1])


def inscribed_and_circumscribed_radius(footprint: Polygon) -> tuple[float, float]:
    """(inscribed, circumscribed) radii about the robot origin (``calculateMinAndMaxDistances``)."""
    fp = np.asarray(footprint, dtype=np.float64)
    vd = np.hypot(fp[:, 0], fp[:, 1])
    min_d = float(vd.min())
    max_d = float(vd.max())
    n = fp.shape[0]
    for i in range(n):
        d = _point_segment_distance(0.0, 0.0, fp[i], fp[(i + 1) % n])
        min_d = min(min_d, d)
        max_d = max(max_d, d)
    return min_d, max_d


def transform_footprint(pose: npt.ArrayLike, footprint: Polygon) -> Polygon:
    """Footprint placed at ``pose`` (x, y, theta) in the global frame."""
    x, y, th = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
    c, s = math.cos(th), math.sin(th)
    fp = np.asarray(footprint, dtype=np.float64)
    out = np.empty_like(fp)
    out[:, 0] = x + c * fp[:, 0] - s * fp[:, 1]
    out[:, 1] = y + s * fp[:, 0] + c * fp[:, 1]
    return out


__all__ = [
    "inscribed_and_circumscribed_radius",
    "make_footprint_from_radius",
    "pad_footprint",
    "parse_footprint",
    "transform_footprint",
]
