"""A fault-injecting link for tests: an emulated board behind an unreliable wire.

:class:`FaultyLink` implements the :class:`~eddiebot.robot.links.Link` protocol in front of
a :class:`~eddiebot.robot.emulator.FirmwareEmulator`, on a :class:`FakeClock`.  Replies are
scheduled on the fake clock (``latency_s`` after the write) and :meth:`FaultyLink.read`
advances the clock instead of sleeping, so tests are deterministic and take no wall time.

Faults apply to the next replies in order (:meth:`FaultyLink.inject`) or at random with a
seeded generator (:class:`RandomFaults`):

* ``Drop(n)`` — lose ``n`` bytes of the reply (``cr=True``: lose its CR);
* ``Garbage(data, before=True)`` — line noise before (or after) the reply;
* ``Delay(seconds)`` — the reply arrives late (e.g. after the driver's timeout);
* ``Split(parts, gap_s)`` — the reply arrives in pieces across several reads;
* ``Silence()`` — no reply at all;
* ``Vanish(down_s)`` — the port disappears after the command reached the board and comes
  back ``down_s`` later (``None``: until :meth:`FaultyLink.restore`).
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from eddiebot.robot.emulator import FirmwareEmulator
from eddiebot.robot.errors import LinkLost

__all__ = [
    "Delay",
    "Drop",
    "FakeClock",
    "Fault",
    "FaultyLink",
    "Garbage",
    "RandomFaults",
    "Silence",
    "Split",
    "Vanish",
]


class FakeClock:
    """A manual clock in integer nanoseconds (callable, as the driver expects)."""

    def __init__(self, start_ns: int = 0) -> None:
        self.now_ns = start_ns

    def __call__(self) -> int:
        return self.now_ns

    def advance(self, dt_s: float) -> None:
        """Move time forward by ``dt_s`` seconds."""
        self.now_ns += max(0, round(dt_s * 1e9))


@dataclass(frozen=True)
class Drop:
    """Lose ``count`` bytes of the reply (the last ones, or the CR when ``cr``)."""

    count: int = 1
    cr: bool = False


@dataclass(frozen=True)
class Garbage:
    """Insert ``data`` before (or after) the reply."""

    data: bytes = b"\xff\x13#"
    before: bool = True


@dataclass(frozen=True)
class Delay:
    """Deliver the reply ``seconds`` later than normal."""

    seconds: float = 1.0


@dataclass(frozen=True)
class Split:
    """Deliver the reply in ``parts`` pieces, ``gap_s`` apart."""

    parts: int = 3
    gap_s: float = 0.002


@dataclass(frozen=True)
class Silence:
    """The board never answers this command."""


@dataclass(frozen=True)
class Vanish:
    """The port disappears after the command was sent; back after ``down_s`` (None: never)."""

    down_s: float | None = 0.5


Fault = Drop | Garbage | Delay | Split | Silence | Vanish


@dataclass
class RandomFaults:
    """Per-reply fault probabilities for randomised scenarios (seeded, deterministic)."""

    drop: float = 0.0
    garbage: float = 0.0
    delay: float = 0.0
    split: float = 0.0
    silence: float = 0.0
    vanish: float = 0.0
    delay_s: float = 0.5
    vanish_down_s: float = 0.3


class FaultyLink:
    """An emulated board behind a wire that drops, garbles, delays, splits and vanishes."""

    synchronous = False

    def __init__(self, emulator: FirmwareEmulator, clock: FakeClock, *,
                 latency_s: float = 0.001, random_faults: RandomFaults | None = None,
                 seed: int = 0) -> None:
        self.emulator = emulator
        self.clock = clock
        self.latency_ns = round(latency_s * 1e9)
        self.random_faults = random_faults
        self._rng = random.Random(seed)
        self._faults: list[Fault] = []
        self._scheduled: list[tuple[int, bytes]] = []
        self._generation = 0
        self._down_until: int | None = None  # fake-time ns; -1 = until restore()
        self.writes: list[bytes] = []
        self.delivered = bytearray()

    # --- control ---------------------------------------------------------------------------

    def inject(self, *faults: Fault) -> None:
        """Apply ``faults`` to the next replies, one each, in order."""
        self._faults.extend(faults)

    def vanish(self, down_s: float | None = None) -> None:
        """The port disappears now; it returns after ``down_s`` (None: at :meth:`restore`)."""
        self._scheduled.clear()
        self._down_until = -1 if down_s is None else self.clock() + round(down_s * 1e9)

    def restore(self) -> None:
        """The port comes back (the reconnect bumps :attr:`generation`)."""
        if self._down_until is not None:
            self._down_until = None
            self._generation += 1

    @property
    def is_down(self) -> bool:
        """Whether the port is currently gone."""
        self._maybe_return()
        return self._down_until is not None

    def _maybe_return(self) -> None:
        if self._down_until is not None and 0 <= self._down_until <= self.clock():
            self.restore()

    # --- Link protocol ---------------------------------------------------------------------

    @property
    def generation(self) -> int:
        """+1 per (re)connect."""
        self._maybe_return()
        return self._generation

    def open(self) -> None:
        """Connect (first time only)."""
        if self._generation == 0:
            self._generation = 1

    def close(self) -> None:
        """Nothing to release."""

    def write(self, data: bytes) -> None:
        """The board receives ``data``; its reply is scheduled, with the next fault applied."""
        if self.is_down:
            self.clock.advance(0.001)
            raise LinkLost("fault link: port vanished")
        self.writes.append(bytes(data))
        now = self.clock()
        self.emulator.advance_to_ns(now)
        reply = self.emulator.feed(data)
        if not reply:
            return
        fault = self._next_fault()
        t = now + self.latency_ns
        if isinstance(fault, Vanish):
            self.vanish(fault.down_s)
            return
        if isinstance(fault, Silence):
            return
        if isinstance(fault, Drop):
            if fault.cr:
                reply = reply.replace(b"\r", b"", 1)
            else:
                reply = reply[:max(0, len(reply) - 1 - fault.count)] + reply[-1:]
        elif isinstance(fault, Garbage):
            reply = fault.data + reply if fault.before else reply + fault.data
        elif isinstance(fault, Delay):
            t += round(fault.seconds * 1e9)
        if isinstance(fault, Split) and len(reply) > 1:
            parts = max(1, min(fault.parts, len(reply)))
            size = -(-len(reply) // parts)
            for i in range(0, len(reply), size):
                self._scheduled.append((t, reply[i:i + size]))
                t += round(fault.gap_s * 1e9)
        elif reply:
            self._scheduled.append((t, reply))
        self._scheduled.sort(key=lambda item: item[0])

    def _next_fault(self) -> Fault | None:
        if self._faults:
            return self._faults.pop(0)
        rf = self.random_faults
        if rf is None:
            return None
        r = self._rng.random()
        for p, fault in ((rf.drop, Drop(self._rng.randint(1, 4), cr=self._rng.random() < 0.5)),
                         (rf.garbage, Garbage(bytes(self._rng.randrange(256)
                                                    for _ in range(self._rng.randint(1, 6))),
                                              before=self._rng.random() < 0.5)),
                         (rf.delay, Delay(rf.delay_s)),
                         (rf.split, Split(self._rng.randint(2, 5))),
                         (rf.silence, Silence()),
                         (rf.vanish, Vanish(rf.vanish_down_s))):
            if r < p:
                return fault
            r -= p
        return None

    def read(self, max_wait_s: float) -> bytes:
        """Deliver what is due; advance the fake clock (up to ``max_wait_s``) if nothing is."""
        if self.is_down:
            self.clock.advance(max_wait_s)
            raise LinkLost("fault link: port vanished")
        now = self.clock()
        if not self._scheduled or self._scheduled[0][0] > now:
            limit = now + round(max_wait_s * 1e9)
            if self._scheduled and self._scheduled[0][0] <= limit:
                self.clock.now_ns = self._scheduled[0][0]
            else:
                self.clock.now_ns = limit
                return b""
        now = self.clock()
        out = bytearray()
        while self._scheduled and self._scheduled[0][0] <= now:
            out += self._scheduled.pop(0)[1]
        self.delivered += out
        return bytes(out)

    def discard_input(self) -> None:
        """Drop what is due now (bytes still on the wire keep coming)."""
        now = self.clock()
        self._scheduled = [item for item in self._scheduled if item[0] > now]
