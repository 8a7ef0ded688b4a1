"""The explore node's progress for a user interface, and its pause/resume service.

``explore/status`` (diagnostic_msgs/DiagnosticStatus, transient local): ``message`` says what
the node does in a few words; ``values`` (strings, as DiagnosticStatus has them) are
``state`` (waiting, look_around, exploring, returning, done), ``paused``, ``reason`` (why
exploring finished), ``frontiers`` (frontiers the last search found; empty before one),
``abandoned``, ``goals_reached``, ``known_m2`` and ``free_m2`` (the map's known and free
area), ``elapsed_s`` (since exploring began, node clock), ``returned_home`` and
``home_failure``. Published when any of these but the areas and time changes, and once a
second. ``level`` is WARN once done without getting home, else OK.

``explore/resume`` (std_srvs/SetBool): the ``explore/resume`` topic's pause (false) and
resume (true) as a call that answers; refused once exploring is done.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from eddiebot.core.qos import qos_profile_latched

if TYPE_CHECKING:
    from eddiebot.explore.node import ExploreNode

__all__ = ["STATUS_PERIOD_S", "ExploreStatus"]

#: The status is published at least this often (s, node clock).
STATUS_PERIOD_S = 1.0


class ExploreStatus:
    """Publishes ``node``'s status and serves its pause/resume calls."""

    def __init__(self, node: ExploreNode) -> None:
        from eddiebot.msgs.diagnostic_msgs import DiagnosticStatus
        from eddiebot.msgs.std_srvs import SetBool

        self.node = node
        self._pub = node.create_publisher(DiagnosticStatus, "explore/status", qos_profile_latched)
        node.create_service(SetBool, "explore/resume", self._on_call)
        self._last: tuple[Any, ...] | None = None
        self._last_s = -float("inf")

    def _on_call(self, request: Any, response: Any) -> Any:
        from eddiebot.explore.node import ExploreState
        from eddiebot.msgs.std_msgs import Bool

        node = self.node
        if node.state is ExploreState.DONE:
            response.success = False
            response.message = f"exploration finished ({node.finish_reason or 'stopped'})"
            return response
        node._on_resume(Bool(data=bool(request.data)))
        response.success = True
        response.message = "exploring" if request.data else "paused"
        self.tick(force=True)
        return response

    def values(self) -> dict[str, str]:
        """The status values (strings)."""
        node = self.node
        now = node.get_clock().now_ns() / 1e9
        known = free = 0.0
        if node.grid is not None:
            d = node.grid.data
            cell = node.grid.resolution ** 2
            known = float(np.count_nonzero(d >= 0)) * cell
            free = float(np.count_nonzero((d >= 0) & (d <= node.config.free_threshold))) * cell
        started = node.started_s
        home = node.returned_home
        return {
            "state": node.state.value,
            "paused": str(node.paused).lower(),
            "reason": node.finish_reason,
            "frontiers": "" if node.last_search is None else str(len(node.last_search.frontiers)),
            "abandoned": str(len(node.blacklist)),
            "goals_reached": str(sum(g.outcome == "reached" for g in node.goals)),
            "known_m2": f"{known:.2f}",
            "free_m2": f"{free:.2f}",
            "elapsed_s": "" if started is None else f"{max(0.0, now - started):.1f}",
            "returned_home": "" if home is None else str(home).lower(),
            "home_failure": node.home_failure,
        }

    def tick(self, force: bool = False) -> None:
        """Publish when something changed, once a second, or when ``force``d."""
        node = self.node
        now = node.get_clock().now_ns() / 1e9
        key = (node.state, node.paused, node.finish_reason,
               None if node.last_search is None else len(node.last_search.frontiers),
               len(node.blacklist), len(node.goals), node.returned_home)
        if not force and key == self._last and now - self._last_s < STATUS_PERIOD_S:
            return
        self._last, self._last_s = key, now
        self._pub.publish(self.message(self.values()))

    def message(self, values: dict[str, str]) -> Any:
        from eddiebot.msgs.diagnostic_msgs import DiagnosticStatus, KeyValue

        state = values["state"]
        if values["paused"] == "true" and state != "done":
            text = f"paused ({state.replace('_', ' ')})"
        elif state == "exploring":
            text = f"exploring: {values['frontiers'] or '?'} frontiers"
        elif state == "returning":
            text = f"returning home ({values['reason']})"
        elif state == "done":
            home = {"true": ", home", "false": ", not home"}.get(values["returned_home"], "")
            text = f"done: {values['reason']}{home}"
        else:
            text = state.replace("_", " ")
        level = (DiagnosticStatus.WARN if state == "done" and values["returned_home"] == "false"
                 else DiagnosticStatus.OK)
        return DiagnosticStatus(level=level, name=self.node.get_fully_qualified_name(),
                                message=text, hardware_id="",
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])
