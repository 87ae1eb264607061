"""How far a vertex map is from an isometry, measured by geodesic distances.

A map ``m: X → Y`` is an isometry when it keeps every geodesic distance,
``d_Y(m(a), m(b)) = d_X(a, b)``. Its *geodesic distortion* is the mean
deviation over pairs of well spread samples ``a, b`` of ``X``,

    D(m) = mean over a, b of | d_X(a, b) / √A_X − d_Y(m(a), m(b)) / √A_Y |,

each shape's distances in units of the square root of its area (a match is
sought up to scale). No ground truth enters, so it can judge maps that an
intrinsic energy cannot tell apart: the heat kernels and spectral descriptors
are smooth and global, while a path between two limbs runs through the body,
so a map that swaps or twists limbs changes such paths by the body's width.
The distances are shortest edge paths (Dijkstra on the edge graph), which
overestimate the true geodesics by a few per cent alike on both shapes; the
distortion compares maps of one pair, so the bias cancels.
"""

from __future__ import annotations

import numpy as np

#: farthest-point samples of the source between which the distances are compared (100 Dijkstra runs per map)
GEODESIC_SAMPLES = 100


def geodesic_distortions(source, target, maps) -> list[float]:
    """:math:`D(m)` (module docstring) of several maps of one pair, the source's distances computed once.

    Parameters
    ----------
    source, target : TriMesh
    maps : sequence of (n_X,) int
        Target vertex of every source vertex; -1 (unmatched) leaves the sample out of that map's mean.

    Returns
    -------
    list of float
        One distortion per map, in their order; ``nan`` for a map that matches fewer than two samples.
    """
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.geometry.sampling import outermost_farthest_points

    sample = outermost_farthest_points(source.vertices, min(GEODESIC_SAMPLES, source.n_vertices))
    solver_x = GeodesicSolver(source)
    before = solver_x.distances(sample, method="graph")[:, sample] / np.sqrt(source.area)
    solver_y = solver_x if target is source else GeodesicSolver(target)
    out = []
    for map_xy in maps:
        images = np.asarray(map_xy)[sample]
        matched = images >= 0
        if matched.sum() < 2:
            out.append(float("nan"))
            continue
        images = images[matched]
        after = solver_y.distances(images, method="graph")[:, images] / np.sqrt(target.area)
        out.append(float(np.mean(np.abs(before[np.ix_(matched, matched)] - after))))
    return out
