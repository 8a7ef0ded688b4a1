import logging

import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor
from eddiebot.core.lifecycle import (
    LifecycleManager,
    LifecycleNode,
    LifecycleState,
    TransitionCallbackReturn,
)
from eddiebot.msgs.lifecycle_msgs import (
    ChangeState,
    GetAvailableTransitions,
    GetState,
    Transition,
    TransitionEvent,
)
from eddiebot.msgs.nav2_msgs import ManageLifecycleNodes
from eddiebot.msgs.std_msgs import String
from eddiebot.msgs.std_srvs import Trigger

S = 1_000_000_000
OK = TransitionCallbackReturn.SUCCESS


class Server(LifecycleNode):
    def __init__(self, name, journal, ctx, fail=None, **kw):
        super().__init__(name, context=ctx, **kw)
        self.journal = journal
        self.fail = fail or {}
        self.pub = self.create_lifecycle_publisher(String, "~/out", 10)

    def _step(self, what):
        self.journal.append((self.get_name(), what))
        return self.fail.get(what, OK)

    def on_configure(self, state):
        return self._step("configure")

    def on_activate(self, state):
        return self._step("activate")

    def on_deactivate(self, state):
        return self._step("deactivate")

    def on_cleanup(self, state):
        return self._step("cleanup")

    def on_shutdown(self, state):
        return self._step("shutdown")

    def on_error(self, state):
        self.journal.append((self.get_name(), f"error from {state.label}"))
        return OK


@pytest.fixture
def ctx():
    c = Context(use_sim_time=True)
    yield c
    c.shutdown()


def test_transitions_and_state_ids(ctx):
    journal = []
    n = Server("map_server", journal, ctx)
    assert n.current_state.state_id == 1 and n.current_state.label == "unconfigured"
    assert n.trigger_activate() == TransitionCallbackReturn.FAILURE  # not from unconfigured
    assert n.trigger_configure() == OK
    assert n.current_state.state_id == LifecycleState.INACTIVE
    assert n.trigger_activate() == OK and n.current_state.label == "active"
    assert n.trigger_deactivate() == OK and n.trigger_cleanup() == OK
    assert n.current_state.state_id == LifecycleState.UNCONFIGURED
    assert n.trigger_shutdown() == OK
    assert n.current_state.state_id == LifecycleState.FINALIZED
    assert [w for _, w in journal] == ["configure", "activate", "deactivate", "cleanup", "shutdown"]
    assert n.available_transitions() == []


def test_failure_stays_and_error_goes_through_on_error(ctx):
    journal = []
    n = Server("a", journal, ctx, fail={"configure": TransitionCallbackReturn.FAILURE})
    assert n.trigger_configure() == TransitionCallbackReturn.FAILURE
    assert n.current_state.state_id == LifecycleState.UNCONFIGURED
    n.fail = {"activate": TransitionCallbackReturn.ERROR}
    n.trigger_configure()
    assert n.trigger_activate() == TransitionCallbackReturn.ERROR
    assert n.current_state.state_id == LifecycleState.UNCONFIGURED  # on_error SUCCESS
    assert ("a", "error from inactive") in journal

    class Broken(LifecycleNode):
        def on_configure(self, state):
            raise RuntimeError("no map file")

        def on_error(self, state):
            return TransitionCallbackReturn.FAILURE

    b = Broken("b", context=ctx)
    assert b.trigger_configure() == TransitionCallbackReturn.ERROR
    assert b.current_state.state_id == LifecycleState.FINALIZED


def test_lifecycle_publisher_silent_until_active(ctx, caplog):
    ex = SingleThreadedExecutor(context=ctx)
    n = Server("pub", [], ctx)
    got = []
    listener = Node("listener", context=ctx)
    listener.create_subscription(String, "/pub/out", got.append, 10)
    ex.add_node(n)
    ex.add_node(listener)
    with caplog.at_level(logging.WARNING):
        n.pub.publish(String(data="early"))
        n.pub.publish(String(data="early again"))
    assert sum("not activated" in r.message for r in caplog.records) == 1  # logged once
    n.trigger_configure()
    n.pub.publish(String(data="inactive"))
    n.trigger_activate()
    n.pub.publish(String(data="active"))
    n.trigger_deactivate()
    n.pub.publish(String(data="inactive again"))
    ex.spin_until_idle()
    assert [m.data for m in got] == ["active"]


