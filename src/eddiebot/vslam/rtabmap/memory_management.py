"""Memory glue: the likelihood of a new node against working memory, the Bayes filter's
neighbourhoods, retrieval from long-term memory around a hypothesis and transfer to it
(`Rtabmap/MemoryThr`, `Rtabmap/TimeThr`)."""

from __future__ import annotations

from eddiebot.vslam.bayes import tfidf_scores
from eddiebot.vslam.memory import Node
from eddiebot.vslam.rtabmap.state import RtabmapState


class MemoryManagement(RtabmapState):
    """Likelihood, retrieval and transfer between working and long-term memory."""

    def _likelihood_scores(self, node: Node, candidates: list[int]) -> dict[int, float]:
        mem = self.memory
        if self.params.kp_tf_idf_likelihood_used:
            n_nodes = len(mem.wm) + len(mem.stm)
            return tfidf_scores(node.word_counts, mem.inverted, mem.word_totals, n_nodes,
                                candidates)
        scores = {}
        n_new = sum(node.word_counts.values())
        for j in candidates:
            other = mem.nodes[j].word_counts
            common = sum(min(c, other.get(w, 0)) for w, c in node.word_counts.items())
            scores[j] = common / max(1, max(n_new, sum(other.values())))
        return scores

    def _bayes_neighbours(self, node_id: int, max_depth: int) -> dict[int, int]:
        """A node's neighbourhood in the Bayes prediction: loop partners at the same depth
        (upstream's `getNeighborsId` as `BayesFilter` calls it)."""
        return self.memory.neighbours(node_id, max_depth, loop_margin=True)

    def _retrieve_around(self, hyp_id: int) -> list[int]:
        mem = self.memory
        limit = self.params.rtabmap_max_retrieved
        if limit <= 0:
            return []
        frontier = [hyp_id]
        seen = {hyp_id}
        out: list[int] = []
        for _ in range(self.bayes.max_depth):
            nxt = []
            for n in frontier:
                # time neighbours (adjacent ids) first, then loop links
                for m in sorted(mem.links.get(n, ()), key=lambda k: (abs(k - n) != 1, k)):
                    if m in seen:
                        continue
                    seen.add(m)
                    nxt.append(m)
                    if m in mem.ltm and len(out) < limit and mem.retrieve(m):
                        out.append(m)
            if len(out) >= limit or not nxt:
                break
            frontier = nxt
        for m in out:
            self.bayes.node_entered(m, self._bayes_neighbours(m, self.bayes.max_depth))
        return out

    def _manage_memory(self, t0: float, protected: set[int]) -> int:
        p = self.params
        mem = self.memory
        elapsed_ms = (self._timer() - t0) * 1e3
        n = 0
        if p.rtabmap_memory_thr > 0 and len(mem.wm) > p.rtabmap_memory_thr:
            n = len(mem.wm) - p.rtabmap_memory_thr
        if p.rtabmap_time_thr > 0 and elapsed_ms > p.rtabmap_time_thr:
            n = max(n, 2)
        if n <= 0:
            return 0
        cands = mem.transfer_candidates(protected, p.mem_recent_wm_ratio, n,
                                        p.mem_transfer_sorting_by_weight_id)
        for i in cands:
            neighbourhood = self._bayes_neighbours(i, self.bayes.max_depth)
            mem.transfer_to_ltm(i)
            self.bayes.node_left(i, neighbourhood)
        return len(cands)
