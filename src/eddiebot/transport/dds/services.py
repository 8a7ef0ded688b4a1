"""Service routes, both ways, with rmw_cyclonedds's request correlation.

ROS 2 puts a service ``/x`` of type ``pkg/srv/T`` on DDS as two topics, ``rq/xRequest``
(type ``pkg::srv::dds_::T_Request_``) and ``rr/xReply`` (``…T_Response_``). rmw_cyclonedds
puts the client's ``{uint64 guid; int64 seq}`` between the CDR encapsulation header and the
body of every request; the server copies it into the reply, and a client keeps only the
replies bearing its own guid. Fast DDS (rmw_fastrtps) correlates through the RTPS
``related_sample_identity`` inline QoS instead, which Cyclone DDS can neither read nor
write: a Fast DDS server cannot be called through the bridge, and a call of one from our
graph is answered at once with an error that says so.
"""

from __future__ import annotations

import functools
import logging
import random
import struct
import threading
import time
from typing import TYPE_CHECKING, Any

from eddiebot.transport.dds.types import REQUEST_HEADER_SIZE, TAKE_BATCH, dds_qos, padded

if TYPE_CHECKING:
    from eddiebot.transport.dds.bridge import DdsBridge, Live, Route

__all__ = ["open_dds_service", "open_service", "open_unreachable_service"]

log = logging.getLogger("eddiebot.transport.dds")

_HEADER = struct.Struct("<Qq")
#: A call waits at most this long for the bridge's request writer and reply reader to match
#: the DDS server's (a server replies only to a client whose reply reader it has matched).
_MATCH_WAIT_S = 2.0


def _endpoints(bridge: DdsBridge, route: Route, server: bool, listener: Any) -> tuple[Any, Any]:
    """The bridge's (reader, writer): for a server, requests in and replies out; for a
    client, replies in and requests out."""
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader

    from eddiebot.transport.keys import service_type_hash

    name = route.topic.lstrip("/")
    qos = dds_qos(route.qos, f"typehash={service_type_hash(route.type_name)};".encode())
    request = bridge.topic(route.topic, route.type_name + "_Request", f"rq/{name}Request")
    reply = bridge.topic(route.topic, route.type_name + "_Response", f"rr/{name}Reply")
    if server:
        return (DataReader(bridge.dds_subscriber, request, qos=qos, listener=listener),
                DataWriter(bridge.dds_publisher, reply, qos=qos))
    return (DataReader(bridge.dds_subscriber, reply, qos=qos, listener=listener),
            DataWriter(bridge.dds_publisher, request, qos=qos))


def open_service(bridge: DdsBridge, route: Route) -> Live:
    """A service of our graph for ROS 2 clients on rmw_cyclonedds: requests taken from
    ``rq/<name>Request``, called on our graph, answered on ``rr/<name>Reply`` with the
    client's correlation."""
    from cyclonedds._clayer import ddspy_take, ddspy_write
    from cyclonedds.core import InstanceState, Listener, SampleState, ViewState

    from eddiebot.transport.dds.bridge import Live, delete_entity

    live = Live(route)
    mask = SampleState.Any | ViewState.Any | InstanceState.Any
    state: dict[str, Any] = {"ref": None, "writer": None}
    call = bridge.zenoh.caller(route.topic, route.type_name)

    def answer(correlation: bytes, reply: bytes) -> None:
        if bridge.closed or len(reply) < 4:
            return
        ref = state["writer"]
        if ref is None or ddspy_write(ref, padded(reply[:4] + correlation + reply[4:])) < 0:
            log.warning("could not send a reply of %s to its DDS client", route.topic)
        else:
            live.stats["samples"] += 1

    def on_request(_reader: Any = None) -> None:
        ref = state["ref"]
        if ref is None or bridge.closed:
            return
        got = ddspy_take(ref, mask, TAKE_BATCH)
        for data, info in [] if isinstance(got, int) else got:
            raw = bytes(data)
            if not info.valid_data or len(raw) < 4 + REQUEST_HEADER_SIZE:
                continue
            correlation = raw[4:4 + REQUEST_HEADER_SIZE]
            call(raw[:4] + raw[4 + REQUEST_HEADER_SIZE:], functools.partial(answer, correlation))

    reader, writer = _endpoints(bridge, route, True, Listener(on_data_available=on_request))
    live.readers.append(reader.guid.bytes)
    live.writers.append(writer.guid.bytes)
    state["writer"] = writer._ref
    state["ref"] = reader._ref
    on_request()  # requests that arrived before the listener's first call

    def close() -> None:
        state["ref"] = state["writer"] = None
        delete_entity(reader)
        delete_entity(writer)

    live.close = close
    return live


