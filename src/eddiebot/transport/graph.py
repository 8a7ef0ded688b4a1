"""What this process knows of the rest of the graph, from liveliness tokens.

Every remote node, publisher, subscription, service and client announces itself with a
liveliness token (``eddiebot.transport.keys``); the cache keeps them by key and answers
the questions the runtime and the CLI ask: which topics exist with which types, who
publishes and subscribes, which services are served.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from eddiebot.transport.keys import GraphEntity

__all__ = ["GraphCache"]


class GraphCache:
    """Remote entities by liveliness key; counts per topic are kept ready for hot paths."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._entities: dict[str, GraphEntity] = {}
        #: topic → remote subscriptions / publishers (replaced, never mutated: lock-free reads)
        self.sub_counts: dict[str, int] = {}
        self.pub_counts: dict[str, int] = {}
        self.version = 0
        self.listeners: list[Callable[[GraphEntity, bool], None]] = []

    def add(self, entity: GraphEntity) -> None:
        with self._cond:
            if entity.key in self._entities:
                return
            self._entities[entity.key] = entity
            self._changed()
        for cb in list(self.listeners):
            cb(entity, True)

    def remove(self, key: str) -> None:
        with self._cond:
            entity = self._entities.pop(key, None)
            if entity is None:
                return
            self._changed()
        for cb in list(self.listeners):
            cb(entity, False)

    def _changed(self) -> None:
        subs: dict[str, int] = {}
        pubs: dict[str, int] = {}
        for e in self._entities.values():
            if e.kind == "MS":
                subs[e.name] = subs.get(e.name, 0) + 1
            elif e.kind == "MP":
                pubs[e.name] = pubs.get(e.name, 0) + 1
        self.sub_counts, self.pub_counts = subs, pubs
        self.version += 1
        self._cond.notify_all()

    # -- queries --------------------------------------------------------------------
    def entities(self, kind: str | None = None, name: str | None = None) -> list[GraphEntity]:
        with self._cond:
            return [
                e for e in self._entities.values()
                if (kind is None or e.kind == kind) and (name is None or e.name == name)
            ]

    def nodes(self) -> list[GraphEntity]:
        return self.entities("NN")

    def publishers(self, topic: str | None = None) -> list[GraphEntity]:
        return self.entities("MP", topic)

    def subscriptions(self, topic: str | None = None) -> list[GraphEntity]:
        return self.entities("MS", topic)

    def services(self, name: str | None = None) -> list[GraphEntity]:
        return self.entities("SS", name)

    def clients(self, name: str | None = None) -> list[GraphEntity]:
        return self.entities("SC", name)

    def has_service(self, name: str) -> bool:
        with self._cond:
            return any(e.kind == "SS" and e.name == name for e in self._entities.values())

    def topic_types(self) -> dict[str, set[str]]:
        """Every topic with a remote publisher or subscription, with its types."""
        out: dict[str, set[str]] = {}
        for e in self.entities():
            if e.kind in ("MP", "MS"):
                out.setdefault(e.name, set()).add(e.type_name)
        return out

    def service_types(self) -> dict[str, set[str]]:
        out: dict[str, set[str]] = {}
        for e in self.entities("SS"):
            out.setdefault(e.name, set()).add(e.type_name)
        return out

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float | None) -> bool:
        """Block until ``predicate()`` holds (re-checked at every graph change)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with self._cond:
            while not predicate():
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return False
                self._cond.wait(0.1 if remaining is None else min(remaining, 0.1))
            return True
