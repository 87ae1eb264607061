"""Decimation of a mesh to a vertex budget, with the way back to its vertices.

Quadric edge collapse (Garland & Heckbert, *Surface Simplification Using
Quadric Error Metrics*, SIGGRAPH 1997), by the maintained ``fast-simplification``
package, with the degenerate faces it leaves on flat regions repaired, then
the vertices spread evenly over the input surface by tangential relaxation
(the smoothing step of isotropic remeshing): quadric collapse leaves an
adaptive mesh, the benchmarks' meshes are uniform. A method that works on a
graph of the mesh's vertices (2D-to-3D matching's product graph) runs on the
decimated mesh and reports its result on the input mesh through
:attr:`Decimated.to_original`, the input vertex nearest to every decimated
vertex.

Why a method would decimate: a discretised energy whose value depends on the
resolution (the product-graph energy of 2D-to-3D matching grows with the
vertex count, see ``docs/decisions.md``) compares meshes only at one
resolution, and its cost grows with the vertex count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from corrlib.errors import MeshError
from corrlib.shapes import TriMesh, area_weighted_normals


@dataclass(frozen=True)
class Decimated:
    """A mesh decimated from a finer one.

    Attributes
    ----------
    mesh : TriMesh
        The decimated mesh (k vertices), carrying the input's part labels at
        :attr:`to_original` if the input had labels.
    to_original : (k,) int
        The input vertex nearest to every decimated vertex.
    n_original : int
        The input's vertex count.
    """

    mesh: TriMesh
    to_original: np.ndarray
    n_original: int


def decimated(mesh: TriMesh, max_vertices: int) -> Decimated | None:
    """``mesh`` decimated to about ``max_vertices`` vertices, or None if it has no more than that.

    The face budget is the input's faces in the ratio of the vertex budget
    (``F ≈ 2V`` on a closed surface whatever its size), so the result has
    about ``max_vertices`` vertices: ±1 %, or a few per cent fewer where the
    repair merged coincident vertices (:func:`without_degenerate_faces`).

    Raises
    ------
    MeshError
        The decimated surface is not a valid mesh (e.g. an edge collapse left
        a non-manifold edge); the message names the input mesh.
    """
    from corrlib import cache

    if max_vertices < 4:
        raise ValueError(f"max_vertices must be at least 4, got {max_vertices}")
    if mesh.n_vertices <= max_vertices:
        return None
    # on disk like the spectra: a retrieval decimates each mesh of its collection for every query
    key = cache.make_key("decimated-v2", mesh.content_hash, max_vertices, RELAXATION_STEPS, RELAXATION_DAMPING)
    entry = cache.load("decimated", key)
    if entry is None:
        points, faces, to_original = _decimate(mesh, max_vertices)
        cache.store("decimated", key, {"points": points, "faces": faces, "to_original": to_original})
    else:
        points, faces, to_original = entry["points"], entry["faces"], entry["to_original"]
    coarse = TriMesh(points, faces, name=f"{mesh.name} (decimated to {len(points)} vertices)")
    if mesh.labels is not None:
        coarse = coarse.with_labels(mesh.labels[to_original])
    return Decimated(coarse, to_original, mesh.n_vertices)


def _decimate(mesh: TriMesh, max_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`decimated` without the cache: ``(points (k, 3), faces, to_original (k,))``.

    The collapse runs on the mesh centred and scaled to unit area (the package's error thresholds are
    absolute): a mesh in other units or far from the origin is decimated alike.
    """
    centre, scale = mesh.vertices.mean(axis=0), np.sqrt(mesh.area)
    unit = TriMesh((mesh.vertices - centre) / scale, mesh.faces, name=mesh.name, validate=False)
    points, faces, to_original = _decimate_unit(unit, max_vertices)
    return points * scale + centre, faces, to_original


