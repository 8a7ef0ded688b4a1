"""rosbag2 (MCAP) recording, playback and inspection, and recovery of damaged bags.

- ``BagWriter`` writes rosbag2 MCAP with ``rosbags`` (metadata version 9): every topic carries
  its full message definition and RIHS01 type hash from our type store and its offered QoS
  profiles, so Foxglove and ``ros2 bag`` read the files. Chunks are flushed to the file at
  least every ``flush_interval`` and on ``close``; a process that dies leaves at worst a
  truncated MCAP whose prefix ``BagReader`` recovers.
- ``RecorderNode`` subscribes to topics as they appear (the context's topic registry and the
  transports' graphs) and writes each message at its receive time on the node clock (sim time
  in a simulation).
- ``Player`` is a node that republishes a bag with its original timing (× ``rate``), driven by
  a timer: on a simulated clock playback is instant and deterministic. Transient-local topics
  are republished latched; ``/clock`` is published on request.
- ``BagReader`` reads rosbag2 directories (MCAP or sqlite3) and bare ``.mcap`` files through
  ``rosbags``; when that fails (truncated file, missing ``metadata.yaml``) it streams the MCAP
  records itself up to the damage and reports where reading stopped (``BagProblem``).
- ``bag_info`` / ``format_bag_info``: what ``ros2 bag info`` prints.
"""

from __future__ import annotations

import datetime as _dt
import re
import struct
import zlib
from collections import defaultdict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any, BinaryIO

import yaml
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.errors import ReaderError, WriterError
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import (
    McapWriter,
    PendingChunk,
    Schema,
    write_record,
    write_schema,
    write_string,
)

from eddiebot.core.node import Node, Publisher, Subscription, Timer
from eddiebot.core.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.msgs import (
    TYPESTORE,
    deserialize,
    get_message,
    load_type,
    message_definition,
    raw_message_type,
    serialize,
    type_hash,
    type_name,
)
from eddiebot.msgs.errors import UnknownTypeError

__all__ = [
    "BagConnection",
    "BagError",
    "BagInfo",
    "BagMessage",
    "BagProblem",
    "BagReader",
    "BagWriter",
    "Player",
    "RecorderNode",
    "TopicSummary",
    "bag_info",
    "format_bag_info",
    "qos_from_rosbags",
    "qos_to_rosbags",
]

_MCAP_MAGIC = b"\x89MCAP0\r\n"
_NS = 1_000_000_000
#: rmw's "infinite" duration (RMW_DURATION_INFINITE, INT64_MAX ns) as rosbag2 (Jazzy) writes
#: it into metadata.yaml: split into seconds and nanoseconds, 9223372036 s + 854775807 ns.
_INFINITE = QosTime(9223372036, 854775807)
_LOOP_GAP_NS = 1_000_000


class BagError(Exception):
    """A bag that cannot be opened, written or played at all."""


# --------------------------------------------------------------------------------------
# QoS
# --------------------------------------------------------------------------------------
def qos_to_rosbags(qos: QoSProfile) -> Qos:
    """Our QoS profile as rosbags' ``Qos`` (offered profile in the bag's metadata)."""
    return Qos(
        QosHistory(int(qos.history)),
        int(qos.depth),
        QosReliability(int(qos.reliability)),
        QosDurability(int(qos.durability)),
        _INFINITE,
        _INFINITE,
        QosLiveliness.AUTOMATIC,
        _INFINITE,
        False,
    )


def qos_from_rosbags(qos: Qos) -> QoSProfile:
    """A bag's offered ``Qos`` as our profile (unknown policies become the defaults)."""
    history = (
        HistoryPolicy.KEEP_ALL if qos.history == QosHistory.KEEP_ALL else HistoryPolicy.KEEP_LAST
    )
    depth = max(1, int(qos.depth)) if history == HistoryPolicy.KEEP_LAST else int(qos.depth)
    reliability = (
        ReliabilityPolicy.BEST_EFFORT
        if qos.reliability == QosReliability.BEST_EFFORT
        else ReliabilityPolicy.RELIABLE
    )
    durability = (
        DurabilityPolicy.TRANSIENT_LOCAL
        if qos.durability == QosDurability.TRANSIENT_LOCAL
        else DurabilityPolicy.VOLATILE
    )
    return QoSProfile(depth=depth, reliability=reliability, durability=durability, history=history)


# --------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------
class _McapFile(McapWriter):
    """rosbags' MCAP storage writing to a file name of our choice (``<bag>_<i>.mcap``)."""

    def __init__(self, file: Path, compression: CompressionMode) -> None:
        # McapWriter.__init__ derives the file name from the directory; this is the same
        # start with our name.
        self.path = file
        self.bio = file.open("xb")
        self.bio.write(_MCAP_MAGIC)
        rec = BytesIO()
        write_string(rec, "ros2")
        write_string(rec, "eddiebot")
        write_record(self.bio, 0x01, rec)
        self.schemas = []
        self.channels = []
        self.chunks = []
        self.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
        if compression == CompressionMode.STORAGE:
            from rosbags.rosbag2.storage_mcap import zstd

            self.compression = "zstd"
            self.compressor = zstd.compress
        else:
            self.compression = ""
            self.compressor = lambda x: x
        self.message_start_time = 2**63 - 1
        self.message_end_time = 0
        self.channel_stats = {}

    def flush_chunk(self) -> None:
        """Write the pending chunk (if any) and hand the file's buffer to the OS."""
        if self.chunk.bio.tell():
            self.close_chunk()
        self.bio.flush()

    def add_msgtype(self, connection: Connection) -> None:
        """A type without a definition gets rosbag2's empty schema: encoding and data ""."""
        if connection.msgdef.data:
            super().add_msgtype(connection)
            return
        self.schemas.append(Schema(len(self.schemas) + 1, connection.msgtype, "", ""))
        write_schema(self.chunk.bio, self.schemas[-1])

    def pending_bytes(self) -> int:
        return int(self.bio.tell() + self.chunk.bio.tell())


