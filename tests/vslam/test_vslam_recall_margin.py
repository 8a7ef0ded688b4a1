"""Neighbourhoods of the Bayes prediction as upstream's `Memory::getNeighborsId(id, depth, 0,
incrementMarginOnLoop=false, ..., ignoreLocalSpaceLoopIds=true)`."""

import numpy as np
import pytest

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter
from eddiebot.vslam.memory import Link, LinkType, Memory, Node
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.transforms import from_xyz_yaw
from eddiebot.vslam.vocabulary import Vocabulary

LC = RtabmapParameters().prediction_lc()


def _two_passes() -> Memory:
    """Pass 1: nodes 1–10, pass 2: 11–20 along the same path (a chain of odometry links);
    12 closes on 3 (global closure) and 16 on 7 (proximity closure); STM holds 19, 20."""
    mem = Memory(Vocabulary(), stm_size=2)
    step = from_xyz_yaw(0.3, 0.0, 0.0)
    for i in range(1, 21):
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
        if i > 1:
            mem.add_link(Link(i - 1, i, LinkType.NEIGHBOR, step, np.eye(6)))
    mem.add_link(Link(12, 3, LinkType.GLOBAL_CLOSURE, np.eye(4), np.eye(6)))
    mem.add_link(Link(16, 7, LinkType.LOCAL_SPACE_CLOSURE, np.eye(4), np.eye(6)))
    return mem


def test_loop_partners_share_the_margin_and_proximity_links_are_not_followed():
    mem = _two_passes()
    got = mem.neighbours(3, 3, loop_margin=True)
    # 12 at depth 0 (its partner), then both passes' neighbours at the same depths
    assert got == {12: 0, 2: 1, 4: 1, 11: 1, 13: 1, 1: 2, 5: 2, 10: 2, 14: 2,
                   6: 3, 9: 3, 15: 3}
    # counted as one more link each (eddiebot's earlier walk), the proximity link followed
    old = mem.neighbours(3, 3)
    assert old[12] == 1 and old[11] == old[13] == 2 and old[14] == 3 and 15 not in old
    assert 16 not in got and mem.neighbours(7, 1, loop_margin=True) == {6: 1, 8: 1}
    assert 16 in mem.neighbours(7, 1)  # the proximity link is a link of depth 1 there
    # STM (19, 20) stays out
    assert not {19, 20} & set(mem.neighbours(18, 4, loop_margin=True))


def test_a_loop_partner_gets_the_place_s_own_prediction_value():
    mem = _two_passes()
    ids = sorted(mem.wm)
    bayes = BayesFilter(LC, 0.9)

    def neighbours(i, d):
        return mem.neighbours(i, d, loop_margin=True)

    flat = dict.fromkeys(ids, 1.0)
    bayes.update({VIRTUAL_PLACE_ID: 1e-13, **{i: (1.0 if i == 3 else 1e-13) for i in ids}},
                 neighbours)
    post = bayes.update({VIRTUAL_PLACE_ID: 1.0, **flat}, neighbours)
    # 3 and its partner 12 get PredictionLC[1] each, their neighbours PredictionLC[2] each
    assert post[12] == pytest.approx(post[3], rel=1e-12)
    assert post[2] == pytest.approx(post[4], rel=1e-12) == pytest.approx(post[11], rel=1e-12)
    assert post[2] / post[3] == pytest.approx(0.30 / 0.36, rel=1e-9)
    assert post[VIRTUAL_PLACE_ID] == pytest.approx(0.1, abs=1e-6)
