"""ctypes binding to libfreenect's asynchronous API (Kinect v1), just what the driver needs.

The library is ``libfreenect.so.0.*`` from Debian's ``libfreenect0.5`` (pulled in by
``libfreenect-dev``), found with :func:`ctypes.util.find_library`. ``EDDIE_FREENECT_LIBRARY``
names another file to load instead, e.g. libfreenect's *fakenect* replay library from
``libfreenect-bin``, which plays back a ``fakenect-record`` dump from ``FAKENECT_PATH``
(loading it by path replaces ``LD_PRELOAD``; both work).

The asynchronous API is used rather than ``libfreenect_sync``: the sync calls wait for a
frame without a timeout, so a device that disappears would hang the caller, whereas
``freenect_process_events_timeout`` returns an error the driver can act on.
Callbacks run inside :meth:`FreenectDevice.process_events`, on the caller's thread.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import enum
import os
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.robot.errors import RobotError

__all__ = [
    "APT_PACKAGES",
    "LIBRARY_ENV",
    "DepthFormat",
    "FrameMode",
    "FreenectDevice",
    "FreenectError",
    "FreenectUnavailableError",
    "KinectDeviceError",
    "Led",
    "find_library",
    "load_library",
]

#: Debian packages providing the library (runtime, headers) and fakenect (replay, record).
APT_PACKAGES = ("libfreenect-dev", "libfreenect-bin")
#: Environment variable naming a libfreenect-compatible library file to load instead.
LIBRARY_ENV = "EDDIE_FREENECT_LIBRARY"

RESOLUTION_MEDIUM = 1  # 640×480
VIDEO_RGB = 0
_DEVICE_MOTOR = 0x01
_DEVICE_CAMERA = 0x02


class DepthFormat(enum.IntEnum):
    """``freenect_depth_format``."""

    BIT11 = 0
    """Raw 11-bit disparity, one uint16 per pixel (2047 = no return)."""
    REGISTERED = 4
    """Millimetres, aligned to the 640×480 RGB image."""
    MM = 5
    """Millimetres, in the depth camera's own geometry."""


class Led(enum.IntEnum):
    """``freenect_led_options``."""

    OFF = 0
    GREEN = 1
    RED = 2
    YELLOW = 3
    BLINK_GREEN = 4
    BLINK_RED_YELLOW = 6


class FreenectError(RobotError):
    """A libfreenect call failed."""


class FreenectUnavailableError(FreenectError, ImportError):
    """libfreenect is not installed (or the named library file cannot be loaded)."""


class KinectDeviceError(FreenectError, ConnectionError):
    """No Kinect at the index, it cannot be opened, or it stopped answering."""


class FrameMode(ctypes.Structure):
    """``freenect_frame_mode`` (returned and passed by value)."""

    _fields_ = [
        ("reserved", ctypes.c_uint32),
        ("resolution", ctypes.c_int32),
        ("format", ctypes.c_int32),
        ("bytes", ctypes.c_int32),
        ("width", ctypes.c_int16),
        ("height", ctypes.c_int16),
        ("data_bits_per_pixel", ctypes.c_int8),
        ("padding_bits_per_pixel", ctypes.c_int8),
        ("framerate", ctypes.c_int8),
        ("is_valid", ctypes.c_int8),
    ]


class _Timeval(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_usec", ctypes.c_long)]


_FRAME_CB = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint32)


def _missing_message(detail: str) -> str:
    return (f"libfreenect not available ({detail}); install it with "
            f"`sudo apt-get install {' '.join(APT_PACKAGES)}` (Debian/Ubuntu), "
            f"or set {LIBRARY_ENV} to the library file")


def find_library() -> str:
    """The library to load: ``$EDDIE_FREENECT_LIBRARY`` or libfreenect found by the linker."""
    override = os.environ.get(LIBRARY_ENV, "")
    if override:
        return override
    name = ctypes.util.find_library("freenect")
    if name is None:
        raise FreenectUnavailableError(_missing_message("no libfreenect.so found"))
    return name


