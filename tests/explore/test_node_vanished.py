"""A target that stops showing ``min_gain`` on the way is dropped; a place dropped as often
as an idle frontier is reached is abandoned, so the robot does not shuttle between two."""

from __future__ import annotations

import numpy as np

from eddiebot.explore.frontiers import Frontier
from eddiebot.explore.node import _IDLE_VISITS, ExploreNode


def _frontier(x: float, y: float, gain: float) -> Frontier:
    return Frontier(points=np.array([[x, y]]), size=0.5, centroid=(x, y), entry=(x, y),
                    viewpoint=(x - 1.0, y, 0.0), distance=5.0, gain=gain, turn=0.0, cost=5.0 - gain)


def test_a_place_dropped_on_the_way_again_and_again_is_abandoned(node: ExploreNode) -> None:
    low = node.config.min_gain * 0.5
    limit = _IDLE_VISITS * node.config.max_visits
    for n in range(1, limit + 1):
        # the target, a little elsewhere each time (a new track for the same pocket), now
        # shows too little: dropped; the other place is chosen meanwhile
        node._target = 10 + n
        node._note_vanished([_frontier(4.0 + 0.05 * n, -7.0, low), _frontier(17.5, 7.1, 3.0)],
                            [10 + n, 1])
        assert len(node.vanished) == n
        assert node.blacklist.contains((4.0, -7.0)) == (n >= limit)
    assert not node.blacklist.contains((17.5, 7.1))
    assert "showed nothing on the way" in node.blacklist.entries[0].reason


def test_a_target_that_still_shows_enough_or_is_gone_counts_nothing(node: ExploreNode) -> None:
    node._target = 3
    node._note_vanished([_frontier(4.0, -7.0, node.config.min_gain)], [3])  # still enough
    node._note_vanished([_frontier(4.0, -7.0, 0.0)], [4])  # not the target: it is gone
    node._target = None
    node._note_vanished([_frontier(4.0, -7.0, 0.0)], [4])
    assert node.vanished == [] and len(node.blacklist) == 0
