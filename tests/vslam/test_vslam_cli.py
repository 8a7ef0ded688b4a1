"""``eddie vslam loops`` and ``eddie vslam db info/export`` on small generated inputs."""

import argparse
import csv
import json

import cv2
from vslam_synthetic import frame, kinect_camera

from _support.vslam_session import write_session_database
from eddiebot.cli import vslam as cli

CAM = kinect_camera(320, 240)
SEC = 1_000_000_000


def _run(argv):
    parser = argparse.ArgumentParser(prog="eddie vslam")
    cli.add_arguments(parser)
    return cli.run(parser.parse_args(argv))


def test_loops_writes_query_match_score_rows(tmp_path):
    folder = tmp_path / "images"
    folder.mkdir()
    # out along x looking at one wall, then a turn, then back at the first places
    poses = [(2.0 + 0.4 * k, 3.0, 0.0) for k in range(8)]
    poses += [(5.0, 3.0, 1.2 * k) for k in range(1, 4)]
    poses += [(2.0 + 0.4 * k, 3.0, 0.0) for k in range(3)]
    for i, (x, y, yaw) in enumerate(poses):
        rgb, _ = frame(3, x, y, yaw)
        cv2.imwrite(str(folder / f"img{i + 1}.png"), rgb[:, :, ::-1])
    out = tmp_path / "loops.csv"
    assert _run(["loops", str(folder), "-o", str(out)]) == 0
    rows = list(csv.reader(out.open()))
    assert rows[0] == ["query", "match", "score"]
    assert len(rows) == len(poses) + 1
    assert [r[0] for r in rows[1:3]] == ["img1.png", "img2.png"]  # numeric order
    for r in rows[1:]:
        assert 0.0 <= float(r[2]) <= 1.0
        assert r[1] == "" or r[1].endswith(".png")


def test_db_info_and_export(tmp_path, capsys):
    db = tmp_path / "map.db"
    write_session_database(db)
    assert _run(["db", "info", str(db), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["nodes"] == 6 and info["sessions"] == 1
    assert info["link_types"]["neighbor"] == 5
    assert abs(info["path_length_m"] - 1.0) < 0.05
    assert info["Reg/Force3DoF"] == "true"
    ply, tum = tmp_path / "cloud.ply", tmp_path / "poses.tum"
    assert _run(["db", "export", str(db), "--ply", str(ply), "--poses", str(tum)]) == 0
    assert ply.read_bytes().startswith(b"ply")
    lines = [ln for ln in tum.read_text().splitlines() if not ln.startswith("#")]
    assert len(lines) == 6
    assert abs(float(lines[-1].split()[1]) - 1.0) < 0.05
    # export does not start a new mapping session
    capsys.readouterr()
    assert _run(["db", "info", str(db), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["sessions"] == 1


def test_db_info_refuses_a_file_that_is_not_a_session(tmp_path, capsys):
    bad = tmp_path / "x.db"
    bad.write_bytes(b"not a database" * 100)
    assert _run(["db", "info", str(bad)]) == 1
    assert "x.db" in capsys.readouterr().err
