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
:func:`keep_input_partners` gives the input partner back to the rows of the
first kind, so a refinement leaves the input's detail below its own resolution
alone. A match moved by more than the width is a real change, but not always an
improvement: the refinement's density follows the majority of the matches around
it. The same function decides those rows by the assumption both
refiners rest on, that the map is locally an isometry: of the two partners, input
and refined, the row keeps the one whose distances to its neighbours' partners
differ less from the distances to those neighbours on the source.

An extraction that couples the two area measures (an assignment with area
capacities) pairs samples of equal size: where the source has more vertices
than the target, a target sample would have to take several source samples
with little rounding slack in its capacity, and a map whose local area differs
from the lumped masses would push rows off their best partner, each pushing
the next. Both refiners therefore assign a sample of the source of the
target's size and give every other source vertex the partner of its nearest
sampled vertex (:func:`surplus_partners`).
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


def keep_input_partners(map_xy: np.ndarray, ix: np.ndarray, iy: np.ndarray, source_points: np.ndarray,
                        target_points: np.ndarray, width_x: float, width_y: float) -> tuple[np.ndarray, np.ndarray]:
    """Give back their input partner to the rows a refinement did not resolve, or did not improve.

    Only rows with exactly one input match and a refined partner (not -1) are considered.

    * A row moved by less than ``width_y`` gets its input partner back (the refinement cannot tell the two
      apart). Distances are Euclidean on the target, a lower bound of the geodesic ones, so a partner across
      a narrow gap (a hand against a hip) can be kept when the refinement moved it to the other side.
    * A row moved farther keeps the more isometric of its two partners: with the local distortion

        e_i(p) = mean_j | ‖x_i − x_j‖ − ‖y_p − y_m(j)‖ |

      over the source neighbours ``j`` within ``width_x`` of ``i`` that have a partner, ``m`` the refined
      map, the row gets its input partner back where ``e_i(input) < e_i(refined)``. Within a kernel's width
      Euclidean distances stand for geodesic ones; all rows are decided against the same neighbours.

    Parameters
    ----------
    map_xy : (n_X,) int
        The refined map; changed in place.
    ix, iy : (s,) int
        The input matches (source and target vertices).
    source_points : (n_X, d) float
    target_points : (n_Y, d) float
    width_x, width_y : float
        :func:`kernel_width` on the source and on the target, in their units.

    Returns
    -------
    resolved, isometric : (n_X,) bool
        The rows that got their input partner back by the first rule and by the second.
    """
    ix, iy = np.asarray(ix, dtype=np.int64), np.asarray(iy, dtype=np.int64)
    counts = np.bincount(ix, minlength=map_xy.size)
    single = (counts[ix] == 1) & (map_xy[ix] >= 0) & (iy >= 0)
    rows, partners = ix[single], iy[single]
    moved_by = np.linalg.norm(target_points[map_xy[rows]] - target_points[partners], axis=1)
    close = moved_by < width_y
    map_xy[rows[close]] = partners[close]
    resolved = np.zeros(map_xy.size, dtype=bool)
    resolved[rows[close]] = True
    far_rows, far_partners = rows[~close], partners[~close]
    give_back = _input_is_more_isometric(map_xy, far_rows, far_partners, source_points, target_points, width_x)
    map_xy[far_rows[give_back]] = far_partners[give_back]
    isometric = np.zeros(map_xy.size, dtype=bool)
    isometric[far_rows[give_back]] = True
    return resolved, isometric


def _input_is_more_isometric(map_xy, rows, partners, source_points, target_points, width_x) -> np.ndarray:
    """(r,) bool: ``e_i(partner) < e_i(map_xy[i])`` for each row (see :func:`keep_input_partners`)."""
    if rows.size == 0:
        return np.zeros(0, dtype=bool)
    neighbours = cKDTree(source_points).query_ball_point(source_points[rows], width_x)
    counts = np.fromiter((len(n) for n in neighbours), dtype=np.int64, count=rows.size)
    owner = np.repeat(np.arange(rows.size), counts)
    flat = np.fromiter((j for n in neighbours for j in n), dtype=np.int64, count=int(counts.sum()))
    usable = (flat != rows[owner]) & (map_xy[flat] >= 0)  # not the row itself, and a neighbour with a partner
    owner, flat = owner[usable], flat[usable]
    d_source = np.linalg.norm(source_points[rows[owner]] - source_points[flat], axis=1)
    their_partners = target_points[map_xy[flat]]

    def distortion(candidates):  # sums over the same neighbours for both candidates: they compare as means
        d_target = np.linalg.norm(target_points[candidates[owner]] - their_partners, axis=1)
        return np.bincount(owner, np.abs(d_source - d_target), minlength=rows.size)

    return distortion(partners) < distortion(map_xy[rows])


def nearest_partners(source, matched_x: np.ndarray, matched_y: np.ndarray) -> np.ndarray:
    """(n_x,) int: for every source vertex, the partner of its nearest matched vertex (geodesic Voronoi cells
    of ``matched_x``, :func:`~corrlib.geometry.sampling.voronoi_cells`; -1 where none is connected).

    Parameters
    ----------
    source : TriMesh
    matched_x, matched_y : (s,) int
        Matched source vertices (repeats allowed: the first one counts) and their target vertices.
    """
    from corrlib.geometry.sampling import voronoi_cells

    matched_x, first = np.unique(np.asarray(matched_x, dtype=np.int64), return_index=True)
    nearest, _ = voronoi_cells(source, matched_x)
    return np.where(nearest >= 0, np.asarray(matched_y)[first][np.maximum(nearest, 0)], -1)


def surplus_partners(source, map_xy: np.ndarray, sampled: np.ndarray, anchors=()) -> None:
    """Partners of the source vertices an extraction left out of its sample, in place: each takes the partner
    of the nearest matched sample vertex (:func:`nearest_partners`; -1 where none is connected).

    Parameters
    ----------
    source : TriMesh
    map_xy : (n_x,) int
        Target vertex of every sampled source vertex (-1: unmatched); completed in place.
    sampled : (s,) int
        The source vertices that were assigned (matched or not).
    anchors : (a,) int
        Vertices left alone (landmarks, which the caller sets).
    """
    matched = sampled[map_xy[sampled] >= 0]
    if matched.size == 0:
        return
    rest = np.ones(map_xy.size, dtype=bool)
    rest[sampled] = False
    rest[np.asarray(anchors, dtype=np.int64)] = False
    partner = nearest_partners(source, matched, map_xy[matched])
    rest &= partner >= 0  # a piece of the mesh without a matched vertex stays unmatched
    map_xy[rest] = partner[rest]
