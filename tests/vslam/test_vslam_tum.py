import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from vslam_synthetic import CAMERA_HEIGHT, frame, planar_pose

from eddiebot.vslam.errors import TumFormatError
from eddiebot.vslam.loops import detect_loops, list_images, write_loop_rows
from eddiebot.vslam.replay import replay_tum
from eddiebot.vslam.transforms import OPTICAL_ROTATION, from_xyz_rpy
from eddiebot.vslam.tum import (
    absolute_trajectory_error,
    associate,
    read_file_list,
    read_tum_sequence,
    read_tum_trajectory,
    write_tum_trajectory,
)


def _reference_associate(first, second, offset, max_difference):
    """TUM's associate.py algorithm, verbatim in behaviour (quadratic)."""
    first_keys = list(first)
    second_keys = list(second)
    potential = [(abs(a - (b + offset)), a, b) for a in first_keys for b in second_keys
                 if abs(a - (b + offset)) < max_difference]
    potential.sort()
    matches = []
    for _, a, b in potential:
        if a in first_keys and b in second_keys:
            first_keys.remove(a)
            second_keys.remove(b)
            matches.append((a, b))
    matches.sort()
    return matches


stamps = st.lists(st.floats(0, 5, allow_nan=False).map(lambda v: round(v, 3)), max_size=40,
                  unique=True)


@settings(max_examples=150, deadline=None)
@given(stamps, stamps, st.sampled_from([0.0, 0.01, -0.02]))
def test_association_matches_associate_py(a, b, offset):
    assert associate(a, b, offset, 0.02) == _reference_associate(a, b, offset, 0.02)


def test_association_examples():
    rgb = [1.000, 1.033, 1.066, 1.100]
    depth = [1.005, 1.030, 1.031, 1.090, 1.200]
    # 1.066 has nothing within 0.02 s; 1.033 takes the closer 1.031 (greedy by difference)
    assert associate(rgb, depth) == [(1.0, 1.005), (1.033, 1.031), (1.1, 1.09)]


def test_read_file_list_semantics(tmp_path):
    p = tmp_path / "rgb.txt"
    p.write_text("# color images\n# file: 'x.bag'\n1305031102.175304 rgb/1.png\n"
                 "1305031102.211214,rgb/2.png\n\n1305031102.243211\trgb/3.png\n")
    d = read_file_list(p)
    assert d == {1305031102.175304: ["rgb/1.png"], 1305031102.211214: ["rgb/2.png"],
                 1305031102.243211: ["rgb/3.png"]}
    with pytest.raises(TumFormatError):
        read_tum_sequence(tmp_path / "missing")


def test_trajectory_round_trip_and_ate(tmp_path):
    rng = np.random.default_rng(0)
    stamps = np.arange(20) * 0.1
    poses = [from_xyz_rpy(*rng.normal(size=3), *rng.uniform(-3, 3, size=3)) for _ in stamps]
    write_tum_trajectory(tmp_path / "t.txt", stamps, poses)
    s2, p2 = read_tum_trajectory(tmp_path / "t.txt")
    np.testing.assert_allclose(s2, stamps)
    np.testing.assert_allclose(p2, np.array(poses), atol=1e-6)
    # ATE is invariant to a rigid transform of the estimate
    t = from_xyz_rpy(1, 2, 3, 0.1, 0.2, 0.3)
    moved = np.array([t @ p for p in poses])
    ate, n = absolute_trajectory_error(stamps, moved, stamps, np.array(poses))
    assert n == 20 and ate < 1e-9


def _write_tum_folder(folder, n):
    (folder / "rgb").mkdir(parents=True)
    (folder / "depth").mkdir()
    rgb_lines, depth_lines, gt_lines = [], [], []
    for k in range(n):
        x, yaw = 2.0 + 0.03 * k, 0.01 * k
        rgb, depth_mm = frame(6, x, 3.0, yaw)
        t = 100.0 + k / 30.0
        cv2.imwrite(str(folder / f"rgb/{t:.6f}.png"), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        depth_tum = (depth_mm.astype(np.float64) * 5.0).astype(np.uint16)  # 5000 per metre
        cv2.imwrite(str(folder / f"depth/{t + 0.004:.6f}.png"), depth_tum)
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png")
        depth_lines.append(f"{t + 0.004:.6f} depth/{t + 0.004:.6f}.png")
        cam = planar_pose(x, 3.0, yaw) @ OPTICAL_ROTATION
        cam[2, 3] += CAMERA_HEIGHT
        from eddiebot.vslam.tum import matrix_to_tum_row

        gt_lines.append(f"{t:.6f} " + " ".join(f"{v:.9f}" for v in matrix_to_tum_row(cam)))
    (folder / "rgb.txt").write_text("# rgb\n" + "\n".join(rgb_lines) + "\n")
    (folder / "depth.txt").write_text("# depth\n" + "\n".join(depth_lines) + "\n")
    (folder / "groundtruth.txt").write_text("# gt\n" + "\n".join(gt_lines) + "\n")


def test_replay_tum_synthetic_sequence(tmp_path):
    folder = tmp_path / "rgbd_dataset_synthetic"
    _write_tum_folder(folder, 12)
    seq = read_tum_sequence(folder)
    assert len(seq.frames) == 12 and seq.camera.width == 320
    # the synthetic images use 525·(320/640); TUM folders default to 525 at 640 px
    report = replay_tum(folder, tmp_path / "out", {"RGBD/LinearUpdate": "0"})
    assert report.frames == 12 and report.lost_frames <= 1
    assert (tmp_path / "out" / "poses.txt").is_file()
    assert (tmp_path / "out" / "rtabmap.db").is_file()
    assert np.isfinite(report.odom_ate_m)


def test_detect_loops_over_numbered_images(tmp_path):
    names = []
    views = [0.26 * k for k in range(24)] + [0.26 * k + 0.03 for k in (2, 3, 4)]
    for k, yaw in enumerate(views):
        name = f"img{k + 1}.png"  # numeric order, not lexicographic
        cv2.imwrite(str(tmp_path / name), frame(4, 4.0, 3.0, yaw)[0][:, :, 0])
        names.append(name)
    assert [p.name for p in list_images(tmp_path)] == names
    rows = detect_loops(tmp_path)
    assert [r[0] for r in rows] == names
    # no loop until the turn comes back to overlap the first views
    assert all(r[1] == "" for r in rows[:21])
    assert {r[1] for r in rows[21:24]} <= {"", "img1.png", "img2.png"}
    assert [r[1] for r in rows[-3:]] == ["img3.png", "img4.png", "img5.png"]
    write_loop_rows(rows, tmp_path / "loops.csv")
    text = (tmp_path / "loops.csv").read_text().splitlines()
    assert text[0] == "query,match,score" and text[-1].startswith("img27.png,img5.png,")
