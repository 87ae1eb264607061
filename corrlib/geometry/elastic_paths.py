"""Cyclic paths with costs on consecutive edges: the elastic 2D-to-3D energy.

The first-order product graph (:mod:`corrlib.geometry.cyclic_paths`) cannot
tell a curve of the query's shape from one that runs back and forth over a
few vertices, so its optimum collapses (measured: docs/methods.md, ``corr
bench-contour``). Following the conjugate product graph of Roetzer, Lähner
and Bernard (*Conjugate Product Graphs for Globally Optimal 2D-3D Shape
Matching*, CVPR 2023), whose nodes are the edges of the product graph, a
state here remembers the last move of the path in the graph: state
``(i, e)`` is curve point ``i`` at the head ``j`` of the directed graph edge
``e = (u -> j)`` by which the path last moved on the graph. From it the path
may

* stay on ``j`` and advance on the curve (the memory ``e`` is kept),
* move to a neighbour ``k != u`` with or without advancing on the curve
  (no immediate reversal ``u -> j -> u``).

The cost of a move of curve length ``a`` and graph length ``b`` is

    c̄ · sqrt(a² + b²)  +  w_s · |b − a|  +  w_b · (1 − cos θ),

the paper's term (mean node cost times product length, thesis Eq. 7.1), a
stretching term that is zero for a locally isometric match, and, for a graph
move, a bending term with θ the turning angle between ``e`` and the new edge.
All costs are non-negative, so every layer is a Dijkstra over the directed
edges; the first-order graph with the same ``w_s`` and without bending or the
reversal rule is a relaxation, and its exact cost-to-go is the admissible A*
heuristic. The closed-path branch-and-bound of :mod:`cyclic_paths` runs
unchanged on the start *vertices*: a path closes where it started, and it
starts without a memory (states ``E + v``: at vertex ``v``, no graph move
yet), so its first move is not charged for bending and the turn at the seam
is not charged either. Reversing a closed path therefore keeps its energy,
and a mirrored query matches the same curve with the same energy.
"""

from __future__ import annotations

import heapq
import time

import numba
import numpy as np

from corrlib.errors import Cancelled, ParameterError
from corrlib.geometry.cyclic_paths import CyclicPath, ProductGraph


@numba.njit(cache=True, nogil=True)
def _turn_cosines(indptr, indices, tail, points):
    """(E, max degree) float: cos of the turning angle from directed edge e into each out-edge of its head."""
    n_edges = indices.shape[0]
    max_degree = 0
    for v in range(indptr.shape[0] - 1):
        max_degree = max(max_degree, indptr[v + 1] - indptr[v])
    out = np.ones((n_edges, max_degree))
    for e in range(n_edges):
        j, u = indices[e], tail[e]
        din = points[j] - points[u]
        din /= max(np.sqrt(np.sum(din * din)), 1e-300)
        for q in range(indptr[j], indptr[j + 1]):
            dout = points[indices[q]] - points[j]
            dout /= max(np.sqrt(np.sum(dout * dout)), 1e-300)
            out[e, q - indptr[j]] = np.sum(din * dout)
    return out


@numba.njit(inline="always")
def _within_layer_move(e, q, j, memory, layer_cost, indices, indptr, edge_len, cos_turn, stretch, bend):
    """Cost of the move from state ``e`` (at vertex ``j``) along CSR edge ``q`` within a layer: the node costs
    and stretching along the edge, and the bending of the turn where ``e`` remembers its incoming edge."""
    move = (0.5 * (layer_cost[j] + layer_cost[indices[q]]) + stretch) * edge_len[q]
    if memory:
        move += bend * (1.0 - cos_turn[e, q - indptr[j]])
    return move


