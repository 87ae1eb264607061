"""Cyclic shortest paths on the product of a closed curve with a graph (thesis ch. 7, CVPR 2016).

The product graph has a node ``(i, j)`` for every curve point ``i`` (a
*layer*) and graph vertex ``j``. The curve is cut open at point 0 and closed
by a duplicated last layer ``m`` (= point 0 again), so a closed matching is a
path from ``(0, s)`` to ``(m, s)``. Edges (directed, layer never decreases):

* ``(i, j) -> (i, k)`` for graph edges ``(j, k)`` (the curve point stays),
* ``(i, j) -> (i+1, j)`` (the graph vertex stays),
* ``(i, j) -> (i+1, k)`` for graph edges ``(j, k)``.

The cost of an edge is the mean of its two node costs times its length in the
stacked coordinates ``(curve point, graph vertex)`` (thesis Eq. 7.1
discretised with the trapezoidal rule). The length of an edge that advances
``a`` along the curve and ``b`` in the graph is ``sqrt(a² + b²)`` (the
paper's Euclidean product metric) or ``max(a, b)`` (``metric="max"``). Under
the Euclidean metric a step whose graph vertex stays (``b = 0``) is cheaper
than one that keeps pace (``b = a``: ``√2 a``), so a matching that shortens
the graph curve, down to a few vertices, is rewarded for it at every step;
under the max metric both cost ``a`` and only stretching (``b > a``) costs
more: the curve's length is no longer traded against its fit. Nothing of size ``m n × m n`` is ever
built: :func:`_layered_dijkstra` computes edge costs on the fly from the
graph's CSR adjacency, one Dijkstra per layer (O(m n log n) in total).

:func:`branch_and_bound` finds the globally optimal *closed* path
(Algorithm 1 of the paper): the lower bound of a region R of start vertices
is the shortest path from any ``(0, s in R)`` to any ``(m, t in R)``; if its
end equals its start it is closed and optimal for R, otherwise R is split
by graph distance to s and t. Upper bounds come from closing open paths
(single-source runs), and every search is pruned by the best closed path so
far plus an admissible per-layer heuristic. With ``eps > 0`` it stops as
soon as ``lower * (1 + eps) >= upper``, which guarantees a closed path
within a factor ``1 + eps`` of the optimum.
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass

import numba
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from corrlib.errors import Cancelled, InputError, ParameterError
from corrlib.progress import CancelToken, Progress


@numba.njit(inline="always")
def _sift_up(keys, heap, position, slot):
    """Move ``heap[slot]`` up to its place in the binary min-heap ``heap`` (vertex ids) ordered by ``keys``."""
    vertex = heap[slot]
    key = keys[vertex]
    while slot > 0:
        parent = (slot - 1) >> 1
        other = heap[parent]
        if keys[other] <= key:
            break
        heap[slot] = other
        position[other] = slot
        slot = parent
    heap[slot] = vertex
    position[vertex] = slot


@numba.njit(inline="always")
def _sift_down(keys, heap, position, slot, size):
    """Move ``heap[slot]`` down to its place among the first ``size`` entries of the min-heap."""
    vertex = heap[slot]
    key = keys[vertex]
    while True:
        child = 2 * slot + 1
        if child >= size:
            break
        if child + 1 < size and keys[heap[child + 1]] < keys[heap[child]]:
            child += 1
        other = heap[child]
        if keys[other] >= key:
            break
        heap[slot] = other
        position[other] = slot
        slot = child
    heap[slot] = vertex
    position[vertex] = slot


@numba.njit(inline="always")
def _improves_a_neighbour(j, d, c, h, upper, indptr, indices, edge_len, extra, stretch):
    """Whether node ``j`` of a layer lowers a neighbour's distance ``d`` along a within-layer edge (below ``upper``
    with the heuristic ``h``)."""
    for e in range(indptr[j], indptr[j + 1]):
        k = indices[e]
        through_j = d[j] + (0.5 * (c[j] + c[k]) + stretch) * edge_len[e] + extra[e]
        if through_j < d[k] and through_j + h[k] < upper:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _layered_dijkstra(cost, step2, graph_points, indptr, indices, edge_len, source_mask, target_mask,
                      upper, heuristic, cancel, dist, pred, origin, stretch, gain, extra, max_metric):
    """Multi-source shortest paths through all layers; returns (best end vertex, its cost).

    ``stretch`` adds ``stretch * |b - a|`` to every edge, ``a`` and ``b`` its
    lengths along the curve and in the graph (0: the paper's energy; the
    second-order energy of :mod:`corrlib.geometry.elastic_paths` uses this
    first-order part as its admissible heuristic). ``gain`` subtracts
    ``gain * min(a, b)`` from every edge that advances along both the curve
    and the graph (the credited length of :meth:`ProductGraph.credited_length`;
    the parametric problem of the ratio energy). Edges within a layer never
    get a credit, so they stay non-negative and every layer's Dijkstra is exact
    whatever the distances it starts from. ``extra`` (one entry per CSR edge)
    is added to every move along that directed graph edge. ``max_metric``:
    an edge advancing on both is ``max(a, b)`` long instead of ``sqrt(a² + b²)``.

    ``dist``/``pred``/``origin`` (L, n) are overwritten: distance, predecessor
    (``j`` within the layer, ``n + j`` from vertex j of the previous layer,
    -1 for a start node) and start vertex of the best path to every node.
    Nodes whose distance plus their ``heuristic`` (L, n; a lower bound of the
    remaining cost to the last layer) reaches ``upper`` are pruned (A*-style). Returns (-2, inf) when cancelled, (-1, inf) when no path
    below ``upper`` exists.

    Within a layer the search is Dijkstra's on an indexed binary heap
    (decrease-key, no stale entries), seeded only with the nodes that can
    improve a neighbour at the distance the previous layer gave them: a node
    that cannot, and is never improved itself, relaxes nothing later either
    (distances only decrease), so leaving it out changes no distance.
    """
    n_layers, n = cost.shape
    inf = np.inf
    heap = np.empty(n, dtype=np.int64)  # vertex ids of the current layer's open nodes
    position = np.full(n, -1, dtype=np.int64)  # slot of every vertex in the heap, -1 outside it
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
        c = cost[i]
        if i == 0:
            for j in range(n):
                if source_mask[j] and h[j] < upper:
                    d[j] = 0.0
                    o[j] = j
        else:
            dprev = dist[i - 1]
            oprev = origin[i - 1]
            cprev = cost[i - 1]
            s2 = step2[i - 1]
            step = np.sqrt(s2)
            for j in range(n):
                dj = dprev[j]
                if dj == inf:
                    continue
                cj = cprev[j]
                nd = dj + (0.5 * (cj + c[j]) + stretch) * step
                if nd < d[j] and nd + h[j] < upper:
                    d[j] = nd
                    p[j] = n + j
                    o[j] = oprev[j]
                for e in range(indptr[j], indptr[j + 1]):
                    k = indices[e]
                    b = edge_len[e]
                    length = max(step, b) if max_metric else np.sqrt(s2 + b * b)
                    nd = (dj + 0.5 * (cj + c[k]) * length
                          + stretch * abs(b - step) - gain * min(b, step) + extra[e])
                    if nd < d[k] and nd + h[k] < upper:
                        d[k] = nd
                        p[k] = n + j
                        o[k] = oprev[j]
        size = 0
        for j in range(n):  # the seeds: nodes that improve a neighbour within the layer now
            if d[j] < inf and _improves_a_neighbour(j, d, c, h, upper, indptr, indices, edge_len, extra, stretch):
                heap[size] = j
                position[j] = size
                size += 1
        for slot in range((size >> 1) - 1, -1, -1):
            _sift_down(d, heap, position, slot, size)
        while size > 0:
            j = heap[0]
            position[j] = -1
            size -= 1
            if size > 0:
                heap[0] = heap[size]
                _sift_down(d, heap, position, 0, size)
            dj = d[j]
            cj = c[j]
            for e in range(indptr[j], indptr[j + 1]):
                k = indices[e]
                nd = dj + (0.5 * (cj + c[k]) + stretch) * edge_len[e] + extra[e]
                if nd < d[k] and nd + h[k] < upper:
                    d[k] = nd
                    p[k] = j
                    o[k] = o[j]
                    if position[k] < 0:
                        heap[size] = k
                        position[k] = size
                        size += 1
                    _sift_up(d, heap, position, position[k])
    best = inf
    best_t = -1
    last = dist[n_layers - 1]
    for j in range(n):
        if target_mask[j] and last[j] < best:
            best = last[j]
            best_t = j
    return best_t, best


@dataclass
class CyclicPath:
    """A closed path on the product graph.

    Attributes
    ----------
    vertices : (p,) int
        Graph vertex of every step, from the start ``(0, s)`` to the end ``(m, s)``.
    layers : (p,) int
        Curve point of every step, ``0 .. m``; ``m`` is point 0 again.
    energy : float
        Sum of the edge costs.
    """

    vertices: np.ndarray
    layers: np.ndarray
    energy: float

    @property
    def curve_index(self) -> np.ndarray:
        """(p,) int: curve point of every step modulo m (the closing layer m is point 0)."""
        m = int(self.layers.max())
        return self.layers % m

    def matched_vertices(self, n_curve: int) -> np.ndarray:
        """(m,) int: graph vertex where the path enters each curve point's layer."""
        out = np.full(n_curve, -1, dtype=np.int64)
        for layer, vertex in zip(self.layers[::-1], self.vertices[::-1]):
            if layer < n_curve:
                out[layer] = vertex
        return out


