"""Writing rosbag2 MCAP bags: ``BagWriter``.

Files are rosbag2 (Jazzy) MCAP with ``metadata.yaml`` version 9, written with ``rosbags``:
every topic carries its full message definition, its RIHS01 type hash (``topic_type_hash``
in the MCAP channel, ``type_description_hash`` in ``metadata.yaml``) and its offered QoS
profiles, so Foxglove and ``ros2 bag`` read the files. Chunks are flushed to the file at
least every ``flush`` and on ``close``; a process that dies leaves at worst a truncated MCAP
whose prefix ``BagReader`` recovers.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.errors import WriterError
from rosbags.rosbag2.storage_mcap import (
    Channel,
    McapWriter,
    PendingChunk,
    Schema,
    write_channel,
    write_record,
    write_schema,
    write_string,
)

from eddiebot.bag.errors import BagError
from eddiebot.bag.qos import qos_to_rosbags
from eddiebot.core.qos import QoSProfile
from eddiebot.msgs import message_definition, serialize, type_hash, type_name

__all__ = ["ROS_DISTRO", "BagWriter"]

#: The distribution our bags say they come from (``ros_distro``; the message definitions and
#: hashes are Jazzy's).
ROS_DISTRO = "jazzy"
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_NS = 1_000_000_000


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

    def add_connection(self, connection: Connection, offered_qos_profiles: str) -> None:
        """A channel with rosbag2's metadata: the offered QoS and the RIHS01
        ``topic_type_hash`` (rosbags writes only the QoS)."""
        metadata = BytesIO()
        for key, value in (("offered_qos_profiles", offered_qos_profiles),
                           ("topic_type_hash", connection.digest or "")):
            write_string(metadata, key)
            write_string(metadata, value)
        ext = connection.ext
        encoding = ext.serialization_format if isinstance(ext, ConnectionExtRosbag2) else "cdr"
        self.channels.append(Channel(connection.id, connection.msgtype, connection.topic,
                                     encoding, metadata.getvalue()))
        self.channel_stats[connection.id] = 0
        write_channel(self.chunk.bio, self.channels[-1], self.schemas)

    def close(self, version: int, metadata: str) -> None:
        """Finish the file; its embedded copy of the metadata names our distribution."""
        info = yaml.safe_load(metadata)
        if isinstance(info, dict):
            info["ros_distro"] = ROS_DISTRO
            metadata = yaml.safe_dump(info, sort_keys=False).strip()
        super().close(version, metadata)

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
            "ros_distro": ROS_DISTRO,
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
