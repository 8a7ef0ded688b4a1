"""Where interface files of types we do not ship are looked for.

Two environment variables name folders, read at each look-up (a look-up only happens for a
type missing from the store, so start-up never walks them):

- ``EDDIE_INTERFACE_PATH`` (``:``-separated): each folder holds ``<pkg>/msg/*.msg``,
  ``<pkg>/srv/*.srv``, ``<pkg>/action/*.action``, or is an install prefix with
  ``share/<pkg>/msg/...``;
- ``AMENT_PREFIX_PATH`` (``:``-separated install prefixes, as a sourced ROS 2 workspace
  sets it): ``share/<pkg>/msg/*.msg`` and the like.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["INTERFACE_PATH_ENV", "find_interface_file", "interface_roots", "searched_description"]

INTERFACE_PATH_ENV = "EDDIE_INTERFACE_PATH"
_AMENT_ENV = "AMENT_PREFIX_PATH"


def interface_roots() -> list[Path]:
    """Folders that may hold ``<pkg>/<kind>/<Name>.<kind>``, in search order."""
    roots: list[Path] = []
    for entry in os.environ.get(INTERFACE_PATH_ENV, "").split(os.pathsep):
        if entry:
            roots += [Path(entry), Path(entry) / "share"]
    for entry in os.environ.get(_AMENT_ENV, "").split(os.pathsep):
        if entry:
            roots.append(Path(entry) / "share")
    out: list[Path] = []
    for root in roots:
        if root not in out:
            out.append(root)
    return out


def find_interface_file(pkg: str, kind: str, name: str) -> Path | None:
    """The first ``<root>/<pkg>/<kind>/<name>.<kind>`` of :func:`interface_roots`."""
    for root in interface_roots():
        candidate = root / pkg / kind / f"{name}.{kind}"
        if candidate.is_file():
            return candidate
    return None


def searched_description() -> str:
    """The folders a look-up went through, for an error message."""
    env = [e for e in os.environ.get(INTERFACE_PATH_ENV, "").split(os.pathsep) if e]
    ament = [e for e in os.environ.get(_AMENT_ENV, "").split(os.pathsep) if e]
    parts = [f"{INTERFACE_PATH_ENV}={':'.join(env)}" if env else f"{INTERFACE_PATH_ENV} unset",
             f"{_AMENT_ENV}={':'.join(ament)}" if ament else f"{_AMENT_ENV} unset"]
    return ", ".join(parts)
