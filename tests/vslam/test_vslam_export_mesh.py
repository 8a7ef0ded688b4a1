"""``eddie vslam db export --mesh``: the Poisson mesh of the stored RGB-D frames as
``rtabmap-export --mesh`` makes it, on ICL-NUIM frames, one mesh per unmerged map; the refusal
without Open3D; the depth and cluster rules without it."""

import argparse
import sys

import numpy as np
import pytest
from icl_data import ICL, icl_reference, needs_icl, write_icl_tum
from scipy.spatial import cKDTree

from _support.vslam_session import write_session_database
from eddiebot.cli import vslam as cli
from eddiebot.vslam.export import read_ply
from eddiebot.vslam.export_mesh import MeshSettings, _filter_clusters

# two stretches of the living room with a 0.86 m / 37° jump between: the odometry is lost at
# the jump and re-seeded, so the database holds two maps that never merge
FIRST = list(range(0, 31, 6))
SECOND = list(range(150, 181, 6))


def _run(argv):
    parser = argparse.ArgumentParser(prog="eddie vslam")
    cli.add_arguments(parser)
    return cli.run(parser.parse_args([str(a) for a in argv]))


def test_poisson_depth_follows_rtabmap_export():
    s = MeshSettings()  # --poisson_size 0.03: first depth of 6..11 with length / 2^d < 0.03
    assert s.depth(3.7) == 7      # 3.7 / 128 = 0.029
    assert s.depth(3.9) == 8      # 3.9 / 128 = 0.030 is not below
    assert s.depth(0.5) == 6
    assert s.depth(200.0) == 12   # nothing up to 11 is fine enough
    assert MeshSettings(poisson_depth=9).depth(3.7) == 9


def test_cluster_filter_keeps_pieces_by_size():
    # a strip of 3 triangles (vertices 0-4) and a lone triangle (5-7)
    tris = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [5, 6, 7]])
    assert _filter_clusters(tris, 8, 2).tolist() == tris[:3].tolist()
    assert _filter_clusters(tris, 8, 4).shape[0] == 0
    assert _filter_clusters(tris, 8, 1).shape[0] == 4
    assert _filter_clusters(tris, 8, -1).tolist() == tris[:3].tolist()


