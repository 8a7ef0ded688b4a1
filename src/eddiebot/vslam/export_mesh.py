"""Map export as a coloured triangle mesh, as ``rtabmap-export --mesh`` makes it.

The stored RGB-D frames of one map's nodes become clouds at their optimised poses (depth
decimated by ``--decimation``, kept within ``--min_range``/``--max_range``), assembled and
voxel-filtered (``--voxel``); normals from the 20 nearest points are turned towards the camera
that saw each point; Poisson surface reconstruction at ``--poisson_depth`` (0: the smallest
depth whose cell is under ``--poisson_size`` across the map's longest side); then upstream's
``denseMeshPostProcessing``: quadric decimation to ``--max_polygons``, vertex colours averaged
from the cloud within ``--color_radius`` (0: the nearest point), polygons with a vertex no
cloud point is near removed (Poisson's closure over unseen space), pieces of fewer than
``--min_cluster`` polygons dropped (-1: the largest piece only). Option names and defaults are
``rtabmap-export``'s. Open3D (the optional ``mesh`` extra) does normals, Poisson and decimation.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from eddiebot.vslam.camera import CameraIntrinsics
from eddiebot.vslam.errors import VslamError
from eddiebot.vslam.export import atomic_write
from eddiebot.vslam.occupancy import depth_cloud, voxel_first_indices

__all__ = ["MESH_SUFFIXES", "Mesh", "MeshSettings", "MeshUnavailableError", "assemble_viewed_cloud",
           "poisson_mesh", "require_open3d", "write_mesh"]

MESH_SUFFIXES = (".ply", ".obj")
INSTALL_HINT = "pip install 'eddiebot[mesh]'"
NORMAL_K = 20  # rtabmap-export: util3d::computeNormals(cloud, 20)


class MeshUnavailableError(VslamError):
    """Open3D (the ``mesh`` extra) is not installed."""


@dataclass(frozen=True)
class MeshSettings:
    """Cloud, Poisson and post-processing settings (``rtabmap-export`` names and defaults)."""

    decimation: int = 4          # --decimation: depth image step
    min_range: float = 0.0       # --min_range (m, 0 = none)
    max_range: float = 4.0       # --max_range (m, 0 = none)
    voxel: float = 0.01          # --voxel (m, 0 = none)
    poisson_depth: int = 0       # --poisson_depth (0 = from --poisson_size)
    poisson_size: float = 0.03   # --poisson_size (m)
    max_polygons: int = 300_000  # --max_polygons (0 = no limit)
    color_radius: float = 0.05   # --color_radius (m; 0 = nearest point, -1 = no colour/clean)
    min_cluster: int = 200       # --min_cluster (polygons; -1 = largest piece only, 0 = keep)

    def check(self) -> None:
        if self.decimation < 1:
            raise ValueError(f"--decimation must be >= 1, got {self.decimation}")
        if self.min_range < 0 or self.max_range < 0:
            raise ValueError("--min_range and --max_range must be >= 0 m")
        if self.max_range and self.min_range >= self.max_range:
            raise ValueError(f"--min_range {self.min_range} must be below --max_range "
                             f"{self.max_range}")
        if self.voxel < 0:
            raise ValueError(f"--voxel must be >= 0 m, got {self.voxel}")
        if not 0 <= self.poisson_depth <= 16:
            raise ValueError(f"--poisson_depth must be 0 (automatic) to 16, got "
                             f"{self.poisson_depth}")
        if not self.poisson_size > 0:
            raise ValueError(f"--poisson_size must be > 0 m, got {self.poisson_size}")
        if self.max_polygons < 0:
            raise ValueError(f"--max_polygons must be >= 0, got {self.max_polygons}")
        if self.color_radius < 0 and self.color_radius != -1:
            raise ValueError(f"--color_radius must be >= 0 m or -1, got {self.color_radius}")
        if self.min_cluster < -1:
            raise ValueError(f"--min_cluster must be >= -1, got {self.min_cluster}")

    def depth(self, map_length: float) -> int:
        """rtabmap-export's Poisson depth: the given one, else the first of 6..11 whose cell
        (map length / 2^depth) is under ``poisson_size``, else 12."""
        if self.poisson_depth > 0:
            return self.poisson_depth
        return next((i for i in range(6, 12) if map_length / float(1 << i) < self.poisson_size),
                    12)


@dataclass
class Mesh:
    """Vertices (N, 3) in the map frame, triangles (M, 3) vertex indices, colours (N, 3)."""

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int32]
    colors: NDArray[np.uint8]
    poisson_depth: int = 0


def require_open3d() -> Any:
    """The ``open3d`` module, or MeshUnavailableError naming the extra to install."""
    try:
        import open3d
    except ImportError:
        raise MeshUnavailableError(f"mesh export needs Open3D: {INSTALL_HINT}") from None
    return open3d


def assemble_viewed_cloud(
    frames: Iterable[tuple[NDArray[np.uint8] | None, NDArray[np.generic], CameraIntrinsics,
                           NDArray[np.float64]]],
    settings: MeshSettings,
) -> tuple[NDArray[np.float64], NDArray[np.uint8], NDArray[np.float64]]:
    """(rgb, depth, camera, base pose in the map) frames → the map-frame cloud, its colours and
    the camera position that saw each point, voxel-filtered (first point of each voxel)."""
    xyz_parts, rgb_parts, view_parts = [], [], []
    for rgb, depth, cam, pose in frames:
        xyz, colors = depth_cloud(depth, cam, settings.decimation, settings.min_range,
                                  settings.max_range, rgb)
        t = np.asarray(pose, np.float64)
        xyz_parts.append(xyz @ t[:3, :3].T + t[:3, 3])
        rgb_parts.append(colors)
        eye = t[:3, :3] @ np.asarray(cam.local_transform)[:3, 3] + t[:3, 3]
        view_parts.append(np.broadcast_to(eye, xyz.shape))
    if not xyz_parts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3))
    xyz, rgb, view = (np.concatenate(xyz_parts), np.concatenate(rgb_parts),
                      np.concatenate(view_parts))
    if settings.voxel > 0:
        keep = voxel_first_indices(xyz, settings.voxel)
        xyz, rgb, view = xyz[keep], rgb[keep], view[keep]
    return xyz, rgb, view


def poisson_mesh(xyz: NDArray[np.float64], rgb: NDArray[np.uint8], view: NDArray[np.float64],
                 settings: MeshSettings | None = None) -> Mesh:
    """Poisson mesh of a cloud whose points were seen from `view`, cleaned as upstream's
    ``denseMeshPostProcessing``."""
    s = settings or MeshSettings()
    s.check()
    o3d = require_open3d()
    if xyz.shape[0] < NORMAL_K:
        return Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.uint8))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, np.float64)))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=NORMAL_K))
    normals = np.asarray(cloud.normals)
    flip = np.einsum("ij,ij->i", normals, view - xyz) < 0  # towards the camera that saw it
    normals[flip] *= -1.0
    cloud.normals = o3d.utility.Vector3dVector(normals)
    depth = s.depth(float(np.max(xyz.max(axis=0) - xyz.min(axis=0))))
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=depth)
    if s.max_polygons and len(mesh.triangles) > s.max_polygons:
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=s.max_polygons)
    vertices = np.asarray(mesh.vertices, np.float64).copy()
    triangles = np.asarray(mesh.triangles, np.int64).copy()
    colors = np.full((vertices.shape[0], 3), 255, np.uint8)
    if s.color_radius >= 0 and vertices.shape[0]:
        tree = cKDTree(xyz)
        if s.color_radius > 0:  # mean colour of the cloud points within the radius
            near = tree.query_ball_point(vertices, s.color_radius)
            counts = np.fromiter((len(n) for n in near), np.intp, len(near))
            colored = counts > 0
            flat = np.fromiter(chain.from_iterable(near), np.intp, int(counts.sum()))
            if flat.size:
                starts = np.concatenate(([0], np.cumsum(counts)[:-1]))[colored]
                sums = np.add.reduceat(rgb[flat].astype(np.int64), starts, axis=0)
                colors[colored] = (sums // counts[colored, None]).astype(np.uint8)
        else:
            _, nearest = tree.query(vertices)
            colors = rgb[nearest].astype(np.uint8)
            colored = np.ones(vertices.shape[0], bool)
        triangles = triangles[colored[triangles].all(axis=1)]
    if s.min_cluster and triangles.shape[0]:
        triangles = _filter_clusters(triangles, vertices.shape[0], s.min_cluster)
    used = np.zeros(vertices.shape[0], bool)
    used[triangles.ravel()] = True
    remap = np.cumsum(used) - 1
    return Mesh(vertices[used], remap[triangles].astype(np.int32), colors[used], depth)


def _filter_clusters(triangles: NDArray[np.int64], n_vertices: int,
                     min_cluster: int) -> NDArray[np.int64]:
    """Drop connected pieces (triangles sharing a vertex) of fewer than `min_cluster`
    triangles; -1 keeps the largest piece only."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    m = triangles.shape[0]
    rows = np.repeat(np.arange(m), 3)
    incidence = coo_matrix((np.ones(3 * m), (rows, triangles.ravel())), shape=(m, n_vertices))
    _, vertex_label = connected_components(
        (incidence.T @ incidence).tocsr(), directed=False)
    label = vertex_label[triangles[:, 0]]
    counts = np.bincount(label)
    keep = (label == int(np.argmax(counts))) if min_cluster < 0 else counts[label] >= min_cluster
    return triangles[keep]


