"""Kinect v1 driver over libfreenect: the simulator's four camera topics from the real sensor.

Publishes, like kinect_ros2 and the simulator (``eddiebot.sim``):

- ``/image_raw`` — rgb8 640×480, frame ``camera_rgb_optical_frame``;
- ``/camera_info`` — the real RGB calibration (plumb_bob, D ≠ 0);
- ``/depth/image_raw`` — 16UC1 in **millimetres** (libfreenect's ``FREENECT_DEPTH_MM``),
  frame ``camera_depth_optical_frame``; with ``depth_registration`` libfreenect's
  ``FREENECT_DEPTH_REGISTERED`` (mm, aligned to the RGB image, so RGB frame and calibration);
- ``/depth/camera_info`` — the real depth calibration;
- ``/points`` — XYZ PointCloud2 of the depth image, computed only while someone subscribes.

One stamp per frame on all four topics (the fix the original team had to add to
kinect_ros2): an RGB frame and a depth frame are paired by their libfreenect timestamps
(the camera's 60 MHz counter) and the pair is stamped with the node clock's time when the
pair completed. Frames that find no partner within ``sync_tolerance`` are dropped.

A capture thread runs libfreenect's event loop (``_freenect``); the node's timer publishes
the pairs in order (the newest three when it falls behind), no more than ``rate`` a second.
A Kinect that cannot be opened or that disappears (libfreenect reports an error, or no frame
for ``frame_timeout``) is logged once as an error and retried every ``retry_period``
seconds; the node keeps running. Frames whose size is not 640×480 are skipped with one
warning per stream.

Tilt (``tilt_angle`` parameter, degrees, −30..30) and LED (``led`` parameter, or the
``~/set_led`` SetBool service: true = green, false = off) are applied by the capture thread.

This module is a node (the layer above ``sim`` and ``perception``): it reuses the camera
message builders of :mod:`eddiebot.sim.camera` and the cloud of
:mod:`eddiebot.perception.depth_to_cloud`.
"""

from __future__ import annotations

import collections
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.core.node import Node
from eddiebot.core.parameters import Parameter, ParameterDescriptor, SetParametersResult
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.msgs.sensor_msgs import CameraInfo, Image, PointCloud2
from eddiebot.msgs.std_srvs import SetBool
from eddiebot.perception.depth_to_cloud import depth_to_pointcloud2
from eddiebot.robot._freenect import (
    APT_PACKAGES,
    DepthFormat,
    FreenectDevice,
    FreenectError,
    FreenectUnavailableError,
    KinectDeviceError,
    Led,
    load_library,
)
from eddiebot.robot.kinect_model import (
    DEPTH_OPTICAL_FRAME,
    KINECT_DEPTH,
    KINECT_RGB,
    RGB_OPTICAL_FRAME,
    CameraIntrinsics,
    camera_info_msg,
    depth_image_msg,
    rgb_image_msg,
)

__all__ = [
    "APT_PACKAGES",
    "DEPTH_DISTORTION",
    "FRAME_HEIGHT",
    "FRAME_WIDTH",
    "RGB_DISTORTION",
    "TIMESTAMP_HZ",
    "FramePair",
    "FramePairer",
    "FreenectUnavailableError",
    "KinectDeviceError",
    "KinectNode",
    "KinectParams",
    "disparity_to_mm",
    "kinect_camera_info",
]

FRAME_WIDTH, FRAME_HEIGHT = 640, 480
#: libfreenect frame timestamps count a 60 MHz clock (OpenKinect/libfreenect#681).
TIMESTAMP_HZ = 60_000_000
#: ``cfg/calibration_rgb.yaml`` of kinect_ros2 (plumb_bob k1, k2, t1, t2, k3).
RGB_DISTORTION = (0.10265184, -0.18646532, 0.0, 0.0, 0.0)
DEPTH_DISTORTION = (0.0, 0.0, 0.0, 0.0, 0.0)
LED_NAMES = {led.name.lower(): led for led in Led}


# -- pure core ----------------------------------------------------------------------------
def kinect_camera_info(intr: CameraIntrinsics, distortion: tuple[float, ...], stamp_ns: int,
                       frame_id: str) -> Any:
    """``CameraInfo`` of a calibrated camera: plumb_bob with ``distortion``, R = I, P = [K | 0]."""
    info = camera_info_msg(intr, stamp_ns, frame_id)
    info.d = np.asarray(distortion, dtype=np.float64)
    return info