def load_library(path: str | None = None) -> ctypes.CDLL:
    """Load libfreenect (or a compatible replacement such as fakenect) and declare the
    signatures used here. Raises :class:`FreenectUnavailableError` naming the packages."""
    path = path or find_library()
    try:
        lib = ctypes.CDLL(path)
    except OSError as exc:
        raise FreenectUnavailableError(_missing_message(f"cannot load {path}: {exc}")) from exc
    vp, i32 = ctypes.c_void_p, ctypes.c_int
    sigs: dict[str, tuple[list[Any], Any]] = {
        "freenect_init": ([ctypes.POINTER(vp), vp], i32),
        "freenect_shutdown": ([vp], i32),
        "freenect_num_devices": ([vp], i32),
        "freenect_select_subdevices": ([vp, i32], None),
        "freenect_open_device": ([vp, ctypes.POINTER(vp), i32], i32),
        "freenect_close_device": ([vp], i32),
        "freenect_get_video_mode_count": ([], i32),
        "freenect_get_video_mode": ([i32], FrameMode),
        "freenect_get_depth_mode_count": ([], i32),
        "freenect_get_depth_mode": ([i32], FrameMode),
        "freenect_set_video_mode": ([vp, FrameMode], i32),
        "freenect_set_depth_mode": ([vp, FrameMode], i32),
        "freenect_get_current_video_mode": ([vp], FrameMode),
        "freenect_get_current_depth_mode": ([vp], FrameMode),
        "freenect_set_video_callback": ([vp, _FRAME_CB], None),
        "freenect_set_depth_callback": ([vp, _FRAME_CB], None),
        "freenect_start_video": ([vp], i32),
        "freenect_start_depth": ([vp], i32),
        "freenect_stop_video": ([vp], i32),
        "freenect_stop_depth": ([vp], i32),
        "freenect_process_events_timeout": ([vp, ctypes.POINTER(_Timeval)], i32),
        "freenect_set_tilt_degs": ([vp, ctypes.c_double], i32),
        "freenect_set_led": ([vp, i32], i32),
    }
    for name, (argtypes, restype) in sigs.items():
        try:
            fn = getattr(lib, name)
        except AttributeError as exc:
            raise FreenectUnavailableError(
                _missing_message(f"{path} lacks {name}; is it libfreenect?")) from exc
        fn.argtypes = argtypes
        fn.restype = restype
    return lib


def _modes(lib: ctypes.CDLL, kind: str) -> list[FrameMode]:
    count = getattr(lib, f"freenect_get_{kind}_mode_count")()
    get = getattr(lib, f"freenect_get_{kind}_mode")
    return [m for m in (get(i) for i in range(count)) if m.is_valid]


FrameCallback = Callable[[str, int, npt.NDArray[Any]], None]
"""``callback(kind, timestamp, array)``: kind ``"video"`` gives an (H, W, 3) uint8 RGB copy,
``"depth"`` an (H, W) uint16 copy; the timestamp is the camera's 60 MHz counter."""


