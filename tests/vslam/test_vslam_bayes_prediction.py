"""The Bayes filter's compiled prediction pass gives bit for bit the numpy formulation.

Batched prediction-column updates give the posterior of the entry-by-entry updates, bit for bit.

The prediction with the column sums kept as entries come and go (one compiled pass over the
live entries) gives the posterior of the pass that sums the whole table, bit for bit, through
closures (invalidated columns), nodes entering and leaving (single retired entries) and
compactions of the table."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from vslam_synthetic import graph_neighbours

from eddiebot.vslam import bayes as bayes_module
from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter
from eddiebot.vslam.parameters import RtabmapParameters


def _run(monkeypatch, compiled: bool, offset: int = 0):
    """120 steps on a chain with random loop links and nodes leaving WM; ids shifted by
    `offset` (a huge offset makes ids too sparse for the dense table)."""
    if not compiled:
        monkeypatch.setattr(bayes_module, "_dense_table", lambda states, max_id: None)
    lc = RtabmapParameters().prediction_lc()
    rng = np.random.default_rng(11)
    links: dict[int, set[int]] = {}
    wm: set[int] = set()

    def neighbours(i, depth_max):
        return graph_neighbours(links, wm, i, depth_max)

    bf = BayesFilter(lc, 0.9)
    posts = []
    for k in range(offset + 1, offset + 121):
        if k > offset + 1:
            links.setdefault(k - 1, set()).add(k)
            links.setdefault(k, set()).add(k - 1)
        if k > offset + 40 and rng.random() < 0.4:
            j = int(rng.integers(offset + 1, k - 20))
            links[k].add(j)
            links.setdefault(j, set()).add(k)
            bf.invalidate([k, j])
        if k > offset + 10:
            wm.add(k - 10)
            bf.node_entered(k - 10, neighbours(k - 10, bf.max_depth))
        if k > offset + 70 and (k - offset) % 9 == 0:
            gone = int(rng.choice(sorted(wm)))
            near = neighbours(gone, bf.max_depth)
            wm.discard(gone)
            bf.node_left(gone, near)
        if not wm:
            continue
        like = {i: float(rng.choice([1.0, 1.0, 2.0 + 6.0 * rng.random()])) for i in sorted(wm)}
        like[VIRTUAL_PLACE_ID] = 1.0 + rng.random()
        post = bf.update(like, neighbours)
        # the hypothesis straight from the arrays: top location (lowest id on ties), 1 − P(vp)
        best = max((i for i in post if i != VIRTUAL_PLACE_ID), key=lambda i: post[i], default=0)
        assert bf.highest_hypothesis() == (best, 1.0 - post[VIRTUAL_PLACE_ID])
        posts.append(post)
    return posts


def test_compiled_prediction_equals_the_gathers_exactly(monkeypatch):
    fast = _run(monkeypatch, compiled=True)
    with monkeypatch.context() as m:
        slow = _run(m, compiled=False)
    assert len(fast) == len(slow) == 110
    for a, b in zip(fast, slow):
        assert a.keys() == b.keys()
        assert all(a[k] == b[k] for k in a)  # bit-identical, not just close
    last = fast[-1]
    assert len(last) > 80 and 0.0 < last[VIRTUAL_PLACE_ID] < 1.0
    tied = BayesFilter(RtabmapParameters().prediction_lc(), 0.9)
    tied.update({7: 1.0, 3: 1.0, 5: 1.0, VIRTUAL_PLACE_ID: 1.0}, lambda i, d: {})
    tied.update({7: 1.0, 3: 1.0, 5: 1.0, VIRTUAL_PLACE_ID: 1.0}, lambda i, d: {})
    assert tied.highest_hypothesis()[0] == 3


def test_sparse_ids_fall_back_and_agree(monkeypatch):
    calls = []
    real = bayes_module._predict_entries

    def spy(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(bayes_module, "_predict_entries", spy)
    dense = _run(monkeypatch, compiled=True)
    assert calls  # the compiled pass ran
    calls.clear()
    sparse = _run(monkeypatch, compiled=True, offset=10**7)
    assert not calls  # ids ~10⁷ with ~100 states: searchsorted lookup instead of a table
    for a, b in zip(dense, sparse):
        va = [a[k] for k in sorted(a)]
        vb = [b[k] for k in sorted(b)]
        # (neighbour sets iterate in another order with other ids: equal up to rounding)
        np.testing.assert_allclose(va, vb, rtol=1e-12, atol=0.0)


def _adjust_reference(scores, mode):
    """RTAB-Map's adjustment written out score by score."""
    values = [v for v in scores.values() if v > 0.0]
    out = dict.fromkeys(scores, 1.0)
    if not values:
        out[VIRTUAL_PLACE_ID] = 2.0
        return out
    mu = float(np.mean(values))
    sigma = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
    for k, s in scores.items():
        if s > mu + sigma:
            out[k] = (s - mu) / sigma if mode == 1 else (s - sigma + 1e-4) / mu
    if sigma > 1e-4:
        top = max(values)
        out[VIRTUAL_PLACE_ID] = (sigma / (top - mu) + 1.0 if top > mu else 2.0) if mode == 1 \
            else mu / sigma + 1.0
    else:
        out[VIRTUAL_PLACE_ID] = 2.0
    return out


