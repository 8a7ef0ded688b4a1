"""``bag info``: what ``ros2 bag info`` (Jazzy) prints about a bag, and where it is damaged.

The layout is rosbag2's: files, size, storage, ROS distribution, time span, messages, one
line per topic, then the services recorded as their event topics. Our additions follow
it: ``| transient_local`` on latched topics, ``Note:`` lines (how the bag was read) and
``Damaged:`` lines with the readable prefix.
"""

from __future__ import annotations

import datetime as _dt
from pathlib import Path

from eddiebot.bag.reader import BagReader
from eddiebot.bag.records import BagInfo

__all__ = ["bag_info", "format_bag_info"]

_NS = 1_000_000_000


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
        f"{'ROS Distro:':<{pad}}{info.ros_distro or 'unknown'}",
        f"{'Duration:':<{pad}}{info.duration_ns / _NS:.9f}s",
        f"{'Start:':<{pad}}{_format_time(info.start_ns)}",
        f"{'End:':<{pad}}{_format_time(info.end_ns)}",
        f"{'Messages:':<{pad}}{info.topic_message_count}",
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
    lines.append(f"{'Service:':<{pad}}{len(info.services)}")
    services = [
        f"Service: {s.name} | Type: {s.type_name} | Event Count: {s.event_count} | "
        f"Serialization Format: {s.serialization_format}"
        for s in sorted(info.services, key=lambda s: s.name)
    ]
    lines.append("Service information: " + ("\n" + " " * (pad + 2)).join(services))
    for note in info.notes:
        lines.append(f"Note: {note}")
    for p in info.problems:
        lines.append(f"Damaged: {p}")
    if info.problems:
        lines.append(f"Readable prefix: {info.message_count} messages "
                     f"({info.duration_ns / _NS:.3f} s)")
    return "\n".join(lines)
