"""A map found between remeshed copies of two fine meshes, carried to the meshes' own vertices.

A spectral method resolves a map no finer than its basis: kernel matching's smallest heat kernel resolves
the eigenfunctions with ``τ_min λ · area ≤ 1`` (about 160 on any shape, by Weyl's law), and its final steps
project the map onto those. A mesh of 5,000 vertices represents that many eigenfunctions accurately, so a
finer mesh adds vertices that the method cannot place better, at a cost that grows with them (500
eigenpairs of an 80k-vertex mesh take minutes). Such a pair can be matched on copies remeshed to the
method's resolution (:func:`~corrlib.geometry.remeshing.remeshed`; kernel matching's ``mesh_vertices``),
the map carried back in two steps:

1. every fine vertex takes the partner of its nearest coarse vertex, on the nearest fine vertex of the
   other shape (an error of up to about a coarse edge on either side);
2. the final steps of the method (:func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis`: every
   vertex takes its nearest partner in the basis, with one functional map from both directions) run at
   full resolution in the coarse eigenfunctions carried to the fine vertices (:func:`carried_basis`:
   linear on the coarse triangles, read at each fine vertex's closest point), which removes the
   quantisation of step 1.

The eigenvalues are the coarse ones; the carried eigenfunctions keep their Rayleigh quotients under the
fine Laplacian and are nearly orthonormal under the fine mass matrix (tested on a sphere), which is all
the final steps ask of a basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from corrlib.geometry.fmaps import ZoomOutSamples, repeated_pointwise_from_basis
from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.geometry.remeshing import remeshed
from corrlib.geometry.spectrum import Spectrum
from corrlib.shapes import readonly_view

#: the nearest vertices of the copy whose stars hold the candidates of a closest point (see
#: :func:`closest_surface_points`)
STAR_CENTRES = 6


@dataclass(frozen=True)
class MatchedCopy:
    """The mesh a method matches in place of a fine one.

    Attributes
    ----------
    mesh : TriMesh
        The remeshed copy, or the input itself where it is not finer than the budget.
    to_original : (k,) int or None
        The input vertex nearest to every vertex of the copy (None: the copy is the input).
    nearby : (n, STAR_CENTRES) int or None
        The vertices of the copy nearest to every input vertex, nearest first (None: the copy is the input).
    """

    mesh: object
    to_original: np.ndarray | None = None
    nearby: np.ndarray | None = None

    @property
    def nearest_copy(self) -> np.ndarray | None:
        """(n,) int: the vertex of the copy nearest to every input vertex (None: the copy is the input)."""
        return None if self.nearby is None else self.nearby[:, 0]

    @property
    def remeshed(self) -> bool:
        return self.to_original is not None


def matched_copy(mesh, budget: int) -> MatchedCopy:
    """``mesh`` itself if it has at most twice ``budget`` vertices, else its copy remeshed to ``budget``
    (twice: with fewer than two input vertices per copy vertex the remeshing saves little and moves the
    surface's sampling for nothing, the rule of :class:`~corrlib.geometry.fmaps.ZoomOutSamples`).

    ``budget`` 0: always the input.
    """
    if budget <= 0 or mesh.n_vertices <= 2 * budget:
        return MatchedCopy(mesh)
    copy = remeshed(mesh, budget)
    nearby = cKDTree(copy.mesh.vertices).query(mesh.vertices, k=min(STAR_CENTRES, copy.mesh.n_vertices))[1]
    return MatchedCopy(copy.mesh, copy.to_original, nearby.reshape(mesh.n_vertices, -1))


def carried_basis(spectrum: Spectrum, copy: MatchedCopy, original) -> Spectrum:
    """The copy's eigenpairs on the original mesh's vertices: each eigenfunction, linear on the copy's
    triangles, read at every vertex's closest point on the copy (:func:`closest_surface_points`); the
    eigenvalues are the copy's, the stiffness and mass the original's. The spectrum itself where the copy is
    the original.

    Parameters
    ----------
    spectrum : Spectrum
        Of ``copy.mesh`` (n_copy rows).
    copy : MatchedCopy
    original : TriMesh

    Returns
    -------
    Spectrum
        (n_original rows).
    """
    if not copy.remeshed:
        return spectrum
    faces, weights = closest_surface_points(original.vertices, copy.mesh, copy.nearby)
    rows = np.repeat(np.arange(original.n_vertices), 3)
    corners = copy.mesh.faces[faces].ravel()
    blend = sp.csr_matrix((weights.ravel(), (rows, corners)), shape=(original.n_vertices, copy.mesh.n_vertices))
    stiffness, mass = mesh_laplacian(original)
    return Spectrum(spectrum.evals, blend @ spectrum.evecs, stiffness, mass)


def closest_surface_points(points: np.ndarray, mesh, nearby: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closest point of ``mesh`` to every point, among the triangles around its nearest vertices, as a
    face and barycentric weights.

    The closest triangle of a surface to a point near it has one of the point's nearest vertices as a
    corner, though not always the nearest one (on an uneven mesh a long edge's midpoint can be nearer to a
    third vertex than to either end): the candidates are the stars of the nearby vertices given (a
    remeshed sphere: the nearest vertex's star misses the closest triangle for 13 % of points, the six
    nearest stars for none of 513 checked by brute force). On each candidate the closest point is found by
    the Voronoi regions of the triangle's corners, edges and face (Ericson, *Real-Time Collision
    Detection*, 2005, §5.1.5).

    Parameters
    ----------
    points : (p, 3) float
    mesh : TriMesh
    nearby : (p, m) int
        Mesh vertices near every point (their stars hold the candidate triangles).

    Returns
    -------
    faces : (p,) int
    weights : (p, 3) float
        Barycentric weights of the closest point on the face's corners (non-negative, summing to 1).
    """
    nearby = np.ascontiguousarray(np.asarray(nearby, dtype=np.int64).reshape(len(points), -1))
    star = sp.csr_matrix((np.ones(3 * mesh.n_faces), (mesh.faces.ravel(), np.repeat(np.arange(mesh.n_faces), 3))),
                         shape=(mesh.n_vertices, mesh.n_faces))
    return _closest_in_stars(readonly_view(points, np.float64), readonly_view(mesh.vertices, np.float64),
                             readonly_view(mesh.faces, np.int64), star.indptr.astype(np.int64),
                             star.indices.astype(np.int64), nearby)


@numba.njit(cache=True, nogil=True)
def _closest_in_stars(points, vertices, faces, indptr, indices, nearby):
    n = points.shape[0]
    best_face = np.zeros(n, dtype=np.int64)
    best_weights = np.zeros((n, 3))
    for i in range(n):
        best = np.inf
        for centre in nearby[i]:
            for e in range(indptr[centre], indptr[centre + 1]):
                f = indices[e]
                u, v, w = _closest_on_triangle(points[i], vertices[faces[f, 0]], vertices[faces[f, 1]],
                                               vertices[faces[f, 2]])
                d = 0.0
                for c in range(3):
                    q = u * vertices[faces[f, 0], c] + v * vertices[faces[f, 1], c] + w * vertices[faces[f, 2], c]
                    d += (q - points[i, c]) ** 2
                if d < best:
                    best = d
                    best_face[i] = f
                    best_weights[i, 0], best_weights[i, 1], best_weights[i, 2] = u, v, w
    return best_face, best_weights


@numba.njit(cache=True, nogil=True)
def _closest_on_triangle(p, a, b, c):
    """Barycentric weights (on a, b, c) of the point of triangle abc closest to p (Ericson 2005, §5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.dot(ab, ap), np.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0  # corner a
    bp = p - b
    d3, d4 = np.dot(ab, bp), np.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0  # corner b
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3) if d1 > d3 else 0.0
        return 1.0 - v, v, 0.0  # edge ab
    cp = p - c
    d5, d6 = np.dot(ab, cp), np.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0  # corner c
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6) if d2 > d6 else 0.0
        return 1.0 - w, 0.0, w  # edge ac
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        total = (d4 - d3) + (d5 - d6)
        w = (d4 - d3) / total if total > 0.0 else 0.0
        return 0.0, 1.0 - w, w  # edge bc
    total = va + vb + vc
    if not total > 0.0:  # a triangle of no area: its corner a
        return 1.0, 0.0, 0.0
    v, w = vb / total, vc / total
    return 1.0 - v - w, v, w  # the face


def nearest_lift(map_copy: np.ndarray, copy_from: MatchedCopy, copy_to: MatchedCopy) -> np.ndarray:
    """(n_from,) int: a map between the copies as a map between the originals, every original vertex taking
    the partner of its nearest copy vertex, on the original vertex nearest to that partner (-1 stays -1)."""
    rows = map_copy if copy_from.nearest_copy is None else map_copy[copy_from.nearest_copy]
    if copy_to.to_original is None:
        return rows
    return np.where(rows >= 0, copy_to.to_original[np.maximum(rows, 0)], -1)


def lifted_maps(map_xy: np.ndarray, map_yx: np.ndarray, source, target, copy_x: MatchedCopy,
                copy_y: MatchedCopy, spec_x: Spectrum, spec_y: Spectrum, k: int, token=None):
    """The maps between the copies carried to the originals (the module docstring's two steps).

    Parameters
    ----------
    map_xy : (n_copy_x,) int
    map_yx : (n_copy_y,) int
        The maps between the copies (-1: unmatched).
    source, target : TriMesh
        The originals.
    copy_x, copy_y : MatchedCopy
    spec_x, spec_y : Spectrum
        Of the copies, with at least ``k`` eigenpairs.
    k : int
        Eigenfunctions of the final steps; 0: step 1 only.
    token : CancelToken, optional

    Returns
    -------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    """
    lift_xy, lift_yx = nearest_lift(map_xy, copy_x, copy_y), nearest_lift(map_yx, copy_y, copy_x)
    if k <= 0:
        return lift_xy, lift_yx
    basis_x = carried_basis(spec_x.truncated(k), copy_x, source)
    basis_y = carried_basis(spec_y.truncated(k), copy_y, target)
    samples_x, samples_y = ZoomOutSamples.of_pair(source, target, basis_x.mass.diagonal(), basis_y.mass.diagonal())
    return repeated_pointwise_from_basis(lift_xy, lift_yx, basis_x, basis_y, k, source.adjacency, target.adjacency,
                                         token=token, samples_x=samples_x, samples_y=samples_y)
