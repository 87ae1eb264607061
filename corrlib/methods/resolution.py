"""What a diffusion-based refinement can resolve, and the input matches it therefore keeps.

Both refiners of a dense map score a match by heat kernels: the product-manifold
refinement diffuses the input matches for a time ``t`` (:mod:`.product_manifold`),
kernel matching ends at its smallest diffusion time (:mod:`.kernel_matching`).
The heat kernel ``k_t(d) ∝ exp(-d² / 4t)`` falls to ``1/e`` at ``d = 2√t``
(:func:`kernel_width`), so a score built from it cannot tell apart partners that
lie closer than that: moving a match by less than the width is a choice among
partners the score holds equal (the capacities of an assignment spread the rows of
a many-to-one input over their neighbours), while a match that disagrees with its
neighbours' by more than the width is an outlier the refinement corrects.
:func:`keep_resolved_matches` gives the input partner back to the rows of the
first kind, so a refinement leaves the input's detail below its own resolution
alone.
"""

from __future__ import annotations

import numpy as np


def kernel_width(t: float, unit: float) -> float:
    """Length at which the heat kernel of relative time ``t`` falls to ``1/e`` of its peak.

    Parameters
    ----------
    t : float
        Diffusion time relative to the shape's scale (eigenvalues multiplied by ``unit``).
    unit : float
        The scale: the surface area of a mesh, the squared length of a curve.

    Returns
    -------
    float
        ``2 √(t · unit)``, in the shape's own length units.
    """
    return 2.0 * float(np.sqrt(t * unit))


def keep_resolved_matches(map_xy: np.ndarray, ix: np.ndarray, iy: np.ndarray, target_points: np.ndarray,
                          width: float) -> np.ndarray:
    """Give back their input partner to the rows that a refinement moved by less than ``width``.

    Only rows with exactly one input match and a refined partner (not -1) are considered. Distances are
    Euclidean on the target, a lower bound of the geodesic ones, so a partner across a narrow gap (a hand
    against a hip) can be kept when the refinement moved it to the other side.

    Parameters
    ----------
    map_xy : (n_X,) int
        The refined map; changed in place.
    ix, iy : (s,) int
        The input matches (source and target vertices).
    target_points : (n_Y, d) float
    width : float
        :func:`kernel_width`, in the units of ``target_points``.

    Returns
    -------
    (n_X,) bool
        The rows that got their input partner back.
    """
    ix, iy = np.asarray(ix, dtype=np.int64), np.asarray(iy, dtype=np.int64)
    counts = np.bincount(ix, minlength=map_xy.size)
    single = (counts[ix] == 1) & (map_xy[ix] >= 0) & (iy >= 0)
    rows, partners = ix[single], iy[single]
    moved_by = np.linalg.norm(target_points[map_xy[rows]] - target_points[partners], axis=1)
    close = moved_by < width
    map_xy[rows[close]] = partners[close]
    kept = np.zeros(map_xy.size, dtype=bool)
    kept[rows[close]] = True
    return kept
