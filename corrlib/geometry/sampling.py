"""Farthest-point sampling and Voronoi cells.

* :func:`farthest_point_sampling`: greedy farthest-point samples in the
  Euclidean metric (any point set) or the geodesic metric of a mesh (edge
  graph Dijkstra, pruned to the region whose distance can still change).
* :func:`surface_farthest_points`: farthest-point samples of the surface
  itself (points inside triangles, :class:`SurfaceSample`), so that their
  density follows the area and not the vertex density of the mesh.
* :func:`voronoi_cells`: geodesic Voronoi cells of seed vertices by one
  multi-source Dijkstra on the edge graph.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
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
    if metric == "euclidean":
        return _euclidean_fps(p, n_samples, start)
    if metric == "geodesic":
        if mesh is None:
            raise InputError("geodesic farthest-point sampling needs the mesh")
        samples = np.empty(n_samples, dtype=np.int64)
        samples[0] = start
        graph = mesh.adjacency
        dist = dijkstra(graph, directed=False, indices=start)
        for i in range(1, n_samples):
            nxt = int(np.argmax(dist))
            samples[i] = nxt
            # only vertices closer to nxt than their current distance change: prune the search there
            d_new = dijkstra(graph, directed=False, indices=nxt, limit=float(dist[nxt]))
            np.minimum(dist, d_new, out=dist)
        return samples
    raise ParameterError(f"unknown metric {metric!r} (use 'euclidean' or 'geodesic')")


def outermost_farthest_points(points, n_samples: int) -> np.ndarray:
    """(n_samples,) int: :func:`farthest_point_sampling` started at the point farthest from the centroid, so
    that the sample does not depend on the order of the points (the file's vertex order)."""
    p = np.asarray(points, dtype=np.float64)
    start = int(np.argmax(np.linalg.norm(p - p.mean(axis=0), axis=1)))
    return farthest_point_sampling(p, n_samples, start=start)


@numba.njit(cache=True, nogil=True)
def _fps_kernel(coords, n_samples, start):  # pragma: no cover - compiled
    """Greedy farthest points of ``coords`` (dim, n) float64 (coordinate-major: contiguous inner loops)."""
    dim, n = coords.shape
    dist = np.full(n, np.inf)
    step = np.empty(n)
    samples = np.empty(n_samples, dtype=np.int64)
    nxt = start
    for k in range(n_samples):
        samples[k] = nxt
        if dim == 3:
            x, y, z = coords[0], coords[1], coords[2]
            cx, cy, cz = x[nxt], y[nxt], z[nxt]
            for i in range(n):
                dx, dy, dz = x[i] - cx, y[i] - cy, z[i] - cz
                acc = dx * dx + dy * dy + dz * dz
                if acc < dist[i]:
                    dist[i] = acc
        else:
            step[:] = 0.0
            for d in range(dim):
                c = coords[d, nxt]
                row = coords[d]
                for i in range(n):
                    diff = row[i] - c
                    step[i] += diff * diff
            for i in range(n):
                if step[i] < dist[i]:
                    dist[i] = step[i]
        nxt = np.argmax(dist)  # the first maximum wins ties
    return samples


def _euclidean_fps(points: np.ndarray, n_samples: int, start: int) -> np.ndarray:
    """(n_samples,) int: greedy Euclidean farthest points of ``points`` (n, d), starting at ``start``."""
    return _fps_kernel(np.ascontiguousarray(np.asarray(points, dtype=np.float64).T), n_samples, start)


@dataclass(frozen=True)
class SurfaceSample:
    """Points on a triangle mesh, each given by a face and barycentric coordinates.

    Attributes
    ----------
    faces : (s,) int
        Face containing every point.
    barycentric : (s, 3) float
        Weights of the face's three corners (non-negative, summing to 1).
    points : (s, 3) float
        Positions.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray

    def __len__(self) -> int:
        return int(self.faces.size)

    def interpolate(self, mesh, values: np.ndarray) -> np.ndarray:
        """(s, ...) the per-vertex ``values`` (n, ...) interpolated linearly inside the faces."""
        corners = np.asarray(values)[mesh.faces[self.faces]]  # (s, 3, ...)
        weights = self.barycentric.reshape(self.barycentric.shape + (1,) * (corners.ndim - 2))
        return (weights * corners).sum(axis=1)

    def nearest_corners(self, mesh) -> np.ndarray:
        """(s,) int: for every point the corner of its face with the largest barycentric weight."""
        return mesh.faces[self.faces, np.argmax(self.barycentric, axis=1)]


#: most candidate points :func:`surface_farthest_points` generates before it coarsens its grid
MAX_SURFACE_CANDIDATES = 2_000_000


def _face_grid_points(mesh, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidates: a barycentric grid in every face, fine enough that no edge step exceeds ``spacing``.

    Returns (faces (c,) int, barycentric (c, 3) float); points on shared edges appear once per face.
    """
    tri = mesh.vertices[mesh.faces]
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    steps = np.maximum(1, np.ceil(longest / spacing)).astype(np.int64)
    faces, bary = [], []
    for r in np.unique(steps):
        members = np.flatnonzero(steps == r)
        ij = np.array([(i, j) for i in range(r + 1) for j in range(r + 1 - i)], dtype=np.float64) / r
        grid = np.column_stack([1.0 - ij.sum(axis=1), ij])  # (g, 3), the same grid in every face of this size
        faces.append(np.repeat(members, grid.shape[0]))
        bary.append(np.tile(grid, (members.size, 1)))
    return np.concatenate(faces), np.concatenate(bary)


def surface_farthest_points(mesh, n_samples: int, *, oversample: float = 2.0) -> SurfaceSample:
    """Farthest-point samples of the surface (not only of its vertices).

    Candidates are barycentric grids in every face with steps of at most
    ``sqrt(area / n_samples) / oversample`` (the expected sample spacing,
    refined); the greedy Euclidean farthest-point order over them starts at the
    candidate farthest from the centroid. The sample's density follows the
    surface area wherever the mesh is coarser than the sample — a vertex
    sample of a mesh with only a few vertices more than samples follows the
    vertex density instead (independently remeshed shapes differ in it by up
    to two orders of magnitude). The sample does not depend on the order of
    the vertices, faces or face corners (the greedy order runs on candidate
    positions rounded to 1/1000 of the grid step, so ties break the same way).

    Parameters
    ----------
    mesh : TriMesh
    n_samples : int
        Number of points, ``>= 1``.
    oversample : float
        Grid refinement relative to the expected sample spacing (``>= 1``).

    Returns
    -------
    SurfaceSample
        ``n_samples`` points in farthest-point order.
    """
    if not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ParameterError(f"n_samples must be a positive integer, got {n_samples!r}")
    if not np.isfinite(oversample) or oversample < 1:
        raise ParameterError(f"oversample must be at least 1, got {oversample}")
    spacing = np.sqrt(mesh.area / n_samples) / oversample
    while True:
        faces, bary = _face_grid_points(mesh, spacing)
        if faces.size <= MAX_SURFACE_CANDIDATES:
            break
        spacing *= 1.5  # very long thin faces: a coarser grid
    points = np.einsum("ck,ckd->cd", bary, mesh.vertices[mesh.faces[faces]])
    # one candidate per position (shared edges and corners repeat): keys rounded far below the spacing
    keys = np.round(points / (spacing * 1e-3)).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    if first.size < n_samples:
        raise ParameterError(f"cannot draw {n_samples} surface samples from {first.size} distinct candidates")
    order = first[np.lexsort(keys[first].T[::-1])]  # candidates sorted by position: independent of the face order
    faces, bary, points, grid = faces[order], bary[order], points[order], keys[order].astype(np.float64)
    # the greedy order runs on the rounded positions (exact in float64): the same choices, ties included, for
    # any order of the vertices, faces and corners
    radius = np.linalg.norm(grid - grid.mean(axis=0), axis=1)
    chosen = _euclidean_fps(grid, n_samples, int(np.argmax(radius)))
    return SurfaceSample(faces[chosen], bary[chosen], points[chosen])


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
        ``labels[v]`` is the position in ``seeds`` of the seed nearest to v (-1 where no seed is connected
        to v).
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
    return np.where(sources >= 0, position[np.maximum(sources, 0)], -1), dist  # -1: no seed reaches v


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
