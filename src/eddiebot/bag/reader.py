"""Reading rosbag2 bags: ``BagReader``, recovering what it can of damaged ones.

Intact bags (directories of MCAP or sqlite3 files, bare ``.mcap`` and ``.db3`` files) are
read by index through ``rosbags``; an MCAP bag that ``rosbags`` cannot open is streamed
record by record up to the damage (``eddiebot.bag.recovery``).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Connection, ConnectionExtRosbag2
from rosbags.rosbag2 import Reader
from rosbags.rosbag2.errors import ReaderError

from eddiebot.bag.errors import BagError
from eddiebot.bag.qos import qos_from_rosbags
from eddiebot.bag.records import (
    BagConnection,
    BagInfo,
    BagMessage,
    BagProblem,
    TopicSummary,
    split_services,
)
from eddiebot.bag.recovery import McapStream, distro_from_metadata, read_rosbag2_metadata
from eddiebot.core.qos import QoSProfile

__all__ = ["BagReader"]


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
        #: the ROS distribution that wrote the bag, as its metadata says ("": not said)
        self.ros_distro = ""
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
            if not self.ros_distro and self.storage == "mcap":  # a bare .mcap file
                self.ros_distro = distro_from_metadata(read_rosbag2_metadata(self.files[0]))

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
                self.ros_distro = str(info.get("ros_distro") or "")
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
            stream = McapStream(file, index)
            for conn, ts, data in stream.messages():
                if not self.ros_distro:
                    self.ros_distro = stream.ros_distro
                key = (conn.topic, conn.type_name)
                if key not in seen:
                    seen[key] = conn
                    self._streamed.append(conn)
                if (wanted is None or conn.topic in wanted) and (start is None or ts >= start):
                    yield BagMessage(conn, ts, data)
            index = stream.index
            self.problems.extend(stream.problems)
            self.ros_distro = self.ros_distro or stream.ros_distro

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
            return self._info(size, n, start, end, topics)
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
        return self._info(size, n, start, end, topics)

    def _info(self, size: int, n: int, start: int, end: int,
              topics: list[TopicSummary]) -> BagInfo:
        plain, services = split_services(topics)
        return BagInfo(self.path, self.files, self.storage, size, n, start, end, plain,
                       list(self.problems), list(self.notes), services, self.ros_distro)

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
