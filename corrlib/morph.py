"""Shape sequences between a source and a target.

:func:`linear_sequence` is the fallback for any point-to-point map: vertex
positions interpolated (and extrapolated for t > 1) linearly between the
source and the partners of its vertices on the target, with the source's
connectivity. It is not volume preserving and folds where the map does;
methods with a deformation model (divergence-free flow) provide their own.
"""

from __future__ import annotations

import numpy as np

from corrlib.errors import InputError


def linear_positions(source_vertices: np.ndarray, target_vertices: np.ndarray, map_xy: np.ndarray,
                     t: float) -> np.ndarray:
    """(n_x, 3) float: ``(1 - t) X + t Y[map_xy]``; unmatched vertices (-1) stay at the source position."""
    mp = np.asarray(map_xy)
    if mp.shape[0] != source_vertices.shape[0]:
        raise InputError(f"the map has {mp.shape[0]} entries for {source_vertices.shape[0]} source vertices")
    partner = np.where((mp >= 0)[:, None], target_vertices[np.clip(mp, 0, None)], source_vertices)
    return (1.0 - t) * source_vertices + t * partner
