"""QoS deadline, lifespan, liveliness and the QoS events, in one process on sim time."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from eddiebot.core import Context, Node, QoSProfile, SingleThreadedExecutor
from eddiebot.core.qos import (
    DurabilityPolicy,
    LivelinessPolicy,
    QoSCompatibility,
    QoSPolicyKind,
    ReliabilityPolicy,
    qos_check_compatible,
)
from eddiebot.core.qos_events import PublisherEventCallbacks, SubscriptionEventCallbacks
from eddiebot.core.time import Clock, Duration
from eddiebot.msgs.std_msgs import Int32

S = 1_000_000_000


def _d(seconds: float) -> Duration:
    return Duration.from_seconds(seconds)


@pytest.fixture
def ctx() -> Any:
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def _setup(ctx: Context) -> tuple[SingleThreadedExecutor, Node]:
    ex = SingleThreadedExecutor(context=ctx)
    node = Node("qos", context=ctx, start_parameter_services=False)
    ex.add_node(node)
    return ex, node


@pytest.mark.parametrize(("pub", "sub", "policy"), [
    (QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT), QoSProfile(), QoSPolicyKind.RELIABILITY),
    (QoSProfile(), QoSProfile(durability=DurabilityPolicy.TRANSIENT_LOCAL), QoSPolicyKind.DURABILITY),
    (QoSProfile(deadline=_d(2)), QoSProfile(deadline=_d(1)), QoSPolicyKind.DEADLINE),
    (QoSProfile(), QoSProfile(deadline=_d(1)), QoSPolicyKind.DEADLINE),
    (QoSProfile(), QoSProfile(liveliness=LivelinessPolicy.MANUAL_BY_TOPIC), QoSPolicyKind.LIVELINESS),
    (QoSProfile(liveliness_lease_duration=_d(3)), QoSProfile(liveliness_lease_duration=_d(2)),
     QoSPolicyKind.LIVELINESS_LEASE_DURATION),
])
def test_incompatible_pairs_name_the_policy(pub: QoSProfile, sub: QoSProfile,
                                            policy: QoSPolicyKind) -> None:
    verdict, reason, kind = qos_check_compatible(pub, sub)
    assert verdict == QoSCompatibility.ERROR and kind == policy and reason


def test_compatible_pairs() -> None:
    assert qos_check_compatible(QoSProfile(), QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT))[0] \
        == QoSCompatibility.OK
    assert qos_check_compatible(QoSProfile(deadline=_d(1)), QoSProfile(deadline=_d(2)))[0] \
        == QoSCompatibility.OK
    with pytest.raises(ValueError, match="deadline"):
        QoSProfile(deadline=Duration(-1))


def test_matched_events_follow_publishers_coming_and_going(ctx: Context) -> None:
    ex, node = _setup(ctx)
    infos: list[Any] = []
    node.create_subscription(Int32, "/m", lambda m: None, 10,
                             event_callbacks=SubscriptionEventCallbacks(matched=infos.append))
    a = node.create_publisher(Int32, "/m", 10)
    ex.spin_until_idle()
    b = node.create_publisher(Int32, "/m", 10)
    ex.spin_until_idle()
    node.destroy_publisher(a)
    ex.spin_until_idle()
    assert [(i.total_count, i.current_count, i.current_count_change) for i in infos] == [
        (1, 1, 1), (2, 2, 1), (2, 1, -1)]
    pub_infos: list[Any] = []
    node.destroy_publisher(b)
    node.create_publisher(Int32, "/m", 10,
                          event_callbacks=PublisherEventCallbacks(matched=pub_infos.append))
    ex.spin_until_idle()
    assert [(i.current_count, i.total_count) for i in pub_infos] == [(1, 1)]


def test_incompatible_qos_is_reported_on_both_sides(
    ctx: Context, caplog: pytest.LogCaptureFixture
) -> None:
    ex, node = _setup(ctx)
    requested: list[Any] = []
    offered: list[Any] = []
    matched: list[Any] = []
    node.create_subscription(Int32, "/r", lambda m: None, 10, event_callbacks=SubscriptionEventCallbacks(
        incompatible_qos=requested.append, matched=matched.append))
    node.create_publisher(Int32, "/r", QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT),
                          event_callbacks=PublisherEventCallbacks(incompatible_qos=offered.append))
    ex.spin_until_idle()
    assert [(i.total_count, i.last_policy_kind) for i in requested] == [(1, QoSPolicyKind.RELIABILITY)]
    assert [(i.total_count, i.last_policy_kind) for i in offered] == [(1, QoSPolicyKind.RELIABILITY)]
    assert matched == []  # an incompatible pair does not match
    # without a callback, rclpy's default: one warning naming the node, topic and policy
    with caplog.at_level(logging.WARNING):
        node.create_subscription(Int32, "/r", lambda m: None,
                                 QoSProfile(durability=DurabilityPolicy.TRANSIENT_LOCAL),
                                 event_callbacks=SubscriptionEventCallbacks())
        ex.spin_until_idle()
    warnings = [r.getMessage() for r in caplog.records if "incompatible" in r.getMessage()]
    assert len(warnings) == 1 and "/qos" in warnings[0] and "/r" in warnings[0]
    assert "RELIABILITY" in warnings[0]  # the first policy that fails: reliability


def test_deadline_missed_counts_silent_periods(ctx: Context) -> None:
    ex, node = _setup(ctx)
    requested: list[Any] = []
    offered: list[Any] = []
    qos = QoSProfile(deadline=_d(0.4))
    node.create_subscription(Int32, "/d", lambda m: None, qos,
                             event_callbacks=SubscriptionEventCallbacks(deadline=requested.append))
    pub = node.create_publisher(Int32, "/d", qos,
                                event_callbacks=PublisherEventCallbacks(deadline=offered.append))
    sent = [0]

    def tick() -> None:
        if sent[0] < 6:  # at 0.25 s .. 1.5 s, then silence
            sent[0] += 1
            pub.publish(Int32(data=sent[0]))

    node.create_timer(0.25, tick)
    ex.spin_until(4 * S)
    # deadline checks at 0.4, 0.8, ..., 4.0 s: the six from 2.0 s on saw nothing
    for infos in (requested, offered):
        assert infos[-1].total_count == 6
        assert sum(i.total_count_change for i in infos) == 6


def test_manual_liveliness_lost_and_regained(ctx: Context) -> None:
    ex, node = _setup(ctx)
    lost: list[Any] = []
    changed: list[Any] = []
    qos = QoSProfile(liveliness=LivelinessPolicy.MANUAL_BY_TOPIC, liveliness_lease_duration=_d(1))
    node.create_subscription(Int32, "/l", lambda m: None, qos,
                             event_callbacks=SubscriptionEventCallbacks(liveliness=changed.append))
    pub = node.create_publisher(Int32, "/l", qos,
                                event_callbacks=PublisherEventCallbacks(liveliness=lost.append))
    ex.spin_until_idle()
    assert (changed[-1].alive_count, changed[-1].not_alive_count) == (1, 0)
    ex.spin_until(S + S // 2)  # no publish, no assert within the first lease
    assert [i.total_count for i in lost] == [1]
    assert (changed[-1].alive_count, changed[-1].not_alive_count) == (0, 1)
    assert changed[-1].alive_count_change == -1
    pub.assert_liveliness()
    ex.spin_until_idle()
    assert (changed[-1].alive_count, changed[-1].not_alive_count) == (1, 0)
    ex.spin_until(5 * S // 2)  # asserted inside the lease that ended at 2 s
    assert [i.total_count for i in lost] == [1]
    ex.spin_until(4 * S)
    assert lost[-1].total_count == 2


class _Wall(Clock):
    """A system clock the test moves."""

    def __init__(self) -> None:
        super().__init__()
        self.ns = 1_700_000_000 * S

    def now_ns(self) -> int:
        return self.ns


def test_lifespan_drops_messages_that_waited_too_long(ctx: Context) -> None:
    ex, node = _setup(ctx)
    wall = _Wall()
    ctx.system_clock = wall
    got: list[int] = []
    node.create_subscription(Int32, "/s", lambda m: got.append(m.data), 10)
    short = node.create_publisher(Int32, "/s", QoSProfile(lifespan=_d(1)))
    short.publish(Int32(data=1))
    short.publish(Int32(data=2))
    wall.ns += 2 * S
    short.publish(Int32(data=3))
    ex.spin_until_idle()
    assert got == [3]
