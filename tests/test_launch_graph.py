"""docs/architecture.md's running-system diagrams are what the launch files build
(tools/launch_graph.py; regenerate with ``python tools/launch_graph.py --write``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

TOOL = Path(__file__).resolve().parents[1] / "tools" / "launch_graph.py"


def _load() -> ModuleType:
    spec = importlib.util.spec_from_file_location("launch_graph", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def tool() -> ModuleType:
    return _load()


@pytest.fixture(scope="module")
def graphs(tool: ModuleType) -> list[Any]:
    return tool.collect_all()  # every stack built once for the whole module


def test_architecture_page_is_current(tool: ModuleType, graphs: list[Any]) -> None:
    doc = tool.DOC.read_text(encoding="utf-8")
    assert tool.splice(doc, tool.section(graphs)) == doc, (
        "docs/architecture.md's launch-graph section is stale: "
        "run python tools/launch_graph.py --write")


def test_check_fails_on_a_stale_page(tool: ModuleType, graphs: list[Any], tmp_path: Path,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tool, "collect_all", lambda: graphs)
    page = tmp_path / "architecture.md"
    page.write_text(f"# page\n\n{tool.BEGIN}\nold\n{tool.END}\n\nafter\n", encoding="utf-8")
    assert tool.main(["--check", "--doc", str(page)]) == 1
    assert tool.main(["--write", "--doc", str(page)]) == 0
    assert tool.main(["--check", "--doc", str(page)]) == 0
    text = page.read_text(encoding="utf-8")
    assert text.startswith("# page\n\n") and text.endswith("\n\nafter\n")


def test_every_stack_is_drawn_without_plumbing(graphs: list[Any]) -> None:
    assert [g.stack.launch for g in graphs] == ["bringup", "slam", "nav_sim", "vslam"]
    for g in graphs:
        topics = g.topics
        assert "TF" in topics and "/tf" not in topics and "/tf_static" not in topics
        assert not [t for t in topics if t in ("/parameter_events", "/rosout", "/bond", "/clock")
                    or t.endswith("/transition_event") or "/_action/" in t]
    by_launch = {g.stack.launch: g for g in graphs}
    # the velocity chain of nav.yaml, through the bring-up's mux
    nav = {n.name: n for n in by_launch["nav_sim"].nodes}
    assert "/cmd_vel_nav" in nav["/controller_server"].publishes
    assert "/cmd_vel_safe" in nav["/collision_monitor"].publishes
    assert "/cmd_vel_safe" in nav["/twist_mux"].subscribes
    assert "/navigate_to_pose" in nav["/bt_navigator"].action_servers
    assert "/scan" in {t for n in by_launch["slam"].nodes for t in n.subscribes}
    assert any(n.name == "/rtabmap" for n in by_launch["vslam"].nodes)
