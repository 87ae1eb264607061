"""The repairs a mesh file may need before the methods accept it (``corr repair``), each one said.

The loader refuses what the methods cannot use (:func:`corrlib.shapes.inspect_mesh`) and names it. Some of it
has one obvious repair, the one mesh editors offer (MeshLab's "merge close vertices", "remove duplicate faces",
"remove isolated pieces", "remove unreferenced vertices"):

1. vertices at one position welded into one (a triangle soup, or parts exported with their seams split);
2. faces dropped that repeat a vertex (welding can make them), that are flat to the coordinates' precision
   (:func:`~corrlib.shapes.degenerate_faces`), or that repeat another face's three vertices;
3. the faces' windings made to agree (:func:`~corrlib.shapes.consistently_oriented`);
4. the largest connected component by surface area kept (a scan's loose fragments, a second body), and the
   vertices dropped that no face uses;
5. a closed surface turned inside out (every face) so that its normals point outward (MeshLab's "invert faces
   orientation"; the loader does it too, :meth:`~corrlib.shapes.TriMesh.from_arrays`, as normals, descriptors
   that tell left from right, renderers and other tools read a negative volume as inside out).

What has no safe repair (NaN coordinates, indices out of range, edges of three faces) is refused, naming it.
Every kept vertex keeps its index in the input (:attr:`Repaired.source_index`), so that ground truth and maps
given on the input can be carried to the repaired mesh.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from corrlib.errors import InputError, MeshError
from corrlib.shapes import TriMesh, consistently_oriented, degenerate_faces, face_components, inspect_mesh

#: findings that no repair here removes: the input is refused with them
UNREPAIRABLE = frozenset({"vertices-type", "faces-type", "vertices-shape", "faces-shape", "empty", "non-finite",
                          "coordinate-scale", "index-range"})


@dataclass
class Repaired:
    """A repaired mesh.

    Attributes
    ----------
    vertices : (m, 3) float
    faces : (g, 3) int
    source_index : (m,) int
        The input vertex each vertex is (the first of those welded into it).
    notes : list of str
        What was done, one repair per entry; empty when the input needed nothing.
    warnings : list of str
        What the loader still warns of and has no repair here (a non-orientable surface, two parts that
        touch at a vertex, ...).
    """

    vertices: np.ndarray
    faces: np.ndarray
    source_index: np.ndarray
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def repaired(vertices, faces, *, name: str = "mesh") -> Repaired:
    """The mesh with the repairs of the module applied in their order; a :class:`~corrlib.errors.MeshError`
    naming ``name`` and the problem where one is left that has no repair here.

    The last two steps and the final validation are the loader's own: the faces' windings made to agree
    (:func:`~corrlib.shapes.consistently_oriented`) and :meth:`TriMesh.from_arrays` with
    ``largest_component=True``, which keeps the largest component and the vertices its faces use.

    Parameters
    ----------
    vertices : (n, 3) array_like of float
    faces : (f, 3) array_like of int
    name : str
        Shown in error messages (the file name).
    """
    refused = [fd for fd in inspect_mesh(vertices, faces) if fd.level == "error" and fd.code in UNREPAIRABLE]
    if refused:
        raise MeshError(f"{name}: {refused[0].message} (no repair for this)")
    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    notes: list[str] = []
    v, f, source = _welded(v, f, notes)
    f = _without_bad_faces(v, f, notes)
    if f.shape[0] == 0:
        raise MeshError(f"{name}: no face is left after dropping the degenerate ones")
    f, turned = consistently_oriented(f, v.shape[0])
    if turned:
        notes.append(f"turned {_count(turned, 'face', 'faces')} to agree with their neighbours' winding")
    used = np.unique(f)
    components = np.unique(face_components(v.shape[0], f)[1][used]).size
    try:
        mesh = TriMesh.from_arrays(v, f, name=name, largest_component=True)
    except MeshError as exc:
        raise MeshError(f"{exc} (after the repairs: {'; '.join(notes) or 'none needed'})") from None
    if components > 1:
        notes.append(f"kept the largest of {components} connected components by surface area ({mesh.n_vertices} of "
                     f"{used.size} vertices in faces)")
    if used.size < v.shape[0]:
        notes.append(f"dropped {_count(v.shape[0] - used.size, 'vertex', 'vertices')} that no face uses")
    if mesh.original_indices is not None:
        source = source[mesh.original_indices]
    found = mesh.report()
    if any(fd.code == "inside-out" for fd in found):  # turned by the loader
        notes.append("turned every face so that the normals point outward (the closed surface was inside out)")
    warnings = [fd for fd in found if fd.level == "warning" and fd.code not in ("reoriented", "inside-out")]
    return Repaired(np.asarray(mesh.vertices), np.ascontiguousarray(mesh.faces), source, notes,
                    [fd.message for fd in warnings])


#: beside a repaired mesh ``OUT.off``: ``OUT.source_vertices.txt``, the input vertex of each of its vertices
INDEX_SUFFIX = ".source_vertices.txt"


def index_file(out) -> Path:
    """The file beside the repaired mesh ``out`` that gives the input vertex of each of its vertices."""
    out = Path(out)
    return out.with_name(out.stem + INDEX_SUFFIX)


def check_repair_outputs(mesh, out, what: str = "-o") -> Path:
    """Before any work: ``out`` (and its :func:`index_file`) can be written, is a mesh format that can be written,
    and is not the input ``mesh``; returns ``out`` as a Path. :class:`~corrlib.errors.InputError` naming it
    (as ``what``: the option or field that gave it)."""
    from corrlib.formats import suffixes
    from corrlib.io import check_output_file, check_outputs_apart

    out = check_output_file(out, what)
    check_output_file(index_file(out), what)
    check_outputs_apart([(what, out), (what, index_file(out))], [("the mesh", mesh)])
    writable = suffixes("mesh", writable=True)
    if out.suffix.lower() not in writable:
        raise InputError(f"{out}: {what} must name a mesh file ({', '.join(writable)}), got "
                         f"{out.suffix or 'no suffix'}")
    return out


def repair_file(mesh, out, what: str = "-o") -> Repaired:
    """``corr repair``: read ``mesh``, repair it (:func:`repaired`) and write it at ``out`` with its
    :func:`index_file`, both or neither; the outputs are checked first (:func:`check_repair_outputs`, ``what``
    names ``out`` in its messages)."""
    from corrlib.io import read_mesh_arrays, save_map, save_mesh, staged_output

    out = check_repair_outputs(mesh, out, what)
    vertices, faces = read_mesh_arrays(mesh)
    result = repaired(vertices, faces, name=Path(mesh).name)
    with staged_output(out.parent) as stage:
        save_mesh(stage / out.name, result.vertices, result.faces)
        save_map(stage / index_file(out).name, result.source_index)
    return result


def _welded(v: np.ndarray, f: np.ndarray, notes: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices at exactly one position merged, in the order of their first occurrence."""
    _, first, position = np.unique(v, axis=0, return_index=True, return_inverse=True)
    position = position.ravel()
    if first.size == v.shape[0]:
        return v, f, np.arange(v.shape[0])
    order = np.argsort(first)  # the merged vertices in input order
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    notes.append(f"welded {_count(v.shape[0] - first.size, 'vertex', 'vertices')} into others at the same position")
    return v[first[order]], rank[position[f]], first[order]


def _without_bad_faces(v: np.ndarray, f: np.ndarray, notes: list[str]) -> np.ndarray:
    """Faces that repeat a vertex, are flat to the coordinates' precision, or repeat another face, dropped."""
    repeats = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    flat = ~repeats & degenerate_faces(v, f)
    keep = ~(repeats | flat)
    _, first = np.unique(np.sort(f, axis=1)[keep], axis=0, return_index=True)
    duplicates = int(keep.sum()) - first.size
    kept = np.flatnonzero(keep)[np.sort(first)]
    for count, one, many in ((int(repeats.sum()), "repeats a vertex", "repeat a vertex"),
                             (int(flat.sum()), "has zero area", "have zero area"),
                             (duplicates, "repeats another face", "repeat another face")):
        if count:
            notes.append(f"dropped {_count(count, 'face that ' + one, 'faces that ' + many)}")
    return f[kept]


def _count(n: int, one: str, many: str) -> str:
    return f"{n} {one if n == 1 else many}"
