"""Interface files (``.msg``, ``.srv``, ``.action``) to rosbags type definitions, services
and actions split into plain messages as rosidl does."""

from __future__ import annotations

from importlib import resources
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg

from eddiebot.msgs._defaults import _FILE_DEFAULTS, _field_defaults


def _split_srv(text: str) -> tuple[str, str]:
    parts = _sections(text)
    if len(parts) != 2:
        raise ValueError(f"a .srv needs exactly one '---' separator, found {len(parts) - 1}")
    return parts[0], parts[1]


def _sections(text: str) -> list[str]:
    out: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            out.append([])
        else:
            out[-1].append(line)
    return ["\n".join(lines) + "\n" for lines in out]


def _interface_files() -> list[tuple[str, str, str, str]]:
    """(package, kind, name, text) of every shipped interface file."""
    root = resources.files("eddiebot.msgs") / "interfaces"
    found = []
    for pkg in sorted(root.iterdir(), key=lambda p: p.name):
        if not pkg.is_dir():
            continue
        for kind in ("msg", "srv", "action"):
            folder = pkg / kind
            if not folder.is_dir():
                continue
            for f in sorted(folder.iterdir(), key=lambda p: p.name):
                if f.name.endswith(f".{kind}"):
                    found.append((pkg.name, kind, f.name[: -len(kind) - 1], f.read_text()))
    return found


def _parse_interface(
    pkg: str, kind: str, name: str, text: str
) -> tuple[dict[str, Any], str | None, str | None]:
    """The message types of one interface file (services and actions split as rosidl does),
    with the service or action name it defines (if any)."""
    full = f"{pkg}/{kind}/{name}"
    typs: dict[str, Any] = {}
    if kind == "msg":
        typs.update(get_types_from_msg(text, full))
        _FILE_DEFAULTS[full] = _field_defaults(text)
    elif kind == "srv":
        req, res = _split_srv(text)
        typs.update(get_types_from_msg(req, f"{full}_Request"))
        typs.update(get_types_from_msg(res, f"{full}_Response"))
        _FILE_DEFAULTS[f"{full}_Request"] = _field_defaults(req)
        _FILE_DEFAULTS[f"{full}_Response"] = _field_defaults(res)
    else:
        sections = _sections(text)
        if len(sections) != 3:
            raise ValueError(f"{full}.action needs two '---' separators")
        goal, result, feedback = sections
        for suffix, part in zip(("_Goal", "_Result", "_Feedback"), sections):
            _FILE_DEFAULTS[f"{full}{suffix}"] = _field_defaults(part)
        typs.update(get_types_from_msg(goal, f"{full}_Goal"))
        typs.update(get_types_from_msg(result, f"{full}_Result"))
        typs.update(get_types_from_msg(feedback, f"{full}_Feedback"))
        uuid = "unique_identifier_msgs/UUID goal_id\n"
        typs.update(
            get_types_from_msg(uuid + f"{pkg}/{name}_Goal goal\n", f"{full}_SendGoal_Request")
        )
        typs.update(
            get_types_from_msg(
                "bool accepted\nbuiltin_interfaces/Time stamp\n", f"{full}_SendGoal_Response"
            )
        )
        typs.update(get_types_from_msg(uuid, f"{full}_GetResult_Request"))
        typs.update(
            get_types_from_msg(
                f"int8 status\n{pkg}/{name}_Result result\n", f"{full}_GetResult_Response"
            )
        )
        typs.update(
            get_types_from_msg(
                uuid + f"{pkg}/{name}_Feedback feedback\n", f"{full}_FeedbackMessage"
            )
        )
    # get_types_from_msg resolves "pkg/Name" references as pkg/msg/Name; action sub-types live
    # under pkg/action/, so point those references at the right names.
    # get_types_from_msg also files pkg/srv/X_Request under pkg/srv/msg/; undo that.
    typs = {k.replace("/srv/msg/", "/srv/"): _fix_action_refs(v) for k, v in typs.items()}
    return typs, full if kind == "srv" else None, full if kind == "action" else None


def _fix_action_refs(entry: Any) -> Any:
    consts, fields = entry

    def fix(desc: Any) -> Any:
        kind, detail = desc
        if kind == Nodetype.NAME:
            # A bare "Name" inside pkg/srv/X or pkg/action/X comes back as pkg/srv/msg/Name or
            # pkg/action/Name; rosidl resolves it as pkg/msg/Name.
            head, _, name = detail.rpartition("/")
            pkg = head.split("/", 1)[0]
            if name.endswith(("_Goal", "_Result", "_Feedback")):
                return (kind, f"{pkg}/action/{name}")
            return (kind, f"{pkg}/msg/{name}")
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            inner, size = detail
            return (kind, (fix(inner), size))
        return desc

    return (consts, [(fname, fix(desc)) for fname, desc in fields])
