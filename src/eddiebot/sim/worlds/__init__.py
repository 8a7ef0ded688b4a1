"""Built-in simulator worlds (YAML files shipped in this package) and how to find them.

`list_worlds()` names them; `world_path(name)` gives the file; `load_world(name_or_path)`
loads a built-in world by name or any world file by path. Each has a PNG top view
(``<name>.png``) beside it.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from eddiebot.sim.errors import UnknownWorldError
from eddiebot.sim.world import World, load_world_file, world_from_nav2_map

__all__ = ["WORLDS_DIR", "list_worlds", "load_world", "preview_path", "world_path"]

WORLDS_DIR = Path(__file__).parent


def list_worlds() -> list[str]:
    """Names of the built-in worlds, sorted."""
    return sorted(p.stem for p in WORLDS_DIR.glob("*.yaml"))


def world_path(name: str) -> Path:
    """The YAML file of built-in world ``name``. Raises `UnknownWorldError`."""
    path = WORLDS_DIR / f"{name}.yaml"
    if not path.is_file():
        raise UnknownWorldError(f"no built-in world {name!r} (built-in: {', '.join(list_worlds())})")
    return path


def preview_path(name: str) -> Path:
    """The PNG top view shipped with built-in world ``name``."""
    return world_path(name).with_suffix(".png")


def load_world(name_or_path: str | Path) -> World:
    """A built-in world by name, or a file by path: a world YAML file, or a nav2 map YAML
    (one with ``image:`` and ``resolution:``) extruded to 2 m walls."""
    p = Path(name_or_path)
    # a bare name is a built-in world even when a folder of that name is in the way
    if p.suffix in (".yaml", ".yml") or p.is_file() or len(p.parts) > 1:
        if not p.is_file():
            raise UnknownWorldError(f"world file {p} does not exist")
        if _is_nav2_map(p):
            return world_from_nav2_map(p)
        return load_world_file(p)
    return load_world_file(world_path(str(name_or_path)))


def _is_nav2_map(path: Path) -> bool:
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError):
        return False
    return isinstance(doc, dict) and "image" in doc and "resolution" in doc
