"""Types described by a publisher (REP-2016 TypeDescription, as ``~/get_type_description``
answers it): checked against the announced RIHS01 hash, then registered in the store."""

from __future__ import annotations

import hashlib
import json
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import get_types_from_msg
from rosbags.typesys.store import TIDMAP, Typestore

from eddiebot.msgs._defaults import _FILE_DEFAULTS, _add_defaults, _field_defaults
from eddiebot.msgs._interfaces import _fix_action_refs
from eddiebot.msgs._store import _LOAD_LOCK, TYPESTORE, _known, normalize_type_name

#: FieldType ids (type_description_interfaces/msg/FieldType) → rosbags base type names
_FIELD_TYPES = {tid: name for name, tid in TIDMAP.items() if not name.startswith("bounded_")}
_FIELD_TYPES[14], _FIELD_TYPES[18] = "wchar", "wstring"
_EMPTY_MEMBER = "structure_needs_at_least_one_member"


def _field_desc(where: str, ft: Any) -> Any:
    """The rosbags field description of one ``FieldType``."""
    group, base = divmod(int(ft.type_id), 48)
    if base == 1:
        if not ft.nested_type_name:
            raise ValueError(f"{where}: a nested field without nested_type_name")
        inner: Any = (Nodetype.NAME, normalize_type_name(str(ft.nested_type_name)))
    elif base in (21, 22):
        inner = (Nodetype.BASE, ("string" if base == 21 else "wstring", int(ft.string_capacity)))
    elif base in _FIELD_TYPES and group < 4:
        inner = (Nodetype.BASE, (_FIELD_TYPES[base], 0))
    else:
        raise ValueError(f"{where}: unsupported field type id {ft.type_id}")
    if group == 0:
        return inner
    if group == 1:
        return (Nodetype.ARRAY, (inner, int(ft.capacity)))
    return (Nodetype.SEQUENCE, (inner, int(ft.capacity) if group == 2 else 0))


def _fields_of(individual: Any) -> Any:
    """``(constants, fields)`` of one ``IndividualTypeDescription`` (it carries no constants)."""
    fields = [(str(f.name), _field_desc(f"{individual.type_name}.{f.name}", f.type))
              for f in individual.fields]
    if [name for name, _ in fields] == [_EMPTY_MEMBER]:
        fields = []  # REP-2016 gives an empty message this one placeholder member
    return ([], fields)


def _description_hash(description: Any) -> str:
    """The RIHS01 hash of a ``TypeDescription`` message as it was received (REP-2016: the
    JSON of its type names and fields, referenced types sorted by name)."""
    def struct(s: Any) -> dict[str, Any]:
        return {"type_name": str(s.type_name), "fields": [
            {"name": str(f.name), "type": {
                "type_id": int(f.type.type_id), "capacity": int(f.type.capacity),
                "string_capacity": int(f.type.string_capacity),
                "nested_type_name": str(f.type.nested_type_name)}}
            for f in s.fields]}

    refs = sorted(description.referenced_type_descriptions, key=lambda s: str(s.type_name))
    data = {"type_description": struct(description.type_description),
            "referenced_type_descriptions": [struct(s) for s in refs]}
    return f"RIHS01_{hashlib.sha256(json.dumps(data).encode()).hexdigest()}"


def _definitions(description: Any, texts: dict[str, str]
                 ) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Parsed definitions (and file defaults) of the description's types this store lacks:
    from their ``msg`` source in ``texts`` when it parses, else from the description."""
    typs: dict[str, Any] = {}
    defaults: dict[str, dict[str, Any]] = {}
    for individual in (description.type_description, *description.referenced_type_descriptions):
        name = normalize_type_name(str(individual.type_name))
        if name in TYPESTORE.fielddefs or name in typs:
            continue
        parsed: dict[str, Any] = {}
        if name in texts:
            try:
                parsed = get_types_from_msg(texts[name], name)
            except Exception:  # the description's fields describe it too
                parsed = {}
        if len(parsed) == 1:
            typs[name] = _fix_action_refs(next(iter(parsed.values())))
            defaults[name] = _field_defaults(texts[name])
        else:
            typs[name] = _fields_of(individual)
    return typs, defaults


def _hash_with(typs: dict[str, Any], full: str) -> str:
    """The RIHS01 hash of ``full`` were ``typs`` registered (nothing is registered)."""
    scratch = Typestore()
    scratch.fielddefs.update(TYPESTORE.fielddefs)
    scratch.fielddefs.update(typs)
    try:
        return scratch.hash_rihs01(full)
    except KeyError as exc:
        raise ValueError(f"the description of {full} does not describe {exc}") from None


def register_type_description(type_name: str, rihs01: str, description: Any,
                              sources: Any = ()) -> list[str]:
    """Register message type ``type_name`` and the types it uses from a REP-2016 description,
    as a publisher's ``~/get_type_description`` answers it, and return the names registered.

    ``description`` is a ``type_description_interfaces/msg/TypeDescription``; ``sources``
    its ``TypeSource`` list: a type with an ``msg`` source is read from that text (so its
    constants and default values come too), any other from the description's fields, and
    all from the fields when the sources do not hash as the description does. Types this
    store already has keep their definition. The description, and the definitions
    about to be registered, must both hash to ``rihs01`` (the hash the publisher announces),
    else ``ValueError`` says which does not and nothing is registered. A type already known
    under another hash is refused the same way.
    """
    full = normalize_type_name(type_name)
    top = normalize_type_name(str(description.type_description.type_name))
    if top != full:
        raise ValueError(f"the description is of {top}, not of {full}")
    got = _description_hash(description)
    if got != rihs01:
        raise ValueError(f"the description of {full} hashes to {got}, not to the "
                         f"publisher's {rihs01}")
    with _LOAD_LOCK:
        if _known(full):
            have = TYPESTORE.hash_rihs01(full)
            if have != rihs01:
                raise ValueError(f"{full} is known here as {have}, not as the publisher's "
                                 f"{rihs01}")
            return []
        texts = {normalize_type_name(str(s.type_name)): str(s.raw_file_contents)
                 for s in sources if str(s.encoding) == "msg"}
        typs, defaults = _definitions(description, texts)
        ours = _hash_with(typs, full)
        if ours != rihs01 and texts:
            # sources another parser reads otherwise (a .msg ``char`` is IDL uint8 to rosidl,
            # not rosbags' char): the hashed description's fields alone still decode
            typs, defaults = _definitions(description, {})
            if _hash_with(typs, full) == rihs01:
                ours = rihs01
        if ours != rihs01:
            differ = [str(i.type_name) for i in description.referenced_type_descriptions
                      if normalize_type_name(str(i.type_name)) in TYPESTORE.fielddefs
                      and _fields_of(i)[1] != TYPESTORE.fielddefs[
                          normalize_type_name(str(i.type_name))][1]]
            if differ:
                raise ValueError(f"{full} uses {', '.join(differ)} of another definition than "
                                 f"the one known here")
            raise ValueError(f"the definitions given for {full} hash to {ours}, not to the "
                             f"publisher's {rihs01}")
        try:
            TYPESTORE.register(typs)
        except Exception as exc:
            raise ValueError(f"cannot register {full}: {exc}") from None
        _FILE_DEFAULTS.update(defaults)
        for name in typs:
            _add_defaults(TYPESTORE, TYPESTORE.types[name])
        return sorted(typs)
