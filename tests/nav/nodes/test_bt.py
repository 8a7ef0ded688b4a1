"""Behaviour-tree nodes with BehaviorTree.CPP v4 / Nav2 semantics, on scripted leaves
loaded from XML (no servers)."""

from pathlib import Path
from typing import ClassVar

import pytest

from eddiebot.nav.bt import (
    BehaviorTreeFactory,
    Blackboard,
    LeafNode,
    Status,
    TreeContext,
    TreeError,
    input_port,
    output_port,
)

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING
_CODES = {"S": S, "F": F, "R": R}


class Scripted(LeafNode):
    """Returns the statuses of its ``script`` port ("S,F,R", the last one forever); counts
    ticks and halts."""

    PORTS: ClassVar = {"script": input_port(str, "S")}

    def __init__(self, *args):
        super().__init__(*args)
        self.script = [_CODES[c.strip()] for c in self.get_input("script").split(",")]
        self.ticks = 0
        self.halts = 0

    def tick(self):
        s = self.script[min(self.ticks, len(self.script) - 1)]
        self.ticks += 1
        return s

    def halt(self):
        self.halts += 1


class Echo(LeafNode):
    """Copies ``in`` to ``out``."""

    PORTS: ClassVar = {"in": input_port(str), "out": output_port(str)}

    def tick(self):
        self.set_output("out", self.get_input("in"))
        return S


class Clock:
    def __init__(self):
        self.ns = 0

    def __call__(self):
        return self.ns


def load(xml, clock=None, bb=None):
    f = BehaviorTreeFactory()
    f.register_node_type("Scripted", Scripted)
    f.register_node_type("Echo", Echo)
    body = xml if xml.lstrip().startswith("<root") else (
        f'<root BTCPP_format="4"><BehaviorTree ID="Main">{xml}</BehaviorTree></root>')
    return f.create_tree_from_text(body, bb, TreeContext(clock=clock or Clock()), file="t.xml")


def node(tree, name):
    (n,) = tree.find(name)
    return n


def test_recovery_node_bounded_retries():
    t = load('<RecoveryNode number_of_retries="6"><Scripted name="main" script="F"/>'
             '<Scripted name="rec" script="S"/></RecoveryNode>')
    assert t.tick_once() == F
    assert node(t, "main").ticks == 7 and node(t, "rec").ticks == 6


def test_recovery_node_succeeds_after_a_recovery():
    t = load('<RecoveryNode number_of_retries="2"><Scripted name="main" script="F,R,S"/>'
             '<Scripted name="rec" script="S"/></RecoveryNode>')
    assert t.tick_once() == R
    assert t.tick_once() == S
    assert node(t, "rec").ticks == 1


def test_round_robin_rotates_and_fails_when_all_fail():
    t = load('<RoundRobin><Scripted name="a" script="S"/><Scripted name="b" script="F"/>'
             '<Scripted name="c" script="S"/></RoundRobin>')
    a, b, c = (node(t, n) for n in "abc")
    assert t.tick_once() == S and (a.ticks, b.ticks, c.ticks) == (1, 0, 0)
    assert t.tick_once() == S and (a.ticks, b.ticks, c.ticks) == (1, 1, 1)  # b failed, c ran
    assert t.tick_once() == S and (a.ticks, b.ticks, c.ticks) == (2, 1, 1)
    t2 = load('<RoundRobin><Scripted script="F"/><Scripted script="F"/></RoundRobin>')
    assert t2.tick_once() == F


def test_pipeline_sequence_reticks_earlier_children():
    t = load('<PipelineSequence><Scripted name="plan" script="S"/>'
             '<Scripted name="follow" script="R,R,S"/></PipelineSequence>')
    assert t.tick_once() == R
    assert t.tick_once() == R
    assert node(t, "plan").ticks == 2 and node(t, "follow").ticks == 2
    assert t.tick_once() == S


