"""CDR round trip and defaults of every registered message, request, response, goal, ..."""

from __future__ import annotations

import numpy as np
import pytest
from _msgtools import NUMPY_DTYPES, assert_equal, fields, sample_message
from rosbags.interfaces import Nodetype

from eddiebot.msgs import TYPESTORE, deserialize, serialize
from eddiebot.msgs._defaults import _FILE_DEFAULTS

ALL_TYPES = sorted(TYPESTORE.types)


def test_store_is_populated() -> None:
    # rosbags' Jazzy store (~200) plus the interfaces shipped here (~170 incl. split types)
    assert len(ALL_TYPES) > 350


@pytest.mark.parametrize("typename", ALL_TYPES)
def test_default_round_trip(typename: str) -> None:
    msg = TYPESTORE.types[typename]()
    data = serialize(msg)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little endian encapsulation header
    assert_equal(msg, deserialize(data, typename), typename)


@pytest.mark.parametrize("typename", ALL_TYPES)
def test_filled_round_trip(typename: str) -> None:
    msg = sample_message(typename)
    back = deserialize(serialize(msg), typename)
    assert_equal(msg, back, typename)
    # and the encoding is canonical: re-encoding the decoded message gives the same bytes
    assert serialize(back) == serialize(msg)


@pytest.mark.parametrize("typename", ALL_TYPES)
def test_every_field_has_a_default(typename: str) -> None:
    """Zero values everywhere, except a primitive field whose interface file gives a default
    (``bool include_type_sources true``), which takes that."""
    msg = TYPESTORE.types[typename]()
    written = _FILE_DEFAULTS.get(typename, {})
    for name, (kind, detail) in fields(typename):
        value = getattr(msg, name)
        if name in written:
            assert value == written[name] and type(value) is type(written[name])
        elif kind == Nodetype.BASE:
            typ = detail[0]
            if typ in ("string", "wstring"):
                assert value == ""
            elif typ == "bool":
                assert value is False
            elif typ.startswith("float"):
                assert isinstance(value, float)
                assert value == 0.0
            else:
                assert isinstance(value, int)
                assert value == 0
        elif kind == Nodetype.NAME:
            assert value.__msgtype__ == detail
        else:
            (inner_kind, inner_detail), size = detail
            length = size if kind == Nodetype.ARRAY else 0
            if inner_kind == Nodetype.BASE and inner_detail[0] in NUMPY_DTYPES:
                assert isinstance(value, np.ndarray)
                assert value.dtype == NUMPY_DTYPES[inner_detail[0]]
                assert value.shape == (length,)
                assert not value.any()
            else:
                assert isinstance(value, list)
                assert len(value) == length


def test_defaults_are_fresh_objects() -> None:
    """Mutable defaults must not be shared between instances."""
    cls = TYPESTORE.types["nav_msgs/msg/Path"]
    a, b = cls(), cls()
    a.poses.append(TYPESTORE.types["geometry_msgs/msg/PoseStamped"]())
    a.header.frame_id = "map"
    assert b.poses == []
    assert b.header.frame_id == ""
    grid = TYPESTORE.types["nav2_msgs/msg/VoxelGrid"]
    g1, g2 = grid(), grid()
    assert g1.data is not g2.data


def test_positional_and_keyword_construction() -> None:
    enc = TYPESTORE.types["eddiebot_msgs/msg/Encoders"]
    assert enc(5).left == 5
    assert enc(5).right == 0
    assert enc(right=3).left == 0
    assert enc(1, 2).right == 2


def test_sequence_of_messages_round_trip_values() -> None:
    cloud_t = "nav2_msgs/msg/ParticleCloud"
    particle = TYPESTORE.types["nav2_msgs/msg/Particle"]
    cloud = TYPESTORE.types[cloud_t](particles=[particle(weight=0.25), particle(weight=0.75)])
    cloud.particles[1].pose.position.x = 3.5
    cloud.header.frame_id = "map"
    back = deserialize(serialize(cloud), cloud_t)
    assert [p.weight for p in back.particles] == [0.25, 0.75]
    assert back.particles[1].pose.position.x == 3.5
    assert back.header.frame_id == "map"
