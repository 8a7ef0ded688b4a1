"""nav2_behavior_tree's own unit cases for its control nodes (Jazzy
``test/plugins/control/test_pipeline_sequence.cpp``, ``test_round_robin_node.cpp``,
``test_recovery_node.cpp``), as data: each step sets the children's statuses, ticks the
node once and checks its result and the children's statuses after.

Letters: I idle, R running, S success, F failure, K skipped, ``-`` left as it is.
"""

from typing import ClassVar

import pytest

from eddiebot.nav.bt import BehaviorTreeFactory, LeafNode, Status, TreeContext

ST = {"I": Status.IDLE, "R": Status.RUNNING, "S": Status.SUCCESS, "F": Status.FAILURE,
      "K": Status.SKIPPED}


class Dummy(LeafNode):
    """nav2's DummyNode: ticks return the status it was given; halting does nothing. With
    ``success_on``/``failure_on`` (RecoveryDummy) the n-th tick sets that status."""

    PORTS: ClassVar = {}

    def __init__(self, *args):
        super().__init__(*args)
        self.ticks = 0
        self.success_on = -1
        self.failure_on = -1

    def tick(self):
        if self.ticks == self.success_on:
            self.status = Status.SUCCESS
        elif self.ticks == self.failure_on:
            self.status = Status.FAILURE
        self.ticks += 1
        return self.status


def _tree(xml):
    f = BehaviorTreeFactory()
    f.register_node_type("Dummy", Dummy)
    tree = f.create_tree_from_text(
        f'<root BTCPP_format="4"><BehaviorTree ID="T">{xml}</BehaviorTree></root>', None,
        TreeContext(clock=lambda: 0))
    kids = [tree.find(n)[0] for n in ("c1", "c2", "c3") if tree.find(n)]
    return tree, kids


def _set(kids, statuses):
    for k, s in zip(kids, statuses):
        if s != "-":
            k.status = ST[s]


def _run(xml, steps):
    tree, kids = _tree(xml)
    for i, (before, result, after) in enumerate(steps):
        _set(kids, before)
        if result == "error":
            with pytest.raises(RuntimeError):
                tree.tick_once()
            continue
        assert tree.tick_once() == ST[result], f"step {i}"
        if after:
            assert "".join(k.status.value[0] if k.status != Status.SKIPPED else "K"
                           for k in kids) == after, f"step {i}"


THREE = '<{0}><Dummy name="c1"/><Dummy name="c2"/><Dummy name="c3"/></{0}>'

PIPELINE = {
    "test_failure_on_idle_child": [("I--", "error", None)],
    "test_failure": [
        ("F--", "F", "III"),
        ("SF-", "F", "III"),
        ("SSF", "F", "III"),
        ("SSR", "R", None),
        ("F--", "F", "III"),
    ],
    "test_behavior": [
        ("RII", "R", None),
        ("SRI", "R", None),
        ("RSR", "R", None),
        ("RSS", "S", "III"),
    ],
    "test_skipped": [
        ("KSS", "S", "III"),
        ("KSF", "F", "III"),
        ("KKK", "K", "III"),
    ],
}

ROUND_ROBIN = {
    "test_failure_on_idle_child": [("I--", "error", None)],
    "test_failure": [
        ("FR-", "R", None),
        ("-FR", "R", None),
        ("--F", "F", "III"),
    ],
    "test_behavior": [
        ("RII", "R", None),
        ("FRI", "R", None),
        ("FSI", "S", None),
        ("IIR", "R", None),
        ("RIF", "R", None),
        ("FSF", "S", "III"),
    ],
    "test_skipped": [
        ("KSF", "S", "III"),
        ("KKF", "F", "III"),
        ("KKK", "K", "III"),
    ],
}


@pytest.mark.parametrize("case", sorted(PIPELINE))
def test_pipeline_sequence(case):
    _run(THREE.format("PipelineSequence"), PIPELINE[case])


@pytest.mark.parametrize("case", sorted(ROUND_ROBIN))
def test_round_robin(case):
    _run(THREE.format("RoundRobin"), ROUND_ROBIN[case])


RECOVERY = '<RecoveryNode number_of_retries="1"><Dummy name="c1"/><Dummy name="c2"/></RecoveryNode>'


def test_recovery_running():
    _run(RECOVERY, [("R-", "R", None), ("FR", "R", None)])


def test_recovery_failure_on_idle_child():
    _run(RECOVERY, [("I-", "error", None), ("FI", "error", None)])


def test_recovery_success_one_retry():
    tree, (first, second) = _tree(RECOVERY)
    _set((first, second), "S-")
    assert tree.tick_once() == Status.SUCCESS
    first.success_on, first.ticks = 1, 0
    _set((first, second), "FS")
    assert tree.tick_once() == Status.SUCCESS
    assert (first.status, second.status) == (Status.IDLE, Status.IDLE)