def _disparity_table() -> npt.NDArray[np.uint16]:
    # libfreenect's raw → mm formula (src/registration.c, freenect_raw_to_mm) with the
    # nominal PrimeSense constants: reference distance 120 mm (in the cm-like unit the
    # formula scales by 10), pixel size 0.1042, emitter–CMOS distance 7.5, const shift 200.
    raw = np.arange(2048, dtype=np.float64)
    fixed_ref_x = (raw - 4.0 * 200.0) / 4.0 - 0.375
    metric = fixed_ref_x * 0.1042
    with np.errstate(divide="ignore", invalid="ignore"):
        mm = 10.0 * (metric * 120.0 / (7.5 - metric) + 120.0)
    valid = np.isfinite(mm) & (mm > 0) & (mm < 10_000)
    table = np.where(valid, np.floor(np.where(valid, mm, 0.0)), 0.0).astype(np.uint16)
    table[2047] = 0  # libfreenect's "no return"
    return table


_DISPARITY_TO_MM = _disparity_table()


def disparity_to_mm(raw: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint16]:
    """Raw 11-bit Kinect disparity → depth in mm (0 = no return), with libfreenect's formula
    and nominal constants. Used only where libfreenect cannot deliver ``FREENECT_DEPTH_MM``
    itself (fakenect 0.5 replays raw disparity); a real device converts with its own
    factory registration, which may differ from these constants by a few percent."""
    return _DISPARITY_TO_MM[np.minimum(raw, 2047)]


@dataclass(frozen=True)
class FramePair:
    """An RGB frame and a depth frame (mm) taken together; timestamps in 60 MHz ticks."""

    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    video_timestamp: int
    depth_timestamp: int


def _tick_diff(a: int, b: int) -> int:
    """a − b on the 32-bit wrapping counter."""
    return ((a - b + 2**31) % 2**32) - 2**31


class FramePairer:
    """Pairs RGB and depth frames whose timestamps differ by at most ``tolerance_ticks``.

    Holds the newest unpaired frame of each stream. A frame that is older than the other
    stream's pending frame by more than the tolerance can never be paired (later frames are
    newer still), so it is dropped; otherwise the older pending frame is.
    """

    def __init__(self, tolerance_ticks: int) -> None:
        self.tolerance_ticks = int(tolerance_ticks)
        self._pending: dict[str, tuple[int, Any]] = {}
        self.dropped = 0

    def reset(self) -> None:
        self._pending.clear()

    def push(self, kind: str, timestamp: int, frame: Any) -> FramePair | None:
        """Offer a frame of ``kind`` ``"video"`` or ``"depth"``; returns a pair when it
        completes one."""
        other_kind = "depth" if kind == "video" else "video"
        other = self._pending.get(other_kind)
        if other is None:
            if kind in self._pending:
                self.dropped += 1
            self._pending[kind] = (timestamp, frame)
            return None
        diff = _tick_diff(timestamp, other[0])
        if abs(diff) <= self.tolerance_ticks:
            del self._pending[other_kind]
            self._pending.pop(kind, None)
            video, depth = ((timestamp, frame), other) if kind == "video" else (other, (timestamp, frame))
            return FramePair(video[1], depth[1], video[0], depth[0])
        self.dropped += 1
        if diff > 0:  # the new frame is the newer one: the other will never find a partner
            del self._pending[other_kind]
            self._pending[kind] = (timestamp, frame)
        return None


@dataclass(frozen=True)
class KinectParams:
    """Node parameters (names as ROS freenect_camera where it has one)."""

    device_index: int = 0
    depth_registration: bool = False
    rate: float = 30.0
    """Maximum publish rate (Hz); the sensor delivers about 30."""
    rgb_frame_id: str = RGB_OPTICAL_FRAME
    depth_frame_id: str = DEPTH_OPTICAL_FRAME
    tilt_angle: float = 0.0
    """Tilt motor target (deg, −30..30; positive looks up)."""
    led: str = "green"
    sync_tolerance: float = 1.0 / 60.0
    """Largest RGB/depth timestamp difference of a pair (s): half a frame at 30 Hz."""
    retry_period: float = 1.0
    """Wait between attempts to (re)open a missing Kinect (s)."""
    frame_timeout: float = 5.0
    """No frame for this long (s) counts as a lost Kinect."""


