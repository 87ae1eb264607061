"""Reading and writing shapes, contours, maps and results.

Every suffix the library knows is in one table,
:data:`~corrlib.formats.FORMATS` (:mod:`corrlib.formats`, re-exported
here); :func:`load_shape` loads a mesh or a contour by its suffix.

* Meshes: OFF by our own line-based parser, OBJ/PLY/STL through trimesh with
  ``process=False`` (vertex order survives; an STL is welded); saved as
  OFF/OBJ/PLY with optional per-vertex colours by our own writers (vertex
  order and count exactly as given).
* Contours: text/CSV point lists, an SVG path, or a silhouette image
  (PNG/GIF/JPG/BMP/TIFF); always returned counter-clockwise.
* Ground truth ``.vts`` (1-based vertex indices, one per line) and plain map
  files (one 0-based target index per line).
* Results: ``.npz`` (numeric arrays only, loaded without pickle) plus a
  ``.json`` sidecar with parameters, versions and timings.

Every writer is atomic: it writes a temporary file in the destination folder
and renames it, so an interrupted export never leaves a truncated file
(:mod:`corrlib.outputs`, whose writers and output checks are re-exported
here).
Every reader raises :class:`~corrlib.errors.FileFormatError` (or a
:class:`~corrlib.errors.MeshError` / :class:`~corrlib.errors.ContourError`
for invalid content) whose message names the file.
"""

from __future__ import annotations

import json
import os
import platform
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from corrlib.errors import ContourError, CorrError, FileFormatError, InputError, ParameterError
from corrlib.formats import (  # noqa: F401  (the table of formats, re-exported)
    CONTOUR_SUFFIXES,
    FORMATS,
    IMAGE_SUFFIXES,
    KIND_LABELS,
    MESH_SUFFIXES,
    MESH_WRITE_SUFFIXES,
    ORDERED_MESH_SUFFIXES,
    POINT_SUFFIXES,
    SVG_SUFFIXES,
    Format,
    dialog_filter,
    suffixes,
)
from corrlib.outputs import (  # noqa: F401  (the safe writers, re-exported)
    atomic_write,
    check_output_file,
    check_outputs_apart,
    ensure_output_folder,
    exclusive_folder,
    lost_working_folder,
    os_reason,
    remove_created_empty_folders,
    staged_output,
)
from corrlib.shapes import Contour2D, TriMesh, fits_record, inspect_contour


# ----------------------------------------------------------------------------- outputs (corrlib.outputs)

