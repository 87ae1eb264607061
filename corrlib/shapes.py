"""Shape types: :class:`TriMesh` (triangle mesh) and :class:`Contour2D` (closed 2D polygon).

Both hold read-only float64 / int64 arrays and compute derived quantities
(areas, normals, edges, boundary, ...) lazily, once. Construction validates
the input and raises :class:`~corrlib.errors.MeshError` or
:class:`~corrlib.errors.ContourError` with a message that names the shape and
the problem; :func:`inspect_mesh` and :func:`inspect_contour` return the same
findings as a list without raising (for validation reports).

Tolerances live in :data:`TOL`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from corrlib.errors import ContourError, MeshError


@dataclass(frozen=True)
class Tolerances:
    """Numerical tolerances used by validation (relative to the shape's size)."""

    #: a face is degenerate if its area <= zero_area * its longest edge * bbox_diagonal (:func:`degenerate_faces`)
    zero_area: float = 1e-12
    #: contour segments shorter than this fraction of the perimeter are merged
    zero_length: float = 1e-12
    #: a contour file is "closed" if its end-to-start gap is at most this many median spacings
    closing_gap: float = 5.0


TOL = Tolerances()


@dataclass(frozen=True)
class Finding:
    """One validation finding.

    Attributes
    ----------
    level : str
        ``"error"`` (the shape cannot be used) or ``"warning"``.
    code : str
        Short machine-readable identifier, e.g. ``"non-manifold-edge"``.
    message : str
        Human-readable explanation with counts and example indices, ending with ``advice`` if there is one.
    advice : str
        How the user can fix the input (e.g. :data:`REPAIR_ADVICE`), or "".
    """

    level: str
    code: str
    message: str
    advice: str = ""

    @property
    def problem(self) -> str:
        """The message without its advice: what is wrong, for a caller whose input is not at fault (a mesh it
        made itself, such as a remeshed surface)."""
        return self.message.removesuffix(f"; {self.advice}") if self.advice else self.message


def _repairable(code: str, problem: str, advice: str | None = None) -> Finding:
    """An error finding that ``corr repair`` removes: ``problem`` with ``advice`` (default :data:`REPAIR_ADVICE`)."""
    advice = REPAIR_ADVICE if advice is None else advice
    return Finding("error", code, f"{problem}; {advice}", advice)


def readonly_view(a, dtype) -> np.ndarray:
    """``a`` as a C-contiguous array of ``dtype`` that cannot be written through; ``a``'s own flags are left as
    they are (a view, or a copy where the layout or the dtype differ).

    Numba compiles a kernel once per argument type, and a read-only array is another type than a writable one.
    The arrays of :class:`TriMesh` and :class:`Contour2D` are read-only; handing a kernel every input array
    through this function gives it one signature for every caller, the one the warm-up compiles ahead
    (:mod:`corrlib.warmup`), instead of a second compilation the first time a caller passes its own array.
    """
    view = np.ascontiguousarray(a, dtype=dtype).view()
    view.flags.writeable = False
    return view


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _examples(idx: np.ndarray, n: int = 5) -> str:
    idx = np.asarray(idx).ravel()
    shown = ", ".join(str(int(i)) for i in idx[:n])
    return shown + (", ..." if idx.size > n else "")


# ----------------------------------------------------------------------------- meshes


def triangle_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    e1 = vertices[faces[:, 1]] - vertices[faces[:, 0]]
    e2 = vertices[faces[:, 2]] - vertices[faces[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def degenerate_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f,) bool: faces flat to the precision of their coordinates, whose area is at most
    ``TOL.zero_area`` × their longest edge × the bounding-box diagonal ``d``.

    That is a height over the longest edge of at most ``2 TOL.zero_area d``. Coordinates of size ``d`` are
    rounded to about ``1e-16 d``, so such a face's vertices are collinear or coincide as far as the numbers
    tell: its normal and angles are undefined (cotangents 0/0 or infinite). A face that is merely small but
    well shaped (marching cubes leaves them where the surface passes near a grid point) is not degenerate,
    however small against the shape: its angles are as well defined as any face's.
    """
    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces)
    diag = float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) if v.size else 0.0
    corners = v[f]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    return triangle_areas(v, f) <= TOL.zero_area * longest * max(diag, 1e-300)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume enclosed by a closed triangle surface (divergence theorem; positive if outward-oriented).

    The sum of the tetrahedra from the origin does not depend on where the origin is; it is taken at the
    vertices' mean, so that a shape far from the origin does not lose its volume to cancellation."""
    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces)
    v = v - v.mean(axis=0)
    return float(np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6.0)


def area_weighted_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(n, 3) float: area-weighted unit vertex normals; zero for vertices in no non-degenerate face."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = v.shape[0]
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # 2 * area * unit normal
    out = np.empty((n, 3))
    for k in range(3):
        out[:, k] = np.bincount(f.ravel(), weights=np.repeat(fn[:, k], 3), minlength=n)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def face_components(n_vertices: int, faces: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the vertex graph induced by the faces."""
    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    graph = sp.coo_matrix((np.ones(rows.size), (rows, cols)), shape=(n_vertices, n_vertices))
    return connected_components(graph, directed=False)


def _as_arrays(vertices, faces) -> tuple[np.ndarray, np.ndarray, list[Finding]]:
    """Convert to float64 (n,3) / int64 (f,3); structural errors stop further checks."""
    findings: list[Finding] = []
    if np.iscomplexobj(vertices):  # NumPy would drop the imaginary parts with only a warning
        return None, None, [Finding("error", "vertices-type", "vertices are complex numbers; real coordinates "
                                    "are needed")]
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        return None, None, [Finding("error", "vertices-type", f"vertices are not numeric: {exc}")]
    try:
        f_raw = np.asarray(faces)
        if f_raw.size and not np.issubdtype(f_raw.dtype, np.integer):
            f_float = f_raw.astype(np.float64)
            if not np.all(np.isfinite(f_float)) or np.any(f_float != np.round(f_float)):
                return v, None, [Finding("error", "faces-type", "face indices are not integers")]
        f = f_raw.astype(np.int64)
    except (TypeError, ValueError, OverflowError) as exc:
        return v, None, [Finding("error", "faces-type", f"faces are not integer vertex indices: {exc}")]
    if v.ndim != 2 or v.shape[1] != 3:
        findings.append(Finding("error", "vertices-shape", f"vertices must have shape (n, 3), got {v.shape}"))
    elif v.shape[0] == 0:
        findings.append(Finding("error", "empty", "the mesh has no vertices"))
    if f.ndim != 2 or f.shape[1] != 3:
        if f.size == 0:
            findings.append(Finding("error", "empty", "the mesh has no faces"))
        else:
            findings.append(
                Finding("error", "faces-shape", f"faces must have shape (f, 3) (triangles only), got {f.shape}")
            )
    elif f.shape[0] == 0:
        findings.append(Finding("error", "empty", "the mesh has no faces"))
    return v, f, findings


def inspect_mesh(vertices, faces) -> list[Finding]:
    """Validate a triangle mesh and return every finding without raising.

    Parameters
    ----------
    vertices : (n, 3) array_like of float
    faces : (f, 3) array_like of int

    Returns
    -------
    list of Finding
        Errors first, then warnings. An empty list means a clean, closed,
        connected, manifold mesh.
    """
    v, f, findings = _as_arrays(vertices, faces)
    if findings:
        return findings
    findings = _value_findings(v, f)
    if findings:  # NaN coordinates or indices out of range: the other checks cannot run
        return findings
    n = v.shape[0]
    findings += _face_findings(v, f)
    edges = _Edges.of(f, n)
    findings += _manifold_findings(edges)
    findings += _duplicate_face_findings(f, n)
    findings += _connectivity_findings(v, f)
    findings += _edge_warnings(edges)
    findings += _pinched_vertex_warnings(f, edges)
    return findings


#: the advice of the findings that ``corr repair`` (:mod:`corrlib.repair`) removes
REPAIR_ADVICE = ("`corr repair FILE -o FIXED.off` writes the mesh repaired (welded, degenerate and repeated faces "
                 "and loose parts dropped, each said) and the input vertex of each of its vertices, so that ground "
                 "truth can follow; or repair it in a mesh editor")

#: coordinates are usable while squared lengths (a contour) stay finite and non-zero in float64 (about 1e±308)
COORDINATE_LIMITS = (1e-150, 1e150)
#: a mesh's squared triangle areas are fourth powers of its coordinates (the Laplacian's cotangents divide by them)
MESH_COORDINATE_LIMITS = (1e-75, 1e75)


def _coordinate_scale_problem(points: np.ndarray, limits: tuple[float, float] = COORDINATE_LIMITS,
                              what: str = "squared lengths") -> str:
    """A message if the coordinates are too large or their spread too small for ``what`` (the highest power of
    them that is formed), else ''."""
    if points.size == 0:
        return ""
    largest = float(np.abs(points).max())
    if largest > limits[1]:
        return f"coordinates up to {largest:.3g} overflow {what} (at most {limits[1]:.0e}); rescale the input"
    spread = float(np.abs(points - points.mean(axis=0)).max())
    if 0 < spread < limits[0]:
        return (f"the coordinates span only {spread:.3g}, too small for {what} (at least {limits[0]:.0e}); "
                "rescale the input")
    return ""


def _value_findings(v: np.ndarray, f: np.ndarray) -> list[Finding]:
    """Non-finite coordinates, then face indices out of range (each stops the inspection)."""
    n = v.shape[0]
    bad_rows = np.flatnonzero(~np.all(np.isfinite(v), axis=1))
    if bad_rows.size:
        return [Finding("error", "non-finite", f"{bad_rows.size} vertices have NaN or infinite coordinates "
                        f"(e.g. vertex {_examples(bad_rows)})")]
    scale = _coordinate_scale_problem(v, MESH_COORDINATE_LIMITS, "squared triangle areas")
    if scale:
        return [Finding("error", "coordinate-scale", scale)]
    out_of_range = np.flatnonzero(np.any((f < 0) | (f >= n), axis=1))
    if out_of_range.size:
        return [Finding("error", "index-range", f"{out_of_range.size} faces reference vertex indices outside "
                        f"[0, {n - 1}] (e.g. face {_examples(out_of_range)})")]
    return []


def _face_findings(v: np.ndarray, f: np.ndarray) -> list[Finding]:
    """Faces that repeat a vertex, and (other) faces of zero area."""
    findings = []
    repeated = np.flatnonzero((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2]))
    if repeated.size:
        findings.append(
            _repairable("degenerate-face", f"{repeated.size} faces repeat a vertex index "
                        f"(e.g. face {_examples(repeated)})")
        )
    zero = np.setdiff1d(np.flatnonzero(degenerate_faces(v, f)), repeated)
    if zero.size:
        findings.append(
            _repairable("zero-area-face", f"{zero.size} faces have zero area: their vertices are collinear "
                        f"or coincide to the precision of the coordinates (e.g. face {_examples(zero)})")
        )
    return findings


@dataclass(frozen=True)
class _Edges:
    """The half-edges of a face array and their undirected edges (for the manifold and boundary checks)."""

    half: np.ndarray  # (3f, 2) directed half-edges, once per face
    uniq: np.ndarray  # (e, 2) undirected edges, sorted
    inverse: np.ndarray  # (3f,) edge of each half-edge
    counts: np.ndarray  # (e,) faces per edge

    @classmethod
    def of(cls, f: np.ndarray, n: int) -> _Edges:
        half = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        und = np.sort(half, axis=1)
        # 1-D integer keys: np.unique on rows (axis=0) sorts structured views, several times slower
        edge_keys, inverse, counts = np.unique(und[:, 0] * np.int64(n) + und[:, 1], return_inverse=True,
                                               return_counts=True)
        uniq = np.column_stack(np.divmod(edge_keys, np.int64(n)))
        return cls(half, uniq, inverse.ravel(), counts)

    @property
    def non_manifold(self) -> np.ndarray:
        return np.flatnonzero(self.counts > 2)


def _manifold_findings(edges: _Edges) -> list[Finding]:
    nm = edges.non_manifold
    if not nm.size:
        return []
    a, b = edges.uniq[nm[0]]
    return [Finding("error", "non-manifold-edge", f"{nm.size} edges are shared by more than two faces "
                    f"(e.g. edge {a}-{b}); the methods need a surface whose every edge borders one or two faces "
                    "(repair it in a mesh editor, e.g. by splitting the edges or deleting the extra faces)")]


def _duplicate_face_findings(f: np.ndarray, n: int) -> list[Finding]:
    sorted_faces = np.sort(f, axis=1)
    if n < 2_000_000:  # n³ fits in int64
        dup_faces = np.unique((sorted_faces[:, 0] * np.int64(n) + sorted_faces[:, 1]) * np.int64(n)
                              + sorted_faces[:, 2]).size
    else:
        dup_faces = np.unique(sorted_faces, axis=0).shape[0]
    if dup_faces < f.shape[0]:
        return [_repairable("duplicate-face", f"{f.shape[0] - dup_faces} faces are duplicates")]
    return []


def _connectivity_findings(v: np.ndarray, f: np.ndarray) -> list[Finding]:
    """Vertices in no face, and more than one connected component (with the advice to weld where the
    components touch at repeated vertex positions: a triangle soup, as STL stores a mesh)."""
    findings = []
    n = v.shape[0]
    used = np.zeros(n, dtype=bool)
    used[f.ravel()] = True
    unused = np.flatnonzero(~used)
    if unused.size:
        findings.append(
            _repairable("unreferenced-vertex", f"{unused.size} vertices belong to no face "
                        f"(e.g. vertex {_examples(unused)})")
        )
    _, labels = face_components(n, f)
    n_comp_used = np.unique(labels[used]).size
    if n_comp_used > 1:
        sizes = np.bincount(labels[used])
        sizes = np.sort(sizes[sizes > 0])[::-1]
        counts = f"{', '.join(map(str, sizes[:5]))}{', ...' if sizes.size > 5 else ''}"
        _, position = np.unique(v, axis=0, return_inverse=True)
        position = position.ravel()
        n_welded = np.unique(face_components(n, position[f])[1][position[used]]).size
        if n_welded < n_comp_used:  # the parts share positions but not vertices
            advice = (f"{n - (position.max() + 1)} vertices repeat the position of another, so faces that "
                      f"meet there are not joined (welded, {n_welded} component{'s' if n_welded > 1 else ''} would "
                      f"remain); {REPAIR_ADVICE}")
        else:
            advice = f"to keep the largest part, {REPAIR_ADVICE}"
        findings.append(
            _repairable("components", f"the mesh has {n_comp_used} connected components (vertex counts {counts})",
                        advice)
        )
    return findings


def consistently_oriented(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, int]:
    """The faces with their windings made to agree across every edge, and the number of faces turned.

    Two faces that share an edge agree when they traverse it in opposite directions (then their normals point
    to the same side). Breadth-first over the faces joined by edges of exactly two faces, a face that
    traverses the shared edge in its parent's direction is turned. In every patch of faces so joined, the
    winding most of the input's faces have is kept (a file with some wrong faces keeps its outside). Where
    that cannot make every edge agree (a non-orientable surface such as a Möbius strip), the input is
    returned unchanged with 0.

    Parameters
    ----------
    faces : (f, 3) int
    n_vertices : int

    Returns
    -------
    faces : (f, 3) int
    turned : int
    """
    f = np.asarray(faces, dtype=np.int64)
    n_faces = f.shape[0]
    edges = _Edges.of(f, n_vertices)
    owner = np.tile(np.arange(n_faces), 3)  # the face of every half-edge
    order = np.argsort(edges.inverse, kind="stable")  # half-edges grouped by edge
    starts = np.concatenate([[0], np.cumsum(edges.counts)[:-1]])
    pairs = starts[edges.counts == 2]  # edges of exactly two faces
    first, second = order[pairs], order[pairs + 1]
    same_direction = np.all(edges.half[first] == edges.half[second], axis=1)  # disagree: one must turn
    a, b = owner[first], owner[second]
    graph = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n_faces, n_faces)).tocsr()
    graph = graph + graph.T
    pair_keys = np.concatenate([a * np.int64(n_faces) + b, b * np.int64(n_faces) + a])
    pair_same = np.concatenate([same_direction, same_direction])
    key_order = np.argsort(pair_keys)
    pair_keys, pair_same = pair_keys[key_order], pair_same[key_order]
    turn = np.zeros(n_faces, dtype=bool)
    seen = np.zeros(n_faces, dtype=bool)
    for root in range(n_faces):
        if seen[root]:
            continue
        patch, parent = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        seen[patch] = True
        children = patch[1:]
        tree_keys = parent[children] * np.int64(n_faces) + children
        tree_same = pair_same[np.searchsorted(pair_keys, tree_keys)].tolist()
        parents = parent[children].tolist()
        turned = {int(root): False}
        for child, up, same in zip(children.tolist(), parents, tree_same):
            turned[child] = turned[up] ^ same
        patch_turn = np.fromiter((turned[int(i)] for i in patch), dtype=bool, count=patch.size)
        if 2 * np.count_nonzero(patch_turn) > patch.size:  # keep the winding most of the patch has
            patch_turn = ~patch_turn
        turn[patch] = patch_turn
    if not turn.any() or np.any(same_direction ^ turn[a] ^ turn[b]):  # nothing to turn, or non-orientable
        return f, 0
    out = f.copy()
    out[turn] = out[turn][:, ::-1]
    return out, int(np.count_nonzero(turn))


def _edge_warnings(edges: _Edges) -> list[Finding]:
    """Inconsistent orientation (only on a manifold mesh) and a boundary."""
    findings = []
    if not edges.non_manifold.size:
        # consistent orientation: each undirected interior edge must appear once in each direction
        directed = edges.half[:, 0] < edges.half[:, 1]
        fwd = np.bincount(edges.inverse[directed], minlength=edges.uniq.shape[0])
        bad = np.flatnonzero((edges.counts == 2) & (fwd != 1))
        if bad.size:
            findings.append(
                Finding("warning", "orientation", f"{bad.size} interior edges join faces of inconsistent "
                        "orientation (normals may flip)")
            )
    n_boundary = int(np.sum(edges.counts == 1))
    if n_boundary:
        findings.append(
            Finding("warning", "boundary", f"the mesh has a boundary ({n_boundary} boundary edges); "
                    "Neumann boundary conditions are used")
        )
    return findings


def _pinched_vertex_warnings(f: np.ndarray, edges: _Edges) -> list[Finding]:
    """Vertices where separate fans of faces meet (a non-manifold vertex: two sheets, or two parts, touching at
    one point). The faces round a vertex of a surface are one fan, linked through the edges at that vertex;
    the corners of each face are joined across every edge of two faces, and a vertex whose corners fall into
    several groups is pinched."""
    from scipy.sparse import coo_matrix

    n_faces = f.shape[0]
    if edges.non_manifold.size or not n_faces:
        return []  # refused already (an edge of three faces)
    order = np.argsort(edges.inverse, kind="stable")
    interior = np.repeat(edges.counts == 2, edges.counts)  # the half-edges in ``order``, grouped by edge
    first, second = order[interior][0::2], order[interior][1::2]
    links = []
    for end in (0, 1):  # both ends of the shared edge: the vertex's corner in each of the two faces
        vertex = edges.half[first, end]
        corners = []
        for half in (first, second):
            face, start = half % n_faces, half // n_faces
            position = np.where(f[face, start] == vertex, start, (start + 1) % 3)
            corners.append(position * n_faces + face)
        links.append(corners)
    rows = np.concatenate([links[0][0], links[1][0]])
    cols = np.concatenate([links[0][1], links[1][1]])
    graph = coo_matrix((np.ones(rows.size), (rows, cols)), shape=(3 * n_faces, 3 * n_faces))
    _, fan = connected_components(graph, directed=False)
    corner_vertex = f.T.ravel()  # corner p * n_faces + face holds f[face, p]
    fans = np.unique(corner_vertex * np.int64(fan.max() + 1) + fan) // (fan.max() + 1)  # one entry per fan
    pinched = np.flatnonzero(np.bincount(fans) > 1)
    if not pinched.size:
        return []
    return [Finding("warning", "pinched-vertex", f"{pinched.size} vertices join separate fans of faces (e.g. "
                    f"vertex {_examples(pinched)}): the surface touches itself there, and distances and spectra "
                    "pass through that point")]


def _check_labels(labels, n: int, name: str, error):
    lab = np.asarray(labels)
    if lab.shape != (n,) or not (np.issubdtype(lab.dtype, np.integer) or
                                 (np.issubdtype(lab.dtype, np.floating) and np.all(lab == np.round(lab)))):
        raise error(f"{name}: labels must be {n} integers (one per point/vertex), got {lab.dtype} {lab.shape}")
    return _readonly(lab.astype(np.int64))


class TriMesh:
    """An immutable triangle mesh with lazily computed derived quantities.

    Parameters
    ----------
    vertices : (n, 3) array_like of float
    faces : (f, 3) array_like of int
        Zero-based vertex indices, counter-clockwise seen from outside.
    name : str
        Shown in error messages (usually the file name).
    validate : bool
        Run :func:`inspect_mesh` and raise :class:`MeshError` on the first error.
    labels : (n,) int, optional
        Per-vertex part labels (0 = unlabelled).

    Raises
    ------
    MeshError
        Empty input, NaN/inf coordinates, face indices out of range, degenerate
        or zero-area faces, non-manifold edges, unreferenced vertices, several
        connected components.
    """

    def __init__(self, vertices, faces, *, name: str = "mesh", validate: bool = True, labels=None):
        self.name = str(name)
        self._findings = None
        if validate:
            findings = inspect_mesh(vertices, faces)
            errors = [fd for fd in findings if fd.level == "error"]
            if errors:
                raise MeshError(f"{self.name}: {errors[0].message}")
            self._findings = findings  # kept for report(): a mesh is inspected once
        self.vertices = _readonly(np.asarray(vertices, dtype=np.float64))
        self.faces = _readonly(np.asarray(faces, dtype=np.int64))
        self.labels = None if labels is None else _check_labels(labels, self.n_vertices, self.name, MeshError)

    def with_labels(self, labels) -> "TriMesh":
        """A copy carrying per-vertex part labels (int, 0 = unlabelled)."""
        out = TriMesh(self.vertices, self.faces, name=self.name, validate=False, labels=labels)
        out.original_indices = self.original_indices
        return out

    @classmethod
    def from_arrays(cls, vertices, faces, *, name: str = "mesh", largest_component: bool = False) -> "TriMesh":
        """Build a mesh, optionally keeping only its largest connected component.

        With ``largest_component=True`` vertices outside the largest component
        by surface area (and unreferenced vertices) are removed; the kept original
        indices are available as :attr:`original_indices`.

        Faces whose windings disagree with their neighbours' (half of a file's faces turned by an exporter) are
        turned to agree (:func:`consistently_oriented`; normals, descriptors that tell left from right and the
        orientation terms all need one winding), and :meth:`report` says how many. A closed surface wound
        inwards (its enclosed volume negative: an exporter's inside-out file, or a mirror image whose faces were
        not turned with it) has all its faces turned, so that its normals point out as every method assumes.
        """
        mesh = cls._from_arrays(vertices, faces, name=name, largest_component=largest_component)
        findings = []
        if any(fd.code == "orientation" for fd in mesh.report()):
            faces, turned = consistently_oriented(mesh.faces, mesh.n_vertices)
            if not turned:  # a non-orientable surface: the warning stays
                return mesh
            findings.append(Finding("warning", "reoriented", f"{turned} faces were turned to agree with their "
                                    "neighbours (the file's face orientation was inconsistent)"))
        else:
            faces = mesh.faces
        # a closed surface enclosing nothing (flat, two coincident sides) has a volume of rounding: left as it is
        if mesh.is_closed and signed_volume(mesh.vertices, faces) < -VOLUME_TOLERANCE * mesh.area ** 1.5:
            faces = faces[:, ::-1]
            findings.append(Finding("warning", "inside-out", "the closed surface was wound inwards (negative "
                                    "enclosed volume); every face was turned so that the normals point out"))
        if not findings:
            return mesh
        oriented = cls(mesh.vertices, faces, name=name)
        oriented.original_indices = mesh.original_indices
        oriented._findings.extend(findings)
        return oriented

    @classmethod
    def _from_arrays(cls, vertices, faces, *, name: str, largest_component: bool) -> "TriMesh":
        if largest_component:
            v, f, findings = _as_arrays(vertices, faces)
            if not findings and f.size and f.min() >= 0 and f.max() < v.shape[0]:
                n = v.shape[0]
                _, labels = face_components(n, f)
                used = np.zeros(n, dtype=bool)
                used[f.ravel()] = True
                # by surface area, which does not depend on how finely each part is meshed (the first on a tie)
                areas = np.bincount(labels[f[:, 0]], weights=triangle_areas(v, f), minlength=labels.max() + 1)
                keep = used & (labels == np.argmax(areas))
                if not np.all(keep):
                    new_index = -np.ones(n, dtype=np.int64)
                    new_index[keep] = np.arange(int(keep.sum()))
                    f = f[keep[f[:, 0]]]
                    mesh = cls(v[keep], new_index[f], name=name)
                    mesh.original_indices = _readonly(np.flatnonzero(keep))
                    return mesh
        return cls(vertices, faces, name=name)

    #: indices of the kept vertices in the input, when a component was dropped
    original_indices: np.ndarray | None = None

    def __repr__(self) -> str:
        return f"TriMesh({self.name!r}, n_vertices={self.n_vertices}, n_faces={self.n_faces})"

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def report(self) -> list[Finding]:
        """Validation findings (warnings only, for a mesh that was constructed)."""
        if self._findings is None:
            self._findings = inspect_mesh(self.vertices, self.faces)
        return list(self._findings)

    @cached_property
    def face_areas(self) -> np.ndarray:
        """(f,) float: triangle areas."""
        return _readonly(triangle_areas(self.vertices, self.faces))

    @cached_property
    def area(self) -> float:
        """Total surface area."""
        return float(self.face_areas.sum())

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(f, 3) float: unit face normals (right-hand rule on the face order)."""
        v, f = self.vertices, self.faces
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        return _readonly(n / np.linalg.norm(n, axis=1, keepdims=True))

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(n, 3) float: area-weighted unit vertex normals."""
        return _readonly(area_weighted_normals(self.vertices, self.faces))

    @cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) int: unique undirected edges, each sorted ``(i < j)``."""
        f = self.faces
        half = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        return _readonly(np.unique(np.sort(half, axis=1), axis=0))

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """(e,) float: Euclidean lengths of :attr:`edges`."""
        return _readonly(np.linalg.norm(self.vertices[self.edges[:, 0]] - self.vertices[self.edges[:, 1]], axis=1))

    @cached_property
    def relative_edge_length(self) -> float:
        """Mean edge length per √area: the mesh's resolution in units of its size (the same in any units)."""
        return float(np.mean(self.edge_lengths) / np.sqrt(self.area))

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """(b, 2) int: directed boundary edges in face orientation (empty for closed meshes)."""
        f = self.faces
        half = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        _, inverse, counts = np.unique(np.sort(half, axis=1), axis=0, return_inverse=True, return_counts=True)
        return _readonly(half[counts[inverse.ravel()] == 1])

    @cached_property
    def boundary_loops(self) -> tuple[np.ndarray, ...]:
        """Boundary loops as ordered vertex index arrays (empty tuple for closed meshes)."""
        nxt = {int(a): int(b) for a, b in self.boundary_edges}
        loops = []
        while nxt:
            start = next(iter(nxt))
            loop = [start]
            cur = nxt.pop(start)
            while cur != start and cur in nxt:
                loop.append(cur)
                cur = nxt.pop(cur)
            loops.append(np.array(loop, dtype=np.int64))
        return tuple(loops)

    @property
    def is_closed(self) -> bool:
        return self.boundary_edges.shape[0] == 0

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """(n, n) sparse symmetric matrix of edge lengths (the mesh edge graph)."""
        e, w = self.edges, self.edge_lengths
        n = self.n_vertices
        a = sp.coo_matrix((np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]),
                                                     np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n))
        return a.tocsr()

    @cached_property
    def bbox_diagonal(self) -> float:
        return float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))

    @cached_property
    def content_hash(self) -> str:
        """SHA-1 of the vertex and face arrays (keys on-disk caches by mesh content)."""
        h = hashlib.sha1()
        h.update(np.ascontiguousarray(self.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.faces, dtype="<i8").tobytes())
        return h.hexdigest()

    @cached_property
    def shape_print(self) -> np.ndarray:
        """(SHAPE_PRINT_LENGTH,) float: distances between fixed pairs of vertices (spread over the index range)
        per √area. Unchanged by moving, turning or scaling the mesh, changed by another pose or another mesh of
        as many vertices, so that a saved map can tell the target it was computed for from another one of the
        same size without the file's exact bytes (:attr:`content_hash` differs for the same mesh in mm)."""
        ends = np.linspace(0, self.n_vertices - 1, SHAPE_PRINT_LENGTH + 1).round().astype(np.int64)
        steps = self.vertices[ends[1:]] - self.vertices[ends[:-1]]
        return _readonly(np.linalg.norm(steps, axis=1) / np.sqrt(self.area))

    def enclosed_volume(self) -> float | None:
        """Signed enclosed volume by the divergence theorem; ``None`` if the mesh is not closed."""
        if not self.is_closed:
            return None
        return signed_volume(self.vertices, self.faces)