def test_rate_controller_ticks_child_at_rate():
    clock = Clock()
    t = load('<RateController hz="1.0"><Scripted name="plan" script="S"/></RateController>',
             clock)
    child = node(t, "plan")
    for _ in range(10):  # 10 ticks within 0.9 s: only the first reaches the child
        t.tick_once()
        clock.ns += 100_000_000
    assert child.ticks == 1
    clock.ns = 1_100_000_000
    t.tick_once()
    assert child.ticks == 2


def test_reactive_sequence_halts_running_child_when_condition_fails():
    t = load('<ReactiveSequence><Scripted name="cond" script="S,S,F"/>'
             '<Scripted name="act" script="R"/></ReactiveSequence>')
    assert t.tick_once() == R
    assert t.tick_once() == R
    assert t.tick_once() == F
    cond, act = node(t, "cond"), node(t, "act")
    assert (cond.ticks, act.ticks, act.halts) == (3, 2, 1)


def test_reactive_fallback_halts_siblings_of_running_child():
    # v4: the running child halts every other one, so a condition before it starts afresh
    t = load('<ReactiveFallback><Scripted name="c" script="F,F,S"/>'
             '<Scripted name="act" script="R"/></ReactiveFallback>')
    assert t.tick_once() == R and t.tick_once() == R
    assert t.tick_once() == S
    assert node(t, "act").halts == 1 and node(t, "act").status == Status.IDLE


def test_sequence_restarts_but_sequence_with_memory_resumes_after_failure():
    seq = load('<Sequence><Scripted name="a" script="S"/><Scripted name="b" script="F,S"/>'
               '</Sequence>')
    mem = load('<SequenceWithMemory><Scripted name="a" script="S"/>'
               '<Scripted name="b" script="F,S"/></SequenceWithMemory>')
    for t in (seq, mem):
        assert t.tick_once() == F
        assert t.tick_once() == S
    assert node(seq, "a").ticks == 2
    assert node(mem, "a").ticks == 1  # resumed at b


def test_decorators():
    assert load('<Inverter><Scripted script="S"/></Inverter>').tick_once() == F
    t = load('<Repeat num_cycles="3"><Scripted name="x" script="S"/></Repeat>')
    assert t.tick_once() == S and node(t, "x").ticks == 3
    t = load('<RetryUntilSuccessful num_attempts="4"><Scripted name="x" script="F,F,S"/>'
             '</RetryUntilSuccessful>')
    assert t.tick_once() == S and node(t, "x").ticks == 3
    t = load('<KeepRunningUntilFailure><Scripted name="x" script="S,S,F"/>'
             '</KeepRunningUntilFailure>')
    assert [t.tick_once() for _ in range(3)] == [R, R, F]
    t = load('<Parallel success_count="2" failure_count="2"><Scripted script="R,S"/>'
             '<Scripted script="S"/><Scripted script="R"/></Parallel>')
    assert [t.tick_once(), t.tick_once()] == [R, S]


def test_blackboard_ports_and_remapping():
    bb = Blackboard()
    bb.set("goal", "kitchen")
    t = load('<Sequence><Echo in="{goal}" out="{copy}"/><Echo in="literal" out="{lit}"/>'
             '<Echo in="{missing}" out="{none}"/></Sequence>', bb=bb)
    assert t.tick_once() == S
    assert (bb.get("copy"), bb.get("lit"), bb.get("none")) == ("kitchen", "literal", None)


def test_subtree_ports_remap_to_parent():
    xml = """<root BTCPP_format="4" main_tree_to_execute="Main">
  <BehaviorTree ID="Main">
    <Sequence>
      <SubTree ID="Copy" src="{goal}" dst="{result}" tag="fixed"/>
      <SubTree ID="Auto" _autoremap="true"/>
    </Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Copy">
    <Sequence><Echo in="{src}" out="{dst}"/><Echo in="{tag}" out="{inner}"/></Sequence>
  </BehaviorTree>
  <BehaviorTree ID="Auto"><Echo in="{goal}" out="{auto_out}"/></BehaviorTree>
</root>"""
    bb = Blackboard()
    bb.set("goal", "dock")
    t = load(xml, bb=bb)
    assert t.tick_once() == S
    assert bb.get("result") == "dock" and bb.get("auto_out") == "dock"
    assert not bb.has("inner") and not bb.has("dst")  # private to the subtree