def test_recovery_failure_one_retry():
    tree, (first, second) = _tree(RECOVERY)
    _set((first, second), "FF")
    assert tree.tick_once() == Status.FAILURE
    assert (first.status, second.status) == (Status.IDLE, Status.IDLE)
    first.failure_on, first.ticks = 1, 0
    _set((first, second), "FS")
    assert tree.tick_once() == Status.FAILURE
    assert (first.status, second.status) == (Status.IDLE, Status.IDLE)


def test_recovery_skipping():
    tree, (first, second) = _tree(RECOVERY)
    _set((first, second), "KS")
    assert tree.tick_once() == Status.SKIPPED
    assert (first.status, second.status) == (Status.IDLE, Status.IDLE)
    _set((first, second), "FK")
    assert tree.tick_once() == Status.FAILURE
    assert (first.status, second.status) == (Status.IDLE, Status.IDLE)


# -- decorators, conditions, actions ------------------------------------------------------
class Clock:
    def __init__(self):
        self.ns = 0

    def __call__(self):
        return self.ns


def _decorated(xml, clock, speed=lambda: 0.0, bb=None):
    f = BehaviorTreeFactory()
    f.register_node_type("Dummy", Dummy)
    tree = f.create_tree_from_text(
        f'<root BTCPP_format="4"><BehaviorTree ID="T">{xml}</BehaviorTree></root>', bb,
        TreeContext(clock=clock, speed=speed))
    return tree, tree.find("c1")[0]


def test_speed_controller():
    """test_speed_controller.cpp: the period follows the odometry's speed (0.223 m/s → about
    2 s, 0 m/s → 10 s)."""
    clock, speed = Clock(), [0.223]
    tree, dummy = _decorated('<SpeedController><Dummy name="c1"/></SpeedController>', clock,
                             lambda: speed[0])
    s = 1_000_000_000
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS
    assert dummy.status == Status.IDLE
    assert tree.tick_once() == Status.RUNNING  # the first period is 1 s
    dummy.status = Status.SUCCESS
    clock.ns += s
    assert tree.tick_once() == Status.SUCCESS  # new period from 0.223 m/s: ~2 s
    speed[0] = 0.0
    clock.ns += s
    assert tree.tick_once() == Status.RUNNING
    dummy.status = Status.SUCCESS
    clock.ns += s
    assert tree.tick_once() == Status.SUCCESS  # new period from 0 m/s: 10 s
    for _ in range(9):
        clock.ns += s
        assert tree.tick_once() == Status.RUNNING
    dummy.status = Status.SUCCESS
    clock.ns += s
    assert tree.tick_once() == Status.SUCCESS


def test_single_trigger():
    tree, dummy = _decorated('<SingleTrigger><Dummy name="c1"/></SingleTrigger>', Clock())
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS
    assert dummy.status == Status.IDLE
    assert tree.tick_once() == Status.FAILURE
    assert tree.tick_once() == Status.FAILURE
    tree.halt()
    dummy.status = Status.RUNNING
    assert tree.tick_once() == Status.RUNNING
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS
    assert tree.tick_once() == Status.FAILURE


def test_rate_controller_hz_10():
    """test_rate_controller.cpp: hz 10, the child reached again once 100 ms passed."""
    clock = Clock()
    tree, dummy = _decorated('<RateController hz="10"><Dummy name="c1"/></RateController>',
                             clock)
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS
    for _ in range(9):
        clock.ns += 10_000_000
        assert tree.tick_once() == Status.RUNNING  # dummy is IDLE: never ticked
    clock.ns += 10_000_000
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS


CONDITION_MAPS = {
    # FollowPath: NONE, UNKNOWN, INVALID_CONTROLLER, TF_ERROR, INVALID_PATH,
    # PATIENCE_EXCEEDED, FAILED_TO_MAKE_PROGRESS, NO_VALID_CONTROL
    "WouldAControllerRecoveryHelp": {0: "F", 100: "S", 101: "F", 102: "F", 103: "F", 104: "S",
                                     105: "S", 106: "S"},
    # ComputePathToPose: NONE, UNKNOWN, NO_VALID_PATH (and the through-poses twins)
    "WouldAPlannerRecoveryHelp": {0: "F", 200: "S", 208: "S", 204: "F", 206: "F", 300: "S",
                                  308: "S", 304: "F"},
    # SmoothPath: NONE, UNKNOWN, TIMEOUT, FAILED_TO_SMOOTH_PATH, SMOOTHED_PATH_IN_COLLISION
    "WouldASmootherRecoveryHelp": {0: "F", 500: "S", 502: "S", 504: "S", 503: "S"},
}


