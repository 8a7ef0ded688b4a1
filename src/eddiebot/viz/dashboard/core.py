"""Pure helpers of the dashboard: grid tiling, wire frames, command validation, rate limits,
image encoding.

Nothing here touches the bus, a clock or a socket: times are float seconds passed in.
"""

from __future__ import annotations

import json
import math
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.viz.dashboard.errors import CommandError, RateLimitedError

__all__ = [
    "EXPLORE_COMMANDS",
    "MAX_COMMAND_BYTES",
    "SLAM_COMMANDS",
    "VIEWS",
    "Command",
    "GridMeta",
    "TileCache",
    "TokenBucket",
    "binary_frame",
    "colorize_depth",
    "encode_jpeg",
    "image_to_bgr",
    "parse_command",
    "text_frame",
]

#: Largest command a browser may send (bytes); anything longer is refused.
MAX_COMMAND_BYTES = 4096
#: Largest teleop speeds accepted (m/s, rad/s); Eddie's own limits are lower.
MAX_LINEAR = 1.0
MAX_ANGULAR = 3.0


# -- wire frames ------------------------------------------------------------------------
def text_frame(kind: str, **fields: Any) -> str:
    """A JSON text frame ``{"t": kind, ...}``."""
    return json.dumps({"t": kind, **fields}, separators=(",", ":"), allow_nan=False)


def binary_frame(header: dict[str, Any], payload: bytes) -> bytes:
    """A binary frame: uint32 little-endian header length, JSON header, raw payload."""
    head = json.dumps(header, separators=(",", ":"), allow_nan=False).encode()
    return struct.pack("<I", len(head)) + head + payload


def split_binary_frame(frame: bytes) -> tuple[dict[str, Any], bytes]:
    """Inverse of :func:`binary_frame` (tests and benchmarks)."""
    (n,) = struct.unpack_from("<I", frame, 0)
    return json.loads(frame[4 : 4 + n]), frame[4 + n :]


# -- occupancy grids as tiles ----------------------------------------------------------
@dataclass(frozen=True)
class GridMeta:
    """Shape and placement of a grid (origin in the grid's own frame, m/rad)."""

    width: int
    height: int
    resolution: float
    origin: tuple[float, float, float]
    frame_id: str