def _require_file(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise FileFormatError(f"{path}: file not found{lost_working_folder(path)}")
    if not path.is_file():
        raise FileFormatError(f"{path}: not a file")
    return path


# ----------------------------------------------------------------------------- meshes


def _read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse a line-based OFF/COFF/NOFF file (vertex order kept; polygons fan-triangulated).

    Each vertex and each face is on its own line; extra values on a line
    (normals, colours) are ignored.
    """
    text = read_text(path, "mesh")
    lines = [ln.split("#", 1)[0].split() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln]
    if not lines:
        raise FileFormatError(f"{path}: the file is empty")
    if not lines[0][0].upper().endswith("OFF"):
        raise FileFormatError(f"{path}: not an OFF file (it starts with {' '.join(lines[0])[:40]!r})")
    counts, first = (lines[0][1:], 1) if len(lines[0]) > 1 else ((lines[1] if len(lines) > 1 else []), 2)
    try:
        n_v, n_f = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        raise FileFormatError(f"{path}: the OFF header must give the vertex and face counts") from None
    if n_v < 0 or n_f < 0:
        raise FileFormatError(f"{path}: negative element counts in the OFF header")
    if len(lines) < first + n_v + n_f:
        raise FileFormatError(f"{path}: the header announces {n_v} vertices and {n_f} faces but the file "
                              f"has only {len(lines) - first} data lines")
    _check_vertex_lines(path, lines[first:first + n_v], n_v)
    try:
        coords = np.array([ln[:3] for ln in lines[first:first + n_v]], dtype=np.float64)
    except ValueError:
        raise FileFormatError(f"{path}: a vertex line does not hold 3 numbers") from None
    if coords.shape != (n_v, 3) and n_v:
        raise FileFormatError(f"{path}: a vertex line does not hold 3 numbers")
    extra = len(lines) - (first + n_v + n_f)
    if extra:  # faces that would be dropped without a word, or vertices read as faces (too few announced)
        raise FileFormatError(f"{path}: the header announces {n_v} vertices and {n_f} faces but the file has {extra} "
                              "more data lines after them")
    return coords.reshape(n_v, 3), _off_faces(path, lines[first + n_v:], n_v)


def _off_faces(path: Path, face_lines: list[list[str]], n_v: int) -> np.ndarray:
    """(f, 3) int: an OFF file's face lines, polygons fan-triangulated."""
    if all(len(ln) == 4 and ln[0] == "3" for ln in face_lines):  # the common all-triangle file
        try:
            return np.array([ln[1:] for ln in face_lines], dtype=np.int64).reshape(-1, 3)
        except (ValueError, OverflowError):
            pass  # the loop below names the bad face
    faces = []
    for index, ln in enumerate(face_lines):
        try:
            k = int(ln[0])
            poly = [int(v) for v in ln[1:1 + k]]
        except ValueError:
            raise FileFormatError(f"{path}: face {index} is not made of integers") from None
        if k < 3:
            raise FileFormatError(f"{path}: face {index} has {k} vertices; a face needs at least 3")
        if len(poly) != k:
            raise FileFormatError(f"{path}: face {index} announces {k} vertices but lists {len(poly)}")
        if max(abs(v) for v in poly) >= 2 ** 63:  # an ordinary index out of range is the mesh check's to name
            raise FileFormatError(f"{path}: face {index} refers to vertex {max(poly, key=abs)}, but the file has "
                                  f"{n_v} vertices (0 to {n_v - 1})")
        faces.extend((poly[0], poly[j], poly[j + 1]) for j in range(1, k - 1))
    return np.array(faces, dtype=np.int64).reshape(-1, 3)


def _looks_like_face(tokens: list[str]) -> bool:
    try:
        values = [int(t) for t in tokens]
    except ValueError:
        return False
    return values[0] >= 3 and len(values) >= 1 + values[0]


def _check_vertex_lines(path: Path, vertex_lines: list[list[str]], n_v: int) -> None:
    """Refuse a vertex block that runs into the faces (a header announcing more vertices than the file has)."""
    if not vertex_lines:
        return
    widths = np.fromiter(map(len, vertex_lines), dtype=np.int64, count=len(vertex_lines))
    for i in np.flatnonzero(widths != widths[0]):
        if _looks_like_face(vertex_lines[i]):
            raise FileFormatError(f"{path}: vertex line {i} ({' '.join(vertex_lines[i])[:40]!r}) is a face line: "
                                  f"the header announces {n_v} vertices, more than the file has")


def read_mesh_arrays(path) -> tuple[np.ndarray, np.ndarray]:
    """The vertex and face arrays :func:`load_mesh` builds its mesh from (file checks only, no content checks).

    Returns
    -------
    vertices : (n, 3) float
    faces : (f, 3) int
        Polygons fan-triangulated; an STL's vertices welded.

    Raises
    ------
    FileFormatError
        Missing, unreadable or unsupported file; no vertices; no faces (a point cloud).
    """
    path = _require_file(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise FileFormatError(f"{path}: unsupported mesh format {suffix!r} "
                              f"(supported: {', '.join(suffixes('mesh', readable=True))})")
    if suffix == ".off":
        vertices, faces = _read_off(path)  # our parser: fast, exact order, precise messages
    else:
        if suffix == ".obj":
            _check_obj_faces(path)
        elif suffix == ".ply":
            _check_ascii_ply_counts(path)
        vertices, faces = _read_trimesh(path, weld=suffix == ".stl")
    if vertices.size == 0:
        raise FileFormatError(f"{path}: the file contains no vertices")
    if faces.size == 0:
        raise FileFormatError(f"{path}: the file contains no faces (a point cloud, not a mesh)")
    return vertices, faces


def _check_obj_faces(path: Path) -> None:
    """Refuse an OBJ whose faces the reader would misread without a word: an index 0 (OBJ counts from 1, and
    a reader takes 0 for the last vertex), or vertices and no face at all (a point cloud)."""
    has_vertices = has_faces = False
    for number, line in enumerate(read_text(path, "mesh").splitlines(), 1):
        tokens = line.split("#", 1)[0].split()
        if not tokens:
            continue
        has_vertices |= tokens[0] == "v"
        if tokens[0] == "f":
            has_faces = True
            if any(token.split("/", 1)[0] == "0" for token in tokens[1:]):
                raise FileFormatError(f"{path}: line {number} ({line.strip()[:40]!r}) refers to vertex 0, but OBJ "
                                      "vertex indices start at 1 (a file written with 0-based indices: add 1 to "
                                      "every face index)")
    if has_vertices and not has_faces:
        raise FileFormatError(f"{path}: the file contains vertices but no faces (a point cloud, not a mesh)")


def _check_ascii_ply_counts(path: Path) -> None:
    """Refuse an ASCII PLY whose header announces another number of element lines than its body holds (a
    reader would take face lines for vertices or drop faces without a word). Binary PLY is left to the
    reader, which runs out of bytes."""
    with open(path, "rb") as fh:
        head = fh.read(4096)
    if b"format ascii" not in head.split(b"end_header", 1)[0]:
        return
    text = read_text(path, "mesh")
    header, _, body = text.partition("end_header")
    announced = {}
    for line in header.splitlines():
        tokens = line.split()
        if len(tokens) == 3 and tokens[0] == "element" and tokens[2].isdigit():
            announced[tokens[1]] = int(tokens[2])
    lines = sum(1 for line in body.splitlines() if line.strip())
    total = sum(announced.values())
    if lines != total:
        counts = " and ".join(f"{n} {name} lines" for name, n in announced.items())
        raise FileFormatError(f"{path}: the header announces {counts or 'no elements'} ({total} in all), but the "
                              f"file has {lines} data lines")


def _missing_vertex(exc: IndexError, path: Path) -> str:
    """`` (vertex I, counting from B as FORMAT does; the file has N)`` from numpy's index error in a reader (its
    0-based index, which an OBJ file writes from 1), or the error's own text where it says something else."""
    found = re.search(r"index (-?\d+) is out of bounds for axis 0 with size (\d+)", str(exc))
    if found is None:
        return f" ({exc})"
    index, size = int(found.group(1)), int(found.group(2))
    base = 1 if path.suffix.lower() == ".obj" else 0
    return (f" (vertex {index + base}, counting from {base} as {path.suffix.lstrip('.').upper() or 'the format'} "
            f"does; the file has {size} vertices)")


def _read_trimesh(path: Path, *, weld: bool) -> tuple[np.ndarray, np.ndarray]:
    from corrlib.interrupts import signals_held

    with signals_held():  # trimesh's import catches BaseException around its optional parts: a Ctrl-C would be lost
        import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True, force="mesh")
    except KeyError as exc:  # a PLY element without a property the reader needs
        raise FileFormatError(f"{path}: cannot read mesh: the property {exc} is missing (vertices need x, y "
                              f"and z)") from None
    except IndexError as exc:  # a face naming a vertex the file does not have
        raise FileFormatError(f"{path}: cannot read mesh: a face refers to a vertex the file does not have"
                              f"{_missing_vertex(exc, path)}") from None
    except Exception as exc:  # trimesh raises many exception types for malformed files
        raise FileFormatError(f"{path}: cannot read mesh: {exc}") from exc
    if weld and hasattr(loaded, "merge_vertices"):
        # STL is a triangle soup with no shared vertices (and so no vertex order to keep): weld it
        loaded.merge_vertices()
    vertices = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))))
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3))))
    return vertices, faces


def load_mesh(path, *, largest_component: bool = False) -> TriMesh:
    """Load a triangle mesh keeping the file's vertex order.

    Parameters
    ----------
    path : str or Path
        ``.off``, ``.obj``, ``.ply`` or ``.stl``.
    largest_component : bool
        Keep only the largest connected component instead of raising.

    Returns
    -------
    TriMesh
        Named after the file.

    Raises
    ------
    FileFormatError
        Missing, unreadable or unsupported file; no faces (a point cloud).
    MeshError
        Invalid mesh content (see :func:`corrlib.shapes.inspect_mesh`).
    """
    vertices, faces = read_mesh_arrays(path)
    return TriMesh.from_arrays(vertices, faces, name=Path(path).name, largest_component=largest_component)


