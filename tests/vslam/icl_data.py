"""The ICL-NUIM living-room sample (Open3D's copy, /work/shared/datasets/rgbd) as TUM folders.

The sample has numbered ``image/`` and ``depth/`` files (depth 1000 units per metre), no time
stamps and Open3D's own reconstruction trajectory (Redwood ``.log``, camera optical frame). The
helpers list any order of its frames in a TUM ``rgb.txt``/``depth.txt`` pointing at the shared
files (nothing is copied) with stamps at 30 Hz, and that trajectory as ``groundtruth.txt``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from eddiebot.vslam.tum import write_tum_trajectory

ICL = Path(os.environ.get("EDDIE_ICL_LIVINGROOM",
                          "/work/shared/datasets/rgbd/icl_livingroom1_micro"))
ICL_FRAMES = 211
ICL_DEPTH_SCALE = 1000.0
RATE_HZ = 30.0

needs_icl = pytest.mark.skipif(not (ICL / "image").is_dir(),
                               reason=f"ICL-NUIM sample not found at {ICL}")


def read_redwood_log(path: Path) -> list[np.ndarray]:
    """4×4 camera-to-world poses of a Redwood ``.log`` (a header line, then 4 matrix rows)."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    return [np.array(rows[k + 1 : k + 5], dtype=np.float64) for k in range(0, len(rows), 5)]


def icl_reference() -> list[np.ndarray]:
    """Open3D's estimate of the sample's camera trajectory (not ground truth: the only full
    trajectory there is; it agrees with the first frames' ground truth within 1–2 mm)."""
    return read_redwood_log(ICL / "open3d_reconstruction_trajectory.log")


def forward_backward(step: int) -> list[int]:
    """Frame indices 0, step, … to the last and back to 0: every return frame revisits the
    exact image of an outbound one."""
    out = list(range(0, ICL_FRAMES, step))
    return out + out[::-1][1:]


def write_icl_tum(folder: Path, indices: Sequence[int], depth_dir: Path | None = None) -> Path:
    """A TUM folder listing `indices` (stamps k / 30 s) with the reference as ground truth;
    depth is read from `depth_dir` (same file names) when given."""
    folder.mkdir(parents=True, exist_ok=True)
    depth_root = depth_dir or (ICL / "depth")
    stamps = [k / RATE_HZ for k in range(len(indices))]
    (folder / "rgb.txt").write_text(
        "".join(f"{s:.6f} {ICL / 'image' / f'{i:05d}.jpg'}\n" for s, i in zip(stamps, indices)))
    (folder / "depth.txt").write_text(
        "".join(f"{s:.6f} {depth_root / f'{i:05d}.png'}\n" for s, i in zip(stamps, indices)))
    ref = icl_reference()
    write_tum_trajectory(folder / "groundtruth.txt", stamps, [ref[i] for i in indices])
    return folder