@dataclass
class TileCache:
    """Splits a grid into ``tile`` × ``tile`` cell tiles and reports only the changed ones.

    A new shape, resolution or origin starts a new generation (every tile is new); within a
    generation a tile is re-sent only when the CRC of its cells changed.
    """

    tile: int = 64
    meta: GridMeta | None = None
    generation: int = 0
    _hashes: dict[tuple[int, int], int] = field(default_factory=dict)

    def update(
        self, meta: GridMeta, cells: npt.NDArray[np.int8]
    ) -> tuple[bool, list[tuple[int, int, int, int, bytes]]]:
        """(new generation?, changed tiles as (tx, ty, w, h, uint8 bytes)).

        Cells are nav_msgs/OccupancyGrid values (-1 unknown, 0..100); on the wire unknown is
        255. Tile (tx, ty) covers columns tx*tile.. and rows ty*tile.. (row 0 = lowest y).
        """
        if cells.shape != (meta.height, meta.width):
            raise ValueError(f"grid data {cells.shape} does not match {meta.height}x{meta.width}")
        new_gen = meta != self.meta
        if new_gen:
            self.meta = meta
            self.generation += 1
            self._hashes.clear()
        u8 = cells.view(np.uint8)  # -1 → 255 without a copy
        t = self.tile
        changed = []
        for ty in range(0, meta.height, t):
            for tx in range(0, meta.width, t):
                block = np.ascontiguousarray(u8[ty : ty + t, tx : tx + t])
                data = block.tobytes()
                h = zlib.crc32(data)
                key = (tx // t, ty // t)
                if self._hashes.get(key) != h:
                    self._hashes[key] = h
                    changed.append((key[0], key[1], block.shape[1], block.shape[0], data))
        return new_gen, changed


# -- commands from the browser -----------------------------------------------------------
@dataclass(frozen=True)
class Command:
    """A validated browser command: ``op`` and its numeric arguments."""

    op: str
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    linear: float = 0.0
    angular: float = 0.0
    engage: bool | None = None
    name: str = ""
    #: keepout: the rectangle's other corner (``x``, ``y`` the first), display frame, m
    x1: float = 0.0
    y1: float = 0.0
    #: keepout: clear every zone instead of painting one
    clear: bool = False
    #: slam: the action (`SLAM_COMMANDS`), the node a ``move`` drags, the session ``merge`` adds;
    #: explore: the action (`EXPLORE_COMMANDS`)
    action: str = ""
    node: int = -1
    path: str = ""


_OPS = {"goal", "initialpose", "teleop", "estop", "cancel", "save_map", "ping", "view", "keepout",
        "slam", "explore"}
#: the ``explore`` command's actions ("map this floor", pause, resume)
EXPLORE_COMMANDS = ("start", "pause", "resume")
#: the ``slam`` command's actions (2D SLAM graph editing, `eddiebot.viz.dashboard.slam_edit`)
SLAM_COMMANDS = ("interactive", "move", "close_loop", "clear", "merge")
#: views a connection opens on request (``{"op": "view", "name": ..., "engage": bool}``);
#: they change what the page receives, never the robot, so a read-only page may open them
VIEWS = ("tf", "cloud")


def _finite(obj: dict[str, Any], key: str) -> float:
    value = obj.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise CommandError(f"{obj.get('op')}: {key!r} must be a number")
    f = float(value)
    if not math.isfinite(f):
        raise CommandError(f"{obj.get('op')}: {key!r} must be finite, got {value!r}")
    return f


def parse_command(
    raw: str | bytes,
    map_bounds: tuple[float, float, float, float] | None = None,
) -> Command:
    """Validate one browser message; ``CommandError`` says what is wrong.

    ``map_bounds`` (xmin, ymin, xmax, ymax in the display frame, m): goals and initial
    poses outside it are refused.
    """
    if len(raw) > MAX_COMMAND_BYTES:
        raise CommandError(f"message of {len(raw)} bytes refused (limit {MAX_COMMAND_BYTES})")
    try:
        obj = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        raise CommandError(f"malformed message: {exc}") from None
    if not isinstance(obj, dict):
        raise CommandError("malformed message: expected a JSON object")
    op = obj.get("op")
    if op not in _OPS:
        raise CommandError(f"unknown command {op!r}")
    try:
        return _parse_op(str(op), obj, map_bounds)
    except CommandError as exc:
        exc.op = str(op)
        raise


def _parse_op(op: str, obj: dict[str, Any],
              map_bounds: tuple[float, float, float, float] | None) -> Command:
    if op in ("goal", "initialpose"):
        x, y, yaw = _finite(obj, "x"), _finite(obj, "y"), _finite(obj, "yaw")
        if map_bounds is not None:
            xmin, ymin, xmax, ymax = map_bounds
            if not (xmin <= x <= xmax and ymin <= y <= ymax):
                raise CommandError(
                    f"{op} ({x:.2f}, {y:.2f}) is outside the map "
                    f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}]")
        return Command(op, x=x, y=y, yaw=math.remainder(yaw, 2 * math.pi))
    if op == "teleop":
        lin, ang = _finite(obj, "linear"), _finite(obj, "angular")
        if abs(lin) > MAX_LINEAR or abs(ang) > MAX_ANGULAR:
            raise CommandError(
                f"teleop speed ({lin}, {ang}) beyond the limits ({MAX_LINEAR} m/s, {MAX_ANGULAR} rad/s)")
        return Command(op, linear=lin, angular=ang)
    if op == "estop":
        engage = obj.get("engage")
        if engage is not None and not isinstance(engage, bool):
            raise CommandError("estop: 'engage' must be true, false or absent (toggle)")
        return Command(op, engage=engage)
    if op == "save_map":
        name = obj.get("name", "")
        if not isinstance(name, str) or len(name) > 200 or "\x00" in name:
            raise CommandError("save_map: 'name' must be a short string")
        return Command(op, name=name)
    if op == "keepout":
        clear = obj.get("clear", False)
        if not isinstance(clear, bool):
            raise CommandError("keepout: 'clear' must be true or false")
        if clear:
            return Command(op, clear=True)
        x0, y0, x1, y1 = (_finite(obj, k) for k in ("x0", "y0", "x1", "y1"))
        if x0 == x1 or y0 == y1:
            raise CommandError("keepout: the rectangle has no area")
        if map_bounds is not None:
            xmin, ymin, xmax, ymax = map_bounds
            if max(x0, x1) < xmin or min(x0, x1) > xmax or max(y0, y1) < ymin or min(y0, y1) > ymax:
                raise CommandError(
                    f"keepout ({x0:.2f}, {y0:.2f})..({x1:.2f}, {y1:.2f}) is outside the map "
                    f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}]")
        return Command(op, x=x0, y=y0, x1=x1, y1=y1)
    if op == "slam":
        return _parse_slam(obj)
    if op == "explore":
        action = obj.get("action")
        if action not in EXPLORE_COMMANDS:
            raise CommandError(f"explore: 'action' must be one of {', '.join(EXPLORE_COMMANDS)}, "
                               f"got {action!r}")
        return Command(op, action=str(action))
    if op == "view":
        name, engage = obj.get("name"), obj.get("engage")
        if name not in VIEWS:
            raise CommandError(f"view: 'name' must be one of {', '.join(VIEWS)}, got {name!r}")
        if not isinstance(engage, bool):
            raise CommandError("view: 'engage' must be true or false")
        return Command(op, name=str(name), engage=engage)
    return Command(op)


