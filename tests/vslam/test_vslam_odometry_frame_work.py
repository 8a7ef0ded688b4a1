"""Visual odometry per-frame work: the depth cloud is built only for frames that use it (ICP or
a key frame feeding the scan map), and the keypoint attributes read in one pass equal OpenCV's.

Per-frame work without changing results: the compiled grid normals and keypoint depths equal
their array forms, the voxel sums equal np.add.at's, and the scan map's grid subtraction keeps
the points the k-d tree query keeps."""

import cv2
import numpy as np
from scipy.spatial import cKDTree
from vslam_synthetic import BoxRoom, frame, kinect_camera, planar_pose, render

import eddiebot.vslam.odometry as odometry
from _support.vslam_room import ICP_VO, spin_in_room
from eddiebot.vslam import depth_icp, features
from eddiebot.vslam.camera import depth_to_meters
from eddiebot.vslam.depth_icp import ScanCloud, ScanMap
from eddiebot.vslam.features import FeatureExtractor
from eddiebot.vslam.parameters import RtabmapParameters


def test_depth_cloud_built_only_for_icp_and_key_frames(monkeypatch):
    built: list[int] = []
    real = odometry.make_scan

    def counting(depth, camera, settings):
        built.append(1)
        return real(depth, camera, settings)

    monkeypatch.setattr(odometry, "make_scan", counting)
    blank = range(10, 24)
    res, truths = spin_in_room({**ICP_VO, "Odom/IcpFallbackInliers": "40"}, blank)
    # the first frame starts the scan map; afterwards only ICP frames and key frames need it
    # (a fallback ICP attempt on a frame that stays visual would add one: none here)
    needed = 1 + sum(1 for r in res[1:] if r.icp or r.keyframe)
    assert len(built) == needed
    assert needed < len(res) - 10  # most tracked visual frames build no cloud
    assert sum(r.icp for r in res) >= len(blank)
    # the tracking itself is as before: the spin's end pose within 2 cm
    assert np.linalg.norm(res[-1].pose[:2, 3] - truths[-1][:2, 3]) < 0.02


def test_keypoint_attributes_match_opencv():
    rgb, depth = frame(3, 1.0, 1.0, 0.4)
    cam = kinect_camera(320, 240)
    params = RtabmapParameters.from_dict({})
    ex = FeatureExtractor(params, max_features=params.vis_max_features, strategy=params.vis_feature_type)
    f = ex.extract(rgb, depth, cam, depth_as_mask=False)
    assert len(f) > 100
    # reference: the same detector and descriptor, attributes read keypoint by keypoint
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    kps = ex._gftt.detect(gray, None)
    for kp in kps:
        kp.size = 31.0
    kps, desc = ex._orb.compute(gray, kps)
    resp = np.array([k.response for k in kps], np.float32)
    order = np.argsort(-resp, kind="stable")[: params.vis_max_features]
    ref_uv = np.array([kps[i].pt for i in order], np.float32)
    # keypoints outside the depth range are dropped: compare the kept ones, found by position
    assert len(f) > 0.8 * len(order)
    lookup = {tuple(p): i for i, p in enumerate(ref_uv.tolist())}
    idx = np.array([lookup[tuple(p)] for p in f.uv.tolist()])
    assert np.all(np.diff(idx) > 0)  # same order
    src = order[idx]
    np.testing.assert_array_equal(f.responses, resp[src])
    np.testing.assert_array_equal(f.sizes, np.array([kps[i].size for i in src], np.float32))
    np.testing.assert_array_equal(f.angles, np.array([kps[i].angle for i in src], np.float32))
    np.testing.assert_array_equal(f.octaves, np.array([kps[i].octave for i in src], np.int32))
    np.testing.assert_array_equal(f.descriptors, desc[src])