def _colors_u8(colors, n: int, path) -> np.ndarray | None:
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.shape not in {(n, 3), (n, 4)}:
        raise InputError(f"{path}: colours must have shape ({n}, 3) or ({n}, 4), got {c.shape}")
    if np.issubdtype(c.dtype, np.floating):
        if not np.all(np.isfinite(c)):
            raise InputError(f"{path}: colours contain NaN or infinite values")
        c = np.clip(np.round(c * 255.0), 0, 255)
    elif c.size and (c.min() < 0 or c.max() > 255):  # uint8 would wrap 300 round to 44
        raise InputError(f"{path}: integer colours must be 0 to 255, got {c.min()} to {c.max()}")
    return c[:, :3].astype(np.uint8)


def save_mesh(path, vertices, faces, colors=None) -> Path:
    """Write a triangle mesh (OFF, OBJ or PLY) with optional per-vertex colours, atomically.

    Parameters
    ----------
    path : str or Path
    vertices : (n, 3) float
    faces : (f, 3) int
    colors : (n, 3) or (n, 4), optional
        Floats in [0, 1] or uint8. OFF writes ``COFF``, OBJ the common
        ``v x y z r g b`` extension, PLY ``red green blue`` uchar properties.

    Returns
    -------
    Path
    """
    path = Path(path)
    try:
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InputError(f"{path}: vertices must be numbers and faces integers ({exc})") from None
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)):
        raise InputError(f"{path}: vertices must be finite coordinates of shape (n, 3), got shape {v.shape}"
                         + ("" if v.ndim != 2 or v.shape[1] != 3 else " with NaN or infinite values"))
    if f.ndim != 2 or f.shape[1] != 3 or (f.size and (f.min() < 0 or f.max() >= v.shape[0])):
        raise InputError(f"{path}: faces must be (f, 3) indices of the {v.shape[0]} vertices, got shape {f.shape}"
                         + (f" with indices from {f.min()} to {f.max()}" if f.size and f.ndim == 2 else ""))
    c = _colors_u8(colors, v.shape[0], path)
    suffix = path.suffix.lower()
    if suffix not in MESH_WRITE_SUFFIXES:
        raise FileFormatError(f"{path}: cannot write mesh format {suffix!r} "
                              f"(use {', '.join(suffixes('mesh', writable=True))})")
    fmt = "%.9g %.9g %.9g"
    with atomic_write(path) as fh:
        if suffix == ".off":
            fh.write("COFF\n" if c is not None else "OFF\n")
            fh.write(f"{v.shape[0]} {f.shape[0]} 0\n")
            if c is None:
                np.savetxt(fh, v, fmt=fmt)
            else:
                np.savetxt(fh, np.column_stack([v, c, np.full(v.shape[0], 255)]),
                           fmt=fmt + " %d %d %d %d")
            np.savetxt(fh, np.column_stack([np.full(f.shape[0], 3), f]), fmt="%d")
        elif suffix == ".obj":
            if c is None:
                np.savetxt(fh, v, fmt="v " + fmt)
            else:
                np.savetxt(fh, np.column_stack([v, c / 255.0]), fmt="v " + fmt + " %.6g %.6g %.6g")
            np.savetxt(fh, f + 1, fmt="f %d %d %d")
        else:
            fh.write("ply\nformat ascii 1.0\ncomment written by corrlib\n")
            fh.write(f"element vertex {v.shape[0]}\nproperty double x\nproperty double y\nproperty double z\n")
            if c is not None:
                fh.write("property uchar red\nproperty uchar green\nproperty uchar blue\n")
            fh.write(f"element face {f.shape[0]}\nproperty list uchar int vertex_indices\nend_header\n")
            if c is None:
                np.savetxt(fh, v, fmt=fmt)
            else:
                np.savetxt(fh, np.column_stack([v, c]), fmt=fmt + " %d %d %d")
            np.savetxt(fh, np.column_stack([np.full(f.shape[0], 3), f]), fmt="%d")
    return path


# ----------------------------------------------------------------------------- contours


def _points_file(path: Path) -> np.ndarray:
    text = read_text(path, "contour")
    rows = []
    for lineno, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = [p for p in re.split(r"[,;\s]+", line) if p]
        try:
            values = [float(p) for p in parts]
        except ValueError:
            if not rows:  # tolerate one header line
                continue
            raise FileFormatError(f"{path}: line {lineno} is not a pair of numbers: {line!r}") from None
        if len(values) != 2:
            raise FileFormatError(f"{path}: line {lineno} has {len(values)} values, expected 2 (x y)")
        rows.append(values)
    if not rows:
        raise FileFormatError(f"{path}: no points found")
    return np.array(rows, dtype=np.float64)


