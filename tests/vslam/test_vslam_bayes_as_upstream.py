"""Likelihood adjustment and prediction columns as upstream (RTAB-Map's Rtabmap::adjustLikelihood
and BayesFilter::normalize).

Neighbourhoods of the Bayes prediction as upstream's `Memory::getNeighborsId(id, depth, 0,
incrementMarginOnLoop=false, ..., ignoreLocalSpaceLoopIds=true)`."""

import math

import numpy as np
import pytest

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter, adjust_likelihood
from eddiebot.vslam.memory import Link, LinkType, Memory, Node
from eddiebot.vslam.parameters import RtabmapParameters
from eddiebot.vslam.transforms import from_xyz_yaw
from eddiebot.vslam.vocabulary import Vocabulary

LC = RtabmapParameters().prediction_lc()


def test_likelihood_adjustment_uses_the_sample_standard_deviation():
    like = adjust_likelihood({1: 0.1, 2: 0.2, 3: 0.6, 4: 0.0})
    mu, sigma = 0.3, math.sqrt(0.07)  # (0.04 + 0.01 + 0.09) / (3 − 1); population: 0.216
    assert like[3] == pytest.approx((0.6 - sigma + 1e-4) / mu, rel=1e-12)  # 1.1184 (1.2801)
    assert like[1] == like[2] == like[4] == 1.0
    assert like[VIRTUAL_PLACE_ID] == pytest.approx(mu / sigma + 1.0, rel=1e-12)  # 2.134 (2.389)
    # mode 1: (s − μ)/σ and σ/(max − μ) + 1 with the same σ
    like1 = adjust_likelihood({1: 0.1, 2: 0.2, 3: 0.6}, 1)
    assert like1[3] == pytest.approx((0.6 - mu) / sigma, rel=1e-12)
    assert like1[VIRTUAL_PLACE_ID] == pytest.approx(sigma / (0.6 - mu) + 1.0, rel=1e-12)
    # a single non-zero score has no spread: the virtual place gets 2
    assert adjust_likelihood({1: 0.3, 2: 0.0})[VIRTUAL_PLACE_ID] == 2.0


def _chain(ids, depth_max):
    """Neighbourhood function of a path graph over `ids` (link depth = index distance)."""
    def neighbours(i, depth):
        k = ids.index(i)
        return {j: abs(ids.index(j) - k) for j in ids
                if j != i and abs(ids.index(j) - k) <= min(depth, depth_max)}
    return neighbours


def _post_after_a_step_from(bayes, place, ids, neighbours):
    """Put the posterior on `place`, then one step with a flat likelihood: the posterior is the
    prediction column of `place`."""
    tiny = {i: (1.0 if i == place else 1e-13) for i in ids}
    bayes.update({VIRTUAL_PLACE_ID: 1e-13, **tiny}, neighbours)
    return bayes.update({VIRTUAL_PLACE_ID: 1.0, **dict.fromkeys(ids, 1.0)}, neighbours)


def test_missing_neighbour_mass_goes_to_the_place_itself():
    ids = [1, 2, 3]
    post = _post_after_a_step_from(BayesFilter(LC, 0.9), 1, ids, _chain(ids, 16))
    # column of 1: itself 0.36, depth 1 0.30, depth 2 0.16 = 0.82 < 0.9: +0.08 on itself
    assert post[VIRTUAL_PLACE_ID] == pytest.approx(0.1, abs=1e-6)
    assert post[1] == pytest.approx(0.44, abs=1e-6)  # scaled as a whole: 0.395
    assert post[2] == pytest.approx(0.30, abs=1e-6)  # 0.329
    assert post[3] == pytest.approx(0.16, abs=1e-6)  # 0.176
    # a place with neighbours to full depth on one side has nothing missing
    ids = list(range(1, 19))
    post = _post_after_a_step_from(BayesFilter(LC, 0.9), 1, ids, _chain(ids, 16))
    assert post[1] / post[2] == pytest.approx(0.36 / 0.30, rel=1e-9)


def test_a_short_column_is_rebuilt_when_a_neighbour_enters():
    ids = [1, 2, 3]
    bayes = BayesFilter(LC, 0.9)
    _post_after_a_step_from(bayes, 1, ids, _chain(ids, 16))
    ids4 = [1, 2, 3, 4]
    neighbours = _chain(ids4, 16)
    bayes.node_entered(4, neighbours(4, 16))
    # the posterior is still mostly on 1 (0.44 of it): its column now reaches 4 at depth 3
    post = bayes.update({VIRTUAL_PLACE_ID: 1.0, **dict.fromkeys(ids4, 1.0)}, neighbours)
    # the same as every column built again from the graph (full prediction update)
    full = BayesFilter(LC, 0.9)
    _post_after_a_step_from(full, 1, ids, _chain(ids, 16))
    full.invalidate(ids)
    ref = full.update({VIRTUAL_PLACE_ID: 1.0, **dict.fromkeys(ids4, 1.0)}, neighbours)
    assert all(post[i] == pytest.approx(ref[i], abs=1e-12) for i in ref)
    assert post[4] > 0.44 * 0.062  # from 1's column (and 2's, 3's)
    # 1's column: 0.36 + 0.30 + 0.16 + 0.062 = 0.882: +0.018 on itself (not 0.08 any more)
    step = _post_after_a_step_from(BayesFilter(LC, 0.9), 1, ids4, neighbours)
    assert step[1] == pytest.approx(0.378, abs=1e-6) and step[4] == pytest.approx(0.062, abs=1e-6)
    # a neighbour leaving makes the column short again
    bayes.node_left(4, [1, 2, 3])
    post = bayes.update({VIRTUAL_PLACE_ID: 1.0, **dict.fromkeys(ids, 1.0)}, _chain(ids, 16))
    again = _post_after_a_step_from(BayesFilter(LC, 0.9), 1, ids, _chain(ids, 16))
    assert again[1] == pytest.approx(0.44, abs=1e-6)
    assert set(post) == {VIRTUAL_PLACE_ID, 1, 2, 3}




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
