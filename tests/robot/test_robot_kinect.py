"""Kinect v1 driver: pure pairing/conversion/calibration, and the node end to end on
libfreenect's fakenect replaying a dump these tests write (Debian ``libfreenect-bin``).

Each fakenect test loads a private copy of the fakenect library (``EDDIE_FREENECT_LIBRARY``),
so its global replay state (open INDEX.txt, pacing) starts fresh; no ``LD_PRELOAD`` needed.
"""

from __future__ import annotations

import glob
import logging
import shutil
import struct
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.parameters import Parameter
from eddiebot.core.qos import qos_profile_sensor_data
from eddiebot.msgs.sensor_msgs import CameraInfo, Image, PointCloud2
from eddiebot.msgs.std_srvs import SetBool
from eddiebot.robot import _freenect
from eddiebot.robot.kinect import (
    FRAME_HEIGHT,
    FRAME_WIDTH,
    RGB_DISTORTION,
    FramePairer,
    FreenectUnavailableError,
    KinectNode,
    disparity_to_mm,
    kinect_camera_info,
)
from eddiebot.sim.camera import KINECT_DEPTH, KINECT_RGB

FAKENECT = sorted(glob.glob("/usr/lib/*/fakenect/libfreenect.so*")
                  + glob.glob("/usr/lib/fakenect/libfreenect.so*")
                  + glob.glob("/usr/local/lib/fakenect/libfreenect.so*"))
needs_fakenect = pytest.mark.skipif(
    not FAKENECT,
    reason="fakenect not installed: apt-get install libfreenect-dev libfreenect-bin")

TICKS_PER_FRAME = 2_000_000  # 60 MHz / 30 Hz
FRAME_GAP_S = 0.04


# -- pure core ------------------------------------------------------------------------------
def test_pairer_pairs_within_tolerance_and_drops_the_unpairable() -> None:
    p = FramePairer(tolerance_ticks=1_000)
    assert p.push("video", 10_000, "v0") is None
    pair = p.push("depth", 10_500, "d0")
    assert pair is not None
    assert (pair.rgb, pair.depth, pair.video_timestamp, pair.depth_timestamp) == ("v0", "d0", 10_000, 10_500)
    # a depth frame with no RGB partner, then the next RGB frame much later: the stale
    # depth frame is dropped, the new RGB frame waits and pairs with its own depth frame.
    assert p.push("depth", 20_000, "d-orphan") is None
    assert p.push("video", 50_000, "v1") is None
    assert p.dropped == 1
    pair = p.push("depth", 49_400, "d1")
    assert pair is not None and (pair.rgb, pair.depth) == ("v1", "d1")
    # a late frame older than the other stream's pending one is the one dropped
    assert p.push("video", 90_000, "v2") is None
    assert p.push("depth", 80_000, "d-late") is None
    assert p.dropped == 2
    pair = p.push("depth", 90_100, "d2")
    assert pair is not None and (pair.rgb, pair.depth) == ("v2", "d2")


def test_pairer_handles_the_32_bit_timestamp_wrap() -> None:
    p = FramePairer(tolerance_ticks=1_000)
    assert p.push("video", 2**32 - 300, "v") is None
    pair = p.push("depth", 200, "d")  # 500 ticks later, after the wrap
    assert pair is not None and pair.video_timestamp == 2**32 - 300


def test_disparity_to_mm_follows_libfreenects_formula() -> None:
    # raw 800: ((800 - 800)/4 - 0.375)·0.1042 = -0.039075 → 10·(-0.039075·120/7.539075 + 120)
    raw = np.array([[800, 1000], [2047, 1500]], dtype=np.uint16)
    mm = disparity_to_mm(raw)
    assert mm.dtype == np.uint16 and mm.shape == (2, 2)
    assert mm[0, 0] == int(10 * (-0.039075 * 120 / 7.539075 + 120))  # 1193 mm
    metric = (200 / 4 - 0.375) * 0.1042
    assert mm[0, 1] == int(10 * (metric * 120 / (7.5 - metric) + 120))  # 3864 mm
    assert mm[1, 0] == 0 and mm[1, 1] == 0  # no return; beyond 10 m
    table = disparity_to_mm(np.arange(500, 1050, dtype=np.uint16)).astype(int)
    assert np.all(np.diff(table) > 0)  # farther with disparity, one-to-one


