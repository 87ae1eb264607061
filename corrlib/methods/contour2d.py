"""Contour-to-contour matching as a cyclic shortest path on the product torus.

Two closed 2D contours A and B are matched by the machinery of 2D-to-3D
matching (thesis ch. 7 and §9.5): both are resampled, scaled to unit
enclosed area and described by the boundary features of their filled
silhouettes (row-normalised WKS and scaled HKS, as in
:mod:`corrlib.methods.contour3d`); the product of A with the cycle graph of
B is the discretised torus A × B, and the globally optimal closed path on it
(branch-and-bound over the start point on B) is the correspondence. The path
must wind once around both factors: B is unrolled twice with forward moves
only, and a path from ``(0, s)`` must end at ``(m, s + n)``, so every
matching is a bijection of the curves that keeps their order (no collapse
onto a few points). A silhouette has no front and back: a dog seen from its
left and a horse seen from its right face opposite ways, and the matching
between them reverses the order of the points. With ``mirror`` (the
default) B is also read in reverse order, its mirror image's (the features
do not change under a reflection), and one branch-and-bound over both tori
(:func:`~corrlib.geometry.cyclic_paths.branch_and_bound_union`) keeps the
cheaper reading, with the guarantee of each. The path's map is then refined on the product
manifold (``refine``, :mod:`.product_manifold`): its matches diffused on
the torus and extracted by assignment (optionally followed by localized
Dirichlet harmonics on shrinking ``bands``); the density and the first
localized harmonics of a band around the final map are stored as torus
functions for the product view.

Map convention: ``map_xy[i]`` = point of (resampled) B matched to point i of
(resampled) A; ``map_yx[j]`` the point of A first matched to point j of B.
``result.path.product_functions["cost"]`` is the (m, n) node cost on the torus.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from corrlib.geometry.cyclic_paths import ProductGraph, branch_and_bound_union
from corrlib.methods.base import ContourPath, MatchResult, SearchCertificate, param
from corrlib.methods.contour3d import Contour3DParams, PreparedQuery, node_costs, prepare_query
from corrlib.methods.registry import MethodSpec, register
from corrlib.progress import Progress, Stopwatch


#: the orders B is read in: as given, and reversed (its mirror image's order)
READINGS = ("as given", "mirrored")


@dataclass(frozen=True, kw_only=True)
class Contour2DParams:
    n_source: int = param(120, label="Points on A", low=10, high=2000, help="Resampling of the first contour.")
    n_target: int = param(120, label="Points on B", low=10, high=2000, help="Resampling of the second contour.")
    k: int = param(25, label="Eigenpairs", low=5, high=500, help="Eigenpairs of the filled silhouettes.")
    n_scales: int = param(100, label="Scales", low=2, high=500, help="Times of the HKS, energies of the WKS.")
    eps: float = param(0.0, label="Approximation ε", low=0.0, high=0.9,
                       help="0: global optimum; ε > 0: within a factor 1 + ε.")
    mirror: bool = param(True, label="Mirror image of B",
                         help="Also match B's mirror image (its points in reverse order) and keep the cheaper: "
                              "two silhouettes facing opposite ways correspond in reverse order.")
    refine: bool = param(True, label="Product refinement",
                         help="Refine the path's map on the product manifold (diffusion, assignment, "
                              "localized harmonics on shrinking bands).")
    bands: str = param("", label="Band fractions",
                       help="Bands of localized refinement stages (share of the torus; empty: global diffusion "
                            "and assignment only — on resampled silhouettes the path is already at the "
                            "sampling resolution and localized stages did not improve it).")
    view_band: float = param(0.05, label="Band shown", low=0.001, high=1.0,
                             help="Band around the final map whose localized harmonics the torus view shows.")
    n_harmonics: int = param(100, label="Localized harmonics", low=1, high=2000,
                             help="Dirichlet harmonics per band.")


def forward_path_adjacency(n: int) -> sp.csr_matrix:
    """(n, n) directed adjacency of the path 0 → 1 → … → n-1."""
    i = np.arange(n - 1)
    return sp.coo_matrix((np.ones(n - 1), (i, i + 1)), shape=(n, n)).tocsr()


def prepared_outline(contour, n_points: int, k: int, n_scales: int, finer: str) -> PreparedQuery:
    """A contour resampled to ``n_points`` with the features of the module docstring (its filled outline at unit
    area, ``k`` eigenpairs, ``n_scales`` scales); ``finer``: how the user makes the filled outline finer."""
    params = Contour3DParams(k=k, n_scales=n_scales, area_ratio=1.0, features="paper", model="half",
                             n_contour=n_points)
    return prepare_query(contour, params, finer=finer, view_measures=False)


def torus_graph(cost: np.ndarray, points_a: np.ndarray, points_b: np.ndarray) -> ProductGraph:
    """The product torus of two resampled closed contours as a product graph.

    B is unrolled twice with forward moves only: a path from ``(0, s)`` to ``(m, s + n)`` runs once around B in
    its orientation, i.e. it is an orientation-preserving bijection of the two closed curves. Its vertices are
    points of the unrolled B (``% n`` gives B's point).

    Parameters
    ----------
    cost : (m, n) float
        Node cost of (point of A, point of B).
    points_a : (m, 2) float
    points_b : (n, 2) float
    """
    n = len(points_b)
    return ProductGraph(np.hstack([cost, cost]), points_a, np.vstack([points_b, points_b]),
                        forward_path_adjacency(2 * n), directed=True, closing_shift=n, n_starts=n)


def torus_maps(path, m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The maps of a closed path on :func:`torus_graph` (``m`` points of A, ``n`` of B).

    Returns
    -------
    vertices : (k,) int
        Point of B at every step of the path.
    map_xy : (m,) int
        Point of B of every point of A (its first visit).
    map_yx : (n,) int
        Point of A of every point of B (its first visit).
    """
    vertices = path.vertices % n  # back from the unrolled copy of B
    map_xy = np.full(m, -1, dtype=np.int64)
    map_yx = np.full(n, -1, dtype=np.int64)
    for layer, vertex in zip(path.layers[::-1], vertices[::-1]):  # first visits win
        if layer < m:
            map_xy[layer] = vertex
        map_yx[vertex] = layer % m
    return vertices, map_xy, map_yx


def reading_maps(vertices: np.ndarray, map_xy: np.ndarray, map_yx: np.ndarray, order: np.ndarray):
    """:func:`torus_maps`' maps of a torus whose B was read in ``order`` ((n,) int: the point of B at each place),
    as points of B as given."""
    given_yx = np.empty_like(map_yx)
    given_yx[order] = map_yx
    return order[vertices], np.where(map_xy >= 0, order[np.maximum(map_xy, 0)], -1), given_yx


def solve_contour2d(source, target, params: Contour2DParams, token):
    watch = Stopwatch()
    yield Progress("features", 0.0)
    with watch("features"):
        qa = prepared_outline(source, params.n_source, params.k, params.n_scales, finer="raise n_source")
        qb = prepared_outline(target, params.n_target, params.k, params.n_scales, finer="raise n_target")
        cost = node_costs(qa.features, qb.features)
    token.raise_if_cancelled()
    n = params.n_target
    orders = [np.arange(n), np.arange(n)[::-1]] if params.mirror else [np.arange(n)]  # B as given, B mirrored
    graphs = [torus_graph(cost[:, order], qa.points, qb.points[order]) for order in orders]
    yield Progress("branch and bound", 0.1, f"{graphs[0].m} x {n} torus, B read {' and '.join(READINGS[:len(graphs)])}")
    with watch("search"):
        bb = yield from branch_and_bound_union(graphs, eps=params.eps, token=token)
    path, order = bb.path, orders[bb.graph_index]
    vertices, map_xy, map_yx = reading_maps(*torus_maps(path, graphs[0].m, n), order)
    functions = {"cost": cost.astype(np.float32)}
    extras = {"b_mirrored": bool(bb.graph_index == 1)}
    if params.refine:
        extras["path_map_xy"] = map_xy.copy()
        map_xy, map_yx = yield from _refine_on_torus(qa.contour.points, qb.contour.points, map_xy, params, token,
                                                     watch, functions, extras)
    path = ContourPath(qa.contour.points, vertices, path.layers % graphs[0].m, path.layers,
                       target_points=qb.contour.points, product_functions=functions)
    yield Progress("done", 1.0, f"energy {bb.energy:.6g}")
    return MatchResult("contour2d", map_xy, map_yx, bb.energy, watch.times, path=path,
                       search=SearchCertificate.of(bb, params.eps), extras=extras,
                       energy_meaning="path energy on the product torus (unit areas)")


def _refine_on_torus(points_a, points_b, map_xy, params: Contour2DParams, token, watch, functions, extras):
    """Product-manifold refinement of the path's map.

    The density and the localized harmonics of a band around the refined
    map are added to ``functions`` (for the product view), the band's share
    of the torus to ``extras``.
    """
    from corrlib.geometry import product as pm
    from corrlib.methods.product_manifold import ProductManifoldParams, refine

    yield Progress("refinement", 0.8, "product manifold")
    with watch("refinement"):
        fx = pm.curve_factor(points_a, min(len(points_a), 200))
        fy = pm.curve_factor(points_b, min(len(points_b), 200))
    keep = np.flatnonzero(map_xy >= 0)
    pm_params = ProductManifoldParams(bands=params.bands, n_harmonics=params.n_harmonics, t_global=2e-4,
                                      t_local=2e-4)
    refined_xy, refined_yx, info = yield from refine(fx, fy, keep, map_xy[keep], points_a, points_b, pm_params,
                                                     token, watch)
    shape = (fx.n, fy.n)
    if "band_pairs" in info:
        pairs, density_band = info["band_pairs"], info["band_density"]
        harmonics = info["band_harmonics"]
        density = np.zeros(shape, dtype=np.float32)
        density[pairs[:, 0], pairs[:, 1]] = density_band
    else:
        density = pm.density_values(info["global_coefficients"], fx, fy).astype(np.float32)
        with watch("harmonics"):  # for the view: the localized harmonics of a band around the final map
            pairs = pm.largest_piece(fx, fy, pm.band_around_map(refined_xy, points_b, params.view_band))
            harmonics = pm.localized_harmonics(fx, fy, pairs, min(6, len(pairs) - 1))[1]
    functions["density"] = density
    for col in range(harmonics.shape[1]):
        harmonic = np.zeros(shape, dtype=np.float32)
        harmonic[pairs[:, 0], pairs[:, 1]] = harmonics[:, col]
        functions[f"harmonic_{col + 1}"] = harmonic
    extras["band_size"] = float(len(pairs) / (fx.n * fy.n))
    return refined_xy, refined_yx


register(MethodSpec(
    name="contour2d", label="Contour-to-contour (product torus)", inputs=("contour", "contour"),
    params=Contour2DParams, solve=solve_contour2d, rank=10,
    description="Two closed contours matched by the globally optimal cyclic path on their product torus, "
                "with silhouette boundary features (thesis ch. 7 and §9.5)."))
