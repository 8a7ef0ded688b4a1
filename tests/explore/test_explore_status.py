"""The explore node's status (explore/status) and its pause/resume (service and topic): the
values a user interface shows, and a resume that goes on with what the pause cancelled."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from eddiebot.core.context import Context
from eddiebot.explore.node import ExploreNode, ExploreState
from eddiebot.maps import OccupancyMap
from eddiebot.msgs.std_msgs import Bool
from eddiebot.msgs.std_srvs import SetBool


@pytest.fixture
def node() -> Iterator[ExploreNode]:
    context = Context()
    n = ExploreNode(context=context, parameter_overrides={"start_paused": True})
    yield n
    n.destroy_node()
    context.shutdown()


def call(node: ExploreNode, data: bool) -> Any:
    return node.status._on_call(SetBool.Request(data=data), SetBool.Response())


def test_status_values_say_state_areas_and_home(node: ExploreNode) -> None:
    assert node.paused and node.state is ExploreState.WAITING
    d = np.full((100, 200), -1, np.int8)  # 10 x 5 m, of which 4 x 5 m free, 1 x 5 m wall
    d[:, :80] = 0
    d[:, 80:100] = 100
    node.grid = OccupancyMap(d, 0.05)
    values = node.status.values()
    assert (values["state"], values["paused"], values["frontiers"]) == ("waiting", "true", "")
    assert (values["known_m2"], values["free_m2"]) == ("25.00", "20.00")
    assert node.status.message(values).message == "paused (waiting)"
    node.paused = False
    node.state = ExploreState.DONE
    node.finish_reason = "no reachable frontier left (2 too small)"
    node.returned_home = False
    msg = node.status.message(node.status.values())
    assert msg.message == "done: no reachable frontier left (2 too small), not home"
    assert msg.level == msg.WARN
    reply = call(node, True)
    assert not reply.success and reply.message.startswith("exploration finished (no reachable")


def test_service_pauses_and_resumes_like_the_topic(node: ExploreNode) -> None:
    reply = call(node, True)
    assert reply.success and reply.message == "exploring" and not node.paused
    reply = call(node, False)
    assert reply.success and reply.message == "paused" and node.paused


def test_resume_after_a_pause_goes_on_with_the_look_around_or_the_way_home(node: ExploreNode) -> None:
    sent: list[Any] = []
    node._send = lambda client, goal, on_result: sent.append(goal)  # type: ignore[method-assign]
    node.grid = OccupancyMap(np.zeros((80, 80), np.int8), 0.05)
    node.state = ExploreState.LOOK_AROUND  # the pause cancelled the spin
    node._on_resume(Bool(data=True))
    assert node.state is ExploreState.EXPLORING and sent == []
    node.initial_pose = (2.0, 2.0, 0.0)
    node.state = ExploreState.RETURNING
    node._on_resume(Bool(data=False))
    node._on_resume(Bool(data=True))
    assert len(sent) == 1  # the goal home again, to the start
    p = sent[0].pose.pose.position
    assert (p.x, p.y) == (2.0, 2.0)
    node._on_resume(Bool(data=True))  # not paused: nothing more
    assert len(sent) == 1
