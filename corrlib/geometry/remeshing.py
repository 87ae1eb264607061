"""A mesh remeshed to a vertex budget, with the way back to its vertices.

Every mesh is brought to one resolution the same way: a mesh that is not
finer than the budget is first subdivided at its edge midpoints (the same
piecewise-linear surface) until it is; then quadric edge collapse (Garland &
Heckbert, *Surface Simplification Using Quadric Error Metrics*, SIGGRAPH
1997, by the maintained ``fast-simplification`` package) brings it to the
budget, the degenerate faces the collapse leaves on flat regions are
repaired, and tangential relaxation spreads the vertices evenly over the
surface (the smoothing step of isotropic remeshing): quadric collapse leaves
an adaptive mesh, the benchmarks' meshes are uniform. A method that works on
a graph of the mesh's vertices (2D-to-3D matching's product graph) runs on
the remeshed mesh and reports its result on the input mesh through
:attr:`Remeshed.to_original`, the input vertex nearest to every remeshed
vertex.

Why a method would remesh: a discretised energy whose value depends on the
resolution and on the evenness of the triangulation (the product-graph
energy of 2D-to-3D matching grows with the vertex count, and edges longer
than the contour's step push its curve short, see ``docs/decisions.md``)
compares meshes only when they are meshed alike, and its cost grows with
the vertex count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from corrlib.errors import MeshError
from corrlib.shapes import TriMesh, area_weighted_normals, inspect_mesh, triangle_areas


@dataclass(frozen=True)
class Remeshed:
    """A mesh remeshed from another one.

    Attributes
    ----------
    mesh : TriMesh
        The remeshed surface (k vertices), carrying the input's part labels
        at :attr:`to_original` if the input had labels.
    to_original : (k,) int
        The input vertex nearest to every remeshed vertex.
    n_original : int
        The input's vertex count.
    """

    mesh: TriMesh
    to_original: np.ndarray
    n_original: int


def remeshed(mesh: TriMesh, n_vertices: int) -> Remeshed:
    """``mesh`` remeshed to about ``n_vertices`` vertices (see the module docstring).

    The face budget of the collapse is the (subdivided) input's faces in the
    ratio of the vertex budget (``F ≈ 2V`` on a closed surface whatever its
    size), so the result has about ``n_vertices`` vertices (±1 %; where the
    repair merged coincident vertices, :func:`without_degenerate_faces`, the
    collapse runs again with a corrected budget). The result does not depend on the
    order of the input's vertices and faces (:func:`canonical_order`), nor on
    its units or position (the collapse runs at unit area about the centre).
    Cached on disk by the mesh's content, as the spectra are.

    Raises
    ------
    MeshError
        The remeshed surface is not a valid mesh (e.g. an edge collapse left
        a non-manifold edge); the message names the input mesh.
    """
    from corrlib import cache

    if n_vertices < 4:
        raise ValueError(f"n_vertices must be at least 4, got {n_vertices}")
    # on disk like the spectra: a retrieval remeshes each mesh of its collection for every query
    key = cache.make_key("remeshed-v5", mesh.content_hash, n_vertices, RELAXATION_STEPS, RELAXATION_DAMPING)
    entry = cache.load("remeshed", key, {"points": cache.Array("f", ("points", 3)),
                                         "faces": cache.Array("i", (None, 3), below="points"),
                                         "to_original": cache.Array("i", ("points",), below=mesh.n_vertices)})
    if entry is None:
        points, faces, to_original = _remesh(mesh, n_vertices)
        cache.store("remeshed", key, {"points": points, "faces": faces, "to_original": to_original})
    else:
        points, faces, to_original = entry["points"], entry["faces"], entry["to_original"]
    coarse = TriMesh(points, faces, name=f"{mesh.name} (remeshed to {len(points)} vertices)")
    if mesh.labels is not None:
        coarse = coarse.with_labels(mesh.labels[to_original])
    return Remeshed(coarse, to_original, mesh.n_vertices)


def _remesh(mesh: TriMesh, n_vertices: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`remeshed` without the cache: ``(points (k, 3), faces, to_original (k,))``.

    The collapse runs on the mesh centred and scaled to unit area (the package's error thresholds are
    absolute): a mesh in other units or far from the origin is remeshed alike.
    """
    from scipy.spatial import cKDTree

    # in the canonical order first: the centre and the area are sums, whose rounding depends on the order
    points, faces, order = canonical_order(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    centre = points.mean(axis=0)
    scale = np.sqrt(triangle_areas(points, faces).sum())
    unit_points = (points - centre) / scale
    fine = midpoint_subdivided_past(unit_points, faces, n_vertices)
    try:
        points, faces = _decimate_unit(fine, n_vertices)
    except MeshError as err:
        raise MeshError(f"{mesh.name}: {err}") from None
    # a vertex of the subdivided surface that is not one of the input's goes to the input vertex nearest to it
    to_original = order[cKDTree(unit_points).query(points)[1]].astype(np.int64)
    return points * scale + centre, faces, to_original


def canonical_order(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The surface with its vertices sorted by position and its faces by their vertices.

    Quadric edge collapse breaks ties between collapses of equal cost by the order of the input, so the
    same surface given in another vertex or face order would be remeshed differently. Each face is
    rotated to start at its smallest index (its orientation kept).

    Parameters
    ----------
    points : (n, 3) float
    faces : (f, 3) int

    Returns
    -------
    points : (n, 3) float
        Sorted lexicographically by (x, y, z).
    faces : (f, 3) int
        On the sorted points, sorted lexicographically.
    order : (n,) int
        The input index of every sorted point.
    """
    order = np.lexsort((points[:, 2], points[:, 1], points[:, 0]))
    new_index = np.empty_like(order)
    new_index[order] = np.arange(order.size)
    faces = new_index[faces]
    first = np.argmin(faces, axis=1)
    faces = np.take_along_axis(faces, (first[:, None] + np.arange(3)) % 3, axis=1)
    faces = faces[np.lexsort((faces[:, 2], faces[:, 1], faces[:, 0]))]
    return points[order], faces, order


def midpoint_subdivided_past(points: np.ndarray, faces: np.ndarray, n_vertices: int) -> TriMesh:
    """The surface subdivided at its edge midpoints (every face into four, the same piecewise-linear
    surface) until it has more than ``n_vertices`` vertices; as given if it already has."""
    import trimesh

    while len(points) <= n_vertices:
        points, faces = trimesh.remesh.subdivide(points, faces)
    return TriMesh(points, faces, name="surface to remesh", validate=False)


#: how far below the vertex budget the repaired collapse may end before it runs again with a corrected
#: budget, and how often it does
BUDGET_TOLERANCE, BUDGET_ROUNDS = 0.01, 3


def _decimate_unit(mesh: TriMesh, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(points (k, 3), faces)``: ``mesh`` (at unit area, finer than the budget) decimated to about
    ``n_vertices`` vertices, repaired and relaxed."""
    import fast_simplification

    # the face budget in the ratio of the vertex budget; where the repair merged coincident vertices (flat
    # regions, e.g. of a subdivided coarse mesh) the collapse runs again with the budget corrected by that
    # ratio: the energy of a graph on the mesh grows with its vertex count
    face_budget = max(4, round(mesh.n_faces * n_vertices / mesh.n_vertices))
    for _ in range(BUDGET_ROUNDS):
        # writable copies: the extension refuses the mesh's read-only arrays
        points, faces = fast_simplification.simplify(np.array(mesh.vertices, dtype=np.float64),
                                                     np.array(mesh.faces, dtype=np.int32), target_count=face_budget)
        points, faces = without_degenerate_faces(points, faces.astype(np.int64))
        if len(points) >= (1 - BUDGET_TOLERANCE) * n_vertices or face_budget >= mesh.n_faces:
            break
        face_budget = min(mesh.n_faces, round(face_budget * n_vertices / len(points)))
    # the collapse's own output: what is wrong with it, without the loader's advice to repair the input
    errors = [finding for finding in inspect_mesh(points, faces) if finding.level == "error"]
    if errors:
        raise MeshError(f"remeshing to {n_vertices} vertices gave an invalid mesh (the collapse pinched or split a "
                        f"thin part: {errors[0].problem}); change the vertex budget (mesh_vertices), set it to 0 "
                        "to match the mesh as given, or remesh it with another tool first")
    coarse = tangentially_relaxed(TriMesh(points, faces, name="remeshed surface"), mesh)
    return np.asarray(coarse.vertices), np.asarray(coarse.faces)


#: tangential relaxation: iterations and step towards the neighbours' centroid (Botsch & Kobbelt 2004 use a few
#: damped steps per remeshing round; measured: the spread of edge lengths stops falling after about ten)
RELAXATION_STEPS, RELAXATION_DAMPING = 10, 0.5


def tangentially_relaxed(coarse: TriMesh, surface: TriMesh) -> TriMesh:
    """``coarse`` with its vertices spread evenly over ``surface`` (the finer mesh it was decimated from).

    Quadric edge collapse keeps vertices where the surface bends and leaves long edges on flat regions; a
    graph on such a mesh is not the uniform one of a remeshed benchmark shape. Every step moves each vertex
    by ``RELAXATION_DAMPING`` towards the centroid of its neighbours, within its tangent plane, and back onto
    ``surface`` (onto the tangent plane of the nearest surface vertex: ``surface`` is the finer mesh), the
    tangential smoothing of isotropic remeshing (Botsch & Kobbelt, *A Remeshing Approach to
    Multiresolution Modeling*, SGP 2004). The connectivity is kept. A vertex whose move would turn one of
    its faces over (its normal against the one before the step) stays for that step, so no face is turned
    over; a vertex on the boundary of an open surface stays where it is. If the result is not a valid mesh,
    ``coarse`` is returned as it was.
    """
    from scipy.spatial import cKDTree

    faces = coarse.faces
    n = coarse.n_vertices
    edges = coarse.edges
    rows, cols = np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]]
    neighbours = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n)).tocsr()
    valence = np.asarray(neighbours.sum(axis=1)).ravel()
    # a boundary vertex stays: the centroid of its neighbours lies inside the surface, so it would draw the
    # boundary in
    half_edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edge_rows, face_count = np.unique(half_edges, axis=0, return_counts=True)
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[edge_rows[face_count == 1].ravel()] = True
    nearest = cKDTree(surface.vertices)
    surface_normals = surface.vertex_normals
    points = np.array(coarse.vertices)
    for _ in range(RELAXATION_STEPS):
        normals = area_weighted_normals(points, faces)
        move = (neighbours @ points) / valence[:, None] - points
        move -= np.sum(move * normals, axis=1, keepdims=True) * normals
        move[on_boundary] = 0.0
        moved = points + RELAXATION_DAMPING * move
        foot = nearest.query(moved)[1]
        moved -= np.sum((moved - surface.vertices[foot]) * surface_normals[foot], axis=1,
                        keepdims=True) * surface_normals[foot]
        moved[on_boundary] = points[on_boundary]
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


#: points closer than this fraction of the median edge length are one point of the surface: quadric collapse of a
#: flat region (a subdivided mesh) leaves vertex pairs 1e-7 of an edge apart, whose needle triangles carry no area
#: and whose tangential relaxation moves both alike
COINCIDENT_FRACTION = 1e-4


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

    from corrlib.shapes import degenerate_faces

    diag = float(np.linalg.norm(np.ptp(points, axis=0))) or 1.0
    faces = faces.copy()
    edge_lengths = np.linalg.norm(points[faces] - points[np.roll(faces, 1, axis=1)], axis=2)
    same_point = max(diag * 1e-9, COINCIDENT_FRACTION * float(np.median(edge_lengths)))
    for _ in range(max_rounds):
        # coincident points (closer than the mesh resolves, see COINCIDENT_FRACTION): one representative each;
        # faces repeating a vertex go
        pairs = cKDTree(points).query_pairs(same_point, output_type="ndarray")
        if len(pairs):
            graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
            _, component = connected_components(graph, directed=False)
            representative = np.full(component.max() + 1, len(points))
            np.minimum.at(representative, component, np.arange(len(points)))
            faces = representative[component][faces]
        faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
        caps = np.flatnonzero(degenerate_faces(points, faces))
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