def open_dds_service(bridge: DdsBridge, route: Route) -> Live:
    """A service served on DDS (an rmw_cyclonedds server) for our clients: a queryable on
    our graph whose calls go out on ``rq/<name>Request`` under the bridge's own guid and a
    sequence number, and come back from ``rr/<name>Reply`` matched on both."""
    from cyclonedds._clayer import ddspy_take, ddspy_write
    from cyclonedds.core import InstanceState, Listener, SampleState, ViewState

    from eddiebot.transport.dds.bridge import Live, delete_entity
    from eddiebot.transport.dds.zenoh_side import PendingCalls, finalize, reply_error, undeclare
    from eddiebot.transport.keys import ATTACHMENT

    live = Live(route)
    # rmw_cyclonedds uses the request writer's instance handle; any value unique among the
    # server's clients does, as long as the replies carry it back
    guid = random.getrandbits(63) | 1
    pending = PendingCalls()
    live.pending = pending
    mask = SampleState.Any | ViewState.Any | InstanceState.Any
    state: dict[str, Any] = {"ref": None}
    matched = threading.Event()

    def on_reply(_reader: Any = None) -> None:
        ref = state["ref"]
        if ref is None or bridge.closed:
            return
        got = ddspy_take(ref, mask, TAKE_BATCH)
        for data, info in [] if isinstance(got, int) else got:
            raw = bytes(data)
            if not info.valid_data or len(raw) < 4 + REQUEST_HEADER_SIZE:
                continue
            their_guid, seq = _HEADER.unpack_from(raw, 4)
            if their_guid != guid:
                continue  # another client's reply
            call = pending.pop(seq)
            if call is None:
                continue
            query, attachment = call
            try:
                if attachment is not None and len(attachment) >= ATTACHMENT.size:
                    seq_no, _ts, n, gid = ATTACHMENT.unpack_from(attachment)
                    attachment = ATTACHMENT.pack(
                        seq_no, bridge.transport.context.system_clock.now_ns(), n, gid)
                query.reply(query.key_expr, raw[:4] + raw[4 + REQUEST_HEADER_SIZE:],
                            attachment=attachment)
                live.stats["samples"] += 1
            except Exception as exc:
                log.warning("could not pass a reply of %s on: %s", route.topic, exc)
            finally:
                finalize(query)

    def ready() -> bool:
        if not matched.is_set() and (
                writer.get_publication_matched_status().current_count > 0
                and reader.get_subscription_matched_status().current_count > 0):
            matched.set()
        return matched.is_set()

    def on_query(query: Any) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        att = query.attachment.to_bytes() if query.attachment is not None else None
        if len(payload) < 4:
            reply_error(query, f"bad request for {route.topic}: no CDR header")
            return
        deadline = time.monotonic() + _MATCH_WAIT_S
        while not ready() and time.monotonic() < deadline and not bridge.closed:
            time.sleep(0.01)
        if not ready():
            reply_error(query, f"service {route.topic} on DDS did not match the bridge's "
                               f"client within {_MATCH_WAIT_S:g} s")
            return
        seq = pending.add(query, att, time.monotonic())
        body = payload[:4] + _HEADER.pack(guid, seq) + payload[4:]
        if ddspy_write(writer_ref, padded(body)) < 0 and pending.pop(seq) is not None:
            reply_error(query, f"could not send the request of {route.topic} on DDS")

    reader, writer = _endpoints(bridge, route, False, Listener(on_data_available=on_reply))
    writer_ref = writer._ref
    live.readers.append(reader.guid.bytes)
    live.writers.append(writer.guid.bytes)
    state["ref"] = reader._ref
    queryable = bridge.zenoh.serve(route.topic, route.type_name, on_query)

    def close() -> None:
        undeclare(queryable)
        state["ref"] = None
        pending.close()
        delete_entity(reader)
        delete_entity(writer)

    live.close = close
    return live


def open_unreachable_service(bridge: DdsBridge, route: Route) -> Live:
    """A service served only by Fast DDS participants: a queryable that answers every call
    at once with the reason it cannot be made."""
    from eddiebot.transport.dds.bridge import Live
    from eddiebot.transport.dds.zenoh_side import reply_error, undeclare

    reason = (f"service {route.topic} is served on DDS by {route.vendor}, which correlates "
              "requests in RTPS inline QoS that Cyclone DDS cannot write; call it from a "
              "ROS 2 node on the same middleware, or run its server on rmw_cyclonedds")
    live = Live(route)

    def on_query(query: Any) -> None:
        live.stats["samples"] += 1
        reply_error(query, reason)

    queryable = bridge.zenoh.serve(route.topic, route.type_name, on_query)
    live.close = lambda: undeclare(queryable)
    return live