class _SplitWriter(Writer):
    """A rosbags ``Writer`` for one file of a (possibly split) bag directory."""

    def __init__(self, bag_dir: Path, file_name: str) -> None:
        super().__init__(bag_dir / f".{file_name}.unused", version=9,
                         storage_plugin=StoragePlugin.MCAP)
        self.path = bag_dir
        self.metapath = bag_dir / "metadata.yaml"
        self.file_name = file_name

    def open(self) -> None:
        self.path.mkdir(parents=True, exist_ok=True)
        if (self.path / self.file_name).exists():
            raise WriterError(f"{self.path / self.file_name} exists already, not overwriting")
        self.storage = _McapFile(self.path / self.file_name, self.compression_mode)


@dataclass
class _TopicSpec:
    topic: str
    type_name: str
    qos: tuple[QoSProfile, ...]
    msgdef: str
    rihs01: str


class BagWriter:
    """Write a rosbag2 MCAP bag directory from serialized data or message objects.

    ``path`` is the bag directory (it must not exist). ``max_bag_duration`` (s) and
    ``max_bag_size`` (bytes) split the bag into ``<name>_0.mcap``, ``<name>_1.mcap``, ...
    as ``ros2 bag record -d/-b`` does (0: no split). Use as a context manager or call
    ``close()``; ``metadata.yaml`` is written (atomically) when a file is finished.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        max_bag_duration: float = 0.0,
        max_bag_size: int = 0,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already, not overwriting")
        self.max_bag_duration_ns = round(max_bag_duration * _NS)
        self.max_bag_size = int(max_bag_size)
        self._topics: dict[str, _TopicSpec] = {}
        self._connections: dict[str, Connection] = {}
        self._writer: _SplitWriter | None = None
        self._file_index = -1
        self._file_start_ns: int | None = None
        self._finished: list[dict[str, Any]] = []  # metadata of closed files
        self._topic_counts: dict[str, int] = {}
        self._closed = False
        self.message_count = 0
        self._open_next_file()

    # -- topics ---------------------------------------------------------------------------
    @property
    def topics(self) -> dict[str, str]:
        """Topic name → type name of every topic added so far."""
        return {t: s.type_name for t, s in self._topics.items()}

    def add_topic(
        self,
        topic: str,
        msg_type: str,
        *,
        qos: QoSProfile | Sequence[QoSProfile] | None = None,
        msgdef: str | None = None,
        rihs01: str | None = None,
    ) -> None:
        """Declare ``topic`` of type ``msg_type`` (``pkg/msg/Name``) with its offered QoS.

        The definition and hash come from our type store unless given (a type we do not
        know, recorded from another process).
        """
        if topic in self._topics:
            if self._topics[topic].type_name != msg_type:
                raise BagError(
                    f"topic {topic!r} already recorded as {self._topics[topic].type_name}, "
                    f"not {msg_type}"
                )
            return
        if msgdef is None or rihs01 is None:
            try:
                msgdef = message_definition(msg_type) if msgdef is None else msgdef
                rihs01 = type_hash(msg_type) if rihs01 is None else rihs01
            except KeyError:
                raise BagError(
                    f"type {msg_type} of topic {topic!r} is not in the type store and no "
                    "definition was given"
                ) from None
        if qos is None:
            profiles: tuple[QoSProfile, ...] = (QoSProfile(),)
        elif isinstance(qos, QoSProfile):
            profiles = (qos,)
        else:
            profiles = tuple(qos)
        spec = _TopicSpec(topic, msg_type, profiles, msgdef, rihs01)
        self._topics[topic] = spec
        self._topic_counts.setdefault(topic, 0)
        self._add_connection(spec)

    def _add_connection(self, spec: _TopicSpec) -> None:
        assert self._writer is not None
        self._connections[spec.topic] = self._writer.add_connection(
            spec.topic,
            spec.type_name,
            msgdef=spec.msgdef,
            rihs01=spec.rihs01,
            offered_qos_profiles=[qos_to_rosbags(q) for q in spec.qos],
        )

    # -- data -----------------------------------------------------------------------------
    def write(self, topic: str, data: bytes | memoryview, timestamp_ns: int) -> None:
        """Append CDR ``data`` of an added topic at ``timestamp_ns`` (receive time, ns)."""
        if self._closed:
            raise BagError(f"bag {self.path} is closed")
        self._maybe_split(int(timestamp_ns))
        conn = self._connections.get(topic)
        if conn is None:
            raise BagError(f"topic {topic!r} was not added to bag {self.path}")
        assert self._writer is not None
        self._writer.write(conn, int(timestamp_ns), data)
        if self._file_start_ns is None:
            self._file_start_ns = int(timestamp_ns)
        self._topic_counts[topic] += 1
        self.message_count += 1

    def write_message(
        self, topic: str, msg: Any, timestamp_ns: int, *, qos: QoSProfile | None = None
    ) -> None:
        """Serialize ``msg`` (adding its topic on first use) and append it."""
        name = type_name(msg)
        if topic not in self._topics:
            self.add_topic(topic, name, qos=qos)
        self.write(topic, serialize(msg, name), timestamp_ns)

    def flush(self) -> None:
        """Put everything written so far into the file (a crash loses nothing before this)."""
        if self._writer is not None and self._writer.storage is not None:
            storage = self._writer.storage
            assert isinstance(storage, _McapFile)
            storage.flush_chunk()

    # -- files ----------------------------------------------------------------------------
    def _file_name(self, index: int) -> str:
        return f"{self.path.name}_{index}.mcap"

    def _open_next_file(self) -> None:
        self._file_index += 1
        self._writer = _SplitWriter(self.path, self._file_name(self._file_index))
        self._writer.open()
        self._file_start_ns = None
        for spec in self._topics.values():
            self._add_connection(spec)

    def _maybe_split(self, timestamp_ns: int) -> None:
        writer = self._writer
        if writer is None or writer.storage is None or self._file_start_ns is None:
            return
        storage = writer.storage
        assert isinstance(storage, _McapFile)
        too_long = (
            self.max_bag_duration_ns > 0
            and timestamp_ns - self._file_start_ns >= self.max_bag_duration_ns
        )
        too_big = self.max_bag_size > 0 and storage.pending_bytes() >= self.max_bag_size
        if too_long or too_big:
            self._close_file()
            self._open_next_file()

    def _close_file(self) -> None:
        writer, self._writer = self._writer, None
        if writer is None:
            return
        counts = {c.topic: writer.counts[c.id] for c in writer.connections}
        n = sum(counts.values())
        start = writer.min_timestamp if n else 0
        duration = max(0, writer.max_timestamp - writer.min_timestamp) if n else 0
        writer.close()  # writes this file's metadata.yaml; replaced below by the bag's
        self._finished.append(
            {
                "path": writer.file_name,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": n,
                "_end": start + duration,
            }
        )
        self._write_metadata()

    def _write_metadata(self) -> None:
        from rosbags.rosbag2.metadata import dump_qos_v9

        files = [f for f in self._finished if f["message_count"]] or self._finished[-1:]
        starts = [f["starting_time"]["nanoseconds_since_epoch"] for f in files if f["message_count"]]
        ends = [f["_end"] for f in files if f["message_count"]]
        start = min(starts) if starts else 0
        end = max(ends) if ends else 0
        info = {
            "version": 9,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": end - start},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": self.message_count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": s.topic,
                        "type": s.type_name,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": dump_qos_v9([qos_to_rosbags(q) for q in s.qos]),
                        "type_description_hash": s.rihs01,
                    },
                    "message_count": self._topic_counts[s.topic],
                }
                for s in self._topics.values()
            ],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [f["path"] for f in self._finished],
            "files": [{k: v for k, v in f.items() if k != "_end"} for f in self._finished],
            "custom_data": None,
            "ros_distro": "jazzy",
        }
        text = yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False)
        tmp = self.path / "metadata.yaml.tmp"
        tmp.write_text(text, encoding="utf8")
        tmp.replace(self.path / "metadata.yaml")

    def close(self) -> None:
        """Finish the current file and write ``metadata.yaml``; idempotent."""
        if self._closed:
            return
        self._closed = True
        self._close_file()

    @property
    def closed(self) -> bool:
        return self._closed

    def __enter__(self) -> BagWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BagConnection:
    """One topic of a bag: type, definition (as stored), hash and offered QoS."""

    topic: str
    type_name: str
    msgdef: str = ""
    msgdef_format: str = "ros2msg"
    type_hash: str = ""
    qos: tuple[QoSProfile, ...] = ()
    serialization_format: str = "cdr"

    @property
    def transient_local(self) -> bool:
        return any(q.transient_local for q in self.qos)


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: CDR bytes received at ``timestamp`` (ns)."""

    connection: BagConnection
    timestamp: int
    data: bytes

    @property
    def topic(self) -> str:
        return self.connection.topic

    def decode(self) -> Any:
        """The message object (types the store lacks are registered from the bag)."""
        ensure_type(self.connection)
        return deserialize(self.data, self.connection.type_name)


