"""``eddie world list|show``."""

from __future__ import annotations

import argparse

import cv2

from eddiebot.cli import world


def _run(argv):
    parser = argparse.ArgumentParser()
    world.add_arguments(parser)
    return world.run(parser.parse_args(argv))


def test_list(capsys):
    assert _run(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("office", "maze", "warehouse", "depot", "corridor", "house"):
        assert name in out


def test_show_writes_png_and_maps(tmp_path, capsys):
    out = tmp_path / "o.png"
    assert _run(["show", "maze", "-o", str(out), "--scale", "10", "--maps", str(tmp_path / "m")]) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape[1] > 100
    assert (tmp_path / "m" / "maze-scan.yaml").exists()
    assert (tmp_path / "m" / "maze-footprint.pgm").exists()


def test_show_unknown_world(capsys):
    from eddiebot.cli.main import main

    assert main(["world", "show", "atlantis"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no built-in world 'atlantis'" in err[0]
    assert "Traceback" not in err[0]


def test_a_folder_named_like_a_world_does_not_hide_it(tmp_path, monkeypatch):
    from eddiebot.sim.worlds import load_world

    (tmp_path / "house").mkdir()
    monkeypatch.chdir(tmp_path)
    assert load_world("house").name == "house"
