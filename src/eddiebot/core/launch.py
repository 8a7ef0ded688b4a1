"""YAML launch files, in the shape of ROS 2's YAML launch format.

```yaml
launch:
  - arg: {name: port, default: /dev/ttyUSB0}
  - node:
      pkg: eddiebot
      exec: base.board              # or `type: eddiebot.base.board`
      name: eddie                   # optional; the node class's default otherwise
      namespace: ""
      param:
        - {from: $(find-pkg-share eddiebot)/config/eddie.yaml}
        - {name: port, value: $(var port)}
      remap:
        - {from: /cmd_vel, to: /cmd_vel_mux}
  - include: {file: other.yaml, arg: [{name: x, value: "1"}]}
```

Substitutions: ``$(var NAME)``, ``$(env NAME [default])``, ``$(find-pkg-share eddiebot)``.
Nodes are found by registered name in an explicit registry (``eddiebot.registry``), never
by scanning modules. All nodes of a launch run in one process. Before any node spins, every
parameter file entry must name a launched node and every key a declared parameter (unless the
node allows undeclared ones); any error names file, line, node and key, and nothing starts.
"""

from __future__ import annotations

import importlib
import logging
import os
import re
import signal
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from eddiebot.core.context import Context
from eddiebot.core.errors import ParameterError, RuntimeErrorBase
from eddiebot.core.node import Node
from eddiebot.core.parameters import (
    ParameterFile,
    ParameterOverride,
    load_parameter_file,
    node_matches,
)

_log = logging.getLogger(__name__)


class LaunchError(RuntimeErrorBase):
    """A launch file that cannot be run; the message names file, line and what is wrong."""


@dataclass
class NodeSpec:
    """One node of a launch: its registered type, name, parameters and remaps."""

    type: str
    name: str | None = None
    namespace: str = ""
    param_files: list[Path] = field(default_factory=list)
    params: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)
    where: str = ""


@dataclass
class LaunchDescription:
    """What a launch file asks for, after argument substitution."""

    nodes: list[NodeSpec] = field(default_factory=list)
    args: dict[str, str] = field(default_factory=dict)
    source: Path | None = None


_SUBST = re.compile(r"\$\(([a-z-]+)\s*([^)]*)\)")


def package_share() -> Path:
    """The installed package's data root (holds launch/, config/, urdf/, worlds)."""
    return Path(str(resources.files("eddiebot")))


def find_launch_file(name: str) -> Path:
    """A path, or the name of one of the package's launch files (``bringup``)."""
    p = Path(name)
    if p.suffix in (".yaml", ".yml") and p.exists():
        return p
    if p.exists() and p.is_file():
        return p
    candidate = package_share() / "launch" / (name if name.endswith(".yaml") else f"{name}.yaml")
    if candidate.exists():
        return candidate
    known = sorted(f.stem for f in (package_share() / "launch").glob("*.yaml"))
    raise LaunchError(f"no launch file {name!r}: not a file, and the package has {known}")


def _substitute(text: str, args: Mapping[str, str], where: str) -> str:
    def repl(m: re.Match[str]) -> str:
        kind, rest = m.group(1), m.group(2).strip()
        if kind == "var":
            if rest not in args:
                raise LaunchError(f"{where}: undefined launch argument {rest!r} (known: {sorted(args)})")
            return str(args[rest])
        if kind == "env":
            name, _, default = rest.partition(" ")
            value = os.environ.get(name, default or None)
            if value is None:
                raise LaunchError(f"{where}: environment variable {name!r} is not set")
            return value
        if kind == "find-pkg-share":
            if rest != "eddiebot":
                raise LaunchError(f"{where}: unknown package {rest!r} (only eddiebot is installed)")
            return str(package_share())
        raise LaunchError(f"{where}: unknown substitution $({kind} ...)")

    return _SUBST.sub(repl, text)


def _subst_value(value: Any, args: Mapping[str, str], where: str) -> Any:
    if isinstance(value, str):
        out = _substitute(value, args, where)
        if out != value:
            # a substituted scalar is parsed as YAML, so "$(var rate)" can become a number
            try:
                return yaml.safe_load(out) if out.strip() else out
            except yaml.YAMLError:
                return out
        return out
    if isinstance(value, list):
        return [_subst_value(v, args, where) for v in value]
    if isinstance(value, dict):
        return {k: _subst_value(v, args, where) for k, v in value.items()}
    return value


class _LineLoader(yaml.SafeLoader):
    """Adds ``__line__`` to every mapping so errors can name the line."""


