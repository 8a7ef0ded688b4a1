"""The recorder node: which topics it records, including ones that appear later or live in
another process."""

from __future__ import annotations

from pathlib import Path

from _support.bags import EXCLUDE, T0, Talker
from eddiebot.bag import (
    BagReader,
    RecorderNode,
    bag_info,
)
from eddiebot.core import (
    Context,
    SingleThreadedExecutor,
    qos_profile_latched,
)
from eddiebot.msgs.nav_msgs import OccupancyGrid


def test_recorder_topic_list_and_exclude(tmp_path: Path) -> None:
    ctx = Context(use_sim_time=True)
    talker = Talker(ctx)
    bag = tmp_path / "some"
    rec = RecorderNode(context=ctx, parameter_overrides={
        "output": str(bag), "all": True, "exclude": ["^/sc", *EXCLUDE]})
    bag2 = tmp_path / "named"
    rec2 = RecorderNode("rec2", context=ctx, parameter_overrides={
        "output": str(bag2), "topics": ["/odom"]})
    ex = SingleThreadedExecutor(context=ctx)
    for n in (talker, rec, rec2):
        ex.add_node(n)
    ex.spin_for(0.5)
    rec.destroy_node()
    rec2.destroy_node()
    assert {t.name for t in bag_info(bag).topics} == {"/odom", "/map"}
    assert {t.name: t.count for t in bag_info(bag2).topics} == {"/odom": 5}


class _FakeTransport:
    """A transport whose graph shows one remote publisher (as eddiebot.transport reports it)."""

    def __init__(self, entities: list[object]) -> None:
        from types import SimpleNamespace

        self.cache = SimpleNamespace(publishers=lambda topic=None: list(entities))

    def graph(self) -> dict[str, object]:
        return {"cache": self.cache, "remote_publishers": {}, "remote_subscriptions": {}}

    def __getattr__(self, name: str) -> object:
        return lambda *args, **kwargs: False


def test_recorder_finds_remote_topics_through_the_transport(tmp_path: Path) -> None:
    from types import SimpleNamespace

    from eddiebot.transport.keys import qos_to_keyexpr

    ctx = Context(use_sim_time=True)
    ctx.sim_clock.set_ns(T0)
    remote = SimpleNamespace(name="/remote/map", type_name="nav_msgs/msg/OccupancyGrid",
                             qos=qos_to_keyexpr(qos_profile_latched))
    ctx.attach_transport(_FakeTransport([remote]))  # type: ignore[arg-type]
    bag = tmp_path / "remote"
    rec = RecorderNode(context=ctx, parameter_overrides={"output": str(bag), "all": True,
                                                         "exclude": EXCLUDE})
    assert rec.recorded_topics == ["/remote/map"]
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(rec)
    ctx.deliver_remote("/remote/map", "nav_msgs/msg/OccupancyGrid", OccupancyGrid())
    ex.spin_for(0.5)
    rec.destroy_node()
    with BagReader(bag) as reader:
        (conn,) = reader.connections
        assert conn.transient_local
        assert [m.timestamp for m in reader.messages()] == [T0]
