"""Where a vertex map sends a mesh, as points of the target's surface rather than its vertices.

A point-to-point map between two meshes sends every source vertex to a target *vertex*. Where the source is
sampled more finely than the map resolves (a spectral method's maps are not one-to-one), neighbouring source
vertices land on the same target vertex, and the source drawn at the image, ``Y[map_xy]``, has faces of no
area (``docs/decisions.md`` has the figures). That image is the last frame of a sequence through the map
(:mod:`corrlib.morph`), the mesh a user exports as the target pose.

:func:`image_on_surface` spreads the corners of the faces the map collapses or turns over
(:func:`collapsed_or_turned`) over the target's surface by tangential relaxation, as remeshers relax their
vertices on the surface they remesh (e.g. Botsch & Kobbelt, *A remeshing approach to multiresolution
modeling*, SGP 2004): every step moves each of them half way to the mean of its source neighbours' images and
puts it back at the closest point of the target's surface, among the triangles within :data:`CANDIDATE_RINGS`
edges of the vertex the map gives it (:func:`~corrlib.geometry.lifting.closest_surface_points`). The mean of
the neighbours separates vertices that share a partner and unfolds most faces the map turned over; the
projection keeps every vertex on the surface; the neighbourhood keeps it within the map's resolution of its
partner, so that it cannot slide onto another part of the target (a neighbouring leg).
:data:`RELAXATION_STEPS` steps spread a vertex over about as far as the neighbourhood reaches. Every other
vertex stays on its partner, so the image of a one-to-one map is left as it is.

Unmatched source vertices (-1 in a partial map) keep the image :func:`corrlib.morph.map_image` gives them,
and take part in their neighbours' means.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corrlib.geometry.lifting import STAR_CENTRES, closest_surface_points

#: the target vertices within this many edges of a vertex's partner hold the candidates of its place on the
#: surface: the map is known to about an edge, and one ring more leaves room to spread the vertices sharing one
CANDIDATE_RINGS = 2
#: relaxation steps: each moves a vertex by at most half its distance to its neighbours' mean (about half an
#: edge), so that a vertex can spread over the neighbourhood of :data:`CANDIDATE_RINGS` rings and no farther
RELAXATION_STEPS = 5


def ring_neighbourhoods(adjacency: sp.spmatrix, rings: int) -> sp.csr_matrix:
    """(n, n) sparse 0/1: the vertices within ``rings`` edges of every vertex (itself included)."""
    step = (sp.csr_matrix(adjacency) != 0).astype(np.int8)
    reach = sp.identity(step.shape[0], format="csr", dtype=np.int8)
    for _ in range(rings):
        reach = ((reach + reach @ step) > 0).astype(np.int8)
    return reach.tocsr()


def nearest_candidates(points: np.ndarray, target_vertices: np.ndarray, partners: np.ndarray,
                       neighbourhoods: sp.csr_matrix, count: int = STAR_CENTRES) -> np.ndarray:
    """(p, count) int: for every point, the ``count`` vertices of its partner's neighbourhood nearest to it
    (nearest first; the nearest repeated where the neighbourhood is smaller).

    Parameters
    ----------
    points : (p, 3) float
    target_vertices : (n_y, 3) float
    partners : (p,) int
        A target vertex per point.
    neighbourhoods : (n_y, n_y) sparse
        :func:`ring_neighbourhoods` of the target (every row holds its own vertex).
    count : int
    """
    sizes = np.diff(neighbourhoods.indptr)
    width = int(sizes.max())
    padded = np.repeat(neighbourhoods.indices[neighbourhoods.indptr[:-1], None], width, axis=1)
    padded[np.arange(width)[None, :] < sizes[:, None]] = neighbourhoods.indices  # row by row, as CSR stores them
    candidates = padded[partners]  # (p, width); the padding repeats a vertex of the row
    distances = np.linalg.norm(target_vertices[candidates] - points[:, None, :], axis=2)
    chosen = np.take_along_axis(candidates, np.argsort(distances, axis=1, kind="stable")[:, :count], axis=1)
    if chosen.shape[1] < count:
        chosen = np.concatenate([chosen, np.repeat(chosen[:, :1], count - chosen.shape[1], axis=1)], axis=1)
    return chosen


def collapsed_or_turned(faces: np.ndarray, map_xy: np.ndarray, target) -> np.ndarray:
    """(f,) bool: source faces (all corners matched) whose image on the target's vertices has no area (two
    corners share a partner) or faces against the target's surface (its normal against the sum of the partners'
    vertex normals), unless the image is a face of the target as the target orients it."""
    partners = map_xy[faces]
    complete = np.all(partners >= 0, axis=1)
    p = np.where(complete[:, None], partners, 0)
    collapsed = (p[:, 0] == p[:, 1]) | (p[:, 1] == p[:, 2]) | (p[:, 0] == p[:, 2])
    corners = target.vertices[p]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    turned = np.einsum("ij,ij->i", normals, target.vertex_normals[p].sum(axis=1)) < 0.0
    turned &= ~is_target_face(p, target)
    return complete & (collapsed | turned)


def is_target_face(corners: np.ndarray, target) -> np.ndarray:
    """(f,) bool: whether each row of ``corners`` ((f, 3) int, target vertices) is a face of the target as the
    target orients it (in any rotation of its corners). Such an image faces the way the surface does, which
    the sum of its corners' vertex normals can contradict where the surface bends sharply."""
    n = np.int64(target.n_vertices)
    own = np.concatenate([np.roll(target.faces, shift, axis=1) for shift in range(3)]).astype(np.int64)
    c = np.asarray(corners, dtype=np.int64)
    return np.isin((c[:, 0] * n + c[:, 1]) * n + c[:, 2], (own[:, 0] * n + own[:, 1]) * n + own[:, 2])


def image_on_surface(source, target, map_xy: np.ndarray, image: np.ndarray) -> np.ndarray:
    """(n_x, 3) float: every source vertex at a point of the target's surface near its partner (the module).

    Only the corners of faces that the map collapses or turns over (:func:`collapsed_or_turned`) move; every
    other vertex stays at its partner, so the image of a one-to-one map that keeps the faces' orientation (two
    registrations sharing connectivity) is left exactly as it is.

    Parameters
    ----------
    source, target : TriMesh
    map_xy : (n_x,) int
        The partner of every source vertex (-1: unmatched).
    image : (n_x, 3) float
        The map's image (:func:`corrlib.morph.map_image`); the start, and kept for unmatched vertices.
    """
    map_xy = np.asarray(map_xy)
    landed = np.array(image, dtype=np.float64, copy=True)
    free = np.unique(source.faces[collapsed_or_turned(source.faces, map_xy, target)])
    if free.size == 0:
        return landed
    neighbours = (source.adjacency[free] != 0).astype(np.float64)  # the free vertices' rows of the edge graph
    degree = np.maximum(np.asarray(neighbours.sum(axis=1)).ravel(), 1.0)[:, None]
    neighbourhoods = ring_neighbourhoods(target.adjacency, CANDIDATE_RINGS)
    for _ in range(RELAXATION_STEPS):
        goal = 0.5 * landed[free] + 0.5 * (neighbours @ landed) / degree
        nearby = nearest_candidates(goal, target.vertices, map_xy[free], neighbourhoods)
        faces, weights = closest_surface_points(goal, target, nearby)
        landed[free] = np.einsum("pk,pkc->pc", weights, target.vertices[target.faces[faces]])
    return landed