@dataclass(frozen=True)
class GraphTopology:
    """The graph of a product graph, in the arrays its searches walk; one per graph, shared by all the
    product graphs built on it (the readings of one query and mesh differ in their costs only).

    Attributes
    ----------
    points : (n, d) float
        Vertex coordinates.
    indptr, indices : (n + 1,), (e,) int
        The directed edges in sorted CSR order.
    edge_len : (e,) float
        Length of every edge.
    reverse : tuple of arrays
        ``(indptr, indices, edge_len)`` of the transposed graph (the backward search).
    reverse_order : (e,) int
        For every edge of the transposed graph in its CSR order, its index in the forward order.
    adjacency : (n, n) sparse
        Edge lengths as a matrix.
    directed : bool
        Whether the adjacency was taken as given (True) or symmetrised.
    """

    points: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    edge_len: np.ndarray
    reverse: tuple
    reverse_order: np.ndarray
    adjacency: csr_matrix
    directed: bool

    @property
    def n(self) -> int:
        return int(self.points.shape[0])

    @classmethod
    def of(cls, graph_points, adjacency, directed: bool = False) -> GraphTopology:
        """The topology of a graph given by its vertices ((n, d) float) and adjacency ((n, n) sparse)."""
        pts = np.ascontiguousarray(graph_points, dtype=np.float64)
        n = pts.shape[0]
        adj = csr_matrix(adjacency)
        if adj.shape != (n, n):
            raise InputError(f"the adjacency is {adj.shape}, the graph has {n} vertices")
        if not directed:
            adj = (adj + adj.T).tocsr()

        def csr_arrays(matrix):
            matrix = csr_matrix(matrix)
            matrix.sort_indices()
            indptr = matrix.indptr.astype(np.int64)
            indices = matrix.indices.astype(np.int64)
            rows = np.repeat(np.arange(n), np.diff(indptr))
            return indptr, indices, np.ascontiguousarray(np.linalg.norm(pts[indices] - pts[rows], axis=1))

        indptr, indices, edge_len = csr_arrays(adj)
        edge_ids = csr_matrix((np.arange(1, indices.size + 1, dtype=np.float64), indices, indptr), shape=(n, n))
        reverse_ids = csr_matrix(edge_ids.T)
        reverse_ids.sort_indices()
        return cls(pts, indptr, indices, edge_len, csr_arrays(adj.T), reverse_ids.data.astype(np.int64) - 1,
                   csr_matrix((edge_len, indices, indptr), shape=(n, n)), bool(directed))