@dataclass(frozen=True)
class BagProblem:
    """Where and why reading a bag stopped or skipped data."""

    file: Path
    offset: int | None
    message_index: int
    reason: str

    def __str__(self) -> str:
        where = f"byte {self.offset}" if self.offset is not None else "position unknown"
        return f"{self.file}: {where}, after message #{self.message_index}: {self.reason}"


def ensure_type(conn: BagConnection) -> None:
    """Register ``conn``'s type from the bag's own definition if our store lacks it."""
    if conn.type_name in TYPESTORE.types:
        return
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    if not conn.msgdef:  # an empty schema: perhaps an interface file describes it
        load_type(conn.type_name)
        return
    if conn.msgdef_format in ("ros2idl", "omgidl"):
        types = get_types_from_idl(conn.msgdef)
    else:
        types = get_types_from_msg(conn.msgdef, conn.type_name)
    TYPESTORE.register(types)


def _connection_from_rosbags(conn: Connection) -> BagConnection:
    ext = conn.ext
    qos: tuple[QoSProfile, ...] = ()
    fmt = "cdr"
    if isinstance(ext, ConnectionExtRosbag2):
        qos = tuple(qos_from_rosbags(q) for q in ext.offered_qos_profiles)
        fmt = ext.serialization_format
    msgdef_format = "ros2idl" if conn.msgdef.format.name == "IDL" else "ros2msg"
    return BagConnection(conn.topic, conn.msgtype, conn.msgdef.data, msgdef_format,
                         conn.digest or "", qos, fmt)


# -- streaming MCAP -----------------------------------------------------------------------
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MSG_HEAD = struct.Struct("<HIQQ")
_CHUNK_HEAD = struct.Struct("<QQQI")
_OPCODES = set(range(0x01, 0x10))


class _Truncated(Exception):
    pass


class _Cursor:
    """Reads MCAP primitives from a bytes-like body."""

    def __init__(self, buf: bytes | memoryview) -> None:
        self.buf = memoryview(buf)
        self.pos = 0

    def take(self, n: int) -> memoryview:
        if self.pos + n > len(self.buf):
            raise _Truncated(f"field needs {n} bytes, {len(self.buf) - self.pos} left")
        out = self.buf[self.pos:self.pos + n]
        self.pos += n
        return out

    def u16(self) -> int:
        return int(_U16.unpack(self.take(2))[0])

    def u32(self) -> int:
        return int(_U32.unpack(self.take(4))[0])

    def u64(self) -> int:
        return int(_U64.unpack(self.take(8))[0])

    def string(self) -> str:
        return bytes(self.take(self.u32())).decode("utf8")

    def map(self) -> dict[str, str]:
        end = self.u32() + self.pos
        out: dict[str, str] = {}
        while self.pos < end:
            k = self.string()
            out[k] = self.string()
        return out


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        try:
            from compression import zstd  # type: ignore[import-not-found]
        except ImportError:
            from backports import zstd  # type: ignore[import-not-found,no-redef]
        return bytes(zstd.decompress(data))
    if compression == "lz4":
        from lz4.frame import decompress  # type: ignore[import-untyped]

        return bytes(decompress(data))
    raise ValueError(f"unsupported chunk compression {compression!r}")