def test_v3_format_loads():
    xml = """<root main_tree_to_execute="MainTree">
  <BehaviorTree ID="MainTree">
    <SequenceStar>
      <Action ID="Scripted" name="a" script="S"/>
      <SubTreePlus ID="Sub" __autoremap="true"/>
    </SequenceStar>
  </BehaviorTree>
  <BehaviorTree ID="Sub"><Condition ID="Scripted" name="b" script="S"/></BehaviorTree>
</root>"""
    t = load(xml)
    assert t.tick_once() == S
    assert node(t, "b").ticks == 1


@pytest.mark.parametrize(("xml", "line", "words"), [
    ('<Sequence>\n<Scripted/>\n<Sequense/>\n</Sequence>', 3,
     ["unknown node type 'Sequense'", "did you mean 'Sequence'"]),
    ('<Sequence>\n<Scripted scirpt="S"/>\n</Sequence>', 2,
     ["Scripted", "unknown port 'scirpt'", "did you mean 'script'"]),
    ('<RateController hz="fast">\n<Scripted/>\n</RateController>', 1,
     ["RateController", "port 'hz'", "'fast'"]),
    ('<Echo out="literal"/>', 1, ["output port 'out'"]),
    ('<Inverter><Scripted/><Scripted/></Inverter>', 1, ["exactly one child, has 2"]),
    ('<RecoveryNode><Scripted/></RecoveryNode>', 1, ["RecoveryNode takes 2 children, has 1"]),
    ('<SubTree ID="Nope"/>', 1, ["SubTree 'Nope' is not defined"]),
    ('<Sequence _skipIf="x"><Scripted/></Sequence>', 1, ["'_skipIf' is not supported"]),
])
def test_load_errors_name_file_line_and_node(xml, line, words):
    body = f'<root BTCPP_format="4">\n<BehaviorTree ID="Main">\n{xml}\n</BehaviorTree>\n</root>'
    with pytest.raises(TreeError) as err:
        load(body)
    msg = str(err.value)
    assert msg.startswith(f"t.xml:{line + 2}: "), msg
    for w in words:
        assert w in msg, msg
    assert msg.count("\n") == 0


def test_missing_file_and_malformed_xml(tmp_path):
    f = BehaviorTreeFactory()
    with pytest.raises(TreeError, match=r"nope\.xml: behaviour tree file not found"):
        f.create_tree_from_file(tmp_path / "nope.xml")
    bad = tmp_path / "bad.xml"
    bad.write_text('<root>\n<BehaviorTree ID="M">\n<Sequence>\n</BehaviorTree>\n</root>\n')
    with pytest.raises(TreeError, match=r"bad\.xml:4: malformed XML"):
        f.create_tree_from_file(bad)


def test_include_and_recursive_subtree(tmp_path):
    (tmp_path / "lib.xml").write_text(
        '<root BTCPP_format="4"><BehaviorTree ID="Lib"><AlwaysSuccess/></BehaviorTree></root>')
    main = tmp_path / "main.xml"
    main.write_text('<root BTCPP_format="4" main_tree_to_execute="M"><include path="lib.xml"/>'
                    '<BehaviorTree ID="M"><SubTree ID="Lib"/></BehaviorTree></root>')
    assert BehaviorTreeFactory().create_tree_from_file(main).tick_once() == S
    loop = tmp_path / "loop.xml"
    loop.write_text('<root BTCPP_format="4" main_tree_to_execute="A">\n'
                    '<BehaviorTree ID="A"><SubTree ID="B"/></BehaviorTree>\n'
                    '<BehaviorTree ID="B"><SubTree ID="A"/></BehaviorTree>\n</root>')
    with pytest.raises(TreeError, match=r"loop\.xml:3: SubTree 'A' includes itself \(A -> B -> A\)"):
        BehaviorTreeFactory().create_tree_from_file(loop)