class ProductGraph:
    """Implicit product of a closed curve (layers) with a graph.

    Parameters
    ----------
    node_cost : (m, n) float
        Cost of matching curve point i to graph vertex j (non-negative;
        ``inf`` forbids the node: no path passes it).
    curve_points : (m, d1) float
        Coordinates of the closed curve.
    graph_points : (n, d2) float
        Coordinates of the graph vertices.
    adjacency : (n, n) sparse
        Symmetric graph adjacency (non-zero pattern = edges).
    stretch : float
        Weight of the stretching term ``|b - a|`` per edge (graph length
        against curve length); 0 is the paper's energy.
    edge_penalty : (n, n) sparse, optional
        Non-negative cost per unit graph length of walking the directed graph
        edge ``j → k`` (within a layer or to the next), added to the edge's
        cost; it may differ from ``k → j`` (e.g. a curve that must keep one
        side of the surface on its left). Entries outside the adjacency are
        ignored. The backward search of the heuristic walks every edge with
        the penalty of its forward direction, so it stays exact.
    metric : {"euclidean", "max"}
        Length of an edge that advances ``a`` along the curve and ``b`` in the
        graph: ``sqrt(a² + b²)`` (the paper) or ``max(a, b)`` (see the module
        docstring).
    """

    def __init__(self, node_cost, curve_points, graph_points, adjacency, *, directed: bool = False,
                 closing_shift: int = 0, n_starts: int | None = None, stretch: float = 0.0, edge_penalty=None,
                 metric: str = "euclidean", topology: GraphTopology | None = None):
        cost = np.asarray(node_cost, dtype=np.float64)
        curve = np.asarray(curve_points, dtype=np.float64)
        pts = np.asarray(graph_points, dtype=np.float64)
        m, n = cost.shape
        if curve.shape[0] != m or pts.shape[0] != n:
            raise InputError(f"node costs {cost.shape} do not match {curve.shape[0]} curve points and "
                             f"{pts.shape[0]} graph vertices")
        if np.any(np.isnan(cost)) or cost.min() < 0 or not np.isfinite(cost).any():
            raise InputError("node costs must be non-negative (inf forbids a node) and not all inf")
        if topology is None:
            topology = GraphTopology.of(pts, adjacency, directed)
        elif topology.n != n or topology.directed != directed:
            raise InputError(f"the shared graph topology has {topology.n} vertices "
                             f"({'directed' if topology.directed else 'undirected'}), the graph {n} "
                             f"({'directed' if directed else 'undirected'})")
        self.topology = topology
        self.m, self.n = m, n
        if not (np.isfinite(stretch) and stretch >= 0):
            raise ParameterError(f"stretch must be finite and non-negative, got {stretch}")
        self.stretch = float(stretch)
        if metric not in ("euclidean", "max"):
            raise ParameterError(f"metric must be 'euclidean' or 'max', got {metric!r}")
        self.metric = metric
        #: Dinkelbach parameter of the ratio energy: every edge advancing along curve and graph gets
        #: ``-gain * min(a, b)`` (0: no credit; set by :func:`minimum_ratio_union`)
        self.gain = 0.0
        # a closed path starts at (0, s) and ends at (m, s + closing_shift), s < n_starts
        self.closing_shift = int(closing_shift)
        self.n_starts = int(n_starts if n_starts is not None else n)
        self.cyclic_starts = directed and self.closing_shift > 0
        # layer m duplicates layer 0: the path closes on the curve's first point
        self.cost = np.ascontiguousarray(np.vstack([cost, cost[:1]]))
        self.curve_points = curve
        curve_closed = np.vstack([curve, curve[:1]])
        self.step2 = np.ascontiguousarray(np.sum(np.diff(curve_closed, axis=0) ** 2, axis=1))
        self.graph_points = topology.points
        self.indptr, self.indices, self.edge_len = topology.indptr, topology.indices, topology.edge_len
        # the backward search of the heuristic walks the edges in reverse
        self._reverse = topology.reverse
        # directed extra cost of every graph edge, aligned with the forward and the reversed CSR order
        self.extra = self._edge_extra(edge_penalty, n)
        self._reverse_extra = np.ascontiguousarray(self.extra[topology.reverse_order])
        self.adjacency = topology.adjacency
        # admissible heuristic (remaining cost to the last layer); zero until compute_heuristic()
        self.heuristic = np.zeros((m + 1, n))
        #: the cheapest open path, once compute_heuristic() has run
        self.root_path: CyclicPath | None = None
        self._closing_weights: csr_matrix | None = None
        self.dist = np.empty((m + 1, n))
        self.pred = np.empty((m + 1, n), dtype=np.int32)
        self.origin = np.empty((m + 1, n), dtype=np.int32)
        self.runs = 0
        self.run_seconds = 0.0

    def _edge_extra(self, edge_penalty, n: int) -> np.ndarray:
        """(nnz,) float: ``penalty(j → k) · |j k|`` for every directed edge in CSR order (zeros without one)."""
        if edge_penalty is None:
            return np.zeros(self.indices.size)
        penalty = csr_matrix(edge_penalty)
        if penalty.shape != (n, n):
            raise InputError(f"edge penalties must be an ({n}, {n}) matrix, got {penalty.shape}")
        penalty.sort_indices()
        rows = np.repeat(np.arange(n), np.diff(self.indptr))
        values = np.asarray(penalty[rows, self.indices]).ravel()
        if not np.all(np.isfinite(values)) or values.min(initial=0.0) < 0:
            raise InputError("edge penalties must be finite and non-negative")
        return np.ascontiguousarray(values * self.edge_len)

    def compute_heuristic(self, cancel: np.ndarray | None = None, upper: float = np.inf,
                          cost_to_come: np.ndarray | None = None) -> None:
        """Exact cost-to-go ignoring where the path must end: one backward layered Dijkstra.

        Edge costs are symmetric and the product structure is the same with
        the layers (and the graph edges) reversed, so the backward search is
        the forward kernel run on the reversed layers and transposed graph
        from every node of the last layer. The result
        is the tightest admissible A* heuristic for every later search.

        Parameters
        ----------
        cancel : (1,) int8, optional
        upper : float
            Only paths cheaper than this matter (a closed path of this cost is known).
        cost_to_come : (m + 1, n) float, optional
            A lower bound of the cost of reaching every node from a start
            (``inf``: not below ``upper``), e.g. the forward distances of a
            relaxation of this graph. The backward search then skips the
            nodes through which no path is cheaper than ``upper``: their
            heuristic is ``inf`` (every later search, bounded by at most
            ``upper``, prunes them), every other node's is exact, because the
            forward distances obey the triangle inequality along the edges,
            which cost at least as much here. Without it the search is complete.
        """
        flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
        everything = np.ones(self.n, dtype=np.bool_)
        start = time.perf_counter()
        indptr, indices, edge_len = self._reverse
        if cost_to_come is None:
            cost_to_come, upper = np.zeros((self.m + 1, self.n)), np.inf
        t, _ = _layered_dijkstra(np.ascontiguousarray(self.cost[::-1]), np.ascontiguousarray(self.step2[::-1]),
                                 self.graph_points, indptr, indices, edge_len, everything,
                                 everything, float(upper), np.ascontiguousarray(cost_to_come[::-1]), flag,
                                 self.dist, self.pred, self.origin, self.stretch, self.gain, self._reverse_extra,
                                 self.metric == "max")
        self.runs += 1
        self.run_seconds += time.perf_counter() - start
        if t == -2:
            raise Cancelled("the computation was cancelled")
        self.heuristic = np.ascontiguousarray(self.dist[::-1])
        root = int(np.argmin(self.heuristic[0, :self.n_starts]))
        self.root_path = self._backward_path(root) if np.isfinite(self.heuristic[0, root]) else None

    def _backward_path(self, start: int) -> CyclicPath:
        """The cheapest open path from ``(0, start)``, read off the backward search (before any other run).

        The backward search ran on the reversed layers (its layer ``m`` is
        layer 0), so following its predecessors from ``(0, start)`` walks the
        path forwards.
        """
        layers, vertices = self._predecessor_walk(self.m, int(start))
        return CyclicPath(vertices, self.m - layers, float(self.heuristic[0, start]))

    def _predecessor_walk(self, layer: int, vertex: int) -> tuple[np.ndarray, np.ndarray]:
        """(layers, vertices) ((p,) int each) from node ``(layer, vertex)`` back along the last run's predecessors."""
        n = self.n
        layers, vertices = [layer], [vertex]
        while True:
            p = int(self.pred[layer, vertex])
            if p < 0:
                break
            if p >= n:
                layer, vertex = layer - 1, p - n
            else:
                vertex = p
            layers.append(layer)
            vertices.append(vertex)
        return np.array(layers, dtype=np.int64), np.array(vertices, dtype=np.int64)

    def shortest(self, sources: np.ndarray, targets: np.ndarray, upper: float = np.inf,
                 cancel: np.ndarray | None = None) -> tuple[float, int, int]:
        """Shortest path from any ``(0, s in sources)`` to any ``(m, t in targets)``.

        Parameters
        ----------
        sources, targets : (n,) bool
        upper : float
            Only paths cheaper than this are searched for.
        cancel : (1,) int8, optional
            Polled once per layer.

        Returns
        -------
        cost : float
            ``inf`` if no path cheaper than ``upper`` exists.
        start, end : int
            Start and end vertex (-1 if none).
        """
        flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
        start = time.perf_counter()
        t, c = _layered_dijkstra(self.cost, self.step2, self.graph_points, self.indptr, self.indices,
                                 self.edge_len, sources, targets, float(upper), self.heuristic, flag,
                                 self.dist, self.pred, self.origin, self.stretch, self.gain, self.extra,
                                 self.metric == "max")
        self.runs += 1
        self.run_seconds += time.perf_counter() - start
        if t == -2:
            raise Cancelled("the computation was cancelled")
        if t < 0:
            return np.inf, -1, -1
        return float(c), int(self.origin[self.m, t]), int(t)

    def backtrack(self, end: int) -> CyclicPath:
        """The path found by the last :meth:`shortest` run that ends at ``(m, end)``."""
        layers, vertices = self._predecessor_walk(self.m, int(end))
        return CyclicPath(vertices[::-1].copy(), layers[::-1].copy(), float(self.dist[self.m, end]))

    def endpoints(self, region: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sources, targets) masks over the graph vertices for a region of start vertices."""
        sources = np.zeros(self.n, dtype=np.bool_)
        targets = np.zeros(self.n, dtype=np.bool_)
        idx = np.flatnonzero(region)
        sources[idx] = True
        targets[idx + self.closing_shift] = True
        return sources, targets

    def is_closed(self, start: int, end: int) -> bool:
        return end == start + self.closing_shift

    def split(self, region: np.ndarray, start: int, end: int) -> tuple[np.ndarray, np.ndarray]:
        """Split a region of starts into the parts nearer to ``start`` and to ``end``'s start."""
        if self.cyclic_starts:
            idx = np.arange(self.n_starts)
            k = self.n_starts

            def cyclic(a):
                d = np.abs(idx - a) % k
                return np.minimum(d, k - d)

            near_start = cyclic(start) <= cyclic((end - self.closing_shift) % k)
        else:
            dist = dijkstra(self.adjacency, directed=False, indices=[start, end])
            near_start = dist[0] <= dist[1]
        return region & near_start, region & ~near_start

    def close_by_detour(self, open_path: CyclicPath) -> tuple[float, CyclicPath | None]:
        """A closed path from an open one: walk back to its start within the last layer (an upper bound).

        The open path ends at ``(m, t)``; the cheapest walk from ``(m, t)``
        to ``(m, s)`` along graph edges (cost ``(c̄ + stretch) ·`` edge length,
        the costs of the closing layer) closes it. Only for graphs closed at
        their start (``closing_shift = 0``); ``(inf, None)`` otherwise.
        """
        if self.closing_shift != 0:
            return np.inf, None
        s, t = int(open_path.vertices[0]), int(open_path.vertices[-1])
        if self._closing_weights is None:  # the closing layer's edge costs, built once
            layer_cost = self.cost[self.m]
            tails = np.repeat(np.arange(self.n), np.diff(self.indptr))
            weights = (0.5 * (layer_cost[tails] + layer_cost[self.indices]) + self.stretch) * self.edge_len + self.extra
            usable = np.isfinite(weights)  # an edge at a forbidden node is no edge
            self._closing_weights = csr_matrix((weights[usable], (tails[usable], self.indices[usable])),
                                               shape=(self.n, self.n))
        dist, pred = dijkstra(self._closing_weights, directed=True, indices=t, return_predecessors=True)
        if not np.isfinite(dist[s]):
            return np.inf, None
        walk = [s]
        while walk[-1] != t:
            walk.append(int(pred[walk[-1]]))
        detour = np.array(walk[::-1][1:], dtype=np.int64)  # t (exclusive) ... s
        path = CyclicPath(np.concatenate([open_path.vertices, detour]),
                          np.concatenate([open_path.layers, np.full(detour.size, self.m)]),
                          float(open_path.energy + dist[s]))
        return path.energy, path

    def closed_from(self, start: int, upper: float = np.inf, cancel=None) -> tuple[float, CyclicPath | None]:
        """The cheapest closed path through ``(0, start)`` (if cheaper than ``upper``)."""
        region = np.zeros(self.n_starts, dtype=np.bool_)
        region[start] = True
        sources, targets = self.endpoints(region)
        cost, _, end = self.shortest(sources, targets, upper, cancel)
        if end < 0:
            return np.inf, None
        return cost, self.backtrack(end)

    def path_energy(self, path: CyclicPath) -> float:
        """Recompute the energy of a path edge by edge (independent check of the search)."""
        layers, vertices = path.layers, path.vertices
        j0, j1 = vertices[:-1], vertices[1:]
        b2 = np.sum((self.graph_points[j1] - self.graph_points[j0]) ** 2, axis=1)
        a2 = np.where(np.diff(layers) == 1, np.append(self.step2, 0.0)[layers[:-1]], 0.0)
        length = np.maximum(np.sqrt(a2), np.sqrt(b2)) if self.metric == "max" else np.sqrt(a2 + b2)
        total = np.sum(0.5 * (self.cost[layers[:-1], j0] + self.cost[layers[1:], j1]) * length)
        total += self.stretch * np.sum(np.abs(np.sqrt(b2) - np.sqrt(a2)))
        moves = j1 != j0
        # CSR order is (row, column) ascending, so the key row * n + column finds a directed edge's slot
        keys = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr)) * self.n + self.indices
        slots = np.searchsorted(keys, j0[moves].astype(np.int64) * self.n + j1[moves])
        total += np.sum(self.extra[slots])
        return float(total - self.gain * self.credited_length(path))

    @classmethod
    def relaxation(cls, members) -> ProductGraph:
        """A graph whose every edge costs at most the same edge of each member: a lower bound for all of them.

        Node costs are the members' element-wise minimum, without directed
        edge penalties and with the least stretching weight; the curve, the
        graph and the closing rule must be the members' own. Its backward
        search bounds every member from below and its A* heuristic is
        admissible for each, so one search stands in for several until the
        bound says which members can still win.
        """
        first = members[0]
        for other in members[1:]:
            if (other.m, other.n, other.closing_shift, other.n_starts, other.metric) != (
                    first.m, first.n, first.closing_shift, first.n_starts, first.metric):
                raise InputError("a relaxation's members must share the curve, the graph, the closing rule and the "
                                 "metric")
        cost = members[0].cost[:-1].copy()
        for other in members[1:]:
            np.minimum(cost, other.cost[:-1], out=cost)
        return cls(cost, first.curve_points, first.graph_points, first.adjacency, directed=first.topology.directed,
                   closing_shift=first.closing_shift, n_starts=first.n_starts,
                   stretch=min(g.stretch for g in members), metric=first.metric, topology=first.topology)

    def credited_length(self, path: CyclicPath) -> float:
        """The length of the curve a path matches to moving graph vertices: ``Σ min(a, b)`` over its edges.

        An edge from ``(i, j)`` to ``(i + 1, k)``, ``k ≠ j``, advances ``a`` along
        the curve and ``b`` in the graph and is credited ``min(a, b)``; an edge
        on which either stays is credited nothing. So a curve point whose match
        does not move (a collapsed stretch of the matching) adds nothing, a
        point whose match keeps pace adds its own step, and a detour within a
        layer adds nothing either: the credit is at most the curve's length.
        """
        layers, vertices = path.layers, path.vertices
        advancing = (np.diff(layers) == 1) & (vertices[1:] != vertices[:-1])
        b = np.linalg.norm(self.graph_points[vertices[1:]] - self.graph_points[vertices[:-1]], axis=1)
        a = np.sqrt(np.append(self.step2, 0.0)[layers[:-1]])  # no edge advances from the closing layer
        return float(np.sum(np.minimum(a, b)[advancing]))

    @property
    def curve_length(self) -> float:
        """Length of the closed curve: the largest possible credited length."""
        return float(np.sum(np.sqrt(self.step2)))