class _McapStream:
    """A forward-only MCAP record reader that survives truncation and damage.

    The data section is magic, then records of opcode (u8) + length (u64 LE) + body.
    Schema (0x03), Channel (0x04) and Message (0x05) records are used, at top level or
    inside Chunks (0x06, uncompressed chunks are read even when cut short); reading stops at
    DataEnd (0x0F), at the Footer, or at the first damage, which is recorded in ``problems``.
    """

    def __init__(self, file: Path, first_index: int = 0) -> None:
        self.file = file
        self.schemas: dict[int, tuple[str, str, str]] = {}
        self.channels: dict[int, BagConnection] = {}
        self.problems: list[BagProblem] = []
        self.index = first_index
        self.complete = False
        self.metadata: dict[str, str] = {}

    def _problem(self, offset: int | None, reason: str) -> None:
        self.problems.append(BagProblem(self.file, offset, self.index, reason))

    def messages(self) -> Iterator[tuple[BagConnection, int, bytes]]:
        with self.file.open("rb") as f:
            size = f.seek(0, 2)
            f.seek(0)
            magic = f.read(8)
            if magic != _MCAP_MAGIC:
                self._problem(0, "not an MCAP file (bad magic)" if magic else "empty file")
                return
            yield from self._top_level(f, size)

    def _top_level(self, f: BinaryIO, size: int) -> Iterator[tuple[BagConnection, int, bytes]]:
        in_summary = False  # after DataEnd: only check that the file is whole
        while True:
            offset = f.tell()
            head = f.read(9)
            if len(head) < 9:
                if in_summary:
                    reason = ("summary section cut short (no footer): every message was read, "
                              "but tools that need the index (ros2 bag) cannot open the file")
                elif head:
                    reason = f"truncated record header ({len(head)} of 9 bytes)"
                else:
                    reason = ("file ends without DataEnd/Footer: the recording was interrupted "
                              "(everything before this point was read)")
                self._problem(offset, reason)
                return
            op = head[0]
            length = int(_U64.unpack(head[1:])[0])
            if op not in _OPCODES:
                self._problem(offset, f"invalid record opcode 0x{op:02x} (corrupt data)")
                return
            if op == 0x02:  # footer
                self.complete = True
                return
            available = size - offset - 9
            truncated = length > available
            if in_summary:
                if truncated:
                    self._problem(offset, f"summary record 0x{op:02x} cut short: every message "
                                          "was read, but the index is incomplete")
                    return
                f.seek(length, 1)
                continue
            if truncated and op != 0x06:
                self._problem(offset, f"record 0x{op:02x} truncated: needs {length} bytes, "
                                      f"file has {available} left")
                return
            if op == 0x0F:  # data end: the summary section follows
                f.seek(min(length, available), 1)
                in_summary = True
                continue
            body = f.read(min(length, available))
            if op == 0x06:
                yield from self._chunk(body, offset, truncated, length)
                if truncated:
                    return
                continue
            try:
                yield from self._record(op, body, offset)
            except (_Truncated, UnicodeDecodeError, struct.error) as exc:
                self._problem(offset, f"malformed record 0x{op:02x}: {exc}")
                return

    def _chunk(
        self, body: bytes, offset: int, truncated: bool, length: int
    ) -> Iterator[tuple[BagConnection, int, bytes]]:
        cur = _Cursor(body)
        try:
            _, _, uncompressed_size, crc = _CHUNK_HEAD.unpack(cur.take(28))
            compression = cur.string()
            records_len = cur.u64()
        except (_Truncated, UnicodeDecodeError) as exc:
            self._problem(offset, f"chunk header truncated: {exc}")
            return
        records = bytes(cur.buf[cur.pos:cur.pos + records_len])
        if truncated:
            if compression:
                self._problem(offset, f"{compression} chunk truncated: needs {length} bytes, "
                                      f"file has {len(body)}; its messages are lost")
                return
            data = records
        else:
            try:
                data = _decompress(records, compression, uncompressed_size)
            except Exception as exc:
                self._problem(offset, f"chunk cannot be decompressed: {exc}")
                return
            if len(data) != uncompressed_size:
                self._problem(offset, f"chunk size mismatch: {len(data)} != {uncompressed_size}")
                return
            if crc and zlib.crc32(data) != crc:
                self._problem(offset, "chunk CRC mismatch; chunk skipped")
                return
        # Records inside a chunk; offsets reported are file offsets of the chunk's data.
        data_offset = offset + 9 + 28 + 4 + len(compression) + 8
        inner = _Cursor(data)
        while inner.pos < len(data):
            rec_off = data_offset + inner.pos
            if len(data) - inner.pos < 9:
                self._problem(rec_off, "truncated inside a chunk (record header cut)")
                return
            op = data[inner.pos]
            inner.pos += 1
            rlen = inner.u64()
            if op not in _OPCODES:
                self._problem(rec_off, f"invalid record opcode 0x{op:02x} inside a chunk")
                return
            if rlen > len(data) - inner.pos:
                why = "truncated" if truncated else "overruns its chunk"
                self._problem(rec_off, f"record 0x{op:02x} {why}: needs {rlen} bytes, "
                                       f"{len(data) - inner.pos} left")
                return
            rec = inner.buf[inner.pos:inner.pos + rlen]
            inner.pos += rlen
            try:
                yield from self._record(op, rec, rec_off)
            except (_Truncated, UnicodeDecodeError, struct.error) as exc:
                self._problem(rec_off, f"malformed record 0x{op:02x}: {exc}")
                return
        if truncated:
            self._problem(offset + 9 + len(body), "file ends inside a chunk: the recording was "
                                                  "interrupted (everything before was read)")

    def _record(
        self, op: int, body: bytes | memoryview, offset: int
    ) -> Iterator[tuple[BagConnection, int, bytes]]:
        if op == 0x05:
            if len(body) < _MSG_HEAD.size:
                raise _Truncated("message record shorter than its header")
            channel_id, _, log_time, _ = _MSG_HEAD.unpack_from(body)
            conn = self.channels.get(channel_id)
            if conn is None:
                self._problem(offset, f"message on unknown channel {channel_id} skipped")
                return
            self.index += 1
            yield conn, int(log_time), bytes(body[_MSG_HEAD.size:])
        elif op == 0x03:
            cur = _Cursor(body)
            sid = cur.u16()
            name = cur.string()
            encoding = cur.string()
            data = bytes(cur.take(cur.u32())).decode("utf8")
            self.schemas[sid] = (name, encoding, data)
        elif op == 0x04:
            cur = _Cursor(body)
            cid = cur.u16()
            sid = cur.u16()
            topic = cur.string()
            encoding = cur.string()
            meta = cur.map()
            name, schema_enc, data = self.schemas.get(sid, ("", "", ""))
            qos: tuple[QoSProfile, ...] = ()
            if "offered_qos_profiles" in meta:
                try:
                    qos = tuple(qos_from_rosbags(q) for q in parse_qos(meta["offered_qos_profiles"]))
                except Exception:
                    qos = ()
            rihs = meta.get("type_description_hash", "")
            self.channels[cid] = BagConnection(
                topic, name, data, schema_enc or "ros2msg", rihs, qos, encoding or "cdr"
            )
        elif op == 0x0C:
            cur = _Cursor(body)
            if cur.string() == "rosbag2":
                self.metadata = cur.map()


