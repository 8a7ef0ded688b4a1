"""QoS across processes: rmw_zenoh's QoS key chunk, matched and message-lost events,
lifespan."""

from __future__ import annotations

import time
from typing import Any

from eddiebot.core import Context, Node, QoSProfile, SingleThreadedExecutor
from eddiebot.core.qos import LivelinessPolicy
from eddiebot.core.qos_events import SubscriptionEventCallbacks
from eddiebot.core.time import Clock, Duration
from eddiebot.msgs.std_msgs import Int32
from eddiebot.transport import connect
from eddiebot.transport.keys import qos_from_keyexpr, qos_to_keyexpr


def test_qos_chunk_carries_deadline_lifespan_and_liveliness() -> None:
    qos = QoSProfile(depth=5, deadline=Duration(1_500_000_000), lifespan=Duration(2 * 10**9),
                     liveliness=LivelinessPolicy.MANUAL_BY_TOPIC,
                     liveliness_lease_duration=Duration(3 * 10**9))
    # rmw_zenoh: sec,nsec each left empty when equal to the infinite default's
    assert qos_to_keyexpr(qos) == "::,5:1,500000000:2,0:3,3,0"
    assert qos_from_keyexpr(qos_to_keyexpr(qos)) == qos
    assert qos_to_keyexpr(QoSProfile()) == "::,10:,:,:,,"
    assert qos_from_keyexpr("::,10:,:,:,,") == QoSProfile()
    assert qos_from_keyexpr("::,7") == QoSProfile(depth=7)  # older, shorter form


def _wait(cond: Any, ex: SingleThreadedExecutor, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.02)
        if cond():
            return True
    return cond()


class _Wall(Clock):
    def __init__(self, ns: int) -> None:
        super().__init__()
        self.ns = ns

    def now_ns(self) -> int:
        return self.ns


def test_remote_matched_lost_and_lifespan(zenoh_config: Any) -> None:
    pub_ctx, sub_ctx = Context(), Context()
    try:
        talker = Node("lossy_talker", context=pub_ctx, start_parameter_services=False)
        connect(pub_ctx, zenoh_config, required=True)
        listener = Node("lossy_listener", context=sub_ctx, start_parameter_services=False)
        connect(sub_ctx, zenoh_config, required=True)
        ex = SingleThreadedExecutor(context=sub_ctx)
        ex.add_node(listener)
        got: list[int] = []
        matched: list[Any] = []
        lost: list[Any] = []
        listener.create_subscription(Int32, "/lossy", lambda m: got.append(m.data), 100,
                                     event_callbacks=SubscriptionEventCallbacks(
                                         matched=matched.append, message_lost=lost.append))
        pub = talker.create_publisher(Int32, "/lossy", 100)
        assert _wait(lambda: bool(matched) and matched[-1].current_count == 1, ex)
        assert _wait(lambda: pub.get_subscription_count() == 1, ex)
        pub.publish(Int32(data=1))
        pub.sequence += 4  # four samples that never left
        pub.publish(Int32(data=6))
        assert _wait(lambda: got == [1, 6], ex)
        assert _wait(lambda: bool(lost) and lost[-1].total_count == 4, ex)

        # lifespan: the subscriber's wall clock is 10 s ahead of the publisher's
        sub_ctx.system_clock = _Wall(time.time_ns() + 10 * 10**9)
        short = talker.create_publisher(Int32, "/lossy", QoSProfile(depth=100, lifespan=Duration(10**9)))
        assert _wait(lambda: len(listener.get_publishers_info_by_topic("/lossy")) == 2, ex)
        short.publish(Int32(data=7))  # 1 s lifespan: expired on arrival
        pub.publish(Int32(data=8))    # no lifespan
        assert _wait(lambda: 8 in got, ex)
        assert got == [1, 6, 8]
        talker.destroy_publisher(pub)
        assert _wait(lambda: matched[-1].current_count == 1 and matched[-1].total_count == 2, ex)
    finally:
        sub_ctx.shutdown()
        pub_ctx.shutdown()
