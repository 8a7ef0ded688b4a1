"""The Zenoh side of the bridge: raw-CDR publishers, subscribers, callers and queryables on
the transport's session, and the liveliness tokens that show the DDS graph on ours.

The transport's own publishers serialize messages; the bridge passes bytes through, so it
declares its Zenoh endpoints itself (same keys, QoS and attachment as the transport). Data
endpoints carry no token of their own: the graph a ROS tool sees is the DDS one, mirrored
by :class:`GraphTokens` (a DDS node is a node of ours, its writers are publishers of ours).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from eddiebot.core.qos import QoSProfile, ReliabilityPolicy
from eddiebot.transport.keys import (
    encode_attachment,
    entity_gid,
    liveliness_key,
    node_liveliness_key,
    topic_key,
)

if TYPE_CHECKING:
    from eddiebot.transport.zenoh import ZenohTransport

__all__ = ["GraphTokens", "TokenSpec", "ZenohSide", "undeclare"]

log = logging.getLogger("eddiebot.transport.dds")

#: A bridged call that the DDS side has not answered in this long is dropped (our client has
#: timed out long before).
CALL_EXPIRY_S = 120.0


class ZenohSide:
    """Raw-CDR endpoints on ``transport``'s session (remote traffic only: the bridge never
    hears what it sends itself)."""

    def __init__(self, transport: ZenohTransport) -> None:
        self.transport = transport
        self.session = transport.session

    def publish(self, topic: str, type_name: str, qos: QoSProfile) -> ZenohPublisher:
        import zenoh

        key = topic_key(self.transport.domain, topic, type_name)
        reliable = qos.reliability != ReliabilityPolicy.BEST_EFFORT
        rel = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        cc = zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP
        if qos.transient_local:
            import zenoh.ext as zext

            zpub = zext.declare_advanced_publisher(
                self.session, key, congestion_control=cc, reliability=rel,
                cache=zext.CacheConfig(max_samples=max(1, qos.depth)),
                publisher_detection=True, allowed_destination=zenoh.Locality.REMOTE,
            )
        else:
            zpub = self.session.declare_publisher(
                key, congestion_control=cc, reliability=rel,
                allowed_destination=zenoh.Locality.REMOTE,
            )
        gid = entity_gid(f"{self.transport.zid}/dds-bridge/{key}")
        return ZenohPublisher(zpub, gid, self.transport)

    def subscribe(self, topic: str, type_name: str, qos: QoSProfile,
                  on_sample: Callable[[bytes], None]) -> Any:
        import zenoh

        key = topic_key(self.transport.domain, topic, type_name)

        def handler(sample: Any) -> None:
            try:
                on_sample(sample.payload.to_bytes())
            except Exception:
                log.exception("dropping a sample of %s on its way to DDS", topic)

        if qos.transient_local:
            import zenoh.ext as zext

            return zext.declare_advanced_subscriber(
                self.session, key, handler, allowed_origin=zenoh.Locality.REMOTE,
                history=zext.HistoryConfig(detect_late_publishers=True,
                                           max_samples=max(1, qos.depth)),
            )
        return self.session.declare_subscriber(key, handler, allowed_origin=zenoh.Locality.REMOTE)

    def serve(self, name: str, srv_type: str, on_query: Callable[[Any], None]) -> Any:
        """A queryable answering calls of the service ``name`` from our graph."""
        import zenoh

        key = topic_key(self.transport.domain, name, srv_type, service=True)

        def handler(query: Any) -> None:
            try:
                on_query(query)
            except Exception as exc:
                log.exception("passing a call of %s to DDS", name)
                reply_error(query, f"the DDS bridge could not pass the call on: {exc}")

        return self.session.declare_queryable(key, handler, complete=True,
                                              allowed_origin=zenoh.Locality.REMOTE)

    def caller(self, name: str, srv_type: str) -> Callable[[bytes, Callable[[bytes], None]], None]:
        """``call(request_cdr, on_reply)``: a raw call of the service ``name`` (a Zenoh get
        on its queryable); ``on_reply`` gets the response's CDR, nothing on an error."""
        import zenoh

        key = topic_key(self.transport.domain, name, srv_type, service=True)
        gid = entity_gid(f"{self.transport.zid}/dds-bridge/{name}")
        clock = self.transport.context.system_clock
        seq = [0]

        def call(request: bytes, on_reply: Callable[[bytes], None]) -> None:
            seq[0] += 1

            def handle(reply: Any) -> None:
                try:
                    if reply.ok is not None:
                        on_reply(reply.ok.payload.to_bytes())
                    else:
                        log.warning("service %s answered a DDS client with an error: %s",
                                    name, reply.err.payload.to_string())
                except Exception:
                    log.exception("passing a reply of %s to DDS", name)

            self.session.get(key, handle, payload=request,
                             attachment=encode_attachment(seq[0], clock.now_ns(), gid),
                             target=zenoh.QueryTarget.ALL_COMPLETE, timeout=60.0)

        return call