def _construct_mapping(loader: _LineLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    mapping: dict[Any, Any] = loader.construct_mapping(node, deep=True)
    mapping["__line__"] = node.start_mark.line + 1
    return mapping


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def parse_launch_file(path: str | Path, cli_args: Mapping[str, str] | None = None) -> LaunchDescription:
    """Read a launch file, resolve its arguments (command-line values win) and includes."""
    p = Path(path)
    try:
        doc = yaml.load(p.read_text(), Loader=_LineLoader)
    except OSError as exc:
        raise LaunchError(f"{p}: cannot read: {exc.strerror}") from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        raise LaunchError(f"{p}{line}: malformed YAML: {getattr(exc, 'problem', exc)}") from exc
    if not isinstance(doc, dict) or "launch" not in doc or not isinstance(doc["launch"], list):
        raise LaunchError(f"{p}:1: a launch file is a mapping with a 'launch:' list")
    desc = LaunchDescription(source=p)
    args: dict[str, str] = {}
    given = dict(cli_args or {})
    for item in doc["launch"]:
        where = f"{p}:{item.get('__line__', 0) if isinstance(item, dict) else 0}"
        if not isinstance(item, dict) or len([k for k in item if k != "__line__"]) != 1:
            raise LaunchError(f"{where}: each launch entry is one of arg, node, include")
        kind = next(k for k in item if k != "__line__")
        body = item[kind]
        if kind == "arg":
            name = body.get("name")
            if not name:
                raise LaunchError(f"{where}: arg needs a name")
            if name in given:
                args[name] = given[name]
            elif "default" in body:
                args[name] = _substitute(str(body["default"]), args, where)
            else:
                raise LaunchError(f"{where}: launch argument {name!r} has no default; pass {name}:=VALUE")
        elif kind == "node":
            desc.nodes.append(_parse_node(body, args, where, p))
        elif kind == "include":
            file = _substitute(str(body.get("file", "")), args, where)
            inc_args: dict[str, str] = {}
            for a in body.get("arg", []) or []:
                inc_args[a["name"]] = _substitute(str(a["value"]), args, where)
            included = parse_launch_file(find_launch_file(file), inc_args)
            desc.nodes.extend(included.nodes)
        else:
            raise LaunchError(f"{where}: unknown launch entry {kind!r} (use arg, node or include)")
    unknown = sorted(set(given) - set(args))
    if unknown:
        raise LaunchError(f"{p}: unknown launch arguments {unknown}; this file takes {sorted(args)}")
    desc.args = args
    return desc


def _parse_node(body: dict[str, Any], args: Mapping[str, str], where: str, path: Path) -> NodeSpec:
    where = f"{path}:{body.get('__line__', where.rsplit(':', 1)[-1])}"
    if "type" in body:
        node_type = str(body["type"])
    elif "exec" in body:
        pkg = body.get("pkg", "eddiebot")
        node_type = f"{pkg}.{body['exec']}"
    else:
        raise LaunchError(f"{where}: node needs 'type' (e.g. eddiebot.base.odometry) or 'pkg' + 'exec'")
    spec = NodeSpec(type=node_type, where=where)
    if "name" in body:
        spec.name = _substitute(str(body["name"]), args, where)
    spec.namespace = _substitute(str(body.get("namespace", "")), args, where)
    for entry in body.get("param", []) or []:
        if "from" in entry:
            file = Path(_substitute(str(entry["from"]), args, where)).expanduser()
            if entry.get("optional") and not file.exists():
                continue
            spec.param_files.append(file)
        elif "name" in entry:
            spec.params[entry["name"]] = _subst_value(entry.get("value"), args, where)
        else:
            raise LaunchError(f"{where}: a param entry needs 'from' (a file) or 'name' + 'value'")
    for entry in body.get("remap", []) or []:
        spec.remaps[_substitute(str(entry["from"]), args, where)] = _substitute(str(entry["to"]), args, where)
    return spec


NodeFactory = Callable[..., Node]


def resolve_node_type(type_name: str, registry: Mapping[str, str]) -> NodeFactory:
    """The node class registered as ``type_name`` (registry values are ``module:Class``)."""
    target = registry.get(type_name)
    if target is None:
        raise LaunchError(f"unknown node type {type_name!r}; registered: {sorted(registry)}")
    module_name, _, attr = target.partition(":")
    module = importlib.import_module(module_name)
    factory: NodeFactory = getattr(module, attr)
    return factory


def build_nodes(
    desc: LaunchDescription,
    context: Context,
    registry: Mapping[str, str],
    extra_overrides: list[ParameterOverride] | None = None,
) -> list[Node]:
    """Construct every node; validate parameter files and keys before anything spins.

    On any error the nodes already made are destroyed and a ``LaunchError`` names the file,
    line, node and key.
    """
    nodes: list[Node] = []
    files: dict[Path, ParameterFile] = {}
    claimed: set[tuple[Path, str]] = set()
    try:
        for spec in desc.nodes:
            overrides: list[ParameterOverride] = list(extra_overrides or [])
            for f in spec.param_files:
                if f not in files:
                    files[f] = load_parameter_file(f)
            factory = resolve_node_type(spec.type, registry)
            kwargs: dict[str, Any] = {
                "context": context,
                "namespace": spec.namespace,
                "remappings": spec.remaps,
            }
            if spec.name:
                kwargs["node_name"] = spec.name
            # name and namespace are known only after construction for default names, so
            # match file entries against the name we will get
            probe_name = spec.name or getattr(factory, "default_node_name", None) or spec.type.rsplit(".", 1)[-1]
            fqn = f"{('/' + spec.namespace.strip('/')) if spec.namespace.strip('/') else ''}/{probe_name}"
            # Nav2's servers own inner nodes (the planner's global_costmap, ...) whose parameters
            # a Nav2 file gives under their own node key: they become prefixed parameters here
            nested: dict[str, str] = getattr(factory, "nested_parameter_nodes", {}) or {}
            for f in spec.param_files:
                for o in files[f].overrides:
                    if node_matches(o.node_pattern, fqn):
                        overrides.append(o)
                    elif o.node_pattern.strip("/") in nested:
                        prefix = nested[o.node_pattern.strip("/")]
                        overrides.append(ParameterOverride(o.node_pattern, f"{prefix}.{o.name}", o.value, o.where))
                for pattern in nested:
                    claimed.add((f, pattern))
            overrides.extend(
                ParameterOverride("/**", k, v, f"{spec.where} (inline param)") for k, v in spec.params.items()
            )
            kwargs["parameter_overrides"] = overrides
            try:
                node = factory(**kwargs)
            except ParameterError as exc:
                raise LaunchError(f"{exc} (node {fqn}, launched at {spec.where})") from exc
            nodes.append(node)
            if not node.allow_undeclared_parameters:
                for o in node.undeclared_overrides():
                    raise LaunchError(
                        f"{o.where}: node {node.fully_qualified_name} has no parameter {o.name!r}"
                    )
        # a node entry of a file that names no launched node is unused: say so once (a
        # Nav2 user's nav2_params.yaml carries sections for servers this launch does not run)
        fqns = [n.fully_qualified_name for n in nodes]
        for path, pf in files.items():
            for pattern in pf.node_patterns:
                if (path, pattern.strip("/")) in claimed:
                    continue
                if not any(node_matches(pattern, q) for q in fqns):
                    line = next(o.where for o in pf.overrides if o.node_pattern == pattern)
                    _log.warning("%s: parameter file names node %r, which is not launched: "
                                 "its parameters are not used", line, pattern)
    except (LaunchError, ParameterError):
        for n in nodes:
            n.destroy_node()
        raise
    return nodes


TERMINATING_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
    if hasattr(signal, name))