@dataclass
class BranchAndBoundResult:
    """Outcome of :func:`branch_and_bound`."""

    path: CyclicPath
    energy: float
    lower_bound: float
    upper_bound: float
    iterations: int
    dijkstra_runs: int
    seconds_per_run: float
    graph_index: int = 0


def branch_and_bound(graph: ProductGraph, *, eps: float = 0.0, token: CancelToken | None = None,
                     max_iterations: int = 100_000):
    """Globally optimal (``eps = 0``) or ``(1 + eps)``-approximate closed path (generator).

    Yields
    ------
    Progress
        One per iteration, with the current lower and upper bounds.

    Returns
    -------
    BranchAndBoundResult
    """
    return (yield from branch_and_bound_union([graph], eps=eps, token=token, max_iterations=max_iterations))


#: backward searches of the branch-and-bound's first round below a relaxation, and the most graphs searched
#: without relaxations: fixed, not the thread count, so that the search visits the graphs in the same order on
#: every machine and on every thread (with ``eps > 0`` the path returned depends on that order; the optimum
#: does not); the threads only run a round's searches side by side
SEARCH_ROUND = 2


def parallel_searches() -> int:
    """How many backward searches :func:`compute_heuristics` runs at once.

    ``numba.get_num_threads()`` when called from the main thread (the command
    line, a worker process of a pool, which limits numba to its share of the
    cores); 1 from another thread (a job of the studio, which may run beside
    others).
    """
    import threading

    return numba.get_num_threads() if threading.current_thread() is threading.main_thread() else 1