_SVG_TOKEN = re.compile(r"[MmLlHhVvCcSsQqTtZzAa]|[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _bezier(points: np.ndarray, samples: int = 16) -> np.ndarray:
    """Points on a Bézier curve with control points ``points`` (excluding the start)."""
    t = np.linspace(0.0, 1.0, samples + 1)[1:, None]
    if points.shape[0] == 3:
        return (1 - t) ** 2 * points[0] + 2 * (1 - t) * t * points[1] + t ** 2 * points[2]
    return ((1 - t) ** 3 * points[0] + 3 * (1 - t) ** 2 * t * points[1]
            + 3 * (1 - t) * t ** 2 * points[2] + t ** 3 * points[3])


class _SvgPathReader:
    """The state of :func:`parse_svg_path`: tokens, read position, current point and subpaths so far."""

    def __init__(self, d: str, source: str):
        self.tokens = _SVG_TOKEN.findall(d)
        self.source = source
        self.i = 0
        self.cur = np.zeros(2)
        self.start = np.zeros(2)
        self.last_ctrl = None
        self.subpaths: list[list[np.ndarray]] = []

    def error(self, what: str) -> FileFormatError:
        return FileFormatError(f"{self.source}: {what}")

    def nums(self, count: int) -> np.ndarray:
        vals = self.tokens[self.i:self.i + count]
        if len(vals) < count or any(v.isalpha() for v in vals):
            raise self.error(f"malformed SVG path data near token {self.i}")
        self.i += count
        return np.array([float(v) for v in vals])

    def add(self, point: np.ndarray) -> None:
        self.cur = point
        self.subpaths[-1].append(point.copy())

    def step(self, cmd: str) -> str:
        """Run one command (its parameters follow at :attr:`i`); returns the command implied for more numbers."""
        if cmd in "Aa":
            raise self.error("SVG elliptical arc commands (A) are not supported; convert arcs to Bézier curves")
        rel = cmd.islower()
        base = self.cur if rel else np.zeros(2)
        c = cmd.upper()
        if c == "Z":
            if self.subpaths and self.subpaths[-1]:
                self.cur = self.start.copy()
            self.last_ctrl = None
            if self.i < len(self.tokens) and not self.tokens[self.i].isalpha():
                raise self.error(f"malformed SVG path data near token {self.i} (numbers after Z)")
            return cmd
        if c == "M":
            self.cur = base + self.nums(2)
            self.start = self.cur.copy()
            self.subpaths.append([self.cur.copy()])
            self.last_ctrl = None
            return "l" if rel else "L"  # further pairs are implicit line-tos
        if not self.subpaths:
            self.subpaths.append([self.cur.copy()])
        if c in "LHV":
            self.line(c, base, rel)
        elif c in "CSQT":
            self.curve(c, base)
        else:
            raise self.error(f"unsupported SVG path command {cmd!r}")
        return cmd

    def line(self, c: str, base: np.ndarray, rel: bool) -> None:
        if c == "L":
            self.add(base + self.nums(2))
        elif c == "H":
            x = self.nums(1)[0]
            self.add(np.array([self.cur[0] + x if rel else x, self.cur[1]]))
        else:
            y = self.nums(1)[0]
            self.add(np.array([self.cur[0], self.cur[1] + y if rel else y]))
        self.last_ctrl = None

    def reflected_ctrl(self) -> np.ndarray:
        return 2 * self.cur - self.last_ctrl if self.last_ctrl is not None else self.cur.copy()

    def curve(self, c: str, base: np.ndarray) -> None:
        if c == "C":
            ctrl = self.nums(6).reshape(3, 2) + base
        elif c == "S":
            ctrl = np.vstack([self.reflected_ctrl(), self.nums(4).reshape(2, 2) + base])
        elif c == "Q":
            ctrl = self.nums(4).reshape(2, 2) + base
        else:
            ctrl = np.vstack([self.reflected_ctrl(), self.nums(2) + base])
        self.subpaths[-1].extend(_bezier(np.vstack([self.cur, ctrl])))
        self.last_ctrl = ctrl[-2] if c in "CS" else ctrl[0]
        self.cur = ctrl[-1].copy()


def parse_svg_path(d: str, source: str = "svg") -> list[np.ndarray]:
    """Polylines (one per subpath) of an SVG path ``d`` attribute, in SVG coordinates.

    Supports M, L, H, V, C, S, Q, T, Z in absolute and relative form; curves
    are sampled with 16 points per segment. Elliptical arcs (A) are rejected.
    """
    reader = _SvgPathReader(d, source)
    cmd = None
    # relative steps, reflected control points and curve samples of coordinates near the largest float overflow
    # to infinity: such a contour is then refused by name as non-finite (Contour2D), like a coordinate of 1e400
    with np.errstate(over="ignore", invalid="ignore"):
        while reader.i < len(reader.tokens):
            tok = reader.tokens[reader.i]
            if tok.isalpha():
                cmd = tok
                reader.i += 1
            elif cmd is None:
                raise reader.error("SVG path data must start with a command")
            cmd = reader.step(cmd)
    return [np.array(sp_) for sp_ in reader.subpaths if len(sp_) >= 3]


def _svg_polylines(path: Path) -> list[np.ndarray]:
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise FileFormatError(f"{path}: cannot parse SVG: {exc}") from exc
    polylines = []
    for elem in root.iter():
        tag = elem.tag.rsplit("}", 1)[-1]
        if tag == "path" and elem.get("d"):
            polylines.extend(parse_svg_path(elem.get("d"), str(path)))
        elif tag in {"polygon", "polyline"} and elem.get("points"):
            vals = [float(v) for v in re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?", elem.get("points"))]
            if len(vals) >= 6 and len(vals) % 2 == 0:
                polylines.append(np.array(vals).reshape(-1, 2))
    if not polylines:
        raise FileFormatError(f"{path}: the SVG contains no path, polygon or polyline with at least 3 points")
    return polylines


def _polygon_area(p: np.ndarray) -> float:
    return 0.5 * abs(float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))


def _largest_polygon(polylines: list[np.ndarray]) -> np.ndarray:
    """The polyline enclosing the largest area. The areas are compared at one common scale (the largest
    coordinate), so that coordinates whose products overflow are still compared; such a contour is then
    refused by :class:`~corrlib.shapes.Contour2D` with a message."""
    scale = max(float(np.abs(p).max()) for p in polylines)
    if not 0 < scale < np.inf:  # all zero, or infinite or NaN coordinates: Contour2D names the problem
        return polylines[0]
    return max(polylines, key=lambda p: _polygon_area(p / scale))


def contour_from_mask(mask: np.ndarray, *, name: str = "image") -> np.ndarray:
    """Outer boundary of the largest foreground region of a binary mask.

    Parameters
    ----------
    mask : (h, w) bool
        True on the silhouette.

    Returns
    -------
    (m, 2) float
        Boundary points in image units with x to the right and y up
        (``x = column``, ``y = -row``), counter-clockwise, not resampled.
    """
    from skimage import measure

    if mask.ndim != 2 or not mask.any():
        raise ContourError(f"{name}: the image has no foreground silhouette")
    padded = np.pad(mask.astype(np.float64), 1)
    curves = measure.find_contours(padded, 0.5)
    closed = [c for c in curves if c.shape[0] >= 4 and np.allclose(c[0], c[-1])]
    if not closed:
        raise ContourError(f"{name}: no closed boundary found in the image")
    best = max(closed, key=_polygon_area)
    pts = np.column_stack([best[:, 1] - 1.0, -(best[:, 0] - 1.0)])
    if _polygon_area(pts) < 4.0:
        raise ContourError(f"{name}: the silhouette is too small (encloses less than 4 pixels)")
    return pts


#: cells of the raster across the longer side of a drawing in :func:`enclosed_outline` (a stroke is resampled to
#: a few hundred points afterwards, so a cell of a thousandth of its size loses nothing)
OUTLINE_RESOLUTION = 1024


def winding_mask(points: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) bool: the cells whose centres ``(column + ½, row + ½)`` a closed polygon winds around.

    The nonzero winding rule, by scanlines: along the line through a row's centres, the polygon's edges
    cross upwards (+1) or downwards (−1), and the cumulative sum of these signs in the order of the crossings
    is the winding number between two crossings. A point enclosed twice (where a stroke overlaps itself) is
    inside, as it is for a pen that fills what it draws round.

    Parameters
    ----------
    points : (m, 2) float
        Polygon vertices in raster units, x along the columns, y along the rows; closed implicitly.
    width, height : int
    """
    start = np.asarray(points, dtype=np.float64)
    end = np.roll(start, -1, axis=0)
    mask = np.zeros((height, width), dtype=bool)
    for row in range(height):
        y = row + 0.5
        up = (start[:, 1] <= y) & (end[:, 1] > y)
        down = (end[:, 1] <= y) & (start[:, 1] > y)
        crossing = up | down
        if not crossing.any():
            continue
        a, b = start[crossing], end[crossing]
        x = a[:, 0] + (y - a[:, 1]) / (b[:, 1] - a[:, 1]) * (b[:, 0] - a[:, 0])
        order = np.argsort(x, kind="stable")
        x, winding = x[order], np.cumsum(np.where(up[crossing], 1, -1)[order])
        for k in np.flatnonzero(winding[:-1] != 0):  # between crossings k and k + 1
            first, last = int(np.ceil(x[k] - 0.5)), int(np.floor(x[k + 1] - 0.5))
            mask[row, max(first, 0):min(last, width - 1) + 1] = True
    return mask


def enclosed_outline(points, *, resolution: int = OUTLINE_RESOLUTION, name: str = "drawing") -> np.ndarray:
    """The outline of the region a closed drawing encloses, for a drawing that crosses itself.

    A stroke drawn by hand crosses itself where the user did not mean it to: an end that overshoots the
    start when the stroke is closed, a small loop of a shaky hand. A polygon that crosses itself has no
    inside, so it cannot be filled or matched; the region it draws round can. That region (the nonzero
    winding rule, :func:`winding_mask`) is rasterised with ``resolution`` cells across the drawing's longer
    side, and the outer boundary of its largest connected part is returned (:func:`contour_from_mask`).

    Parameters
    ----------
    points : (m, 2) array_like of float
        The drawing's points in order, closed implicitly.
    resolution : int
    name : str
        Used in error messages.

    Returns
    -------
    (k, 2) float
        The outline in the drawing's units (a simple polygon, not resampled).

    Raises
    ------
    ContourError
        What makes any polygon unusable except crossing itself (:func:`~corrlib.shapes.inspect_contour`:
        complex, non-finite or overflowing coordinates, fewer than 3 distinct points, no area), or no region
        wider than a cell.
    ParameterError
        ``resolution`` is not a whole number of at least 16 cells.
    """
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 16:
        raise ParameterError(f"resolution must be a whole number of at least 16 raster cells, got {resolution!r}")
    # what makes a polygon unusable, other than crossing itself (complex, non-finite or overflowing coordinates,
    # fewer than 3 points, no area at all): the contour's own checks
    problems = [f for f in inspect_contour(points, min_points=3)
                if f.level == "error" and f.code != "self-intersection"]
    if problems:
        raise ContourError(f"{name}: {problems[0].message}")
    p = np.asarray(points, dtype=np.float64)
    lo, span = p.min(axis=0), np.ptp(p, axis=0)
    margin = 2  # empty cells round the drawing, so that its boundary is closed
    scale = (resolution - 2 * margin) / span.max()
    width, height = (np.ceil(span * scale).astype(int) + 2 * margin + 1)
    mask = winding_mask((p - lo) * scale + margin, int(width), int(height))
    if not mask.any():
        raise ContourError(f"{name}: the drawing encloses no area (none wider than 1/{resolution} of its size)")
    boundary = contour_from_mask(mask, name=name)  # (column, −row) of the mask's cell centres
    cells = np.column_stack([boundary[:, 0], -boundary[:, 1]]) + 0.5
    return lo + (cells - margin) / scale


def silhouette_mask(image: np.ndarray, threshold: float | None = None, *, name: str = "image") -> np.ndarray:
    """Binary silhouette of a grey or colour image.

    The threshold defaults to Otsu's. The foreground is the side of the
    threshold that touches the image border least (so both dark-on-light and
    light-on-dark silhouettes work). The alpha channel of an RGBA image is
    the silhouette when its transparent pixels are the background (most of
    the border); an opaque picture with a few translucent pixels (an
    anti-aliased corner) is read by its grey levels.
    """
    img = np.asarray(image)
    alpha = None
    if img.ndim == 3:
        if img.shape[2] == 4:
            alpha = img[..., 3].astype(np.float64)
            img = img[..., :3]
        img = img.astype(np.float64).mean(axis=2)
    elif img.ndim != 2:
        raise FileFormatError(f"{name}: expected a 2D image, got array of shape {img.shape}")
    img = img.astype(np.float64)
    if img.size == 0 or not np.all(np.isfinite(img)):
        raise FileFormatError(f"{name}: the image is empty or has invalid pixel values")
    if alpha is not None and alpha.min() < alpha.max():
        opaque = alpha > (alpha.min() + alpha.max()) / 2.0
        if _border(opaque).mean() < 0.5:  # a transparent background: the opaque pixels are the silhouette
            return opaque
    if img.min() == img.max():
        raise ContourError(f"{name}: the image is uniform: no silhouette to extract")
    if threshold is None:
        from skimage.filters import threshold_otsu

        threshold = float(threshold_otsu(img))
    elif isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.integer, np.floating)) or \
            not np.isfinite(threshold):
        raise ParameterError(f"{name}: threshold must be a grey level (a finite number), got {threshold!r}")
    bright = img > threshold
    return ~bright if _border(bright).mean() > 0.5 else bright


def _border(mask: np.ndarray) -> np.ndarray:
    """The pixels of a 2D mask along the image border (1-D)."""
    return np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])


#: largest silhouette image read (pixels): 6,000 x 6,000 holds far more outline detail than a match uses
#: (200 points), and a larger image costs gigabytes to decode
MAX_IMAGE_PIXELS = 36_000_000


def check_image_size(path, width: int, height: int) -> None:
    """Refuse an image of more than :data:`MAX_IMAGE_PIXELS` (a :class:`FileFormatError` naming it)."""
    if width * height > MAX_IMAGE_PIXELS:
        raise FileFormatError(f"{path}: the image has {width} x {height} pixels, more than the {MAX_IMAGE_PIXELS:,} "
                              f"a silhouette may have; downsample it first")


def load_contour(path, n_points: int | None = None, *, assume_closed: bool = False,
                 threshold: float | None = None, min_points: int = 10) -> Contour2D:
    """Load a closed 2D contour from a point file, an SVG, a silhouette image or a flat triangulated sketch.

    Parameters
    ----------
    path : str or Path
        ``.txt``/``.csv``/``.xy``/``.pts``/``.dat`` (``x y`` per line, comma,
        semicolon or blank separated, ``#`` comments), ``.svg`` (the
        largest closed subpath of any path/polygon/polyline; y flipped to
        point up), an image (largest outer silhouette boundary; x right, y up,
        one unit per pixel), or a mesh file of a planar sketch (its longest
        boundary loop in the sketch's plane, :func:`~corrlib.shapes.sketch_outline`;
        a mesh that is not flat is refused).
    n_points : int, optional
        Resample uniformly by arc length to this many points.
    assume_closed : bool
        Treat point files as closed even if their ends are far apart.
    threshold : float, optional
        Grey-level threshold for images (default Otsu).
    min_points : int
        Fewest distinct points accepted.

    Returns
    -------
    Contour2D
        Counter-clockwise.
    """
    path = _require_file(path)
    suffix = path.suffix.lower()
    name = path.name
    if suffix in POINT_SUFFIXES:
        points = _points_file(path)
        contour = Contour2D.from_open_points(points, name=name, assume_closed=assume_closed,
                                             min_points=min_points)
    elif suffix in SVG_SUFFIXES:
        polylines = _svg_polylines(path)
        best = _largest_polygon(polylines)
        best = best * np.array([1.0, -1.0])
        contour = Contour2D.from_open_points(best, name=name, assume_closed=True, min_points=min_points)
    elif suffix in IMAGE_SUFFIXES:
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                check_image_size(path, *im.size)
                im.seek(0)
                arr = np.asarray(im.convert("RGBA") if im.mode in {"P", "LA", "RGBA", "PA"} else im.convert("L"))
        except Image.DecompressionBombError:
            raise FileFormatError(f"{path}: the image is too large to read (more than {MAX_IMAGE_PIXELS:,} "
                                  f"pixels); downsample it first") from None
        except (UnidentifiedImageError, OSError, ValueError, SyntaxError, EOFError) as exc:
            raise FileFormatError(f"{path}: cannot read image: {exc}") from exc
        mask = silhouette_mask(arr, threshold, name=name)
        contour = Contour2D(contour_from_mask(mask, name=name), name=name, min_points=min_points)
    elif suffix in MESH_SUFFIXES:  # a flat triangulated sketch (as the 2D-to-3D commands read one)
        from corrlib.shapes import sketch_outline

        contour = Contour2D(sketch_outline(load_mesh(path))[0].points, name=name, min_points=min_points)
    else:
        raise FileFormatError(f"{path}: unsupported contour format {suffix!r} (use a point file, "
                              f"an SVG or an image: {', '.join(suffixes('contour', readable=True))})")
    contour = contour.ccw()
    if n_points is not None:
        contour = contour.resample(n_points)
    return contour


def save_contour(path, contour: Contour2D) -> Path:
    """Write a contour as a text file, one ``x y`` per line (atomic)."""
    with atomic_write(path) as fh:
        np.savetxt(fh, contour.points, fmt="%.9g")
    return Path(path)


# ----------------------------------------------------------------------------- either kind of shape


def shape_kind(path) -> str:
    """``"mesh"`` or ``"contour"`` by the file's suffix (see :data:`FORMATS`).

    Raises
    ------
    FileFormatError
        The suffix is neither a mesh nor a contour format.
    """
    suffix = Path(path).suffix.lower()
    if suffix in MESH_SUFFIXES:
        return "mesh"
    if suffix in CONTOUR_SUFFIXES:
        return "contour"
    raise FileFormatError(f"{path}: unsupported shape format {suffix!r} (meshes: "
                          f"{', '.join(suffixes('mesh', readable=True))}; contours: "
                          f"{', '.join(suffixes('contour', readable=True))})")


def load_shape(path) -> TriMesh | Contour2D:
    """Load a mesh (:func:`load_mesh`) or a contour (:func:`load_contour`) according to the file's suffix."""
    if Path(path).is_dir():  # before the suffix is asked: a folder has none
        raise FileFormatError(f"{path}: a folder, not a shape file (choose a mesh or a contour in it)")
    return load_mesh(path) if shape_kind(path) == "mesh" else load_contour(path)


# ----------------------------------------------------------------------------- maps and ground truth


def read_text(path, what: str = "input") -> str:
    """The text of a file (undecodable bytes replaced, a leading byte-order mark dropped), every failure a
    :class:`FileFormatError` naming it."""
    path = _require_file(path)
    try:
        return path.read_bytes().decode("utf-8", errors="replace").removeprefix("\ufeff")
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read the {what} file ({os_reason(exc)})") from None


#: integer entries must stay exactly representable (float64) and within int64
_LARGEST_INDEX = 2 ** 53


def non_integer_entry(values: np.ndarray) -> tuple | None:
    """The index of the first entry of a float array that is not an integer of at most 2^53 in magnitude (NaN,
    0.5, 1e300: casting would cut or wrap it without a word), or None if there is none."""
    values = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(values) | (values != np.round(values)) | (np.abs(values) > _LARGEST_INDEX)
    return np.unravel_index(int(np.argmax(bad)), values.shape) if np.any(bad) else None


def checked_map(values, n_x: int, n_y: int, what: str = "the map") -> np.ndarray:
    """``values`` as a map of an ``n_x``-vertex source onto an ``n_y``-vertex target, (n_x,) int64 (-1: no
    partner); an :class:`InputError` naming ``what`` unless it holds one whole-number index in range per source
    vertex and matches some vertex."""
    mp = vertex_indices(values, what)
    if mp.shape != (n_x,):
        raise InputError(f"{what} must hold one target vertex per source vertex, shape ({n_x},); got shape "
                         f"{mp.shape}")
    bad = np.flatnonzero((mp < -1) | (mp >= n_y))
    if bad.size:
        raise InputError(f"{what} sends source vertex {bad[0]} to {mp[bad[0]]}, outside a {n_y}-vertex target "
                         f"(0 to {n_y - 1}, or -1 for no partner)")
    if not np.any(mp >= 0):
        raise InputError(f"{what} matches no vertex")
    return mp


def vertex_indices(values, what: str) -> np.ndarray:
    """``values`` as int64 vertex indices; :class:`InputError` naming ``what`` unless every entry is a whole
    number (a float map, e.g. 0.9, would otherwise be cut to 0 without a word)."""
    array = np.asarray(values)
    if array.dtype == bool or not (np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)):
        raise InputError(f"{what} must hold vertex indices (integers), got {array.dtype} values")
    where = non_integer_entry(array) if np.issubdtype(array.dtype, np.floating) else None
    if where is not None:
        raise InputError(f"{what} must hold integer vertex indices; entry {where[0] if len(where) == 1 else where} "
                         f"is {float(array[where])!r}")
    return array.astype(np.int64)


