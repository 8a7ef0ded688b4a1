"""Localization mode on real logs: tracking error against a map built from the log's first
part, and global relocalisation's success rate.

For each log: the first ``--map-share`` of its scans (default 0.5) are mapped (sync, upstream
sample parameters, config/slam_defaults.yaml); the session is serialized, loaded back in
localization mode, and the *rest* of the log is localised against it — with degraded odometry
(benchmarks/degrade_odometry.py, seed 1: 5 % distance, 3°/m heading noise, four 0.3 m / 15°
slips) on the corrected Intel and ACES logs, with the raw odometry on the MIT CSAIL log.
``max_odometry_jump`` is 2 m: the corrected logs hold one scan per ~0.6 m of travel, up to
1.3 m on Intel, which the 1 m default would take for odometry jumps.

Reference: Intel and ACES, the corrected laser poses (GMapping's output, 0.05–0.07 m off the
true relations per Kümmerle et al. 2009); CSAIL, the poses of a mapping run over the whole log
(node poses; only localised scans that are nodes of that run are scored). Where the robot
truly is in the map's frame is taken two ways: ``pos_*`` through the one SE(2) that best fits
the map's node poses onto their reference poses (this includes the map's own distortion, its
``map_ate_rmse_m``), ``local_pos_*`` through the map node nearest in the reference — that
node's map pose composed with the reference relation from it to the scan, i.e. where the map
as built says the robot is. The localisation starts from that pose of its first scan (an
operator's ``/initialpose``).

Set-ups: ``buffer`` (slam_toolbox's rolling buffer, the default), ``map only`` (each scan
matched against the map's nodes alone), ``odometry`` (the start pose carried by odometry, no
matching) and ``kidnapped`` (started at the map's middle node instead: how many processed
scans until the pose first comes within 0.3 m, ``back_after_scans``, and until it is within
0.3 m for good, ``recovered_after_scans``). Figures: position
error of every localised scan (median, 95th percentile, share within 0.2 m), heading error,
weak matches, global relocalisations, CPU per scan.

Relocalisation: ``--reloc`` scans spread evenly over the localised part whose reference pose
lies within 1 m of a map node, each searched over the whole map with no prior
(`SlamCore.relocalize`); ``correct``: within 0.3 m and 3° of the local truth. Figures: the
share accepted, accepted and correct, accepted but wrong (a false relocalisation), the median
fine response and the CPU time per search.

    python benchmarks/bench_slam_localization.py [intel] [aces] [csail] [--reloc 40]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import DATASETS, print_table, write_results
from degrade_odometry import degrade_odometry

from eddiebot.geometry import se2_between, se2_compose, se2_inverse, wrap_angle
from eddiebot.slam import load_slam_config
from eddiebot.slam.io import read_carmen
from eddiebot.slam.mapper import ProcessStatus, SlamCore
from eddiebot.slam.relocalization_process import RelocalizationProcess
from eddiebot.slam.replay import replay_lasers
from eddiebot.slam.scan import Scan, scan_points
from eddiebot.slam.session import load_session, save_session

LOGS = {
    "intel": DATASETS / "slam2d" / "intel" / "intel-corrected.log.gz",
    "aces": DATASETS / "slam2d" / "aces" / "aces-corrected.log.gz",
    "csail": DATASETS / "slam2d" / "mit-csail" / "mit-csail.clf",
}
CONFIG = Path(__file__).resolve().parents[1] / "config" / "slam_defaults.yaml"
PROCESS = " (search in a process)"


def fit_se2(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The SE(2) pose T with T ∘ src ≈ dst in position (least squares)."""
    a, b = src[:, :2], dst[:, :2]
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    r = vt.T @ u.T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = vt.T @ u.T
    t = cb - r @ ca
    return np.array([t[0], t[1], math.atan2(r[1, 0], r[0, 0])])


def _scans(lasers: list[Any]) -> list[Scan]:
    return [
        Scan(r.ranges, r.angles, 0.0, r.range_max, round(r.timestamp * 1e9)) for r in lasers
    ]


