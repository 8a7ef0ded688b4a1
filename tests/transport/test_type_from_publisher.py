"""A type nothing here describes, decoded from its publisher's ``~/get_type_description``
(REP-2016), as ``ros2 topic echo`` on Jazzy can: the publisher's description and sources
are checked against the RIHS01 hash it announces before they are registered."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _procs import Proc
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from eddiebot.core.type_description import describe, rihs01, to_message
from eddiebot.msgs import (
    TYPESTORE,
    deserialize,
    get_message,
    register_type_description,
    serialize,
    type_hash,
)

CLI = [sys.executable, "-m", "eddiebot.cli.main"]
PKG = "served_test_msgs"
BLOB = "std_msgs/Header header\nInner[] items\nstring label\nbool flag true\nint32 LIMIT=7\n"
INNER = "int32 x\nfloat64[2] y\n"

#: A node publishing PKG/msg/Blob, which only its own EDDIE_INTERFACE_PATH describes; with
#: "tamper", its ~/get_type_description renames a field in the description it gives.
PUBLISHER = f"""
import sys, time
import numpy as np
from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core import type_description
from eddiebot.msgs import get_message
from eddiebot.transport import connect

topic, mode = sys.argv[1], sys.argv[2]
if mode == "tamper":
    answer = type_description.TypeDescriptionService._answer

    def tampered(self, request, response):
        response = answer(self, request, response)
        if response.successful:
            for f in response.type_description.type_description.fields:
                if f.name == "label":
                    f.name = "title"
        return response

    type_description.TypeDescriptionService._answer = tampered
context = Context()
node = Node("blob_talker_" + mode, context=context)
connect(context, required=True)
Blob, Inner = get_message("{PKG}/msg/Blob"), get_message("{PKG}/msg/Inner")
pub = node.create_publisher(Blob, topic, 10)
msg = Blob(label="hello", flag=False, items=[Inner(x=3, y=np.array([0.5, -2.0]))])
msg.header.frame_id = "cam"
ex = SingleThreadedExecutor(context=context)
ex.add_node(node)
print("READY", flush=True)
deadline = time.monotonic() + 120
while time.monotonic() < deadline:
    pub.publish(msg)
    end = time.monotonic() + 0.05
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.01)
"""


def _write_package(root: Path) -> Path:
    folder = root / PKG / "msg"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "Blob.msg").write_text(BLOB)
    (folder / "Inner.msg").write_text(INNER)
    return root


def _env(zenoh_env: dict[str, str], **extra: str) -> dict[str, str]:
    env = {k: v for k, v in zenoh_env.items()
           if k not in ("EDDIE_INTERFACE_PATH", "AMENT_PREFIX_PATH")}
    return {**env, **extra}


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("served")
    (base / "empty").mkdir()
    return {"own": _write_package(base / "own"), "empty": base / "empty"}


def _publisher(zenoh_env: dict[str, str], folders: dict[str, Path], topic: str,
               mode: str) -> Iterator[Proc]:
    env = _env(zenoh_env, EDDIE_INTERFACE_PATH=str(folders["own"]))
    p = Proc([sys.executable, "-c", PUBLISHER, topic, mode], env)
    if not p.wait_for("READY", timeout=30):
        p.finish(timeout=5)
        pytest.fail(f"the publisher did not start: {p.stderr}")
    yield p
    p.popen.kill()
    p.popen.wait(timeout=10)


@pytest.fixture(scope="module")
def served(zenoh_env: dict[str, str], folders: dict[str, Path]) -> Iterator[Proc]:
    yield from _publisher(zenoh_env, folders, "/served_blob", "honest")


@pytest.fixture(scope="module")
def tampered(zenoh_env: dict[str, str], folders: dict[str, Path]) -> Iterator[Proc]:
    yield from _publisher(zenoh_env, folders, "/tampered_blob", "tamper")


def _echo(topic: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, "topic", "echo", topic, "--once", "--timeout", "30"], env=env,
                          capture_output=True, text=True, timeout=90, check=False)


def test_echo_decodes_a_type_only_its_publisher_describes(
    served: Proc, zenoh_env: dict[str, str], folders: dict[str, Path]
) -> None:
    out = _echo("/served_blob", _env(zenoh_env, EDDIE_INTERFACE_PATH=str(folders["empty"])))
    assert out.returncode == 0, out.stderr
    assert "label: hello" in out.stdout
    assert "frame_id: cam" in out.stdout
    assert "x: 3" in out.stdout
    assert "- 0.5" in out.stdout and "- -2.0" in out.stdout
    assert "flag: false" in out.stdout  # as published (the file's default is true)


def test_a_description_that_does_not_hash_to_the_announced_hash_is_refused(
    tampered: Proc, zenoh_env: dict[str, str], folders: dict[str, Path]
) -> None:
    out = _echo("/tampered_blob", _env(zenoh_env, EDDIE_INTERFACE_PATH=str(folders["empty"])))
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    line = lines[0]
    assert line.startswith(f"eddie topic echo: cannot decode /tampered_blob: unknown message "
                           f"type '{PKG}/msg/Blob'")
    assert "/blob_talker_tamper/get_type_description refused" in line
    assert "not to the publisher's RIHS01_" in line
    assert "EDDIE_INTERFACE_PATH" in line  # still says how to add the type from files
    assert not out.stdout


# -- register_type_description itself -----------------------------------------------------
def _described(pkg: str, blob: str = BLOB) -> tuple[str, Any, list[Any]]:
    """(RIHS01 hash, TypeDescription, TypeSources) of pkg/msg/Blob as a publisher gives them."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register({**get_types_from_msg(INNER, f"{pkg}/msg/Inner"),
                    **get_types_from_msg(blob, f"{pkg}/msg/Blob")})
    description = describe(store.fielddefs, f"{pkg}/msg/Blob")
    source = get_message("type_description_interfaces/msg/TypeSource")
    sources = [source(type_name=f"{pkg}/msg/Blob", encoding="msg", raw_file_contents=blob),
               source(type_name=f"{pkg}/msg/Inner", encoding="msg", raw_file_contents=INNER)]
    assert rihs01(description) == store.hash_rihs01(f"{pkg}/msg/Blob")
    return rihs01(description), to_message(description), sources