def _integers(values: np.ndarray, path: Path, what: str, entry: str = "vertex indices") -> np.ndarray:
    """``values`` as int64 if every one is a finite integer of at most 2^53 in magnitude."""
    values = np.asarray(values)
    if np.issubdtype(values.dtype, np.integer):
        return values.astype(np.int64)
    if not np.issubdtype(values.dtype, np.floating) and not np.issubdtype(values.dtype, np.bool_):
        raise FileFormatError(f"{path}: the {what} must hold {entry}, found {values.dtype} values")
    first = non_integer_entry(values)
    if first is not None:  # named by its position in the file: row and column where the values form a table
        where = f"data line {first[0] + 1}, column {first[1] + 1}" if values.ndim == 2 else f"entry {first[0]}"
        value = float(values[first])
        beyond = " (beyond 2^53, the largest an index can be)" if np.isfinite(value) and value == round(value) else ""
        raise FileFormatError(f"{path}: the {what} must hold integer {entry}; {where} is {value!r}{beyond}")
    return values.astype(np.int64)


def _index_file(path: Path, what: str, entry: str = "vertex indices") -> np.ndarray:
    """One integer per data line (``#`` comments and blank lines skipped); ``entry`` names what they are."""
    rows = [line.split("#", 1)[0].split() for line in read_text(path, what).splitlines()]
    rows = [row for row in rows if row]
    if not rows:
        raise FileFormatError(f"{path}: the {what} file is empty")
    wide = next((number for number, row in enumerate(rows, 1) if len(row) != 1), None)
    if wide is not None:  # e.g. a two-column pairs file given as a map: its entries would be read as one list
        raise FileFormatError(f"{path}: the {what} file must hold one integer per line; data line {wide} has "
                              f"{len(rows[wide - 1])} values")
    text = [row[0] for row in rows]
    try:
        values = np.array([float(t) for t in text])
    except ValueError:
        bad = next(t for t in text if not _is_number(t))
        raise FileFormatError(f"{path}: {what} file has a non-numeric entry {bad[:40]!r}") from None
    return _integers(values, path, f"{what} file", entry)


