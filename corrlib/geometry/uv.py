"""A simple UV parametrisation for texture transfer: cylindrical coordinates about the principal axis.

``u`` is the angle around the longest principal axis (in [0, 1)) and ``v``
the position along it (in [0, 1]). It has a seam and is not conformal; it
only needs to make a checkerboard on the source readable, which the map then
carries to the target (``uv_Y = uv_X[map_yx]``).
"""

from __future__ import annotations

import numpy as np


def cylindrical_uv(vertices: np.ndarray) -> np.ndarray:
    """(n, 2) float in [0, 1]: cylindrical texture coordinates about the longest principal axis."""
    v = np.asarray(vertices, dtype=np.float64)
    centred = v - v.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    local = centred @ axes.T
    along = local[:, 0]
    u = (np.arctan2(local[:, 2], local[:, 1]) + np.pi) / (2 * np.pi)
    span = np.ptp(along)
    return np.column_stack([u, (along - along.min()) / (span if span > 0 else 1.0)])


def checkerboard(size: int = 256, squares: int = 8) -> np.ndarray:
    """(size, size, 3) uint8 checkerboard with coloured squares (orientation visible)."""
    idx = (np.arange(size) * squares // size)
    board = (idx[:, None] + idx[None, :]) % 2
    img = np.empty((size, size, 3), dtype=np.uint8)
    img[board == 0] = (235, 235, 235)
    img[board == 1] = (40, 60, 140)
    # a red band marks u = 0 and a green band v = 0 so mirrored transfers are recognisable
    img[:, : size // (2 * squares)] = (200, 40, 40)
    img[: size // (2 * squares), :] = (40, 160, 60)
    return img