def test_register_from_sources_keeps_constants_and_defaults() -> None:
    pkg = "desc_src_test_msgs"
    h, description, sources = _described(pkg)
    assert register_type_description(f"{pkg}/msg/Blob", h, description, sources) == [
        f"{pkg}/msg/Blob", f"{pkg}/msg/Inner"]
    blob = get_message(f"{pkg}/msg/Blob")
    assert (blob.LIMIT, blob().flag) == (7, True)
    assert type_hash(f"{pkg}/msg/Blob") == h
    # a second registration of the same definition changes nothing
    assert register_type_description(f"{pkg}/msg/Blob", h, description, sources) == []


def test_register_from_description_fields_alone_decodes() -> None:
    pkg = "desc_fields_test_msgs"
    h, description, _ = _described(pkg)
    register_type_description(f"{pkg}/msg/Blob", h, description)
    inner = get_message(f"{pkg}/msg/Inner")
    msg = get_message(f"{pkg}/msg/Blob")(label="x" * 3, items=[inner(x=-9, y=np.array([1.5, 2.5]))])
    back = deserialize(serialize(msg), f"{pkg}/msg/Blob")
    assert (back.label, back.items[0].x, list(back.items[0].y)) == ("xxx", -9, [1.5, 2.5])
    assert type_hash(f"{pkg}/msg/Blob") == h


def test_register_refuses_what_does_not_hash_to_the_announced_hash() -> None:
    pkg = "desc_bad_test_msgs"
    h, description, sources = _described(pkg)
    with pytest.raises(ValueError, match=r"description of .* hashes to RIHS01_\w+, not to"):
        register_type_description(f"{pkg}/msg/Blob", "RIHS01_" + "0" * 64, description, sources)
    # a referenced type this store knows with another definition
    defs = dict(get_typestore(Stores.ROS2_JAZZY).fielddefs)
    defs.update(get_types_from_msg(INNER, f"{pkg}/msg/Inner"))
    defs.update(get_types_from_msg(BLOB, f"{pkg}/msg/Blob"))
    defs["std_msgs/msg/Header"] = ([], [("frame_id", (Nodetype.BASE, ("string", 0)))])
    other = describe(defs, f"{pkg}/msg/Blob")
    with pytest.raises(ValueError, match=r"uses std_msgs/msg/Header of another definition"):
        register_type_description(f"{pkg}/msg/Blob", rihs01(other), to_message(other), sources)
    assert f"{pkg}/msg/Blob" not in TYPESTORE.fielddefs
    assert f"{pkg}/msg/Inner" not in TYPESTORE.fielddefs


def test_sources_that_disagree_with_the_description_give_way_to_its_fields() -> None:
    pkg = "desc_src_bad_test_msgs"
    h, description, sources = _described(pkg)
    inner = type(sources[1])(type_name=f"{pkg}/msg/Inner", encoding="msg",
                             raw_file_contents="int64 x\nfloat64[2] y\n")
    register_type_description(f"{pkg}/msg/Blob", h, description, [sources[0], inner])
    assert type_hash(f"{pkg}/msg/Blob") == h
    assert TYPESTORE.fielddefs[f"{pkg}/msg/Inner"][1][0] == ("x", (Nodetype.BASE, ("int32", 0)))
    assert not hasattr(get_message(f"{pkg}/msg/Blob"), "LIMIT")  # constants are not hashed
