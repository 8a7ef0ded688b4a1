"""GIDs as rmw_zenoh computes them (XXH3-128 of the liveliness key), one per entity, and
rmw_zenoh's congestion-control rule."""

from __future__ import annotations

from typing import Any

import pytest

from eddiebot.core._xxh3 import xxh3_128
from eddiebot.core.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from eddiebot.transport.keys import entity_gid, node_liveliness_key

_DATA = bytes(range(256)) * 3

# Reference digests from xxHash's XXH3_128bits (high 64 bits first), one per code path.
_VECTORS = [
    (b"", "99aa06d3014798d86001c324468d497f"),
    (b"abc", "06b05ab6733a618578af5f94892f3950"),
    (_DATA[:1], "a6cd5e9392000f6ac44bdff4074eecdb"),
    (_DATA[:5], "9434532106a7c141c920d2347a85929b"),
    (_DATA[:12], "38f92247a7f73cc57780eb31198f13ca"),
    (_DATA[:17], "685bc458b37d057fc06e233df7729217"),
    (_DATA[:100], "da95ef16fd9566f329b20ba5f03ec01e"),
    (_DATA[:129], "dd5e74ac6b45f54ebc30b63382b09a3b"),
    (_DATA[:200], "cb0395310643ba0edd97e9af3609d9f5"),
    (_DATA[:240], "65b5be86da5540e7c92b68e16f83bbb6"),
    (_DATA[:241], "1da1cb61bcb8a2a102e8cd95421c6d02"),
    (_DATA[:700], "2ca45810bb184608201e65abafdb7f73"),
]


@pytest.mark.parametrize(("data", "digest"), _VECTORS)
def test_xxh3_128_matches_reference(data: bytes, digest: str) -> None:
    low, high = xxh3_128(data)
    assert f"{high:016x}{low:016x}" == digest


def test_gid_is_low_then_high_little_endian() -> None:
    key = node_liveliness_key(0, "zid", 0, "", "talker")
    assert key == "@ros2_lv/0/zid/0/0/NN/%/%/talker"
    # XXH3-128 of that key is ec47c950fdcb96fa 41ef92f34391a043 (high, low)
    assert entity_gid(key).hex() == "43a09143f392ef41fa96cbfd50c947ec"


def test_every_entity_has_its_own_gid() -> None:
    keys = [node_liveliness_key(0, "z", i, "/ns", f"n{i}") for i in range(200)]
    assert len({entity_gid(k) for k in keys}) == 200
    assert all(len(entity_gid(k)) == 16 for k in keys)


@pytest.mark.parametrize(("reliability", "history", "block"), [
    (ReliabilityPolicy.RELIABLE, HistoryPolicy.KEEP_ALL, True),
    (ReliabilityPolicy.RELIABLE, HistoryPolicy.KEEP_LAST, False),
    (ReliabilityPolicy.BEST_EFFORT, HistoryPolicy.KEEP_ALL, False),
    (ReliabilityPolicy.BEST_EFFORT, HistoryPolicy.KEEP_LAST, False),
])
def test_only_reliable_keep_all_blocks_on_congestion(
    reliability: ReliabilityPolicy, history: HistoryPolicy, block: bool
) -> None:
    import zenoh

    from eddiebot.transport.zenoh import publisher_congestion_control

    qos = QoSProfile(depth=10, reliability=reliability, history=history)
    expected = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
    assert publisher_congestion_control(qos) == expected


def test_each_client_sends_its_own_gid(zenoh_config: Any) -> None:
    from eddiebot.core import Context, Node
    from eddiebot.msgs.std_srvs import Trigger
    from eddiebot.transport import connect
    from eddiebot.transport.keys import ATTACHMENT

    server_ctx, client_ctx = Context(), Context()
    try:
        seen: list[bytes] = []
        server = Node("gid_server", context=server_ctx)
        transport = connect(server_ctx, zenoh_config, required=True)
        assert transport is not None

        def answer(req: Any, res: Any) -> Any:
            res.success = True
            return res

        server.create_service(Trigger, "/gid_probe", answer)
        handler = transport._query_handler  # record the attachment of every query

        def recording(srv: Any) -> Any:
            inner = handler(srv)

            def h(query: Any) -> None:
                seen.append(query.attachment.to_bytes())
                inner(query)
            return h

        transport._query_handler = recording
        server.destroy_service(server.services[-1])
        server.create_service(Trigger, "/gid_probe", answer)
        node = Node("gid_caller", context=client_ctx)
        connect(client_ctx, zenoh_config, required=True)
        a = node.create_client(Trigger, "/gid_probe")
        b = node.create_client(Trigger, "/gid_probe")
        assert a.wait_for_service(timeout_sec=10)
        for client in (a, a, b):
            assert client.call(Trigger.Request(), timeout_sec=10).success
        fields = [ATTACHMENT.unpack_from(s) for s in seen]
        assert [f[0] for f in fields] == [1, 2, 1]  # sequence numbers per client
        assert fields[0][3] == fields[1][3] != fields[2][3]
    finally:
        client_ctx.shutdown()
        server_ctx.shutdown()
