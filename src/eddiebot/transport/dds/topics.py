"""Topic routes: our publishers → a DDS writer, DDS publications → a Zenoh publisher.

Payloads pass as raw CDR, never re-serialized: our samples' bytes (rosbags' CDR, with its
4-byte encapsulation header) are the DDS samples' serialized data, and the other way round;
the Python layer of ``cyclonedds`` makes the entities, its C layer (``ddspy_write``,
``ddspy_take``) moves the bytes.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

from eddiebot.transport.dds.types import TAKE_BATCH, dds_qos, padded

if TYPE_CHECKING:
    from eddiebot.transport.dds.bridge import DdsBridge, Live, Route

__all__ = ["open_from_dds", "open_to_dds"]

log = logging.getLogger("eddiebot.transport.dds")


def open_to_dds(bridge: DdsBridge, route: Route) -> Live:
    """Our publishers → a DDS writer, fed by a Zenoh subscriber."""
    from cyclonedds._clayer import ddspy_write
    from cyclonedds.pub import DataWriter

    from eddiebot.transport.dds.bridge import Live, delete_entity
    from eddiebot.transport.dds.zenoh_side import undeclare

    writer = DataWriter(bridge.dds_publisher, bridge.topic(route.topic, route.type_name),
                        qos=dds_qos(route.qos, bridge.user_data(route.type_name)))
    ref = writer._ref
    live = Live(route, writers=[writer.guid.bytes])

    def on_sample(cdr: bytes) -> None:
        if bridge.closed:
            return
        ret = ddspy_write(ref, padded(cdr))
        if ret < 0:
            live.stats["failed"] = live.stats.get("failed", 0) + 1
            log.debug("DDS write on %s failed (%d)", route.topic, ret)
        else:
            live.stats["samples"] += 1

    zsub = bridge.zenoh.subscribe(route.topic, route.type_name, route.qos, on_sample)

    def close() -> None:
        undeclare(zsub)
        delete_entity(writer)

    live.close = close
    return live


def open_from_dds(bridge: DdsBridge, route: Route) -> Live:
    """DDS publications → a DDS reader whose samples a Zenoh publisher sends on."""
    from cyclonedds._clayer import ddspy_take
    from cyclonedds.core import InstanceState, Listener, SampleState, ViewState
    from cyclonedds.sub import DataReader

    from eddiebot.transport.dds.bridge import Live, delete_entity

    zpub = bridge.zenoh.publish(route.topic, route.type_name, route.qos)
    live = Live(route)
    mask = SampleState.Any | ViewState.Any | InstanceState.Any
    state: dict[str, Any] = {"ref": None}

    def pump(_reader: Any = None) -> None:
        ref = state["ref"]
        if ref is None or bridge.closed:
            return
        while True:
            got = ddspy_take(ref, mask, TAKE_BATCH)
            if isinstance(got, int) or not got:
                return
            for data, info in got:
                if info.valid_data:
                    zpub.put(bytes(data), info.source_timestamp)
                    live.stats["samples"] += 1
            if len(got) < TAKE_BATCH:
                return

    reader = DataReader(bridge.dds_subscriber, bridge.topic(route.topic, route.type_name),
                        qos=dds_qos(route.qos, bridge.user_data(route.type_name), reader=True),
                        listener=Listener(on_data_available=pump))
    live.readers.append(reader.guid.bytes)
    state["ref"] = reader._ref
    pump()  # samples that arrived before the listener's first call

    def close() -> None:
        state["ref"] = None
        delete_entity(reader)
        zpub.close()

    live.close = close
    return live
