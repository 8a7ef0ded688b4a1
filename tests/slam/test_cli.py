"""``eddie slam replay`` and ``eddie posegraph optimize`` on small generated inputs."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from slam_world import ROOM, drifting_odometry, loop_path, raycast

from eddiebot.cli import posegraph as posegraph_cli
from eddiebot.cli import slam as slam_cli
from eddiebot.slam.io import carmen_beam_angles, read_tum


def _parse(module, argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)
    return parser.parse_args(argv)


def test_slam_replay_writes_map_trajectory_report(tmp_path: Path, capsys) -> None:
    truth = loop_path(0.5)[:24]
    odom = drifting_odometry(truth, seed=3)
    angles = carmen_beam_angles(181)
    lines = ["PARAM robot_frontlaser_offset 0.0 nohost 0"]
    for k, (p, o) in enumerate(zip(truth, odom)):
        r = raycast(ROOM, p, angles, 20.0)
        r[~np.isfinite(r)] = 81.91
        ranges = " ".join(f"{v:.3f}" for v in r)
        pose = " ".join(f"{v:.6f}" for v in o)
        lines.append(f"FLASER 181 {ranges} {pose} {pose} {100.0 + k:.6f} host {k:.6f}")
    lines.insert(5, "FLASER 181 1 2 3")  # malformed: skipped with a warning
    log = tmp_path / "room.clf"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    args = _parse(
        slam_cli,
        [
            "replay",
            str(log),
            "-o",
            str(out),
            "--no-progress",
            "--set",
            "minimum_travel_distance:=0.5",
        ],
    )
    assert slam_cli.run(args) == 0
    # a lidar log gets slam_toolbox's sample values, not Eddie's Kinect and encoder tuning
    assert "parameters: " in capsys.readouterr().err
    assert slam_cli.replay_params(log).name == "slam_defaults.yaml"
    for name in ("map.pgm", "map.yaml", "map.png", "trajectory.tum", "report.md"):
        assert (out / name).is_file(), name
    stamps, poses = read_tum(out / "trajectory.tum")
    assert stamps[0] == 100.0
    assert np.all(np.diff(stamps) > 0)
    assert len(stamps) >= 12
    report = (out / "report.md").read_text()
    assert "bad_line: 1" in report
    assert np.hypot(*(poses[-1, :2] - truth[int(stamps[-1] - 100.0), :2])) < 0.1


def test_replay_parameters_follow_the_input(tmp_path: Path) -> None:
    bag = tmp_path / "run1"
    bag.mkdir()
    assert slam_cli.replay_params(bag).name == "slam.yaml"  # Eddie's own recordings
    assert slam_cli.replay_params(tmp_path / "run1.mcap").name == "slam.yaml"
    for log in ("csail.clf", "intel.log", "intel.log.gz"):
        assert slam_cli.replay_params(tmp_path / log).name == "slam_defaults.yaml"


def test_posegraph_optimize_prints_chi2(tmp_path: Path, capsys) -> None:
    g2o = tmp_path / "square.g2o"
    rows = [
        "VERTEX_SE2 0 0 0 0",
        "VERTEX_SE2 1 1.1 0 1.6",
        "VERTEX_SE2 2 1.0 1.2 3.1",
        "VERTEX_SE2 3 -0.1 1 -1.5",
    ]
    info = "100 0 0 100 0 1000"
    rows += [f"EDGE_SE2 {i} {i + 1} 1 0 1.5707963 {info}" for i in range(3)]
    rows += [f"EDGE_SE2 3 0 1 0 1.5707963 {info}"]
    g2o.write_text("\n".join(rows) + "\n")
    out = tmp_path / "opt.g2o"
    assert posegraph_cli.run(_parse(posegraph_cli, ["optimize", str(g2o), "-o", str(out)])) == 0
    text = capsys.readouterr().out
    assert "final   1/2 chi2: " in text
    final = float(text.split("final   1/2 chi2:")[1].split()[0])
    assert final < 1e-6
    assert out.read_text().count("VERTEX_SE2") == 4
    assert posegraph_cli.run(_parse(posegraph_cli, ["optimize", str(tmp_path / "none.g2o")])) == 1


def test_posegraph_optimize_gate_rejects_a_false_loop(tmp_path: Path, capsys) -> None:
    g2o = tmp_path / "false.g2o"
    info = "100 0 0 100 0 1000"
    rows = ["VERTEX_SE2 0 0 0 0", "VERTEX_SE2 1 1.1 0 1.6", "VERTEX_SE2 2 1.0 1.2 3.1",
            "VERTEX_SE2 3 -0.1 1 -1.5"]
    rows += [f"EDGE_SE2 {i} {i + 1} 1 0 1.5707963 {info}" for i in range(3)]
    rows += [f"EDGE_SE2 3 0 1 0 1.5707963 {info}", f"EDGE_SE2 2 0 4 3 0.5 {info}"]  # last: false
    g2o.write_text("\n".join(rows) + "\n")
    out = tmp_path / "opt.g2o"
    args = ["optimize", str(g2o), "--robust", "dcs", "-o", str(out)]
    assert posegraph_cli.run(_parse(posegraph_cli, args)) == 0
    text = capsys.readouterr().out
    assert "rejected loops:   1" in text
    rest = float(text.split("1/2 chi2 of the rest")[1].split(")")[0])
    assert rest < 1e-6  # the true square closes exactly
    node2 = next(line.split() for line in out.read_text().splitlines()
                 if line.startswith("VERTEX_SE2 2 "))
    assert abs(float(node2[2]) - 1.0) < 1e-3 and abs(float(node2[3]) - 1.0) < 1e-3
    assert posegraph_cli.run(_parse(posegraph_cli, [*args, "--gate", "none"])) == 0
    assert "rejected loops" not in capsys.readouterr().out