def localize(
    core: SlamCore, scans: list[Scan], odom: np.ndarray, start: np.ndarray, variant: str
) -> tuple[dict[int, np.ndarray], dict[str, float]]:
    """Localise ``scans`` from ``start`` (map frame); the pose of each processed scan."""
    core.set_initial_pose(start, odom[0])
    if variant == "map only":
        core._buffer_reference = lambda: None  # type: ignore[method-assign]
    search = RelocalizationProcess() if variant.endswith(PROCESS) else None
    core.global_search = search
    poses: dict[int, np.ndarray] = {}
    counts = {"weak": 0, "relocalized": 0, "lost": 0}
    cpu: list[float] = []
    seen: dict[int, int] = {}  # scan stamp → processed scans before it
    delays: list[int] = []  # processed scans from a searched scan to its answer
    last = -1
    try:
        for k, scan in enumerate(scans):
            if scan.stamp_ns <= last:
                continue
            if search is not None and search.busy() and last >= 0:
                # a search in flight: the log's own time passes before this scan comes
                search.wait(1e-9 * (scan.stamp_ns - last))
            last = scan.stamp_ns
            if variant == "odometry":
                poses[k] = se2_compose(start, se2_between(odom[0], odom[k]))
                continue
            t0 = time.process_time()
            attempts = len(core.relocalizations)
            r = core.process(scan, odom[k], expected_beams=scan.ranges.size)
            t1 = time.process_time()
            seen[scan.stamp_ns] = len(cpu)
            delays += [len(cpu) - seen[a.stamp_ns] for a in core.relocalizations[attempts:]]
            if r.pose is None and r.status is not ProcessStatus.LOST:
                continue
            cpu.append(t1 - t0)
            if r.pose is None:
                counts["lost"] += 1
                continue
            poses[k] = r.pose
            kinds = {w.kind for w in r.warnings}
            counts["weak"] += "weak_match" in kinds or "off_map" in kinds
            counts["relocalized"] += "relocalized" in kinds
    finally:
        if search is not None:
            search.close()
    if variant != "odometry":
        ms = 1e3 * np.array(cpu or [0.0])
        counts["cpu_ms_per_scan"] = float(ms.mean())
        counts["cpu_ms_p95"] = float(np.percentile(ms, 95))
        counts["cpu_ms_max"] = float(ms.max())
        counts["reloc_attempts"] = len(core.relocalizations)
        counts["answer_delay_scans"] = float(np.median(delays)) if delays else 0.0
        counts["search_cpu_ms_per_scan"] = (
            1e3 * sum(search.search_cpu_s) / max(len(cpu), 1) if search is not None else 0.0
        )
    return poses, counts


class MapTruth:
    """Where the robot truly is, in the map's frame: ``global_`` through the one SE(2) that
    fits the map onto the reference; ``local`` through the map node nearest in the reference
    (that node's map pose ∘ the reference relation from it): what a map with its own
    distortions (a sheared ACES) says the pose is there."""

    def __init__(self, node_poses: np.ndarray, node_ref: np.ndarray, to_ref: np.ndarray) -> None:
        ok = np.all(np.isfinite(node_ref), axis=1)
        self.est, self.ref = node_poses[ok], node_ref[ok]
        self.to_map = se2_inverse(to_ref)

    def global_(self, r: np.ndarray) -> np.ndarray:
        return se2_compose(self.to_map, r)

    def local(self, r: np.ndarray) -> np.ndarray:
        j = int(np.argmin(np.hypot(*(self.ref[:, :2] - r[:2]).T)))
        return se2_compose(self.est[j], se2_between(self.ref[j], r))

    def near(self, r: np.ndarray, dist: float) -> bool:
        return bool(np.min(np.hypot(*(self.ref[:, :2] - r[:2]).T)) <= dist)


def errors(poses: dict[int, np.ndarray], ref: np.ndarray, truth: MapTruth) -> dict[str, float]:
    keys = sorted(k for k in poses if np.all(np.isfinite(ref[k])))
    out: dict[str, float] = {"scored": len(keys)}
    for label, where in (("", truth.global_), ("local_", truth.local)):
        t = np.array([where(ref[k]) for k in keys])
        e = np.array([poses[k] for k in keys])
        d = np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1])
        a = np.degrees(np.abs(wrap_angle(e[:, 2] - t[:, 2])))
        out.update({
            f"{label}pos_median_m": float(np.median(d)),
            f"{label}pos_p95_m": float(np.percentile(d, 95)),
            f"{label}within_0.2m": float(np.mean(d <= 0.2)),
            f"{label}head_median_deg": float(np.median(a)),
            f"{label}head_p95_deg": float(np.percentile(a, 95)),
        })
    return out


