"""Types we do not ship, read from interface files on EDDIE_INTERFACE_PATH / AMENT_PREFIX_PATH."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from eddiebot.msgs import (
    TYPESTORE,
    UnknownTypeError,
    deserialize,
    get_action,
    get_message,
    get_service,
    message_definition,
    serialize,
    type_hash,
)

_IDS = itertools.count()
BLOB = "std_msgs/Header header\nInner[] items\nuint8[] data\nstring label\n"
INNER = "int32 x\nfloat64 y\n"


@pytest.fixture
def pkg(monkeypatch: pytest.MonkeyPatch) -> str:
    """A package name no other test registers (the type store is process-wide)."""
    monkeypatch.delenv("EDDIE_INTERFACE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    return f"blob_msgs_{next(_IDS)}"


def _write(root: Path, pkg: str, kind: str, name: str, text: str) -> Path:
    folder = root / pkg / kind
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.{kind}"
    path.write_text(text)
    return path


def _reference_store(pkg: str) -> Typestore:
    """The same definitions registered by rosbags alone, on top of the store's std types."""
    store = get_typestore(Stores.ROS2_JAZZY)
    typs = {**get_types_from_msg(INNER, f"{pkg}/msg/Inner"),
            **get_types_from_msg(BLOB, f"{pkg}/msg/Blob")}
    store.register(typs)
    return store


def test_message_from_eddie_interface_path(tmp_path: Path, pkg: str,
                                           monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path, pkg, "msg", "Blob", BLOB)
    _write(tmp_path, pkg, "msg", "Inner", INNER)
    assert f"{pkg}/msg/Blob" not in TYPESTORE.types
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", f"/nonexistent:{tmp_path}")
    blob_cls = get_message(f"{pkg}/msg/Blob")
    inner_cls = get_message(f"{pkg}/msg/Inner")  # registered with Blob, which uses it
    msg = blob_cls(items=[inner_cls(x=3, y=0.5)], data=np.arange(4, dtype=np.uint8), label="hi")
    assert msg.header.frame_id == ""  # defaults as for shipped types
    ref = _reference_store(pkg)
    data = serialize(msg)
    assert data == bytes(ref.serialize_cdr(ref.deserialize_cdr(data, f"{pkg}/msg/Blob"),
                                           f"{pkg}/msg/Blob"))
    back = deserialize(data, f"{pkg}/msg/Blob")
    assert (back.label, back.items[0].x, back.items[0].y) == ("hi", 3, 0.5)
    assert back.data.tolist() == [0, 1, 2, 3]
    assert type_hash(f"{pkg}/msg/Blob") == ref.hash_rihs01(f"{pkg}/msg/Blob")
    assert f"MSG: {pkg}/Inner" in message_definition(f"{pkg}/msg/Blob")


def test_ament_prefix_share_layout(tmp_path: Path, pkg: str,
                                   monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path / "install" / "share", pkg, "msg", "Inner", INNER)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(tmp_path / "install"))
    assert get_message(f"{pkg}/Inner")(x=1).x == 1


def test_install_prefix_on_eddie_interface_path(tmp_path: Path, pkg: str,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path / "share", pkg, "msg", "Inner", INNER)
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    assert get_message(f"{pkg}/msg/Inner")(y=2.0).y == 2.0


def test_service_and_action(tmp_path: Path, pkg: str, monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path, pkg, "srv", "Scale", "float64 factor\nInner item\n---\nInner item\n")
    _write(tmp_path, pkg, "msg", "Inner", INNER)
    _write(tmp_path, pkg, "action", "Count", "int32 to\n---\nint32[] seen\n---\nInner last\n")
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    srv = get_service(f"{pkg}/srv/Scale")
    assert srv.Request(factor=2.0).item.x == 0
    action = get_action(f"{pkg}/Count")
    assert action.Feedback().last.y == 0.0
    assert action.SendGoal.Request().goal.to == 0


def test_undescribed_type_says_where_it_looked(tmp_path: Path, pkg: str,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    with pytest.raises(UnknownTypeError) as info:
        get_message(f"{pkg}/msg/Missing")
    text = str(info.value)
    assert f"{pkg}/msg/Missing.msg" in text
    assert str(tmp_path) in text
    assert "EDDIE_INTERFACE_PATH" in text
    assert "\n" not in text


def test_missing_dependency_is_named(tmp_path: Path, pkg: str,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    _write(tmp_path, pkg, "msg", "Blob", BLOB)  # Inner.msg is not there
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    with pytest.raises(UnknownTypeError, match=f"uses {pkg}/msg/Inner"):
        get_message(f"{pkg}/msg/Blob")
    assert f"{pkg}/msg/Blob" not in TYPESTORE.types
    _write(tmp_path, pkg, "msg", "Inner", INNER)
    # the failed look-up is remembered per search path; a new path looks again
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", f"{tmp_path}:")
    assert get_message(f"{pkg}/msg/Blob")().label == ""
