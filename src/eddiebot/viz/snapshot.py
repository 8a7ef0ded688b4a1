"""PNG snapshots: a map with trajectories, planned paths, a laser scan and the robot.

``render_map`` draws an ``OccupancyMap`` (free white, occupied black, unknown grey, as the
nav2 map files) and, on top, trajectories (arrays of x, y[, yaw] in the map frame, m/rad, or
TUM files), planned paths, a laser scan at a pose, the robot footprint (a circle of radius
0.2245 m with its heading), a scale bar and a legend. ``render_bag`` builds the same picture
from a rosbag2 at a given time: ``/map``, the trajectory from ``/odom`` (put in the map frame
with the ``map → odom`` transform on ``/tf`` when there is one), ``/ground_truth/odom``,
``/plan`` and ``/scan``. Drawing uses OpenCV; images are BGR ``uint8`` arrays.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from eddiebot.geometry import quaternion_to_yaw, se2_compose
from eddiebot.maps import OccupancyMap, load_map, map_from_msg

__all__ = [
    "FREE_BGR",
    "OCCUPIED_BGR",
    "ROBOT_RADIUS",
    "UNKNOWN_BGR",
    "Overlay",
    "Snapshot",
    "read_tum",
    "render_bag",
    "render_map",
    "render_trajectories",
]

#: Eddie's footprint radius, m.
ROBOT_RADIUS = 0.2245
#: Cell colours (BGR), as nav2's map_saver writes them: free 254, occupied 0, unknown 205.
FREE_BGR = (254, 254, 254)
OCCUPIED_BGR = (0, 0, 0)
UNKNOWN_BGR = (205, 205, 205)
_BACKGROUND = (245, 245, 245)
#: matplotlib's tab10, BGR.
_PALETTE = [
    (180, 119, 31), (14, 127, 255), (44, 160, 44), (40, 39, 214), (189, 103, 148),
    (75, 86, 140), (194, 119, 227), (127, 127, 127), (34, 189, 188), (207, 190, 23),
]
_PATH_COLOR = (0, 170, 0)
_SCAN_COLOR = (0, 0, 230)
_ROBOT_COLOR = (160, 60, 0)
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_SHIFT = 4  # sub-pixel bits for cv2 drawing
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Overlay:
    """A polyline in the map frame: ``points`` (N, 2+) x, y[, yaw] in m/rad."""

    points: FloatArray
    label: str = ""
    color: tuple[int, int, int] | None = None  # BGR
    thickness: int = 2


@dataclass(frozen=True)
class Snapshot:
    """A rendered picture and the transform from the map frame to its pixels."""

    image: npt.NDArray[np.uint8]
    grid: OccupancyMap
    pixels_per_cell: int
    margin: int
    legend: tuple[tuple[str, tuple[int, int, int]], ...] = field(default=())

    def world_to_pixel(self, points: npt.ArrayLike) -> FloatArray:
        """Pixel coordinates (column, row), continuous, of map-frame points (..., 2), m.

        Pixel (c, r) covers [c, c + 1) × [r, r + 1); row 0 is the top (highest y).
        """
        pts = np.asarray(points, dtype=float)
        g = self.grid
        c, s = math.cos(g.origin[2]), math.sin(g.origin[2])
        dx = pts[..., 0] - g.origin[0]
        dy = pts[..., 1] - g.origin[1]
        u = (c * dx + s * dy) / g.resolution
        v = (-s * dx + c * dy) / g.resolution
        k = self.pixels_per_cell
        return np.stack([self.margin + u * k, self.margin + (g.height - v) * k], axis=-1)

    def pixel(self, x: float, y: float) -> tuple[int, int, int]:
        """The BGR colour of the pixel under map-frame point (x, y)."""
        col, row = self.world_to_pixel([x, y])
        b, g, r = self.image[int(row), int(col)]
        return int(b), int(g), int(r)

    def save(self, path: str | Path) -> Path:
        """Write the PNG (atomically: temporary file, then rename)."""
        return _write_png(self.image, Path(path))


def _write_png(image: npt.NDArray[np.uint8], path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - OpenCV failure
        raise OSError(f"cannot encode PNG for {path}")
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(buf.tobytes())
    tmp.replace(path)
    return path


# --------------------------------------------------------------------------------------
# inputs
# --------------------------------------------------------------------------------------
def read_tum(path: str | Path) -> FloatArray:
    """A TUM trajectory file (``t x y z qx qy qz qw`` per line) as (N, 8) floats."""
    rows = []
    for line in Path(path).read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        values = [float(v) for v in line.replace(",", " ").split()]
        if len(values) != 8:
            raise ValueError(f"{path}: TUM lines have 8 numbers, got {len(values)}: {line!r}")
        rows.append(values)
    return np.asarray(rows, dtype=float).reshape(-1, 8)


def _tum_to_poses(tum: FloatArray) -> FloatArray:
    yaw = [quaternion_to_yaw(*q) for q in tum[:, 4:8]]
    return np.column_stack([tum[:, 1], tum[:, 2], yaw]) if len(tum) else np.zeros((0, 3))


def _points(value: Any) -> FloatArray:
    """(N, 2+) map-frame points from an array, a TUM file or a nav_msgs/Path."""
    if isinstance(value, (str, Path)):
        return _tum_to_poses(read_tum(value))
    if getattr(value, "__msgtype__", "") == "nav_msgs/msg/Path":
        return np.array(
            [[p.pose.position.x, p.pose.position.y,
              quaternion_to_yaw(p.pose.orientation.x, p.pose.orientation.y,
                                p.pose.orientation.z, p.pose.orientation.w)]
             for p in value.poses],
            dtype=float,
        ).reshape(-1, 3)
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise ValueError(f"a trajectory needs shape (N, 2+), got {arr.shape}")
    return arr


def _overlays(items: Any, palette: Sequence[tuple[int, int, int]], thickness: int) -> list[Overlay]:
    """Normalise the accepted forms: Overlay, array, TUM path, nav_msgs/Path, (label, x),
    a mapping label → x, or a sequence of those."""
    if items is None:
        return []
    if isinstance(items, Mapping):
        seq: list[Any] = [(k, v) for k, v in items.items()]
    elif isinstance(items, (Overlay, str, Path, np.ndarray)) or hasattr(items, "__msgtype__"):
        seq = [items]
    else:
        seq = list(items)
    out: list[Overlay] = []
    for i, item in enumerate(seq):
        color = palette[i % len(palette)]
        if isinstance(item, Overlay):
            out.append(item if item.color is not None else Overlay(item.points, item.label, color,
                                                                   item.thickness))
        elif isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str):
            out.append(Overlay(_points(item[1]), item[0], color, thickness))
        else:
            label = Path(item).stem if isinstance(item, (str, Path)) else ""
            out.append(Overlay(_points(item), label, color, thickness))
    return out


def _scan_points(scan: Any, pose: Sequence[float] | None) -> FloatArray:
    """Map-frame end points (N, 2) of a LaserScan taken at ``pose`` (or an (N, 2) array)."""
    if not hasattr(scan, "ranges"):
        return np.asarray(scan, dtype=float).reshape(-1, 2)
    if pose is None:
        raise ValueError("drawing a LaserScan needs the pose it was taken at (scan_pose)")
    r = np.asarray(scan.ranges, dtype=float)
    angles = scan.angle_min + scan.angle_increment * np.arange(len(r))
    valid = np.isfinite(r) & (r >= scan.range_min)
    if scan.range_max > 0:
        valid &= r <= scan.range_max
    local = np.column_stack([r * np.cos(angles), r * np.sin(angles)])[valid]
    x, y, th = (float(v) for v in pose[:3])
    c, s = math.cos(th), math.sin(th)
    return np.column_stack([x + c * local[:, 0] - s * local[:, 1],
                            y + s * local[:, 0] + c * local[:, 1]])


# --------------------------------------------------------------------------------------
# drawing
# --------------------------------------------------------------------------------------
def _map_image(grid: OccupancyMap) -> npt.NDArray[np.uint8]:
    data = grid.data.astype(np.int16)
    grey = np.where(data < 0, UNKNOWN_BGR[0],
                    np.round(254 - np.clip(data, 0, 100) * 254 / 100)).astype(np.uint8)
    return np.repeat(np.flipud(grey)[:, :, None], 3, axis=2)


def _cv_points(snap: Snapshot, xy: FloatArray) -> npt.NDArray[np.int32]:
    px = snap.world_to_pixel(xy[:, :2]) - 0.5  # cv2 puts pixel centres on integers
    return np.round(px * (1 << _SHIFT)).astype(np.int32)


def _nice_length(target_m: float) -> float:
    if target_m <= 0:
        return 1.0
    exp = math.floor(math.log10(target_m))
    for m in (5, 2, 1):
        if m * 10**exp <= target_m:
            return float(m * 10**exp)
    return float(10**exp)


def _draw_scale_bar(img: npt.NDArray[np.uint8], snap: Snapshot) -> None:
    k = snap.pixels_per_cell / snap.grid.resolution  # pixels per metre
    h, w = img.shape[:2]
    length_m = _nice_length(0.2 * w / k)
    length_px = round(length_m * k)
    label = f"{length_m:g} m"
    (tw, th), _ = cv2.getTextSize(label, _FONT, 0.45, 1)
    x0, y0 = 10, h - 12
    cv2.rectangle(img, (x0 - 6, y0 - th - 14), (x0 + max(length_px, tw) + 6, y0 + 6),
                  (255, 255, 255), -1)
    cv2.line(img, (x0, y0), (x0 + length_px, y0), (0, 0, 0), 2)
    for x in (x0, x0 + length_px):
        cv2.line(img, (x, y0 - 4), (x, y0 + 4), (0, 0, 0), 2)
    cv2.putText(img, label, (x0, y0 - 8), _FONT, 0.45, (0, 0, 0), 1, cv2.LINE_AA)


def _draw_legend(img: npt.NDArray[np.uint8], entries: Sequence[tuple[str, tuple[int, int, int]]],
                 title: str | None) -> None:
    rows = [(t, c) for t, c in entries if t]
    if not rows and not title:
        return
    scale, pad, line_h, swatch = 0.45, 6, 18, 22
    widths = [cv2.getTextSize(t, _FONT, scale, 1)[0][0] for t, _ in rows]
    tw = cv2.getTextSize(title, _FONT, 0.5, 1)[0][0] if title else 0
    box_w = max([w + swatch + 3 * pad for w in widths] + [tw + 2 * pad])
    box_h = pad + (line_h if title else 0) + line_h * len(rows) + pad // 2
    w = img.shape[1]
    x0, y0 = w - box_w - 8, 8
    overlay = img.copy()
    cv2.rectangle(overlay, (x0, y0), (x0 + box_w, y0 + box_h), (255, 255, 255), -1)
    cv2.addWeighted(overlay, 0.85, img, 0.15, 0, dst=img)
    cv2.rectangle(img, (x0, y0), (x0 + box_w, y0 + box_h), (120, 120, 120), 1)
    y = y0 + pad + 11
    if title:
        cv2.putText(img, title, (x0 + pad, y), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        y += line_h
    for (text, color), _ in zip(rows, widths):
        cv2.line(img, (x0 + pad, y - 4), (x0 + pad + swatch, y - 4), color, 3, cv2.LINE_AA)
        cv2.putText(img, text, (x0 + 2 * pad + swatch, y), _FONT, scale, (0, 0, 0), 1,
                    cv2.LINE_AA)
        y += line_h


def _draw_robot(img: npt.NDArray[np.uint8], snap: Snapshot, pose: Sequence[float],
                radius: float) -> None:
    x, y, th = (float(v) for v in pose[:3])
    center = _cv_points(snap, np.array([[x, y]]))[0]
    r_px = round(radius / snap.grid.resolution * snap.pixels_per_cell * (1 << _SHIFT))
    tip = _cv_points(snap, np.array([[x + radius * math.cos(th), y + radius * math.sin(th)]]))[0]
    overlay = img.copy()
    cv2.circle(overlay, tuple(int(v) for v in center), r_px, _ROBOT_COLOR, -1, cv2.LINE_AA, _SHIFT)
    cv2.addWeighted(overlay, 0.35, img, 0.65, 0, dst=img)
    cv2.circle(img, tuple(int(v) for v in center), r_px, _ROBOT_COLOR, 2, cv2.LINE_AA, _SHIFT)
    cv2.line(img, tuple(int(v) for v in center), tuple(int(v) for v in tip), _ROBOT_COLOR, 2,
             cv2.LINE_AA, _SHIFT)


def render_map(
    grid: OccupancyMap,
    *,
    trajectories: Any = None,
    paths: Any = None,
    scan: Any = None,
    scan_pose: Sequence[float] | None = None,
    robot_pose: Sequence[float] | None = None,
    robot_radius: float = ROBOT_RADIUS,
    markers: Any = None,
    out_path: str | Path | None = None,
    title: str | None = None,
    pixels_per_cell: int | None = None,
    min_size: int = 600,
    max_size: int = 4000,
    margin: int = 10,
    scale_bar: bool = True,
    legend: bool = True,
) -> Snapshot:
    """Draw ``grid`` with overlays; write a PNG to ``out_path`` if given.

    ``trajectories`` and ``paths``: an (N, 2+) array of x, y[, yaw] (map frame, m/rad), a
    TUM file, a ``nav_msgs/Path``, an ``Overlay``, a ``(label, value)`` pair, a mapping
    label → value, or a sequence of those (colours from a palette in order).
    ``scan``: a ``sensor_msgs/LaserScan`` taken at ``scan_pose`` (default ``robot_pose``),
    or (N, 2) map-frame points. ``robot_pose``: (x, y, yaw) drawn as the footprint with
    its heading. ``markers``: points drawn as crosses (same forms as ``trajectories``, e.g.
    ``{"goal reached": array, "goal missed": array}``). ``pixels_per_cell`` defaults to the smallest integer making the longer
    side at least ``min_size`` pixels (capped by ``max_size``).
    """
    h, w = grid.height, grid.width
    if pixels_per_cell is None:
        pixels_per_cell = max(1, math.ceil(min_size / max(h, w, 1)))
        pixels_per_cell = max(1, min(pixels_per_cell, max_size // max(h, w, 1)))
    k = pixels_per_cell
    base = np.repeat(np.repeat(_map_image(grid), k, axis=0), k, axis=1)
    img = np.full((base.shape[0] + 2 * margin, base.shape[1] + 2 * margin, 3), _BACKGROUND,
                  np.uint8)
    img[margin:margin + base.shape[0], margin:margin + base.shape[1]] = base
    snap = Snapshot(img, grid, pixels_per_cell, margin)
    entries: list[tuple[str, tuple[int, int, int]]] = []

    for ov in _overlays(trajectories, _PALETTE, 2):
        color = ov.color or _PALETTE[0]
        if len(ov.points) >= 2:
            cv2.polylines(img, [_cv_points(snap, ov.points)], False, color, ov.thickness,
                          cv2.LINE_AA, _SHIFT)
        if len(ov.points):
            start = _cv_points(snap, ov.points[:1])[0]
            cv2.circle(img, tuple(int(v) for v in start), 4 << _SHIFT, color, -1, cv2.LINE_AA,
                       _SHIFT)
        entries.append((ov.label, color))
    for ov in _overlays(paths, [_PATH_COLOR, *_PALETTE[3:]], 3):
        color = ov.color or _PATH_COLOR
        if len(ov.points) >= 2:
            cv2.polylines(img, [_cv_points(snap, ov.points)], False, color, ov.thickness,
                          cv2.LINE_AA, _SHIFT)
        entries.append((ov.label or "planned path", color))
    if scan is not None:
        pts = _scan_points(scan, scan_pose if scan_pose is not None else robot_pose)
        radius = max(1, pixels_per_cell // 3)
        for p in snap.world_to_pixel(pts):
            cv2.circle(img, (int(p[0]), int(p[1])), radius, _SCAN_COLOR, -1)
        entries.append(("scan", _SCAN_COLOR))
    if robot_pose is not None:
        _draw_robot(img, snap, robot_pose, robot_radius)
        entries.append(("robot", _ROBOT_COLOR))
    for ov in _overlays(markers, _PALETTE[2:], 2):
        color = ov.color or _PALETTE[2]
        size = max(6, 2 * pixels_per_cell)
        for p in snap.world_to_pixel(ov.points[:, :2]) if len(ov.points) else []:
            x, y = int(p[0]), int(p[1])
            cv2.line(img, (x - size, y - size), (x + size, y + size), color, 3, cv2.LINE_AA)
            cv2.line(img, (x - size, y + size), (x + size, y - size), color, 3, cv2.LINE_AA)
        entries.append((ov.label, color))
    if scale_bar:
        _draw_scale_bar(img, snap)
    if legend:
        _draw_legend(img, entries, title)
    snap = Snapshot(img, grid, pixels_per_cell, margin, tuple(entries))
    if out_path is not None:
        snap.save(out_path)
    return snap


def _extent_map(points: Iterable[FloatArray], resolution: float | None = None,
                pad_m: float = 1.0) -> OccupancyMap:
    """A blank (free) canvas covering ``points`` with ``pad_m`` around them."""
    arrays = [p[:, :2] for p in points if len(p)]
    allp = np.vstack(arrays) if arrays else np.zeros((1, 2))
    lo = allp.min(axis=0) - pad_m
    hi = allp.max(axis=0) + pad_m
    span = float(max(hi - lo))
    res = resolution or max(span / 800.0, 0.01)
    shape = (math.ceil(float(hi[1] - lo[1]) / res), math.ceil(float(hi[0] - lo[0]) / res))
    return OccupancyMap(np.zeros(shape, np.int8), res, (float(lo[0]), float(lo[1]), 0.0))


def render_trajectories(trajectories: Any, *, out_path: str | Path | None = None,
                        **kwargs: Any) -> Snapshot:
    """Trajectories alone, on a blank canvas sized to fit them (grid lines omitted)."""
    overlays = _overlays(trajectories, _PALETTE, 2)
    grid = _extent_map([o.points for o in overlays])
    return render_map(grid, trajectories=overlays, out_path=out_path, **kwargs)


# --------------------------------------------------------------------------------------
# bags
# --------------------------------------------------------------------------------------
def _strip(frame: str) -> str:
    return frame.lstrip("/")


def _tf_pose(tf: Any) -> FloatArray:
    t, q = tf.transform.translation, tf.transform.rotation
    return np.array([t.x, t.y, quaternion_to_yaw(q.x, q.y, q.z, q.w)])


def _odom_pose(msg: Any) -> FloatArray:
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    return np.array([p.x, p.y, quaternion_to_yaw(q.x, q.y, q.z, q.w)])


def _latest_before(times: Sequence[int], values: Sequence[Any], t: int) -> Any:
    """The value at the last time ≤ t (the first value if none is earlier)."""
    idx = int(np.searchsorted(np.asarray(times), t, side="right")) - 1
    return values[max(idx, 0)]


def render_bag(
    bag: str | Path,
    *,
    at: float | None = None,
    out_path: str | Path | None = None,
    trajectories: Any = None,
    map_topic: str = "/map",
    odom_topic: str = "/odom",
    scan_topic: str = "/scan",
    plan_topic: str = "/plan",
    ground_truth_topic: str = "/ground_truth/odom",
    title: str | None = None,
    **kwargs: Any,
) -> Snapshot:
    """The state recorded in ``bag`` at ``at`` seconds after its start (default: the end).

    The map is the last ``/map`` up to then; the trajectory is ``/odom`` so far (or the
    ``odom → base_footprint`` transforms on ``/tf`` when ``/odom`` was not recorded), in the
    map frame through the ``map → odom`` transforms on ``/tf`` when present (else in the odom
    frame); the robot is drawn at its last pose with the last ``/scan``; ``/plan`` and
    ``/ground_truth/odom`` are added when recorded. Extra ``trajectories`` (TUM files,
    arrays) are drawn as given. A damaged bag is drawn up to the damage.
    """
    from eddiebot.bag import BagReader

    wanted = [map_topic, odom_topic, scan_topic, plan_topic, ground_truth_topic, "/tf"]
    grid_msg = None
    scan_msg = None
    plan_msg = None
    odom_t: list[int] = []
    odom_p: list[FloatArray] = []
    gt: list[FloatArray] = []
    tf_t: list[int] = []
    tf_p: list[FloatArray] = []
    base_t: list[int] = []
    base_p: list[FloatArray] = []
    start: int | None = None
    with BagReader(bag) as reader:
        for m in reader.messages(wanted):
            if start is None:
                start = m.timestamp
            if at is not None and m.timestamp > start + round(at * 1e9):
                break
            if m.topic == map_topic:
                grid_msg = m
            elif m.topic == scan_topic:
                scan_msg = m
            elif m.topic == plan_topic:
                plan_msg = m
            elif m.topic == odom_topic:
                odom_t.append(m.timestamp)
                odom_p.append(_odom_pose(m.decode()))
            elif m.topic == ground_truth_topic:
                gt.append(_odom_pose(m.decode()))
            elif m.topic == "/tf":
                for tf in m.decode().transforms:
                    pair = (_strip(tf.header.frame_id), _strip(tf.child_frame_id))
                    if pair == ("map", "odom"):
                        tf_t.append(m.timestamp)
                        tf_p.append(_tf_pose(tf))
                    elif pair in (("odom", "base_footprint"), ("odom", "base_link")):
                        base_t.append(m.timestamp)
                        base_p.append(_tf_pose(tf))
        problems = list(reader.problems)
    if not odom_p and base_p:  # no /odom recorded: the odometry is in TF
        odom_t, odom_p = base_t, base_p
    traj = np.array(odom_p).reshape(-1, 3)
    label = "odometry"
    if len(traj) and tf_p:
        corr = np.array([_latest_before(tf_t, tf_p, t) for t in odom_t])
        traj = se2_compose(corr, traj)
        label = "trajectory (map)"
    overlays: list[Any] = []
    if len(traj):
        overlays.append((label, traj))
    if gt:
        overlays.append(("ground truth", np.array(gt)))
    overlays.extend(_overlays(trajectories, _PALETTE[len(overlays):] or _PALETTE, 2))
    overlays = _overlays(overlays, _PALETTE, 2)
    if grid_msg is not None:
        grid = map_from_msg(grid_msg.decode())
    else:
        grid = _extent_map([o.points for o in overlays])
    robot = traj[-1] if len(traj) else None
    scan = scan_msg.decode() if scan_msg is not None and robot is not None else None
    path = plan_msg.decode() if plan_msg is not None else None
    if title is None:
        when = f"t = {at:.1f} s" if at is not None else "end"
        title = f"{Path(bag).name} @ {when}" + (" (damaged bag: prefix)" if problems else "")
    return render_map(grid, trajectories=overlays, paths=path, scan=scan, robot_pose=robot,
                      out_path=out_path, title=title, **kwargs)


def render_file(path: str | Path, **kwargs: Any) -> Snapshot:
    """Render a map YAML, a bag or a TUM trajectory file, by what ``path`` is."""
    p = Path(path)
    if p.suffix in (".yaml", ".yml"):
        return render_map(load_map(p), **kwargs)
    if p.is_dir() or p.suffix in (".mcap", ".db3"):
        return render_bag(p, **kwargs)
    extra = kwargs.pop("trajectories", None)
    items = [p] + (list(extra) if extra else [])
    return render_trajectories(items, **kwargs)
