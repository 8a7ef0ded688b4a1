"""Reading a ``--params`` file (ROS 2 parameters YAML) so that its errors name file and line.

:func:`load_params_file` parses one (``ParamsFileError``: ``FILE:LINE:COLUMN: malformed
YAML: ...``). Keys that no Nav2 server reads are named by
:func:`eddiebot.nav.nodes.params_audit.audit_nav2_params`, as ``eddie nav`` does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from eddiebot.cli.errors import ParamsFileError

__all__ = ["load_params_file"]


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