def load_labels(path, n: int | None = None, what: str = "labels") -> np.ndarray:
    """Part labels: one integer per line (0 = unlabelled).

    Parameters
    ----------
    path : str or Path
    n : int, optional
        Expected count (contour points or mesh vertices); checked by the caller when several counts fit.
    what : str
        Named in the messages (e.g. ``"--mesh-labels"``).

    Returns
    -------
    (r,) int
    """
    values = _index_file(Path(path), what, "labels")
    if n is not None and values.shape[0] != n:
        raise FileFormatError(f"{path}: the {what} file has {values.shape[0]} labels, expected {n}")
    return values


def load_pairs(path, what: str = "landmarks") -> np.ndarray:
    """Landmark pairs: two integer columns (source vertex, target vertex) per line, ``#`` comments allowed.

    Returns
    -------
    (r, 2) int
    """
    rows = [line.split("#", 1)[0].split() for line in read_text(path, what).splitlines()]
    rows = [row for row in rows if row]
    if not rows:
        raise FileFormatError(f"{path}: the {what} file is empty")
    if any(len(row) != 2 for row in rows):
        line = next(i for i, row in enumerate(rows) if len(row) != 2)
        raise FileFormatError(f"{path}: {what} must be two integer columns (source, target); data line {line + 1} "
                              f"has {len(rows[line])} values")
    try:
        values = np.array([[float(v) for v in row] for row in rows])
    except ValueError:
        raise FileFormatError(f"{path}: {what} must be two integer columns (source, target)") from None
    return _integers(values, Path(path), f"{what} file").reshape(-1, 2)


