"""The running system of each stack, drawn from its launch file, for docs/architecture.md.

Each stack's launch description is built in a private ``Context`` (sim time, no transport),
its lifecycle managers bring their nodes up (lifecycle nodes make most of their publishers
and subscriptions on configure), every node's publishers, subscriptions, action servers and
clients and service clients are read, and everything is destroyed again. Nothing spins.
The result is one Mermaid ``flowchart LR`` per stack, written between the markers
``<!-- launch-graph:begin -->`` and ``<!-- launch-graph:end -->`` of docs/architecture.md.

    python tools/launch_graph.py            # print the section
    python tools/launch_graph.py --write    # rewrite it in docs/architecture.md
    python tools/launch_graph.py --check    # exit 1 when docs/architecture.md is stale
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import sys
import tempfile
import textwrap
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
BEGIN = "<!-- launch-graph:begin -->"
END = "<!-- launch-graph:end -->"

#: Topics every node or launcher carries that say nothing about the data flow.
PLUMBING_EXACT = ("/parameter_events", "/rosout", "/bond", "/clock")
PLUMBING_SUFFIX = ("/transition_event",)
TF_TOPICS = ("/tf", "/tf_static")
#: Services every (lifecycle) node serves: parameters and state transitions.
PLUMBING_SERVICE_SUFFIX = (
    "/describe_parameters", "/get_parameter_types", "/get_parameters", "/list_parameters",
    "/set_parameters", "/set_parameters_atomically", "/get_type_description",
    "/change_state", "/get_state", "/get_available_states", "/get_available_transitions",
    "/get_transition_graph",
)
ACTION_INFIX = "/_action/"
#: Width of the prose of docs/architecture.md.
_WIDTH = 92


@dataclass(frozen=True)
class Stack:
    """One stack: its heading, the command that runs it, the launch file and its arguments."""

    key: str
    title: str
    command: str
    launch: str
    args: Callable[[Path], dict[str, str]]


def _nav_args(tmp: Path) -> dict[str, str]:
    """What ``eddie nav --world office --map …`` hands nav_sim: a map and the resolved Nav2
    parameters (costmaps folded into the servers)."""
    import numpy as np

    from eddiebot.maps import OccupancyMap, save_map
    from eddiebot.nav.params_file import default_params, resolve_params

    grid = np.zeros((40, 40), np.int8)
    grid[0, :] = grid[-1, :] = grid[:, 0] = grid[:, -1] = 100
    map_yaml = save_map(OccupancyMap(grid, 0.05, (-1.0, -1.0, 0.0)), tmp / "map")
    params = resolve_params(default_params(), tmp, None, warn=lambda _line: None)
    return {"world": "office", "map": str(map_yaml), "params_file": str(params),
            "localization": "amcl"}


STACKS: tuple[Stack, ...] = (
    Stack("base", "Base", "eddie launch bringup port:=emulator:1.1", "bringup",
          lambda _tmp: {"port": "emulator:1.1"}),
    Stack("slam", "SLAM + navigation, mapping", "eddie slam --world office", "slam",
          lambda _tmp: {"world": "office"}),
    Stack("nav", "SLAM + navigation, navigating", "eddie nav --world office --map office.yaml",
          "nav_sim", _nav_args),
    Stack("vslam", "vSLAM", "eddie vslam --world office", "vslam",
          lambda tmp: {"world": "office", "database_path": str(tmp / "rtabmap.db")}),
)


@dataclass
class NodeInfo:
    """What one node of a launch publishes, subscribes to, serves and calls."""

    name: str
    group: str
    publishes: set[str] = field(default_factory=set)
    subscribes: set[str] = field(default_factory=set)
    action_servers: set[str] = field(default_factory=set)
    action_clients: set[str] = field(default_factory=set)
    services: set[str] = field(default_factory=set)
    service_clients: set[str] = field(default_factory=set)


@dataclass
class Graph:
    stack: Stack
    nodes: list[NodeInfo]

    @property
    def topics(self) -> list[str]:
        return sorted({t for n in self.nodes for t in n.publishes | n.subscribes})

    @property
    def actions(self) -> list[str]:
        return sorted({a for n in self.nodes for a in n.action_servers | n.action_clients})

    @property
    def service_calls(self) -> list[tuple[str, str, str]]:
        """(client node, service, server node) for services served and called in the stack."""
        server = {s: n.name for n in self.nodes for s in n.services}
        return sorted((n.name, s, server[s]) for n in self.nodes for s in n.service_clients
                      if s in server and server[s] != n.name)


def is_plumbing(topic: str) -> bool:
    return topic in PLUMBING_EXACT or topic.endswith(PLUMBING_SUFFIX)


def _topic(name: str) -> str | None:
    """The topic as drawn: None for plumbing and action topics, ``TF`` for /tf and /tf_static."""
    if is_plumbing(name) or ACTION_INFIX in name:
        return None
    return "TF" if name in TF_TOPICS else name


def _action(name: str) -> str | None:
    head, sep, _ = name.partition(ACTION_INFIX)
    return head if sep else None


@contextlib.contextmanager
def _quiet_private_env(tmp: Path) -> Iterator[None]:
    """No transport, no user calibration file, and no log lines while stacks come and go."""
    saved = {k: os.environ.get(k) for k in ("EDDIE_TRANSPORT", "EDDIE_CALIBRATION")}
    os.environ["EDDIE_TRANSPORT"] = "none"
    os.environ["EDDIE_CALIBRATION"] = str(tmp / "no-calibration.yaml")
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(logging.NOTSET)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def collect(stack: Stack, tmp: Path) -> Graph:
    """Build ``stack`` in a private context, bring its lifecycle nodes up, read it, destroy it."""
    from eddiebot.core.context import Context
    from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
    from eddiebot.core.lifecycle import LifecycleManager
    from eddiebot.registry import NODES

    desc = parse_launch_file(find_launch_file(stack.launch), stack.args(tmp))
    context = Context(use_sim_time=True)
    nodes = build_nodes(desc, context, NODES)
    try:
        for node in nodes:
            if isinstance(node, LifecycleManager) and node.get_parameter("autostart").value \
                    and not node.startup():
                raise RuntimeError(f"{stack.launch}: {node.get_name()}: {node.last_error}")
        infos = []
        for spec, node in zip(desc.nodes, nodes):
            info = NodeInfo(node.fully_qualified_name, Path(spec.where.rsplit(":", 1)[0]).name)
            for pub in node.publishers:
                if (action := _action(pub.topic_name)) is not None:
                    info.action_servers.add(action)
                elif (topic := _topic(pub.topic_name)) is not None:
                    info.publishes.add(topic)
            for sub in node.subscriptions:
                if (topic := _topic(sub.topic_name)) is not None:
                    info.subscribes.add(topic)
            for srv in node.services:
                if ACTION_INFIX not in srv.srv_name and not srv.srv_name.endswith(PLUMBING_SERVICE_SUFFIX):
                    info.services.add(srv.srv_name)
            for client in node.clients:
                if (action := _action(client.srv_name)) is not None:
                    info.action_clients.add(action)
                elif not client.srv_name.endswith(PLUMBING_SERVICE_SUFFIX):
                    info.service_clients.add(client.srv_name)
            infos.append(info)
    finally:
        for node in reversed(nodes):
            node.destroy_node()
        context.shutdown()
    return Graph(stack, infos)


def collect_all() -> list[Graph]:
    with tempfile.TemporaryDirectory(prefix="launch_graph_") as d, _quiet_private_env(Path(d)):
        return [collect(stack, Path(d)) for stack in STACKS]


# -- rendering ---------------------------------------------------------------------------

def _id(prefix: str, name: str) -> str:
    return prefix + (re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "root")


def render(graph: Graph) -> str:
    """One Mermaid flowchart: nodes as boxes grouped by launch file, topics as rounded nodes,
    TF as one circle, actions as hexagons, service calls as dotted labelled edges."""
    lines = ["```mermaid", "flowchart LR"]
    groups: dict[str, list[NodeInfo]] = {}
    for n in graph.nodes:
        groups.setdefault(n.group, []).append(n)
    for group, members in groups.items():
        lines.append(f'  subgraph {_id("g_", group)}["{group}"]')
        lines.extend(f'    {_id("n_", n.name)}["{n.name}"]' for n in members)
        lines.append("  end")
    published = {t for n in graph.nodes for t in n.publishes}
    inputs = []
    for topic in graph.topics:
        if topic == "TF":
            lines.append('  t_TF(("TF"))')
        else:
            lines.append(f'  {_id("t_", topic)}(["{topic}"])')
        if topic not in published:
            inputs.append(_id("t_", topic))
    for action in graph.actions:
        lines.append(f'  {_id("a_", action)}{{{{"{action}"}}}}')
    for n in graph.nodes:
        nid = _id("n_", n.name)
        lines.extend(f"  {nid} --> {_id('t_', t)}" for t in sorted(n.publishes))
    for n in graph.nodes:
        nid = _id("n_", n.name)
        lines.extend(f"  {_id('t_', t)} --> {nid}" for t in sorted(n.subscribes))
    for n in graph.nodes:
        nid = _id("n_", n.name)
        lines.extend(f"  {nid} -.-> {_id('a_', a)}" for a in sorted(n.action_clients))
        lines.extend(f"  {_id('a_', a)} -.- {nid}" for a in sorted(n.action_servers))
    for client, service, server in graph.service_calls:
        lines.append(f'  {_id("n_", client)} -.->|"{service}"| {_id("n_", server)}')
    lines.append("  classDef topic fill:#eef4ff,stroke:#6b8fd6")
    lines.append("  classDef input fill:#fff,stroke:#6b8fd6,stroke-dasharray:4 3")
    lines.append("  classDef action fill:#fff4e0,stroke:#d69a2d")
    drawn = [_id("t_", t) for t in graph.topics if _id("t_", t) not in inputs]
    if drawn:
        lines.append(f"  class {','.join(drawn)} topic")
    if inputs:
        lines.append(f"  class {','.join(inputs)} input")
    if graph.actions:
        lines.append(f"  class {','.join(_id('a_', a) for a in graph.actions)} action")
    lines.append("```")
    return "\n".join(lines)


def _counts(graph: Graph) -> str:
    parts = [f"{len(graph.nodes)} nodes", f"{len(graph.topics)} topics (TF counted once)"]
    if graph.actions:
        parts.append(f"{len(graph.actions)} actions")
    if graph.service_calls:
        parts.append(f"{len(graph.service_calls)} service calls between nodes")
    return ", ".join(parts)


def section(graphs: list[Graph]) -> str:
    """The whole generated section, markers included."""
    out = [
        BEGIN,
        "## The running system (generated from the launch files)",
        "",
        "Regenerate this section with `python tools/launch_graph.py --write` after changing a "
        "launch file or a node's topics; `tests/test_launch_graph.py` fails while it is stale.",
        "",
        "Each launch file is built in a private context (sim time, no transport), its lifecycle "
        "managers bring their nodes up, and every node's publishers, subscriptions, actions and "
        "service clients are read; nothing spins. Boxes are nodes, grouped by the launch file "
        "that starts them; rounded boxes are topics (dashed: nobody in the stack publishes it, "
        "it comes from outside, such as teleop, the dashboard or `eddie goal`); the `TF` circle "
        "is `/tf` and `/tf_static`; hexagons are actions (dotted arrow from a client, dotted "
        "line to the server); a dotted labelled arrow is a service one node calls on another. "
        "Lifecycle managers stand alone: their state changes and bonds are plumbing.",
        "",
    ]
    for graph in graphs:
        s = graph.stack
        out += [f"### {s.title}: `{s.command}`", "", f"Launch file `{s.launch}`: {_counts(graph)}.",
                "", render(graph), "",
                "Not drawn: `/parameter_events`, `/rosout`, `*/transition_event`, `/bond`, "
                "`/clock`, and the parameter and lifecycle services every node has; services "
                "nobody in the stack calls are not drawn either.", ""]
    out.append(END)
    # prose wrapped as the rest of the page; headings, diagrams and markers as they are
    return "\n".join(line if line.startswith(("#", "<!--", "```")) else
                     textwrap.fill(line, _WIDTH, break_on_hyphens=False) for line in out)


def splice(doc: str, new_section: str) -> str:
    """``doc`` with the text from BEGIN to END replaced; raise if the markers are missing."""
    start, stop = doc.find(BEGIN), doc.find(END)
    if start < 0 or stop < start:
        raise SystemExit(f"{DOC}: markers {BEGIN} ... {END} not found")
    return doc[:start] + new_section + doc[stop + len(END):]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--write", action="store_true", help=f"rewrite the section of {DOC.name}")
    mode.add_argument("--check", action="store_true", help="exit 1 if the section is stale")
    parser.add_argument("--doc", type=Path, default=DOC, help="the page (default: %(default)s)")
    args = parser.parse_args(argv)
    new = section(collect_all())
    if not (args.write or args.check):
        print(new)
        return 0
    doc = args.doc.read_text(encoding="utf-8")
    updated = splice(doc, new)
    if args.check:
        if updated != doc:
            print(f"{args.doc}: the launch-graph section is stale; run "
                  "python tools/launch_graph.py --write", file=sys.stderr)
            return 1
        return 0
    if updated != doc:
        args.doc.write_text(updated, encoding="utf-8")
        print(f"{args.doc}: launch-graph section rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
