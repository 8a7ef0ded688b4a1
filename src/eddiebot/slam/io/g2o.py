"""2D pose-graph files: g2o (``VERTEX_SE2`` / ``EDGE_SE2``) and TORO (``VERTEX2`` / ``EDGE2``).

g2o: ``EDGE_SE2 i j dx dy dθ I11 I12 I13 I22 I23 I33`` (upper triangle of the information
matrix, row-major). TORO: ``EDGE2 i j dx dy dθ I_xx I_xy I_yy I_θθ I_xθ I_yθ``.
Without vertex lines, poses are initialised by chaining the odometry edges (j = i + 1)
from the origin. Errors name the file and line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from eddiebot.geometry import se2_compose
from eddiebot.slam.errors import PoseGraphFormatError
from eddiebot.slam.pose_graph import EdgeKind, PoseGraph

__all__ = ["PoseGraphFile", "build_pose_graph", "read_g2o", "read_pose_graph", "read_toro"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PoseGraphFile:
    """Vertices (N, 3) indexed 0..N-1 (file ids remapped in order), edges and informations."""

    path: Path
    poses: FloatArray
    edge_index: npt.NDArray[np.int64]
    """(E, 2) node indices (i, j)."""
    measurements: FloatArray
    """(E, 3) relative poses."""
    information: FloatArray
    """(E, 3, 3) information matrices."""
    had_vertices: bool
    ids: npt.NDArray[np.int64]
    """File id of each node."""


def _info_g2o(v: list[float]) -> FloatArray:
    i11, i12, i13, i22, i23, i33 = v
    return np.array([[i11, i12, i13], [i12, i22, i23], [i13, i23, i33]])


def _info_toro(v: list[float]) -> FloatArray:
    ixx, ixy, iyy, itt, ixt, iyt = v
    return np.array([[ixx, ixy, ixt], [ixy, iyy, iyt], [ixt, iyt, itt]])


def _read(
    path: str | os.PathLike[str], vertex_tag: str, edge_tag: str, toro: bool
) -> PoseGraphFile:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise PoseGraphFormatError(f"{p}: cannot read: {exc.strerror or exc}") from exc
    vertices: dict[int, FloatArray] = {}
    edges: list[tuple[int, int, FloatArray, FloatArray]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        try:
            if tok[0] == vertex_tag:
                if len(tok) < 5:
                    raise ValueError(f"{vertex_tag} needs id x y theta")
                vertices[int(tok[1])] = np.array([float(t) for t in tok[2:5]])
            elif tok[0] == edge_tag:
                if len(tok) < 12:
                    raise ValueError(f"{edge_tag} needs 11 values, got {len(tok) - 1}")
                vals = [float(t) for t in tok[3:12]]
                info = _info_toro(vals[3:]) if toro else _info_g2o(vals[3:])
                if not np.all(np.isfinite(vals)):
                    raise ValueError("non-finite value")
                edges.append((int(tok[1]), int(tok[2]), np.array(vals[:3]), info))
            elif tok[0] in ("FIX", "VERTEX_XY", "EDGE_SE2_XY"):
                continue
            else:
                raise ValueError(f"unknown record {tok[0]!r}")
        except ValueError as exc:
            raise PoseGraphFormatError(f"{p}:{lineno}: {exc}") from exc
    if not edges and not vertices:
        raise PoseGraphFormatError(f"{p}: no {vertex_tag} or {edge_tag} lines")
    ids = sorted(set(vertices) | {e[0] for e in edges} | {e[1] for e in edges})
    index = {k: n for n, k in enumerate(ids)}
    poses = np.zeros((len(ids), 3))
    had_vertices = bool(vertices)
    if had_vertices:
        missing = [k for k in ids if k not in vertices]
        if missing:
            raise PoseGraphFormatError(
                f"{p}: edges refer to nodes without vertices, e.g. {missing[0]}"
            )
        for k, v in vertices.items():
            poses[index[k]] = v
    else:
        odo = {(e[0], e[1]): e[2] for e in edges if e[1] == e[0] + 1}
        for n in range(1, len(ids)):
            z = odo.get((ids[n - 1], ids[n]))
            if z is None:
                raise PoseGraphFormatError(
                    f"{p}: no vertices and no odometry edge {ids[n - 1]}->{ids[n]} to chain"
                )
            poses[n] = se2_compose(poses[n - 1], z)
    edge_index = np.array([[index[e[0]], index[e[1]]] for e in edges], dtype=np.int64).reshape(
        -1, 2
    )
    meas = np.array([e[2] for e in edges]).reshape(-1, 3)
    info = np.array([e[3] for e in edges]).reshape(-1, 3, 3)
    return PoseGraphFile(
        p, poses, edge_index, meas, info, had_vertices, np.array(ids, dtype=np.int64)
    )


def read_g2o(path: str | os.PathLike[str]) -> PoseGraphFile:
    """Read a 2D g2o file."""
    return _read(path, "VERTEX_SE2", "EDGE_SE2", toro=False)


def read_toro(path: str | os.PathLike[str]) -> PoseGraphFile:
    """Read a TORO ``.graph`` file."""
    return _read(path, "VERTEX2", "EDGE2", toro=True)


def read_pose_graph(path: str | os.PathLike[str]) -> PoseGraphFile:
    """g2o or TORO, told apart by the first record tag."""
    p = Path(path)
    try:
        with p.open(encoding="utf-8", errors="replace") as handle:
            for line in handle:
                tok = line.split()
                if not tok or tok[0].startswith("#"):
                    continue
                if tok[0] in ("VERTEX2", "EDGE2"):
                    return read_toro(p)
                break
    except OSError as exc:
        raise PoseGraphFormatError(f"{p}: cannot read: {exc.strerror or exc}") from exc
    return read_g2o(p)


def build_pose_graph(
    data: PoseGraphFile,
    *,
    optimizer: str = "levenberg_marquardt",
    robust_kernel: str = "none",
    kernel_width: float = 1.0,
    robust_loops: bool = False,
    gate_probability: float | None = 0.999,
) -> PoseGraph:
    """A `PoseGraph` holding the file's nodes (at their initial poses) and edges.

    Edges with j != i + 1 are loop edges; ``robust_loops`` puts the kernel (and the χ² gate,
    ``gate_probability``) on them.
    """
    graph = PoseGraph(optimizer=optimizer, robust_kernel=robust_kernel, kernel_width=kernel_width,
                      gate_probability=gate_probability)
    for pose in data.poses:
        graph.add_node(pose)
    for (i, j), z, info in zip(data.edge_index, data.measurements, data.information):
        loop = int(j) != int(i) + 1
        graph.add_edge(
            int(i),
            int(j),
            z,
            np.linalg.inv(info),
            kind=EdgeKind.LOOP if loop else EdgeKind.ODOMETRY,
            robust=robust_loops and loop,
        )
    return graph
