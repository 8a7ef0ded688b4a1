"""The dashboard's status layers: battery, velocity, collisions, the e-stop lock, the
``/rosout`` log, and the velocity source that holds ``cmd_vel``.

The source is worked out as twist_mux does, from the mux's own parameters (read from the
running ``twist_mux`` node, twist_mux's defaults until it answers) and the commands and
locks seen on its input topics.
"""

from __future__ import annotations

import functools
from collections import deque
from typing import Any

from eddiebot.base.twist_mux import DEFAULT_LOCKS, DEFAULT_TOPICS, MuxInput, TwistMux
from eddiebot.core.errors import TopicTypeMismatchError
from eddiebot.core.param_services import ParameterClient
from eddiebot.core.parameters import value_from_msg
from eddiebot.core.task import Future
from eddiebot.viz.dashboard.core import text_frame
from eddiebot.viz.dashboard.display import DisplayNode, _r

__all__ = ["StatusLayers"]


class StatusLayers(DisplayNode):
    """Status values, the log and twist_mux's active source."""

    _status: dict[str, Any]
    _logs: deque[dict[str, Any]]
    _logs_dirty: bool
    _estop: bool
    _mux: TwistMux
    _mux_source: str
    _mux_subs: dict[str, Any]
    _mux_params: ParameterClient | None
    _mux_query: Future | None

    def _on_battery(self, msg: Any) -> None:
        self._status["battery"] = _r(msg.value, 3)

    def _on_odom(self, msg: Any) -> None:
        self._status["linear"] = _r(msg.twist.twist.linear.x, 3)
        self._status["angular"] = _r(msg.twist.twist.angular.z, 3)

    def _on_collisions(self, msg: Any) -> None:
        self._status["collisions"] = int(msg.data)

    def _on_log(self, msg: Any) -> None:
        self._logs.append({"level": int(msg.level), "name": str(msg.name), "msg": str(msg.msg)[:500],
                           "sec": int(msg.stamp.sec)})
        self._logs_dirty = True

    def _on_estop(self, msg: Any) -> None:
        locked = bool(msg.data)
        if locked != self._estop:
            self._estop = locked
            self.hub.post("estop", text_frame("estop", locked=locked))

    @staticmethod
    def _mux_inputs(params: dict[str, Any] | None) -> tuple[list[MuxInput], list[MuxInput]]:
        """twist_mux's sources and locks from its parameters (its defaults when None)."""
        out: list[list[MuxInput]] = []
        for group, defaults in (("topics", DEFAULT_TOPICS), ("locks", DEFAULT_LOCKS)):
            if params is None:
                table = {n: (t, to, pr) for n, (t, to, pr) in defaults.items()}
            else:
                names = sorted({k.split(".")[1] for k in params
                                if k.startswith(f"{group}.") and k.count(".") == 2})
                table = {n: (str(params.get(f"{group}.{n}.topic") or ""),
                             float(params.get(f"{group}.{n}.timeout") or 0.0),
                             int(params.get(f"{group}.{n}.priority") or 0)) for n in names}
            out.append([MuxInput(n, t, round(to * 1e9), pr) for n, (t, to, pr) in table.items() if t])
        return out[0], out[1]

    def _mux_topic(self, topic: str) -> str:
        if topic.startswith("/"):
            return topic
        ns = self.topics.twist_mux.rsplit("/", 1)[0]
        return f"{ns}/{topic}"

    def _subscribe_mux(self) -> None:
        for sub in self._mux_subs.values():
            self.destroy_subscription(sub)
        self._mux_subs.clear()
        for src in [*self._mux.sources, *self._mux.locks]:
            is_lock = src in self._mux.locks
            cls = self._bool_cls if is_lock else self._twist_cls

            def cb(m: Any, src: MuxInput = src, is_lock: bool = is_lock) -> None:
                src.last_ns = self._wall.now_ns()
                src.value = bool(m.data) if is_lock else m

            topic = self._mux_topic(src.topic)
            try:
                self._mux_subs[f"{src.name}:{topic}"] = self.create_subscription(cls, topic, cb, 10)
            except TopicTypeMismatchError as exc:
                self._problems[topic] = str(exc)

    def _poll_mux_params(self) -> None:
        """Read the running twist_mux's table once (it is read-only there)."""
        client = self._mux_params
        if client is None or self._mux_query is not None or not client.services_are_ready():
            return
        def got_values(names: list[str], f: Future) -> None:
            if f.exception() is not None:
                self._mux_query = None
                return
            params = {n: value_from_msg(v) for n, v in zip(names, f.result().values, strict=False)}
            sources, locks = self._mux_inputs(params)
            if sources:
                self._mux = TwistMux(sources, locks)
                self._mux_source = f"{self.topics.twist_mux} parameters"
                self._subscribe_mux()
            self._mux_params = None

        def got_names(f: Future) -> None:
            if f.exception() is not None or client is None:
                self._mux_query = None
                return
            names = [n for n in f.result().result.names if n.count(".") == 2]
            self._mux_query = client.get_parameters_async(names)
            self._mux_query.add_done_callback(functools.partial(got_values, names))

        self._mux_query = client.list_parameters_async(["topics", "locks"])
        self._mux_query.add_done_callback(got_names)

    def mux_state(self, now_ns: int) -> dict[str, Any]:
        """Which source drives ``cmd_vel`` now (twist_mux's rule), and which locks hold."""
        chosen = self._mux.select(now_ns)
        locks = [lk.name for lk in self._mux.locks
                 if bool(lk.value) or (lk.timeout_ns > 0 and (
                     lk.last_ns is None or now_ns - lk.last_ns > lk.timeout_ns))]
        return {"active": None if chosen is None else chosen.name,
                "topic": None if chosen is None else self._mux_topic(chosen.topic),
                "locks": locks, "table": self._mux_source}
