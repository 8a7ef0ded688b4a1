"""Reading what is left of a damaged MCAP file: ``McapStream``.

A forward-only record reader for rosbag2 MCAP files that ``rosbags`` cannot open by index
(a recording cut short by a crash, damaged records, a missing ``metadata.yaml``): it yields
every message up to the damage and says where and why it stopped (``BagProblem``).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import yaml
from rosbags.rosbag2.metadata import parse_qos

from eddiebot.bag.qos import qos_from_rosbags
from eddiebot.bag.records import BagConnection, BagProblem
from eddiebot.core.qos import QoSProfile

__all__ = ["McapStream", "distro_from_metadata", "read_rosbag2_metadata"]

_MCAP_MAGIC = b"\x89MCAP0\r\n"
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


def read_rosbag2_metadata(file: Path) -> dict[str, str]:
    """The ``rosbag2`` metadata record of an intact MCAP file, found through its summary's
    metadata index (no scan of the data); empty when the file has none or is not intact."""
    try:
        with file.open("rb") as f:
            size = f.seek(0, 2)
            if size < 8 + 37:
                return {}
            f.seek(size - 37)
            footer = f.read(37)
            if footer[0] != 0x02 or footer[-8:] != _MCAP_MAGIC:
                return {}
            summary_start = int(_U64.unpack_from(footer, 9)[0])
            if not 0 < summary_start < size - 37:
                return {}
            f.seek(summary_start)
            summary = _Cursor(f.read(size - 37 - summary_start))
            while summary.pos + 9 <= len(summary.buf):
                op = summary.buf[summary.pos]
                summary.pos += 1
                body = _Cursor(summary.take(summary.u64()))
                if op != 0x0D:  # metadata index: offset, length, name
                    continue
                offset, length = body.u64(), body.u64()
                if body.string() != "rosbag2":
                    continue
                f.seek(offset)
                record = f.read(length)
                if len(record) != length or record[0] != 0x0C:
                    return {}
                rec = _Cursor(record[9:])
                rec.string()
                return rec.map()
    except (OSError, _Truncated, UnicodeDecodeError, struct.error):
        return {}
    return {}


def distro_from_metadata(metadata: dict[str, str]) -> str:
    """The distribution a ``rosbag2`` metadata record names ("" if none): a ``ROS_DISTRO``
    entry (older rosbag2) or ``ros_distro`` in ``serialized_metadata``."""
    if metadata.get("ROS_DISTRO"):
        return metadata["ROS_DISTRO"]
    try:
        info = yaml.safe_load(metadata.get("serialized_metadata", "") or "{}")
    except yaml.YAMLError:
        return ""
    return str(info.get("ros_distro") or "") if isinstance(info, dict) else ""


class McapStream:
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

    @property
    def ros_distro(self) -> str:
        """The distribution named by the file's ``rosbag2`` metadata record, once read."""
        return distro_from_metadata(self.metadata)

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
            # rosbag2 (Jazzy) names the channel's RIHS01 hash "topic_type_hash"
            rihs = meta.get("topic_type_hash") or meta.get("type_description_hash", "")
            self.channels[cid] = BagConnection(
                topic, name, data, schema_enc or "ros2msg", rihs, qos, encoding or "cdr"
            )
        elif op == 0x0C:
            cur = _Cursor(body)
            if cur.string() == "rosbag2":
                self.metadata = cur.map()