@pytest.mark.parametrize("node", sorted(CONDITION_MAPS))
def test_would_a_recovery_help(node):
    from eddiebot.nav.bt import Blackboard

    bb = Blackboard()
    tree = BehaviorTreeFactory().create_tree_from_text(
        f'<root BTCPP_format="4"><BehaviorTree ID="T"><{node} error_code="{{error_code}}"/>'
        f'</BehaviorTree></root>', bb, TreeContext())
    for code, want in CONDITION_MAPS[node].items():
        bb.set("error_code", code)
        assert tree.tick_once() == ST[want], (node, code)


def test_are_error_codes_present():
    from eddiebot.nav.bt import Blackboard

    bb = Blackboard()
    bb.set("error_codes_to_check", {100})  # ActionResult::UNKNOWN
    tree = BehaviorTreeFactory().create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><AreErrorCodesPresent '
        'error_code="{error_code}" error_codes_to_check="{error_codes_to_check}"/>'
        '</BehaviorTree></root>', bb, TreeContext())
    for code, want in ((0, Status.FAILURE), (100, Status.SUCCESS)):
        bb.set("error_code", code)
        assert tree.tick_once() == want


def test_truncate_path():
    """test_truncate_path_action.cpp: (0,0) (0.5,0) (0.9,0) (1.5,0.5) cut by 1.0 m keeps two
    poses, the last facing the old end (yaw 0.463)."""
    import math

    from eddiebot.msgs.nav_msgs import Path
    from eddiebot.nav.bt import Blackboard
    from eddiebot.nav.nodes._common import pose_stamped

    bb = Blackboard()
    path = Path()
    path.poses = [pose_stamped(x, y, 0.0, "map", 0) for x, y in
                  ((0.0, 0.0), (0.5, 0.0), (0.9, 0.0), (1.5, 0.5))]
    bb.set("path", path)
    tree = BehaviorTreeFactory().create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><TruncatePath distance="1.0" '
        'input_path="{path}" output_path="{truncated_path}"/></BehaviorTree></root>', bb,
        TreeContext())
    assert tree.tick_once() == Status.SUCCESS
    out = bb.get("truncated_path")
    assert len(out.poses) == 2 and len(path.poses) == 4
    q = out.poses[-1].pose.orientation
    assert abs(2 * math.atan2(q.z, q.w) - 0.463) < 0.001


def test_goal_updated_and_globally_updated_goal():
    """test_goal_updated.cpp / test_globally_updated_goal.cpp: GoalUpdated fails on its
    first tick and succeeds once the goal changed; GlobalUpdatedGoal succeeds on its very
    first tick."""
    from eddiebot.nav.bt import Blackboard
    from eddiebot.nav.nodes._common import pose_stamped

    for node, first in (("GoalUpdated", Status.FAILURE), ("GlobalUpdatedGoal", Status.SUCCESS)):
        bb = Blackboard()
        bb.set("goal", pose_stamped(1.0, 1.0, 0.0, "map", 0))
        bb.set("goals", [])
        tree = BehaviorTreeFactory().create_tree_from_text(
            f'<root BTCPP_format="4"><BehaviorTree ID="T"><{node}/></BehaviorTree></root>',
            bb, TreeContext())
        assert tree.tick_once() == first, node
        assert tree.tick_once() == Status.FAILURE, node
        bb.set("goal", pose_stamped(2.0, 1.0, 0.0, "map", 0))
        assert tree.tick_once() == Status.SUCCESS, node
        assert tree.tick_once() == Status.FAILURE, node


def test_path_expiring_timer():
    """test_path_expiring_timer.cpp: SUCCESS once ``seconds`` passed; a new path restarts
    the timer."""
    from eddiebot.msgs.nav_msgs import Path
    from eddiebot.nav.bt import Blackboard
    from eddiebot.nav.nodes._common import pose_stamped

    clock, bb = Clock(), Blackboard()
    bb.set("path", Path())
    tree = BehaviorTreeFactory().create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><PathExpiringTimer seconds="1.0" '
        'path="{path}"/></BehaviorTree></root>', bb, TreeContext(clock=clock))
    assert tree.tick_once() == Status.FAILURE
    for _ in range(9):
        clock.ns += 100_000_000
        assert tree.tick_once() == Status.FAILURE
    clock.ns += 100_000_000
    assert tree.tick_once() == Status.SUCCESS
    clock.ns += 900_000_000
    new = Path()
    new.poses = [pose_stamped(1.0, 0.0, 0.0, "map", 0)]
    bb.set("path", new)
    assert tree.tick_once() == Status.FAILURE  # restarted by the new path
    clock.ns += 500_000_000
    assert tree.tick_once() == Status.FAILURE
    clock.ns += 500_000_000
    assert tree.tick_once() == Status.SUCCESS