def test_adjusted_likelihood_equals_the_score_by_score_formula():
    from eddiebot.vslam.bayes import adjust_likelihood

    rng = np.random.default_rng(2)
    for trial in range(30):
        n = int(rng.integers(1, 300))
        ids = rng.permutation(np.arange(1, 2 * n + 1))[:n].tolist()
        vals = np.where(rng.random(n) < 0.3, 0.0, rng.gamma(1.0, 0.02, n))
        scores = dict(zip(ids, vals.tolist()))
        for mode in (0, 1):
            got = adjust_likelihood(scores, mode)
            ref = _adjust_reference(scores, mode)
            assert list(got) == list(ref)  # same keys, same order
            assert all(got[k] == ref[k] for k in ref), (trial, mode)
    assert adjust_likelihood({3: 0.0, 4: 0.0}) == {3: 1.0, 4: 1.0, VIRTUAL_PLACE_ID: 2.0}


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


def test_kept_column_sums_give_the_same_posterior():
    rng = np.random.default_rng(15)
    lc = RtabmapParameters().prediction_lc()
    links: dict[int, set[int]] = {}

    def neighbours(i: int, depth: int) -> dict[int, int]:
        return link_neighbours(links, i, depth)

    kept, summed = BayesFilter(lc, 0.9), BayesFilter(lc, 0.9)
    summed._col_sum_ok = False  # the pass that sums the table
    wm: list[int] = []
    compactions = 0
    for node in range(1, 261):
        links.setdefault(node, set())
        if node > 1:
            links[node].add(node - 1)
            links[node - 1].add(node)
        if node > 40 and rng.random() < 0.4:  # a loop closure to an older node
            old = int(rng.integers(1, node - 30))
            links[node].add(old)
            links[old].add(node)
            for f in (kept, summed):
                f.invalidate([node, old])
        for f in (kept, summed):
            f.node_entered(node, {j: d for j, d in neighbours(node, f.max_depth).items() if j in wm})
        wm.append(node)
        if node % 3 == 0 and len(wm) > 20:  # a node leaves: single entries retired
            gone = wm.pop(int(rng.integers(0, len(wm) - 10)))
            for f in (kept, summed):
                f.node_left(gone, neighbours(gone, f.max_depth))
        if node % 50 == 0:  # as when the table grows with half its entries retired
            for f in (kept, summed):
                f._compact()
            compactions += 1
        like = {VIRTUAL_PLACE_ID: 1.0, **{j: float(1.0 + 3.0 * rng.random() ** 8) for j in wm}}
        a = kept.update(like, neighbours)
        b = summed.update(like, neighbours)
        assert list(a.items()) == list(b.items())  # same states, same values to the last bit
    assert kept._col_sum_ok and compactions == 5 and kept._n > 30_000
    ids = np.array(list(kept._columns))
    table_sums = np.bincount(kept._e_col[: kept._n], kept._e_raw[: kept._n], minlength=ids.max() + 1)
    assert np.array_equal(kept._col_sum[ids], table_sums[ids])  # np.bincount adds in order too
