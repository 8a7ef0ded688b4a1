"""A Nav2 user's parameters file made ready for eddiebot's servers: unsupported sections and
keys named and left out, costmaps folded into their servers, AMCL's initial pose set. The
CLI and the demo both resolve their parameters here."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import yaml

from eddiebot.core.errors import ParameterFileError
from eddiebot.core.parameters import load_params_file
from eddiebot.nav.nodes._common import nest_nav2_params
from eddiebot.nav.nodes.params_audit import audit_nav2_params

__all__ = ["default_params", "resolve_params"]

_log = logging.getLogger(__name__)


def _log_warning(text: str) -> None:
    _log.warning("%s", text)


def default_params() -> Path:
    from eddiebot.core.launch import package_share

    return package_share() / "config" / "nav2.yaml"


def resolve_params(source: Path, out_dir: Path, initial_pose: tuple[float, float, float] | None,
                   *, warn: Callable[[str], None] = _log_warning) -> Path:
    """Write the Nav2 parameters with the costmaps folded in (and AMCL's initial pose).

    A Nav2 user's file drops in: each section of a server eddiebot does not run and each key
    no server or plugin reads is named once through ``warn`` (``FILE: not supported: …``,
    ``FILE: ignored: …``) and left out. Raises `ParameterFileError` (``FILE:LINE: ...``) for a
    file that is not YAML, and `eddiebot.nav.errors.UnsupportedPlugin` (server, key,
    plugin) for a plugin that cannot be configured.
    """

    doc, _ = load_params_file(source)
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise ParameterFileError(f"{source}: top level must map node names to "
                              "{ros__parameters: {...}}")
    audit = audit_nav2_params(doc)
    for warning in audit.warnings:
        warn(f"{source}: {warning}")
    doc = nest_nav2_params(audit.supported)
    if initial_pose is not None:
        amcl = doc.setdefault("amcl", {}).setdefault("ros__parameters", {})
        amcl["set_initial_pose"] = True
        amcl["initial_pose"] = {"x": initial_pose[0], "y": initial_pose[1], "z": 0.0,
                                "yaw": initial_pose[2]}
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / "nav2_params.yaml"
    tmp = out.with_suffix(".yaml.tmp")
    tmp.write_text(f"# resolved from {source}\n" + yaml.safe_dump(doc, sort_keys=False))
    tmp.replace(out)
    return out
