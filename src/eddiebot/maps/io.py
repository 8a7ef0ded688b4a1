"""nav2 map_server files: ``.yaml`` metadata + ``.pgm``/``.png`` image, read and written.

Pixel rules follow ``nav2_map_server/src/map_io.cpp``:

* load: ``shade`` = mean of the colour channels / 255 (trinary mode also averages in
  ``255 - alpha`` when the image has alpha); ``occ = shade if negate else 1 - shade``.
  trinary: ``occ > occupied_thresh`` → 100, ``occ < free_thresh`` → 0, else -1.
  scale: transparent → -1, then as trinary but in-between values become
  ``rint((occ - free) / (occupied - free) * 100)``.
  raw: ``round(shade * 255)`` if in 0..100, else -1.
* save: trinary: unknown → 205, ``cell <= rint(free*100)`` → 254,
  ``cell >= rint(occupied*100)`` → 0, else 205. scale: unknown → transparent (PNG only),
  else ``round(255 * (100 - cell) / 100)``. raw: unknown → 255, else the cell value.
  ``negate`` inverts the written pixels (not in raw mode, whose loader ignores it) so that
  loading with the same flag round-trips.

Image row 0 is the top of the map (highest y); `OccupancyMap` row 0 is the lowest y.

Unknown stays unknown: unknown cells are written as grey 205 (occ 0.19608), so files are
saved with ``free_thresh`` 0.196 (as ROS 1's map_saver did and Nav2 does again since
navigation2 #5278): 205 then reloads as unknown. nav2's older default of 0.25 read 205 back
as *free* (slam_toolbox issue #587). Files that eddiebot wrote with that default (trinary,
thresholds 0.25 / 0.65, only the pixels 0 / 205 / 254) load with 205 as unknown and one
`LegacyMapWarning` asking to save them again; every other file loads exactly as
map_server reads it.

Where the robot is in the map: a map saved from a running SLAM session carries two keys
of eddiebot's beside nav2's (map_server reads only its own keys and ignores these):
``map_to_odom: [x, y, yaw]``, the map → odom transform when the map was saved, and
``odom_session``, the odometry that odom frame belongs to (`MapAnchor`). While that same
odometry still runs, the robot's pose in the map is ``map_to_odom ∘ odom → base``.
"""

from __future__ import annotations

import contextlib
import enum
import math
import os
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import yaml

from eddiebot.core.files import created_file_mode
from eddiebot.maps.errors import LegacyMapWarning, MapFormatError, MapWriteError
from eddiebot.maps.grid import OccupancyMap

__all__ = [
    "DEFAULT_FREE_THRESH",
    "DEFAULT_OCCUPIED_THRESH",
    "MapAnchor",
    "MapMode",
    "MapYaml",
    "image_to_map",
    "load_map",
    "map_to_image",
    "read_anchor",
    "read_map_yaml",
    "save_anchor",
    "save_map",
    "write_image",
]

#: Thresholds every eddiebot writer uses (DESIGN §9): grey 205 (occ 0.19608) reloads as unknown.
DEFAULT_OCCUPIED_THRESH = 0.65
DEFAULT_FREE_THRESH = 0.196

#: What eddiebot wrote before: 205 reloads as free with these (see `_legacy_unknown_pixel`).
_LEGACY_FREE_THRESH = 0.25
#: Thresholds that came through a float32 service field (SaveMap) differ by ~1e-8.
_THRESH_TOLERANCE = 1e-6


class MapMode(str, enum.Enum):
    """How image pixels map to cell values (nav2 ``mode`` key)."""

    TRINARY = "trinary"
    SCALE = "scale"
    RAW = "raw"


@dataclass(frozen=True)
class MapAnchor:
    """Where a map's frame stood against odometry when it was saved (eddiebot's keys)."""

    map_to_odom: tuple[float, float, float]
    """The map → odom transform (x, y, yaw) at saving time."""
    odom_session: str
    """The odometry it belongs to: the ``/odom`` publisher's process and node."""

    def yaml_keys(self) -> dict[str, Any]:
        x, y, yaw = self.map_to_odom
        return {"map_to_odom": [float(x), float(y), float(yaw)],
                "odom_session": self.odom_session}