@numba.njit(inline="always")
def _state_improves_a_successor(e, d, layer_cost, h, upper, indptr, indices, tail, edge_len, cos_turn, n_edges,
                                stretch, bend):
    """Whether state ``e`` lowers a successor's distance ``d`` along a within-layer move (below ``upper`` with
    the heuristic ``h``). A state that does not, and is never lowered itself, relaxes nothing later either
    (distances only decrease), so the layer's Dijkstra need not start from it."""
    memory = e < n_edges
    j = indices[e] if memory else e - n_edges
    u = tail[e] if memory else -1
    for q in range(indptr[j], indptr[j + 1]):
        k = indices[q]
        if k == u:
            continue
        through_e = d[e] + _within_layer_move(e, q, j, memory, layer_cost, indices, indptr, edge_len, cos_turn,
                                              stretch, bend)
        if through_e < d[q] and through_e + h[k] < upper:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _elastic_layered_dijkstra(cost, step, indptr, indices, tail, edge_len, cos_turn, source_mask, target_mask,
                              upper, heuristic, stretch, bend, cancel, dist, pred, origin, gain):
    """Multi-source shortest paths over (layer, directed edge) states; returns (best end state, its cost).

    The layer-by-layer scheme of :func:`~corrlib.geometry.cyclic_paths._layered_dijkstra`
    over a larger state space, unrolled as its own kernel so that the
    first-order kernel keeps its tight loops.

    ``dist``/``pred``/``origin`` (L, S) are overwritten, S = E + n (the
    directed edges, then a memoryless state per vertex): distance,
    predecessor (``p`` within the layer, ``S + p`` from state p of the
    previous layer, -1 for a start state) and start vertex. ``heuristic`` (L, n) bounds the
    remaining cost from a vertex from below; states whose distance plus it
    reaches ``upper`` are pruned. Returns (-2, inf) when cancelled, (-1, inf)
    when no path below ``upper`` exists. ``gain`` credits every step that
    advances along curve and graph with ``-gain * min(a, b)``, as the
    first-order kernel does (the ratio energy's parametric problem).
    """
    n_layers = cost.shape[0]
    n_edges = indices.shape[0]
    n_states = dist.shape[1]  # n_edges directed edges, then one memoryless state per vertex
    inf = np.inf
    for i in range(n_layers):
        if cancel[0] != 0:
            return -2, inf
        d = dist[i]
        p = pred[i]
        o = origin[i]
        d[:] = inf
        p[:] = -1
        o[:] = -1
        h = heuristic[i]
        layer_cost = cost[i]
        heap = [(0.0, 0)]
        heap.pop()
        if i == 0:
            for j in range(n_states - n_edges):
                if source_mask[j] and h[j] < upper:
                    d[n_edges + j] = 0.0
                    o[n_edges + j] = j
                    heap.append((0.0, n_edges + j))
        else:
            a = step[i - 1]
            dprev = dist[i - 1]
            oprev = origin[i - 1]
            for e in range(n_states):
                de = dprev[e]
                if de == inf:
                    continue
                memory = e < n_edges
                j = indices[e] if memory else e - n_edges
                u = tail[e] if memory else -1
                cj = cost[i - 1, j]
                nd = de + (0.5 * (cj + cost[i, j]) + stretch) * a  # stay on j
                if nd < d[e] and nd + h[j] < upper:
                    d[e] = nd
                    p[e] = n_states + e
                    o[e] = oprev[e]
                for q in range(indptr[j], indptr[j + 1]):
                    k = indices[q]
                    if k == u:
                        continue
                    b = edge_len[q]
                    nd = (de + 0.5 * (cj + cost[i, k]) * np.sqrt(a * a + b * b) + stretch * abs(b - a)
                          - gain * min(a, b))
                    if memory:
                        nd += bend * (1.0 - cos_turn[e, q - indptr[j]])
                    if nd < d[q] and nd + h[k] < upper:
                        d[q] = nd
                        p[q] = n_states + e
                        o[q] = oprev[e]
            for e in range(n_states):  # seeds: the states that lower a successor within the layer now
                if d[e] < inf and _state_improves_a_successor(e, d, layer_cost, h, upper, indptr, indices, tail,
                                                              edge_len, cos_turn, n_edges, stretch, bend):
                    heap.append((d[e], e))
        heapq.heapify(heap)
        while len(heap) > 0:
            de, e = heapq.heappop(heap)
            if de > d[e]:
                continue
            memory = e < n_edges
            j = indices[e] if memory else e - n_edges
            u = tail[e] if memory else -1
            for q in range(indptr[j], indptr[j + 1]):
                k = indices[q]
                if k == u:
                    continue
                nd = de + _within_layer_move(e, q, j, memory, layer_cost, indices, indptr, edge_len, cos_turn,
                                             stretch, bend)
                if nd < d[q] and nd + h[k] < upper:
                    d[q] = nd
                    p[q] = e
                    o[q] = o[e]
                    heapq.heappush(heap, (nd, q))
    best = inf
    best_state = -1
    last = dist[n_layers - 1]
    for e in range(n_states):
        j = indices[e] if e < n_edges else e - n_edges
        if target_mask[j] and last[e] < best:
            best = last[e]
            best_state = e
    return best_state, best


