"""2D curves made from 3D meshes: plane sections and rendered silhouettes.

* :func:`plane_section` intersects a closed mesh with a plane and returns the
  section loops with, for every loop point, the mesh edge it lies on — the
  construction of 2D queries with point-to-point ground truth used to
  evaluate 2D-to-3D matching (the loop lies in the plane, so its in-plane
  coordinates are a 2D contour).
* :func:`render_silhouette` rasterises the orthographic projection of a mesh
  and returns its outer outline as a :class:`~corrlib.shapes.Contour2D`
  (a synthetic "sketch" of the shape); :func:`rim_vertices` gives the
  vertices that project onto outline points (its ground truth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from corrlib.errors import InputError
from corrlib.shapes import Contour2D, readonly_view


@dataclass
class SectionLoop:
    """One closed loop of a plane section.

    Attributes
    ----------
    points : (p, 3) float
        Loop points on mesh edges, in order.
    points_2d : (p, 2) float
        The same points in the plane's (u, v) coordinates.
    edges : (p, 2) int
        Mesh edge of each point.
    weights : (p,) float
        ``points = (1 - w) * V[edges[:, 0]] + w * V[edges[:, 1]]``.
    """

    points: np.ndarray
    points_2d: np.ndarray
    edges: np.ndarray
    weights: np.ndarray


def principal_frame(mesh) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted centroid (3,) and principal axes (3, 3) of a mesh, rows by decreasing variance."""
    from corrlib.geometry.laplacian import mass_matrix

    weights = mass_matrix(mesh.vertices, mesh.faces).diagonal()
    centre = weights @ mesh.vertices / weights.sum()
    centred = (mesh.vertices - centre) * np.sqrt(weights / weights.sum())[:, None]
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return centre, vt


