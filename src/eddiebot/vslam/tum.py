"""TUM RGB-D benchmark folders: reading, association (as TUM's associate.py), trajectories, ATE.

A sequence folder holds ``rgb.txt``, ``depth.txt`` (``timestamp filename`` lines, ``#``
comments), the images, and optionally ``groundtruth.txt`` (``t tx ty tz qx qy qz qw``). Depth PNGs
are 16-bit with 5000 units per metre. This is an explicit I/O module.
"""

from __future__ import annotations

import bisect
import os
import re
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.errors import TumFormatError
from eddiebot.vslam.transforms import OPTICAL_ROTATION, fit_rigid

__all__ = [
    "TUM_CALIBRATIONS",
    "TUM_DEPTH_SCALE",
    "TumFrame",
    "TumSequence",
    "absolute_trajectory_error",
    "associate",
    "load_tum_frame",
    "matrix_to_tum_row",
    "read_file_list",
    "read_tum_sequence",
    "read_tum_trajectory",
    "tum_camera",
    "tum_row_to_matrix",
    "write_tum_trajectory",
]

TUM_DEPTH_SCALE = 5000.0
F64 = NDArray[np.float64]

# Per-sequence calibrations from the TUM RGB-D site (fx, fy, cx, cy); 525/319.5/239.5 otherwise.
TUM_CALIBRATIONS = {
    "freiburg1": (517.3, 516.5, 318.6, 255.3),
    "freiburg2": (520.9, 521.0, 325.1, 249.7),
    "freiburg3": (535.4, 539.2, 320.1, 247.6),
}


def read_file_list(path: str | Path) -> dict[float, list[str]]:
    """``timestamp data...`` lines as {stamp: [data...]} (commas/tabs as spaces, ``#`` comments)."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise TumFormatError(f"{path}: {exc}") from exc
    out: dict[float, list[str]] = {}
    for line in text.replace(",", " ").replace("\t", " ").split("\n"):
        if not line or line[0] == "#":
            continue
        fields = [v.strip() for v in line.split(" ") if v.strip() != ""]
        if len(fields) > 1:
            try:
                out[float(fields[0])] = fields[1:]
            except ValueError as exc:
                raise TumFormatError(f"{path}: bad timestamp in {line!r}") from exc
    return out


def associate(
    first: Iterable[float], second: Iterable[float], offset: float = 0.0,
    max_difference: float = 0.02,
) -> list[tuple[float, float]]:
    """Greedy one-to-one matching by increasing |a − (b + offset)| < max_difference, as associate.py.

    Candidate pairs are sorted by (difference, a, b) and taken when both stamps are still free;
    the result is sorted by the first stamp.
    """
    a_keys = sorted(set(first))
    b_keys = sorted(set(second))
    shifted = [b + offset for b in b_keys]
    potential = []
    for a in a_keys:
        lo = bisect.bisect_left(shifted, a - max_difference)
        hi = bisect.bisect_right(shifted, a + max_difference)
        for k in range(lo, hi):
            diff = abs(a - shifted[k])
            if diff < max_difference:
                potential.append((diff, a, b_keys[k]))
    potential.sort()
    used_a: set[float] = set()
    used_b: set[float] = set()
    matches = []
    for _, a, b in potential:
        if a not in used_a and b not in used_b:
            used_a.add(a)
            used_b.add(b)
            matches.append((a, b))
    matches.sort()
    return matches


@dataclass(frozen=True)
class TumFrame:
    """One associated RGB/depth pair (stamps in seconds)."""

    stamp: float
    rgb_path: Path
    depth_stamp: float
    depth_path: Path


@dataclass(frozen=True)
class TumSequence:
    """Associated frames, ground truth (stamps, 4×4 camera poses) and intrinsics."""

    folder: Path
    frames: tuple[TumFrame, ...]
    groundtruth_stamps: NDArray[np.float64]
    groundtruth_poses: NDArray[np.float64]
    camera: CameraIntrinsics


def tum_camera(folder: str | Path, width: int = 640, height: int = 480) -> CameraIntrinsics:
    """Intrinsics for a sequence from its name (freiburg1/2/3), base frame = optical frame rotated."""
    name = Path(folder).name
    fx, fy, cx, cy = 525.0, 525.0, 319.5, 239.5
    for key, calib in TUM_CALIBRATIONS.items():
        if key in name:
            fx, fy, cx, cy = calib
    return CameraIntrinsics(fx, fy, cx, cy, width, height, OPTICAL_ROTATION.copy())


def read_tum_sequence(folder: str | Path, max_difference: float = 0.02) -> TumSequence:
    """Read and associate a TUM RGB-D folder."""
    root = Path(folder)
    if not (root / "rgb.txt").is_file() or not (root / "depth.txt").is_file():
        raise TumFormatError(f"{root}: rgb.txt and depth.txt are required")
    rgb = read_file_list(root / "rgb.txt")
    depth = read_file_list(root / "depth.txt")
    pairs = associate(rgb, depth, 0.0, max_difference)
    frames = tuple(
        TumFrame(a, root / rgb[a][0], b, root / depth[b][0]) for a, b in pairs
    )
    stamps = np.zeros(0)
    poses = np.zeros((0, 4, 4))
    gt_path = root / "groundtruth.txt"
    if gt_path.is_file():
        stamps, poses = read_tum_trajectory(gt_path)
    first = cv2.imread(str(frames[0].rgb_path), cv2.IMREAD_UNCHANGED) if frames else None
    h, w = (480, 640) if first is None else first.shape[:2]
    return TumSequence(root, frames, stamps, poses, tum_camera(root, w, h))


def load_tum_frame(
    frame: TumFrame, depth_scale: float = TUM_DEPTH_SCALE,
) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
    """RGB (H, W, 3) uint8 and depth in metres (float32, 0 = none); `depth_scale` is the
    depth PNG's units per metre (TUM 5000, ICL-NUIM/Redwood 1000)."""
    bgr = cv2.imread(str(frame.rgb_path), cv2.IMREAD_COLOR)
    raw = cv2.imread(str(frame.depth_path), cv2.IMREAD_UNCHANGED)
    if bgr is None or raw is None:
        raise TumFormatError(f"cannot read {frame.rgb_path} or {frame.depth_path}")
    rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)
    return rgb, np.asarray(raw, dtype=np.float32) / np.float32(depth_scale)