class ElasticProductGraph(ProductGraph):
    """Product of a closed curve with a graph, with stretching, bending and no immediate reversal.

    Same interface as :class:`~corrlib.geometry.cyclic_paths.ProductGraph`
    (so :func:`~corrlib.geometry.cyclic_paths.branch_and_bound` finds its
    globally optimal closed path); see the module docstring for the energy.

    Parameters
    ----------
    node_cost, curve_points, graph_points, adjacency
        As for :class:`ProductGraph` (undirected graphs only).
    stretch : float
        ``w_s`` ≥ 0.
    bending : float
        ``w_b`` ≥ 0.
    """

    def __init__(self, node_cost, curve_points, graph_points, adjacency, *, stretch: float, bending: float):
        super().__init__(node_cost, curve_points, graph_points, adjacency, stretch=stretch)
        if not (np.isfinite(bending) and bending >= 0):
            raise ParameterError(f"bending must be finite and non-negative, got {bending}")
        self.bending = float(bending)
        self.step = np.ascontiguousarray(np.sqrt(self.step2))
        self.tail = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr))
        self.cos_turn = _turn_cosines(self.indptr, self.indices, self.tail, self.graph_points)
        n_states = self.indices.shape[0] + self.n
        self.state_dist = np.empty((self.m + 1, n_states))
        self.state_pred = np.empty((self.m + 1, n_states), dtype=np.int64)
        self.state_origin = np.empty((self.m + 1, n_states), dtype=np.int32)
        self._end_state = -1

    def shortest(self, sources: np.ndarray, targets: np.ndarray, upper: float = np.inf,
                 cancel: np.ndarray | None = None) -> tuple[float, int, int]:
        """Shortest path from any ``(0, s in sources)`` to any ``(m, t in targets)`` (vertex masks)."""
        flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
        start = time.perf_counter()
        state, c = _elastic_layered_dijkstra(self.cost, self.step, self.indptr, self.indices, self.tail,
                                             self.edge_len, self.cos_turn, sources, targets, float(upper),
                                             self.heuristic, self.stretch, self.bending, flag, self.state_dist,
                                             self.state_pred, self.state_origin, self.gain)
        self.runs += 1
        self.run_seconds += time.perf_counter() - start
        if state == -2:
            raise Cancelled("the computation was cancelled")
        self._end_state = int(state)
        if state < 0:
            return np.inf, -1, -1
        return float(c), int(self.state_origin[self.m, state]), self._vertex(state)

    def _vertex(self, state: int) -> int:
        n_edges = self.indices.shape[0]
        return int(self.indices[state]) if state < n_edges else int(state - n_edges)

    def close_by_detour(self, open_path: CyclicPath) -> tuple[float, CyclicPath | None]:
        """No closing walk: its turns and reversals would need the second-order energy ((inf, None))."""
        return np.inf, None

    def backtrack(self, end: int) -> CyclicPath:
        """The path found by the last :meth:`shortest` run (which ended at vertex ``end``)."""
        state = self._end_state
        if state < 0 or self._vertex(state) != int(end):
            raise ValueError("backtrack() follows the shortest() run that ended at this vertex")
        n_states = self.state_dist.shape[1]
        layer = self.m
        layers, vertices = [layer], [self._vertex(state)]
        energy = float(self.state_dist[layer, state])
        while True:
            p = int(self.state_pred[layer, state])
            if p < 0:
                break
            if p >= n_states:
                layer, state = layer - 1, p - n_states
            else:
                state = p
            layers.append(layer)
            vertices.append(self._vertex(state))
        return CyclicPath(np.array(vertices[::-1], dtype=np.int64), np.array(layers[::-1], dtype=np.int64), energy)

    def path_energy(self, path: CyclicPath) -> float:
        """The elastic energy of a path, recomputed step by step (independent check of the search)."""
        points = self.graph_points
        total = 0.0
        previous = -1  # vertex the path last came from on the graph (-1: no graph move yet)
        for s in range(len(path.vertices) - 1):
            i0, j0, i1, j1 = path.layers[s], path.vertices[s], path.layers[s + 1], path.vertices[s + 1]
            a = self.step[i0] if i1 == i0 + 1 else 0.0
            b = float(np.linalg.norm(points[j1] - points[j0]))
            total += 0.5 * (self.cost[i0, j0] + self.cost[i1, j1]) * np.sqrt(a * a + b * b)
            total += self.stretch * abs(b - a)
            if j1 == j0:
                continue
            if j1 == previous:
                return np.inf  # an immediate reversal is not a path of this graph
            if previous >= 0:
                into = points[j0] - points[previous]
                total += self.bending * (1.0 - (points[j1] - points[j0]) @ into / (b * np.linalg.norm(into)))
            previous = j0
        return float(total - self.gain * self.credited_length(path))
