"""The DDS graph as a ROS 2 node on rmw_cyclonedds / rmw_fastrtps sees it.

Endpoints come from DDS's built-in discovery topics (DCPSParticipant, DCPSPublication,
DCPSSubscription); nodes from ``ros_discovery_info`` (``rmw_dds_common/msg/
ParticipantEntitiesInfo``), where every ROS 2 participant publishes its GID and, per node,
the GIDs of the node's readers and writers (a DDS GUID is a GID: its 16 bytes as they are).
The bridge publishes its own participant's sample the same way, with our graph's nodes and
the bridge's DDS endpoints that stand in for them, so ``ros2 node list`` shows our nodes.

The topic, its type and QoS are rmw_cyclonedds's: ``ros_discovery_info`` (no ``rt/``
prefix), reliable, transient-local; the writer keeps the last sample, the reader all.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

from eddiebot.core.qos import DurabilityPolicy, HistoryPolicy, QoSProfile
from eddiebot.transport.dds.types import dds_qos, dds_type, type_hash_of, vendor_of

__all__ = ["DISCOVERY_TOPIC", "DISCOVERY_TYPE", "DdsDiscovery", "DdsEndpoint", "DdsNode"]

log = logging.getLogger("eddiebot.transport.dds")

DISCOVERY_TOPIC = "ros_discovery_info"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
_WRITER_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
_READER_QOS = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         history=HistoryPolicy.KEEP_ALL)


@dataclass(frozen=True)
class DdsEndpoint:
    """A reader or writer of another participant: its GUID and its participant's (16 bytes
    each), DDS topic and type names, ``Qos``, and the vendor of the DDS implementation."""

    guid: bytes
    participant: bytes
    topic: str
    type_name: str
    qos: Any
    vendor: str


@dataclass(frozen=True)
class DdsNode:
    """A ROS node of another participant, as its ``ros_discovery_info`` sample lists it."""

    participant: bytes
    namespace: str
    name: str
    readers: frozenset[bytes]
    writers: frozenset[bytes]

    @property
    def owner_id(self) -> str:
        """Identifies the node across discovery passes (for its token's node id)."""
        return f"{self.participant.hex()}{self.namespace}/{self.name}"


class DdsDiscovery:
    """Built-in topic readers and the ``ros_discovery_info`` writer and reader of the
    bridge's ``participant``; :meth:`poll` takes what arrived, the other methods read the
    resulting view (the bridge's own participant left out)."""

    def __init__(self, participant: Any, publisher: Any, subscriber: Any) -> None:
        from cyclonedds.builtin import (
            BuiltinDataReader,
            BuiltinTopicDcpsParticipant,
            BuiltinTopicDcpsPublication,
            BuiltinTopicDcpsSubscription,
        )
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic

        self.own = participant.guid.bytes
        self._participant_reader = BuiltinDataReader(participant, BuiltinTopicDcpsParticipant)
        self._pub_reader = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
        self._sub_reader = BuiltinDataReader(participant, BuiltinTopicDcpsSubscription)
        topic = Topic(participant, DISCOVERY_TOPIC, dds_type(DISCOVERY_TYPE))
        user_data = f"typehash={type_hash_of(DISCOVERY_TYPE)};".encode()
        self._info_writer = DataWriter(publisher, topic, qos=dds_qos(_WRITER_QOS, user_data))
        self._info_reader = DataReader(subscriber, topic, qos=dds_qos(_READER_QOS, user_data))
        self._topic = topic
        self._participants: set[bytes] = set()
        self._pubs: dict[bytes, DdsEndpoint] = {}
        self._subs: dict[bytes, DdsEndpoint] = {}
        self._infos: dict[bytes, tuple[DdsNode, ...]] = {}
        self._announced: Any = None
        self.gids = {"writer": self._info_writer.guid.bytes,
                     "reader": self._info_reader.guid.bytes}

    # -- reading ------------------------------------------------------------------------
    def poll(self) -> None:
        from cyclonedds.core import InstanceState

        for sample in self._participant_reader.take(N=256):
            key = sample.key.bytes
            if sample.sample_info.instance_state == InstanceState.Alive:
                if key != self.own:
                    self._participants.add(key)
            else:
                self._participants.discard(key)
                self._infos.pop(key, None)
        for reader, table in ((self._pub_reader, self._pubs), (self._sub_reader, self._subs)):
            for sample in reader.take(N=256):
                key = sample.key.bytes
                if sample.sample_info.instance_state != InstanceState.Alive:
                    table.pop(key, None)
                    continue
                participant = sample.participant_key.bytes
                if participant == self.own:
                    continue
                table[key] = DdsEndpoint(key, participant, sample.topic_name or "",
                                         sample.type_name or "", sample.qos, vendor_of(key))
        self._read_infos()

    def _read_infos(self) -> None:
        from cyclonedds._clayer import ddspy_take
        from cyclonedds.core import InstanceState, SampleState, ViewState

        from eddiebot.msgs import deserialize

        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        while True:
            got = ddspy_take(self._info_reader._ref, mask, 64)
            if isinstance(got, int) or not got:
                return
            for data, info in got:
                if not info.valid_data:
                    continue
                try:
                    msg = deserialize(bytes(data), DISCOVERY_TYPE)
                except Exception as exc:  # a Gid of another size (Humble) and the like
                    log.debug("unreadable ros_discovery_info sample: %s", exc)
                    continue
                participant = bytes(msg.gid.data)
                if participant == self.own:
                    continue
                self._infos[participant] = tuple(
                    DdsNode(participant, n.node_namespace or "/", n.node_name,
                            frozenset(bytes(g.data) for g in n.reader_gid_seq),
                            frozenset(bytes(g.data) for g in n.writer_gid_seq))
                    for n in msg.node_entities_info_seq if n.node_name)
            if len(got) < 64:
                return

    def publications(self) -> list[DdsEndpoint]:
        return [e for e in self._pubs.values() if e.participant in self._participants]

    def subscriptions(self) -> list[DdsEndpoint]:
        return [e for e in self._subs.values() if e.participant in self._participants]

    def nodes(self) -> list[DdsNode]:
        """ROS nodes of the other participants still alive."""
        return [n for p, nodes in self._infos.items() if p in self._participants for n in nodes]

    def participants(self) -> set[bytes]:
        return set(self._participants)

    # -- writing ------------------------------------------------------------------------
    def announce(self, nodes: list[tuple[str, str, list[bytes], list[bytes]]]) -> bool:
        """Publish the bridge's ``ParticipantEntitiesInfo``: ``nodes`` as (namespace, name,
        reader GIDs, writer GIDs); nothing when it is what was last published. True when a
        sample went out."""
        from cyclonedds._clayer import ddspy_write

        from eddiebot.msgs import get_message, serialize
        from eddiebot.transport.dds.types import padded

        wanted = tuple(sorted((ns, name, tuple(sorted(r)), tuple(sorted(w)))
                              for ns, name, r, w in nodes))
        if wanted == self._announced:
            return False
        import numpy as np

        gid_t = get_message("rmw_dds_common/msg/Gid")
        node_t = get_message("rmw_dds_common/msg/NodeEntitiesInfo")
        info_t = get_message(DISCOVERY_TYPE)

        def gid(raw: bytes) -> Any:
            return gid_t(data=np.frombuffer(raw.ljust(16, b"\0")[:16], dtype=np.uint8).copy())

        msg = info_t(gid=gid(self.own), node_entities_info_seq=[
            node_t(node_namespace=ns, node_name=name, reader_gid_seq=[gid(g) for g in r],
                   writer_gid_seq=[gid(g) for g in w]) for ns, name, r, w in wanted])
        if ddspy_write(self._info_writer._ref, padded(serialize(msg, DISCOVERY_TYPE))) < 0:
            log.warning("could not publish ros_discovery_info")
            return False
        self._announced = wanted
        return True