@dataclass
class TopicSummary:
    """One line of ``bag info``: a topic, its type and how many messages it has."""

    name: str
    type_name: str
    count: int
    serialization_format: str = "cdr"
    qos: tuple[QoSProfile, ...] = ()


@dataclass
class BagInfo:
    """What ``bag_info`` found: files, storage, size, time span, topics, damage."""

    path: Path
    files: list[Path]
    storage: str
    size_bytes: int
    message_count: int
    start_ns: int
    end_ns: int
    topics: list[TopicSummary]
    problems: list[BagProblem] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    @property
    def complete(self) -> bool:
        return not self.problems


class BagReader:
    """Read a rosbag2 bag (directory, ``.mcap`` or ``.db3``), recovering what it can.

    ``rosbags`` reads intact bags (time-ordered, by index). An MCAP bag that it cannot open
    — no ``metadata.yaml``, a file cut short by a crash, damaged records — is streamed
    record by record up to the damage; ``problems`` then says where and why reading
    stopped. ``notes`` explains which path was taken.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f"bag {self.path} does not exist")
        self.problems: list[BagProblem] = []
        self.notes: list[str] = []
        self.storage = "mcap"
        self._unlisted: list[Path] = []
        self.files = self._files()
        self._reader: Reader | None = None
        self._connections: dict[int, BagConnection] = {}
        self._streamed: list[BagConnection] = []
        try:
            if self._unlisted:
                raise ReaderError("the bag has files its metadata.yaml does not list")
            reader = Reader(self.path)
            reader.open()
        except (ReaderError, FileNotFoundError, OSError, KeyError, ValueError) as exc:
            if not any(f.suffix == ".mcap" for f in self.files):
                raise BagError(f"cannot read bag {self.path}: {exc}") from exc
            self.notes.append(f"rosbags could not open the bag ({exc}); streaming the MCAP "
                              "records directly")
        else:
            self._reader = reader
            self.storage = "sqlite3" if any(f.suffix == ".db3" for f in self.files) else "mcap"

    def _files(self) -> list[Path]:
        if self.path.is_file():
            if self.path.suffix == ".db3":
                self.storage = "sqlite3"
            return [self.path]
        listed: list[Path] = []
        meta = self.path / "metadata.yaml"
        if meta.exists():
            try:
                info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
                listed = [self.path / p for p in info.get("relative_file_paths", [])]
                self.storage = str(info.get("storage_identifier", "mcap"))
            except Exception as exc:
                self.notes.append(f"{meta} is unreadable ({exc}); ignoring it")
        else:
            self.notes.append(f"{meta} is missing; reading the storage files directly")
        found = sorted(self.path.glob("*.mcap")) + sorted(self.path.glob("*.db3"))
        extra = [f for f in found if f not in listed]
        if extra and listed:
            self._unlisted = extra
            self.notes.append(
                "files not listed in metadata.yaml (an interrupted split?): "
                + ", ".join(f.name for f in extra)
            )
        files = [f for f in listed if f.exists()] + _natural_sorted(extra)
        if not files:
            raise BagError(f"no .mcap or .db3 files in {self.path}")
        return files

    @property
    def streaming(self) -> bool:
        """True when reading record by record (the bag could not be opened by index)."""
        return self._reader is None

    @property
    def connections(self) -> list[BagConnection]:
        """Connections known so far (all of them for an indexed bag)."""
        if self._reader is not None:
            return [self._conn(c) for c in self._reader.connections]
        return list(self._streamed)

    def _conn(self, c: Connection) -> BagConnection:
        bc = self._connections.get(c.id)
        if bc is None:
            bc = self._connections[c.id] = _connection_from_rosbags(c)
        return bc

    def messages(
        self, topics: Iterable[str] | None = None, start: int | None = None
    ) -> Iterator[BagMessage]:
        """Messages in order (``start``: skip those before this timestamp, ns).

        On damage, iteration ends after the last readable message and ``problems`` says
        where it broke.
        """
        wanted = set(topics) if topics is not None else None
        if self._reader is not None:
            conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
            if wanted is not None and not conns:
                return
            index = 0
            try:
                for c, ts, data in self._reader.messages(conns, start=start):
                    index += 1
                    yield BagMessage(self._conn(c), ts, bytes(data))
            except (ReaderError, OSError, ValueError) as exc:
                self.problems.append(BagProblem(self.path, None, index, str(exc)))
            return
        index = 0
        self.problems = []
        seen: dict[tuple[str, str], BagConnection] = {}
        for file in self.files:
            if file.suffix != ".mcap":
                self.problems.append(BagProblem(file, None, index, "cannot stream a non-MCAP file"))
                continue
            stream = _McapStream(file, index)
            for conn, ts, data in stream.messages():
                key = (conn.topic, conn.type_name)
                if key not in seen:
                    seen[key] = conn
                    self._streamed.append(conn)
                if (wanted is None or conn.topic in wanted) and (start is None or ts >= start):
                    yield BagMessage(conn, ts, data)
            index = stream.index
            self.problems.extend(stream.problems)

    def info(self) -> BagInfo:
        """Counts, time span and damage (streams the whole bag when it is not indexed)."""
        size = sum(f.stat().st_size for f in self.files if f.exists())
        if self._reader is not None:
            r = self._reader
            counts: dict[str, int] = {}
            for c in r.connections:
                counts[c.topic] = counts.get(c.topic, 0) + c.msgcount
            topics = [
                TopicSummary(bc.topic, bc.type_name, counts[bc.topic],
                             bc.serialization_format, bc.qos)
                for bc in _unique_topics([self._conn(c) for c in r.connections])
            ]
            n = r.message_count
            start = r.start_time if n else 0
            end = r.end_time if n else 0
            if n and end > start:
                end -= 1  # rosbags reports the end as exclusive
            return BagInfo(self.path, self.files, self.storage, size, n, start, end, topics,
                           list(self.problems), list(self.notes))
        scount: dict[str, int] = {}
        start = end = 0
        n = 0
        for m in self.messages():
            scount[m.topic] = scount.get(m.topic, 0) + 1
            start = m.timestamp if n == 0 else min(start, m.timestamp)
            end = max(end, m.timestamp)
            n += 1
        topics = [
            TopicSummary(c.topic, c.type_name, scount.get(c.topic, 0), c.serialization_format, c.qos)
            for c in _unique_topics(self._streamed)
        ]
        return BagInfo(self.path, self.files, self.storage, size, n, start, end, topics,
                       list(self.problems), list(self.notes))

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _unique_topics(conns: Iterable[BagConnection]) -> list[BagConnection]:
    out: dict[str, BagConnection] = {}
    for c in conns:
        out.setdefault(c.topic, c)
    return sorted(out.values(), key=lambda c: c.topic)


def _natural_sorted(files: Iterable[Path]) -> list[Path]:
    def key(p: Path) -> list[Any]:
        return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", p.name)]

    return sorted(files, key=key)


def bag_info(path: str | Path) -> BagInfo:
    """Summarise a bag as ``ros2 bag info`` does (recovering damaged MCAP bags)."""
    with BagReader(path) as reader:
        return reader.info()


def _format_size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.1f} {unit}" if unit != "B" else f"{n} B"
        size /= 1024
    return f"{n} B"  # pragma: no cover


def _format_time(ns: int) -> str:
    t = _dt.datetime.fromtimestamp(ns // _NS, tz=_dt.timezone.utc)
    return f"{t:%b %d %Y %H:%M:%S}.{ns % _NS:09d} ({ns // _NS}.{ns % _NS:09d})"


def format_bag_info(info: BagInfo) -> str:
    """The text ``eddie bag info`` prints (the layout of ``ros2 bag info``)."""
    pad = 19
    lines = [
        f"{'Files:':<{pad}}" + ("\n" + " " * pad).join(str(f.name) for f in info.files),
        f"{'Bag size:':<{pad}}{_format_size(info.size_bytes)}",
        f"{'Storage id:':<{pad}}{info.storage}",
        f"{'Duration:':<{pad}}{info.duration_ns / _NS:.9f}s",
        f"{'Start:':<{pad}}{_format_time(info.start_ns)}",
        f"{'End:':<{pad}}{_format_time(info.end_ns)}",
        f"{'Messages:':<{pad}}{info.message_count}",
    ]
    if info.topics:
        width = max(len(t.name) for t in info.topics)
        tw = max(len(t.type_name) for t in info.topics)
        rows = [
            f"Topic: {t.name:<{width}} | Type: {t.type_name:<{tw}} | Count: {t.count} | "
            f"Serialization Format: {t.serialization_format}"
            + (" | transient_local" if any(q.transient_local for q in t.qos) else "")
            for t in info.topics
        ]
        lines.append(f"{'Topic information:':<{pad}}" + ("\n" + " " * pad).join(rows))
    else:
        lines.append(f"{'Topic information:':<{pad}}")
    for note in info.notes:
        lines.append(f"Note: {note}")
    for p in info.problems:
        lines.append(f"Damaged: {p}")
    if info.problems:
        lines.append(f"Readable prefix: {info.message_count} messages "
                     f"({info.duration_ns / _NS:.3f} s)")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------
# Recording node
# --------------------------------------------------------------------------------------
def _graph_topics(graph: Any) -> dict[str, tuple[str, list[QoSProfile]]]:
    """Topic → (type, offered QoS profiles) of remote publishers in a transport's ``graph()``.

    Read from ``graph["cache"].publishers()`` (entities with ``name``, ``type_name`` and
    an rmw_zenoh QoS string ``qos``), as ``eddiebot.transport`` provides it. Also accepted
    under ``"topics"``: a mapping of topic to type name, or a list of ``(topic, type)``.
    """
    out: dict[str, tuple[str, list[QoSProfile]]] = {}
    if not isinstance(graph, dict):
        return out
    cache = graph.get("cache")
    publishers = getattr(cache, "publishers", None)
    if callable(publishers):
        from eddiebot.transport.keys import qos_from_keyexpr

        for entity in publishers():
            name = getattr(entity, "name", "")
            typ = getattr(entity, "type_name", "")
            if not name or not typ:
                continue
            _, profiles = out.setdefault(name, (typ, []))
            text = getattr(entity, "qos", "")
            if text:
                try:
                    q = qos_from_keyexpr(text)
                except Exception:
                    continue
                if q not in profiles:
                    profiles.append(q)
    topics = graph.get("topics")
    if isinstance(topics, dict):
        for name, typ in topics.items():
            if isinstance(typ, str):
                out.setdefault(name, (typ, []))
    elif isinstance(topics, (list, tuple)):
        for item in topics:
            if isinstance(item, (list, tuple)) and len(item) >= 2:
                out.setdefault(str(item[0]), (str(item[1]), []))
    return out


class RecorderNode(Node):
    """``ros2 bag record`` as a node: topics to a rosbag2 MCAP directory.

    Parameters: ``output`` (bag directory; default ``rosbag2_<date>-<time>``), ``topics``
    (names), ``all`` (every topic, including ones that appear later), ``exclude`` (regular
    expressions), ``max_bag_duration`` (s, 0: no split), ``max_bag_size`` (bytes, 0: no
    split), ``polling_interval`` (s, how often new topics are looked for),
    ``flush_interval`` (wall s between flushes to the file). Each message is stamped with
    its receive time on the node clock. The bag is closed by ``destroy_node``.
    """

    def __init__(self, node_name: str = "recorder", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        output = str(self.declare_parameter("output", "").value or "")
        topics = self.declare_parameter("topics", []).value or []
        self._all = bool(self.declare_parameter("all", False).value)
        exclude = self.declare_parameter("exclude", []).value or []
        max_duration = float(self.declare_parameter("max_bag_duration", 0.0).value or 0.0)
        max_size = int(self.declare_parameter("max_bag_size", 0).value or 0)
        polling = float(self.declare_parameter("polling_interval", 0.1).value)
        self._flush_ns = round(float(self.declare_parameter("flush_interval", 1.0).value) * _NS)
        if isinstance(topics, str):
            topics = [topics]
        if isinstance(exclude, str):
            exclude = [exclude]
        self._topics = [self.resolve_topic_name(str(t)) for t in topics]
        self._exclude = [re.compile(str(e)) for e in exclude]
        if not self._all and not self._topics:
            raise BagError("recorder: give topics or set all: true")
        if not output:
            now = _dt.datetime.fromtimestamp(self.context.system_clock.now_ns() / _NS)
            output = f"rosbag2_{now:%Y_%m_%d-%H_%M_%S}"
        self.output = Path(output)
        self.writer = BagWriter(self.output, max_bag_duration=max_duration,
                                max_bag_size=max_size)
        self._subs: dict[str, Subscription] = {}
        self._skipped: set[str] = set()
        self._remote_qos: dict[str, list[QoSProfile]] = {}
        self._last_flush = self.context.system_clock.now_ns()
        self.discover()
        self._poll = self.create_timer(polling, self._on_poll)
        self.get_logger().info(f"recording to {self.output}")

    # -- topics -----------------------------------------------------------------------
    def _wanted(self, topic: str) -> bool:
        if any(rx.search(topic) for rx in self._exclude):
            return False
        return self._all or topic in self._topics

    def _offered_qos(self, topic: str) -> list[QoSProfile]:
        entry = self.context.topics.get(topic)
        pubs: list[Publisher] = list(entry.publishers) if entry is not None else []
        profiles: list[QoSProfile] = []
        for q in [p.qos for p in pubs] + self._remote_qos.get(topic, []):
            if q not in profiles:
                profiles.append(q)
        return profiles

    def discover(self) -> None:
        """Subscribe to wanted topics not yet recorded (local registry and transports)."""
        found: dict[str, str] = {}
        for name, entry in list(self.context.topics.items()):
            if entry.type_name and entry.publishers:
                found[name] = entry.type_name
        for t in list(self.context.transports):
            try:
                remote = _graph_topics(t.graph())
            except Exception as exc:
                self.get_logger().warning(f"transport graph unavailable: {exc}", once=True)
                continue
            for name, (typ, profiles) in remote.items():
                found.setdefault(name, typ)
                known = self._remote_qos.setdefault(name, [])
                known.extend(q for q in profiles if q not in known)
        # Named topics with a known type are subscribed even before anyone publishes.
        for name in self._topics:
            known_entry = self.context.topics.get(name)
            if name not in found and known_entry is not None and known_entry.type_name:
                found[name] = known_entry.type_name
        for name, typ in sorted(found.items()):
            if name in self._subs or name in self._skipped or not self._wanted(name):
                continue
            self._subscribe(name, typ)

    def _remote_hash(self, topic: str, typ: str) -> str | None:
        """The RIHS01 hash the publishers of ``topic`` announce for ``typ`` (None: none yet)."""
        for t in list(self.context.transports):
            try:
                cache = t.graph().get("cache")
            except Exception:
                continue
            for e in cache.publishers(topic) if cache is not None else []:
                if e.type_name == typ and e.type_hash.startswith("RIHS01_"):
                    return str(e.type_hash)
        return None

    def _subscribe(self, topic: str, typ: str) -> None:
        msgdef: str | None = None
        rihs01: str | None = None
        try:
            cls = get_message(typ)
        except UnknownTypeError as exc:
            # nothing describes it here: record its CDR as it comes, with an empty schema
            # (as rosbag2 does for a type whose definition it cannot find)
            rihs01 = self._remote_hash(topic, typ)
            if rihs01 is None:
                return  # no publisher has announced it yet: look again at the next poll
            cls = raw_message_type(typ, rihs01)
            msgdef = ""
            self.get_logger().warning(f"recording {topic} undecoded, with no definition: {exc}")
        offered = self._offered_qos(topic)
        latched = any(q.transient_local for q in offered)
        best_effort = bool(offered) and all(
            q.reliability == ReliabilityPolicy.BEST_EFFORT for q in offered
        )
        sub_qos = QoSProfile(
            depth=1000,
            history=HistoryPolicy.KEEP_ALL,
            reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        self.writer.add_topic(topic, cls.__msgtype__, qos=offered or [sub_qos], msgdef=msgdef,
                              rihs01=rihs01)

        def on_message(msg: Any, topic: str = topic, typ: str = cls.__msgtype__) -> None:
            self._record(topic, typ, msg)

        self._subs[topic] = self.create_subscription(cls, topic, on_message, sub_qos, raw=True)
        self.get_logger().info(f"recording {topic} [{typ}]")

    # -- data -------------------------------------------------------------------------
    def _record(self, topic: str, typ: str, msg: Any) -> None:
        if self.writer.closed:
            return
        stamp = self.get_clock().now_ns()
        data = bytes(msg) if isinstance(msg, (bytes, bytearray, memoryview)) else serialize(msg, typ)
        self.writer.write(topic, data, stamp)
        wall = self.context.system_clock.now_ns()
        if wall - self._last_flush >= self._flush_ns:
            self._last_flush = wall
            self.writer.flush()

    def _on_poll(self) -> None:
        self.discover()
        wall = self.context.system_clock.now_ns()
        if wall - self._last_flush >= self._flush_ns and not self.writer.closed:
            self._last_flush = wall
            self.writer.flush()

    @property
    def recorded_topics(self) -> list[str]:
        return sorted(self._subs)

    def destroy_node(self) -> None:
        super().destroy_node()
        self.writer.close()


# --------------------------------------------------------------------------------------
# Playing node
# --------------------------------------------------------------------------------------
class Player(Node):
    """``ros2 bag play`` as a node, paced by a timer on the node clock.

    Each message is published at ``anchor + (t - t_start) / rate`` on the node clock, where
    ``t_start`` is the bag's first timestamp plus ``start_offset`` (s). On a simulated clock
    that is behind the bag's start, the clock is moved to the bag's start first, so messages
    come out at their recorded times (``use_bag_time``); the executor then jumps from one
    message to the next, so playback is instant and deterministic. Topics offered
    transient-local in the bag are republished latched. With ``publish_clock``, ``/clock``
    carries the bag time before each message and every ``1 / clock_frequency`` s.
    """

    def __init__(
        self,
        bag: str | Path,
        node_name: str = "player",
        *,
        rate: float = 1.0,
        loop: bool = False,
        start_offset: float = 0.0,
        topics: Sequence[str] | None = None,
        publish_clock: bool = False,
        clock_frequency: float = 40.0,
        delay: float = 0.0,
        use_bag_time: bool = True,
        shutdown_when_done: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(node_name, **kwargs)
        if rate <= 0:
            raise BagError(f"play rate must be > 0, got {rate}")
        self.bag = Path(bag)
        self.rate = float(rate)
        self.loop = bool(loop)
        self.start_offset_ns = round(start_offset * _NS)
        self.topics = list(topics) if topics else None
        self.publish_clock = publish_clock
        self.shutdown_when_done = shutdown_when_done
        self.problems: list[BagProblem] = []
        self.notes: list[str] = []
        self.published = 0
        self.loops = 0
        self.done = False
        self._publishers: dict[str, Publisher] = {}
        self._failed_topics: set[str] = set()
        self._reader: BagReader | None = None
        self._iter: Iterator[BagMessage] | None = None
        self._next: BagMessage | None = None
        self._anchor_bag = 0
        self._anchor_play = 0
        self._clock_pub: Publisher | None = None
        if publish_clock:
            from eddiebot.msgs.rosgraph_msgs import Clock as ClockMsg

            self._clock_msg = ClockMsg
            self._clock_pub = self.create_publisher(ClockMsg, "/clock", QoSProfile(depth=1))
            if clock_frequency > 0:
                self.create_timer(1.0 / clock_frequency, self._on_clock_timer)
        self._open(first=True)
        assert self._reader is not None
        for conn in self._reader.connections:  # indexed bags: every topic is known up front
            if self.topics is None or conn.topic in self.topics:
                self._publisher(conn)
        now = self.get_clock().now_ns()
        clock = self.get_clock()
        if use_bag_time and clock is self.context.sim_clock and now < self._anchor_bag:
            self.context.sim_clock.set_ns(self._anchor_bag)
            now = self._anchor_bag
        self._anchor_play = now + round(delay * _NS)
        self._timer: Timer = self.create_timer(1.0, self._on_timer)
        self._schedule()

    # -- reading ----------------------------------------------------------------------
    def _open(self, first: bool) -> None:
        if self._reader is not None:
            self._reader.close()
        self._reader = BagReader(self.bag)
        if first:
            self.notes.extend(self._reader.notes)
        self._iter = self._reader.messages(self.topics)
        self._next = self._pull()
        if self._next is not None:
            self._anchor_bag = self._next.timestamp + self.start_offset_ns
            if self.start_offset_ns > 0:
                while self._next is not None and self._next.timestamp < self._anchor_bag:
                    self._next = self._pull()

    def _pull(self) -> BagMessage | None:
        assert self._iter is not None
        msg = next(self._iter, None)
        if msg is None and self._reader is not None:
            for p in self._reader.problems:
                if p not in self.problems:
                    self.problems.append(p)
                    self.get_logger().warning(f"bag damaged: {p}; played the readable prefix")
        return msg

    def _play_time(self, msg: BagMessage) -> int:
        return self._anchor_play + round((msg.timestamp - self._anchor_bag) / self.rate)

    def bag_time(self, now_ns: int | None = None) -> int:
        """The bag time (ns) that corresponds to node-clock time ``now_ns``."""
        now = self.get_clock().now_ns() if now_ns is None else now_ns
        return self._anchor_bag + round((now - self._anchor_play) * self.rate)

    # -- timing -----------------------------------------------------------------------
    def _schedule(self) -> None:
        timer = self._timer
        if self._next is None:
            timer.cancel()
            self._finish()
            return
        timer.canceled = False
        timer.next_call_ns = self._play_time(self._next)
        self._timers_changed()

    def _on_timer(self) -> None:
        now = self.get_clock().now_ns()
        clock_sent = False
        while self._next is not None and self._play_time(self._next) <= now:
            msg = self._next
            if not clock_sent and self._clock_pub is not None:
                self._publish_clock(now)
                clock_sent = True
            self._publish(msg)
            self._next = self._pull()
        if self._next is None and self.loop and self.published:
            self.loops += 1
            self._open(first=False)
            self._anchor_play = now + _LOOP_GAP_NS
        self._schedule()

    def _publisher(self, conn: BagConnection) -> Publisher | None:
        topic = conn.topic
        pub = self._publishers.get(topic)
        if pub is not None or topic in self._failed_topics:
            return pub
        try:
            ensure_type(conn)
            cls = get_message(conn.type_name)
        except Exception as exc:
            self._failed_topics.add(topic)
            self.get_logger().warning(f"cannot play {topic} [{conn.type_name}]: {exc}")
            return None
        qos = conn.qos[0] if conn.qos else QoSProfile()
        if conn.transient_local:
            qos = QoSProfile(depth=max(q.depth for q in conn.qos),
                             durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        pub = self._publishers[topic] = self.create_publisher(cls, topic, qos)
        return pub

    def _publish(self, msg: BagMessage) -> None:
        pub = self._publisher(msg.connection)
        if pub is None:
            return
        try:
            obj = msg.decode()
        except Exception as exc:
            self.get_logger().warning(f"message on {msg.topic} cannot be decoded: {exc}", once=True)
            return
        pub.publish(obj)
        self.published += 1

    def _publish_clock(self, now: int) -> None:
        if self._clock_pub is None:
            return
        from eddiebot.core.time import ns_to_stamp

        self._clock_pub.publish(self._clock_msg(clock=ns_to_stamp(self.bag_time(now))))

    def _on_clock_timer(self) -> None:
        if not self.done:
            self._publish_clock(self.get_clock().now_ns())

    def _finish(self) -> None:
        if self.done:
            return
        self.done = True
        self.get_logger().info(f"played {self.published} messages from {self.bag}")
        executor = self.executor
        if self.shutdown_when_done and executor is not None:
            # After the callbacks the last messages queued (they were enqueued first).
            executor.create_task(lambda: executor.shutdown())

    def destroy_node(self) -> None:
        super().destroy_node()
        if self._reader is not None:
            self._reader.close()
            self._reader = None
