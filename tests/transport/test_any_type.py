"""Any message type across processes: types read from interface files, undescribed types
handled raw, and samples of another definition (another RIHS01 hash) not decoded."""

from __future__ import annotations

import logging
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from _procs import Proc

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.msgs import serialize
from eddiebot.msgs.std_msgs import String
from eddiebot.transport import connect
from eddiebot.transport.keys import encode_attachment, topic_key

BLOB = "std_msgs/Header header\nInner[] items\nstring label\n"
INNER = "int32 x\nfloat64 y\n"
PKG = "blob_test_msgs"
CLI = [sys.executable, "-m", "eddiebot.cli.main"]


def _write_package(root: Path) -> Path:
    for name, text in (("Blob", BLOB), ("Inner", INNER)):
        folder = root / PKG / "msg"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{name}.msg").write_text(text)
    return root


@pytest.fixture(scope="module")
def interfaces(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same package as an EDDIE_INTERFACE_PATH folder and as an install prefix."""
    base = tmp_path_factory.mktemp("interfaces")
    return {"eddie": _write_package(base / "eddie"),
            "ament": _write_package(base / "install" / "share").parent,
            "empty": base}


def _env(zenoh_env: dict[str, str], **extra: str) -> dict[str, str]:
    env = {k: v for k, v in zenoh_env.items()
           if k not in ("EDDIE_INTERFACE_PATH", "AMENT_PREFIX_PATH")}
    return {**env, **extra}


@pytest.fixture(scope="module")
def blob_publisher(zenoh_env: dict[str, str], interfaces: dict[str, Path]) -> Iterator[Proc]:
    """``eddie topic pub`` of the package's type, which it reads from EDDIE_INTERFACE_PATH."""
    env = _env(zenoh_env, EDDIE_INTERFACE_PATH=str(interfaces["eddie"]))
    p = Proc([*CLI, "topic", "pub", "/blob", f"{PKG}/msg/Blob",
              "{label: hello, header: {frame_id: cam}, items: [{x: 3, y: 0.5}]}",
              "-r", "20", "-w", "0", "-p", "0"], env)
    if not p.wait_for("publisher: beginning loop", timeout=30):
        p.finish(timeout=5)
        pytest.fail(f"the publisher did not start: {p.stderr}")
    yield p
    p.popen.send_signal(signal.SIGINT)
    try:
        p.popen.wait(timeout=10)
    except subprocess.TimeoutExpired:
        p.popen.kill()


def _run(args: list[str], env: dict[str, str], timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], env=env, capture_output=True, text=True, timeout=timeout,
                          check=False)


def test_echo_decodes_a_type_from_an_install_prefix(blob_publisher: Proc,
                                                    zenoh_env: dict[str, str],
                                                    interfaces: dict[str, Path]) -> None:
    env = _env(zenoh_env, AMENT_PREFIX_PATH=str(interfaces["ament"]))
    out = _run(["topic", "echo", "/blob", "--once", "--timeout", "30"], env)
    assert out.returncode == 0, out.stderr
    assert "label: hello" in out.stdout
    assert "frame_id: cam" in out.stdout
    assert "x: 3" in out.stdout
    assert "y: 0.5" in out.stdout


def test_undescribed_type_echo_says_so_and_hz_bw_still_count(
    blob_publisher: Proc, zenoh_env: dict[str, str], interfaces: dict[str, Path]
) -> None:
    env = _env(zenoh_env, EDDIE_INTERFACE_PATH=str(interfaces["empty"]))
    echo = _run(["topic", "echo", "/blob", "--once", "--timeout", "30"], env)
    assert echo.returncode == 2
    lines = echo.stderr.strip().splitlines()
    assert len(lines) == 1, echo.stderr
    assert f"{PKG}/msg/Blob" in lines[0]
    assert str(interfaces["empty"]) in lines[0]  # where it looked
    assert "add a folder holding" in lines[0]
    assert "EDDIE_INTERFACE_PATH" in lines[0]
    hz = _run(["topic", "hz", "/blob", "--duration", "3"], env)
    assert hz.returncode == 0, hz.stderr
    rate = [float(x.split()[-1]) for x in hz.stdout.splitlines() if "average rate" in x]
    assert rate and 10 < rate[-1] < 30, hz.stdout  # published at 20 Hz
    bw = _run(["topic", "bw", "/blob", "--duration", "3"], env)
    assert bw.returncode == 0, bw.stderr
    assert "Message size mean" in bw.stdout