@dataclass(frozen=True)
class MapYaml:
    """The contents of a map YAML file, validated; ``image`` resolved against its folder."""

    image: Path
    resolution: float
    origin: tuple[float, float, float]
    negate: bool = False
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH
    free_thresh: float = DEFAULT_FREE_THRESH
    mode: MapMode = MapMode.TRINARY
    anchor: MapAnchor | None = None
    """eddiebot's ``map_to_odom`` + ``odom_session`` keys, when the file has them."""


def _anchor(doc: dict[str, Any], path: Path) -> MapAnchor | None:
    if "map_to_odom" not in doc and "odom_session" not in doc:
        return None
    for key in ("map_to_odom", "odom_session"):
        if key not in doc:
            raise MapFormatError(f"{path}: key '{key}' missing (it goes with "
                                 f"'{'odom_session' if key == 'map_to_odom' else 'map_to_odom'}')")
    raw = doc["map_to_odom"]
    if (
        not isinstance(raw, (list, tuple))
        or len(raw) != 3
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in raw)
        or not all(math.isfinite(float(v)) for v in raw)
    ):
        raise MapFormatError(f"{path}: key 'map_to_odom' must be [x, y, yaw], got {raw!r}")
    session = doc["odom_session"]
    if not isinstance(session, str) or not session:
        raise MapFormatError(f"{path}: key 'odom_session' must be a non-empty string, "
                             f"got {session!r}")
    return MapAnchor((float(raw[0]), float(raw[1]), float(raw[2])), session)


def save_anchor(path: str | os.PathLike[str], anchor: MapAnchor) -> Path:
    """Write ``anchor``'s keys alone to the YAML file ``path`` (atomically): the sidecar of
    a saved SLAM session."""
    target = Path(path)
    _atomic_write_bytes(target, yaml.safe_dump(anchor.yaml_keys(), sort_keys=False).encode())
    return target