def tum_row_to_matrix(values: Sequence[float]) -> F64:
    """(tx, ty, tz, qx, qy, qz, qw) → 4×4."""
    tx, ty, tz, qx, qy, qz, qw = (float(v) for v in values)
    n = np.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    t = np.eye(4)
    t[:3, :3] = [
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)],
    ]
    t[:3, 3] = (tx, ty, tz)
    return t


def matrix_to_tum_row(t: F64) -> tuple[float, ...]:
    """4×4 → (tx, ty, tz, qx, qy, qz, qw) with qw ≥ 0."""
    r = t[:3, :3]
    tr = np.trace(r)
    if tr > 0:
        s = np.sqrt(tr + 1.0) * 2
        qw, qx, qy, qz = 0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        qw, qx, qy, qz = (r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        qw, qx, qy, qz = (r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s
    else:
        s = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        qw, qx, qy, qz = (r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s
    q = np.array([qx, qy, qz, qw])
    q = q / np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return (float(t[0, 3]), float(t[1, 3]), float(t[2, 3]), *(float(v) for v in q))


def read_tum_trajectory(path: str | Path) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Stamps (N,) and 4×4 poses (N, 4, 4) from a TUM trajectory file."""
    rows = read_file_list(path)
    stamps = np.array(sorted(rows))
    poses = np.zeros((stamps.size, 4, 4))
    for k, s in enumerate(stamps):
        if len(rows[s]) != 7:
            raise TumFormatError(f"{path}: expected 8 columns at t={s}")
        poses[k] = tum_row_to_matrix([float(v) for v in rows[s]])
    return stamps, poses


def write_tum_trajectory(path: str | Path, stamps: Sequence[float], poses: Sequence[F64]) -> None:
    """Write ``t tx ty tz qx qy qz qw`` lines atomically."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    lines = [
        f"{s:.6f} " + " ".join(f"{v:.9g}" for v in matrix_to_tum_row(p))
        for s, p in zip(stamps, poses)
    ]
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(lines) + "\n")
    os.replace(tmp, target)


def absolute_trajectory_error(
    est_stamps: NDArray[np.float64], est_poses: NDArray[np.float64],
    gt_stamps: NDArray[np.float64], gt_poses: NDArray[np.float64],
    max_difference: float = 0.02,
) -> tuple[float, int]:
    """ATE translational RMSE (m) after rigid (Horn) alignment, and the number of pairs used."""
    pairs = associate(list(est_stamps), list(gt_stamps), 0.0, max_difference)
    if len(pairs) < 3:
        return float("nan"), len(pairs)
    e_index = {s: k for k, s in enumerate(est_stamps)}
    g_index = {s: k for k, s in enumerate(gt_stamps)}
    a = np.array([est_poses[e_index[s]][:3, 3] for s, _ in pairs])
    b = np.array([gt_poses[g_index[g]][:3, 3] for _, g in pairs])
    t = fit_rigid(b, a, np.ones(len(a)), three_dof=False)
    aligned = a @ t[:3, :3].T + t[:3, 3]
    err = np.linalg.norm(aligned - b, axis=1)
    return float(np.sqrt(np.mean(err**2))), len(pairs)


_DIGITS = re.compile(r"\d+")


def numeric_sort_key(path: Path) -> tuple[int, str]:
    """Sort key: the last number in the file stem, then the name."""
    nums = _DIGITS.findall(path.stem)
    return (int(nums[-1]) if nums else -1, path.name)
