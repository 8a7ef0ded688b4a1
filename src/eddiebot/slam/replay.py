"""Replay a CARMEN log or a rosbag2's scans through `SlamCore` and write map, trajectory and
report (io module).

``sync`` processes every scan in order (slam_toolbox's sync mode). ``async`` models the
async node's skip-when-busy policy on the log's clock: a scan that arrives while the
previous one is still being processed (measured processing time) is dropped, so the output
depends on the machine's speed, as it does on a robot.

rosbag2 input: `scans_from_messages` turns decoded bag messages — ``sensor_msgs/LaserScan``
on the scan topic, ``nav_msgs/Odometry`` on the odometry topic or TF ``odom → base`` on
``/tf``, static TF for the laser's mount — into scans with the odometry interpolated at each
scan's header stamp; `check_bag_topics` says which topics to read (or names the missing
one). Opening the bag is the caller's (``eddie slam replay`` uses the project's bag reader).
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import quaternion_to_yaw, se2_interpolate
from eddiebot.maps import OccupancyMap, map_to_image, save_map, write_image
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.errors import SlamError
from eddiebot.slam.io.carmen import LaserRecord, read_carmen
from eddiebot.slam.io.tum import write_tum
from eddiebot.slam.mapper import ProcessStatus, SlamCore
from eddiebot.slam.scan import Scan

__all__ = [
    "LASER_SCAN_TYPE",
    "ODOMETRY_TYPE",
    "TF_TYPE",
    "BagInputError",
    "BagTopics",
    "ReplayResult",
    "ScanLog",
    "check_bag_topics",
    "replay_lasers",
    "replay_log",
    "replay_scans",
    "scans_from_messages",
    "write_outputs",
]

LASER_SCAN_TYPE = "sensor_msgs/msg/LaserScan"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TF_TYPE = "tf2_msgs/msg/TFMessage"

FloatArray = npt.NDArray[np.float64]


@dataclass
class ReplayResult:
    """What a replay produced (poses in the map frame, times in s)."""

    source: str
    mode: str
    core: SlamCore
    scans: int = 0
    dropped_busy: int = 0
    time_backwards: int = 0
    """Scans stamped before the scan read just before them (skipped, and reported)."""
    duration_s: float = 0.0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    warnings: Counter[str] = field(default_factory=Counter)
    first_warnings: list[str] = field(default_factory=list)
    node_stamps_s: list[float] = field(default_factory=list)
    node_records: list[int] = field(default_factory=list)
    """Index into the input records of each processed scan."""
    statuses: Counter[str] = field(default_factory=Counter)
    notes: list[str] = field(default_factory=list)
    """Input details for the report (e.g. where the odometry came from)."""
    scan_cpu_s: list[float] = field(default_factory=list)
    """CPU time of `SlamCore.process` for each processed scan (s)."""

    @property
    def realtime_factor(self) -> float:
        """Log duration / CPU time (one core)."""
        return self.duration_s / self.cpu_s if self.cpu_s > 0 else math.inf

    def trajectory(self) -> tuple[FloatArray, FloatArray]:
        """(stamps s, final poses (N, 3)) of every processed scan."""
        return np.asarray(self.node_stamps_s, dtype=np.float64), self.core.node_poses()


def replay_scans(
    scans: Sequence[Scan],
    odometry: Sequence[npt.ArrayLike],
    config: SlamConfig,
    *,
    mode: str = "sync",
    sensor_offset: npt.ArrayLike = (0.0, 0.0, 0.0),
    source: str = "<scans>",
    progress: Callable[[int], None] | None = None,
    node_time_gate: bool = False,
) -> ReplayResult:
    """Run the core over scans (each with the robot's odometry pose at its stamp).

    ``node_time_gate``: skip a scan stamped less than ``minimum_time_interval`` after the
    last processed one, as the node does (off: every scan goes to the core).
    """
    if mode not in ("sync", "async"):
        raise ValueError(f"mode must be 'sync' or 'async', got {mode!r}")
    if len(odometry) != len(scans):
        raise ValueError(f"{len(scans)} scans but {len(odometry)} odometry poses")
    core = SlamCore(config, sensor_offset=sensor_offset)
    result = ReplayResult(source, mode, core)
    if scans:
        result.duration_s = (scans[-1].stamp_ns - scans[0].stamp_ns) * 1e-9
    busy_until = -math.inf
    gate_ns = config.minimum_time_interval * 1e9 * 0.999 if node_time_gate else 0.0
    last_ns: int | None = None
    newest_ns: int | None = None
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k, scan in enumerate(scans):
        if progress is not None:
            progress(1)
        result.scans += 1
        stamp_s = scan.stamp_ns * 1e-9
        if newest_ns is not None and scan.stamp_ns < newest_ns:
            # before the busy and time gates, which would drop it without a word
            result.time_backwards += 1
            result.warnings["time_backwards"] += 1
            if len(result.first_warnings) < 10:
                result.first_warnings.append(
                    f"scan {k} at {stamp_s:.3f} s is older than the scan before it "
                    f"({newest_ns * 1e-9:.3f} s): skipped"
                )
            continue
        newest_ns = scan.stamp_ns
        if mode == "async" and stamp_s < busy_until:
            result.dropped_busy += 1
            continue
        if last_ns is not None and scan.stamp_ns - last_ns < gate_ns:
            continue
        t0 = time.process_time()
        out = core.process(scan, odometry[k], expected_beams=scan.ranges.size)
        spent = time.process_time() - t0
        busy_until = stamp_s + spent
        result.statuses[out.status.value] += 1
        if out.processed:
            last_ns = scan.stamp_ns
        if out.status is ProcessStatus.ADDED:
            result.scan_cpu_s.append(spent)
            result.node_stamps_s.append(stamp_s)
            result.node_records.append(k)
        for w in out.warnings:
            result.warnings[w.kind] += 1
            if len(result.first_warnings) < 10:
                result.first_warnings.append(w.message)
    result.wall_s = time.perf_counter() - wall0
    result.cpu_s = time.process_time() - cpu0
    return result


def replay_lasers(
    lasers: Sequence[LaserRecord],
    config: SlamConfig,
    *,
    odometry: Sequence[npt.ArrayLike] | None = None,
    mode: str = "sync",
    sensor_offset: npt.ArrayLike = (0.0, 0.0, 0.0),
    source: str = "<records>",
    progress: Callable[[int], None] | None = None,
) -> ReplayResult:
    """Run the core over laser records; ``odometry`` overrides each record's odom pose."""
    scans = [
        Scan(rec.ranges, rec.angles, 0.0, rec.range_max, round(rec.timestamp * 1e9))
        for rec in lasers
    ]
    odom = [rec.odom_pose for rec in lasers] if odometry is None else odometry
    result = replay_scans(
        scans, odom, config, mode=mode, sensor_offset=sensor_offset, source=source,
        progress=progress,
    )
    if lasers:  # the log's own clock (a float; the scans' stamps are rounded to ns)
        result.duration_s = lasers[-1].timestamp - lasers[0].timestamp
        result.node_stamps_s = [lasers[k].timestamp for k in result.node_records]
    return result


def replay_log(
    path: str | os.PathLike[str],
    config: SlamConfig,
    *,
    mode: str = "sync",
    strict: bool = False,
    progress_factory: Callable[[int], Callable[[int], None]] | None = None,
) -> ReplayResult:
    """Read a CARMEN log and replay it (bad lines skipped with warnings unless ``strict``)."""
    log = read_carmen(path, strict=strict)
    offset_x = float(log.params.get("robot_frontlaser_offset", "0") or 0.0)
    progress = progress_factory(len(log.lasers)) if progress_factory is not None else None
    result = replay_lasers(
        log.lasers,
        config,
        mode=mode,
        sensor_offset=(offset_x, 0.0, 0.0),
        source=str(path),
        progress=progress,
    )
    for w in log.warnings:
        result.warnings["bad_line"] += 1
        if len(result.first_warnings) < 10:
            result.first_warnings.append(w)
    return result


class BagInputError(SlamError, ValueError):
    """A bag lacks a topic the replay needs (the message names it), or has it with the
    wrong type."""


@dataclass(frozen=True)
class BagTopics:
    """Which topics of a bag a replay reads."""

    scan: str
    odometry: str
    """The ``nav_msgs/Odometry`` topic, or ``/tf`` (odometry from TF odom → base)."""
    tf_static: tuple[str, ...] = ()

    @property
    def from_tf(self) -> bool:
        return self.odometry == "/tf"

    @property
    def all(self) -> list[str]:
        return [self.scan, self.odometry, *self.tf_static]


def _topic(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def check_bag_topics(
    topics: Mapping[str, str],
    *,
    scan_topic: str = "/scan",
    odom_topic: str | None = None,
    source: str = "bag",
) -> BagTopics:
    """Choose the topics to read from a bag's ``topic → type`` map.

    The scan topic must carry ``sensor_msgs/msg/LaserScan``. Odometry: ``odom_topic`` when
    given (``nav_msgs/msg/Odometry``, or ``/tf``); otherwise ``/odom`` if the bag has it, else
    TF (``/tf``). Raises `BagInputError` naming what is missing.
    """
    listing = ", ".join(f"{t} ({ty})" for t, ty in sorted(topics.items())) or "none"
    scan = _topic(scan_topic)
    if scan not in topics:
        raise BagInputError(
            f"{source}: no scan topic {scan!r} (sensor_msgs/msg/LaserScan); "
            f"the bag has: {listing} — choose one with --scan-topic"
        )
    if topics[scan] != LASER_SCAN_TYPE:
        raise BagInputError(
            f"{source}: topic {scan!r} is {topics[scan]}, not {LASER_SCAN_TYPE}"
        )
    if odom_topic is not None:
        odom = _topic(odom_topic)
        if odom not in topics:
            raise BagInputError(
                f"{source}: no odometry topic {odom!r}; the bag has: {listing}"
            )
        want = TF_TYPE if odom == "/tf" else ODOMETRY_TYPE
        if topics[odom] != want:
            raise BagInputError(f"{source}: topic {odom!r} is {topics[odom]}, not {want}")
    elif topics.get("/odom") == ODOMETRY_TYPE:
        odom = "/odom"
    elif topics.get("/tf") == TF_TYPE:
        odom = "/tf"
    else:
        raise BagInputError(
            f"{source}: no odometry — neither '/odom' (nav_msgs/msg/Odometry) nor '/tf' "
            f"(tf2_msgs/msg/TFMessage) is in the bag; it has: {listing}"
        )
    static = tuple(t for t in ("/tf_static",) if topics.get(t) == TF_TYPE)
    if odom != "/tf" and not static and topics.get("/tf") == TF_TYPE:
        static = ("/tf",)  # no static TF: the mount may be on /tf
    return BagTopics(scan, odom, static)


@dataclass
class ScanLog:
    """Scans read from a bag, each with the robot's odometry pose at its stamp."""

    scans: list[Scan] = field(default_factory=list)
    odometry: list[FloatArray] = field(default_factory=list)
    sensor_offset: FloatArray = field(default_factory=lambda: np.zeros(3))
    scan_frame: str = ""
    odometry_source: str = ""
    scan_messages: int = 0
    odometry_samples: int = 0
    warnings: list[str] = field(default_factory=list)


def _strip(frame: str) -> str:
    return frame[1:] if frame.startswith("/") else frame


def _stamp_ns(header: Any, fallback_ns: int) -> int:
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns > 0 else int(fallback_ns)


def _pose2d(position: Any, orientation: Any) -> tuple[float, float, float]:
    q = orientation
    return (float(position.x), float(position.y),
            float(quaternion_to_yaw(q.x, q.y, q.z, q.w)))


def scans_from_messages(
    messages: Iterable[tuple[str, int, Any]],
    topics: BagTopics,
    *,
    odom_frame: str = "odom",
    base_frame: str = "base_footprint",
    max_odometry_gap_s: float = 0.5,
) -> ScanLog:
    """Scans and interpolated odometry from ``(topic, receive_ns, message)`` in bag order.

    Odometry samples (``nav_msgs/Odometry`` poses, or TF ``odom_frame → base_frame``
    transforms) are stamped by their headers; each scan gets the pose interpolated at its
    header stamp (the receive time when a stamp is zero). A scan outside the odometry's time
    span, or in a gap longer than ``max_odometry_gap_s``, is skipped with one warning. The
    laser's mount (``base_frame → scan frame``) comes from static TF (chains allowed);
    without it the scan is taken at the base, with a warning.
    """
    from eddiebot.core.tf import Buffer

    odom_frame, base_frame = _strip(odom_frame), _strip(base_frame)
    log = ScanLog(odometry_source=(
        f"TF {odom_frame} → {base_frame} on /tf" if topics.from_tf
        else f"nav_msgs/Odometry on {topics.odometry}"))
    raw: list[Scan] = []
    odom_t: list[int] = []
    odom_p: list[tuple[float, float, float]] = []
    mounts = Buffer(cache_time=1e9)
    frames: set[str] = set()
    dynamic_seen: set[str] = set()
    for topic, receive_ns, msg in messages:
        if topic == topics.scan:
            log.scan_messages += 1
            frames.add(_strip(msg.header.frame_id))
            raw.append(Scan.from_laser_scan(msg, _stamp_ns(msg.header, receive_ns)))
            continue
        is_odom_tf = topics.from_tf and topic == topics.odometry
        if topic == topics.odometry and not is_odom_tf:
            odom_t.append(_stamp_ns(msg.header, receive_ns))
            odom_p.append(_pose2d(msg.pose.pose.position, msg.pose.pose.orientation))
            continue
        for tf in getattr(msg, "transforms", ()):
            parent, child = _strip(tf.header.frame_id), _strip(tf.child_frame_id)
            if parent == odom_frame and child == base_frame:
                if is_odom_tf:
                    odom_t.append(_stamp_ns(tf.header, receive_ns))
                    odom_p.append(_pose2d(tf.transform.translation, tf.transform.rotation))
                continue
            if topic == "/tf_static" or child not in dynamic_seen:
                # a mount is static: the first transform of each dynamic child is enough
                mounts.set_transform_static(tf)
                if topic != "/tf_static":
                    dynamic_seen.add(child)
    log.odometry_samples = len(odom_t)
    if not raw:
        raise BagInputError(f"no messages on the scan topic {topics.scan!r}")
    if not odom_t:
        raise BagInputError(
            f"no odometry samples ({log.odometry_source}) — check --odom-topic and the frames "
            f"odom_frame {odom_frame!r} / base_frame {base_frame!r}"
        )
    order = np.argsort(np.asarray(odom_t, dtype=np.int64), kind="stable")
    t = np.asarray(odom_t, dtype=np.int64)[order]
    poses = np.asarray(odom_p, dtype=np.float64)[order]
    gap_ns = round(max_odometry_gap_s * 1e9)
    skipped = 0
    for scan in raw:
        ts = int(scan.stamp_ns)
        j = int(np.searchsorted(t, ts, side="left"))
        if j < t.size and t[j] == ts:
            pose = poses[j]
        elif 0 < j < t.size and t[j] - t[j - 1] <= gap_ns:
            frac = (ts - t[j - 1]) / (t[j] - t[j - 1])
            pose = se2_interpolate(poses[j - 1], poses[j], float(frac))
        else:
            skipped += 1
            continue
        log.scans.append(scan)
        log.odometry.append(np.asarray(pose, dtype=np.float64).copy())
    if skipped:
        log.warnings.append(
            f"{skipped} of {len(raw)} scans skipped: no odometry within "
            f"{max_odometry_gap_s} s around their stamps"
        )
    log.scan_frame = sorted(frames)[0] if frames else ""
    if len(frames) > 1:
        log.warnings.append(f"scans in several frames {sorted(frames)}; using {log.scan_frame}'s mount")
    if log.scan_frame and log.scan_frame != base_frame:
        try:
            log.sensor_offset = np.array(mounts.lookup_pose2d(base_frame, log.scan_frame, 0))
        except Exception as exc:
            log.warnings.append(
                f"no static transform {base_frame} → {log.scan_frame} ({exc}); "
                "taking the scans at the base"
            )
    return log


def _percentiles_ms(values: Sequence[float]) -> str:
    if not values:
        return "-"
    v = 1e3 * np.asarray(values, dtype=np.float64)
    return (f"median {np.median(v):.1f} ms, p99 {np.percentile(v, 99):.1f} ms, "
            f"max {v.max():.1f} ms")


def _render(grid: OccupancyMap, poses: FloatArray) -> npt.NDArray[np.uint8]:
    import cv2

    img = cv2.cvtColor(map_to_image(grid), cv2.COLOR_GRAY2BGR)
    if poses.shape[0] > 1:
        res = grid.resolution
        h = grid.height
        cols = ((poses[:, 0] - grid.origin[0]) / res).astype(np.int32)
        rows = (h - 1 - (poses[:, 1] - grid.origin[1]) / res).astype(np.int32)
        pts = np.stack([cols, rows], axis=-1).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], False, (40, 40, 220), 1, cv2.LINE_AA)
    return np.asarray(img, dtype=np.uint8)


