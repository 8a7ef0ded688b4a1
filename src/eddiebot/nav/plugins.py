"""Navigation plugin registries: a Nav2 plugin type name to the factory that builds it.

A server's YAML lists instance names (``controller_plugins: [FollowPath]``) and gives each
``plugin: <type>``; the server asks the registry of that kind for the type and calls its
factory. One :class:`PluginRegistry` per kind holds the built-in types (registered by the
module that defines them) and finds a user's own types in two ways:

- an explicit call, ``register("controllers", "my_pkg::StraightController", factory)``;
- an installed package's entry point of group ``eddiebot.nav.<kind>`` (``controllers``,
  ``progress_checkers``, ``goal_checkers``, ``planners``, ``smoothers``, ``behaviors``,
  ``costmap_layers``), named by the type and pointing at the plugin class, e.g. in
  ``pyproject.toml``: ``[project.entry-points."eddiebot.nav.controllers"]
  "my_pkg.StraightController" = "my_pkg.control:StraightController"`` (an entry point's
  ``pkg.Type`` is the type ``pkg::Type``, which packaging tools accept with a warning).

Entry points are read when a type is first asked for and loaded only then. A factory (or an
entry point's class's ``from_params`` classmethod) is called as ``factory(params, name,
context)``: ``params`` is the instance's parameter block without ``plugin``, ``name`` the
instance name, ``context`` a :class:`PluginContext` (server name, the server's parsed
config). ``pkg/Type`` (Humble) and ``pkg::Type`` (Jazzy) name the same type. BT nodes have
their own entry-point group, ``eddiebot.nav.bt_nodes`` (:mod:`eddiebot.nav.bt.factory`).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from importlib import metadata
from typing import Any, Protocol

from eddiebot.nav.errors import NavError, UnsupportedPlugin

__all__ = [
    "ENTRY_POINT_PREFIX",
    "KINDS",
    "NoParameters",
    "PluginContext",
    "PluginFactory",
    "PluginRegistry",
    "PluginType",
    "clear_entry_point_cache",
    "plugin_key",
    "register",
    "registry",
]

#: entry-point group of kind ``k`` is ``ENTRY_POINT_PREFIX + k``
ENTRY_POINT_PREFIX = "eddiebot.nav."
#: the plugin kinds, each a registry and an entry-point group
KINDS = ("controllers", "progress_checkers", "goal_checkers", "planners", "smoothers",
         "behaviors", "costmap_layers")


def plugin_key(name: str) -> str:
    """``pkg/Type`` (Humble) and ``pkg::Type`` (Jazzy) name the same plugin."""
    return name.replace("/", "::")


@dataclass(frozen=True)
class NoParameters:
    """The config of a plugin type that reads no parameters of its own (besides ``plugin``)."""


@dataclass(frozen=True)
class PluginContext:
    """What a plugin is built with besides its own parameters.

    ``server``: the hosting node's name (for error messages: ``f"{server}.{name}"``);
    ``server_config``: that server's parsed config — ``ControllerServerConfig`` (controllers
    and checkers: ``controller_frequency``), ``PlannerServerConfig``,
    ``BehaviorServerConfig``, ``CostmapConfig`` (layers), ``None`` for smoothers.
    """

    server: str
    name: str
    server_config: Any = None

    @property
    def where(self) -> str:
        """``<server>.<instance>``, the prefix of the instance's parameters."""
        return f"{self.server}.{self.name}"


class PluginFactory(Protocol):
    def __call__(self, params: dict[str, Any], name: str, context: PluginContext) -> Any: ...


@dataclass(frozen=True)
class PluginType:
    """One registered type: its factory, the config dataclass whose fields are the keys it
    reads (``None``: not known, e.g. a plugin from an entry point) and where it came from."""

    name: str
    factory: PluginFactory
    config: type[Any] | None = None
    source: str = "built-in"


