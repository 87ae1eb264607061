"""Quality triangulation of the region enclosed by a closed 2D contour.

Uses Shewchuk's Triangle (package ``triangle``) with a constrained
Delaunay triangulation, a minimum angle and a maximum triangle area, and the
``Y`` switch so that no Steiner points are inserted on the boundary. The
result is a planar :class:`~corrlib.shapes.TriMesh` (z = 0) whose first
``m`` vertices are the contour points in their original order, followed by
interior vertices. The 2D-to-3D method computes its spectral features on it.
"""

from __future__ import annotations

import numpy as np

from corrlib.errors import ContourError, ParameterError
from corrlib.shapes import Contour2D, TriMesh


def fill_contour(contour: Contour2D, *, max_area: float | None = None, min_angle: float = 30.0,
                 density: float = 1.0) -> TriMesh:
    """Triangulate the interior of a closed contour.

    Parameters
    ----------
    contour : Contour2D
        A valid (non-self-intersecting) closed contour, any orientation.
    max_area : float, optional
        Largest triangle area. Default: the area of an equilateral triangle
        whose side is the mean contour spacing divided by ``density``, so the
        interior is sampled about as densely as the boundary.
    min_angle : float
        Smallest triangle angle in degrees (Triangle guarantees up to ~33).
    density : float
        Interior refinement relative to the boundary spacing (> 0).

    Returns
    -------
    TriMesh
        Planar mesh, z = 0, faces oriented counter-clockwise (normal +z);
        vertices ``0 .. m-1`` are ``contour.points`` in order.

    Raises
    ------
    ParameterError
        Non-positive ``max_area``/``density`` or ``min_angle`` outside (0, 34].
    ContourError
        Triangle failed (should not happen for a valid contour).
    """
    import triangle

    if not 0 < min_angle <= 34:
        raise ParameterError(f"min_angle must be in (0, 34] degrees, got {min_angle}")
    if density <= 0:
        raise ParameterError(f"density must be positive, got {density}")
    p = contour.points
    m = p.shape[0]
    if max_area is None:
        side = float(np.mean(contour.segment_lengths)) / density
        max_area = np.sqrt(3.0) / 4.0 * side ** 2
    if max_area <= 0:
        raise ParameterError(f"max_area must be positive, got {max_area}")
    segments = np.column_stack([np.arange(m), (np.arange(m) + 1) % m])
    try:
        out = triangle.triangulate({"vertices": np.array(p), "segments": segments},
                                   f"pq{min_angle:.6g}a{max_area:.17g}YQ")
    except Exception as exc:  # Triangle reports failures as generic exceptions
        raise ContourError(f"{contour.name}: triangulating the contour failed: {exc}") from exc
    verts = np.asarray(out["vertices"], dtype=np.float64)
    tris = np.asarray(out.get("triangles", np.zeros((0, 3))), dtype=np.int64)
    if verts.shape[0] < m or not np.array_equal(verts[:m], p) or tris.shape[0] == 0:
        raise ContourError(f"{contour.name}: triangulating the contour did not keep its boundary points")
    # orient every face counter-clockwise (normal +z)
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris[signed < 0] = tris[signed < 0][:, [0, 2, 1]]
    vertices3 = np.column_stack([verts, np.zeros(verts.shape[0])])
    return TriMesh(vertices3, tris, name=f"{contour.name} (filled)")
