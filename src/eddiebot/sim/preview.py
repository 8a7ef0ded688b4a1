"""Top-down PNG previews of worlds: prisms filled with their texture's mean colour, outlined
darker the taller they are; low obstacles (below the scan plane) hatched grey; people's paths
dotted; the start pose as an arrow. Image row 0 is the highest y (north up)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from eddiebot.sim.ground_truth import SCAN_HEIGHT
from eddiebot.sim.textures import texture
from eddiebot.sim.world import ROBOT_RADIUS, World

__all__ = ["top_view"]


def top_view(world: World, px_per_m: float = 20.0, margin: float = 0.5) -> npt.NDArray[np.uint8]:
    """(H, W, 3) RGB uint8 top view of ``world``."""
    xmin, ymin, xmax, ymax = world.bounds
    xmin, ymin, xmax, ymax = xmin - margin, ymin - margin, xmax + margin, ymax + margin
    w = math.ceil((xmax - xmin) * px_per_m)
    h = math.ceil((ymax - ymin) * px_per_m)
    img = np.full((h, w, 3), 245, np.uint8)
    floor = texture(world.floor_texture).reshape(-1, 3).mean(axis=0)
    img[:] = (0.5 * floor + 0.5 * 245).astype(np.uint8)

    def px(x: float, y: float) -> tuple[int, int]:
        return round((x - xmin) * px_per_m), round((ymax - y) * px_per_m)

    for p in sorted(world.prisms, key=lambda q: q.top):
        col = tuple(int(c) for c in texture(p.texture).reshape(-1, 3).mean(axis=0))
        edge = tuple(int(c * 0.5) for c in col)
        low = p.top < SCAN_HEIGHT or p.bottom > SCAN_HEIGHT
        if p.circle is not None:
            cx, cy, r = p.circle
            c = px(cx, cy)
            rad = max(1, round(r * px_per_m))
            cv2.circle(img, c, rad, col, -1, lineType=cv2.LINE_AA)
            cv2.circle(img, c, rad, edge, 1, lineType=cv2.LINE_AA)
        elif p.quad is not None:
            pts = np.array([px(x, y) for x, y in p.quad], np.int32)
            cv2.fillPoly(img, [pts], col, lineType=cv2.LINE_AA)
            cv2.polylines(img, [pts], True, edge, 1, lineType=cv2.LINE_AA)
            if low:  # not in the scan: mark with a diagonal
                cv2.line(img, tuple(pts[0]), tuple(pts[2]), (120, 120, 120), 1, cv2.LINE_AA)
    for person in world.people:
        path = [px(x, y) for x, y in person.path + ((person.path[0],) if person.loop else ())]
        for a, b in zip(path[:-1], path[1:]):
            n = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / 6))
            for t in np.linspace(0, 1, n):
                cv2.circle(img, (int(a[0] + t * (b[0] - a[0])), int(a[1] + t * (b[1] - a[1]))),
                           1, (200, 40, 40), -1)
        cv2.circle(img, path[0], max(2, int(person.radius * px_per_m)), (200, 40, 40), 2)
    sx, sy, sth = world.start
    c = px(sx, sy)
    cv2.circle(img, c, max(2, int(ROBOT_RADIUS * px_per_m)), (20, 120, 20), 2, cv2.LINE_AA)
    tip = px(sx + 0.5 * math.cos(sth), sy + 0.5 * math.sin(sth))
    cv2.arrowedLine(img, c, tip, (20, 120, 20), 2, cv2.LINE_AA, tipLength=0.3)
    return img
