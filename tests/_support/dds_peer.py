"""A Cyclone DDS participant that behaves as a ROS 2 node on rmw_cyclonedds, for the DDS
bridge's tests: ``rt/`` names, ``pkg::msg::dds_::Type_`` types written by hand (not by the
bridge), raw CDR serialized with rosbags, ``typehash`` user data, and rmw_cyclonedds's
``{uint64 guid; int64 seq}`` request header on service calls.

Import it after ``pytest.importorskip("cyclonedds")``.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import struct
import tempfile
import time
from collections.abc import Callable, Iterator
from typing import Any

from cyclonedds._clayer import ddspy_take, ddspy_write
from cyclonedds.builtin import (
    BuiltinDataReader,
    BuiltinTopicDcpsParticipant,
    BuiltinTopicDcpsPublication,
)
from cyclonedds.core import InstanceState, SampleState, ViewState
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.idl import make_idl_struct
from cyclonedds.idl import types as idl
from cyclonedds.pub import DataWriter
from cyclonedds.qos import Policy, Qos
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from eddiebot.msgs import TYPESTORE, serialize, type_hash
from eddiebot.transport.dds import cyclone_config

__all__ = ["ANY", "RosPeer", "String_", "Twist_", "private_dds_domain", "wait"]

ANY = SampleState.Any | ViewState.Any | InstanceState.Any

# The types as a ROS 2 node declares them on DDS (written by hand, not by the bridge).
String_ = make_idl_struct("String_", "std_msgs::msg::dds_::String_", {"data": str})
Vector3_ = make_idl_struct("Vector3_", "geometry_msgs::msg::dds_::Vector3_",
                           {"x": idl.float64, "y": idl.float64, "z": idl.float64})
Twist_ = make_idl_struct("Twist_", "geometry_msgs::msg::dds_::Twist_",
                         {"linear": Vector3_, "angular": Vector3_})
Time_ = make_idl_struct("Time_", "builtin_interfaces::msg::dds_::Time_",
                        {"sec": idl.int32, "nanosec": idl.uint32})
Header_ = make_idl_struct("Header_", "std_msgs::msg::dds_::Header_",
                          {"stamp": Time_, "frame_id": str})
Point_ = make_idl_struct("Point_", "geometry_msgs::msg::dds_::Point_",
                         {"x": idl.float64, "y": idl.float64, "z": idl.float64})
Quaternion_ = make_idl_struct("Quaternion_", "geometry_msgs::msg::dds_::Quaternion_",
                              {"x": idl.float64, "y": idl.float64, "z": idl.float64,
                               "w": idl.float64})
Pose_ = make_idl_struct("Pose_", "geometry_msgs::msg::dds_::Pose_",
                        {"position": Point_, "orientation": Quaternion_})
PoseWithCovariance_ = make_idl_struct(
    "PoseWithCovariance_", "geometry_msgs::msg::dds_::PoseWithCovariance_",
    {"pose": Pose_, "covariance": idl.array[idl.float64, 36]})
TwistWithCovariance_ = make_idl_struct(
    "TwistWithCovariance_", "geometry_msgs::msg::dds_::TwistWithCovariance_",
    {"twist": Twist_, "covariance": idl.array[idl.float64, 36]})
Odometry_ = make_idl_struct("Odometry_", "nav_msgs::msg::dds_::Odometry_", {
    "header": Header_, "child_frame_id": str, "pose": PoseWithCovariance_,
    "twist": TwistWithCovariance_})
LaserScan_ = make_idl_struct("LaserScan_", "sensor_msgs::msg::dds_::LaserScan_", {
    "header": Header_, "angle_min": idl.float32, "angle_max": idl.float32,
    "angle_increment": idl.float32, "time_increment": idl.float32, "scan_time": idl.float32,
    "range_min": idl.float32, "range_max": idl.float32,
    "ranges": idl.sequence[idl.float32], "intensities": idl.sequence[idl.float32]})


def wait(cond: Callable[[], bool], timeout: float = 15.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return False


@contextlib.contextmanager
def private_dds_domain() -> Iterator[int]:
    """A DDS domain id no other test process on this machine holds (a lock file per id,
    held while the block runs); skips the test when every id is taken."""
    import pytest

    ids = list(range(100, 230))
    random.shuffle(ids)
    for domain in ids:
        path = os.path.join(tempfile.gettempdir(), f"eddie-dds-domain-{domain}.lock")
        with open(path, "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                continue
            try:
                yield domain
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)
            return
    pytest.skip("no free DDS domain id")


class RosPeer:
    """A DDS participant behaving as a ROS 2 node on rmw_cyclonedds (raw CDR in and out)."""

    def __init__(self, domain_id: int) -> None:
        self.domain = Domain(domain_id, cyclone_config("loopback"))
        self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        self.publications = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        self.participants = BuiltinDataReader(self.participant, BuiltinTopicDcpsParticipant)
        self._topics: dict[str, Any] = {}
        self._known: dict[str, Any] = {}
        self._clients: dict[str, tuple[Any, Any]] = {}
        self._seq = 0

    def _topic(self, name: str, cls: Any) -> Any:
        if name not in self._topics:
            self._topics[name] = Topic(self.participant, name, cls)
        return self._topics[name]

    @staticmethod
    def qos(ros_type: str, *, latched: bool = False, depth: int = 10,
            best_effort: bool = False) -> Qos:
        return Qos(
            Policy.Reliability.BestEffort if best_effort
            else Policy.Reliability.Reliable(max_blocking_time=100_000_000),
            Policy.Durability.TransientLocal if latched else Policy.Durability.Volatile,
            Policy.History.KeepLast(depth),
            Policy.DataRepresentation(use_cdrv0_representation=True),
            Policy.Userdata(f"typehash={type_hash(ros_type)};".encode()),
        )

    def writer(self, topic: str, cls: Any, ros_type: str, **kw: Any) -> Any:
        return DataWriter(self.participant, self._topic("rt" + topic, cls),
                          qos=self.qos(ros_type, **kw))

    def reader(self, topic: str, cls: Any, ros_type: str, **kw: Any) -> Any:
        return DataReader(self.participant, self._topic("rt" + topic, cls),
                          qos=self.qos(ros_type, **kw))

    @staticmethod
    def pad(cdr: bytes) -> bytes:
        return cdr.ljust(-(-len(cdr) // 4) * 4, b"\0")

    @staticmethod
    def write(writer: Any, msg: Any) -> None:
        assert ddspy_write(writer._ref, RosPeer.pad(serialize(msg))) == 0

    @staticmethod
    def take(reader: Any, ros_type: str) -> list[Any]:
        got = ddspy_take(reader._ref, ANY, 100)
        return [TYPESTORE.deserialize_cdr(bytes(d), ros_type) for d, info in got
                if info.valid_data]

    def publications_on(self, dds_topic: str) -> list[Any]:
        """Alive publications of other participants on ``dds_topic`` (DCPSPublication)."""
        for s in self.publications.take(N=200):
            key = str(s.key)
            if s.sample_info.instance_state == InstanceState.Alive:
                self._known[key] = s
            else:
                self._known.pop(key, None)
        own = str(self.participant.guid)
        return [s for s in self._known.values()
                if s.topic_name == dds_topic and str(s.participant_key) != own]

    # -- services, as rmw_cyclonedds's client --------------------------------------------
    def client(self, name: str, srv_type: str, request_t: Any, response_t: Any,
               timeout: float = 15.0) -> bool:
        """Declare a client of ``name`` (``request_t``/``response_t``: the DDS types with
        the ``rmw_request_guid``/``rmw_request_seq`` header); True once it is ready (its
        request writer and reply reader both matched, as rmw's ``service_is_ready``)."""
        from eddiebot.transport.keys import service_type_hash

        if name not in self._clients:
            qos = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
                      Policy.History.KeepLast(10),
                      Policy.DataRepresentation(use_cdrv0_representation=True),
                      Policy.Userdata(f"typehash={service_type_hash(srv_type)};".encode()))
            dds_name = name.lstrip("/")
            self._clients[name] = (
                DataWriter(self.participant, self._topic(f"rq/{dds_name}Request", request_t),
                           qos=qos),
                DataReader(self.participant, self._topic(f"rr/{dds_name}Reply", response_t),
                           qos=qos))
        writer, reader = self._clients[name]
        return wait(lambda: writer.get_publication_matched_status().current_count > 0
                    and reader.get_subscription_matched_status().current_count > 0, timeout)

    def call(self, name: str, srv_type: str, request: Any, timeout: float = 15.0) -> Any:
        """Call the service ``name`` (declared by :meth:`client`) with ``request``; the
        decoded response whose header carries this call's guid and sequence, or None."""
        writer, reader = self._clients[name]
        self._seq += 1
        guid, seq = int.from_bytes(self.participant.guid.bytes[:8], "little"), self._seq
        body = serialize(request, f"{srv_type}_Request")
        assert ddspy_write(writer._ref,
                           self.pad(body[:4] + struct.pack("<Qq", guid, seq) + body[4:])) == 0
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for data, info in ddspy_take(reader._ref, ANY, 10):
                raw = bytes(data)
                if info.valid_data and struct.unpack_from("<Qq", raw, 4) == (guid, seq):
                    return TYPESTORE.deserialize_cdr(raw[:4] + raw[20:], f"{srv_type}_Response")
            time.sleep(0.01)
        return None
