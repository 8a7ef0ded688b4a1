"""The board node's ``/diagnostics`` status: one level and message, and the values a person
debugging the base reads (link, firmware, poll rate, timeouts, stops, battery, veto)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from eddiebot.base.board_health import diagnostic_array
from eddiebot.msgs.diagnostic_msgs import DiagnosticStatus

if TYPE_CHECKING:
    from eddiebot.base.board_node import BoardNode

__all__ = ["board_diagnostics"]


def board_diagnostics(node: BoardNode, now_ns: int) -> Any:
    """``node``'s state at ``now_ns`` as a DiagnosticArray: the worst condition first (no
    board, e-stop, battery cut-off, an unconfirmed stop, low battery), else OK."""
    if not node.connected:
        level, message = DiagnosticStatus.ERROR, "board not answering"
    elif node._estop:
        level, message = DiagnosticStatus.WARN, "e-stop engaged"
    elif node._battery_low:
        level, message = DiagnosticStatus.ERROR, "battery below cut-off"
    elif node.stops.owed:
        level, message = DiagnosticStatus.ERROR, "stop not yet confirmed"
    elif node._battery_v < node.battery_warning_v:
        level, message = DiagnosticStatus.WARN, "battery low"
    else:
        level, message = DiagnosticStatus.OK, "ok"
    version = node.board.firmware_version
    values = {
        "link": "connected" if node.connected else "down",
        "firmware": node._profile.name if node._profile else "unknown",
        "version word": f"{version:04X}" if version is not None else "unknown",
        "poll rate achieved (Hz)": f"{node.achieved_poll_rate():.1f}",
        "poll rate set (Hz)": f"{node.poll_rate:g}",
        "timeouts": str(node._stats["timeouts"]),
        "link losses": str(node._stats["link_lost"]),
        "stops sent": str(node._stats["stops"]),
        "vetoes": str(node._stats["vetoes"]),
        "battery (V)": f"{node._battery_v:.2f}",
        "motion": node._motion.value,
        "stop": node.stops.describe(),
        "e-stop": str(node._estop).lower(),
        "veto": str(bool(node.veto.vetoed_at(now_ns))).lower(),
        "last events": " | ".join(node._events[-3:]),
    }
    return diagnostic_array(f"{node.get_name()}: control board", node.port, level, message,
                            values, now_ns)
