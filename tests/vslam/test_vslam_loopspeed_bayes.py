"""The prediction with the column sums kept as entries come and go (one compiled pass over the
live entries) gives the posterior of the pass that sums the whole table, bit for bit, through
closures (invalidated columns), nodes entering and leaving (single retired entries) and
compactions of the table."""

from __future__ import annotations

import numpy as np
from test_vslam_speed_bayes import link_neighbours

from eddiebot.vslam.bayes import VIRTUAL_PLACE_ID, BayesFilter
from eddiebot.vslam.parameters import RtabmapParameters


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