#: length of :attr:`TriMesh.shape_print`
SHAPE_PRINT_LENGTH = 32
#: two shape prints further apart than this (largest difference, in units of √area) are of different shapes:
#: far above a file's rounding of its coordinates, far below any change of pose
SHAPE_PRINT_TOLERANCE = 1e-3


def fits_record(mesh: TriMesh, record: dict) -> bool:
    """Whether ``mesh`` is the mesh a result's input record (:func:`corrlib.methods.registry.input_record`)
    describes, up to moving, turning and scaling: as many vertices, and the same bytes or as many faces and
    the same :attr:`TriMesh.shape_print`. What the record lacks (a result made by hand or saved by an older
    version) is not checked."""
    if record.get("vertices") is not None and record["vertices"] != mesh.n_vertices:
        return False
    if record.get("shape_print") is None or record.get("content_hash") == mesh.content_hash:
        return True
    try:
        kept = np.asarray(record["shape_print"], dtype=np.float64)
    except (TypeError, ValueError):  # an edited record: nothing to compare
        return True
    if record.get("faces") != mesh.n_faces or kept.shape != mesh.shape_print.shape:
        return False
    return bool(np.max(np.abs(kept - mesh.shape_print)) <= SHAPE_PRINT_TOLERANCE)


#: an enclosed volume below this fraction of ``area^{3/2}`` is rounding, not volume (a flat closed mesh)
VOLUME_TOLERANCE = 1e-9


