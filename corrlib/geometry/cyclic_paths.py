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
discretised with the trapezoidal rule). Nothing of size ``m n × m n`` is ever
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


@numba.njit(cache=True, nogil=True)
def _layered_dijkstra(cost, step2, graph_points, indptr, indices, edge_len, source_mask, target_mask,
                      upper, heuristic, cancel, dist, pred, origin, stretch, gain, extra):
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
    is added to every move along that directed graph edge.

    ``dist``/``pred``/``origin`` (L, n) are overwritten: distance, predecessor
    (``j`` within the layer, ``n + j`` from vertex j of the previous layer,
    -1 for a start node) and start vertex of the best path to every node.
    Nodes whose distance plus their ``heuristic`` (L, n; a lower bound of the
    remaining cost to the last layer) reaches ``upper`` are pruned (A*-style). Returns (-2, inf) when cancelled, (-1, inf) when no path
    below ``upper`` exists.
    """
    n_layers, n = cost.shape
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
        heap = [(0.0, 0)]
        heap.pop()
        if i == 0:
            for j in range(n):
                if source_mask[j] and h[j] < upper:
                    d[j] = 0.0
                    o[j] = j
                    heap.append((0.0, j))
        else:
            dprev = dist[i - 1]
            oprev = origin[i - 1]
            s2 = step2[i - 1]
            step = np.sqrt(s2)
            for j in range(n):
                dj = dprev[j]
                if dj == inf:
                    continue
                cj = cost[i - 1, j]
                nd = dj + (0.5 * (cj + cost[i, j]) + stretch) * step
                if nd < d[j] and nd + h[j] < upper:
                    d[j] = nd
                    p[j] = n + j
                    o[j] = oprev[j]
                for e in range(indptr[j], indptr[j + 1]):
                    k = indices[e]
                    nd = (dj + 0.5 * (cj + cost[i, k]) * np.sqrt(s2 + edge_len[e] * edge_len[e])
                          + stretch * abs(edge_len[e] - step) - gain * min(edge_len[e], step) + extra[e])
                    if nd < d[k] and nd + h[k] < upper:
                        d[k] = nd
                        p[k] = n + j
                        o[k] = oprev[j]
            for j in range(n):
                if d[j] < inf:
                    heap.append((d[j], j))
        heapq.heapify(heap)
        while len(heap) > 0:
            dj, j = heapq.heappop(heap)
            if dj > d[j]:
                continue
            cj = cost[i, j]
            for e in range(indptr[j], indptr[j + 1]):
                k = indices[e]
                nd = dj + (0.5 * (cj + cost[i, k]) + stretch) * edge_len[e] + extra[e]
                if nd < d[k] and nd + h[k] < upper:
                    d[k] = nd
                    p[k] = j
                    o[k] = o[j]
                    heapq.heappush(heap, (nd, k))
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


class ProductGraph:
    """Implicit product of a closed curve (layers) with a graph.

    Parameters
    ----------
    node_cost : (m, n) float
        Cost of matching curve point i to graph vertex j (non-negative).
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
    """

    def __init__(self, node_cost, curve_points, graph_points, adjacency, *, directed: bool = False,
                 closing_shift: int = 0, n_starts: int | None = None, stretch: float = 0.0, edge_penalty=None):
        cost = np.asarray(node_cost, dtype=np.float64)
        curve = np.asarray(curve_points, dtype=np.float64)
        pts = np.asarray(graph_points, dtype=np.float64)
        m, n = cost.shape
        if curve.shape[0] != m or pts.shape[0] != n:
            raise InputError(f"node costs {cost.shape} do not match {curve.shape[0]} curve points and "
                             f"{pts.shape[0]} graph vertices")
        if not np.all(np.isfinite(cost)) or cost.min() < 0:
            raise InputError("node costs must be finite and non-negative")
        adj = csr_matrix(adjacency)
        if not directed:
            adj = (adj + adj.T).tocsr()
        self.m, self.n = m, n
        if not (np.isfinite(stretch) and stretch >= 0):
            raise ParameterError(f"stretch must be finite and non-negative, got {stretch}")
        self.stretch = float(stretch)
        #: Dinkelbach parameter of the ratio energy: every edge advancing along curve and graph gets
        #: ``-gain * min(a, b)`` (0: no credit; set by :func:`minimum_ratio_union`)
        self.gain = 0.0
        # a closed path starts at (0, s) and ends at (m, s + closing_shift), s < n_starts
        self.closing_shift = int(closing_shift)
        self.n_starts = int(n_starts if n_starts is not None else n)
        self.cyclic_starts = directed and self.closing_shift > 0
        # layer m duplicates layer 0: the path closes on the curve's first point
        self.cost = np.ascontiguousarray(np.vstack([cost, cost[:1]]))
        curve_closed = np.vstack([curve, curve[:1]])
        self.step2 = np.ascontiguousarray(np.sum(np.diff(curve_closed, axis=0) ** 2, axis=1))
        self.graph_points = np.ascontiguousarray(pts)

        def csr_arrays(matrix):
            matrix = csr_matrix(matrix)
            matrix.sort_indices()
            indptr = matrix.indptr.astype(np.int64)
            indices = matrix.indices.astype(np.int64)
            rows = np.repeat(np.arange(n), np.diff(indptr))
            return indptr, indices, np.ascontiguousarray(np.linalg.norm(pts[indices] - pts[rows], axis=1))

        self.indptr, self.indices, self.edge_len = csr_arrays(adj)
        # the backward search of the heuristic walks the edges in reverse
        self._reverse = csr_arrays(adj.T)
        # directed extra cost of every graph edge, aligned with the forward and the reversed CSR order
        self.extra = self._edge_extra(edge_penalty, n)
        edge_ids = csr_matrix((np.arange(1, self.indices.size + 1, dtype=np.float64), self.indices, self.indptr),
                              shape=(n, n))
        reverse_ids = csr_matrix(edge_ids.T)
        reverse_ids.sort_indices()
        self._reverse_extra = np.ascontiguousarray(self.extra[reverse_ids.data.astype(np.int64) - 1])
        self.adjacency = csr_matrix((self.edge_len, self.indices, self.indptr), shape=(n, n))
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

    def compute_heuristic(self, cancel: np.ndarray | None = None) -> None:
        """Exact cost-to-go ignoring where the path must end: one backward layered Dijkstra.

        Edge costs are symmetric and the product structure is the same with
        the layers (and the graph edges) reversed, so the backward search is
        the forward kernel run on the reversed layers and transposed graph
        from every node of the last layer. The result
        is the tightest admissible A* heuristic for every later search.
        """
        flag = np.zeros(1, dtype=np.int8) if cancel is None else cancel
        everything = np.ones(self.n, dtype=np.bool_)
        start = time.perf_counter()
        indptr, indices, edge_len = self._reverse
        t, _ = _layered_dijkstra(np.ascontiguousarray(self.cost[::-1]), np.ascontiguousarray(self.step2[::-1]),
                                 self.graph_points, indptr, indices, edge_len, everything,
                                 everything, np.inf, np.zeros((self.m + 1, self.n)), flag, self.dist, self.pred,
                                 self.origin, self.stretch, self.gain, self._reverse_extra)
        self.runs += 1
        self.run_seconds += time.perf_counter() - start
        if t == -2:
            raise Cancelled("the computation was cancelled")
        self.heuristic = np.ascontiguousarray(self.dist[::-1])
        self.root_path = self._backward_path(int(np.argmin(self.heuristic[0, :self.n_starts])))

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
                                 self.dist, self.pred, self.origin, self.stretch, self.gain, self.extra)
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
            self._closing_weights = csr_matrix(
                ((0.5 * (layer_cost[tails] + layer_cost[self.indices]) + self.stretch) * self.edge_len + self.extra,
                 self.indices, self.indptr), shape=(self.n, self.n))
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
        total = 0.0
        for a in range(len(path.vertices) - 1):
            i0, j0, i1, j1 = path.layers[a], path.vertices[a], path.layers[a + 1], path.vertices[a + 1]
            b2 = np.sum((self.graph_points[j1] - self.graph_points[j0]) ** 2)
            a2 = self.step2[i0] if i1 == i0 + 1 else 0.0
            total += 0.5 * (self.cost[i0, j0] + self.cost[i1, j1]) * np.sqrt(a2 + b2)
            total += self.stretch * abs(np.sqrt(b2) - np.sqrt(a2))
            if j1 != j0:
                e = self.indptr[j0] + np.searchsorted(self.indices[self.indptr[j0]:self.indptr[j0 + 1]], j1)
                total += self.extra[e]
        return float(total - self.gain * self.credited_length(path))

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


def compute_heuristics(graphs, cancel: np.ndarray | None = None) -> None:
    """The backward searches of several product graphs, on up to ``numba.get_num_threads()`` threads.

    The searches are independent and the kernel releases the GIL, so threads
    run them in parallel. They do so only when called from the main thread
    (the command line, a worker process of a pool, which limits numba to its
    share of the cores); called from another thread (a job of the studio,
    which may run beside others) they run one after the other.
    """
    import threading

    workers = min(len(graphs), numba.get_num_threads())
    if workers <= 1 or threading.current_thread() is not threading.main_thread():
        for graph in graphs:
            graph.compute_heuristic(cancel)
        return
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers) as pool:
        for future in [pool.submit(graph.compute_heuristic, cancel) for graph in graphs]:
            future.result()  # re-raises Cancelled


def branch_and_bound_union(graphs, *, eps: float = 0.0, token: CancelToken | None = None,
                           max_iterations: int = 100_000):
    """The best closed path over several product graphs, by one best-first branch-and-bound (generator).

    A region is a set of start vertices of one graph; the open regions of all
    graphs share one priority queue, so a graph whose lower bound exceeds the
    best closed path found in another is never explored further. A graph
    enters the queue with the lower bound its backward search gives for free
    (the cheapest open path from any start), so a graph that cannot win is
    not even searched forward once. This is the
    global optimum of ``min_g E_g`` (e.g. both readings of an ambiguous
    feature), at a cost close to that of the winning graph alone.

    Parameters
    ----------
    graphs : sequence of ProductGraph
    eps, token, max_iterations
        As in :func:`branch_and_bound`.

    Returns
    -------
    BranchAndBoundResult
        ``graph_index`` says which graph the path belongs to.
    """
    if not (0.0 <= eps < 1.0):
        raise ParameterError(f"eps must be in [0, 1), got {eps}")
    if len(graphs) == 0:
        raise ParameterError("branch and bound needs at least one product graph")
    token = token or CancelToken()
    cancel = token.flag
    counter = itertools.count()
    upper, best, best_index = np.inf, None, -1
    heap = []
    compute_heuristics(graphs, cancel)

    def consider_closed(index, cost, path):
        nonlocal upper, best, best_index
        if path is not None and cost < upper:
            upper, best, best_index = cost, path, index

    def explore(index, region):
        """Shortest path of a region: a closed one updates the bound, an open one is queued."""
        graph = graphs[index]
        cost, s, t = graph.shortest(*graph.endpoints(region), upper, cancel)
        if s < 0:
            return s  # nothing in this region beats the best closed path
        if graph.is_closed(s, t):
            consider_closed(index, cost, graph.backtrack(t))
        elif cost * (1.0 + eps) < upper:
            consider_closed(index, *graph.close_by_detour(graph.backtrack(t)))  # an upper bound for free
            heapq.heappush(heap, (cost, next(counter), index, region, s, t))
        return s

    # every graph's whole region is queued unexplored, keyed by its lower bound from the backward search (the
    # cheapest open path from any start): a graph whose bound is beaten by a closed path is never searched
    for index, graph in enumerate(graphs):
        root_bound = float(np.min(graph.heuristic[0, :graph.n_starts]))
        if not np.isfinite(root_bound):
            raise InputError("no path through the product graph (is the graph connected?)")
        consider_closed(index, *graph.close_by_detour(graph.root_path))  # an upper bound before any search
        heapq.heappush(heap, (root_bound, next(counter), index, np.ones(graph.n_starts, dtype=np.bool_), -1, -1))
    lower_bound = np.inf  # stays inf if every region is resolved: then the optimum is `upper`
    iterations = 0
    while heap:
        token.raise_if_cancelled()
        lower, _, index, region, s, t = heapq.heappop(heap)
        if lower * (1.0 + eps) >= upper or iterations >= max_iterations:
            lower_bound = lower  # every open region is at least this
            break
        if s < 0:  # an unexplored whole graph: find its open path (queued again) or its closed optimum
            explore(index, region)
            continue
        iterations += 1
        graph = graphs[index]
        # upper bound: close the region's best open path at its start
        consider_closed(index, *graph.closed_from(s, upper, cancel))
        if lower * (1.0 + eps) >= upper:
            lower_bound = lower
            break
        # split the region by graph distance to the open path's start and end
        for child in graph.split(region, s, t):
            if child.any():
                explore(index, child)
        bound = heap[0][0] if heap else upper
        yield Progress("branch and bound", -1.0,
                       f"iteration {iterations}: lower {min(bound, upper):.6g}, upper {upper:.6g}, "
                       f"{len(heap)} open regions")
    lower_bound = min(lower_bound, upper)
    if best is None:
        raise InputError("branch and bound found no closed path")
    runs = sum(g.runs for g in graphs)
    return BranchAndBoundResult(best, upper, lower_bound, upper, iterations, runs,
                                sum(g.run_seconds for g in graphs) / max(runs, 1), best_index)


def minimum_ratio_union(graphs, *, eps: float = 0.0, token: CancelToken | None = None,
                        max_iterations: int = 100_000, max_rounds: int = 100):
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

    def solve(gain):
        """The global optimum of ``E − gain · D`` over every graph (the gains are reset afterwards)."""
        for graph in graphs:
            graph.gain = gain
        try:
            return (yield from branch_and_bound_union(graphs, token=token, max_iterations=max_iterations))
        finally:
            for graph in graphs:
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
