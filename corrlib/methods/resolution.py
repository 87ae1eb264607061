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
alone. A match moved by more than the width is a real change, but not always an
improvement: the refinement's density follows the majority of the matches around
it. :func:`keep_isometric_matches` decides those rows by the assumption both
refiners rest on, that the map is locally an isometry: of the two partners, input
and refined, the row keeps the one whose distances to its neighbours' partners
differ less from the distances to those neighbours on the source.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


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


def _single_input_rows(map_xy: np.ndarray, ix: np.ndarray, iy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows with exactly one input match and a refined partner (not -1), and that input partner."""
    ix, iy = np.asarray(ix, dtype=np.int64), np.asarray(iy, dtype=np.int64)
    counts = np.bincount(ix, minlength=map_xy.size)
    single = (counts[ix] == 1) & (map_xy[ix] >= 0) & (iy >= 0)
    return ix[single], iy[single]


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
    rows, partners = _single_input_rows(map_xy, ix, iy)
    moved_by = np.linalg.norm(target_points[map_xy[rows]] - target_points[partners], axis=1)
    close = moved_by < width
    map_xy[rows[close]] = partners[close]
    kept = np.zeros(map_xy.size, dtype=bool)
    kept[rows[close]] = True
    return kept


def keep_isometric_matches(map_xy: np.ndarray, ix: np.ndarray, iy: np.ndarray, source_points: np.ndarray,
                           target_points: np.ndarray, width_x: float, width_y: float) -> np.ndarray:
    """Give back their input partner to the moved rows whose input partner is the more isometric one.

    For a row ``i`` moved by at least ``width_y`` (rows with one input match and a refined partner, as in
    :func:`keep_resolved_matches`), and a candidate partner ``p``, the local distortion is

        e_i(p) = mean_j | ‖x_i − x_j‖ − ‖y_p − y_m(j)‖ |,

    over the source neighbours ``j`` within ``width_x`` of ``i``, ``m`` the refined map. The row keeps the
    input partner where ``e_i(input) < e_i(refined)``. Within a kernel's width Euclidean distances stand
    for geodesic ones; all rows are decided against the same refined neighbours (one pass).

    Parameters
    ----------
    map_xy : (n_X,) int
        The refined map (after :func:`keep_resolved_matches`); changed in place.
    ix, iy : (s,) int
        The input matches.
    source_points : (n_X, d) float
    target_points : (n_Y, d) float
    width_x, width_y : float
        :func:`kernel_width` on the source and on the target, in their units.

    Returns
    -------
    (n_X,) bool
        The rows that got their input partner back.
    """
    rows, partners = _single_input_rows(map_xy, ix, iy)
    moved = np.linalg.norm(target_points[map_xy[rows]] - target_points[partners], axis=1) >= width_y
    rows, partners = rows[moved], partners[moved]
    back = np.zeros(map_xy.size, dtype=bool)
    if rows.size == 0:
        return back
    neighbours = cKDTree(source_points).query_ball_point(source_points[rows], width_x)
    counts = np.fromiter((len(n) for n in neighbours), dtype=np.int64, count=rows.size)
    owner = np.repeat(np.arange(rows.size), counts)
    flat = np.fromiter((j for n in neighbours for j in n), dtype=np.int64, count=int(counts.sum()))
    other = flat != rows[owner]
    owner, flat = owner[other], flat[other]
    d_source = np.linalg.norm(source_points[rows[owner]] - source_points[flat], axis=1)
    their_partners = target_points[map_xy[flat]]

    def distortion(candidates):
        d_target = np.linalg.norm(target_points[candidates[owner]] - their_partners, axis=1)
        return np.bincount(owner, np.abs(d_source - d_target), minlength=rows.size)

    give_back = distortion(partners) < distortion(map_xy[rows])  # sums over the same neighbours: means compare
    map_xy[rows[give_back]] = partners[give_back]
    back[rows[give_back]] = True
    return back