def relative_volume_change(volume: float, reference: float | None, area: float) -> float | None:
    """``volume / reference − 1``, or None where it does not apply: no reference volume (an open mesh), or one
    that is rounding rather than volume (a closed mesh that encloses nothing, e.g. flat), relative to the
    surface ``area`` (:data:`VOLUME_TOLERANCE`)."""
    if reference is None or not abs(reference) > VOLUME_TOLERANCE * area ** 1.5:
        return None
    return float(volume / reference - 1.0)


# ----------------------------------------------------------------------------- contours


def _orient(p1: np.ndarray, p2: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Sign of the turn p1 -> p2 -> q (+1 left, -1 right, 0 collinear), broadcasting over rows."""
    return np.sign((p2[..., 0] - p1[..., 0]) * (q[..., 1] - p1[..., 1])
                   - (p2[..., 1] - p1[..., 1]) * (q[..., 0] - p1[..., 0]))


def _segments_intersect(p: np.ndarray) -> np.ndarray:
    """Pairs (i, j) of non-adjacent segments of the closed polygon ``p`` that intersect.

    Segment i joins p[i] and p[i+1 mod m]. Bounding-box pruning by sorting on x,
    then exact orientation tests on the candidate pairs.
    """
    m = p.shape[0]
    a = p
    b = np.roll(p, -1, axis=0)
    lo_x = np.minimum(a[:, 0], b[:, 0])
    hi_x = np.maximum(a[:, 0], b[:, 0])
    lo_y = np.minimum(a[:, 1], b[:, 1])
    hi_y = np.maximum(a[:, 1], b[:, 1])
    order = np.argsort(lo_x)
    hits = []
    # sweep: for each segment, the segments whose lo_x lies within its x-range
    sorted_lo = lo_x[order]
    ends = np.searchsorted(sorted_lo, hi_x[order], side="right")
    for rank in range(m):
        i = order[rank]
        cand = order[rank + 1: ends[rank]]
        if cand.size == 0:
            continue
        cand = cand[(lo_y[cand] <= hi_y[i]) & (hi_y[cand] >= lo_y[i])]
        # skip adjacent segments (they share an endpoint)
        cand = cand[(cand != (i + 1) % m) & (cand != (i - 1) % m)]
        if cand.size == 0:
            continue
        o1 = _orient(a[i], b[i], a[cand])
        o2 = _orient(a[i], b[i], b[cand])
        o3 = _orient(a[cand], b[cand], a[i])
        o4 = _orient(a[cand], b[cand], b[i])
        cross = (o1 * o2 <= 0) & (o3 * o4 <= 0)
        # collinear disjoint segments give all-zero orientations: check overlap explicitly
        coll = (o1 == 0) & (o2 == 0)
        if np.any(coll):
            cross[coll] = (lo_x[cand][coll] <= hi_x[i]) & (hi_x[cand][coll] >= lo_x[i]) & \
                          (lo_y[cand][coll] <= hi_y[i]) & (hi_y[cand][coll] >= lo_y[i])
        for j in cand[cross]:
            hits.append((min(i, j), max(i, j)))
    return np.array(sorted(set(hits)), dtype=np.int64).reshape(-1, 2)


def _clean_polygon(points: np.ndarray) -> np.ndarray:
    """Drop the repeated closing point and consecutive duplicate points."""
    p = points
    if p.shape[0] > 1 and np.allclose(p[0], p[-1], rtol=0, atol=0):
        p = p[:-1]
    if p.shape[0] < 2:
        return p
    step = np.linalg.norm(np.diff(p, axis=0, append=p[:1]), axis=1)
    perimeter = step.sum()
    keep = step > TOL.zero_length * max(perimeter, 1e-300)
    if not np.any(keep):
        return p[:1]
    return p[keep]


def inspect_contour(points, *, min_points: int = 10) -> list[Finding]:
    """Validate a closed polygon and return every finding without raising.

    Parameters
    ----------
    points : (m, 2) array_like of float
        Polygon vertices in order; a repeated closing point is allowed.
    min_points : int
        Fewest distinct points accepted.
    """
    if np.iscomplexobj(points):  # NumPy would drop the imaginary parts with only a warning
        return [Finding("error", "points-type", "contour points are complex numbers; real (x, y) are needed")]
    try:
        p = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        return [Finding("error", "points-type", f"contour points are not numeric: {exc}")]
    if p.ndim != 2 or p.shape[1] != 2:
        return [Finding("error", "points-shape", f"contour points must have shape (m, 2), got {p.shape}")]
    if p.shape[0] == 0:
        return [Finding("error", "empty", "the contour has no points")]
    bad = np.flatnonzero(~np.all(np.isfinite(p), axis=1))
    if bad.size:
        return [Finding("error", "non-finite", f"{bad.size} contour points are NaN or infinite "
                        f"(e.g. point {_examples(bad)})")]
    scale = _coordinate_scale_problem(p)
    if scale:
        return [Finding("error", "coordinate-scale", scale)]
    q = _clean_polygon(p)
    if q.shape[0] < min_points:
        return [Finding("error", "too-short", f"the contour has {q.shape[0]} distinct points; "
                        f"at least {min_points} are needed")]
    sing = np.linalg.svd(q - q.mean(axis=0), compute_uv=False)
    if sing[-1] <= 1e-9 * sing[0]:
        return [Finding("error", "zero-area", "the contour encloses no area (all points are collinear)")]
    crossings = _segments_intersect(q)
    if crossings.size:
        i, j = crossings[0]
        return [Finding("error", "self-intersection", f"the contour intersects itself "
                        f"({crossings.shape[0]} crossing segment pairs, e.g. segments {i} and {j})")]
    area = 0.5 * float(np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1]))
    perimeter = float(np.linalg.norm(np.diff(q, axis=0, append=q[:1]), axis=1).sum())
    if abs(area) <= 1e-9 * perimeter ** 2:
        return [Finding("error", "zero-area", "the contour encloses no area (all points are collinear "
                        "or it folds back on itself)")]
    return []


#: the most points a contour is resampled to (a 2D outline has no use for more; more would only fill memory)
MAX_CONTOUR_POINTS = 1_000_000


class Contour2D:
    """An immutable closed 2D polygon (counter-clockwise or clockwise as given).

    Parameters
    ----------
    points : (m, 2) array_like of float
        Polygon vertices in order. A repeated closing point and consecutive
        duplicates are removed. The closing segment ``points[-1] -> points[0]``
        is implied.
    name : str
        Shown in error messages.
    min_points : int
        Fewest distinct points accepted (default 10).
    labels : (m,) int, optional
        Part label of every point (0 = unlabelled).

    Raises
    ------
    ContourError
        Empty, non-finite, fewer than ``min_points`` points, zero enclosed
        area, or self-intersecting.
    """

    def __init__(self, points, *, name: str = "contour", min_points: int = 10, validate: bool = True,
                 labels=None):
        self.name = str(name)
        if validate:
            errors = [fd for fd in inspect_contour(points, min_points=min_points) if fd.level == "error"]
            if errors:
                raise ContourError(f"{self.name}: {errors[0].message}")
        raw = np.asarray(points, dtype=np.float64)
        self.points = _readonly(_clean_polygon(raw))
        self.labels = None
        if labels is not None:
            if self.points.shape[0] != raw.shape[0]:
                raise ContourError(f"{self.name}: labels cannot be kept: duplicate points were removed")
            self.labels = _check_labels(labels, self.n_points, self.name, ContourError)

    def __repr__(self) -> str:
        return f"Contour2D({self.name!r}, n_points={self.n_points}, {'ccw' if self.is_ccw else 'cw'})"

    @classmethod
    def from_open_points(cls, points, *, name: str = "contour", assume_closed: bool = False,
                         min_points: int = 10) -> "Contour2D":
        """Build a contour from a point sequence that should describe a closed curve.

        A sequence counts as closed if its last point repeats the first or the
        end-to-start gap is at most ``TOL.closing_gap`` median spacings;
        otherwise :class:`ContourError` ("open contour") is raised unless
        ``assume_closed``.
        """
        p = np.asarray(points, dtype=np.float64)
        if not assume_closed and p.ndim == 2 and p.shape[1] == 2 and p.shape[0] >= 3 \
                and np.all(np.isfinite(p)) and not _coordinate_scale_problem(p):
            steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
            steps = steps[steps > 0]
            gap = float(np.linalg.norm(p[-1] - p[0]))
            if steps.size and gap > TOL.closing_gap * float(np.median(steps)):
                raise ContourError(
                    f"{name}: open contour: the gap between the last and the first point ({gap:.4g}) is more "
                    f"than {TOL.closing_gap:g} times the median point spacing ({np.median(steps):.4g}); "
                    "repeat the first point at the end to close the curve, or load it with "
                    "corrlib.io.load_contour(path, assume_closed=True)")
        return cls(p, name=name, min_points=min_points)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @cached_property
    def segment_lengths(self) -> np.ndarray:
        """(m,) float: length of segment i, from point i to point (i + 1) mod m."""
        return _readonly(np.linalg.norm(np.roll(self.points, -1, axis=0) - self.points, axis=1))

    @cached_property
    def length(self) -> float:
        """Perimeter."""
        return float(self.segment_lengths.sum())

    @cached_property
    def arclength(self) -> np.ndarray:
        """(m,) float: arc length from point 0 to point i."""
        return _readonly(np.concatenate([[0.0], np.cumsum(self.segment_lengths)[:-1]]))

    @cached_property
    def signed_area(self) -> float:
        """Shoelace area: positive for counter-clockwise orientation."""
        x, y = self.points[:, 0], self.points[:, 1]
        return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))

    @property
    def area(self) -> float:
        return abs(self.signed_area)

    @property
    def is_ccw(self) -> bool:
        return self.signed_area > 0

    def ccw(self) -> "Contour2D":
        """The same contour oriented counter-clockwise (point 0 kept first)."""
        if self.is_ccw:
            return self
        order = np.concatenate([[0], np.arange(self.n_points - 1, 0, -1)])
        labels = None if self.labels is None else self.labels[order]
        return Contour2D(self.points[order], name=self.name, validate=False, labels=labels)

    def resample(self, n_points: int) -> "Contour2D":
        """Resample uniformly by arc length to ``n_points`` points, starting at point 0.

        Raises
        ------
        ContourError
            If ``n_points`` < 3.
        """
        if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or \
                not 3 <= n_points <= MAX_CONTOUR_POINTS:
            raise ContourError(f"{self.name}: cannot resample to {n_points!r} points (a whole number from 3 to "
                               f"{MAX_CONTOUR_POINTS:,})")
        n_points = int(n_points)
        closed = np.concatenate([self.points, self.points[:1]])
        s = np.concatenate([self.arclength, [self.length]])
        t = np.linspace(0.0, self.length, n_points, endpoint=False)
        p = np.column_stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])])
        labels = None
        if self.labels is not None:
            # the label of the segment each new point falls on (its start point's label)
            labels = self.labels[np.clip(np.searchsorted(self.arclength, t, side="right") - 1, 0, None)]
        return Contour2D(p, name=self.name, min_points=3, validate=False, labels=labels)

    def transformed(self, scale: float = 1.0, rotation: float = 0.0, translation=(0.0, 0.0)) -> "Contour2D":
        """Similarity transform ``x -> scale * R(rotation) x + translation`` (rotation in radians)."""
        c, s = np.cos(rotation), np.sin(rotation)
        r = np.array([[c, -s], [s, c]])
        p = scale * self.points @ r.T + np.asarray(translation, dtype=np.float64)
        return Contour2D(p, name=self.name, min_points=3, validate=False, labels=self.labels)


# ----------------------------------------------------------------------------- planar sketch meshes

#: a mesh is a planar sketch when its vertices lie within this fraction of its bounding-box diagonal of a plane
PLANAR_TOLERANCE = 1e-6


def plane_coordinates(points) -> np.ndarray | None:
    """2D coordinates of 3D points in the plane they lie in, or None where they lie in none.

    A plane normal to a coordinate axis keeps the other two axes in their order (a sketch drawn in the
    xy plane stays as drawn); another plane is described by the points' two principal directions.

    Parameters
    ----------
    points : (n, 3) array of float

    Returns
    -------
    (n, 2) array of float, or None if some point is farther than :data:`PLANAR_TOLERANCE` times the bounding-box
    diagonal from the points' least-squares plane.
    """
    points = np.asarray(points, dtype=np.float64)
    centred = points - points.mean(0)
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    tolerance = PLANAR_TOLERANCE * max(diagonal, np.finfo(float).tiny)
    extent = np.ptp(points, axis=0)
    flat_axis = int(np.argmin(extent))
    if extent[flat_axis] <= tolerance:
        return points[:, [a for a in range(3) if a != flat_axis]].copy()
    _, _, directions = np.linalg.svd(centred, full_matrices=False)  # rows: principal directions, largest first
    if np.abs(centred @ directions[2]).max() > tolerance:
        return None
    return centred @ directions[:2].T


def sketch_outline(mesh: TriMesh) -> tuple[Contour2D, np.ndarray]:
    """The outline of a planar triangulated sketch: its longest boundary loop in the sketch's plane.

    Returns
    -------
    contour : Contour2D
        Named after the mesh.
    loop : (m,) int array
        The mesh vertex of every contour point (to carry per-vertex labels over).

    Raises
    ------
    MeshError
        The mesh does not lie in a plane, or has no boundary.
    """
    flat = plane_coordinates(mesh.vertices)
    if flat is None:
        raise MeshError(f"{mesh.name}: not a planar sketch: its vertices do not lie in a plane (a 2D query is a "
                        "contour file, an SVG, a silhouette image or a flat triangulated sketch)")
    if not mesh.boundary_loops:
        raise MeshError(f"{mesh.name}: the sketch mesh has no boundary to use as a contour")
    loop = max(mesh.boundary_loops, key=len)
    return Contour2D(flat[loop], name=mesh.name), loop
