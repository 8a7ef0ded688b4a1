"""A bridge between our graph and a DDS domain, as a ROS 2 node on ``rmw_cyclonedds`` sees it.

``DdsBridge(context, transport, config)`` joins a DDS domain with Cyclone DDS (the
``cyclonedds`` package, whose wheel carries the C library) and mirrors both ways:

- topics (:mod:`.topics`) as ROS 2 puts them on DDS (:mod:`.types`): ``/odom`` is ``rt/odom``
  of type ``nav_msgs::msg::dds_::Odometry_``; payloads pass as raw CDR, never re-serialized;
  QoS (reliability, durability, history, depth, deadline, lifespan, liveliness and its
  lease) mapped both ways; endpoints carry ``typehash=RIHS01_<hex>;`` and the participant
  ``enclave=/;`` in USER_DATA, as Jazzy does; a type we do not ship is bridged when an
  interface file on ``EDDIE_INTERFACE_PATH`` / ``AMENT_PREFIX_PATH`` describes it;
- services (:mod:`.services`) as ``rq/<name>Request`` / ``rr/<name>Reply`` with
  rmw_cyclonedds's ``{uint64 guid; int64 seq}`` request header, both ways: ours served to
  DDS clients, servers on DDS called by our clients. A server on Fast DDS, which correlates
  in RTPS inline QoS that Cyclone cannot write, answers our calls with one line saying so;
- the ROS graph (:mod:`.discovery`): the bridge publishes ``ros_discovery_info`` with our
  nodes and, under each, the bridge's DDS readers and writers that carry its topics, so
  ``ros2 node list`` shows our nodes; other participants' ``ros_discovery_info`` and DDS
  endpoints become liveliness tokens on our graph (:mod:`.zenoh_side`), so ``eddie node
  list`` / ``eddie topic list`` show theirs, each endpoint under its own node;
- routes follow discovery on both sides (a route goes when its last endpoint goes), one per
  (name, type, direction); no loops: the bridge's DDS readers ignore its own writers
  (``IgnoreLocal``), its Zenoh subscribers its own publishers (``Locality.REMOTE``), and
  neither side's discovery counts the bridge's own endpoints or tokens.

Network: loopback only unless ``network="lan"`` (``EDDIE_NETWORK=lan``), as Jazzy's
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` does for Cyclone (the loopback interface, SPDP
multicast on it and unicast to localhost). A ROS 2 node on the same machine therefore meets a
loopback bridge when it runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (or
``CYCLONEDDS_URI`` naming the loopback interface); with its default range use ``lan``.
"""

from __future__ import annotations

from eddiebot.transport.dds.bridge import DIRECTIONS, DdsBridge, DdsBridgeConfig, Route
from eddiebot.transport.dds.discovery import DdsDiscovery, DdsEndpoint, DdsNode
from eddiebot.transport.dds.types import (
    cyclone_config,
    dds_qos,
    dds_topic_name,
    idl_type,
    qos_from_dds,
    ros_topic_name,
    service_names,
    vendor_of,
)

__all__ = [
    "DIRECTIONS",
    "DdsBridge",
    "DdsBridgeConfig",
    "DdsDiscovery",
    "DdsEndpoint",
    "DdsNode",
    "Route",
    "cyclone_config",
    "dds_qos",
    "dds_topic_name",
    "idl_type",
    "qos_from_dds",
    "ros_topic_name",
    "service_names",
    "vendor_of",
]