def _decimate_unit(mesh: TriMesh, max_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_decimate` on a mesh at unit area."""
    import fast_simplification
    from scipy.spatial import cKDTree

    face_budget = max(4, round(mesh.n_faces * max_vertices / mesh.n_vertices))
    # writable copies: the extension refuses the mesh's read-only arrays
    points, faces = fast_simplification.simplify(np.array(mesh.vertices, dtype=np.float64),
                                                 np.array(mesh.faces, dtype=np.int32), target_count=face_budget)
    points, faces = without_degenerate_faces(points, faces.astype(np.int64))
    name = f"{mesh.name} (decimated to {points.shape[0]} vertices)"
    try:
        coarse = TriMesh(points, faces, name=name)
    except MeshError as err:
        raise MeshError(f"{mesh.name}: decimating {mesh.n_vertices} to {max_vertices} vertices gave an invalid "
                        f"mesh ({err}); decimate it with another tool first, or raise the vertex budget") from None
    coarse = tangentially_relaxed(coarse, mesh)
    to_original = cKDTree(mesh.vertices).query(coarse.vertices)[1].astype(np.int64)
    return np.asarray(coarse.vertices), np.asarray(coarse.faces), to_original


#: tangential relaxation: iterations and step towards the neighbours' centroid (Botsch & Kobbelt 2004 use a few
#: damped steps per remeshing round; measured: the spread of edge lengths stops falling after about ten)
RELAXATION_STEPS, RELAXATION_DAMPING = 10, 0.5


def tangentially_relaxed(coarse: TriMesh, surface: TriMesh) -> TriMesh:
    """``coarse`` with its vertices spread evenly over ``surface`` (the mesh it was decimated from).

    Quadric edge collapse keeps vertices where the surface bends and leaves long edges on flat regions; a
    graph on such a mesh is not the uniform one of a remeshed benchmark shape. Every step moves each vertex
    by ``RELAXATION_DAMPING`` towards the centroid of its neighbours, within its tangent plane, and back onto
    ``surface`` (onto the tangent plane of the nearest surface vertex: ``surface`` is the finer mesh), the
    tangential smoothing of isotropic remeshing (Botsch & Kobbelt, *A Remeshing Approach to
    Multiresolution Modeling*, SGP 2004). The connectivity is kept. A vertex whose move would turn one of
    its faces over (its normal against the one before the step) stays for that step, so no face is turned
    over; if the result is not a valid mesh, ``coarse`` is returned as it was.
    """
    from scipy.spatial import cKDTree

    faces = coarse.faces
    n = coarse.n_vertices
    edges = coarse.edges
    rows, cols = np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]
    neighbours = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    valence = np.asarray(neighbours.sum(axis=1)).ravel()
    nearest = cKDTree(surface.vertices)
    surface_normals = surface.vertex_normals
    points = np.array(coarse.vertices)
    for _ in range(RELAXATION_STEPS):
        normals = area_weighted_normals(points, faces)
        move = (neighbours @ points) / valence[:, None] - points
        move -= np.sum(move * normals, axis=1, keepdims=True) * normals
        moved = points + RELAXATION_DAMPING * move
        foot = nearest.query(moved)[1]
        moved -= np.sum((moved - surface.vertices[foot]) * surface_normals[foot], axis=1,
                        keepdims=True) * surface_normals[foot]
        # a vertex whose move would turn one of its faces over (against its normal before the step) stays;
        # a turned face has a moved vertex, so every round keeps at least one more vertex and this ends
        before = _face_normals(points, faces)
        while True:
            turned = ~(np.sum(before * _face_normals(moved, faces), axis=1) > 0)
            turned &= np.any(moved[faces] != points[faces], axis=(1, 2))  # a face that did not move stays as it was
            if not turned.any():
                break
            stay = np.unique(faces[turned])
            moved[stay] = points[stay]
        points = moved
    try:
        return TriMesh(points, faces, name=coarse.name)
    except MeshError:
        return coarse


def _face_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f, 3) float: unit face normals (NaN for a face of zero area)."""
    n = np.cross(points[faces[:, 1]] - points[faces[:, 0]], points[faces[:, 2]] - points[faces[:, 0]])
    with np.errstate(invalid="ignore", divide="ignore"):
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def without_degenerate_faces(points: np.ndarray, faces: np.ndarray, max_rounds: int = 20):
    """The surface of ``(points, faces)`` without the zero-area faces an edge collapse can leave.

    Quadric edge collapse on a flat region leaves two kinds (the quadric has no unique minimum there):
    faces with two coincident vertices, which are merged (and their faces dropped), and *caps*, a vertex
    on the opposite edge, whose longest edge is flipped (the two triangles across it become two of
    positive area, the surface unchanged). It can also fold a triangle onto its own reverse (a *fin*,
    two faces on the same three vertices), which bounds nothing and is dropped. Unreferenced points are
    dropped.

    Parameters
    ----------
    points : (n, 3) float
    faces : (f, 3) int

    Returns
    -------
    points : (n', 3) float
    faces : (f', 3) int
    """
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from corrlib.shapes import TOL

    diag = float(np.linalg.norm(np.ptp(points, axis=0))) or 1.0
    faces = faces.copy()
    for _ in range(max_rounds):
        # coincident points (closer than 1e-9 of the diagonal): one representative each; faces repeating a
        # vertex go
        pairs = cKDTree(points).query_pairs(diag * 1e-9, output_type="ndarray")
        if len(pairs):
            graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
            _, component = connected_components(graph, directed=False)
            representative = np.full(component.max() + 1, len(points))
            np.minimum.at(representative, component, np.arange(len(points)))
            faces = representative[component][faces]
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
        area = 0.5 * np.linalg.norm(np.cross(points[faces[:, 1]] - points[faces[:, 0]],
                                             points[faces[:, 2]] - points[faces[:, 0]]), axis=1)
        caps = np.flatnonzero(area <= TOL.zero_area * diag ** 2)
        if caps.size == 0:
            break
        if not _flip_cap_edges(points, faces, caps):  # blocked flips: the cap's apex joins its nearer end
            points = points.copy()
            for cap in faces[caps]:
                r = min(range(3), key=lambda r: _outside_segment(points, cap[r], cap[r - 1], cap[r - 2]))
                apex, ends = cap[r], (cap[r - 1], cap[r - 2])
                nearer = min(ends, key=lambda e: np.linalg.norm(points[e] - points[apex]))
                points[apex] = points[nearer]  # coincident now: merged in the next round
    # a face and its reverse (a fin folded onto itself, two faces on the same three vertices): no surface
    _, copy_of, copies = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    faces = faces[copies[copy_of.ravel()] == 1]
    used = np.unique(faces)
    new_index = np.full(points.shape[0], -1, dtype=np.int64)
    new_index[used] = np.arange(used.size)
    return points[used], new_index[faces]


def _flip_cap_edges(points: np.ndarray, faces: np.ndarray, caps: np.ndarray) -> bool:
    """Flip the longest edge of every cap in ``caps`` (face indices), in place; whether any was flipped.

    A cap ``(a, b, c)`` with ``c`` on its longest edge ``ab`` and the face ``(b, a, d)`` across it bound the
    quad ``a, d, b, c``; its other diagonal gives ``(a, d, c)`` and ``(d, b, c)``. A flip that would
    repeat an existing edge (a non-manifold surface) is skipped.
    """
    edge_face = {}
    for index, (i, j, k) in enumerate(faces):
        edge_face[(i, j)] = edge_face[(j, k)] = edge_face[(k, i)] = index
    edges = {tuple(sorted(e)) for e in edge_face}
    touched: set[int] = set()
    flipped = False
    for cap in caps:
        if cap in touched:
            continue
        tri = faces[cap]
        lengths = [np.linalg.norm(points[tri[(r + 1) % 3]] - points[tri[r]]) for r in range(3)]
        r = int(np.argmax(lengths))
        a, b, c = tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3]
        other = edge_face.get((b, a))
        if other is None or other in touched:
            continue
        d = [v for v in faces[other] if v != a and v != b][0]
        if d == c or tuple(sorted((c, d))) in edges:
            continue
        faces[cap] = (a, d, c)
        faces[other] = (d, b, c)
        edges.discard(tuple(sorted((a, b))))
        edges.add(tuple(sorted((c, d))))
        touched.update((int(cap), int(other)))
        flipped = True
    return flipped


def _outside_segment(points: np.ndarray, p: int, a: int, b: int) -> float:
    """How far point ``p`` is *outside* the segment ``ab`` along it (0 for a point between ``a`` and ``b``):
    the apex of a cap is the vertex that lies between the other two."""
    ab = points[b] - points[a]
    t = float(np.dot(points[p] - points[a], ab) / max(float(np.dot(ab, ab)), 1e-300))
    return max(0.0, -t, t - 1.0)