def read_anchor(path: str | os.PathLike[str]) -> MapAnchor | None:
    """The `MapAnchor` of a YAML file holding its keys (a sidecar or a map YAML), or None
    when the file has none; `MapFormatError` names the file for a malformed one."""
    target = Path(path)
    try:
        doc = yaml.safe_load(target.read_text(encoding="utf-8"))
    except OSError as exc:
        raise MapFormatError(f"{target}: cannot read: {exc.strerror or exc}") from exc
    except yaml.YAMLError as exc:
        raise MapFormatError(f"{target}: not valid YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise MapFormatError(f"{target}: must be a mapping of keys")
    return _anchor(doc, target)


def _number(doc: dict[str, Any], key: str, path: Path) -> float:
    value = doc[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MapFormatError(f"{path}: key '{key}' must be a number, got {value!r}")
    return float(value)


def read_map_yaml(yaml_path: str | os.PathLike[str]) -> MapYaml:
    """Parse and validate a nav2 map YAML file; errors name the file and the key."""
    path = Path(yaml_path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MapFormatError(f"{path}: cannot read map YAML: {exc.strerror or exc}") from exc
    try:
        doc = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        raise MapFormatError(f"{where}: not valid YAML: {exc.problem or exc.context}") from exc
    except yaml.YAMLError as exc:
        raise MapFormatError(f"{path}: not valid YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise MapFormatError(
            f"{path}: map YAML must be a mapping of keys, got {type(doc).__name__}"
        )
    for key in ("image", "resolution", "origin"):
        if key not in doc:
            raise MapFormatError(f"{path}: missing required key '{key}'")
    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise MapFormatError(f"{path}: key 'image' must be a non-empty file name, got {image!r}")
    image_path = Path(image)
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    resolution = _number(doc, "resolution", path)
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise MapFormatError(f"{path}: key 'resolution' must be > 0, got {resolution}")
    origin_raw = doc["origin"]
    if (
        not isinstance(origin_raw, (list, tuple))
        or len(origin_raw) != 3
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in origin_raw)
    ):
        raise MapFormatError(f"{path}: key 'origin' must be [x, y, yaw], got {origin_raw!r}")
    origin = (float(origin_raw[0]), float(origin_raw[1]), float(origin_raw[2]))
    negate_raw = doc.get("negate", 0)
    if isinstance(negate_raw, bool) or negate_raw in (0, 1):
        negate = bool(negate_raw)
    else:
        raise MapFormatError(f"{path}: key 'negate' must be 0/1 or true/false, got {negate_raw!r}")
    occupied = (
        _number(doc, "occupied_thresh", path)
        if "occupied_thresh" in doc
        else DEFAULT_OCCUPIED_THRESH
    )
    free = _number(doc, "free_thresh", path) if "free_thresh" in doc else DEFAULT_FREE_THRESH
    if not 0.0 <= free <= 1.0:
        raise MapFormatError(f"{path}: key 'free_thresh' must lie in [0, 1], got {free}")
    if not 0.0 <= occupied <= 1.0:
        raise MapFormatError(f"{path}: key 'occupied_thresh' must lie in [0, 1], got {occupied}")
    if free > occupied:
        raise MapFormatError(
            f"{path}: key 'free_thresh' ({free}) must not exceed 'occupied_thresh' ({occupied})"
        )
    mode_raw = doc.get("mode", "trinary")
    try:
        mode = MapMode(str(mode_raw).lower())
    except ValueError:
        raise MapFormatError(
            f"{path}: key 'mode' must be one of trinary, scale, raw; got {mode_raw!r}"
        ) from None
    return MapYaml(image_path, resolution, origin, negate, occupied, free, mode,
                   _anchor(doc, path))


def image_to_map(
    image: npt.NDArray[np.uint8],
    *,
    resolution: float,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    mode: MapMode | str = MapMode.TRINARY,
    negate: bool = False,
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
    free_thresh: float = DEFAULT_FREE_THRESH,
) -> OccupancyMap:
    """Cells from an 8-bit image (H, W) grey, (H, W, 3) BGR or (H, W, 4) BGRA, top row first."""
    mode = MapMode(mode)
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise MapFormatError(f"map image must be 8-bit, got {img.dtype}")
    alpha: npt.NDArray[np.float64] | None = None
    if img.ndim == 2:
        colour = img[..., None].astype(np.float64)
    elif img.ndim == 3 and img.shape[2] in (1, 3):
        colour = img.astype(np.float64)
    elif img.ndim == 3 and img.shape[2] in (2, 4):
        colour = img[..., :-1].astype(np.float64)
        alpha = img[..., -1].astype(np.float64)
    else:
        raise MapFormatError(f"map image has unsupported shape {img.shape}")
    if mode is MapMode.TRINARY and alpha is not None:
        channels = np.concatenate([colour, (255.0 - alpha)[..., None]], axis=-1)
    else:
        channels = colour
    # Pixel values are averaged (as ImageMagick's quantum sum / count) before scaling.
    shade = channels.mean(axis=-1) / 255.0
    occ = shade if negate else 1.0 - shade
    cells = np.full(shade.shape, -1, dtype=np.int16)
    if mode is MapMode.RAW:
        value = np.round(shade * 255.0)
        ok = (value >= 0) & (value <= 100)
        cells[ok] = value[ok].astype(np.int16)
    else:
        occupied = occ > occupied_thresh
        free = occ < free_thresh
        cells[occupied] = 100
        cells[free] = 0
        if mode is MapMode.SCALE:
            middle = ~(occupied | free)
            span = occupied_thresh - free_thresh
            if span > 0:
                cells[middle] = np.rint((occ[middle] - free_thresh) / span * 100.0).astype(np.int16)
            if alpha is not None:
                cells[alpha != 255] = -1
    return OccupancyMap(data=np.flipud(cells).astype(np.int8), resolution=resolution, origin=origin)


def map_to_image(
    grid: OccupancyMap,
    *,
    mode: MapMode | str = MapMode.TRINARY,
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
    free_thresh: float = DEFAULT_FREE_THRESH,
    negate: bool = False,
    alpha: bool = False,
) -> npt.NDArray[np.uint8]:
    """The image nav2's map_saver writes for ``grid``: (H, W) grey, or (H, W, 2) grey+alpha.

    Top image row = highest y. ``alpha`` adds a transparency channel (used by scale mode to
    mark unknown cells; only PNG can store it).
    """
    mode = MapMode(mode)
    cells = np.flipud(grid.data).astype(np.int16)
    unknown = (cells < 0) | (cells > 100)
    if mode is MapMode.TRINARY:
        free_int = int(np.rint(free_thresh * 100.0))
        occ_int = int(np.rint(occupied_thresh * 100.0))
        img = np.full(cells.shape, 205, dtype=np.uint8)
        img[(cells <= free_int) & ~unknown] = 254
        img[(cells >= occ_int) & ~unknown] = 0
    elif mode is MapMode.SCALE:
        img = np.round(255.0 * (100.0 - np.clip(cells, 0, 100)) / 100.0).astype(np.uint8)
        img[unknown] = 205 if not alpha else 0
    else:
        img = np.where(unknown, 255, np.clip(cells, 0, 100)).astype(np.uint8)
    if negate and mode is not MapMode.RAW:  # raw mode ignores negate on load, too
        img = (255 - img).astype(np.uint8)
    if alpha:
        transparency = np.where(unknown & (mode is MapMode.SCALE), 0, 255).astype(np.uint8)
        return np.stack([img, transparency], axis=-1)
    return img


def _atomic_write_bytes(path: Path, payload: bytes) -> None:
    """Write ``payload`` to ``path`` through a temporary file in the same folder + rename."""
    fd = -1
    tmp = ""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "wb") as handle:
            fd = -1
            handle.write(payload)
            handle.flush()
            os.fsync(handle.fileno())
            # mkstemp made it 0600: give it the mode the user's umask gives new files
            os.fchmod(handle.fileno(), created_file_mode())
        os.replace(tmp, path)
        tmp = ""
    except OSError as exc:
        raise MapWriteError(f"{path}: cannot write: {exc.strerror or exc}") from exc
    finally:
        if fd >= 0:
            os.close(fd)
        if tmp:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_image(path: str | os.PathLike[str], image: npt.NDArray[np.uint8]) -> None:
    """Atomically write an image; the format follows the suffix (``.pgm``, ``.png``, ...).

    A (H, W, 2) grey+alpha image is written as a 4-channel PNG.
    """
    target = Path(path)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 2:
        grey = img[..., 0]
        img = np.dstack([grey, grey, grey, img[..., 1]])
    ok, buf = cv2.imencode(target.suffix or ".png", img)
    if not ok:
        raise MapWriteError(f"{target}: cannot encode image as {target.suffix!r}")
    _atomic_write_bytes(target, buf.tobytes())


def save_map(
    grid: OccupancyMap,
    path_without_ext: str | os.PathLike[str],
    *,
    mode: MapMode | str = MapMode.TRINARY,
    image_format: str = "pgm",
    occupied_thresh: float = DEFAULT_OCCUPIED_THRESH,
    free_thresh: float = DEFAULT_FREE_THRESH,
    negate: bool = False,
    anchor: MapAnchor | None = None,
) -> Path:
    """Write ``<path>.<image_format>`` and ``<path>.yaml`` as nav2's map_saver does
    (plus ``anchor``'s keys when given).

    Each file is written to a temporary file and renamed over the target, image first, so a
    failure leaves any previous map intact. Returns the YAML path. Scale mode stores unknown
    cells as transparency, which only PNG holds; with PGM they are written as grey 205
    (with a warning, like map_saver).
    """
    mode = MapMode(mode)
    fmt = image_format.lower().lstrip(".")
    if fmt not in ("pgm", "png", "bmp"):
        raise MapWriteError(f"{path_without_ext}: unsupported image format {image_format!r}")
    if not (0.0 <= free_thresh <= occupied_thresh <= 1.0):
        raise MapWriteError(
            f"{path_without_ext}: need 0 <= free_thresh ({free_thresh}) <= "
            f"occupied_thresh ({occupied_thresh}) <= 1"
        )
    base = Path(path_without_ext)
    image_path = base.with_name(base.name + "." + fmt)
    yaml_path = base.with_name(base.name + ".yaml")
    use_alpha = mode is MapMode.SCALE and fmt == "png"
    if mode is MapMode.SCALE and not use_alpha:
        warnings.warn(
            f"map mode 'scale' needs transparency for unknown cells, which '{fmt}' lacks; "
            "consider image_format 'png'",
            stacklevel=2,
        )
    image = map_to_image(
        grid,
        mode=mode,
        occupied_thresh=occupied_thresh,
        free_thresh=free_thresh,
        negate=negate,
        alpha=use_alpha,
    )
    if not base.parent.is_dir():
        raise MapWriteError(f"{base.parent}: folder does not exist")
    write_image(image_path, image)
    x, y, yaw = grid.origin
    text = (
        f"image: {image_path.name}\n"
        f"mode: {mode.value}\n"
        f"resolution: {grid.resolution!r}\n"
        f"origin: [{x!r}, {y!r}, {yaw!r}]\n"
        f"negate: {int(negate)}\n"
        f"occupied_thresh: {_threshold_text(occupied_thresh)}\n"
        f"free_thresh: {_threshold_text(free_thresh)}\n"
    )
    if anchor is not None:
        ax, ay, ayaw = (float(v) for v in anchor.map_to_odom)
        text += (f"map_to_odom: [{ax!r}, {ay!r}, {ayaw!r}]\n"
                 f"odom_session: {yaml.safe_dump(anchor.odom_session).splitlines()[0]}\n")
    _atomic_write_bytes(yaml_path, text.encode("utf-8"))
    return yaml_path


def _threshold_text(value: float) -> str:
    """A threshold as the YAML shows it: 6 significant digits, so that a value that came
    through a float32 service field (``0.19599999487``) is written as given (``0.196``)."""
    return repr(float(f"{value:.6g}"))


def _legacy_unknown_pixel(meta: MapYaml, image: npt.NDArray[np.uint8]) -> int | None:
    """The grey that stands for unknown in a file eddiebot wrote with ``free_thresh`` 0.25,
    else None.

    Recognised by what that writer produced: trinary mode, thresholds 0.25 / 0.65 (as
    written, or through a float32 service field), a single-channel image holding only the
    three trinary greys (0 / 205 / 254, inverted with ``negate``) and some unknown (205)
    among them. Such a file from nav2's map_saver (same default, same pixels) has the same
    flaw and is read the same way; a file with other greys is read as map_server reads it.
    """
    if (
        meta.mode is not MapMode.TRINARY
        or abs(meta.free_thresh - _LEGACY_FREE_THRESH) > _THRESH_TOLERANCE
        or abs(meta.occupied_thresh - DEFAULT_OCCUPIED_THRESH) > _THRESH_TOLERANCE
        or image.ndim != 2
    ):
        return None
    free, unknown, occupied = (1, 50, 255) if meta.negate else (254, 205, 0)
    counts = np.bincount(image.ravel(), minlength=256)
    if counts[unknown] == 0 or counts.sum() != counts[[free, unknown, occupied]].sum():
        return None
    return unknown


def load_map(yaml_path: str | os.PathLike[str]) -> OccupancyMap:
    """Read a nav2 map_server map (YAML + image) into an `OccupancyMap`.

    Cells follow map_server's rules for the file's mode and thresholds, except in a file
    eddiebot wrote with the old ``free_thresh`` 0.25 (see `_legacy_unknown_pixel`): there
    grey 205 is unknown, not free, and a `LegacyMapWarning` asks to save the map again.
    """
    meta = read_map_yaml(yaml_path)
    if not meta.image.is_file():
        raise MapFormatError(f"{yaml_path}: key 'image': file {meta.image} not found")
    raw = np.fromfile(meta.image, dtype=np.uint8)
    decoded = cv2.imdecode(raw, cv2.IMREAD_UNCHANGED)
    if decoded is None:
        raise MapFormatError(f"{meta.image}: cannot decode image (referenced by {yaml_path})")
    image: npt.NDArray[np.uint8] = (
        (decoded // 257).astype(np.uint8)
        if decoded.dtype == np.uint16
        else decoded.astype(np.uint8)
    )
    free_thresh = meta.free_thresh
    if _legacy_unknown_pixel(meta, image) is not None:
        # Only the greys 0 / 205 / 254 are present: with the current threshold 205 is unknown
        # and the other two read as before.
        free_thresh = DEFAULT_FREE_THRESH
        warnings.warn(
            f"{yaml_path}: written by an older eddiebot with free_thresh 0.25, which makes "
            "map_server read unexplored space (grey 205) as free; loaded with it as unknown. "
            "Save the map again (eddie map save) to fix the file",
            LegacyMapWarning,
            stacklevel=2,
        )
    try:
        return image_to_map(
            image,
            resolution=meta.resolution,
            origin=meta.origin,
            mode=meta.mode,
            negate=meta.negate,
            occupied_thresh=meta.occupied_thresh,
            free_thresh=free_thresh,
        )
    except MapFormatError as exc:
        raise MapFormatError(f"{meta.image}: {exc}") from exc
