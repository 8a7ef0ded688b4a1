"""`Memory.neighbours(loop_margin=True)` in one pass over each node's links gives the same
{id: depth} — same entries, same insertion order — as the two-pass walk it replaced.

The compiled loop-margin walk (`Memory.neighbours(loop_margin=True)` over the adjacency
arrays `Memory` keeps beside its links dicts) gives the same {id: depth}, entry for entry and in
the same order, as the walk over the dicts, through link additions, replacements, removals and
node deletions."""

from __future__ import annotations

import numpy as np

from eddiebot.vslam.memory import Link, LinkType, Memory, Node
from eddiebot.vslam.vocabulary import Vocabulary


def _two_pass_reference(mem: Memory, node_id: int, max_depth: int, exclude_stm: bool,
                        wm_only: bool) -> dict[int, int]:
    """The walk as written before (loop partners first, then a second pass for odometry)."""
    stm = set(mem.stm) if exclude_stm else set()
    odometry = (LinkType.NEIGHBOR, LinkType.NEIGHBOR_MERGED)
    out: dict[int, int] = {}
    seen = {node_id}
    margin = [node_id]
    for depth in range(max_depth + 1):
        k = 0
        while k < len(margin):
            n = margin[k]
            k += 1
            for m, lk in mem.links.get(n, {}).items():
                if (m in seen or m in stm or lk.type in odometry
                        or lk.type == LinkType.LOCAL_SPACE_CLOSURE):
                    continue
                seen.add(m)
                if wm_only and m not in mem.wm:
                    continue
                out[m] = depth
                margin.append(m)
        if depth == max_depth:
            break
        nxt = []
        for n in margin:
            for m, lk in mem.links.get(n, {}).items():
                if m in seen or m in stm or lk.type not in odometry:
                    continue
                seen.add(m)
                if wm_only and m not in mem.wm:
                    continue
                out[m] = depth + 1
                nxt.append(m)
        if not nxt:
            break
        margin = nxt
    return out