def write_mesh(path: str | Path, mesh: Mesh) -> None:
    """A binary PLY (float x y z, uchar red green blue; faces as uchar count + int indices) or
    a Wavefront OBJ with per-vertex colours (``v x y z r g b``, as MeshLab and Open3D read),
    chosen by the suffix; written to a temporary file beside it, then renamed."""
    target = Path(path)
    suffix = target.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"{target}: mesh file must end in .ply or .obj")
    atomic_write(target, _ply_bytes(mesh) if suffix == ".ply" else _obj_bytes(mesh))


def _ply_bytes(mesh: Mesh) -> bytes:
    n, m = mesh.vertices.shape[0], mesh.triangles.shape[0]
    vertices = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                  ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for k, name in enumerate(("x", "y", "z")):
        vertices[name] = mesh.vertices[:, k]
    for k, name in enumerate(("red", "green", "blue")):
        vertices[name] = mesh.colors[:, k]
    faces = np.zeros(m, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = mesh.triangles
    header = "\n".join([
        "ply", "format binary_little_endian 1.0", f"element vertex {n}",
        "property float x", "property float y", "property float z",
        "property uchar red", "property uchar green", "property uchar blue",
        f"element face {m}", "property list uchar int vertex_indices", "end_header"]) + "\n"
    return header.encode("ascii") + vertices.tobytes() + faces.tobytes()


def _obj_bytes(mesh: Mesh) -> bytes:
    rgb = mesh.colors.astype(np.float64) / 255.0
    v = np.hstack([mesh.vertices, rgb])
    lines = [f"# {mesh.vertices.shape[0]} vertices, {mesh.triangles.shape[0]} faces"]
    lines += [f"v {a:.6f} {b:.6f} {c:.6f} {r:.4f} {g:.4f} {bl:.4f}" for a, b, c, r, g, bl in v]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.triangles]
    return ("\n".join(lines) + "\n").encode("ascii")