def test_services_and_transition_events(ctx):
    ex = SingleThreadedExecutor(context=ctx)
    n = Server("amcl", [], ctx, namespace="robot")
    caller = Node("caller", context=ctx)
    events = []
    caller.create_subscription(TransitionEvent, "/robot/amcl/transition_event", events.append, 10)
    ex.add_node(n)
    ex.add_node(caller)
    change = caller.create_client(ChangeState, "/robot/amcl/change_state")
    get = caller.create_client(GetState, "/robot/amcl/get_state")
    avail = caller.create_client(GetAvailableTransitions, "/robot/amcl/get_available_transitions")
    labels = [t.transition.label for t in avail.call(GetAvailableTransitions.Request()).available_transitions]
    assert labels == ["configure", "shutdown"]
    assert change.call(ChangeState.Request(transition=Transition(id=1))).success
    assert not change.call(ChangeState.Request(transition=Transition(id=1))).success  # already
    assert change.call(ChangeState.Request(transition=Transition(label="activate"))).success
    assert get.call(GetState.Request()).current_state.label == "active"
    ex.spin_until_idle()
    assert [(e.start_state.id, e.goal_state.id) for e in events] == [(1, 10), (10, 2), (2, 13), (13, 3)]
    assert [e.transition.id for e in events] == [1, 10, 3, 30]


def test_bond_heartbeat_only_while_active(ctx):
    from eddiebot.msgs.bond import Status

    ex = SingleThreadedExecutor(context=ctx)
    n = Server("planner", [], ctx)
    beats = []
    listener = Node("listener", context=ctx)
    listener.create_subscription(Status, "/bond", beats.append, 100)
    ex.add_node(n)
    ex.add_node(listener)
    n.trigger_configure()
    ex.spin_for(1.0)
    assert beats == []
    n.trigger_activate()
    ex.spin_for(1.0)
    assert 10 <= len(beats) <= 11
    # bondcpp's heartbeat: the bond id is the node's name, one instance id, the timings
    assert {b.id for b in beats} == {"planner"} and len({b.instance_id for b in beats}) == 1
    assert beats[-1].active and beats[-1].heartbeat_period == pytest.approx(0.1)
    assert beats[-1].heartbeat_timeout == pytest.approx(4.0)
    n.trigger_deactivate()
    ex.spin_for(0.01)
    assert beats[-1].active is False  # the bond is broken, and the sister told so
    count = len(beats)
    ex.spin_for(1.0)
    assert len(beats) == count


def test_manager_beats_its_side_and_a_broken_bond_takes_the_group_down_at_once(ctx):
    from eddiebot.msgs.bond import Status

    journal: list = []
    ex, nodes, manager = _group(ctx, ["a", "b"], journal, bond_timeout=4.0, autostart=True,
                                attempt_respawn_reconnection=False)
    beats = []
    listener = Node("listener2", context=ctx)
    listener.create_subscription(Status, "/bond", beats.append, 100)
    ex.add_node(listener)
    ex.spin_for(0.5)
    ours = {b.id for b in beats if b.instance_id == manager._bond_instance}
    assert ours == {"a", "b"}
    # a bondcpp node breaking its bond (active false) is down now, not after 4 s
    pub = listener.create_publisher(Status, "/bond", 5)
    pub.publish(Status(id="b", instance_id="sister-of-b", active=False))
    ex.spin_for(0.5)
    assert not manager.system_active


def _group(ctx, names, journal, fail=None, **params):
    nodes = [Server(n, journal, ctx, fail=(fail or {}).get(n)) for n in names]
    overrides = {"node_names": names, **params}
    manager = LifecycleManager("lifecycle_manager_navigation", context=ctx,
                               parameter_overrides=overrides)
    ex = SingleThreadedExecutor(context=ctx)
    for n in [*nodes, manager]:
        ex.add_node(n)
    return ex, nodes, manager