def _is_number(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def load_vts(path, n_vertices: int | None = None) -> np.ndarray:
    """Ground-truth correspondence file: 1-based vertex indices, one per line.

    Returns
    -------
    (r,) int
        Zero-based indices (row r of two ``.vts`` files of a pair are the
        same surface point).
    """
    path = _require_file(path)
    idx = _index_file(path, ".vts") - 1
    if idx.min() < 0:
        raise FileFormatError(f"{path}: .vts indices are 1-based; found an index below 1")
    if n_vertices is not None and idx.max() >= n_vertices:
        raise FileFormatError(f"{path}: index {idx.max() + 1} exceeds the mesh's {n_vertices} vertices")
    return idx


def load_map(path, n_target: int | None = None, n_source: int | None = None, *,
             allow_unmatched: bool = False) -> np.ndarray:
    """Point-to-point map file: one 0-based target index per source vertex.

    ``allow_unmatched``: -1 marks a source vertex left unmatched (a partial match writes it); without it such
    a map is refused by name, where a complete map is needed.

    Returns
    -------
    (n_source,) int
    """
    path = _require_file(path)
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as data:
                if "map_xy" not in data.files:
                    raise FileFormatError(f"{path}: no 'map_xy' array in the .npz file")
                raw = np.asarray(data["map_xy"])
        except FileFormatError:
            raise
        except Exception as exc:  # numpy and zipfile raise many types on damaged archives
            raise FileFormatError(f"{path}: cannot read the .npz file ({type(exc).__name__}: {exc})") from None
        if raw.ndim != 1 or raw.size == 0:
            raise FileFormatError(f"{path}: 'map_xy' must be a non-empty 1-D array of target indices, "
                                  f"found shape {raw.shape}")
        mp = _integers(raw, path, "'map_xy' array", "target indices")
    else:
        mp = _index_file(path, "map")
    if mp.min() < -1:
        raise FileFormatError(f"{path}: map indices are 0-based (-1: unmatched); found {int(mp.min())}")
    if mp.min() == -1 and not allow_unmatched:
        raise FileFormatError(f"{path}: {int(np.count_nonzero(mp < 0))} source vertices are unmatched (-1, a "
                              "partial match); a complete map is needed here")
    if n_target is not None and mp.max() >= n_target:
        raise FileFormatError(f"{path}: map index {mp.max()} is out of range for a target with "
                              f"{n_target} vertices (is the file 1-based?)")
    if n_source is not None and mp.shape[0] != n_source:
        raise FileFormatError(f"{path}: map has {mp.shape[0]} entries but the source has {n_source} vertices")
    return mp


def save_map(path, map_xy) -> Path:
    """Write a point-to-point map: one 0-based target index per line (atomic)."""
    mp = np.asarray(map_xy)
    if mp.ndim != 1 or not np.issubdtype(mp.dtype, np.integer):
        raise InputError(f"{path}: a map must be a 1-D integer array, got {mp.dtype} {mp.shape}")
    with atomic_write(path) as fh:
        np.savetxt(fh, mp, fmt="%d")
    return Path(path)


# ----------------------------------------------------------------------------- results


def environment() -> dict:
    """Versions of Python, the platform and the numerical packages."""
    import numba
    import scipy

    import corrlib

    return {"corrlib": corrlib.__version__, "python": platform.python_version(),
            "platform": platform.platform(), "numpy": np.__version__, "scipy": scipy.__version__,
            "numba": numba.__version__}


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return repr(value)


def save_result(stem, arrays: dict[str, np.ndarray], meta: dict | None = None) -> tuple[Path, Path]:
    """Save numeric arrays as ``stem.npz`` and metadata as ``stem.json`` (both atomic).

    Parameters
    ----------
    stem : str or Path
        Output path without suffix (a given ``.npz``/``.json`` suffix is dropped).
    arrays : dict of str -> ndarray
        Numeric arrays only (object arrays are refused so loading never needs pickle).
    meta : dict
        JSON-serialisable parameters, timings, ...; the environment is added.
    """
    if str(stem).endswith(("/", os.sep)) or Path(stem).is_dir() or not Path(stem).name:
        raise InputError(f"{stem}: a result is written as STEM.npz and STEM.json; give a file stem (e.g. "
                         f"{Path(stem) / 'result'}), not a folder")
    stem = Path(stem)
    if stem.suffix in {".npz", ".json"}:
        stem = stem.with_suffix("")
    clean = {}
    for key, arr in arrays.items():
        a = np.asarray(arr)
        if a.dtype == object:
            raise InputError(f"result array {key!r} is not numeric")
        clean[key] = a
    npz = stem.with_name(stem.name + ".npz")  # appended: a stem with a dot ("run.v1") keeps it
    with atomic_write(npz, "wb") as fh:
        np.savez(fh, **clean)
    info = dict(meta or {})
    info.setdefault("environment", environment())
    info["arrays"] = {k: {"shape": list(v.shape), "dtype": str(v.dtype)} for k, v in clean.items()}
    js = stem.with_name(stem.name + ".json")
    with atomic_write(js) as fh:
        json.dump(_jsonable(info), fh, indent=2)
    return npz, js


def check_map_record(path, source: TriMesh | None = None, target: TriMesh | None = None) -> None:
    """:class:`FileFormatError` if the result ``corr match`` wrote beside a map file (``STEM.json`` beside
    ``STEM.npz`` or ``STEM.map_xy.txt``) records another source or target than these meshes
    (:func:`~corrlib.shapes.fits_record`): a map read on other meshes of its size would give numbers without a
    word. A map without such a record, or with an unreadable one, is not checked."""
    path = Path(path)
    stem = next((path.name[:-len(s)] for s in (".map_xy.txt", ".npz") if path.name.lower().endswith(s)), None)
    record_file = None if stem is None else path.with_name(f"{stem}.json")
    if record_file is None or not record_file.is_file():
        return
    try:
        inputs = json.loads(record_file.read_text(encoding="utf-8")).get("inputs") or {}
    except (OSError, ValueError, AttributeError):
        return
    for role, mesh in (("source", source), ("target", target)):
        record = inputs.get(role) if isinstance(inputs, dict) else None
        if mesh is None or not isinstance(record, dict) or record.get("kind") != "mesh" or fits_record(mesh, record):
            continue
        raise FileFormatError(f"{path}: the map was computed for the {role} {record.get('name')!r} "
                              f"({record.get('vertices')} vertices, says {record_file.name}), not for {mesh.name!r} "
                              f"({mesh.n_vertices} vertices): give it the meshes it was computed for")


def load_result(stem) -> tuple[dict[str, np.ndarray], dict]:
    """Load what :func:`save_result` wrote: ``(arrays, meta)``."""
    stem = Path(stem)
    if stem.suffix in {".npz", ".json"}:
        stem = stem.with_suffix("")
    npz = _require_file(stem.with_name(stem.name + ".npz"))
    try:
        with np.load(npz, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as exc:  # numpy and zipfile raise many types on damaged archives
        raise FileFormatError(f"{npz}: cannot read result ({type(exc).__name__}: {exc})") from None
    meta = {}
    js = stem.with_name(stem.name + ".json")
    if js.exists():
        try:
            meta = json.loads(js.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise FileFormatError(f"{js}: invalid JSON: {exc}") from None
        if not isinstance(meta, dict):
            raise FileFormatError(f"{js}: a result's metadata is a JSON object, found a {type(meta).__name__}")
    return arrays, meta


__all__ = [
    "CorrError", "Format", "FORMATS", "KIND_LABELS", "suffixes", "dialog_filter", "shape_kind", "load_shape",
    "atomic_write", "read_mesh_arrays", "load_mesh", "save_mesh", "load_contour", "save_contour",
    "contour_from_mask", "silhouette_mask", "parse_svg_path", "load_vts", "load_map", "save_map",
    "save_result", "load_result", "check_map_record", "environment",
]
