"""The table of every file format the library reads or writes.

Every suffix the library knows is in one table, :data:`FORMATS`; the
``*_SUFFIXES`` constants, :func:`suffixes` and the studio's file-dialog
filters (:func:`dialog_filter`) are derived from it. This module imports
nothing heavy, so that help texts (``corr --help``) can list the suffixes
without loading NumPy; the readers and writers are in :mod:`corrlib.io`.
"""

from __future__ import annotations

from dataclasses import dataclass


# ----------------------------------------------------------------------------- the table of formats


@dataclass(frozen=True)
class Format:
    """One family of files the library reads or writes.

    Attributes
    ----------
    kind : str
        What the file holds: ``"mesh"``, ``"contour"``, ``"ground-truth"``,
        ``"map"``, ``"result"``, ``"picture"``, ``"table"`` or ``"texture"``.
    suffixes : tuple of str
        Lower-case suffixes with the dot, most common first.
    description : str
        One line for help texts.
    readable, writable : bool
        Whether :mod:`corrlib.io` (or the studio, for pictures, tables and
        textures) reads / writes it.
    vertex_order : bool
        For meshes: the file defines a vertex order that ground-truth indices
        refer to (STL is a triangle soup welded on reading: it has none).
    """

    kind: str
    suffixes: tuple[str, ...]
    description: str
    readable: bool = True
    writable: bool = False
    vertex_order: bool = True


_IMAGES = (".png", ".gif", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
_POINT_FILES = (".txt", ".csv", ".xy", ".pts", ".dat")
_SVG = (".svg",)

#: Every file format, in the order dialogs and help texts list them.
FORMATS: tuple[Format, ...] = (
    Format("mesh", (".off",), "OFF/COFF/NOFF mesh (polygons are fan-triangulated)", writable=True),
    Format("mesh", (".obj",), "Wavefront OBJ mesh", writable=True),
    Format("mesh", (".ply",), "PLY mesh", writable=True),
    Format("mesh", (".stl",), "STL triangle soup (vertices welded on reading)", vertex_order=False),
    Format("contour", _IMAGES, "silhouette image (largest outer boundary)"),
    Format("contour", _SVG, "SVG path, polygon or polyline (largest closed one)"),
    Format("contour", _POINT_FILES, "point list, one 'x y' per line", writable=True),
    Format("ground-truth", (".vts",), "ground-truth correspondence, 1-based vertex indices"),
    Format("map", (".txt",), "point-to-point map, one 0-based target index per line", writable=True),
    Format("result", (".npz",), "result arrays (with a .json sidecar)", writable=True),
    Format("picture", (".png",), "PNG picture", readable=False, writable=True),
    Format("table", (".csv",), "comma-separated table", readable=False, writable=True),
    Format("texture", _IMAGES, "texture image"),
)

#: Plural names of the kinds in file dialogs.
KIND_LABELS = {"mesh": "Meshes", "contour": "Contours and silhouettes", "ground-truth": "Ground truth",
               "map": "Maps", "result": "Results", "picture": "Pictures", "table": "Tables",
               "texture": "Images"}


def suffixes(kind: str, *, readable: bool | None = None, writable: bool | None = None,
             vertex_order: bool | None = None) -> tuple[str, ...]:
    """Suffixes of ``kind`` in table order, optionally only those readable / writable / with a vertex order."""
    if kind not in KIND_LABELS:
        raise ValueError(f"unknown file kind {kind!r} (known: {', '.join(KIND_LABELS)})")
    wanted = {"readable": readable, "writable": writable, "vertex_order": vertex_order}
    out: list[str] = []
    for fmt in FORMATS:
        if fmt.kind == kind and all(v is None or getattr(fmt, k) == v for k, v in wanted.items()):
            out.extend(s for s in fmt.suffixes if s not in out)
    return tuple(out)


def dialog_filter(*kinds: str, save: bool = False, all_files: bool | None = None) -> str:
    """A Qt file-dialog filter for one or more kinds of file, from :data:`FORMATS`.

    ``dialog_filter("mesh")`` is ``"Meshes (*.off *.obj *.ply *.stl);;All files (*)"``.

    Parameters
    ----------
    kinds : str
        Kinds of :data:`FORMATS`, one filter entry each, in this order.
    save : bool
        List the formats that can be written (a save dialog) instead of those that can be read.
    all_files : bool, optional
        Append ``All files (*)``; by default for open dialogs only.
    """
    parts = []
    for kind in kinds:
        sfx = suffixes(kind, writable=True) if save else suffixes(kind, readable=True)
        if not sfx:
            raise ValueError(f"no {'writable' if save else 'readable'} {kind} format")
        parts.append(f"{KIND_LABELS[kind]} ({' '.join('*' + s for s in sfx)})")
    if all_files if all_files is not None else not save:
        parts.append("All files (*)")
    return ";;".join(parts)


# compatibility constants, derived from the table
MESH_SUFFIXES = frozenset(suffixes("mesh", readable=True))
MESH_WRITE_SUFFIXES = frozenset(suffixes("mesh", writable=True))
#: mesh formats whose vertex order ground-truth files can refer to (benchmarks)
ORDERED_MESH_SUFFIXES = frozenset(suffixes("mesh", readable=True, vertex_order=True))
IMAGE_SUFFIXES = frozenset(_IMAGES)
POINT_SUFFIXES = frozenset(_POINT_FILES)
SVG_SUFFIXES = frozenset(_SVG)
CONTOUR_SUFFIXES = frozenset(suffixes("contour", readable=True))
