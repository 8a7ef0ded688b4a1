"""Short-term, working and long-term memory of graph nodes (RTAB-Map's memory management).

* STM: the last `Mem/STMSize` nodes; never loop-closure candidates.
* WM: loop-closure candidates (Bayes states), with their words in the inverted index.
* LTM: nodes transferred out of WM; their heavy data (features, words, grid) leaves RAM when a
  `NodeStore` (the session database) holds it, and comes back on retrieval. Poses and links of
  every node stay in RAM (a few hundred bytes each).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import NDArray

from eddiebot.vslam.link_index import LinkIndex, link_kind, walk_loop_margin
from eddiebot.vslam.nodes import ODOMETRY_LINK_TYPES, Link, LinkType, Node, NodeData, NodeStore
from eddiebot.vslam.vocabulary import Vocabulary

__all__ = ["Link", "LinkType", "Memory", "Node", "NodeData", "NodeStore"]

F64 = NDArray[np.float64]


class Memory:
    """Nodes, links, STM/WM/LTM membership, inverted word index and transfers."""

    def __init__(self, vocabulary: Vocabulary, stm_size: int, store: NodeStore | None = None):
        self.vocabulary = vocabulary
        self.stm_size = stm_size
        self.store = store
        self.nodes: dict[int, Node] = {}
        self.links: dict[int, dict[int, Link]] = {}
        self._pairs: dict[tuple[int, int], Link] = {}  # (a, b), a < b → links[a][b]
        self.stm: list[int] = []
        self.wm: dict[int, int] = {}  # id → insertion counter
        self.ltm: set[int] = set()
        #: upstream's `_lastGlobalLoopClosureId`: the newer node of the last accepted closure
        self.last_loop_closure_id = 0
        self._wm_counter = 0
        self.inverted: dict[int, dict[int, int]] = {}
        self.word_totals: dict[int, int] = {}
        # connected components of all nodes (union-find with member lists), kept by
        # `add_link`; any removal drops it and the next `component` call rebuilds it
        self._uf_parent: dict[int, int] = {}
        self._uf_members: dict[int, list[int]] = {}
        self._uf_valid = False
        self._adjacency = LinkIndex()  # `links` as arrays, for the loop-margin walk
        # pairs (a < b) of the links added since `take_link_log`, or None once anything else
        # changed the graph in RAM (a link or node left, a node entered other than as new)
        self._link_log: list[tuple[int, int]] | None = None

    # -- membership -------------------------------------------------------------------------
    @property
    def wm_ids(self) -> list[int]:
        """Working-memory ids, oldest insertion first."""
        return list(self.wm)

    def in_memory(self, node_id: int) -> bool:
        """In STM or WM."""
        return node_id in self.wm or node_id in self.stm

    def _index_words(self, node: Node) -> None:
        for w, c in node.word_counts.items():
            self.inverted.setdefault(w, {})[node.id] = c
        self.word_totals[node.id] = max(1, sum(node.word_counts.values()))
        if node.data is not None:
            self.vocabulary.add_references(node.data.words)

    def _unindex_words(self, node: Node) -> None:
        for w in node.word_counts:
            postings = self.inverted.get(w)
            if postings is not None:
                postings.pop(node.id, None)
                if not postings:
                    del self.inverted[w]
        self.word_totals.pop(node.id, None)
        if node.data is not None:
            self.vocabulary.remove_references(node.data.words)

    def take_link_log(self) -> list[tuple[int, int]] | None:
        """The pairs (a < b, in order) of the links added since the last call, or None when
        the graph of the nodes in RAM changed otherwise meanwhile (a link replaced or removed,
        a node removed, a node moved between WM and LTM, a node entered with links already);
        starts a new log either way."""
        log = self._link_log
        self._link_log = []
        return log

    def _register(self, node: Node) -> None:
        known = node.id in self.nodes or bool(self.links.get(node.id))
        if known:
            self._link_log = None
        self.nodes[node.id] = node
        if node.id not in self.links:
            self.links[node.id] = {}
            self._adjacency.register(node.id)
        if self._uf_valid:
            if known:
                self._uf_valid = False
            else:
                self._uf_parent[node.id] = node.id
                self._uf_members[node.id] = [node.id]

    def add_to_stm(self, node: Node) -> list[int]:
        """Insert a new node; returns the ids that moved from STM to WM."""
        self._register(node)
        self.stm.append(node.id)
        self._index_words(node)
        moved = []
        while len(self.stm) > self.stm_size:
            oldest = self.stm.pop(0)
            self._add_to_wm(oldest)
            moved.append(oldest)
        return moved

    def add_to_wm(self, node: Node) -> None:
        """Insert a node straight into WM (database load, retrieval)."""
        self._link_log = None
        self._register(node)
        self.ltm.discard(node.id)
        self._index_words(node)
        self._add_to_wm(node.id)

    def _add_to_wm(self, node_id: int) -> None:
        self._wm_counter += 1
        self.wm[node_id] = self._wm_counter

    def add_ltm_node(self, node: Node) -> None:
        """Register a node that stays in LTM (poses and links only)."""
        node.data = None
        node.word_counts = {}
        self._link_log = None
        self._register(node)
        self.ltm.add(node.id)

    def remove_node(self, node_id: int) -> None:
        """Delete a node (not kept in the map) and its links."""
        node = self.nodes.pop(node_id, None)
        if node is None:
            return
        self._uf_valid = False
        self._link_log = None
        if node_id in self.stm:
            self.stm.remove(node_id)
        self.wm.pop(node_id, None)
        self.ltm.discard(node_id)
        self._unindex_words(node)
        for other in list(self.links.get(node_id, {})):
            self.links.get(other, {}).pop(node_id, None)
            self._adjacency.pop(other, node_id)
            self._pairs.pop((min(node_id, other), max(node_id, other)), None)
        self.links.pop(node_id, None)
        self._adjacency.clear(node_id)

    # -- links ------------------------------------------------------------------------------
    def add_link(self, link: Link) -> None:
        """Add a link (stored under both ends)."""
        a, b = link.from_id, link.to_id
        kind = link_kind(link.type)
        adjacency = self._adjacency
        for i in (a, b):
            if i not in self.links:
                self.links[i] = {}
                adjacency.register(i)
        self.links[a][b] = link
        adjacency.put(a, b, kind)
        inverse = link.inverse()
        self.links[b][a] = inverse
        adjacency.put(b, a, kind)
        if a != b:
            pair = (a, b) if a < b else (b, a)
            if self._link_log is not None:
                if pair in self._pairs:  # a replaced link (its type may move it in the graph)
                    self._link_log = None
                else:
                    self._link_log.append(pair)
            self._pairs[pair] = link if a < b else inverse
            if self._uf_valid:
                if a in self.nodes and b in self.nodes:
                    self._uf_union(a, b)
                else:
                    self._uf_valid = False

    def remove_link(self, a: int, b: int) -> None:
        """Remove the link between two nodes."""
        self._link_log = None
        if self.links.get(a, {}).pop(b, None) is not None:
            self._adjacency.pop(a, b)
        if self.links.get(b, {}).pop(a, None) is not None:
            self._adjacency.pop(b, a)
        if self._pairs.pop((a, b) if a < b else (b, a), None) is not None:
            self._uf_valid = False

    def unique_links(self, ids: Iterable[int] | None = None) -> list[Link]:
        """Each link once (from < to orientation as stored by `from_id`), among `ids` if given."""
        if ids is None:
            return list(self._pairs.values())
        allowed = ids if isinstance(ids, (set, frozenset)) else set(ids)
        return [link for (a, b), link in self._pairs.items() if a in allowed and b in allowed]

    def neighbours(self, node_id: int, max_depth: int, *, exclude_stm: bool = True,
                   wm_only: bool = True, loop_margin: bool = False) -> dict[int, int]:
        """Breadth-first {id: depth} over links up to `max_depth` (STM cut out of the search).

        `loop_margin`: as upstream's `Memory::getNeighborsId` for the Bayes prediction
        (`incrementMarginOnLoop` false, `ignoreLocalSpaceLoopIds` true): a loop-closure link
        keeps the depth of the node it leaves (a place's loop partners are at depth 0, and
        their neighbours at the depths of its own), a proximity link is not followed, and
        only odometry links add one.
        """
        if loop_margin:
            return self._neighbours_loop_margin(node_id, max_depth, exclude_stm, wm_only)
        stm = set(self.stm) if exclude_stm else set()
        out: dict[int, int] = {}
        frontier = [node_id]
        seen = {node_id}
        for depth in range(1, max_depth + 1):
            nxt = []
            for n in frontier:
                for m in self.links.get(n, ()):
                    if m in seen or m in stm:
                        continue
                    seen.add(m)
                    if wm_only and m not in self.wm:
                        continue
                    out[m] = depth
                    nxt.append(m)
            if not nxt:
                break
            frontier = nxt
        return out

    def _neighbours_loop_margin(self, node_id: int, max_depth: int, exclude_stm: bool,
                                wm_only: bool) -> dict[int, int]:
        adjacency = self._adjacency
        if adjacency.usable:
            in_stm = adjacency.members(self.stm if exclude_stm else (), len(self.stm)
                                       if exclude_stm else 0)
            in_wm = adjacency.members(self.wm, len(self.wm))
            if in_stm is not None and in_wm is not None:
                ids, depths = walk_loop_margin(adjacency.nbr, adjacency.kind, adjacency.deg,
                                                node_id, max_depth, in_stm, in_wm, wm_only)
                return dict(zip(ids.tolist(), depths.tolist()))
        return self._neighbours_loop_margin_walk(node_id, max_depth, exclude_stm, wm_only)

    def _neighbours_loop_margin_walk(self, node_id: int, max_depth: int, exclude_stm: bool,
                                     wm_only: bool) -> dict[int, int]:
        """The loop-margin walk over the links dicts (when ids do not suit `LinkIndex`)."""
        stm = set(self.stm) if exclude_stm else set()
        odometry = ODOMETRY_LINK_TYPES
        local_space = LinkType.LOCAL_SPACE_CLOSURE
        links, wm = self.links, self.wm
        out: dict[int, int] = {}
        seen = {node_id}
        margin = [node_id]
        for depth in range(max_depth + 1):
            # one pass over each margin node's links: loop partners join the margin being
            # walked; odometry neighbours are kept, in the order met, for the next depth
            odo: list[int] = []
            k = 0
            while k < len(margin):
                n = margin[k]
                k += 1
                for m, lk in links.get(n, {}).items():
                    t = lk.type
                    if t in odometry:
                        odo.append(m)
                        continue
                    if m in seen or m in stm or t == local_space:
                        continue
                    seen.add(m)
                    if wm_only and m not in wm:
                        continue
                    out[m] = depth
                    margin.append(m)
            if depth == max_depth:
                break
            nxt = []
            for m in odo:
                if m in seen or m in stm:
                    continue
                seen.add(m)
                if wm_only and m not in wm:
                    continue
                out[m] = depth + 1
                nxt.append(m)
            if not nxt:
                break
            margin = nxt
        return out

    def component(self, node_id: int, within: set[int]) -> set[int]:
        """Nodes connected to `node_id` through links among `within`.

        When `within` holds every node (no node in LTM), the answer comes from components kept
        up to date as links are added (a set copy instead of a graph search).
        """
        if node_id in within and len(within) >= len(self.nodes) and self.nodes.keys() <= within:
            if not self._uf_valid:
                self._uf_rebuild()
            return set(self._uf_members[self._uf_find(node_id)])
        seen = {node_id}
        stack = [node_id]
        while stack:
            n = stack.pop()
            for m in self.links.get(n, ()):
                if m in within and m not in seen:
                    seen.add(m)
                    stack.append(m)
        return seen

    def _uf_find(self, i: int) -> int:
        parent = self._uf_parent
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:  # path compression
            parent[i], i = root, parent[i]
        return root

    def _uf_union(self, a: int, b: int) -> None:
        ra, rb = self._uf_find(a), self._uf_find(b)
        if ra == rb:
            return
        members = self._uf_members
        if len(members[ra]) < len(members[rb]):
            ra, rb = rb, ra
        self._uf_parent[rb] = ra
        members[ra].extend(members.pop(rb))

    def _uf_rebuild(self) -> None:
        self._uf_parent = {i: i for i in self.nodes}
        self._uf_members = {i: [i] for i in self.nodes}
        self._uf_valid = True
        nodes = self.nodes
        for a, b in self._pairs:
            if a in nodes and b in nodes:
                self._uf_union(a, b)

    # -- weights (rehearsal, loop closures) -------------------------------------------------
    def similarity(self, a: Node, b: Node) -> float:
        """Upstream's `Signature::compareTo` on words: word pairs (a word seen n times in one
        and m in the other makes min(n, m) pairs) over the larger count of valid words."""
        na, nb = sum(a.word_counts.values()), sum(b.word_counts.values())
        if na == 0 or nb == 0:
            return 0.0
        small, large = ((a.word_counts, b.word_counts) if len(a.word_counts) <= len(b.word_counts)
                        else (b.word_counts, a.word_counts))
        pairs = sum(min(c, large.get(w, 0)) for w, c in small.items())
        return pairs / max(na, nb)

    def rehearsal(self, node: Node, threshold: float, moving: bool | None,
                  ignored_while_moving: bool = False) -> tuple[int, float, bool]:
        """Upstream's `Memory::rehearsal` (`Mem/RehearsalIdUpdatedToNewOne` false): compare a
        new STM node with the previous one in STM; at `threshold` similarity or more, the
        previous node takes the new one's weight plus one. `moving`: whether the odometry
        link between them exceeds `RGBD/LinearUpdate|AngularUpdate` (None: no such link).
        Returns (the previous node's id if its weight rose, similarity, merged): merged (not
        moving, linked) means the new node is the same place and is to be removed; otherwise
        the new node's weight is reset to 0."""
        if not node.word_counts:
            return 0, 0.0, False
        prev = next((self.nodes[i] for i in reversed(self.stm)
                     if i != node.id and self.nodes[i].weight >= 0), None)
        if prev is None:
            return 0, 0.0, False
        sim = self.similarity(node, prev)
        if sim < threshold:
            return 0, sim, False
        if moving and ignored_while_moving:
            return 0, sim, False
        prev.weight += max(node.weight, 0) + 1
        merged = moving is False
        node.weight = 0
        return prev.id, sim, merged

    def closure_weights(self, link: Link) -> None:
        """An accepted loop closure (not virtual): as upstream's `Memory::addLink`, the newer
        node takes the older one's weight (which drops to 0) and becomes the last loop
        closure id (the start of the recent part of WM)."""
        a, b = self.nodes.get(link.from_id), self.nodes.get(link.to_id)
        if a is None or b is None or link.type == LinkType.VIRTUAL_CLOSURE:
            return
        new, old = (a, b) if a.id > b.id else (b, a)
        new.weight += max(old.weight, 0)
        old.weight = 0
        self.last_loop_closure_id = new.id

    # -- transfer / retrieval ---------------------------------------------------------------
    def transfer_candidates(self, ignored: set[int], recent_ratio: float, count: int,
                            sort_by_weight_id: bool = False) -> list[int]:
        """Up to `count` WM ids to transfer to LTM, as upstream's
        `Memory::getRemovableSignatures`: lowest weight first, then earliest entry into WM
        (or lowest id with `sort_by_weight_id`), then lowest id. Never transferred: `ignored`
        ids, nodes linked to a node in STM (or to the oldest one in STM), the last loop
        closure's node, and, while the nodes entered after it hold less than `recent_ratio`
        of WM, those nodes (`Mem/RecentWmRatio`)."""
        if not self.wm or count <= 0:
            return []
        wm_ids = sorted(self.wm)
        recent_max = int(recent_ratio * len(wm_ids))
        last = self.last_loop_closure_id
        immunized = False
        current_recent = 0
        stm = set(self.stm)
        if last > 0 and last not in stm and last in self.wm:
            current_recent = len(wm_ids) - wm_ids.index(last)
            immunized = 1 < current_recent < recent_max
        oldest_stm = min(stm) if stm else None
        linked_oldest = set(self.links.get(oldest_stm, ())) if oldest_stm is not None else set()
        keys = []
        for i in wm_ids:
            if (immunized and i > last) or i == last or i in ignored or i in linked_oldest:
                continue
            if any(m in stm for m in self.links.get(i, ())):
                continue
            w = self.nodes[i].weight
            if w >= 0:
                keys.append((w, 0 if sort_by_weight_id else self.wm[i], i))
        keys.sort()
        out: list[int] = []
        recent_count = 0
        for _, _, i in keys:
            if not immunized:
                out.append(i)
                if last and i > last:
                    recent_count += 1
                    if current_recent - recent_count < recent_max:
                        immunized = True
            elif last == 0 or i < last:
                out.append(i)
            if len(out) >= count:
                break
        return out

    def transfer_to_ltm(self, node_id: int) -> None:
        """Move a WM node to LTM; its data leaves RAM when a store holds it."""
        node = self.nodes[node_id]
        self._link_log = None
        self.wm.pop(node_id, None)
        self._unindex_words(node)
        self.ltm.add(node_id)
        if self.store is not None:
            node.data = None

    def retrieve(self, node_id: int) -> bool:
        """Bring an LTM node back into WM; False if its data cannot be loaded."""
        node = self.nodes.get(node_id)
        if node is None or node_id not in self.ltm:
            return False
        if node.data is None:
            if self.store is None:
                return False
            data = self.store.load_node_data(node_id)
            if data is None:
                return False
            node.data = data
            node.word_counts = data.word_counts()
        self.ltm.discard(node_id)
        self._link_log = None
        self._index_words(node)
        self._add_to_wm(node_id)
        return True