def _parse_slam(obj: dict[str, Any]) -> Command:
    action = obj.get("action")
    if action not in SLAM_COMMANDS:
        raise CommandError(f"slam: 'action' must be one of {', '.join(SLAM_COMMANDS)}, got {action!r}")
    if action == "move":
        node = obj.get("node")
        if isinstance(node, bool) or not isinstance(node, int) or node < 0:
            raise CommandError(f"slam move: 'node' must be a node id (an integer ≥ 0), got {node!r}")
        x, y = _finite(obj, "x"), _finite(obj, "y")
        yaw = _finite(obj, "yaw") if "yaw" in obj else 0.0
        return Command("slam", action="move", node=node, x=x, y=y, yaw=math.remainder(yaw, 2 * math.pi))
    if action == "merge":
        path = obj.get("path")
        if not isinstance(path, str) or not path.strip() or len(path) > 1000 or "\x00" in path:
            raise CommandError("slam merge: 'path' must be the session file's path")
        return Command("slam", action="merge", path=path.strip())
    return Command("slam", action=str(action))


@dataclass
class TokenBucket:
    """``rate`` tokens per second up to ``burst``; times are float seconds passed in."""

    rate: float
    burst: float
    tokens: float = -1.0
    last: float | None = None

    def take(self, now: float, what: str = "command") -> None:
        """Spend a token or raise ``RateLimitedError``."""
        if self.tokens < 0:
            self.tokens = self.burst
        if self.last is not None:
            self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens < 1.0:
            raise RateLimitedError(f"{what} refused: more than {self.rate:g} per second")
        self.tokens -= 1.0


# -- images -------------------------------------------------------------------------------
def image_to_bgr(encoding: str, width: int, height: int, step: int,
                 data: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8] | None:
    """A BGR (or mono) uint8 array view of a sensor_msgs/Image; None for other encodings."""
    buf = np.asarray(data, dtype=np.uint8)
    if width <= 0 or height <= 0 or buf.size < step * height:
        return None
    rows = buf[: step * height].reshape(height, step)
    if encoding in ("rgb8", "bgr8"):
        img = rows[:, : width * 3].reshape(height, width, 3)
        return img[:, :, ::-1] if encoding == "rgb8" else img
    if encoding in ("rgba8", "bgra8"):
        img = rows[:, : width * 4].reshape(height, width, 4)[:, :, :3]
        return img[:, :, ::-1] if encoding == "rgba8" else img
    if encoding in ("mono8", "8UC1"):
        return rows[:, :width]
    return None


def depth_to_metres(encoding: str, width: int, height: int, step: int, data: npt.NDArray[np.uint8],
                    is_bigendian: int = 0) -> npt.NDArray[np.float32] | None:
    """Depth in metres (NaN where invalid) from a 16UC1 (mm) or 32FC1 (m) image."""
    buf = np.asarray(data, dtype=np.uint8)
    if width <= 0 or height <= 0 or buf.size < step * height:
        return None
    rows = buf[: step * height].reshape(height, step)
    order = ">" if is_bigendian else "<"
    if encoding in ("16UC1", "mono16"):
        mm = np.ascontiguousarray(rows[:, : width * 2]).view(f"{order}u2").astype(np.float32)
        mm[mm == 0] = np.nan
        mm *= 0.001
        return mm
    if encoding == "32FC1":
        m = rows[:, : width * 4].copy().view(f"{order}f4").astype(np.float32)
        m[~np.isfinite(m) | (m <= 0)] = np.nan
        return m
    return None


def colorize_depth(depth_m: npt.NDArray[np.float32], near: float = 0.4,
                   far: float = 5.0) -> npt.NDArray[np.uint8]:
    """A BGR colour image of depth (turbo colour map near → far, black where invalid)."""
    import cv2

    valid = np.isfinite(depth_m)
    scaled = np.nan_to_num((depth_m - near) * (255.0 / (far - near)), nan=0.0)
    np.clip(scaled, 0.0, 255.0, out=scaled)
    out = cv2.applyColorMap(scaled.astype(np.uint8), cv2.COLORMAP_TURBO)
    out[~valid] = 0
    return np.asarray(out, dtype=np.uint8)


def encode_jpeg(img: npt.NDArray[np.uint8], max_width: int = 320, quality: int = 70) -> bytes:
    """JPEG bytes of ``img`` shrunk to at most ``max_width`` pixels wide."""
    import cv2

    stride = img.shape[1] // max_width
    if stride >= 2:  # cheap decimation first, then area averaging for the rest
        img = np.ascontiguousarray(img[::stride, ::stride])
    h, w = img.shape[:2]
    out: Any = img
    if w > max_width:
        size = (max_width, max(1, round(h * max_width / w)))
        out = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return bytes(buf.tobytes())