def test_mesh_without_open3d_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    db = tmp_path / "map.db"
    write_session_database(db)
    monkeypatch.setitem(sys.modules, "open3d", None)  # import open3d raises ImportError
    out = tmp_path / "mesh.ply"
    assert _run(["db", "export", db, "--mesh", out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pip install 'eddiebot[mesh]'" in err
    assert not out.exists()


@pytest.mark.parametrize(("argv", "named"), [
    (["--mesh", "mesh.stl"], "mesh.stl"),
    (["--ply", "c.ply", "--decimation", "0"], "--decimation"),
    (["--mesh", "m.ply", "--poisson_depth", "-1"], "--poisson_depth"),
    (["--mesh", "m.ply", "--min_range", "5", "--max_range", "4"], "--min_range"),
    (["--mesh", "m.ply", "--color_radius", "-0.5"], "--color_radius"),
])
def test_bad_export_options_are_refused_before_anything_is_written(tmp_path, capsys, argv,
                                                                   named):
    db = tmp_path / "map.db"
    write_session_database(db)
    argv = [str(tmp_path / a) if a.endswith((".ply", ".stl")) else a for a in argv]
    assert _run(["db", "export", db, *argv]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.db"]


@pytest.fixture(scope="module")
def two_map_export(tmp_path_factory):
    pytest.importorskip("open3d")
    if not (ICL / "image").is_dir():
        pytest.skip(f"ICL-NUIM sample not found at {ICL}")
    work = tmp_path_factory.mktemp("icl_mesh")
    folder = write_icl_tum(work / "icl", FIRST + SECOND)
    out = work / "out"
    assert _run(["replay", folder, "--depth-scale", "1000", "-o", out,
                 "--set", "RGBD/LinearUpdate=0", "--set", "RGBD/AngularUpdate=0"]) == 0
    db = out / "rtabmap.db"
    assert _run(["db", "export", db, "--ply", work / "cloud.ply",
                 "--mesh", work / "mesh.ply"]) == 0
    return work, db


@needs_icl
def test_one_mesh_per_unmerged_map_lies_on_its_cloud(two_map_export):
    import open3d as o3d

    work, _ = two_map_export
    for mesh_name, cloud_name in (("mesh.ply", "cloud.ply"), ("mesh_map1.ply", "cloud_map1.ply")):
        mesh = o3d.io.read_triangle_mesh(str(work / mesh_name))  # our PLY, read by Open3D
        v = np.asarray(mesh.vertices)
        colors = np.asarray(mesh.vertex_colors)
        xyz, rgb = read_ply(work / cloud_name)
        # a room-sized surface at Poisson depth 7 (≈ 3 cm cells over ≈ 3.5 m)
        assert 5_000 < v.shape[0] < 60_000
        assert len(mesh.triangles) > 1.5 * v.shape[0]
        assert mesh.is_edge_manifold()
        # no surface invented beyond what was seen (polygons far from the cloud are cut)...
        lo, hi = xyz.min(axis=0), xyz.max(axis=0)
        assert np.all(v.min(axis=0) > lo - 0.05) and np.all(v.max(axis=0) < hi + 0.05)
        # ...none missing (the mesh spans the cloud)...
        assert np.all((v.max(axis=0) - v.min(axis=0)) > 0.9 * (hi - lo))
        # ...and on it: vertices within a few mm of the cloud, every cloud point near a vertex
        d_mesh, _ = cKDTree(xyz).query(v)
        d_cloud, _ = cKDTree(v).query(xyz)
        assert np.median(d_mesh) < 0.01
        assert np.mean(d_cloud < 0.025) > 0.9
        # colours are the cloud's
        assert np.all(np.abs(colors.mean(axis=0) * 255 - rgb.mean(axis=0)) < 12)


@needs_icl
def test_first_map_mesh_matches_the_reference_trajectory_cloud(two_map_export):
    """Vertices against a cloud made without our poses: the depth of every 6th frame of the
    first stretch at Open3D's trajectory, in the map frame (the first node's base)."""
    import cv2
    import open3d as o3d

    work, db = two_map_export
    v = np.asarray(o3d.io.read_triangle_mesh(str(work / "mesh.ply")).vertices)
    ref = icl_reference()
    base_from_optical = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1.0]])
    to_map = base_from_optical @ np.linalg.inv(ref[FIRST[0]])
    pts = []
    for i in FIRST:
        d = cv2.imread(str(ICL / "depth" / f"{i:05d}.png"), cv2.IMREAD_UNCHANGED)[::4, ::4]
        r, c = np.nonzero((d > 0) & (d < 4000))
        z = d[r, c] / 1000.0
        p = np.stack([(c * 4 - 319.5) * z / 525.0, (r * 4 - 239.5) * z / 525.0, z, np.ones_like(z)])
        pts.append(((to_map @ ref[i]) @ p)[:3].T)
    d_ref, _ = cKDTree(np.concatenate(pts)).query(v)
    assert np.median(d_ref) < 0.012


@needs_icl
def test_obj_mesh_with_a_polygon_budget(two_map_export):
    work, db = two_map_export
    out = work / "small.obj"
    assert _run(["db", "export", db, "--mesh", out, "--max_polygons", "4000",
                 "--min_cluster", "-1"]) == 0
    lines = out.read_text().splitlines()
    verts = [ln.split() for ln in lines if ln.startswith("v ")]
    faces = [ln.split() for ln in lines if ln.startswith("f ")]
    assert all(len(v) == 7 for v in verts)  # x y z r g b
    assert 1_000 < len(faces) <= 4_000  # decimated first, then cleaned (as upstream)
    assert max(int(i) for f in faces for i in f[1:]) == len(verts)  # 1-based, all used
    assert (work / "small_map1.obj").exists()