VARIANTS = ("buffer", f"buffer{PROCESS}", "map only", "odometry", "kidnapped", f"kidnapped{PROCESS}")


def run_one(
    name: str, map_share: float, n_reloc: int, variants: tuple[str, ...] = VARIANTS
) -> list[dict[str, Any]]:
    log = read_carmen(LOGS[name])
    lasers = log.lasers
    # the corrected logs hold one scan per ~0.6 m of travel (up to 1.3 m on Intel): above
    # max_odometry_jump's 1 m default, which would re-anchor them as jumps
    config = dataclasses.replace(load_slam_config(CONFIG), max_odometry_jump=2.0)
    if name == "csail":
        offset = (float(log.params.get("robot_frontlaser_offset", "0") or 0.0), 0.0, 0.0)
        odom = np.array([r.odom_pose for r in lasers])
        full = replay_lasers(lasers, config, sensor_offset=offset)
        ref = np.full((len(lasers), 3), np.nan)
        ref[np.asarray(full.node_records)] = full.core.node_poses()
    else:
        offset = (0.0, 0.0, 0.0)
        ref = np.array([r.laser_pose for r in lasers])
        odom = degrade_odometry(ref, seed=1)
    split = int(len(lasers) * map_share)
    mapped = replay_lasers(lasers[:split], config, odometry=list(odom[:split]), sensor_offset=offset)
    idx = np.asarray(mapped.node_records)
    node_poses = mapped.core.node_poses()
    ok = np.all(np.isfinite(ref[idx]), axis=1)
    to_ref = fit_se2(node_poses[ok], ref[idx][ok])
    truth = MapTruth(node_poses, ref[idx], to_ref)
    fitted = np.array([se2_compose(to_ref, p) for p in node_poses[ok]])
    map_ate = float(np.sqrt(np.mean(np.sum((fitted[:, :2] - ref[idx][ok][:, :2]) ** 2, axis=1))))
    with tempfile.TemporaryDirectory() as tmp:
        path = save_session(mapped.core, Path(tmp) / "map.eslam")
        sessions = {v: load_session(path, mode="localization") for v in (*variants, "reloc")}
    scans = _scans(lasers[split:])
    rest_odom = odom[split:]
    rest_ref = ref[split:]
    first = int(np.flatnonzero(np.all(np.isfinite(rest_ref), axis=1))[0])
    start = se2_compose(truth.local(rest_ref[first]), se2_between(rest_odom[first], rest_odom[0]))
    rows: list[dict[str, Any]] = []
    for variant in variants:
        at = start
        if variant.startswith("kidnapped"):  # told it stands where the map's middle node is
            at = node_poses[len(node_poses) // 2]
        poses, counts = localize(sessions[variant], scans, rest_odom, at, variant)
        row = {"log": name, "variant": variant, "map_nodes": len(idx), "scans": len(scans),
               "map_ate_rmse_m": map_ate}
        row.update(errors(poses, rest_ref, truth))
        if variant != "odometry":
            row.update(counts)
        if variant.startswith("kidnapped"):
            row["back_after_scans"] = first_back(poses, rest_ref, truth)
            row["recovered_after_scans"] = recovery(poses, rest_ref, truth)
        rows.append(row)
    if n_reloc:
        rows.append(relocalization(name, sessions["reloc"], scans, rest_ref, truth, n_reloc,
                                   config.max_laser_range))
    return rows


def first_back(poses: dict[int, np.ndarray], ref: np.ndarray, truth: MapTruth) -> int | None:
    """Processed scans before the pose first comes within 0.3 m of the truth (local)."""
    keys = sorted(k for k in poses if np.all(np.isfinite(ref[k])))
    for n, k in enumerate(keys):
        if np.hypot(*(poses[k][:2] - truth.local(ref[k])[:2])) <= 0.3:
            return n
    return None


def recovery(poses: dict[int, np.ndarray], ref: np.ndarray, truth: MapTruth) -> int | None:
    """Processed scans before the pose comes within 0.3 m of the truth (local) for good."""
    keys = sorted(k for k in poses if np.all(np.isfinite(ref[k])))
    bad = [
        n for n, k in enumerate(keys)
        if np.hypot(*(poses[k][:2] - truth.local(ref[k])[:2])) > 0.3
    ]
    if not bad:
        return 0
    return bad[-1] + 1 if bad[-1] + 1 < len(keys) else None


def relocalization(
    name: str, core: SlamCore, scans: list[Scan], ref: np.ndarray, truth: MapTruth, n: int,
    max_range: float,
) -> dict[str, Any]:
    near = np.array([bool(np.all(np.isfinite(r))) and truth.near(r, 1.0) for r in ref])
    cand = np.flatnonzero(near)
    pick = cand[np.linspace(0, cand.size - 1, min(n, cand.size)).round().astype(int)]
    accepted = correct = 0
    responses = []
    cpu = 0.0
    core.relocalize(scan_points(scans[pick[0]], max_range))  # the global grid, built once
    for k in pick:
        pts = scan_points(scans[k], max_range)
        t0 = time.process_time()
        found = core.relocalize(pts)
        cpu += time.process_time() - t0
        responses.append(found.response)
        t = truth.local(ref[k])
        err = np.hypot(*(found.pose[:2] - t[:2]))
        dth = abs(float(wrap_angle(found.pose[2] - t[2])))
        if found.accepted:
            accepted += 1
            correct += err <= 0.3 and dth <= math.radians(3.0)
    return {
        "log": name,
        "variant": "relocalisation",
        "tries": int(pick.size),
        "accepted": accepted / pick.size,
        "accepted_correct": correct / pick.size,
        "accepted_wrong": (accepted - correct) / pick.size,
        "response_median": float(np.median(responses)),
        "cpu_ms_per_search": 1e3 * cpu / pick.size,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("logs", nargs="*", metavar="LOG",
                        help=f"logs to run: {', '.join(LOGS)} (default: all)")
    parser.add_argument("--map-share", type=float, default=0.5,
                        help="share of the log's scans mapped before localising the rest")
    parser.add_argument("--reloc", type=int, default=40, help="relocalisation tries per log")
    parser.add_argument("--name", default="slam_localization", help="results file name")
    parser.add_argument("--variants", default=",".join(VARIANTS),
                        help="comma-separated set-ups to run (default: all)")
    args = parser.parse_args()
    unknown = [n for n in args.logs if n not in LOGS]
    if unknown:
        parser.error(f"unknown log {', '.join(unknown)} (choose from {', '.join(LOGS)})")
    variants = tuple(v.strip() for v in args.variants.split(",") if v.strip())
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        parser.error(f"--variants: unknown {', '.join(bad)} (choose from {', '.join(VARIANTS)})")
    if not 0.05 <= args.map_share <= 0.95:
        parser.error(f"--map-share {args.map_share}: must lie in [0.05, 0.95]")
    rows: list[dict[str, Any]] = []
    for n in args.logs or list(LOGS):
        if LOGS[n].exists():
            rows += run_one(n, args.map_share, args.reloc, variants)
    track = [r for r in rows if r["variant"] != "relocalisation"]
    print_table(track, ["log", "variant", "map_ate_rmse_m", "scored", "pos_median_m", "pos_p95_m",
                        "local_pos_median_m", "local_pos_p95_m", "local_within_0.2m",
                        "local_head_median_deg", "local_head_p95_deg", "weak", "relocalized",
                        "back_after_scans", "recovered_after_scans", "reloc_attempts", "cpu_ms_per_scan",
                        "cpu_ms_p95", "cpu_ms_max", "search_cpu_ms_per_scan",
                        "answer_delay_scans"])
    print()
    print_table([r for r in rows if r["variant"] == "relocalisation"],
                ["log", "tries", "accepted", "accepted_correct", "accepted_wrong",
                 "response_median", "cpu_ms_per_search"])
    print(write_results(args.name, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