def compute_heuristics(graphs, cancel: np.ndarray | None = None, upper: float = np.inf,
                       cost_to_come: np.ndarray | None = None) -> None:
    """The backward searches of several product graphs, :func:`parallel_searches` at a time.

    The searches are independent and the kernel releases the GIL, so threads
    run them in parallel. ``upper`` and ``cost_to_come`` as in
    :meth:`ProductGraph.compute_heuristic`, for every graph.
    """
    workers = min(len(graphs), parallel_searches())
    if workers <= 1:
        for graph in graphs:
            graph.compute_heuristic(cancel, upper, cost_to_come)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers) as pool:
        for future in [pool.submit(graph.compute_heuristic, cancel, upper, cost_to_come) for graph in graphs]:
            future.result()  # re-raises Cancelled


@dataclass
class Relaxation:
    """A lower-bounding graph for a group of the graphs of a union (a node of a tree of relaxations).

    Attributes
    ----------
    graph : ProductGraph
        Costs at most those of every graph below it
        (:meth:`ProductGraph.relaxation`).
    children : list of int or Relaxation
        Indices into the union's graphs, or finer relaxations.
    """

    graph: ProductGraph
    children: list

    @property
    def leaves(self) -> list[int]:
        """Indices of the union's graphs below this node."""
        return [leaf for child in self.children
                for leaf in (child.leaves if isinstance(child, Relaxation) else [child])]