def test_plugin_lib_names_resolve_modules():
    f = BehaviorTreeFactory()
    f.load_plugin("nav2_compute_path_to_pose_action_bt_node")  # built in
    f.load_plugin("navnodes_bt_plugin")
    tree = f.create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><CountTicks limit="3"/></BehaviorTree>'
        '</root>', None, TreeContext())
    assert [tree.tick_once() for _ in range(3)] == [R, R, S]
    with pytest.raises(TreeError, match="'no_such_bt_plugin' is neither an entry point"):
        f.load_plugin("no_such_bt_plugin")


def test_timeout_halts_a_slow_child_and_delay_waits():
    clock = Clock()
    t = load('<Timeout msec="500"><Scripted name="x" script="R"/></Timeout>', clock)
    for _ in range(5):
        assert t.tick_once() == R
        clock.ns += 100_000_000
    assert t.tick_once() == F
    assert node(t, "x").halts == 1 and node(t, "x").ticks == 5
    clock = Clock()
    t = load('<Delay delay_msec="300"><Scripted name="x" script="S"/></Delay>', clock)
    statuses = []
    for _ in range(4):
        statuses.append(t.tick_once())
        clock.ns += 100_000_000
    assert statuses == [R, R, R, S] and node(t, "x").ticks == 1


def test_battery_conditions_read_the_last_battery_state():
    from eddiebot.msgs.sensor_msgs import BatteryState

    class Ctx(TreeContext):
        def latest(self, topic, msg_type=None):
            return msgs.get(topic)

    msgs = {}
    f = BehaviorTreeFactory()
    tree = f.create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="M"><Sequence><IsBatteryCharging/>'
        '<IsBatteryLow min_battery="0.2" battery_topic="/battery"/></Sequence></BehaviorTree>'
        '</root>', None, Ctx())
    assert tree.tick_once() == F  # nothing received yet
    msgs["/battery_status"] = BatteryState(
        power_supply_status=BatteryState.POWER_SUPPLY_STATUS_CHARGING)
    msgs["/battery"] = BatteryState(percentage=0.5)
    assert tree.tick_once() == F  # charging, not low
    msgs["/battery"] = BatteryState(percentage=0.15)
    assert tree.tick_once() == S


def test_plugin_lib_names_resolve_entry_points(tmp_path, monkeypatch):
    # a distribution on sys.path that declares its BT nodes as an entry point, as an
    # installed package of the user's would
    dist = tmp_path / "user_bt_nodes-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: user-bt-nodes\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[eddiebot.nav.bt_nodes]\nuser_counters = navnodes_bt_plugin:register_bt_nodes\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    f = BehaviorTreeFactory()
    assert "CountTicks" not in f.builders
    f.load_plugin("user_counters")
    assert "CountTicks" in f.builders


def test_tree_paths_resolve_to_the_shipped_nav2_trees(tmp_path):
    from eddiebot.nav.bt import TREES_DIR, resolve_tree_path

    assert len(list(TREES_DIR.glob("*.xml"))) == 12
    ros = "/opt/ros/jazzy/share/nav2_bt_navigator/behavior_trees/follow_point.xml"
    assert resolve_tree_path(ros) == TREES_DIR / "follow_point.xml"
    assert resolve_tree_path("follow_point.xml") == TREES_DIR / "follow_point.xml"
    mine = tmp_path / "follow_point.xml"
    mine.write_text("<root/>")
    assert resolve_tree_path(str(mine)) == mine  # an existing file is the user's
    assert resolve_tree_path("/elsewhere/follow_point.xml") == Path("/elsewhere/follow_point.xml")
