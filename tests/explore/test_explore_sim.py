"""A whole exploration of a two-room world in the simulator, and the CLI's refusals."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from eddiebot.explore.mission import RETURN_ALLOWANCE, run_exploration
from eddiebot.explore.report import write_report

TWO_ROOMS = """
name: two_rooms
description: two 3 x 3.5 m rooms joined by a 1 m doorway
floor: {texture: wood}
ceiling: {height: 2.5, texture: ceiling}
start: {x: 1.0, y: 1.5, theta: 0.0}
walls:
  - {points: [[0, 0], [6.4, 0], [6.4, 3.5], [0, 3.5], [0, 0]], thickness: 0.15, texture: brick}
  - {points: [[3.2, 0], [3.2, 1.2]], thickness: 0.12, texture: plaster}
  - {points: [[3.2, 2.2], [3.2, 3.5]], thickness: 0.12, texture: plaster}
boxes:
  - {center: [5.2, 2.8], size: [0.8, 0.5], height: 0.9, texture: wood, name: cabinet}
"""


@pytest.fixture
def world_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("EDDIE_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "two_rooms.yaml"
    path.write_text(TWO_ROOMS)
    return path


def test_explores_two_rooms_and_comes_home(world_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run_exploration(out, world=str(world_file), time_limit=240.0,
                             camera=(160, 120, 10.0), wall_timeout_s=240.0)
    write_report(result, out)
    assert result.collisions == 0
    assert result.coverage >= 0.85, result.summary()
    # placed by ATE's fit instead of the start pose: about the same on a good map
    assert abs(result.coverage_aligned - result.coverage) < 0.03, result.summary()
    assert result.map_agreement >= 0.9
    assert result.returned_home, result.summary()
    assert result.reason.startswith(("no reachable frontier left", "time limit"))
    assert result.sim_time_s < 240.0 + RETURN_ALLOWANCE + 61.0
    for name in ("map.yaml", "map.pgm", "report.json", "report.md", "exploration.png"):
        assert (out / name).is_file(), name
    figures = json.loads((out / "report.json").read_text())
    for key in ("coverage", "coverage_aligned", "map_agreement", "ate_m", "distance_m", "sim_time_s", "collisions",
                "returned_home", "frontiers_abandoned", "map_to_world"):
        assert key in figures
    assert figures["map_to_world"] == [1.0, 1.5, 0.0]


CLOSET = """
name: closet
description: a closed 2.5 x 2.5 m room
floor: {texture: wood}
ceiling: {height: 2.5, texture: ceiling}
start: {x: 1.25, y: 1.25, theta: 0.0}
walls:
  - {points: [[0, 0], [2.5, 0], [2.5, 2.5], [0, 2.5], [0, 0]], thickness: 0.15, texture: brick}
"""


def test_a_closed_room_is_done_after_the_look_around(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EDDIE_CACHE_DIR", str(tmp_path / "cache"))
    world = tmp_path / "closet.yaml"
    world.write_text(CLOSET)
    result = run_exploration(tmp_path / "out", world=str(world), camera=(160, 120, 10.0),
                             wall_timeout_s=120.0)
    assert result.reason.startswith("no reachable frontier left (0 unreachable"), result.reason
    assert result.goals_sent == 0 and result.sim_time_s < 30.0
    assert result.coverage > 0.95 and result.returned_home


def test_ctrl_c_stops_the_robot_where_it_is(world_file: Path, tmp_path: Path) -> None:
    seen: dict[str, float] = {}

    def interrupt(node: object, sim_s: float) -> None:
        if len(getattr(node, "goals", ())) >= 2:
            seen["at"] = sim_s
            raise KeyboardInterrupt

    result = run_exploration(tmp_path / "out", world=str(world_file), camera=(160, 120, 10.0),
                             wall_timeout_s=120.0, progress=interrupt)
    assert result.interrupted and result.reason == "interrupted"
    assert not result.returned_home
    assert result.sim_time_s <= seen["at"] + 0.5  # no drive home after the interrupt
    assert (tmp_path / "out" / "map.yaml").is_file()  # what was mapped is kept


def test_explore_resume_pauses_and_resumes(world_file: Path, tmp_path: Path) -> None:
    from eddiebot.msgs.std_msgs import Bool

    log: dict[str, object] = {}

    def operator(node: object, sim_s: float) -> None:
        n: Any = node
        if "pub" not in log:
            log["pub"] = n.create_publisher(Bool, "explore/resume", 10)
        pub: Any = log["pub"]
        if sim_s >= 20.0 and "paused_at" not in log:
            pub.publish(Bool(data=False))
            log["paused_at"], log["goals"] = sim_s, len(n.goals)
        elif sim_s >= 45.0 and "resumed" not in log:
            log["paused_during"] = n.paused and len(n.goals) == log["goals"]
            log["resumed"] = True
            pub.publish(Bool(data=True))

    result = run_exploration(tmp_path / "out", world=str(world_file), time_limit=240.0,
                             camera=(160, 120, 10.0), wall_timeout_s=240.0, progress=operator)
    assert log["paused_during"] is True  # no goal was sent while paused
    assert result.goals_sent > int(log["goals"])  # and exploring went on after the resume
    assert result.returned_home and result.collisions == 0
