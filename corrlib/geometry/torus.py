"""The product of two closed curves is a torus: embedding, flat square and curves on it.

A product point ``(i, j)`` (point i of curve A, point j of curve B) has the
angles ``u = s_A(i) / L_A`` and ``v = s_B(j) / L_B`` (arc length over
length, in [0, 1)). The 3D embedding is the standard ring torus
``((R + r cos 2πv) cos 2πu, (R + r cos 2πv) sin 2πu, r sin 2πv)``; the flat
square is the (u, v) unit square, i.e. the torus cut open along both seams.
"""

from __future__ import annotations

import numpy as np


def arclength_angles(points: np.ndarray) -> np.ndarray:
    """(m,) float in [0, 1): arc-length position of every point of a closed polyline."""
    p = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)[:-1]])
    return s / seg.sum()


def torus_embedding(u: np.ndarray, v: np.ndarray, major: float = 1.0, minor: float = 0.4) -> np.ndarray:
    """(..., 3) float: points of the ring torus at angles u, v (in turns)."""
    a, b = 2 * np.pi * np.asarray(u), 2 * np.pi * np.asarray(v)
    ring = major + minor * np.cos(b)
    return np.stack([ring * np.cos(a), ring * np.sin(a), minor * np.sin(b)], axis=-1)


def torus_grid(u: np.ndarray, v: np.ndarray, *, flat: bool = False, major: float = 1.0, minor: float = 0.4):
    """Triangulated product grid.

    Parameters
    ----------
    u : (m,) float
        Angles of curve A's points.
    v : (n,) float
        Angles of curve B's points.
    flat : bool
        The unit square (seams duplicated: (m + 1) × (n + 1) vertices) instead of the closed torus.

    Returns
    -------
    vertices : (V, 3) float
    faces : (F, 3) int
    index : (V,) int
        Product node ``i * n + j`` of every vertex (so an (m, n) function ``f`` is drawn as
        ``f.ravel()[index]``).
    """
    m, n = len(u), len(v)
    if flat:
        uu = np.append(u, 1.0)
        vv = np.append(v, 1.0)
        gu, gv = np.meshgrid(uu, vv, indexing="ij")
        vertices = np.column_stack([gu.ravel(), gv.ravel(), np.zeros(gu.size)])
        rows, cols = m + 1, n + 1
        ii, jj = np.meshgrid(np.arange(m + 1) % m, np.arange(n + 1) % n, indexing="ij")
        index = (ii * n + jj).ravel()
        wrap = False
    else:
        gu, gv = np.meshgrid(u, v, indexing="ij")
        vertices = torus_embedding(gu, gv, major, minor).reshape(-1, 3)
        rows, cols = m, n
        index = np.arange(m * n)
        wrap = True
    faces = []
    last_i = rows if wrap else rows - 1
    last_j = cols if wrap else cols - 1
    for i in range(last_i):
        i1 = (i + 1) % rows
        for j in range(last_j):
            j1 = (j + 1) % cols
            a, b, c, d = i * cols + j, i1 * cols + j, i1 * cols + j1, i * cols + j1
            faces.append((a, b, c))
            faces.append((a, c, d))
    return vertices, np.array(faces, dtype=np.int64), index


def path_angles(layers: np.ndarray, vertices: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(p, 2) float: (u, v) of a product path, unwrapped so the curve is continuous on the square.

    The closing layer m is curve A's point 0 at u = 1.
    """
    uu = np.append(u, 1.0)[np.asarray(layers)]
    vv = np.asarray(v)[np.asarray(vertices)]
    vv = vv + np.concatenate([[0.0], np.cumsum(np.round(-np.diff(vv)))])  # undo jumps across the seam
    return np.column_stack([uu, vv])