def plane_basis(normal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normal and two in-plane axes (u, v) forming a right-handed frame."""
    nrm = np.asarray(normal, dtype=np.float64)
    length = np.linalg.norm(nrm)
    if not np.isfinite(length) or length == 0:
        raise InputError(f"the plane normal must be a non-zero finite vector, got {normal!r}")
    nrm = nrm / length
    helper = np.eye(3)[np.argmin(np.abs(nrm))]
    u = np.cross(nrm, helper)
    u /= np.linalg.norm(u)
    return nrm, u, np.cross(nrm, u)


def plane_section(mesh, origin, normal) -> list[SectionLoop]:
    """Intersect a mesh with the plane through ``origin`` with ``normal``.

    Returns
    -------
    list of SectionLoop
        Closed loops, longest first (open chains of meshes with boundary are dropped).
    """
    nrm, u, v = plane_basis(normal)
    verts = mesh.vertices
    d = (verts - np.asarray(origin, dtype=np.float64)) @ nrm
    scale = mesh.bbox_diagonal
    d = np.where(np.abs(d) < 1e-12 * scale, 1e-12 * scale, d)  # no vertex exactly on the plane
    f = mesh.faces
    side = d[f] > 0
    crossing = np.flatnonzero(side.any(axis=1) & ~side.all(axis=1))
    if crossing.size == 0:
        return []
    # per crossing face, its two crossing edges
    seg_edges = []
    for face in f[crossing]:
        pair = []
        for a, b in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
            if (d[a] > 0) != (d[b] > 0):
                pair.append((min(a, b), max(a, b)))
        seg_edges.append(pair)
    neighbours: dict[tuple, list] = {}
    for e1, e2 in seg_edges:
        neighbours.setdefault(e1, []).append(e2)
        neighbours.setdefault(e2, []).append(e1)
    loops = []
    unvisited = set(neighbours)
    while unvisited:
        start = unvisited.pop()
        chain = [start]
        prev, cur = None, start
        closed = False
        while True:
            nxt = [e for e in neighbours[cur] if e != prev]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            if cur == start:
                closed = True
                break
            if cur not in unvisited:
                break
            unvisited.discard(cur)
            chain.append(cur)
        if not closed or len(chain) < 3:
            continue
        edges = np.array(chain, dtype=np.int64)
        da, db = d[edges[:, 0]], d[edges[:, 1]]
        w = da / (da - db)
        pts = (1 - w)[:, None] * verts[edges[:, 0]] + w[:, None] * verts[edges[:, 1]]
        pts2 = np.column_stack([(pts - origin) @ u, (pts - origin) @ v])
        loops.append(SectionLoop(pts, pts2, edges, w))
    loops.sort(key=lambda lp: -np.linalg.norm(np.diff(lp.points, axis=0), axis=1).sum())
    return loops


SILHOUETTE_MARGIN = 4  # pixels around the projection in a rendered silhouette


@dataclass
class SilhouetteProjection:
    """Where the vertices of a mesh land in the image of :func:`render_silhouette`.

    Attributes
    ----------
    pixels : (n, 2) float
        Vertex positions in the contour's coordinates (x = column, y = −row).
    depth : (n,) float
        Distance along the viewing direction (smaller = nearer the viewer).
    shape : (int, int)
        Image rows and columns.
    pixels_per_unit : float
        Image scale (pixels per mesh unit).
    """

    pixels: np.ndarray
    depth: np.ndarray
    shape: tuple[int, int]
    pixels_per_unit: float


def project_for_silhouette(mesh, direction, resolution: int = 256, *, up=None) -> SilhouetteProjection:
    """The orthographic projection :func:`render_silhouette` draws (same arguments)."""
    nrm, u, v = plane_basis(direction)
    if up is not None:
        up = np.asarray(up, dtype=np.float64)
        v = up - (up @ nrm) * nrm
        if np.linalg.norm(v) == 0:
            raise InputError("the 'up' direction is parallel to the viewing direction")
        v /= np.linalg.norm(v)
        u = np.cross(v, nrm)
    xy = np.column_stack([mesh.vertices @ u, mesh.vertices @ v])
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pix = (resolution - 1) / max(hi - lo)
    cols = (xy[:, 0] - lo[0]) * pix + SILHOUETTE_MARGIN
    rows = (hi[1] - xy[:, 1]) * pix + SILHOUETTE_MARGIN  # image rows grow downwards
    shape = (int(np.ceil(rows.max())) + SILHOUETTE_MARGIN + 1, int(np.ceil(cols.max())) + SILHOUETTE_MARGIN + 1)
    return SilhouetteProjection(np.column_stack([cols, -rows]), mesh.vertices @ nrm, shape, float(pix))


@numba.njit(cache=True, nogil=True)
def _fill_triangles(rows, cols, faces, mask):
    """Set the pixels of ``mask`` whose centres (integer row, column) lie in a triangle (edges included)."""
    height, width = mask.shape
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ra, rb, rc, ca, cb, cc = rows[a], rows[b], rows[c], cols[a], cols[b], cols[c]
        area = (cb - ca) * (rc - ra) - (cc - ca) * (rb - ra)
        if area == 0.0:
            continue
        sign = 1.0 if area > 0 else -1.0
        r0, r1 = max(int(np.ceil(min(ra, rb, rc))), 0), min(int(np.floor(max(ra, rb, rc))), height - 1)
        c0, c1 = max(int(np.ceil(min(ca, cb, cc))), 0), min(int(np.floor(max(ca, cb, cc))), width - 1)
        for r in range(r0, r1 + 1):
            for col in range(c0, c1 + 1):
                # the three edge functions, each >= 0 on the triangle's side of its edge
                if (sign * ((cb - ca) * (r - ra) - (col - ca) * (rb - ra)) >= 0.0
                        and sign * ((cc - cb) * (r - rb) - (col - cb) * (rc - rb)) >= 0.0
                        and sign * ((ca - cc) * (r - rc) - (col - cc) * (ra - rc)) >= 0.0):
                    mask[r, col] = True


def render_silhouette(mesh, direction, resolution: int = 256, *, up=None) -> Contour2D:
    """Outline of the orthographic projection of a mesh seen along ``direction`` (the outline of
    :func:`rendered_view`, without the projection of the vertices)."""
    return rendered_view(mesh, direction, resolution, up=up)[0]


def rendered_view(mesh, direction, resolution: int = 256, *, up=None) -> tuple[Contour2D, SilhouetteProjection]:
    """Outline of the orthographic projection of a mesh seen along ``direction``, and where its vertices land.

    Parameters
    ----------
    mesh : TriMesh
    direction : (3,) float
        Viewing direction.
    resolution : int
        Pixels along the longer side of the projection.
    up : (3,) float, optional
        World direction drawn as +y in the image (default: any axis
        orthogonal to ``direction``).

    Returns
    -------
    outline : Contour2D
        Counter-clockwise, in pixel units (x = column, y = −row), not
        resampled.
    projection : SilhouetteProjection
        The vertices in the same units (:func:`project_for_silhouette`).
    """
    from scipy.ndimage import binary_closing, binary_fill_holes

    from corrlib.io import contour_from_mask

    projection = project_for_silhouette(mesh, direction, resolution, up=up)
    mask = np.zeros(projection.shape, dtype=np.bool_)
    _fill_triangles(np.ascontiguousarray(-projection.pixels[:, 1]), np.ascontiguousarray(projection.pixels[:, 0]),
                    readonly_view(mesh.faces, np.int64), mask)
    # thin slivers can leave single-pixel gaps between faces: one dilation/erosion pass closes them
    mask = binary_fill_holes(binary_closing(mask, iterations=1))
    outline = Contour2D(contour_from_mask(mask, name=f"{mesh.name} silhouette"), name=f"{mesh.name} silhouette")
    return outline.ccw(), projection


def rim_vertices(points: np.ndarray, projection: SilhouetteProjection, radius: float = 3.0) -> np.ndarray:
    """Ground truth of outline points: the nearest and the farthest vertex projecting onto each.

    A silhouette cannot tell the near side of the rim from the far side, so
    both are returned. Vertices within ``radius`` pixels of a point count as
    projecting onto it (the nearest vertex if there is none).

    Parameters
    ----------
    points : (m, 2) float
        Outline points in pixel units (a resampling of the rendered contour).
    projection : SilhouetteProjection

    Returns
    -------
    (m, 2) int
        Near-side and far-side vertex of every point.
    """
    from scipy.spatial import cKDTree

    tree = cKDTree(projection.pixels)
    out = np.empty((len(points), 2), dtype=np.int64)
    for i, p in enumerate(np.asarray(points, dtype=np.float64)):
        idx = np.array(tree.query_ball_point(p, radius) or [tree.query(p)[1]])
        out[i] = idx[np.argmin(projection.depth[idx])], idx[np.argmax(projection.depth[idx])]
    return out