def _grid_normals_arrays(cam, half):
    """The array form `_grid_normals` had (reference)."""
    h, w, _ = cam.shape
    out = np.full((h, w, 3), np.nan)
    c = cam[half:h - half, half:w - half]
    du = cam[half:h - half, 2 * half:] - cam[half:h - half, : w - 2 * half]
    dv = cam[2 * half:, half:w - half] - cam[: h - 2 * half, half:w - half]
    n = np.cross(du, dv)
    norm = np.linalg.norm(n, axis=2, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
        inv = 1.0 / cam[..., 2]
        ic = inv[half:h - half, half:w - half]
        d2u = inv[half:h - half, 2 * half:] + inv[half:h - half, : w - 2 * half] - 2 * ic
        d2v = inv[2 * half:, half:w - half] + inv[: h - 2 * half, half:w - half] - 2 * ic
        jump = (np.abs(d2u) > depth_icp._JUMP_RATIO * ic) | (np.abs(d2v) > depth_icp._JUMP_RATIO * ic)
        fwd = np.cross(cam[half:h - half, 2 * half:] - c, cam[2 * half:, half:w - half] - c)
        bwd = np.cross(c - cam[half:h - half, : w - 2 * half], c - cam[: h - 2 * half, half:w - half])
        cos_fb = np.sum(fwd * bwd, axis=2) / (
            np.linalg.norm(fwd, axis=2) * np.linalg.norm(bwd, axis=2))
        jump |= ~(cos_fb > depth_icp._CREASE_COS)
    n[jump] = np.nan
    flip = np.sum(n * c, axis=2) > 0
    n[flip] *= -1.0
    out[half:h - half, half:w - half] = n
    return out


def test_compiled_grid_normals_equal_the_array_form():
    cam = kinect_camera(320, 240)
    room = BoxRoom(size_x=8.0, size_y=4.0, height=2.5, seed=3)
    checked = 0
    for x, y, yaw in ((1.0, 1.0, 0.3), (6.5, 3.2, 2.5), (4.0, 2.0, -1.2)):
        _, depth = render(room, planar_pose(x, y, yaw), cam)
        depth[100:110, 50:90] = 0  # holes: NaN neighbours
        for step in (1, 2, 4):
            grid = depth_icp._organised_points(depth, cam, step)
            got = depth_icp._grid_normals(grid, 2)
            ref = _grid_normals_arrays(grid, 2)
            np.testing.assert_array_equal(got, ref)
            checked += int(np.isfinite(got[..., 0]).sum())
    assert checked > 20000
    # a crease and a jump are both NaN; a plane is not
    assert np.isnan(got).any() and np.isfinite(got).any()


def test_scan_map_grid_subtraction_equals_tree_query():
    rng = np.random.default_rng(5)
    radius = 0.05
    pts = rng.uniform([0, 0, 0], [4, 3, 2], (6000, 3))
    m = ScanMap(max_size=100000, subtract_radius=radius)
    m.add(ScanCloud(pts, np.tile([1.0, 0, 0], (6000, 1))), 1)
    # queries near the map (many within the radius), far outside it, and on the cell borders
    q = np.concatenate([pts[:2000] + rng.normal(0, 0.03, (2000, 3)),
                        rng.uniform([-3, -3, -1], [7, 6, 3], (2000, 3)),
                        pts[:200] + np.array([radius, 0, 0])])
    ref = ~np.isfinite(cKDTree(pts).query(q, distance_upper_bound=radius)[0])
    got = m._far(q)
    np.testing.assert_array_equal(got, ref)
    assert 500 < ref.sum() < len(q) - 500
    # add() keeps the far points only
    added = m.add(ScanCloud(q, np.tile([0, 1.0, 0], (len(q), 1))), 2)
    assert added == int(ref.sum()) and len(m) == 6000 + added


def test_voxel_sums_equal_add_at():
    rng = np.random.default_rng(2)
    pts = rng.uniform(-2, 2, (4000, 3))
    nrm = rng.normal(size=(4000, 3))
    for voxel in (0.05, 0.3):
        got, got_n = depth_icp.voxel_filter(pts, voxel, nrm)
        keys = np.floor(pts / voxel).astype(np.int64)
        keys -= keys.min(axis=0)
        span = keys.max(axis=0) + 1
        flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
        _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
        sums = np.zeros((counts.size, 3))
        np.add.at(sums, inverse, pts)
        nsum = np.zeros((counts.size, 3))
        np.add.at(nsum, inverse, nrm)
        np.testing.assert_array_equal(got, sums / counts[:, None])
        np.testing.assert_array_equal(
            got_n, nsum / np.maximum(np.linalg.norm(nsum, axis=1, keepdims=True), 1e-12))
        assert got.shape[0] < pts.shape[0]


def _keypoint_depths_arrays(depth_m, uv):
    """The array form `features.keypoint_depths` had (reference)."""
    h, w = depth_m.shape
    n = uv.shape[0]
    u = np.clip(np.rint(uv[:, 0]).astype(np.intp), 0, w - 1)
    v = np.clip(np.rint(uv[:, 1]).astype(np.intp), 0, h - 1)
    offsets = np.array([-1, 0, 1])
    uu = np.clip(u[:, None, None] + offsets[None, None, :], 0, w - 1)
    vv = np.clip(v[:, None, None] + offsets[None, :, None], 0, h - 1)
    patch = depth_m[vv, uu].reshape(n, 9)
    centre = patch[:, 4]
    valid = (patch > 0) & (np.abs(patch - centre[:, None])
                           <= features._DEPTH_NEIGHBOUR_TOLERANCE * centre[:, None])
    weights = valid * features._DEPTH_WEIGHTS[None, :]
    total = weights.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = (patch * weights).sum(axis=1) / total
    z[~(centre > 0)] = np.nan
    return z.astype(np.float32)


def test_compiled_keypoint_depths_equal_the_array_form():
    cam = kinect_camera(320, 240)
    room = BoxRoom(size_x=8.0, size_y=4.0, height=2.5, seed=4)
    rng = np.random.default_rng(9)
    for x, y, yaw in ((1.0, 1.0, 0.3), (6.5, 3.2, 2.5)):
        _, depth = render(room, planar_pose(x, y, yaw), cam)
        depth[100:110, 50:90] = 0  # holes
        depth_m = depth_to_meters(depth)
        # keypoints anywhere, on the borders and beyond them, on exact pixel centres too
        uv = np.concatenate([rng.uniform(-3, 323, (3000, 2)),
                             rng.integers(0, 320, (500, 2)) + 0.5]).astype(np.float32)
        got = features.keypoint_depths(depth_m, uv)
        ref = _keypoint_depths_arrays(depth_m, uv)
        np.testing.assert_array_equal(got, ref)
        assert 0.5 * len(uv) < np.isfinite(got).sum() < len(uv)


def test_retain_freed_memory_sets_glibc_thresholds():
    import platform

    ok = features.retain_freed_memory()
    assert isinstance(ok, bool)
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert ok
