"""Batched prediction-column updates give the posterior of the entry-by-entry updates, bit for bit."""

from collections.abc import Mapping

import numpy as np

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter
from eddiebot.vslam.parameters import RtabmapParameters


class _OneByOne(BayesFilter):
    """The previous `node_entered`: one `add_neighbour` per neighbour."""

    def node_entered(self, node_id: int, neighbourhood: Mapping[int, int]) -> None:
        for j, depth in neighbourhood.items():
            self.add_neighbour(j, node_id, depth)
        self.invalidate([node_id])


def link_neighbours(links: Mapping[int, set[int]], i: int, depth: int) -> dict[int, int]:
    """Breadth-first neighbours of ``i`` up to ``depth`` links, each at its first depth."""
    out: dict[int, int] = {}
    frontier = [i]
    for d in range(1, depth + 1):
        nxt = [m for n in frontier for m in sorted(links.get(n, ())) if m != i and m not in out]
        for m in nxt:
            out.setdefault(m, d)
        frontier = nxt
    return out


def test_node_entered_in_one_append_equals_one_by_one():
    rng = np.random.default_rng(4)
    lc = RtabmapParameters().prediction_lc()
    links: dict[int, set[int]] = {}

    def neighbours(i: int, depth: int) -> dict[int, int]:
        return link_neighbours(links, i, depth)

    fast, slow = BayesFilter(lc, 0.9), _OneByOne(lc, 0.9)
    wm: list[int] = []
    closures = 0
    for node in range(1, 121):
        links.setdefault(node, set())
        if node > 1:
            links[node].add(node - 1)
            links[node - 1].add(node)
        if node > 40 and rng.random() < 0.3:  # a loop closure to an older node
            old = int(rng.integers(1, node - 30))
            links[node].add(old)
            links[old].add(node)
            closures += 1
            for f in (fast, slow):
                f.invalidate([node, old])
        for f in (fast, slow):
            f.node_entered(node, {j: d for j, d in neighbours(node, f.max_depth).items() if j in wm})
        wm.append(node)
        if node % 25 == 0:  # a node leaves (long-term memory): retired entries, compaction
            gone = wm.pop(3)
            for f in (fast, slow):
                f.node_left(gone, neighbours(gone, f.max_depth))
        like = {VIRTUAL_PLACE_ID: 1.0, **{j: float(1.0 + 3.0 * rng.random() ** 8) for j in wm}}
        a = fast.update(like, neighbours)
        b = slow.update(like, neighbours)
        assert a == b  # same states, same values to the last bit
    assert closures > 15
    assert fast.highest_hypothesis()[1] > 0.0
