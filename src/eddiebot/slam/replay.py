"""Replay a CARMEN log through `SlamCore` and write map, trajectory and report (io module).

``sync`` processes every scan in order (slam_toolbox's sync mode). ``async`` models the
async node's skip-when-busy policy on the log's clock: a scan that arrives while the
previous one is still being processed (measured processing time) is dropped, so the output
depends on the machine's speed, as it does on a robot.
"""

from __future__ import annotations

import math
import os
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from eddiebot.maps import OccupancyMap, map_to_image, save_map, write_image
from eddiebot.slam.config import SlamConfig
from eddiebot.slam.io.carmen import LaserRecord, read_carmen
from eddiebot.slam.io.tum import write_tum
from eddiebot.slam.mapper import ProcessStatus, SlamCore
from eddiebot.slam.scan import Scan

__all__ = ["ReplayResult", "replay_lasers", "replay_log", "write_outputs"]

FloatArray = npt.NDArray[np.float64]


@dataclass
class ReplayResult:
    """What a replay produced (poses in the map frame, times in s)."""

    source: str
    mode: str
    core: SlamCore
    scans: int = 0
    dropped_busy: int = 0
    duration_s: float = 0.0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    warnings: Counter[str] = field(default_factory=Counter)
    first_warnings: list[str] = field(default_factory=list)
    node_stamps_s: list[float] = field(default_factory=list)
    node_records: list[int] = field(default_factory=list)
    """Index into the input records of each processed scan."""
    statuses: Counter[str] = field(default_factory=Counter)

    @property
    def realtime_factor(self) -> float:
        """Log duration / CPU time (one core)."""
        return self.duration_s / self.cpu_s if self.cpu_s > 0 else math.inf

    def trajectory(self) -> tuple[FloatArray, FloatArray]:
        """(stamps s, final poses (N, 3)) of every processed scan."""
        return np.asarray(self.node_stamps_s, dtype=np.float64), self.core.node_poses()


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
    if mode not in ("sync", "async"):
        raise ValueError(f"mode must be 'sync' or 'async', got {mode!r}")
    core = SlamCore(config, sensor_offset=sensor_offset)
    result = ReplayResult(source, mode, core)
    if lasers:
        result.duration_s = lasers[-1].timestamp - lasers[0].timestamp
    busy_until = -math.inf
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k, rec in enumerate(lasers):
        if progress is not None:
            progress(1)
        result.scans += 1
        if mode == "async" and rec.timestamp < busy_until:
            result.dropped_busy += 1
            continue
        odom = rec.odom_pose if odometry is None else odometry[k]
        scan = Scan(rec.ranges, rec.angles, 0.0, rec.range_max, round(rec.timestamp * 1e9))
        t0 = time.process_time()
        out = core.process(scan, odom, expected_beams=rec.ranges.size)
        busy_until = rec.timestamp + (time.process_time() - t0)
        result.statuses[out.status.value] += 1
        if out.status is ProcessStatus.ADDED:
            result.node_stamps_s.append(rec.timestamp)
            result.node_records.append(k)
        for w in out.warnings:
            result.warnings[w.kind] += 1
            if len(result.first_warnings) < 10:
                result.first_warnings.append(w.message)
    result.wall_s = time.perf_counter() - wall0
    result.cpu_s = time.process_time() - cpu0
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
        f"| statuses | {', '.join(f'{k} {v}' for k, v in sorted(result.statuses.items()))} |",
        f"| loop closures | {len(core.loop_closures)} |",
        f"| processing time | {result.cpu_s:.2f} s CPU, {result.wall_s:.2f} s wall |",
        f"| real-time factor (CPU) | {result.realtime_factor:.1f}× |",
        f"| map | {grid.width} × {grid.height} cells at {grid.resolution} m, built in {map_s:.2f} s |",
        f"| graph ½χ² | {core.graph.half_chi2():.3f} |",
        f"| trajectory | `{tum.name}` (TUM, one line per processed scan) |",
        "",
    ]
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