class FreenectDevice:
    """One opened Kinect streaming 640×480 RGB and depth through callbacks.

    ``depth_format`` is the format asked for; :attr:`depth_format` after opening is the one
    delivered: when the library does not offer it (fakenect 0.5 replays raw 11-bit
    disparity only), the device falls back to :attr:`DepthFormat.BIT11` and the caller
    converts.
    """

    def __init__(self, lib: ctypes.CDLL, index: int, depth_format: DepthFormat,
                 on_frame: FrameCallback) -> None:
        self._lib = lib
        self._on_frame = on_frame
        self._ctx = ctypes.c_void_p()
        self._dev = ctypes.c_void_p()
        self._opened = False
        # Keep the ctypes callbacks alive as long as the device.
        self._video_cb = _FRAME_CB(self._video_frame)
        self._depth_cb = _FRAME_CB(self._depth_frame)
        self.depth_format = depth_format
        self.video_mode = FrameMode()
        self.depth_mode = FrameMode()
        self._open(index)

    def _open(self, index: int) -> None:
        lib = self._lib
        if lib.freenect_init(ctypes.byref(self._ctx), None) < 0:
            raise KinectDeviceError("freenect_init failed (USB not accessible?)")
        try:
            lib.freenect_select_subdevices(self._ctx, _DEVICE_MOTOR | _DEVICE_CAMERA)
            n = lib.freenect_num_devices(self._ctx)
            if index >= n:
                raise KinectDeviceError(f"no Kinect at device index {index} ({n} found)")
            if lib.freenect_open_device(self._ctx, ctypes.byref(self._dev), index) < 0:
                raise KinectDeviceError(
                    f"cannot open Kinect {index} (permissions? see the udev rule of libfreenect0.5)")
            self._opened = True
            self.video_mode = self._pick(_modes(lib, "video"), VIDEO_RGB, "video")
            depth_modes = _modes(lib, "depth")
            if not any(m.resolution == RESOLUTION_MEDIUM and m.format == self.depth_format
                       for m in depth_modes):
                self.depth_format = DepthFormat.BIT11
            self.depth_mode = self._pick(depth_modes, self.depth_format, "depth")
            lib.freenect_set_video_callback(self._dev, self._video_cb)
            lib.freenect_set_depth_callback(self._dev, self._depth_cb)
            if lib.freenect_set_video_mode(self._dev, self.video_mode) < 0:
                raise KinectDeviceError("cannot set the 640×480 RGB video mode")
            if lib.freenect_set_depth_mode(self._dev, self.depth_mode) < 0:
                raise KinectDeviceError(f"cannot set the depth mode {self.depth_format.name}")
            if lib.freenect_start_depth(self._dev) < 0 or lib.freenect_start_video(self._dev) < 0:
                raise KinectDeviceError("cannot start the Kinect streams")
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _pick(modes: list[FrameMode], fmt: int, kind: str) -> FrameMode:
        for m in modes:
            if m.resolution == RESOLUTION_MEDIUM and m.format == fmt:
                return m
        raise KinectDeviceError(f"libfreenect offers no 640×480 {kind} mode of format {fmt}")

    # -- callbacks (run inside process_events) -------------------------------------------
    def _copy(self, data: int | None, mode: FrameMode, dtype: Any, shape: tuple[int, ...]) -> Any:
        if not data:
            return None
        nbytes = int(np.prod(shape)) * np.dtype(dtype).itemsize
        if mode.bytes < nbytes:
            # The mode's buffer is smaller than the image it claims: deliver what is there
            # as a flat array so the caller's size check rejects it.
            nbytes, shape = max(int(mode.bytes), 0), (-1,)
        raw = (ctypes.c_uint8 * nbytes).from_address(data)
        return np.frombuffer(raw, dtype=dtype).reshape(shape).copy()

    def _video_frame(self, _dev: int | None, data: int | None, timestamp: int) -> None:
        m = self.video_mode
        arr = self._copy(data, m, np.uint8, (m.height, m.width, 3))
        if arr is not None:
            self._on_frame("video", int(timestamp), arr)

    def _depth_frame(self, _dev: int | None, data: int | None, timestamp: int) -> None:
        m = self.depth_mode
        arr = self._copy(data, m, np.dtype("<u2"), (m.height, m.width))
        if arr is not None:
            self._on_frame("depth", int(timestamp), arr)

    # -- control ----------------------------------------------------------------------------
    def process_events(self, timeout_s: float) -> None:
        """Handle USB events for up to ``timeout_s``; frame callbacks run here.
        Raises :class:`KinectDeviceError` when libfreenect reports the device lost."""
        if not self._opened:
            raise KinectDeviceError("device is closed")
        tv = _Timeval(int(timeout_s), int((timeout_s % 1.0) * 1e6))
        rc = self._lib.freenect_process_events_timeout(self._ctx, ctypes.byref(tv))
        if rc < 0:
            raise KinectDeviceError(f"freenect_process_events failed ({rc}): Kinect lost")

    def set_tilt_degs(self, angle: float) -> None:
        if self._lib.freenect_set_tilt_degs(self._dev, float(angle)) < 0:
            raise KinectDeviceError(f"cannot tilt to {angle} deg")

    def set_led(self, led: Led) -> None:
        if self._lib.freenect_set_led(self._dev, int(led)) < 0:
            raise KinectDeviceError(f"cannot set the LED to {led.name}")

    def close(self) -> None:
        """Stop the streams and release the device and context (safe to call twice)."""
        lib = self._lib
        if self._opened:
            self._opened = False
            lib.freenect_stop_depth(self._dev)
            lib.freenect_stop_video(self._dev)
            lib.freenect_close_device(self._dev)
        if self._ctx:
            lib.freenect_shutdown(self._ctx)
            self._ctx = ctypes.c_void_p()