class PoseContext(TreeContext):
    """A context whose robot stands where the test puts it."""

    def __init__(self, pose=(0.0, 0.0, 0.0)):
        super().__init__(clock=lambda: 0)
        self.pose = pose

    def robot_pose(self, global_frame=None, base_frame=None):
        return self.pose


def test_distance_controller():
    """test_distance_controller.cpp: the robot moves 0.51 m at a time; the child (distance
    1.0) is ticked every second step."""
    ctx = PoseContext()
    f = BehaviorTreeFactory()
    f.register_node_type("Dummy", Dummy)
    tree = f.create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><DistanceController distance="1.0">'
        '<Dummy name="c1"/></DistanceController></BehaviorTree></root>', None, ctx)
    dummy = tree.find("c1")[0]
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS
    assert dummy.status == Status.IDLE
    for i in range(1, 21):
        ctx.pose = (i * 0.51, 0.0, 0.0)
        dummy.status = Status.SUCCESS
        if i % 2:
            assert tree.tick_once() == Status.RUNNING, i
        else:
            assert tree.tick_once() == Status.SUCCESS, i
            assert dummy.status == Status.IDLE


def test_goal_updated_controller():
    from eddiebot.nav.bt import Blackboard
    from eddiebot.nav.nodes._common import pose_stamped

    bb = Blackboard()
    bb.set("goal", pose_stamped(0.0, 0.0, 0.0, "map", 0))
    bb.set("goals", [])
    f = BehaviorTreeFactory()
    f.register_node_type("Dummy", Dummy)
    tree = f.create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><GoalUpdatedController>'
        '<Dummy name="c1"/></GoalUpdatedController></BehaviorTree></root>', bb, TreeContext())
    dummy = tree.find("c1")[0]
    goal2 = pose_stamped(0.0, 0.0, 0.0, "map", 5)
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS  # first tick: the child runs
    bb.set("goal", goal2)
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS  # updated goal: the child runs
    assert tree.tick_once() == Status.RUNNING  # no update: the child is not ticked
    assert dummy.status == Status.IDLE
    bb.set("goals", [goal2])
    dummy.status = Status.SUCCESS
    assert tree.tick_once() == Status.SUCCESS  # updated goals


def test_remove_passed_goals():
    """test_remove_passed_goals_action.cpp: robot at (0.25, 0), radius 0.5: of the goals at
    x = 0, 0.5, 1, 2 the first two are passed."""
    from eddiebot.nav.bt import Blackboard
    from eddiebot.nav.nodes._common import pose_stamped

    bb = Blackboard()
    poses = [pose_stamped(x, 0.0, 0.0, "map", 0) for x in (0.0, 0.5, 1.0, 2.0)]
    bb.set("goals", poses)
    tree = BehaviorTreeFactory().create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><RemovePassedGoals radius="0.5" '
        'input_goals="{goals}" output_goals="{goals}"/></BehaviorTree></root>', bb,
        PoseContext((0.25, 0.0, 0.0)))
    assert tree.tick_once() == Status.SUCCESS
    assert bb.get("goals") == poses[2:]


def test_follow_path_keeps_its_path_when_the_planner_writes_an_empty_one():
    """Nav2's FollowPathAction::on_wait_for_result: a new path preempts the running goal, a
    default Path (what a failed ComputePathToPose writes) does not; the controller keeps the
    last good path while the planner's recovery retries."""
    from eddiebot.msgs.nav_msgs import Path
    from eddiebot.nav.nodes._common import pose_stamped

    f = BehaviorTreeFactory()
    tree = f.create_tree_from_text(
        '<root BTCPP_format="4"><BehaviorTree ID="T"><FollowPath name="follow" path="{path}"/>'
        '</BehaviorTree></root>', None, TreeContext(clock=lambda: 0))
    (node,) = tree.find("follow")
    from eddiebot.msgs.nav2_msgs import FollowPath

    node.goal = FollowPath.Goal()
    good = Path()
    good.header.frame_id = "map"
    good.poses = [pose_stamped(0.0, 0.0, 0.0, "map"), pose_stamped(1.0, 0.0, 0.0, "map")]
    node.goal.path = good
    tree.blackboard.set("path", Path())
    node.on_wait_for_result()
    assert not node.goal_updated and node.goal.path is good
    better = Path()
    better.header.frame_id = "map"
    better.poses = [pose_stamped(0.0, 0.0, 0.0, "map"), pose_stamped(2.0, 0.0, 0.0, "map")]
    tree.blackboard.set("path", better)
    node.on_wait_for_result()
    assert node.goal_updated and node.goal.path is better
