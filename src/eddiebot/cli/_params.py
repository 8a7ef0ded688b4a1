"""Reading a ``--params`` file (ROS 2 parameters YAML) so that its errors name file and line.

:func:`load_params_file` parses one (``ParamsFileError``: ``FILE:LINE:COLUMN: malformed
YAML: ...``); :func:`check_nav_params` refuses a key no Nav2 server of eddiebot has
(``FILE:LINE: node /amcl has no parameter 'alpha_1'``), the rule launch files follow for
every other node: Nav2's servers take any key (their plugins' parameters are declared on
the fly), so a misspelt one would otherwise be ignored without a word.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

import yaml

from eddiebot.cli.errors import ParamsFileError

__all__ = ["check_nav_params", "load_params_file"]

#: Parameters every node has, besides those its class declares.
_COMMON_PARAMETERS = frozenset({"use_sim_time"})


def load_params_file(path: Path) -> tuple[Any, yaml.Node | None]:
    """The document and its YAML node tree (for line numbers) of a parameters file."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParamsFileError(f"{path}: cannot read the parameters file: "
                              f"{exc.strerror or exc}") from exc
    try:
        return yaml.safe_load(text), yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
        raise ParamsFileError(f"{where}: malformed YAML: {exc.problem or exc.context}") from exc
    except yaml.YAMLError as exc:
        raise ParamsFileError(f"{path}: malformed YAML: {exc}") from exc


def _child(node: yaml.Node | None, key: str) -> yaml.Node | None:
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            if isinstance(k, yaml.ScalarNode) and k.value == key:
                return v
    return None


def _key_line(node: yaml.Node | None, key: str) -> int | None:
    if isinstance(node, yaml.MappingNode):
        for k, _ in node.value:
            if isinstance(k, yaml.ScalarNode) and k.value == key:
                return int(k.start_mark.line) + 1
    return None


def _nav_servers() -> dict[str, frozenset[str]]:
    """Node name → the top-level parameters of each Nav2 server eddiebot runs."""
    from eddiebot.nav.nodes._common import NavServer
    from eddiebot.registry import NODES

    out: dict[str, frozenset[str]] = {}
    for target in NODES.values():
        module_name, _, class_name = target.partition(":")
        if not module_name.startswith("eddiebot.nav."):
            continue
        cls = getattr(importlib.import_module(module_name), class_name)
        if isinstance(cls, type) and issubclass(cls, NavServer):
            out[cls.default_node_name] = frozenset(cls.PARAMETERS) | _COMMON_PARAMETERS
    return out


def check_nav_params(path: Path, doc: Any, tree: yaml.Node | None) -> None:
    """Raise `ParamsFileError` at the first scalar or list parameter of a Nav2 server that
    the server does not have. Mappings are plugin or costmap namespaces and are left to
    the server; sections of other nodes are left to the launch (which names them)."""
    if not isinstance(doc, dict):
        raise ParamsFileError(f"{path}: top level must map node names to "
                              "{ros__parameters: ...}")
    servers = _nav_servers()
    for section, body in doc.items():
        known = servers.get(str(section))
        params = body.get("ros__parameters") if isinstance(body, dict) else None
        if known is None or not isinstance(params, dict):
            continue
        params_node = _child(_child(tree, str(section)), "ros__parameters")
        for key, value in params.items():
            if isinstance(value, dict) or key in known:
                continue
            line = _key_line(params_node, str(key))
            where = f"{path}:{line}" if line is not None else str(path)
            raise ParamsFileError(f"{where}: node /{section} has no parameter {key!r}")
