"""``eddie topic hz|bw|delay`` — as ``ros2 topic``: rates, bandwidth and header-stamp delays
measured on the samples of a topic."""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import deque
from typing import Any

from eddiebot.cli._common import CliSession, cli_session
from eddiebot.cli._topic_publishers import _publisher_qos_hint
from eddiebot.msgs.errors import UnknownTypeError

#: ``ros2 topic delay``'s default window, in messages.
DELAY_WINDOW = 10000


# -- hz -------------------------------------------------------------------------------
def _raw_type(s: CliSession, topic: str, type_name: str) -> Any:
    """The class to subscribe to ``topic`` with raw (the samples' CDR bytes, undecoded): ours,
    or for a type nothing here describes a stand-in carrying its publishers' RIHS01 hash."""
    from eddiebot.msgs import get_message, raw_message_type

    try:
        return get_message(type_name)
    except UnknownTypeError:
        cache = s.remote()
        hashes = sorted({e.type_hash for e in (cache.publishers(topic) if cache else [])
                         if e.type_name == type_name and e.type_hash.startswith("RIHS01_")})
        return raw_message_type(type_name, hashes[0] if hashes else None)


def _measure(args: argparse.Namespace, verb: str, on_sample: Any, report: Any,
             banner: str | None = None, prepare: Any = None) -> int:
    """Subscribe raw to the topic (no decoding: any type, described here or not), feed each
    sample to ``on_sample``, and print ``report()`` every second and at the end (nothing
    when it is None). ``prepare(session, type_name)``, if given, runs before subscribing
    (a ValueError from it is the command's one-line error)."""
    from eddiebot.core import SingleThreadedExecutor

    topic = args.topic_name if args.topic_name.startswith("/") else "/" + args.topic_name
    with cli_session("topic") as s:
        type_name = s.wait_for_topic_type(topic, args.duration)
        if type_name is None:
            print(f"eddie topic {verb}: topic {topic} did not appear", file=sys.stderr)
            return 1
        if prepare is not None:
            prepare(s, type_name)
        _tl, be = _publisher_qos_hint(s, topic)
        s.node.create_subscription(_raw_type(s, topic, type_name), topic, on_sample,
                                   10 if not be else _qos_be(), raw=True)
        if banner:
            print(banner.format(topic=topic), flush=True)
        ex = SingleThreadedExecutor(context=s.context)
        ex.add_node(s.node)
        start = next_print = time.monotonic()
        while s.context.ok():
            ex.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now >= next_print + 1.0:
                next_print = now
                _print_report(report())
            if args.duration is not None and now - start >= args.duration:
                break
        _print_report(report())
    return 0


def _print_report(text: str | None) -> None:
    if text is not None:
        print(text, flush=True)


def _hz(args: argparse.Namespace) -> int:
    stamps: deque[float] = deque(maxlen=max(2, args.window + 1))
    return _measure(args, "hz", lambda _m: stamps.append(time.monotonic()),
                    lambda: _rate_report(list(stamps)))


# -- bw -------------------------------------------------------------------------------
def _bw(args: argparse.Namespace) -> int:
    from eddiebot.msgs import serialize

    samples: deque[tuple[float, int]] = deque(maxlen=max(1, args.window))

    def on_sample(data: Any) -> None:
        # bytes from another process; a message object from this one (by reference)
        size = len(data) if isinstance(data, (bytes, bytearray, memoryview)) else len(
            serialize(data))
        samples.append((time.monotonic(), size))

    return _measure(args, "bw", on_sample,
                    lambda: _bw_report(list(samples), time.monotonic()),
                    banner="Subscribed to [{topic}]")


def _bw_report(samples: list[tuple[float, int]], now: float) -> str:
    """``ros2 topic bw``'s lines: bytes per second over the window, and message sizes."""
    if len(samples) < 2:
        return "no new messages" if not samples else f"1 message of {_size(samples[0][1])}"
    sizes = [n for _, n in samples]
    span = max(now, samples[-1][0]) - samples[0][0]
    rate = sum(sizes) / span if span > 0 else float("inf")
    return (f"{_size(rate)}/s from {len(sizes)} messages\n\tMessage size mean: "
            f"{_size(sum(sizes) / len(sizes))} min: {_size(min(sizes))} max: {_size(max(sizes))}")


