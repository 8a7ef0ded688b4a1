"""How long Eddie's serial link takes: a pure model of the wire between host and board.

A request goes host → USB → FTDI FT232R → 115,200 baud UART → Propeller; the reply comes
back the same way.  The figures and where they come from:

* ``baud`` 115,200, 8N1 — 10 bits a byte, 86.8 µs (CS11 p3; FW ``BAUDRATE``).
* ``usb_frame_s`` 1 ms — a full-speed USB device gets host → device bulk data in the next
  1 ms frame, before the FTDI chip starts shifting it out on the UART.
* ``ping_block_s`` 25 ms — FW ``ProcessPings`` triggers the PING))) sensors and then waits
  ``waitcnt(clkfreq / 40)`` before it reads the echo widths; the command loop (one cog)
  does nothing else meanwhile, so later commands wait too.  Other commands take
  microseconds of Spin time and are not modelled.
* ``ftdi_latency_s`` 16 ms — the FT232R's latency timer as the Linux ``ftdi_sio`` driver
  ships it (``/sys/bus/usb-serial/devices/ttyUSB*/latency_timer`` = 16).  The chip holds
  device → host bytes in its buffer and sends them to the host when the timer expires or
  when a 64-byte USB packet (62 data bytes plus 2 status bytes) is full.  A reply shorter
  than 62 bytes therefore sits in the chip until the timer expires; the model charges the
  whole 16 ms after its last byte (the timer runs freely, so a real reply may flush earlier,
  but request/reply traffic on an idle link is commonly measured at the full latency).  A
  reply of 62 bytes or more goes out in full packets as they fill; only a tail that does not
  fill a packet (``len % 62``) waits for the timer.
* ``boot_s`` 1.5 s — a DTR reset (Linux raises DTR when the port is opened) restarts the
  Propeller: a 50 ms reset delay, the boot loader listening for a host on P30/P31, then the
  32 KB image loaded from the EEPROM on the internal RC clock.  The P8X32A datasheet's
  start-up current profile (§8.6) puts booting from EEPROM at about 1.3-1.5 s; the firmware
  starts its UART first thing in ``Main``, so it answers right after.  Bytes sent before
  then are lost.

:func:`reply_delay_s` adds these up for one request on an idle link;
:class:`~eddiebot.robot.pty_server.PtyServer` uses the parts to hold each reply until it
would be readable on the host.  :data:`NO_TIMING` (all zero) turns the model off.
"""

from __future__ import annotations

from dataclasses import dataclass

from eddiebot.robot.constants import BAUD_RATE

__all__ = [
    "BITS_PER_BYTE",
    "DEFAULT_TIMING",
    "FTDI_PACKET_DATA_BYTES",
    "NO_TIMING",
    "PROPELLER_BOOT_S",
    "LinkTiming",
    "byte_time_s",
    "processing_s",
    "reply_delay_s",
    "reply_transit_s",
    "request_transit_s",
    "usb_hold_s",
]

BITS_PER_BYTE = 10
"""8N1: a start bit, 8 data bits and a stop bit."""
FTDI_PACKET_DATA_BYTES = 62
"""Data bytes in one FT232R → host USB packet (64 bytes less 2 modem-status bytes)."""
PROPELLER_BOOT_S = 1.5
"""DTR reset → firmware answering: P8X32A datasheet §8.6 start-up profile, EEPROM boot."""


@dataclass(frozen=True)
class LinkTiming:
    """Timing of the host ↔ control-board link (seconds; see the module docstring)."""

    baud: int = BAUD_RATE
    ftdi_latency_s: float = 0.016
    usb_frame_s: float = 0.001
    ping_block_s: float = 0.025
    boot_s: float = PROPELLER_BOOT_S


DEFAULT_TIMING = LinkTiming()
"""Eddie's link as shipped: 115,200 baud, FTDI latency timer 16 ms, 1.5 s boot."""

NO_TIMING = LinkTiming(baud=0, ftdi_latency_s=0.0, usb_frame_s=0.0, ping_block_s=0.0,
                       boot_s=0.0)
"""No link delays and an instant boot (``baud=0``: bytes take no time)."""


def byte_time_s(timing: LinkTiming, n_bytes: int) -> float:
    """Seconds ``n_bytes`` take on the UART (10 bits each); 0 when ``timing.baud`` is 0."""
    if timing.baud <= 0:
        return 0.0
    return n_bytes * BITS_PER_BYTE / timing.baud


def usb_hold_s(timing: LinkTiming, n_bytes: int) -> float:
    """How long the FTDI chip holds the end of an ``n_bytes`` reply after its last byte.

    The latency timer unless the reply ends exactly on a full 62-byte packet.
    """
    if n_bytes <= 0 or n_bytes % FTDI_PACKET_DATA_BYTES == 0:
        return 0.0
    return timing.ftdi_latency_s


def request_transit_s(timing: LinkTiming, n_bytes: int) -> float:
    """Host write → last request byte received by the board: one USB frame + the UART."""
    return timing.usb_frame_s + byte_time_s(timing, n_bytes)


def processing_s(timing: LinkTiming, command: str, reply: bytes) -> float:
    """Time the firmware spends on ``command`` before it starts sending ``reply``.

    Only a ``PING`` that measures something blocks (``ping_block_s``); a ``PING`` answered
    with ``ERROR`` (bad parameters) or with nothing (no sensor enabled) returns at once.
    """
    if command.upper() != "PING":
        return 0.0
    text = reply.split(b"\r", 1)[0].split(b"\x00", 1)[0]
    if not text.strip() or text.startswith(b"ERROR"):
        return 0.0
    return timing.ping_block_s


def reply_transit_s(timing: LinkTiming, n_bytes: int) -> float:
    """Board starts sending an ``n_bytes`` reply → whole reply readable on the host."""
    return byte_time_s(timing, n_bytes) + usb_hold_s(timing, n_bytes)


def reply_delay_s(timing: LinkTiming, request: bytes, reply: bytes, command: str) -> float:
    """Host writes ``request`` → the whole ``reply`` is readable on the host, idle link.

    One USB frame, the request on the wire, the firmware's processing (``PING`` only), the
    reply on the wire, and the FTDI latency timer (for replies shorter than 62 bytes).
    E.g. ``DIST``: 1 ms + 5 bytes (0.43 ms) + 18 bytes (1.56 ms) + 16 ms ≈ 19.0 ms.
    """
    return (request_transit_s(timing, len(request)) + processing_s(timing, command, reply)
            + reply_transit_s(timing, len(reply)))
