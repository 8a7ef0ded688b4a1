"""``eddie vslam replay``: intrinsics and depth units from options, not constants, on the
ICL-NUIM sample (depth 1000 units per metre, TUM folders written into tmp_path)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from icl_data import ICL, needs_icl, write_icl_tum

from eddiebot.cli import vslam as cli
from eddiebot.vslam.tum import read_tum_trajectory

FRAMES = list(range(0, 211, 3))


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="eddie vslam")
    cli.add_arguments(parser)
    return cli.run(parser.parse_args(argv))


def _report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


@needs_icl
def test_depth_scale_option_matches_the_same_frames_at_5000_units(tmp_path):
    native = write_icl_tum(tmp_path / "icl1000", FRAMES)
    depth5000 = tmp_path / "depth5000"
    depth5000.mkdir()
    for i in FRAMES:
        raw = cv2.imread(str(ICL / "depth" / f"{i:05d}.png"), cv2.IMREAD_UNCHANGED)
        assert raw.dtype == np.uint16 and int(raw.max()) * 5 < 65536
        cv2.imwrite(str(depth5000 / f"{i:05d}.png"), (raw.astype(np.uint32) * 5).astype(np.uint16))
    recoded = write_icl_tum(tmp_path / "icl5000", FRAMES, depth_dir=depth5000)

    a, b = tmp_path / "out_a", tmp_path / "out_b"
    assert _run(["replay", str(native), "-o", str(a), "--depth-scale", "1000"]) == 0
    assert _run(["replay", str(recoded), "-o", str(b)]) == 0
    ra, rb = _report(a), _report(b)
    assert ra["depth_scale"] == 1000.0 and ra["depth_scale_source"] == "--depth-scale"
    assert rb["depth_scale"] == 5000.0 and "default" in rb["depth_scale_source"]
    assert ra["intrinsics"] == [525.0, 525.0, 319.5, 239.5, 640, 480]
    assert "default" in ra["intrinsics_source"]
    assert ra["slam_ate_m"] < 0.03  # against Open3D's reconstruction of the sample
    assert abs(ra["slam_ate_m"] - rb["slam_ate_m"]) <= 0.05 * rb["slam_ate_m"]
    _, pa = read_tum_trajectory(a / "poses.txt")
    _, pb = read_tum_trajectory(b / "poses.txt")
    assert pa.shape == pb.shape == (len(FRAMES), 4, 4)
    assert np.max(np.linalg.norm(pa[:, :3, 3] - pb[:, :3, 3], axis=1)) < 0.01


@needs_icl
@pytest.mark.parametrize("scale", ["100", "1"])
def test_an_implausible_depth_scale_is_refused(tmp_path, capsys, scale):
    folder = write_icl_tum(tmp_path / "icl", FRAMES[:3])
    assert _run(["replay", str(folder), "-o", str(tmp_path / "out"), "--depth-scale", scale]) == 1
    err = capsys.readouterr().err
    assert "--depth-scale" in err and "median valid depth" in err
    assert not (tmp_path / "out").exists()


@needs_icl
def test_intrinsics_from_options_and_camera_info_yaml(tmp_path, capsys):
    folder = write_icl_tum(tmp_path / "icl", FRAMES[:4])
    info = tmp_path / "kinect.yaml"
    info.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: kinect\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [520.0, 0, 318.0, 0, 521.0, 241.0, 0, 0, 1]\n"
        "distortion_model: plumb_bob\n"
        "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0, 0, 0, 0, 0]\n")
    out = tmp_path / "yaml"
    assert _run(["replay", str(folder), "-o", str(out), "--depth-scale", "1000",
                 "--camera-info", str(info)]) == 0
    r = _report(out)
    assert r["intrinsics"] == [520.0, 521.0, 318.0, 241.0, 640, 480]
    assert r["intrinsics_source"] == f"--camera-info {info}"
    out = tmp_path / "opts"
    assert _run(["replay", str(folder), "-o", str(out), "--depth-scale", "1000",
                 "--fx", "530", "--fy", "531", "--cx", "320", "--cy", "240"]) == 0
    r = _report(out)
    assert r["intrinsics"] == [530.0, 531.0, 320.0, 240.0, 640, 480]
    assert r["intrinsics_source"] == "--fx/--fy/--cx/--cy"
    capsys.readouterr()
    assert _run(["replay", str(folder), "-o", str(out), "--fx", "530"]) == 2
    assert "all four" in capsys.readouterr().err
    bad = tmp_path / "small.yaml"
    bad.write_text(info.read_text().replace("640", "320"))
    assert _run(["replay", str(folder), "-o", str(out), "--camera-info", str(bad)]) == 1
    assert "320x480" in capsys.readouterr().err


def _depth_bag(path: Path, millimetres: float) -> Path:
    from eddiebot.bag import BagWriter
    from eddiebot.msgs.sensor_msgs import CameraInfo, Image

    depth = np.full((48, 64), millimetres, np.uint16)
    with BagWriter(path) as w:
        info = CameraInfo(width=64, height=48, k=np.array([52.0, 0, 31.5, 0, 53.0, 23.5, 0, 0, 1]))
        w.write_message("/camera_info", info, 1_000_000_000)
        w.write_message("/depth/image_raw", Image(
            height=48, width=64, encoding="16UC1", step=128,
            data=np.frombuffer(depth.tobytes(), np.uint8).copy()), 1_000_000_000)
    return path


def test_a_bag_reports_its_camera_info_and_refuses_implausible_depth(tmp_path, capsys):
    from eddiebot.bag import BagReader
    from eddiebot.vslam.errors import DepthScaleError

    with BagReader(_depth_bag(tmp_path / "ok", 1500)) as reader:
        cam = cli._bag_camera(reader, {c.topic for c in reader.connections})
    assert cam["intrinsics"] == [52.0, 53.0, 31.5, 23.5, 64, 48]
    assert cam["intrinsics_source"] == "the bag's /camera_info"
    assert cam["depth_scale"] == 1000.0 and "16UC1" in cam["depth_scale_source"]
    # depth recorded in 0.1 mm puts the scene at 15 m
    with BagReader(_depth_bag(tmp_path / "bad", 15000)) as reader, \
            pytest.raises(DepthScaleError, match="median valid depth is 15 m"):
        cli._bag_camera(reader, {c.topic for c in reader.connections})
    # a bag carries its own calibration: the folder options are refused, not ignored
    assert _run(["replay", str(tmp_path / "ok"), "-o", str(tmp_path / "o"),
                 "--depth-scale", "1000"]) == 2
    assert "--depth-scale" in capsys.readouterr().err