def write_outputs(
    result: ReplayResult, out_dir: str | os.PathLike[str], name: str = "map"
) -> dict[str, Path]:
    """Map (PGM + YAML + PNG), TUM trajectory and a Markdown report into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.process_time()
    grid = result.core.occupancy_map()
    map_s = time.process_time() - t0
    yaml_path = save_map(grid, out / name)
    stamps, poses = result.trajectory()
    png = out / f"{name}.png"
    write_image(png, _render(grid, poses))
    tum = out / "trajectory.tum"
    write_tum(tum, stamps, poses)
    core = result.core
    lines = [
        f"# SLAM replay of `{Path(result.source).name}`",
        "",
        f"![map]({png.name})",
        "",
        "| | |",
        "|---|---|",
        f"| input | `{result.source}` |",
        f"| mode | {result.mode} (core mode {core.mode}) |",
        f"| log duration | {result.duration_s:.1f} s |",
        f"| scans read | {result.scans} |",
        f"| scans processed (nodes) | {len(core.nodes)} |",
        f"| dropped while busy (async) | {result.dropped_busy} |",
        f"| skipped: time went backwards | {result.time_backwards} |",
        f"| statuses | {', '.join(f'{k} {v}' for k, v in sorted(result.statuses.items()))} |",
        f"| loop closures | {len(core.loop_closures)} |",
        f"| processing time | {result.cpu_s:.2f} s CPU, {result.wall_s:.2f} s wall |",
        f"| real-time factor (CPU) | {result.realtime_factor:.1f}× |",
        f"| CPU per processed scan | {_percentiles_ms(result.scan_cpu_s)} |",
        f"| map | {grid.width} × {grid.height} cells at {grid.resolution} m, built in {map_s:.2f} s |",
        f"| graph ½χ² | {core.graph.half_chi2():.3f} |",
        f"| trajectory | `{tum.name}` (TUM, one line per processed scan) |",
        "",
    ]
    if result.notes:
        lines += ["## Input", "", *[f"- {n}" for n in result.notes], ""]
    if result.warnings:
        lines += [
            "## Warnings",
            "",
            *[f"- {k}: {v}" for k, v in sorted(result.warnings.items())],
            "",
        ]
        lines += ["First messages:", "", *[f"- {m}" for m in result.first_warnings], ""]
    report = out / "report.md"
    report.write_text("\n".join(lines), encoding="utf-8")
    return {"yaml": yaml_path, "png": png, "trajectory": tum, "report": report}