"""The signals after which the launcher stops the motors and shuts down."""


def parse_cli_args(items: list[str]) -> dict[str, str]:
    """``name:=value`` pairs from a command line."""
    out = {}
    for item in items:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise LaunchError(f"expected launch arguments as name:=value, got {item!r}")
        out[name] = value
    return out


def spin_nodes(
    nodes: list[Node],
    context: Context,
    *,
    real_time_factor: float | None = None,
    duration_s: float | None = None,
    multithreaded: bool = False,
    owns_sim_clock: bool | None = None,
) -> int:
    """Spin ``nodes`` until SIGINT/SIGTERM (or ``duration_s`` of node-clock time); then
    destroy them in reverse order (so drivers stop their motors) and shut the context down.

    On sim time, the process that runs the simulator owns the clock (drives it and publishes
    ``/clock``); any other follows ``/clock`` from the transport.
    """
    import threading

    from eddiebot.core.clock_node import ClockFollower, ClockPublisher
    from eddiebot.core.executors import MultiThreadedExecutor, SingleThreadedExecutor

    if owns_sim_clock is None:
        owns_sim_clock = "simulator" in context.resources
    drive = context.use_sim_time and owns_sim_clock
    executor = (
        MultiThreadedExecutor(context=context, drive_sim_time=drive)
        if multithreaded
        else SingleThreadedExecutor(context=context, real_time_factor=real_time_factor,
                                    drive_sim_time=drive)
    )
    helpers: list[Node] = []
    if context.use_sim_time:
        clock_node = Node("sim_clock" if drive else "clock_follower", context=context)
        helpers.append(clock_node)
        if drive:
            ClockPublisher(clock_node, executor)
        else:
            ClockFollower(clock_node)
    for n in [*nodes, *helpers]:
        executor.add_node(n)
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        # motors first: a stopping command goes on the wire before anything unwinds
        context.safety_stop(f"signal {signal.Signals(signum).name}", from_signal=True)
        stop.set()
        executor.shutdown()

    old = {}
    if threading.current_thread() is threading.main_thread():
        # SIGHUP: the ssh session dropped or the terminal closed; SIGQUIT: Ctrl-\
        for sig in TERMINATING_SIGNALS:
            old[sig] = signal.signal(sig, on_signal)
    try:
        if duration_s is not None:
            executor.spin_for(duration_s)
        else:
            executor.spin()
    except BaseException:
        context.safety_stop("the launcher is failing")
        raise
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for n in reversed([*nodes, *helpers]):
            n.destroy_node()
        context.shutdown()
    return 0