def branch_and_bound_union(graphs, *, eps: float = 0.0, token: CancelToken | None = None,
                           max_iterations: int = 100_000, relaxations=()):
    """The best closed path over several product graphs, by one best-first branch-and-bound (generator).

    A region is a set of start vertices of one graph; the open regions of all
    graphs share one priority queue, so a graph whose lower bound exceeds the
    best closed path found in another is never explored further. A graph
    enters the queue with the lower bound its backward search gives for free
    (the cheapest open path from any start), so a graph that cannot win is
    not even searched forward once. This is the
    global optimum of ``min_g E_g`` (e.g. both readings of an ambiguous
    feature), at a cost close to that of the winning graph alone.

    Relaxations save backward searches (a complete one costs as much as
    tens of pruned forward ones). A graph below a relaxation is searched
    backwards only when the relaxation's bound comes first in the queue, so
    a group of graphs that cannot win costs one search. The first time, the
    most promising items below it are searched completely and followed down
    to a graph whose cheapest open path is closed, which gives a tight upper
    bound early; every later backward search skips the nodes through which
    no path beats it (the relaxation's forward distances bound the cost to
    come, :meth:`ProductGraph.compute_heuristic`), and is then cheap. The
    result is the same optimum (or ``1 + eps`` approximation).

    Parameters
    ----------
    graphs : sequence of ProductGraph
    eps, token, max_iterations
        As in :func:`branch_and_bound`.
    relaxations : sequence of Relaxation
        Roots of trees of relaxations; every graph is below at most one root
        and appears once. Graphs below none are searched from the start.

    Returns
    -------
    BranchAndBoundResult
        ``graph_index`` says which graph the path belongs to.
    """
    if not (0.0 <= eps < 1.0):
        raise ParameterError(f"eps must be in [0, 1), got {eps}")
    if len(graphs) == 0:
        raise ParameterError("branch and bound needs at least one product graph")
    covered = [leaf for root in relaxations for leaf in root.leaves]
    if len(set(covered)) != len(covered) or not all(0 <= leaf < len(graphs) for leaf in covered):
        raise ParameterError("every graph must be below at most one relaxation, once")
    token = token or CancelToken()
    search = _UnionSearch(graphs, eps, token.flag)
    search.start(relaxations, [i for i in range(len(graphs)) if i not in set(covered)])
    heap = search.heap
    lower_bound = np.inf  # stays inf if every region is resolved: then the optimum is `upper`
    iterations = 0
    while heap:
        token.raise_if_cancelled()
        lower, _, index, region, s, t = heapq.heappop(heap)
        if lower * (1.0 + eps) >= search.upper or iterations >= max_iterations:
            lower_bound = lower  # every open region is at least this
            break
        if isinstance(index, Relaxation):  # the graphs below it may still win
            search.expand(index)
            continue
        if s < 0:  # an unexplored whole graph: find its open path (queued again) or its closed optimum
            search.explore(index, region)
            continue
        iterations += 1
        graph = graphs[index]
        # upper bound: close the region's best open path at its start
        search.consider_closed(index, *graph.closed_from(s, search.upper, search.cancel))
        if lower * (1.0 + eps) >= search.upper:
            lower_bound = lower
            break
        # split the region by graph distance to the open path's start and end
        for child in graph.split(region, s, t):
            if child.any():
                search.explore(index, child)
        bound = heap[0][0] if heap else search.upper
        yield Progress("branch and bound", -1.0,
                       f"iteration {iterations}: lower {min(bound, search.upper):.6g}, upper {search.upper:.6g}, "
                       f"{len(heap)} open regions")
    upper = search.upper
    lower_bound = min(lower_bound, upper)
    if search.best is None:
        raise InputError("branch and bound found no closed path")
    searched = list(graphs) + [node.graph for node in _tree_nodes(relaxations)]
    runs = sum(g.runs for g in searched)
    return BranchAndBoundResult(search.best, upper, lower_bound, upper, iterations, runs,
                                sum(g.run_seconds for g in searched) / max(runs, 1), search.best_index)


