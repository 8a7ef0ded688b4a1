"""Map export files: coloured point clouds as binary PLY (atomic writes)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["atomic_write", "read_ply", "write_ply"]


def write_ply(path: str | Path, xyz: NDArray[np.float64], rgb: NDArray[np.uint8] | None = None) -> None:
    """Binary little-endian PLY with float32 x y z and optional uchar red green blue."""
    target = Path(path)
    n = int(xyz.shape[0])
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if rgb is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vertices = np.zeros(n, dtype=fields)
    vertices["x"], vertices["y"], vertices["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}",
              "property float x", "property float y", "property float z"]
    if rgb is not None:
        vertices["red"], vertices["green"], vertices["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
        header += ["property uchar red", "property uchar green", "property uchar blue"]
    header.append("end_header")
    atomic_write(target, ("\n".join(header) + "\n").encode("ascii") + vertices.tobytes())


def atomic_write(path: str | Path, data: bytes) -> None:
    """Write `data` to a temporary file beside `path`, then rename it over `path`: a reader
    never sees half a file and a failed write leaves the old one; mode 0644."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)  # mkstemp makes it 0600
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def read_ply(path: str | Path) -> tuple[NDArray[np.float32], NDArray[np.uint8] | None]:
    """Read a PLY written by `write_ply` (xyz and optional colours)."""
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    n = next(int(line.split()[2]) for line in header if line.startswith("element vertex"))
    has_rgb = any(line.endswith(" red") for line in header)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if has_rgb:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    v = np.frombuffer(data[end:], dtype=fields, count=n)
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1)
    rgb = np.stack([v["red"], v["green"], v["blue"]], axis=1) if has_rgb else None
    return xyz, rgb
