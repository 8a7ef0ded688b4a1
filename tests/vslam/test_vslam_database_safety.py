"""The database is the user's map: never deleted by default, a foreign or damaged file is
refused and left as it is, ``db info``/``db export`` only read."""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import pytest

from _support.vslam_session import write_session_database
from eddiebot.cli import vslam as cli
from eddiebot.core.context import Context
from eddiebot.vslam.database import SessionDatabase, is_session_database
from eddiebot.vslam.errors import DatabaseCorruptError, DatabaseError
from eddiebot.vslam.node import RtabmapNode


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="eddie vslam")
    cli.add_arguments(parser)
    return cli.run(parser.parse_args(argv))


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def foreign(tmp_path: Path) -> Path:
    path = tmp_path / "thesis.db"
    path.write_bytes(b"my notes, not a map\n" * 200)
    return path


def test_session_database_never_deletes_or_maps_over_a_foreign_file(foreign):
    before = _digest(foreign)
    assert not is_session_database(foreign)
    with pytest.raises(DatabaseCorruptError, match="refusing to delete"):
        SessionDatabase(foreign, delete_on_start=True)
    with pytest.raises(DatabaseCorruptError, match=r"not a readable database|not an eddiebot"):
        SessionDatabase(foreign)
    assert _digest(foreign) == before


def test_node_refuses_a_foreign_database_instead_of_mapping_without_one(foreign):
    before = _digest(foreign)
    for delete in (False, True):
        context = Context(use_sim_time=True)
        try:
            with pytest.raises(DatabaseError, match=foreign.name):
                RtabmapNode(context=context, parameter_overrides={
                    "use_sim_time": True, "database_path": str(foreign),
                    "delete_db_on_start": delete})
        finally:
            context.shutdown()
    assert _digest(foreign) == before


def test_sim_keeps_the_database_unless_delete_db_on_start(tmp_path, monkeypatch, foreign):
    import eddiebot.cli._stack as stack

    launched: list[dict[str, str]] = []
    monkeypatch.setattr(stack, "run_stack",
                        lambda args, name, launch_args: launched.append(launch_args) or 0)
    ours = tmp_path / "map.db"
    write_session_database(ours, n=2)
    assert _run(["--world", "office", "--database", str(ours)]) == 0
    assert launched[-1]["delete_db_on_start"] == "false"
    assert _run(["sim", "--database", str(ours), "--delete_db_on_start"]) == 0
    assert launched[-1]["delete_db_on_start"] == "true"
    assert _run(["--world", "office", "--database", str(ours), "--delete_db_on_start",
                 "--localization"]) == 0
    assert launched[-1]["delete_db_on_start"] == "false"
    # a file that is not ours is refused before anything starts, whatever the flags
    before = _digest(foreign)
    n = len(launched)
    assert _run(["--world", "office", "--database", str(foreign), "--delete_db_on_start"]) == 1
    assert _run(["--world", "office", "--database", str(foreign)]) == 1
    assert len(launched) == n and _digest(foreign) == before


def test_db_info_and_export_only_read(tmp_path, capsys, foreign):
    missing = tmp_path / "nope.db"
    assert _run(["db", "info", str(missing)]) == 1
    assert "no such database" in capsys.readouterr().err
    assert not missing.exists()
    assert _run(["db", "export", str(missing), "--poses", str(tmp_path / "p.tum")]) == 1
    assert not missing.exists()
    before = _digest(foreign)
    assert _run(["db", "info", str(foreign)]) == 1
    assert _digest(foreign) == before
    ours = tmp_path / "map.db"
    write_session_database(ours, n=3)
    before = _digest(ours)
    ours.chmod(0o444)  # read-only files can be inspected
    try:
        assert _run(["db", "info", str(ours), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["nodes"] == 3
        assert _run(["db", "export", str(ours), "--poses", str(tmp_path / "p.tum")]) == 0
    finally:
        ours.chmod(0o644)
    assert _digest(ours) == before
    assert not Path(str(ours) + "-journal").exists()