# -- node -----------------------------------------------------------------------------------
class KinectNode(Node):
    """Kinect v1 through libfreenect; see the module docstring for topics and parameters.

    Raises :class:`FreenectUnavailableError` (naming the Debian packages) when libfreenect
    is not installed.
    """

    default_node_name = "kinect_ros2"

    def __init__(self, node_name: str = default_node_name, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        d = KinectParams()
        tilt_desc = ParameterDescriptor(description="tilt motor target, deg", range=(-30.0, 30.0))
        led_desc = ParameterDescriptor(description="LED: " + ", ".join(LED_NAMES))
        self.params = KinectParams(
            device_index=int(self.declare_parameter("device_index", d.device_index).value),
            depth_registration=bool(
                self.declare_parameter("depth_registration", d.depth_registration).value),
            rate=float(self.declare_parameter("rate", d.rate).value),
            rgb_frame_id=str(self.declare_parameter("rgb_frame_id", d.rgb_frame_id).value),
            depth_frame_id=str(self.declare_parameter("depth_frame_id", d.depth_frame_id).value),
            tilt_angle=float(self.declare_parameter("tilt_angle", d.tilt_angle, tilt_desc).value),
            led=str(self.declare_parameter("led", d.led, led_desc).value),
            sync_tolerance=float(self.declare_parameter("sync_tolerance", d.sync_tolerance).value),
            retry_period=float(self.declare_parameter("retry_period", d.retry_period).value),
            frame_timeout=float(self.declare_parameter("frame_timeout", d.frame_timeout).value),
        )
        p = self.params
        if p.rate <= 0:
            raise ValueError(f"rate must be positive, got {p.rate}")
        if p.led not in LED_NAMES:
            raise ValueError(f"led must be one of {sorted(LED_NAMES)}, got {p.led!r}")
        self._lib = load_library()

        self.rgb_pub = self.create_publisher(Image, "/image_raw", qos_profile_sensor_data)
        self.rgb_info_pub = self.create_publisher(CameraInfo, "/camera_info", qos_profile_sensor_data)
        self.depth_pub = self.create_publisher(Image, "/depth/image_raw", qos_profile_sensor_data)
        self.depth_info_pub = self.create_publisher(CameraInfo, "/depth/camera_info",
                                                    qos_profile_sensor_data)
        self.points_pub = self.create_publisher(PointCloud2, "/points", qos_profile_sensor_data)
        self.create_service(SetBool, "~/set_led", self._on_set_led)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._frames_lock = threading.Lock()
        self._pairer = FramePairer(round(p.sync_tolerance * TIMESTAMP_HZ))
        self._queue: collections.deque[tuple[int, FramePair]] = collections.deque(maxlen=3)
        self._last_published_ns: int | None = None
        self._min_period_ns = int(0.9e9 / p.rate)  # 10 % slack for the sensor's own jitter
        self._tilt = p.tilt_angle
        self._led = LED_NAMES[p.led]
        self._controls_dirty = threading.Event()
        self._warned_size: set[str] = set()
        self._stop = threading.Event()
        self._device: FreenectDevice | None = None
        self._last_frame_t = 0.0
        self._frames_since_open = 0
        #: Counters for diagnostics and tests.
        self.open_attempts = 0
        self.pairs_published = 0
        self.applied_tilt: float | None = None
        self.applied_led: Led | None = None
        self.depth_format: DepthFormat | None = None

        self.create_timer(max(1.0 / (3.0 * p.rate), 0.002), self._publish)
        self._thread = threading.Thread(target=self._capture_loop, name=f"{node_name}-freenect",
                                        daemon=True)
        self._thread.start()

    # -- parameters and services ------------------------------------------------------------
    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for prm in params:
            if prm.name == "tilt_angle" and not -30.0 <= float(prm.value) <= 30.0:
                return SetParametersResult(False, f"tilt_angle {prm.value} outside -30..30 deg")
            if prm.name == "led" and str(prm.value) not in LED_NAMES:
                return SetParametersResult(False, f"led must be one of {sorted(LED_NAMES)}")
        return SetParametersResult(True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        for prm in params:
            if prm.name == "tilt_angle":
                self._tilt = float(prm.value)
                self._controls_dirty.set()
            elif prm.name == "led":
                self._led = LED_NAMES[str(prm.value)]
                self._controls_dirty.set()

    def _on_set_led(self, request: Any, response: Any) -> Any:
        result = self.set_parameters([Parameter("led", "green" if request.data else "off")])[0]
        response.success = result.successful
        response.message = result.reason or ("LED green" if request.data else "LED off")
        return response

    # -- capture thread ---------------------------------------------------------------------
    def handle_frame(self, kind: str, timestamp: int, frame: npt.NDArray[Any]) -> None:
        """A frame from libfreenect (``kind`` ``"video"``: (H, W, 3) uint8 RGB, ``"depth"``:
        (H, W) uint16 in the device's depth format). Runs on the capture thread."""
        expected = (FRAME_HEIGHT, FRAME_WIDTH, 3) if kind == "video" else (FRAME_HEIGHT, FRAME_WIDTH)
        if frame.shape != expected:
            if kind not in self._warned_size:
                self._warned_size.add(kind)
                self.get_logger().warning(
                    f"skipping {kind} frames of shape {frame.shape}: expected {expected}")
            return
        self._last_frame_t = time.monotonic()
        self._frames_since_open += 1
        if kind == "depth" and self.depth_format == DepthFormat.BIT11:
            frame = disparity_to_mm(frame)
        with self._frames_lock:
            pair = self._pairer.push(kind, timestamp, frame)
            if pair is not None:
                self._queue.append((self.get_clock().now().nanoseconds, pair))

    def _open(self) -> FreenectDevice:
        p = self.params
        wanted = DepthFormat.REGISTERED if p.depth_registration else DepthFormat.MM
        self.open_attempts += 1
        self.depth_format = wanted
        dev = FreenectDevice(self._lib, p.device_index, wanted, self.handle_frame)
        self.depth_format = dev.depth_format
        if dev.depth_format != wanted:
            self.get_logger().warning(
                f"libfreenect offers no {wanted.name} depth mode (fakenect 0.5 replays raw "
                "disparity): converting 11-bit disparity to mm with nominal Kinect constants"
                + ("; depth is NOT registered to RGB" if p.depth_registration else ""),
                once=True)
        with self._frames_lock:
            self._pairer.reset()
        self._frames_since_open = 0
        self._last_frame_t = time.monotonic()
        self._controls_dirty.set()
        return dev

    def _apply_controls(self, dev: FreenectDevice) -> None:
        self._controls_dirty.clear()
        tilt, led = self._tilt, self._led
        # A motor that refuses (no motor subdevice, e.g. some Kinect for Windows units) is
        # not a lost camera: warn and keep streaming.
        try:
            dev.set_tilt_degs(tilt)
            self.applied_tilt = tilt
        except KinectDeviceError as exc:
            self.get_logger().warning(str(exc), once=True)
        try:
            dev.set_led(led)
            self.applied_led = led
        except KinectDeviceError as exc:
            self.get_logger().warning(str(exc), once=True)

    def _capture_loop(self) -> None:
        p = self.params
        log = self.get_logger()
        outage_logged = False
        while not self._stop.is_set():
            try:
                if self._device is None:
                    self._device = self._open()
                dev = self._device
                if self._controls_dirty.is_set():
                    self._apply_controls(dev)
                dev.process_events(0.1)
                if time.monotonic() - self._last_frame_t > p.frame_timeout:
                    raise KinectDeviceError(f"no frame for {p.frame_timeout:g} s")
                if self._frames_since_open and outage_logged:
                    log.info(f"Kinect {p.device_index} is streaming again")
                    outage_logged = False
            except FreenectError as exc:
                if self._device is not None:
                    self._device.close()
                    self._device = None
                if not outage_logged:
                    log.error(f"Kinect {p.device_index}: {exc}; retrying every "
                              f"{p.retry_period:g} s")
                    outage_logged = True
                self._stop.wait(p.retry_period)
        if self._device is not None:
            self._device.close()
            self._device = None

    # -- publishing (executor thread) ----------------------------------------------------------
    def _publish(self) -> None:
        with self._frames_lock:
            pending = list(self._queue)
            self._queue.clear()
        for stamp, pair in pending:
            last = self._last_published_ns
            if last is None or stamp - last >= self._min_period_ns:
                self._last_published_ns = stamp
                self._publish_pair(stamp, pair)

    def _publish_pair(self, stamp: int, pair: FramePair) -> None:
        p = self.params
        registered = p.depth_registration and self.depth_format == DepthFormat.REGISTERED
        depth_frame = p.rgb_frame_id if registered else p.depth_frame_id
        depth_intr, depth_d = (KINECT_RGB, RGB_DISTORTION) if registered else (KINECT_DEPTH,
                                                                                 DEPTH_DISTORTION)
        depth_msg = depth_image_msg(pair.depth, stamp, depth_frame)
        depth_info = kinect_camera_info(depth_intr, depth_d, stamp, depth_frame)
        self.rgb_pub.publish(rgb_image_msg(pair.rgb, stamp, p.rgb_frame_id))
        self.rgb_info_pub.publish(kinect_camera_info(KINECT_RGB, RGB_DISTORTION, stamp,
                                                     p.rgb_frame_id))
        self.depth_pub.publish(depth_msg)
        self.depth_info_pub.publish(depth_info)
        if self.points_pub.get_subscription_count() > 0:
            self.points_pub.publish(depth_to_pointcloud2(depth_msg, depth_info))
        self.pairs_published += 1

    def destroy_node(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)
        super().destroy_node()