def test_record_of_an_undescribed_type_keeps_raw_cdr_and_an_empty_schema(
    blob_publisher: Proc, zenoh_env: dict[str, str], interfaces: dict[str, Path],
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from eddiebot.bag import BagReader

    env = _env(zenoh_env, EDDIE_INTERFACE_PATH=str(interfaces["empty"]))
    bag = tmp_path / "bag"
    rec = Proc([*CLI, "record", "-o", str(bag), "/blob"], env)
    deadline = time.monotonic() + 30
    while "recording /blob" not in rec.stderr and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "recording /blob" in rec.stderr, rec.stderr
    time.sleep(1.5)
    rec.popen.send_signal(signal.SIGINT)
    assert rec.popen.wait(timeout=20) == 0, rec.stderr
    # the schema rosbag2 writes for a type it has no definition of: encoding and data empty
    mcap = next(bag.glob("*.mcap")).read_bytes()
    name = f"{PKG}/msg/Blob".encode()
    at = mcap.index(name)
    assert mcap[at + len(name):at + len(name) + 8] == b"\0" * 8  # "" encoding, "" data
    monkeypatch.delenv("EDDIE_INTERFACE_PATH", raising=False)
    with BagReader(bag) as reader:
        conn = next(c for c in reader.connections if c.topic == "/blob")
        assert conn.msgdef == ""
        assert conn.type_hash.startswith("RIHS01_")
        data = [m.data for m in reader.messages()]
    assert len(data) >= 10
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register({**get_types_from_msg(INNER, f"{PKG}/msg/Inner"),
                    **get_types_from_msg(BLOB, f"{PKG}/msg/Blob")})
    assert conn.type_hash == store.hash_rihs01(f"{PKG}/msg/Blob")
    msg = store.deserialize_cdr(data[0], f"{PKG}/msg/Blob")
    assert (msg.label, msg.items[0].x) == ("hello", 3)


@pytest.fixture
def two_sessions(zenoh_config: Any) -> Iterator[Callable[[str], tuple[Context, Node, Any]]]:
    made: list[Context] = []

    def make(name: str) -> tuple[Context, Node, Any]:
        ctx = Context()
        made.append(ctx)
        return ctx, Node(name, context=ctx), connect(ctx, zenoh_config, required=True)

    yield make
    for ctx in made:
        ctx.shutdown()


def test_sample_of_another_definition_is_not_decoded(
    two_sessions: Any, caplog: pytest.LogCaptureFixture
) -> None:
    _ctx_a, _node_a, sender = two_sessions("sender")
    ctx, node, receiver = two_sessions("receiver")
    got: list[str] = []
    node.create_subscription(String, "/defs", lambda m: got.append(m.data), 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ours = topic_key(sender.domain, "/defs", "std_msgs/msg/String")
    other = "RIHS01_" + "ab" * 32
    theirs = topic_key(sender.domain, "/defs", "std_msgs/msg/String", type_hash=other)
    gid = b"\1" * 16

    def put(key: str, text: str) -> None:
        sender.session.put(key, serialize(String(data=text)),
                           attachment=encode_attachment(0, 0, gid))

    deadline = time.monotonic() + 10
    while not got and time.monotonic() < deadline:  # until Zenoh routes between the two
        put(ours, "hello")
        ex.spin_once(timeout_sec=0.05)
    assert got
    with caplog.at_level(logging.ERROR, logger="eddiebot.transport"):
        for i in range(5):
            put(theirs, f"other {i}")
        put(ours, "last")
        deadline = time.monotonic() + 10
        while "last" not in got and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
    assert "last" in got
    assert not [x for x in got if x.startswith("other")]
    assert receiver.undecoded["/defs"] == 5
    lines = [r.getMessage() for r in caplog.records if "another definition" in r.getMessage()]
    assert lines == [f"/defs: a publisher of std_msgs/msg/String with another definition "
                     f"({other}); its samples are not decoded"]