def test_camera_info_carries_the_real_calibration() -> None:
    info = kinect_camera_info(KINECT_RGB, RGB_DISTORTION, 1_500_000_007, "camera_rgb_optical_frame")
    assert (info.header.stamp.sec, info.header.stamp.nanosec) == (1, 500_000_007)
    assert info.header.frame_id == "camera_rgb_optical_frame"
    assert (info.width, info.height, info.distortion_model) == (640, 480, "plumb_bob")
    np.testing.assert_allclose(info.d, [0.10265184, -0.18646532, 0, 0, 0])
    np.testing.assert_allclose(info.k, [526.60717328, 0, 318.52510740,
                                        0, 526.60717328, 241.18145973, 0, 0, 1])
    np.testing.assert_allclose(info.r, np.eye(3).ravel())
    np.testing.assert_allclose(info.p, [526.60717328, 0, 318.52510740, 0,
                                        0, 526.60717328, 241.18145973, 0, 0, 0, 1, 0])


def test_missing_library_names_the_packages(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(_freenect.LIBRARY_ENV, str(tmp_path / "libfreenect.so.0.5"))
    with pytest.raises(FreenectUnavailableError, match="libfreenect-dev libfreenect-bin"):
        KinectNode(context=Context())


# -- fakenect --------------------------------------------------------------------------------
class _Dump:
    """Writes a fakenect dump as fakenect-record does: INDEX.txt lists
    ``<type>-<time>-<timestamp>.<ext>`` files; r = PPM (P6, RGB bytes), d = PGM (P5, raw
    11-bit disparity as host-order uint16), a = freenect_raw_tilt_state bytes."""

    def __init__(self, path: Path) -> None:
        self.path = path
        path.mkdir()
        self.lines: list[str] = []
        self.t = 1_700_000_000.0

    def _write(self, kind: str, dt: float, timestamp: int, payload: bytes) -> None:
        self.t += dt
        ext, header = {"r": ("ppm", b"P6 640 480 255\n"), "d": ("pgm", b"P5 640 480 65535\n"),
                       "a": ("dump", b"")}[kind]
        name = f"{kind}-{self.t:f}-{timestamp}.{ext}"
        (self.path / name).write_bytes(header + payload)
        self.lines.append(name)

    def accel(self, timestamp: int) -> None:
        # int16 x, y, z (819 counts per g), int8 tilt (half degrees), int32 status
        self._write("a", 0.0, timestamp, struct.pack("<hhhbxi", 0, 819, 0, 0, 0))

    def rgb(self, dt: float, timestamp: int, rgb: np.ndarray) -> None:
        self._write("r", dt, timestamp, rgb.astype(np.uint8).tobytes())

    def depth(self, dt: float, timestamp: int, raw: np.ndarray) -> None:
        self._write("d", dt, timestamp, raw.astype("<u2").tobytes())

    def close(self) -> None:
        (self.path / "INDEX.txt").write_text("\n".join(self.lines) + "\n")


def _rgb_frame(i: int) -> np.ndarray:
    img = np.zeros((FRAME_HEIGHT, FRAME_WIDTH, 3), np.uint8)
    img[..., 0] = 10 * i + 1
    img[..., 1] = (np.arange(FRAME_WIDTH) % 256)[None, :]
    img[..., 2] = (np.arange(FRAME_HEIGHT) % 256)[:, None]
    return img


def _raw_frame(i: int) -> np.ndarray:
    """Disparity rising down the image (near at the top), a 'no return' block, and the
    frame index in the first pixel's offset so frames can be told apart."""
    raw = np.empty((FRAME_HEIGHT, FRAME_WIDTH), np.uint16)
    raw[:] = (600 + np.arange(FRAME_HEIGHT) % 400)[:, None]
    raw[0, 0] = 700 + i
    raw[400:, 600:] = 2047
    return raw


@pytest.fixture
def fakenect(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Callable[[Path], None]:
    """Point the driver at a fresh copy of fakenect replaying ``dump_dir``."""

    def use(dump_dir: Path) -> None:
        lib = tmp_path / "libfreenect-fakenect.so"
        shutil.copyfile(FAKENECT[0], lib)
        monkeypatch.setenv(_freenect.LIBRARY_ENV, str(lib))
        monkeypatch.setenv("FAKENECT_PATH", str(dump_dir))

    return use


class _Listener(Node):
    def __init__(self, context: Context, points: bool = False) -> None:
        super().__init__("kinect_listener", context=context)
        self.got: dict[str, list[Any]] = {k: [] for k in ("rgb", "rgb_info", "depth", "depth_info",
                                                          "points")}
        for key, cls, topic in (("rgb", Image, "/image_raw"), ("rgb_info", CameraInfo, "/camera_info"),
                                ("depth", Image, "/depth/image_raw"),
                                ("depth_info", CameraInfo, "/depth/camera_info")):
            self.create_subscription(cls, topic, self.got[key].append, qos_profile_sensor_data)
        if points:
            self.create_subscription(PointCloud2, "/points", self.got["points"].append,
                                     qos_profile_sensor_data)


@pytest.fixture
def run_node() -> Iterator[Callable[..., tuple[KinectNode, _Listener, SingleThreadedExecutor]]]:
    made: list[tuple[KinectNode, _Listener]] = []

    def start(points: bool = False, **params: Any) -> tuple[KinectNode, _Listener, SingleThreadedExecutor]:
        ctx = Context()
        listener = _Listener(ctx, points=points)
        node = KinectNode(context=ctx, parameter_overrides={"rate": 1000.0, **params})
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        ex.add_node(listener)
        made.append((node, listener))
        return node, listener, ex

    yield start
    for node, listener in made:
        node.destroy_node()
        listener.destroy_node()


def _spin_until(ex: SingleThreadedExecutor, done: Callable[[], bool], timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "timed out waiting for the Kinect node"
        ex.spin_once(timeout_sec=0.005)


def _pair_dump(path: Path, n: int, gap_s: float = FRAME_GAP_S) -> None:
    """n RGB/depth pairs ``gap_s`` apart (timestamps 300 ticks apart within a pair), plus an
    orphan depth frame between pairs 1 and 2 that must never be published."""
    dump = _Dump(path)
    dump.accel(0)
    for i in range(n):
        ts = 1_000 + i * TICKS_PER_FRAME
        dump.rgb(gap_s, ts, _rgb_frame(i))
        dump.depth(0.001, ts + 300, _raw_frame(i))
        if i == 1:
            dump.depth(0.001, ts + TICKS_PER_FRAME // 4, _raw_frame(99))
    dump.close()


@needs_fakenect
def test_four_topics_from_fakenect(tmp_path: Path, fakenect: Callable[[Path], None],
                                   run_node: Callable[..., Any]) -> None:
    n = 4
    _pair_dump(tmp_path / "dump", n)
    fakenect(tmp_path / "dump")
    node, listener, ex = run_node(points=True)
    got = listener.got
    _spin_until(ex, lambda: len(got["depth_info"]) >= n)
    ex.spin_until_idle()

    assert node.pairs_published == n
    assert all(len(got[k]) == n for k in ("rgb", "rgb_info", "depth", "depth_info", "points"))
    native_mm = node.depth_format == _freenect.DepthFormat.MM
    stamps = []
    for i in range(n):
        rgb, rgb_info, depth, depth_info = (got[k][i] for k in ("rgb", "rgb_info", "depth", "depth_info"))
        # one stamp per frame on all four topics, and on the cloud
        stamp = (rgb.header.stamp.sec, rgb.header.stamp.nanosec)
        for msg in (rgb_info, depth, depth_info, got["points"][i]):
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == stamp
        stamps.append(stamp)
        assert rgb.header.frame_id == rgb_info.header.frame_id == "camera_rgb_optical_frame"
        assert depth.header.frame_id == depth_info.header.frame_id == "camera_depth_optical_frame"
        assert (rgb.encoding, rgb.width, rgb.height, rgb.step) == ("rgb8", 640, 480, 1920)
        assert (depth.encoding, depth.width, depth.height, depth.step) == ("16UC1", 640, 480, 1280)
        # the frames of pair i, in order, and never the orphan depth frame
        rgb_arr = np.asarray(rgb.data).reshape(480, 640, 3)
        np.testing.assert_array_equal(rgb_arr, _rgb_frame(i))
        mm = np.asarray(depth.data).view("<u2").reshape(480, 640)
        if not native_mm:  # fakenect 0.5 replays disparity; the driver converts to mm
            np.testing.assert_array_equal(mm, disparity_to_mm(_raw_frame(i)))
            assert mm[0, 0] == disparity_to_mm(np.array([700 + i], np.uint16))[0]
            assert mm[200, 5] == 1193  # raw 800
            assert mm[450, 620] == 0  # no return
    assert stamps == sorted(set(stamps))

    rgb_info, depth_info = got["rgb_info"][0], got["depth_info"][0]
    np.testing.assert_allclose(rgb_info.k[[0, 2, 4, 5]], [526.60717328, 318.52510740,
                                                          526.60717328, 241.18145973])
    np.testing.assert_allclose(rgb_info.d, [0.10265184, -0.18646532, 0, 0, 0])
    np.testing.assert_allclose(depth_info.k[[0, 2, 4, 5]], [KINECT_DEPTH.fx, KINECT_DEPTH.cx,
                                                            KINECT_DEPTH.fy, KINECT_DEPTH.cy])
    np.testing.assert_allclose(depth_info.d, np.zeros(5))
    np.testing.assert_allclose(depth_info.p[[0, 2, 3, 5, 6, 7, 10]],
                               [587.04607160, 317.39001517, 0, 587.04607160, 234.30080720, 0, 1])
    for info in (rgb_info, depth_info):
        assert (info.width, info.height, info.distortion_model) == (640, 480, "plumb_bob")
        np.testing.assert_allclose(info.r, np.eye(3).ravel())

    cloud = got["points"][0]
    assert (cloud.width, cloud.height, cloud.point_step) == (640, 480, 16)
    pts = np.asarray(cloud.data).view("<f4").reshape(480, 640, 4)
    z_mm = np.asarray(got["depth"][0].data).view("<u2").reshape(480, 640)[100, 5]
    assert pts[100, 5, 2] == pytest.approx(z_mm / 1000.0, rel=1e-6)
    assert np.isnan(pts[450, 620, 2])


@needs_fakenect
def test_no_cloud_without_subscribers_and_rate_limit(tmp_path: Path, fakenect: Callable[[Path], None],
                                                     run_node: Callable[..., Any]) -> None:
    _pair_dump(tmp_path / "dump", 6, gap_s=0.004)
    fakenect(tmp_path / "dump")
    # six pairs within ~25 ms of replay; at most 15 Hz means published stamps >= 60 ms apart
    # (10 % slack): normally only the first pair, more only if the replay stalls
    node, listener, ex = run_node(points=False, rate=15.0, retry_period=0.05)
    _spin_until(ex, lambda: node.open_attempts >= 2)  # the dump has ended
    ex.spin_until_idle()
    got = listener.got["rgb"]
    assert 1 <= node.pairs_published == len(got)
    ns = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in got]
    assert all(b - a >= 0.9e9 / 15.0 for a, b in zip(ns, ns[1:], strict=False))
    np.testing.assert_array_equal(np.asarray(got[0].data).reshape(480, 640, 3), _rgb_frame(0))
    assert listener.got["points"] == [] and node.points_pub.sequence == 0


@needs_fakenect
def test_lost_device_is_logged_once_and_retried(tmp_path: Path, fakenect: Callable[[Path], None],
                                                run_node: Callable[..., Any],
                                                caplog: pytest.LogCaptureFixture) -> None:
    # fakenect 0.5 reports an error once the dump is exhausted, like an unplugged Kinect
    _pair_dump(tmp_path / "dump", 2)
    fakenect(tmp_path / "dump")
    if _freenect.load_library().freenect_get_depth_mode_count() != 1:
        pytest.skip("this fakenect loops its dump forever: no loss to observe")
    caplog.set_level(logging.INFO)
    node, listener, ex = run_node(retry_period=0.02)
    _spin_until(ex, lambda: node.open_attempts >= 5)
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR and r.name == node.get_name()]
    assert len(errors) == 1, [r.getMessage() for r in errors]
    assert "Kinect 0" in errors[0].getMessage() and "retrying" in errors[0].getMessage()
    # still serving: the LED service answers and the frames before the loss were published
    client = listener.create_client(SetBool, "/kinect_ros2/set_led")
    response = client.call(SetBool.Request(data=False))
    assert response.success
    assert node.get_parameter("led").value == "off"
    assert node.pairs_published == 2
    assert node._thread.is_alive()


@needs_fakenect
def test_frames_of_unexpected_size_are_skipped_with_one_warning(
        tmp_path: Path, fakenect: Callable[[Path], None], run_node: Callable[..., Any],
        caplog: pytest.LogCaptureFixture) -> None:
    dump = _Dump(tmp_path / "dump")
    dump.accel(0)
    dump.close()
    fakenect(tmp_path / "dump")
    node, listener, ex = run_node(retry_period=0.02)
    caplog.set_level(logging.WARNING)
    for k in range(3):
        node.handle_frame("depth", 100 + k, np.zeros((240, 320), np.uint16))
        node.handle_frame("video", 100 + k, np.zeros((240, 320, 3), np.uint8))
    ex.spin_until_idle()
    warnings = [r.getMessage() for r in caplog.records
                if r.levelno == logging.WARNING and "skipping" in r.getMessage()]
    assert len(warnings) == 2  # one per stream
    assert "(240, 320)" in warnings[0] and "(480, 640)" in warnings[0]
    assert node.pairs_published == 0 and listener.got["rgb"] == []


@needs_fakenect
def test_tilt_and_led_parameters(tmp_path: Path, fakenect: Callable[[Path], None],
                                 run_node: Callable[..., Any]) -> None:
    _pair_dump(tmp_path / "dump", 1)
    fakenect(tmp_path / "dump")
    node, _listener, ex = run_node(retry_period=0.02, tilt_angle=5.0, led="red")
    _spin_until(ex, lambda: node.applied_tilt == 5.0 and node.applied_led == _freenect.Led.RED)
    assert not node.set_parameters_atomically([Parameter("tilt_angle", 31.0)]).successful
    assert not node.set_parameters_atomically([Parameter("led", "purple")]).successful
    assert node.set_parameters_atomically([Parameter("tilt_angle", -12.5)]).successful
    assert node.set_parameters_atomically([Parameter("led", "blink_green")]).successful
    # applied by the capture thread on its next pass (or on the next reopen)
    _spin_until(ex, lambda: node.applied_tilt == -12.5
                and node.applied_led == _freenect.Led.BLINK_GREEN)