class _UnionSearch:
    """The state of one :func:`branch_and_bound_union`: the queue, the best closed path, the relaxations' order.

    The queue holds ``(lower bound, counter, item, region, s, t)``: a
    relaxation (region None), a graph's whole unexplored region
    (``s = t = -1``) or a region with its cheapest open path from ``s`` to ``t``.
    """

    def __init__(self, graphs, eps: float, cancel: np.ndarray):
        self.graphs, self.eps, self.cancel = graphs, eps, cancel
        self.counter = itertools.count()
        self.heap: list = []
        self.upper, self.best, self.best_index = np.inf, None, -1
        self.promise: dict[int, float] = {}  # per graph: the cheapest relaxation path priced in it (orders searches)
        self.expanded: set[int] = set()
        self.dived = False  # a first closed path has been sought below a relaxation

    def start(self, relaxations, uncovered: list[int]) -> None:
        """The roots' backward searches (in parallel), queued: a graph whose bound is beaten by a closed path is
        never searched forward; one below a relaxation whose bound is beaten is not even searched backward."""
        roots = list(relaxations) + uncovered
        compute_heuristics([self.graph_of(item) for item in roots], self.cancel)
        for item in roots:
            if not np.isfinite(self.settle(item)):
                raise InputError("no path through the product graph (is the graph connected?)")

    def graph_of(self, item) -> ProductGraph:
        return item.graph if isinstance(item, Relaxation) else self.graphs[item]

    def leaves_of(self, item) -> list[int]:
        return item.leaves if isinstance(item, Relaxation) else [item]

    def most_promising(self, item) -> float:
        return min(self.promise.get(leaf, np.inf) for leaf in self.leaves_of(item))

    def consider_closed(self, index: int, cost: float, path: CyclicPath | None) -> None:
        if path is not None and cost < self.upper:
            self.upper, self.best, self.best_index = cost, path, index

    def explore(self, index: int, region: np.ndarray) -> None:
        """Shortest path of a region: a closed one updates the bound, an open one is queued."""
        graph = self.graphs[index]
        cost, s, t = graph.shortest(*graph.endpoints(region), self.upper, self.cancel)
        if s < 0:
            return  # nothing in this region beats the best closed path
        if graph.is_closed(s, t):
            self.consider_closed(index, cost, graph.backtrack(t))
        elif cost * (1.0 + self.eps) < self.upper:
            self.consider_closed(index, *graph.close_by_detour(graph.backtrack(t)))  # an upper bound for free
            heapq.heappush(self.heap, (cost, next(self.counter), index, region, s, t))

    def settle(self, item) -> float:
        """Queue an item whose backward search has run, by the lower bound that search gives for free (the
        cheapest open path from any start); the closed detour of that path is an upper bound, priced in
        every graph below a relaxation. Returns the bound (inf: nothing through it beats the best path)."""
        graph = self.graph_of(item)
        root_bound = float(np.min(graph.heuristic[0, :graph.n_starts]))
        if not np.isfinite(root_bound):
            return root_bound
        _, closed = graph.close_by_detour(graph.root_path)
        if closed is not None:
            for leaf in self.leaves_of(item):
                energy = self.graphs[leaf].path_energy(closed)
                self.promise[leaf] = min(self.promise.get(leaf, np.inf), energy)
                self.consider_closed(leaf, energy, closed)
        region = None if isinstance(item, Relaxation) else np.ones(graph.n_starts, dtype=np.bool_)
        heapq.heappush(self.heap, (root_bound, next(self.counter), item, region, -1, -1))
        return root_bound

    def search_below(self, parent: Relaxation, items) -> None:
        """The backward searches of items below a relaxation (in parallel), skipping the nodes through which no
        path beats the best closed one: the relaxation's forward distances under that bound bound their cost to
        come."""
        searched = [self.graph_of(item) for item in items]
        if np.isfinite(self.upper):
            relaxed = parent.graph
            everything = np.ones(relaxed.n, dtype=np.bool_)
            relaxed.shortest(everything, everything, self.upper, self.cancel)
            compute_heuristics(searched, self.cancel, self.upper, relaxed.dist.copy())
        else:
            compute_heuristics(searched, self.cancel)
        for item in items:
            self.settle(item)

    def expand(self, parent: Relaxation) -> None:
        """The items below a relaxation whose bound came first in the queue (once).

        Until a first closed path has been found below a relaxation, the
        :data:`SEARCH_ROUND` most promising items are searched backwards
        completely (side by side where there are threads) and the best of them
        is followed down to a graph whose cheapest open path is closed
        (:meth:`dive`); every other backward search skips all that the best
        closed path beats.
        """
        if id(parent) in self.expanded:
            return
        self.expanded.add(id(parent))
        ordered = sorted(parent.children, key=self.most_promising)
        if self.dived:
            self.search_below(parent, ordered)
            return
        first, others = ordered[:SEARCH_ROUND], ordered[SEARCH_ROUND:]
        compute_heuristics([self.graph_of(item) for item in first], self.cancel)
        for item in first:
            self.settle(item)
        self.dive(min(first, key=self.most_promising))
        if others:
            self.search_below(parent, others)

    def dive(self, item) -> None:
        """A tight upper bound early: follow the most promising items below a searched one down to a graph and
        close its cheapest open path (one search from every start, one from that path's start)."""
        if not np.isfinite(np.min(self.graph_of(item).heuristic[0])):
            return  # nothing through it beats the best closed path
        if isinstance(item, Relaxation):
            self.expand(item)  # which dives further down
            return
        self.dived = True
        graph = self.graphs[item]
        cost, start, end = graph.shortest(*graph.endpoints(np.ones(graph.n_starts, dtype=np.bool_)), self.upper,
                                          self.cancel)
        if start < 0:
            return
        if graph.is_closed(start, end):
            self.consider_closed(item, cost, graph.backtrack(end))
            return
        self.consider_closed(item, *graph.close_by_detour(graph.backtrack(end)))
        self.consider_closed(item, *graph.closed_from(start, self.upper, self.cancel))