def test_manager_autostart_order_and_shutdown(ctx):
    journal = []
    ex, nodes, manager = _group(ctx, ["map_server", "amcl", "planner"], journal, autostart=True)
    ex.spin_until_idle()
    assert manager.system_active
    assert journal == [("map_server", "configure"), ("amcl", "configure"), ("planner", "configure"),
                       ("map_server", "activate"), ("amcl", "activate"), ("planner", "activate")]
    assert all(n.current_state.label == "active" for n in nodes)
    client_node = Node("cli", context=ctx)
    ex.add_node(client_node)
    is_active = client_node.create_client(Trigger, "/lifecycle_manager_navigation/is_active")
    assert is_active.call(Trigger.Request()).success
    manage = client_node.create_client(ManageLifecycleNodes, "/lifecycle_manager_navigation/manage_nodes")
    journal.clear()
    assert manage.call(ManageLifecycleNodes.Request(command=ManageLifecycleNodes.Request.PAUSE)).success
    assert journal == [("planner", "deactivate"), ("amcl", "deactivate"),
                                    ("map_server", "deactivate")]
    assert manage.call(ManageLifecycleNodes.Request(command=ManageLifecycleNodes.Request.RESUME)).success
    journal.clear()
    assert manage.call(ManageLifecycleNodes.Request(command=ManageLifecycleNodes.Request.SHUTDOWN)).success
    assert [w for _, w in journal] == ["deactivate"] * 3 + ["cleanup"] * 3 + ["shutdown"] * 3
    assert [n for n, _ in journal[:3]] == ["planner", "amcl", "map_server"]
    assert all(n.current_state.label == "finalized" for n in nodes)
    assert not is_active.call(Trigger.Request()).success


def test_manager_failure_brings_group_down_and_names_node(ctx, caplog):
    journal = []
    ex, nodes, manager = _group(ctx, ["map_server", "amcl", "planner"], journal,
                                fail={"amcl": {"activate": TransitionCallbackReturn.FAILURE}})
    with caplog.at_level(logging.ERROR):
        assert not manager.startup()
    assert "amcl" in manager.last_error
    assert any("amcl" in r.message for r in caplog.records)
    assert [n.current_state.label for n in nodes] == ["unconfigured"] * 3
    assert ("map_server", "deactivate") in journal and ("planner", "cleanup") in journal


def test_bond_timeout_takes_group_down(ctx, caplog):
    journal = []
    ex, nodes, manager = _group(ctx, ["map_server", "amcl", "planner"], journal,
                                bond_timeout=1.0, attempt_respawn_reconnection=False)
    assert manager.startup()
    ex.spin_for(5.0)
    assert all(n.current_state.label == "active" for n in nodes)  # heartbeats keep bonds up
    # amcl hangs: its heartbeat stops
    nodes[1]._bond_timer.cancel()
    with caplog.at_level(logging.ERROR):
        ex.spin_for(1.0)
        assert manager.system_active  # not yet: within bond_timeout
        ex.spin_for(0.5)
    assert not manager.system_active
    assert manager.dead_nodes == ["amcl"]
    assert any("amcl" in r.message and "heartbeat" in r.message for r in caplog.records)
    assert nodes[0].current_state.label == "unconfigured"
    assert nodes[2].current_state.label == "unconfigured"
    assert ("amcl", "deactivate") not in journal


def test_bond_respawn_reconnects(ctx):
    journal = []
    ex, nodes, manager = _group(ctx, ["a", "b"], journal, bond_timeout=1.0,
                                attempt_respawn_reconnection=True)
    assert manager.startup()
    nodes[1]._bond_timer.cancel()
    ex.spin_for(1.5)
    assert not manager.system_active
    # node b restarts (as a respawned process would, unconfigured)
    nodes[1]._destroy_bond()
    nodes[1].trigger_deactivate()
    nodes[1].trigger_cleanup()
    ex.spin_for(1.5)
    assert manager.system_active
    assert all(n.current_state.label == "active" for n in nodes)
