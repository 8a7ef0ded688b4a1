"""The memory's link index (what the graph update reads every node) stays exact under edits."""

import numpy as np

from eddiebot.vslam.memory import Link, LinkType, Memory, Node
from eddiebot.vslam.transforms import from_xyz_yaw
from eddiebot.vslam.vocabulary import Vocabulary


def _reference(mem: Memory, ids=None):
    """Each link once, from the lower id, straight from the per-node tables."""
    allowed = set(mem.links) if ids is None else set(ids)
    return {(a, b): lk for a, nb in mem.links.items() for b, lk in nb.items()
            if a < b and a in allowed and b in allowed}


def _key(lk: Link):
    return (lk.from_id, lk.to_id)


def test_unique_links_follow_adds_replacements_and_removals():
    rng = np.random.default_rng(3)
    mem = Memory(Vocabulary(), stm_size=3)
    for i in range(1, 41):
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
        if i > 1:
            mem.add_link(Link(i - 1, i, LinkType.NEIGHBOR, from_xyz_yaw(0.3, 0.0, 0.1), np.eye(6)))
    for _ in range(60):  # closures stored from either end, some replacing an existing link
        a, b = (int(v) for v in rng.choice(np.arange(1, 41), 2, replace=False))
        mem.add_link(Link(a, b, LinkType.GLOBAL_CLOSURE,
                          from_xyz_yaw(*rng.normal(0, 1, 3)), np.eye(6) * 7))
    for a, b in [(5, 6), (6, 5), (17, 30), (2, 2)]:
        mem.remove_link(a, b)
    for n in (9, 22, 40):
        mem.remove_node(n)
    ref = _reference(mem)
    got = mem.unique_links()
    assert len(got) == len(ref) > 30
    for lk in got:
        assert lk.from_id < lk.to_id
        assert lk is ref[_key(lk)]  # the very object the per-node table holds for (a, b)
    subset = set(range(1, 25))
    sub = mem.unique_links(subset)
    assert {_key(lk) for lk in sub} == set(_reference(mem, subset))
    assert not any(9 in k or 22 in k for k in map(_key, got))


def test_a_link_added_from_the_higher_id_is_returned_inverted():
    mem = Memory(Vocabulary(), stm_size=1)
    for i in (1, 2):
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
    t = from_xyz_yaw(1.0, 2.0, 0.5)
    mem.add_link(Link(2, 1, LinkType.GLOBAL_CLOSURE, t, np.eye(6)))
    (lk,) = mem.unique_links()
    assert (lk.from_id, lk.to_id) == (1, 2)
    np.testing.assert_allclose(lk.transform @ t, np.eye(4), atol=1e-12)


def _bfs_component(mem: Memory, node_id: int, within: set[int]) -> set[int]:
    seen, stack = {node_id}, [node_id]
    while stack:
        n = stack.pop()
        for m in mem.links.get(n, ()):
            if m in within and m not in seen:
                seen.add(m)
                stack.append(m)
    return seen


def test_kept_components_equal_a_graph_search_through_adds_and_removals():
    rng = np.random.default_rng(5)
    mem = Memory(Vocabulary(), stm_size=2)
    eye = np.eye(4)
    checked = 0
    for i in range(1, 121):
        mem.add_to_stm(Node(i, 0, 0, eye))
        if i % 30 != 1:  # four separate chains until closures join them
            mem.add_link(Link(i - 1, i, LinkType.NEIGHBOR, eye, np.eye(6)))
        if i > 40 and rng.random() < 0.15:
            j = int(rng.integers(1, i))
            mem.add_link(Link(i, j, LinkType.GLOBAL_CLOSURE, eye, np.eye(6)))
        if i in (50, 80):
            mem.remove_node(i - 3)  # splits a chain unless a closure bridges it
        if i in (60, 90, 110):
            lk = mem.unique_links([k for k in mem.nodes if k > i - 30])[0]
            mem.remove_link(lk.from_id, lk.to_id)
        everything = set(mem.nodes)
        for q in rng.choice(sorted(everything), 3):
            got = mem.component(int(q), everything)
            assert got == _bfs_component(mem, int(q), everything)
            checked += 1
        if i == 45:  # chains 1-30 and 91+ do not exist yet; 31-45 is apart from 1-30 or not
            parts = {frozenset(mem.component(k, everything)) for k in mem.nodes}
            assert sum(len(c) for c in parts) == len(mem.nodes) == 45
    parts = {frozenset(mem.component(k, set(mem.nodes))) for k in mem.nodes}
    assert sum(len(c) for c in parts) == len(mem.nodes) and checked == 360
    assert len(parts) >= 2  # removals left pieces apart

    class CountingLinks(dict):
        reads = 0

        def get(self, *args):
            CountingLinks.reads += 1
            return super().get(*args)

    mem.links = CountingLinks(mem.links)
    assert len(mem.component(1, set(mem.nodes))) > 10
    assert CountingLinks.reads == 0  # all nodes allowed: no graph search
    # a restricted set (nodes in LTM left out) takes the graph search
    within = {k for k in mem.nodes if k % 7}
    start = next(iter(within))
    assert mem.component(start, within) == _bfs_component(mem, start, within)
