"""Farthest-point sampling and Voronoi cells.

* :func:`farthest_point_sampling`: greedy farthest-point samples in the
  Euclidean metric (any point set) or the geodesic metric of a mesh (edge
  graph Dijkstra, pruned to the region whose distance can still change).
* :func:`voronoi_cells`: geodesic Voronoi cells of seed vertices by one
  multi-source Dijkstra on the edge graph.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from corrlib.errors import InputError, ParameterError


def farthest_point_sampling(points, n_samples: int, *, metric: str = "euclidean", mesh=None,
                            start: int | None = 0, seed: int | None = None) -> np.ndarray:
    """Greedy farthest-point sampling.

    Parameters
    ----------
    points : (n, d) float
        Point coordinates (ignored for ``metric="geodesic"`` except for their count).
    n_samples : int
        Number of samples, ``1 <= n_samples <= n``.
    metric : {"euclidean", "geodesic"}
        ``"geodesic"`` needs ``mesh`` (edge-graph distances).
    mesh : TriMesh, optional
    start : int or None
        First sample; ``None`` draws it with ``seed``.
    seed : int, optional

    Returns
    -------
    (n_samples,) int
        Sample indices in the order they were chosen.
    """
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ParameterError(f"n_samples must be a positive integer, got {n_samples!r}")
    if n_samples > n:
        raise ParameterError(f"cannot draw {n_samples} samples from {n} points")
    if start is None:
        start = int(np.random.default_rng(seed).integers(n))
    if not 0 <= start < n:
        raise ParameterError(f"start index {start} out of range [0, {n - 1}]")
    samples = np.empty(n_samples, dtype=np.int64)
    samples[0] = start
    if metric == "euclidean":
        dist = np.linalg.norm(p - p[start], axis=1)
        for i in range(1, n_samples):
            nxt = int(np.argmax(dist))
            samples[i] = nxt
            np.minimum(dist, np.linalg.norm(p - p[nxt], axis=1), out=dist)
    elif metric == "geodesic":
        if mesh is None:
            raise InputError("geodesic farthest-point sampling needs the mesh")
        graph = mesh.adjacency
        dist = dijkstra(graph, directed=False, indices=start)
        for i in range(1, n_samples):
            nxt = int(np.argmax(dist))
            samples[i] = nxt
            # only vertices closer to nxt than their current distance change: prune the search there
            d_new = dijkstra(graph, directed=False, indices=nxt, limit=float(dist[nxt]))
            np.minimum(dist, d_new, out=dist)
    else:
        raise ParameterError(f"unknown metric {metric!r} (use 'euclidean' or 'geodesic')")
    return samples


def voronoi_cells(mesh, seeds) -> tuple[np.ndarray, np.ndarray]:
    """Geodesic Voronoi cells of ``seeds`` on the mesh edge graph.

    Parameters
    ----------
    mesh : TriMesh
    seeds : (s,) int
        Distinct seed vertex indices.

    Returns
    -------
    labels : (n,) int
        ``labels[v]`` is the position in ``seeds`` of the seed nearest to v.
    distances : (n,) float
        Graph distance of v to that seed.
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    if seeds.size == 0:
        raise InputError("voronoi_cells: no seeds given")
    if np.unique(seeds).size != seeds.size:
        raise InputError("voronoi_cells: seeds must be distinct")
    if seeds.min() < 0 or seeds.max() >= mesh.n_vertices:
        raise InputError(f"voronoi_cells: seed index out of range [0, {mesh.n_vertices - 1}]")
    dist, _pred, sources = dijkstra(mesh.adjacency, directed=False, indices=seeds, min_only=True,
                                    return_predecessors=True)
    position = np.full(mesh.n_vertices, -1, dtype=np.int64)
    position[seeds] = np.arange(seeds.size)
    return position[sources], dist


def voronoi_bands(mesh, seeds, margin: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Geodesic Voronoi cells widened across their borders (overlapping cells).

    Cell ``c`` holds every vertex ``v`` with ``d(v, s_c) <= d(v, nearest seed) + margin``
    (graph distances): its Voronoi cell plus a band of about ``margin / 2``
    beyond each border, so neighbouring cells overlap.

    Parameters
    ----------
    mesh : TriMesh
    seeds : (s,) int
        Distinct seed vertex indices.
    margin : float
        Overlap, in the mesh's length unit (0: the plain Voronoi cells).

    Returns
    -------
    labels : (n,) int
        Position in ``seeds`` of the nearest seed (as :func:`voronoi_cells`).
    members : list of s (m_c,) int arrays
        The vertices of every widened cell, ascending.
    """
    seeds = np.asarray(seeds, dtype=np.int64)
    if not np.isfinite(margin) or margin < 0:
        raise InputError(f"voronoi_bands: margin must be a non-negative length, got {margin}")
    labels, nearest = voronoi_cells(mesh, seeds)  # validates the seeds
    if margin == 0 or seeds.size == 1:
        return labels, [np.flatnonzero(labels == c) for c in range(seeds.size)]
    dist = dijkstra(mesh.adjacency, directed=False, indices=seeds)  # (s, n)
    members = [np.flatnonzero(dist[c] <= nearest + margin) for c in range(seeds.size)]
    return labels, members