class PluginRegistry(Mapping[str, PluginType]):
    """Plugin types of one kind by name; a mapping over built-in, registered and installed
    (entry-point) types. Looking an installed type up loads its entry point, once."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.group = ENTRY_POINT_PREFIX + kind
        self._types: dict[str, PluginType] = {}
        self._entry_points: dict[str, metadata.EntryPoint] | None = None
        self._failed: dict[str, str] = {}

    # -- registration -------------------------------------------------------------------------
    def register(self, type_name: str, factory: PluginFactory, config: type[Any] | None = None,
                 source: str = "registered with register()") -> None:
        """Add (or replace) type ``type_name``; ``factory(params, name, context)`` builds it."""
        if not callable(factory):
            raise TypeError(f"{self.kind} plugin {type_name!r}: factory {factory!r} is not callable")
        key = plugin_key(type_name)
        self._types[key] = PluginType(key, factory, config, source)
        self._failed.pop(key, None)

    def unregister(self, type_name: str) -> None:
        """Remove a registered type (an installed one is found again at the next lookup)."""
        self._types.pop(plugin_key(type_name), None)

    def _installed(self) -> dict[str, metadata.EntryPoint]:
        if self._entry_points is None:
            # packaging recommends entry-point names of [\w.-]+: ``pkg.Type`` is ``pkg::Type``
            self._entry_points = {plugin_key(ep.name).replace(".", "::"): ep
                                  for ep in metadata.entry_points(group=self.group)}
        return self._entry_points

    def clear_cache(self) -> None:
        """Forget the entry points read so far (and their load failures); what was loaded
        from them is dropped too and is loaded again when next asked for."""
        self._entry_points = None
        self._failed.clear()
        for key in [k for k, t in self._types.items() if t.source.startswith("entry point")]:
            del self._types[key]

    def _load(self, key: str, ep: metadata.EntryPoint) -> PluginType:
        where = f"entry point {ep.name!r} = {ep.value!r} (group {self.group!r})"
        if key in self._failed:
            raise ImportError(self._failed[key])
        try:
            obj = ep.load()
        except Exception as exc:  # any failure importing user code is reported, not raised
            self._failed[key] = f"{where} failed to load: {type(exc).__name__}: {exc}"
            raise ImportError(self._failed[key]) from None
        factory = getattr(obj, "from_params", None) if isinstance(obj, type) else obj
        if not callable(factory):
            self._failed[key] = (f"{where}: {obj!r} is neither a class with a "
                                 f"from_params(params, name, context) classmethod nor a factory")
            raise ImportError(self._failed[key])
        entry = PluginType(key, factory, None, where)
        self._types[key] = entry
        return entry

    # -- lookup ---------------------------------------------------------------------------------
    def __getitem__(self, type_name: str) -> PluginType:
        key = plugin_key(type_name)
        entry = self._types.get(key)
        if entry is not None:
            return entry
        ep = self._installed().get(key)
        if ep is None:
            raise KeyError(type_name)
        return self._load(key, ep)

    def __contains__(self, type_name: object) -> bool:
        if not isinstance(type_name, str):
            return False
        key = plugin_key(type_name)
        return key in self._types or key in self._installed()

    def __iter__(self) -> Iterator[str]:
        yield from self._types
        yield from (k for k in self._installed() if k not in self._types)

    def __len__(self) -> int:
        return len(set(self._types) | set(self._installed()))

    def resolve(self, type_name: str, server: str, key: str) -> PluginType:
        """The type for parameter ``key`` (``FollowPath.plugin``) of ``server``; an unknown
        type or an entry point that fails to load is :class:`UnsupportedPlugin` naming them."""
        try:
            return self[type_name]
        except KeyError:
            raise UnsupportedPlugin(
                server, key, type_name,
                f"unknown {self.kind} plugin; known: {sorted(self)}") from None
        except ImportError as exc:
            raise UnsupportedPlugin(server, key, type_name, str(exc)) from None

    def create(self, type_name: str, params: Mapping[str, Any], name: str,
               context: PluginContext) -> Any:
        """Build instance ``name`` of ``type_name`` from its parameter block."""
        key = f"{name}.plugin"
        entry = self.resolve(type_name, context.server, key)
        sub = {k: v for k, v in params.items() if k != "plugin"}
        if entry.source == "built-in":
            return entry.factory(sub, name, context)
        try:
            return entry.factory(sub, name, context)
        except NavError:
            raise
        except Exception as exc:  # a user's plugin failing to configure stops the bring-up
            raise UnsupportedPlugin(
                context.server, key, type_name,
                f"{entry.source}: failed to configure: {type(exc).__name__}: {exc}") from None


_REGISTRIES: dict[str, PluginRegistry] = {kind: PluginRegistry(kind) for kind in KINDS}


def registry(kind: str) -> PluginRegistry:
    """The registry of ``kind`` (one of :data:`KINDS`)."""
    try:
        return _REGISTRIES[kind]
    except KeyError:
        raise ValueError(f"unknown plugin kind {kind!r}; kinds: {', '.join(KINDS)}") from None


def register(kind: str, type_name: str, factory: PluginFactory,
             config: type[Any] | None = None) -> None:
    """Register ``type_name`` of ``kind`` (``"controllers"``, ``"costmap_layers"``, ...);
    builders then load it by name as they load the built-in ones."""
    registry(kind).register(type_name, factory, config)


def clear_entry_point_cache() -> None:
    """Read the installed entry points again at the next lookup (after installing a package
    into a running interpreter)."""
    for reg in _REGISTRIES.values():
        reg.clear_cache()