def reply_error(query: Any, text: str) -> None:
    """Answer ``query`` with an error (our clients raise it at once) and finalize it."""
    try:
        query.reply_err(text)
    except Exception as exc:
        log.debug("could not send an error reply: %s", exc)
    finally:
        finalize(query)


def finalize(query: Any) -> None:
    try:
        query.drop()
    except Exception:
        pass


class ZenohPublisher:
    def __init__(self, zpub: Any, gid: bytes, transport: ZenohTransport) -> None:
        self._zpub, self._gid = zpub, gid
        self._clock = transport.context.system_clock
        self._seq = 0

    def put(self, cdr: bytes, source_timestamp_ns: int | None = None) -> None:
        self._seq += 1
        ts = source_timestamp_ns if source_timestamp_ns and source_timestamp_ns > 0 \
            else self._clock.now_ns()
        try:
            self._zpub.put(cdr, attachment=encode_attachment(self._seq, ts, self._gid))
        except Exception as exc:
            log.debug("zenoh put failed: %s", exc)

    def close(self) -> None:
        undeclare(self._zpub)


# -- the DDS graph as liveliness tokens ------------------------------------------------------
TokenSpec = tuple[str, str, str, str, str, str, "QoSProfile | None", str]
"""(owner id, kind, namespace, node name, name, ROS type, QoS, type hash): one token. The
owner id names the DDS node (its participant GID and name) or the endpoint (its GUID);
kind ``NN`` for a node (name, type, QoS and hash empty), else MP/MS/SS/SC."""


class GraphTokens:
    """Liveliness tokens for DDS nodes and endpoints, declared under the bridge's session
    with node and entity ids of their own (far above the transport's counter), kept in step
    with the wanted set by :meth:`update`."""

    _FIRST_ID = 1 << 40

    def __init__(self, transport: ZenohTransport) -> None:
        self.transport = transport
        self._ids: dict[str, int] = {}
        self._next = self._FIRST_ID
        self._tokens: dict[TokenSpec, Any] = {}

    def alias(self, owner: str, node_id: int) -> None:
        """Tokens whose node owner is ``owner`` go under the existing node ``node_id``."""
        self._ids[owner] = node_id

    def _id(self, owner: str) -> int:
        if owner not in self._ids:
            self._ids[owner], self._next = self._next, self._next + 1
        return self._ids[owner]

    def key(self, spec: TokenSpec, node_owner: str) -> str:
        owner, kind, namespace, node, name, ros_type, qos, type_hash = spec
        t = self.transport
        if kind == "NN":
            return node_liveliness_key(t.domain, t.zid, self._id(owner), namespace, node)
        return liveliness_key(t.domain, t.zid, self._id(node_owner), self._id(owner), kind,
                              namespace, node, name, ros_type, qos, type_hash=type_hash or None)

    def update(self, wanted: dict[TokenSpec, str]) -> None:
        """Declare the tokens of ``wanted`` (spec → owner id of its node) not yet declared,
        undeclare the others."""
        for spec in [s for s in self._tokens if s not in wanted]:
            undeclare(self._tokens.pop(spec))
        liveliness = self.transport.session.liveliness()
        for spec, node_owner in wanted.items():
            if spec in self._tokens:
                continue
            try:
                self._tokens[spec] = liveliness.declare_token(self.key(spec, node_owner))
            except Exception as exc:
                log.debug("cannot announce %s %s: %s", spec[1], spec[4] or spec[3], exc)

    def close(self) -> None:
        for token in self._tokens.values():
            undeclare(token)
        self._tokens.clear()


def undeclare(handle: Any) -> None:
    try:
        handle.undeclare()
    except Exception:
        pass


class PendingCalls:
    """Calls from our graph waiting for their DDS reply, by request sequence number."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seq = 0
        self._calls: dict[int, tuple[Any, bytes | None, float]] = {}

    def add(self, query: Any, attachment: bytes | None, now: float) -> int:
        with self._lock:
            self._seq += 1
            self._calls[self._seq] = (query, attachment, now)
            return self._seq

    def pop(self, seq: int) -> tuple[Any, bytes | None] | None:
        with self._lock:
            got = self._calls.pop(seq, None)
        return None if got is None else (got[0], got[1])

    def expire(self, now: float) -> int:
        with self._lock:
            old = [s for s, (_q, _a, t) in self._calls.items() if now - t > CALL_EXPIRY_S]
            gone = [self._calls.pop(s)[0] for s in old]
        for query in gone:
            finalize(query)
        return len(gone)

    def close(self) -> None:
        with self._lock:
            gone = [q for q, _a, _t in self._calls.values()]
            self._calls.clear()
        for query in gone:
            reply_error(query, "the DDS bridge closed before the DDS service answered")