def _random_map(rng: np.random.Generator, n: int) -> Memory:
    """A chain of odometry links (some merged) over several passes, with global, local-time,
    local-space and user closures between passes, a few nodes sent to LTM."""
    mem = Memory(Vocabulary(), stm_size=int(rng.integers(1, 6)))
    types = [LinkType.GLOBAL_CLOSURE, LinkType.LOCAL_SPACE_CLOSURE,
             LinkType.LOCAL_TIME_CLOSURE, LinkType.USER_CLOSURE]
    for i in range(1, n + 1):
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
        if i > 1 and rng.random() > 0.03:  # a few breaks in the chain
            kind = LinkType.NEIGHBOR_MERGED if rng.random() < 0.1 else LinkType.NEIGHBOR
            mem.add_link(Link(i - 1, i, kind, np.eye(4), np.eye(6)))
    for _ in range(n // 2):
        a, b = (int(v) for v in rng.integers(1, n + 1, size=2))
        if a != b:
            mem.add_link(Link(a, b, types[int(rng.integers(len(types)))], np.eye(4), np.eye(6)))
    for i in rng.choice(np.arange(1, n + 1), size=n // 10, replace=False):
        mem.wm.pop(int(i), None)  # in LTM: walked through, not returned when wm_only
    return mem


def test_one_pass_walk_matches_the_two_pass_walk_entry_for_entry():
    rng = np.random.default_rng(8)
    compared = deeper = 0
    for _ in range(30):
        mem = _random_map(rng, int(rng.integers(20, 120)))
        for node_id in rng.choice(sorted(mem.nodes), size=8):
            for depth in (0, 1, 2, 5):
                for exclude_stm in (True, False):
                    for wm_only in (True, False):
                        want = _two_pass_reference(mem, int(node_id), depth, exclude_stm, wm_only)
                        got = mem.neighbours(int(node_id), depth, exclude_stm=exclude_stm,
                                             wm_only=wm_only, loop_margin=True)
                        assert list(got.items()) == list(want.items())
                        compared += 1
                        deeper += any(v >= 2 for v in want.values())
    assert compared == 30 * 8 * 16 and deeper > 500  # most walks reach past the first ring


_TYPES = [LinkType.GLOBAL_CLOSURE, LinkType.LOCAL_SPACE_CLOSURE, LinkType.LOCAL_TIME_CLOSURE,
          LinkType.USER_CLOSURE, LinkType.NEIGHBOR, LinkType.NEIGHBOR_MERGED]


def _link(a: int, b: int, kind: LinkType) -> Link:
    return Link(a, b, kind, np.eye(4), np.eye(6))


def _mutated_map(rng: np.random.Generator, n: int) -> Memory:
    mem = Memory(Vocabulary(), stm_size=int(rng.integers(1, 6)))
    for i in range(1, n + 1):
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
        if i > 1 and rng.random() > 0.03:
            kind = LinkType.NEIGHBOR_MERGED if rng.random() < 0.1 else LinkType.NEIGHBOR
            mem.add_link(_link(i - 1, i, kind))
    for _ in range(n):
        a, b = (int(v) for v in rng.integers(1, n + 1, size=2))
        r = rng.random()
        if r < 0.6:  # new link or a replaced one (its type may change, its place stays)
            mem.add_link(_link(a, b, _TYPES[int(rng.integers(len(_TYPES)))]))
        elif r < 0.85:  # removal (re-added later: goes last)
            mem.remove_link(a, b)
        elif r < 0.9 and a in mem.nodes:
            mem.remove_node(a)
    for i in rng.choice(sorted(mem.nodes), size=len(mem.nodes) // 10, replace=False):
        mem.transfer_to_ltm(int(i)) if int(i) in mem.wm else None
    return mem


def test_compiled_walk_matches_the_dict_walk_entry_for_entry():
    rng = np.random.default_rng(15)
    compared = deeper = 0
    for _ in range(25):
        mem = _mutated_map(rng, int(rng.integers(20, 150)))
        assert mem._adjacency.usable
        for node_id in rng.choice(sorted(mem.nodes), size=6):
            for depth in (0, 1, 3, 14):
                for exclude_stm in (True, False):
                    for wm_only in (True, False):
                        want = mem._neighbours_loop_margin_walk(int(node_id), depth, exclude_stm,
                                                                wm_only)
                        got = mem.neighbours(int(node_id), depth, exclude_stm=exclude_stm,
                                             wm_only=wm_only, loop_margin=True)
                        assert list(got.items()) == list(want.items())
                        compared += 1
                        deeper += any(v >= 3 for v in want.values())
    assert compared == 25 * 6 * 16 and deeper > 300


def test_adjacency_rows_follow_the_links_dict_order():
    rng = np.random.default_rng(3)
    mem = _mutated_map(rng, 80)
    adj = mem._adjacency
    for i, row in mem.links.items():
        d = int(adj.deg[i])
        assert adj.nbr[i, :d].tolist() == list(row)


def test_sparse_ids_fall_back_to_the_dict_walk():
    mem = Memory(Vocabulary(), stm_size=1)
    ids = [1, 2, 10_000_000, 10_000_001]
    for i in ids:
        mem.add_to_stm(Node(i, 0, 0, np.eye(4)))
    for a, b in zip(ids[:-1], ids[1:]):
        mem.add_link(_link(a, b, LinkType.NEIGHBOR))
    mem.add_link(_link(1, 10_000_001, LinkType.GLOBAL_CLOSURE))
    assert not mem._adjacency.usable
    assert mem.neighbours(1, 2, loop_margin=True) == {2: 1, 10_000_000: 2}  # STM cut out
    assert mem.neighbours(1, 2, exclude_stm=False, wm_only=False, loop_margin=True) == {
        10_000_001: 0, 2: 1, 10_000_000: 1}
