"""The ``rtabmap`` node's input side: RGB, depth, camera_info, scan and odometry paired by
stamp (``approx_sync``), throttled by ``Rtabmap/DetectionRate``, held until TF odometry covers
the image stamp (``wait_for_transform``), then handed to the node's ``_process``; and, for
replays, every input colour frame's place recorded in a `FrameTrack` (throttled frames with
their TF odometry, dropped ones as lost)."""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from eddiebot.core.node import Node
from eddiebot.core.tf import Buffer
from eddiebot.core.time import stamp_to_ns
from eddiebot.geometry import se3_from_tq
from eddiebot.vslam.frame_track import FrameTrack
from eddiebot.vslam.rtabmap import Rtabmap
from eddiebot.vslam.transforms import to_3dof

__all__ = ["RgbdSync", "tf_matrix"]

_SEC = 1_000_000_000


def tf_matrix(tf: Any) -> np.ndarray:
    """A TransformStamped as a 4×4 matrix."""
    t = tf.transform.translation
    q = tf.transform.rotation
    return se3_from_tq((t.x, t.y, t.z), (q.x, q.y, q.z, q.w))


class RgbdSync(Node):
    """Synchronisation of the ``rtabmap`` node's inputs (a base of `RtabmapNode`, which sets
    the attributes below and processes a synchronised set in `_process`)."""

    core: Rtabmap
    tf_buffer: Buffer
    frame_id: str
    odom_frame_id: str
    subscribe_depth: bool
    subscribe_scan: bool
    approx_sync: bool
    approx_sync_max_interval: float
    sync_queue_size: int
    wait_for_transform: float
    odom_stamp_offset: float
    paused: bool
    frame_track: FrameTrack | None
    _last_processed_ns: int | None

    def _init_sync(self) -> None:
        """Empty queues, sized by ``sync_queue_size``."""
        n = max(1, self.sync_queue_size)
        self._warned: set[str] = set()
        self._rgb: deque[Any] = deque(maxlen=n)
        self._depth: deque[Any] = deque(maxlen=n)
        self._scans: deque[Any] = deque(maxlen=n)
        self._odom: deque[Any] = deque(maxlen=max(10, 4 * self.sync_queue_size))
        self._rgb_info: deque[Any] = deque(maxlen=5)
        self._depth_info: deque[Any] = deque(maxlen=5)
        self._pending: deque[tuple[int, Any, Any | None]] = deque(maxlen=n)
        self._unprocessed: deque[int] = deque()  # throttled frames' stamps, for frame_track
        self._last_set_ns: int | None = None
        self._static: dict[tuple[str, str], np.ndarray] = {}

    def _process(self, t: int, img: Any, depth_msg: Any | None, scan_msg: Any | None) -> bool:
        """Process one synchronised set (the node's); False when it was skipped."""
        raise NotImplementedError

    # -- warnings --------------------------------------------------------------------------
    def _warn_once(self, kind: str, text: str) -> None:
        if kind not in self._warned:
            self._warned.add(kind)
            self.get_logger().warning(f"{text} (further '{kind}' warnings suppressed)")

    # -- synchronisation -------------------------------------------------------------------
    @property
    def _odom_offset_ns(self) -> int:
        return round(self.odom_stamp_offset * _SEC)

    @property
    def _tolerance_ns(self) -> int:
        return round(self.approx_sync_max_interval * _SEC) if self.approx_sync else 0

    def _on_rgb(self, msg: Any) -> None:
        if self.paused:
            return
        self._rgb.append(msg)
        self._sync()

    def _on_depth(self, msg: Any) -> None:
        if self.paused:
            return
        self._depth.append(msg)
        self._sync()

    def _on_scan(self, msg: Any) -> None:
        self._scans.append(msg)

    def _sync(self) -> None:
        tol = self._tolerance_ns
        rate = self.core.params.rtabmap_detection_rate
        period = round(_SEC / rate) if rate > 0 else 0
        while self._rgb:
            img = self._rgb[0]
            t = stamp_to_ns(img.header.stamp)
            depth = None
            if self.subscribe_depth:
                if not self._depth:
                    return
                best = min(self._depth, key=lambda d: abs(stamp_to_ns(d.header.stamp) - t))
                if abs(stamp_to_ns(best.header.stamp) - t) > tol:
                    if stamp_to_ns(self._depth[-1].header.stamp) > t + tol:
                        self._rgb.popleft()
                        self._warn_once("no_depth", "an image has no depth image within "
                                        f"{tol / 1e9:.3f} s of its stamp: skipped")
                        self._frame_lost(t)
                        continue
                    return  # its depth may still come
                depth = best
                while self._depth and stamp_to_ns(self._depth[0].header.stamp) <= stamp_to_ns(
                        best.header.stamp):
                    self._depth.popleft()
            self._rgb.popleft()
            if self._last_set_ns is not None and t < self._last_set_ns:
                self._warn_once("time_backwards",
                                "image time went backwards (bag restarted?): skipped")
                self._frame_lost(t)
                continue
            # Rtabmap/DetectionRate: drop sets closer than 1/rate to the last kept one
            if self._last_set_ns is not None and period and t - self._last_set_ns < period * 0.999:
                if self.frame_track is not None:
                    self._unprocessed.append(t)
                continue
            self._last_set_ns = t
            self._pending.append((t, img, depth))

    def _drain(self) -> None:
        now = self.get_clock().now_ns()
        wait = round(self.wait_for_transform * _SEC)
        if self.frame_track is not None:
            self._place_unprocessed(now, wait)
        while self._pending:
            t, img, depth = self._pending[0]
            ready = self.tf_buffer.can_transform(self.odom_frame_id, self.frame_id,
                                                 t + self._odom_offset_ns)
            scan = self._match_scan(t) if self.subscribe_scan else None
            if not ready or (self.subscribe_scan and scan is None):
                if now - t <= wait:
                    return  # wait for newer odometry (or the scan)
                if not ready:
                    self._pending.popleft()
                    self._warn_once("no_odom_tf",
                                    f"no transform {self.odom_frame_id} → {self.frame_id} at an "
                                    f"image's time within {self.wait_for_transform} s: frame dropped")
                    self._frame_lost(t)
                    continue
                self._warn_once("no_scan", "no scan near an image's time: processed without it")
            self._pending.popleft()
            try:
                processed = self._process(t, img, depth, scan)
            except Exception as exc:  # one bad frame must not stop the node
                self._warn_once(f"error_{type(exc).__name__}", f"frame skipped: {exc}")
                processed = self._last_processed_ns == t  # failed after the core took it
            if not processed:
                self._frame_lost(t)

    def _frame_lost(self, t: int) -> None:
        if self.frame_track is not None:
            self.frame_track.lost_frame(t / _SEC)

    def _core_odometry(self, odom: np.ndarray) -> np.ndarray:
        """The odometry pose as the core uses it (3-DoF with ``Reg/Force3DoF``)."""
        return to_3dof(odom) if self.core.params.reg_force_3dof else odom

    def _place_unprocessed(self, now: int, wait: int) -> None:
        """Frames ``Rtabmap/DetectionRate`` kept from the core, into `frame_track` with their
        TF odometry (lost without it within ``wait_for_transform``)."""
        assert self.frame_track is not None
        while self._unprocessed:
            t = self._unprocessed[0]
            ts = t + self._odom_offset_ns
            if self.tf_buffer.can_transform(self.odom_frame_id, self.frame_id, ts):
                if self._odometry_state(t) == "lost":
                    self.frame_track.lost_frame(t / _SEC)
                else:
                    odom = tf_matrix(self.tf_buffer.lookup_transform(
                        self.odom_frame_id, self.frame_id, ts))
                    self.frame_track.skipped(t / _SEC, self._core_odometry(odom))
            elif now - t > wait:
                self.frame_track.lost_frame(t / _SEC)
            else:
                return
            self._unprocessed.popleft()

    def _match_scan(self, t: int) -> Any | None:
        if not self._scans:
            return None
        best = min(self._scans, key=lambda s: abs(stamp_to_ns(s.header.stamp) - t))
        if abs(stamp_to_ns(best.header.stamp) - t) <= max(self._tolerance_ns, 1):
            return best
        return None

    def _static_tf(self, target: str, source: str) -> np.ndarray | None:
        key = (target, source)
        if key not in self._static:
            try:
                self._static[key] = tf_matrix(self.tf_buffer.lookup_transform(target, source, 0))
            except Exception as exc:
                self._warn_once(f"no_tf_{source}", f"no transform {target} → {source}: {exc}")
                return None
        return self._static[key]

    def _info_for(self, infos: deque[Any], t: int, frame: str) -> Any | None:
        cands = [i for i in infos if not frame or i.header.frame_id == frame] or list(infos)
        if not cands:
            return None
        return min(cands, key=lambda i: abs(stamp_to_ns(i.header.stamp) - t))

    def _odometry_state(self, t: int) -> str:
        """What the /odom message nearest `t` says: ``lost`` (null pose, as rtabmap_odom
        publishes it), ``reset`` (a pose with covariance 9999: re-initialised, the next node
        starts a new map) or ``ok``."""
        if not self._odom:
            return "ok"
        msg = min(self._odom, key=lambda m: abs(stamp_to_ns(m.header.stamp) - t))
        if abs(stamp_to_ns(msg.header.stamp) - t) > _SEC // 2:
            return "ok"
        q = msg.pose.pose.orientation
        cov = np.asarray(msg.pose.covariance, dtype=np.float64)
        if q.x == 0.0 and q.y == 0.0 and q.z == 0.0 and q.w == 0.0:
            return "lost"
        return "reset" if cov.size and cov[0] >= 9999.0 else "ok"