def _size(n: float) -> str:
    for unit, scale in (("MB", 1e6), ("KB", 1e3)):
        if n >= scale:
            return f"{n / scale:.2f} {unit}"
    return f"{n:.2f} B"


def _qos_be() -> Any:
    from eddiebot.core.qos import qos_profile_sensor_data

    return qos_profile_sensor_data


def _rate_report(stamps: list[float]) -> str:
    if len(stamps) < 2:
        return "no new messages"
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    mean = sum(gaps) / len(gaps)
    std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
    rate = 1.0 / mean if mean > 0 else float("inf")
    return (f"average rate: {rate:.3f}\n\tmin: {min(gaps):.3f}s max: {max(gaps):.3f}s "
            f"std dev: {std:.5f}s window: {len(stamps)}")


# -- delay ----------------------------------------------------------------------------
class DelayStats:
    """``ros2 topic delay``'s figures: receipt time minus header stamp (ns) over the last
    ``window`` messages. The first message (and the first after time went backwards, as
    with a bag replayed in a loop) starts the window; a receipt at time zero (no ``/clock``
    yet) is not counted."""

    def __init__(self, window: int = DELAY_WINDOW) -> None:
        self.delays: deque[int] = deque(maxlen=max(1, window))
        self._first_ns = -1
        self._last_ns = 0
        self._reported_ns = 0
        self.resets = 0

    def add(self, now_ns: int, stamp_ns: int) -> None:
        if now_ns == 0:
            if self.delays:
                self.resets += 1
                self.delays.clear()
            return
        if self._first_ns < 0 or self._first_ns > now_ns:
            if self._first_ns > now_ns:
                self.resets += 1
            self._first_ns = self._last_ns = now_ns
            self.delays.clear()
            return
        self.delays.append(now_ns - stamp_ns)
        self._last_ns = now_ns

    def figures(self) -> tuple[float, float, float, float, int] | None:
        """(mean, min, max, standard deviation) in seconds and the window's size; None
        before the first delay."""
        if not self.delays:
            return None
        n = len(self.delays)
        mean = sum(self.delays) / n
        std = math.sqrt(sum((d - mean) ** 2 for d in self.delays) / n)
        return mean * 1e-9, min(self.delays) * 1e-9, max(self.delays) * 1e-9, std * 1e-9, n

    def report(self) -> str | None:
        """ros2's lines; "no new messages" when nothing came since the last report; None
        before the first delay."""
        got = self.figures()
        if got is None:
            return None
        if self._last_ns == self._reported_ns:
            return "no new messages"
        self._reported_ns = self._last_ns
        mean, lo, hi, std, n = got
        return (f"average delay: {mean:.3f}\n\tmin: {lo:.3f}s max: {hi:.3f}s "
                f"std dev: {std:.5f}s window: {n}")


def _delay(args: argparse.Namespace) -> int:
    from eddiebot.core.time import stamp_to_ns
    from eddiebot.msgs import TYPESTORE, deserialize

    stats = DelayStats(args.window)
    state: dict[str, Any] = {}

    def prepare(s: CliSession, type_name: str) -> None:
        fields = [name for name, _desc in TYPESTORE.fielddefs[type_name][1]] \
            if type_name in TYPESTORE.fielddefs else None
        if fields is None:
            from eddiebot.msgs import get_message

            get_message(type_name)  # loads it from an interface file, or says it cannot
            fields = [name for name, _desc in TYPESTORE.fielddefs[type_name][1]]
        if "header" not in fields:
            raise ValueError(f"{type_name} has no header: the delay is measured from "
                             "header.stamp")
        state["type"] = type_name
        if args.use_sim_time:
            from eddiebot.core.clock_node import ClockFollower

            state["follower"] = ClockFollower(s.node)
            state["clock"] = s.context.sim_clock
        else:
            state["clock"] = s.context.system_clock

    def on_sample(data: Any) -> None:
        # bytes from another process; a message object from this one (by reference)
        msg = deserialize(bytes(data), state["type"]) \
            if isinstance(data, (bytes, bytearray, memoryview)) else data
        stats.add(state["clock"].now_ns(), stamp_to_ns(msg.header.stamp))

    return _measure(args, "delay", on_sample, stats.report, prepare=prepare)