def _tree_nodes(relaxations) -> list[Relaxation]:
    """Every relaxation of the trees, roots first."""
    nodes = list(relaxations)
    for node in nodes:  # grows while iterating: breadth first
        nodes.extend(child for child in node.children if isinstance(child, Relaxation))
    return nodes


def minimum_ratio_union(graphs, *, eps: float = 0.0, token: CancelToken | None = None,
                        max_iterations: int = 100_000, max_rounds: int = 100, relaxations=()):
    """The closed path of least energy per credited length over several product graphs (generator).

    Minimises the ratio ``R(P) = E(P) / D(P)`` of the path energy ``E`` to the
    credited length ``D`` (:meth:`ProductGraph.credited_length`, the part of the
    curve matched to moving graph vertices) by Dinkelbach's parametric search
    (Dinkelbach 1967; the minimum-ratio cycles of Roetzer et al., CVPR 2025):
    for a ratio ``λ`` attained by a path, the global optimum of ``E − λ D``
    (every edge advancing along curve and graph credited ``−λ min(a, b)``,
    :func:`branch_and_bound_union`) is negative exactly when some path has a
    lower ratio, and then that path's ratio is the next ``λ``. The ratios
    decrease strictly, so the search ends, at the global optimum, after a
    handful of rounds. A collapsed matching, whose curve points keep their
    match, has a small ``D`` and a large ratio however small its energy.

    Bounds: the optimum of ``E − μ D`` is non-negative exactly when no path
    has a ratio below ``μ``, so a round that finds it non-negative certifies
    ``R ≥ μ``. With ``eps > 0`` every round solves at ``μ = λ / (1 + eps)``
    instead of ``λ``: either it certifies that ``λ`` is within ``1 + eps`` of
    the optimum, or its path improves the ratio by at least that factor.

    Parameters
    ----------
    graphs : sequence of ProductGraph
    eps, token, max_iterations
        As in :func:`branch_and_bound`.
    max_rounds : int
        Cap on Dinkelbach's rounds.
    relaxations : sequence of Relaxation
        As in :func:`branch_and_bound_union` (they get the same credit).

    Returns
    -------
    BranchAndBoundResult
        ``energy``, ``lower_bound`` and ``upper_bound`` are ratios; the
        inner searches' iterations and runs are summed.
    """
    if not (0.0 <= eps < 1.0):
        raise ParameterError(f"eps must be in [0, 1), got {eps}")
    if len(graphs) == 0:
        raise ParameterError("the ratio search needs at least one product graph")
    token = token or CancelToken()
    curve_length = max(g.curve_length for g in graphs)
    everything = list(graphs) + [node.graph for node in _tree_nodes(relaxations)]

    def solve(gain):
        """The global optimum of ``E − gain · D`` over every graph (the gains are reset afterwards)."""
        for graph in everything:  # the same credit keeps a relaxation below its graphs
            graph.gain = gain
        try:
            return (yield from branch_and_bound_union(graphs, token=token, max_iterations=max_iterations,
                                                      relaxations=relaxations))
        finally:
            for graph in everything:
                graph.gain = 0.0

    bb = yield from solve(0.0)
    iterations = bb.iterations
    path, index = bb.path, bb.graph_index
    credit = graphs[index].credited_length(path)
    energy = graphs[index].path_energy(path)
    # a matching of the paper's optimum that never moves has no ratio yet: start from the smallest credit
    ratio = energy / max(credit, 1e-9 * curve_length)
    lower = -np.inf  # no certificate yet
    for _ in range(max_rounds):
        probe = ratio / (1.0 + eps)
        bb = yield from solve(probe)
        iterations += bb.iterations
        value = bb.lower_bound  # a lower bound of min E - probe * D (the optimum unless the iteration cap hit)
        if value >= -1e-9 * max(abs(energy), 1e-300):  # no path has a ratio below the probe
            lower = probe
            break
        graph = graphs[bb.graph_index]
        candidate_credit = graph.credited_length(bb.path)
        candidate_energy = graph.path_energy(bb.path)  # the gains are 0 again: the energy alone
        if candidate_credit <= 0 or candidate_energy / candidate_credit >= ratio:
            break  # the inner search stopped early (iteration cap): no certificate
        path, index, energy = bb.path, bb.graph_index, candidate_energy
        ratio = energy / candidate_credit
    runs = sum(g.runs for g in graphs)
    result_path = CyclicPath(path.vertices, path.layers, float(ratio))
    return BranchAndBoundResult(result_path, float(ratio), float(min(lower, ratio)), float(ratio), iterations, runs,
                                sum(g.run_seconds for g in graphs) / max(runs, 1), index)
