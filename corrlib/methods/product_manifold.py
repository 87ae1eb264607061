"""Map refinement on the product manifold (thesis §9.4.2; Rodolà, Lähner et al. CGF 2019).

Input: sparse and/or noisy matches ``(x_s, y_s)`` (landmarks, or any dense
map, e.g. another method's output; without one the functional-maps
baseline's map is refined). Output: a dense map.

1. Global stage: the matches as a density on X × Y (deltas), diffused for
   time ``t_global`` in the product eigenbasis of the factors (a filter on
   the ``k_X × k_Y`` coefficients, :func:`corrlib.geometry.product.diffuse`);
   the dense map is extracted by a linear assignment on the density (the
   "sparse assignment" of §9.4.2, here dense up to 8000 × 8000, auction
   solver) or as the maximum-likelihood map (argmax of every row). The
   assignment couples the two area measures, not the vertex counts: a
   target vertex may take as many source vertices as its share of the area
   holds (:func:`corrlib.assignment.area_capacities`), so independently
   remeshed shapes are not forced into a bijection that slides vertices.
   A source with more vertices than the target is assigned on a sample of
   the target's size, and its other vertices take their nearest sampled
   vertex's partner (:mod:`.resolution`).
   The density resolves a partner only to within the heat kernel's width
   ``2 √t``: a row whose extracted partner lies closer than that to its
   (single) input partner gets the input partner back
   (:mod:`.resolution`), so the stage corrects the matches that
   disagree with their neighbours' and leaves the detail below its
   resolution to the input.
2. Local stages: for every band fraction of ``bands`` (decreasing), the band
   P is the set of product vertices ``(i, j)`` with ``j`` among the
   ``fraction · n_Y`` target vertices nearest to the current partner of
   ``i``: a region covering both shapes around the current map (where the
   map jumps the band can fall apart; its largest piece is used and the
   rows outside it keep their partner).
   The matches inside P are diffused with the Dirichlet harmonics of P
   (Eq. 9.19; ``n_harmonics`` of them, time ``t_local`` relative to the
   shapes' scales, shrinking with the band) and every row takes its most
   likely partner within the band. Matches outside the band (outliers far
   from the current map) drop out.

The assignment extracts the map because the maximum-likelihood map snaps
to the partners of the nearest matches. On meshes ``bands`` is empty by
default (a few dozen harmonics of a band covering a whole surface are too
smooth to sharpen a map); on curves (:mod:`.contour2d`) the bands are narrow
and the localized stage is used. Measurements: ``docs/decisions.md``.

Times are relative: ``t`` multiplies eigenvalues scaled by the area of a
surface or the squared length of a curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.errors import InputError, ParameterError
from corrlib.geometry import product as pm
from corrlib.methods.base import MatchResult, param
from corrlib.methods.resolution import keep_input_partners, kernel_width, surplus_partners
from corrlib.methods.registry import MethodSpec, register
from corrlib.progress import Progress, Stopwatch, scaled_progress


@dataclass(frozen=True, kw_only=True)
class ProductManifoldParams:
    n_eigs: int = param(200, label="Factor eigenpairs", low=5, high=1000,
                        help="Eigenpairs of each factor for the global diffusion (k_X = k_Y).")
    t_global: float = param(5e-4, label="Global time", low=0.0, high=10.0,
                            help="Diffusion time of the sparse matches on X × Y (relative to area).")
    bands: str = param("", label="Band fractions",
                       help="Comma-separated, decreasing: the share of target vertices around the current "
                            "partner of each source vertex kept in the localized stages (empty: global only).")
    n_harmonics: int = param(60, label="Localized harmonics", low=1, high=2000,
                             help="Dirichlet eigenfunctions of each band (Eq. 9.19).")
    extraction: str = param("assignment", label="Map extraction", choices=("assignment", "ml"),
                            help="Dense map from the diffused density: a linear assignment (bijective where "
                                 "the sizes agree; falls back to ml above 8000 × 8000) or the maximum "
                                 "likelihood of every row.")
    t_local: float = param(1e-3, label="Local time", low=0.0, high=10.0,
                           help="Diffusion time in the first band (halved in every further band).")
    reorient: bool = param(True, label="Turn a reversed map",
                           help="As kernel matching's last stage: a refined map that sends left to right on most "
                                "of the shape, or on a limb or a mirrored pair of regions, is turned by a "
                                "shape's intrinsic reflection where that rights it (the diffusion follows the "
                                "input's orientation and cannot tell). Dense input maps between closed shapes, "
                                "at least 60 eigenpairs; landmarks fix the orientation themselves.")

    def band_list(self) -> list[float]:
        try:
            values = [float(v) for v in self.bands.split(",") if v.strip()]
        except ValueError:
            raise ParameterError(f"bands: cannot read {self.bands!r} as comma-separated numbers") from None
        if any(not 0 < v <= 1 for v in values):
            raise ParameterError(f"bands must lie in (0, 1], got {values}")
        return values


def _match_density_coeffs(ix, iy, fx: pm.Factor, fy: pm.Factor) -> np.ndarray:
    """Coefficients of the sum of unit-mass deltas at the matches: ``Σ_s φ(x_s) ψ(y_s)ᵀ``."""
    return fx.evecs[ix].T @ fy.evecs[iy]


#: largest product (n_X · n_Y) extracted by a dense linear assignment
ASSIGNMENT_LIMIT = 8000 * 8000


def _vertex_masses(factor: pm.Factor) -> np.ndarray:
    """(n,) float: the measure of every vertex (row sums of the mass matrix: area, or length on a curve)."""
    return np.asarray(factor.mass.sum(axis=1)).ravel()


def _extract(coeffs, fx: pm.Factor, fy: pm.Factor, how: str, token=None,
             source=None) -> tuple[np.ndarray, np.ndarray]:
    """Dense maps from a density given by its product coefficients (assignment or maximum likelihood).

    With the source mesh given and more source than target vertices, the forward assignment takes a
    farthest-point sample of the target's size and the other source vertices the partner of their nearest
    sampled one (:func:`~corrlib.methods.resolution.surplus_partners`)."""
    if how == "assignment" and fx.n * fy.n <= ASSIGNMENT_LIMIT:
        from corrlib.assignment import area_capacities, linear_assignment

        density = pm.density_values(coeffs, fx, fy).astype(np.float32)
        density /= max(float(np.abs(density).max()), 1e-300)
        cancel = token.flag if token is not None else None
        # each side's vertices take the other side's in proportion to their area (or length)
        masses_x, masses_y = _vertex_masses(fx), _vertex_masses(fy)
        if source is not None and fx.n > fy.n:
            from corrlib.geometry.sampling import outermost_farthest_points

            rows = outermost_farthest_points(source.vertices, fy.n)
            map_xy = -np.ones(fx.n, dtype=np.int64)
            map_xy[rows] = linear_assignment(density[rows], cancel=cancel,
                                             capacity=area_capacities(rows.size, masses_y))
            surplus_partners(source, map_xy, rows)
        else:
            map_xy = linear_assignment(density, cancel=cancel, capacity=area_capacities(fx.n, masses_y))
        map_yx = linear_assignment(np.ascontiguousarray(density.T), cancel=cancel,
                                   capacity=area_capacities(fy.n, masses_x))
        # rectangular problems leave rows unmatched: those take their most likely partner
        for mp, dens_rows in ((map_xy, density), (map_yx, density.T)):
            free = np.flatnonzero(mp < 0)
            if free.size:
                mp[free] = dens_rows[free].argmax(axis=1)
        return map_xy, map_yx
    return pm.ml_map(coeffs, fx, fy), pm.ml_map(coeffs.T, fy, fx)


#: nonzeros of the largest band operator the localized stage takes (product vertices times the couplings of
#: each, the product of the factors' nonzeros per row): its Dirichlet harmonics are an eigenproblem of that
#: size (a 162-vertex sphere against itself in one whole band, 26k product vertices and 1.3M nonzeros: 25 s)
MAX_BAND_NONZEROS = 1_500_000


def check_band_size(bands: list[float], n_x: int, n_y: int, row_x: float, row_y: float) -> None:
    """:class:`ParameterError` where the widest band's operator would hold more than
    :data:`MAX_BAND_NONZEROS` nonzeros, before any work is done.

    Parameters
    ----------
    bands : list of float
        The band fractions.
    n_x, n_y : int
        Vertices (or curve samples) of the two factors.
    row_x, row_y : float
        Mean nonzeros per row of each factor's operator (a vertex and its neighbours: about 7 on a surface,
        3 on a curve).
    """
    if not bands:
        return
    widest = max(bands)
    size = n_x * max(1, int(np.ceil(widest * n_y)))
    nonzeros = size * row_x * row_y
    if nonzeros > MAX_BAND_NONZEROS:
        largest = MAX_BAND_NONZEROS / (row_x * row_y * n_x * n_y)
        raise ParameterError(f"bands: a band of {widest:g} of the {n_y} target vertices around each of the {n_x} "
                             f"source vertices holds {size:,} product vertices ({nonzeros:,.0f} couplings), more "
                             f"than the localized stage takes ({MAX_BAND_NONZEROS:,}); use band fractions of at "
                             f"most {largest:.2g} on these shapes, or none (the global stage alone, the default on "
                             "meshes)")


def _nonzeros_per_row(matrix) -> float:
    return matrix.nnz / max(matrix.shape[0], 1)


def refine(fx: pm.Factor, fy: pm.Factor, ix, iy, source_points: np.ndarray, target_points: np.ndarray,
           params: ProductManifoldParams, token=None, watch: Stopwatch | None = None, source=None):
    """Dense map from matches on two factors (generator; returns ``(map_xy, map_yx, extras)``).

    The points of the factors (vertices, curve samples) decide which input partners the global stage keeps
    (:mod:`corrlib.methods.resolution`). ``source``: the source mesh (its vertices are ``source_points``), for
    the extraction's sample where the source has more vertices than the target (:func:`_extract`)."""
    watch = watch or Stopwatch()
    ix, iy = np.asarray(ix, dtype=np.int64), np.asarray(iy, dtype=np.int64)
    if ix.size == 0:
        raise InputError("the initial map is empty: give at least one match")
    bands = params.band_list()
    check_band_size(bands, fx.n, fy.n, _nonzeros_per_row(fx.stiffness), _nonzeros_per_row(fy.stiffness))
    yield Progress("global diffusion", 0.1, f"{ix.size} matches, {fx.k} x {fy.k} product coefficients")
    with watch("global"):
        coeffs = pm.diffuse(_match_density_coeffs(ix, iy, fx, fy), fx, fy, params.t_global)
        map_xy, map_yx = _extract(coeffs, fx, fy, params.extraction, token, source)
        width_x, width_y = kernel_width(params.t_global, fx.unit), kernel_width(params.t_global, fy.unit)
        kept, isometric = keep_input_partners(map_xy, ix, iy, source_points, target_points, width_x, width_y)
    global_map_xy = map_xy.copy()
    band_sizes = []
    match_keys = ix * fy.n + iy
    t_local = params.t_local
    for step, fraction in enumerate(bands):
        if token is not None:
            token.raise_if_cancelled()
        yield Progress(f"band {fraction:g}", 0.2 + 0.7 * step / max(len(bands), 1),
                       f"localized harmonics on {fraction:.1%} of the product")
        with watch("bands"):
            # where the current map jumps the band can fall apart: keep its largest piece, the rows
            # outside it keep their partner
            pairs = pm.largest_piece(fx, fy, pm.band_around_map(map_xy, target_points, fraction))
        with watch("harmonics"):
            k = min(params.n_harmonics, len(pairs) - 1)
            evals, basis = pm.localized_harmonics(fx, fy, pairs, k)
        with watch("local diffusion"):
            keys = pairs[:, 0] * fy.n + pairs[:, 1]
            order = np.argsort(keys)
            # deltas at the current map (every row) and at the given matches, where they lie in the band
            sources = np.concatenate([np.arange(fx.n) * fy.n + map_xy, match_keys])
            pos = np.minimum(np.searchsorted(keys[order], sources), len(keys) - 1)
            inside = keys[order][pos] == sources
            rows_in_band = order[pos[inside]]
            if rows_in_band.size == 0:
                raise InputError(f"no match lies in the {fraction:g} band around the current map; "
                                 "use wider bands")
            scale = np.sqrt(fx.unit * fy.unit)
            c = basis[rows_in_band].sum(axis=0) * np.exp(-t_local * scale * evals)
            density = basis @ c
            row_best = np.full(fx.n, -np.inf)
            np.maximum.at(row_best, pairs[:, 0], density)
            winners = np.flatnonzero(density >= row_best[pairs[:, 0]])
            map_xy[pairs[winners, 0]] = pairs[winners, 1]
            # reverse map: every target vertex covered by the band takes its most likely source vertex
            col_best = np.full(fy.n, -np.inf)
            np.maximum.at(col_best, pairs[:, 1], density)
            winners = np.flatnonzero(density >= col_best[pairs[:, 1]])
            map_yx[pairs[winners, 1]] = pairs[winners, 0]
        band_sizes.append(len(pairs))
        t_local *= 0.5
    extras = {"band_sizes": np.asarray(band_sizes), "n_matches": int(ix.size),
              "global_map_xy": global_map_xy, "kept_matches": kept | isometric, "isometric_matches": isometric}
    if bands:  # the last band: its product vertices, the density on it and its first harmonics
        extras.update(band_pairs=pairs, band_density=density, band_harmonics=basis[:, :6])
    else:
        extras["global_coefficients"] = coeffs
    return map_xy, map_yx, extras


def _reoriented(source, target, fx: pm.Factor, fy: pm.Factor, map_xy, map_yx, extras: dict, watch,
                fraction: float = 0.95):
    """The orientation stage of kernel matching (:func:`corrlib.methods.reorientation.reorient`) on the refined
    maps, with the factors' eigenpairs: the density diffuses the input's matches, so a map the input sends
    left to right on most of the shape (or on a mirrored pair of limbs) comes out so, only more consistently.
    Records the decisions in ``extras`` as kernel matching does (``turned``, ``turned_regions``,
    ``turned_parts``, ``orientation_agreement``), and the swapped limbs it finds (``swapped_regions``): the
    refinement cannot place them again (its diffusion spreads the body's matches, it does not place limbs),
    so they are reported and left as found. A generator; returns the maps."""
    from corrlib.geometry.spectrum import Spectrum
    from corrlib.methods.reorientation import can_reorient, mean_agreement, orientation_blocks, reorient

    spec_x, spec_y = (Spectrum(f.evals, f.evecs, f.stiffness, f.mass) for f in (fx, fy))
    if not can_reorient(source, target, spec_y):
        return map_xy, map_yx
    yield Progress("orientation", fraction, "left and right")
    with watch("orientation"):
        blocks = orientation_blocks(source, target, spec_x, spec_y)
        done = reorient(source, target, spec_x, spec_y, map_xy, map_yx, lambda: blocks)
    extras.update(turned=done.turned is not None, swapped_regions=len(done.released_regions),
                  agreement_before_turn=None if done.turned is None else done.turned.agreement_before,
                  turned_regions=0 if done.turned_regions is None else len(done.turned_regions.parts),
                  turned_parts=0 if done.turned_parts is None else len(done.turned_parts.parts),
                  orientation_agreement=mean_agreement(*blocks, done.map_xy))
    return done.map_xy, done.map_yx


def _refined_again(source, target, fx: pm.Factor, fy: pm.Factor, turned_xy: np.ndarray, first: dict, params,
                   token, watch):
    """The refinement once more from a map the orientation stage turned, then the stage again (no third pass).

    As in kernel matching (:func:`corrlib.methods.kernel_matching.passes.reoptimised`): a turn composes the map
    with a computed reflection, so the turned part is a rough copy of the right one, and the density is
    diffused again from it. A generator; returns the maps and the extras (with the first pass's decisions,
    :func:`~corrlib.methods.reorientation.with_first_pass`).
    """
    from corrlib.methods.reorientation import with_first_pass

    yield Progress("re-optimising", 0.95, "the turned map, refined once more")
    keep = np.flatnonzero(turned_xy >= 0)
    map_xy, map_yx, extras = yield from scaled_progress(
        refine(fx, fy, keep, turned_xy[keep], source.vertices, target.vertices, params, token, watch, source),
        0.95, 0.99, "second pass")
    map_xy, map_yx = yield from _reoriented(source, target, fx, fy, map_xy, map_yx, extras, watch, fraction=0.995)
    return map_xy, map_yx, with_first_pass(extras, first, turned_xy)


def solve_product_manifold(source, target, params: ProductManifoldParams, token, *, initial=None):
    from corrlib.methods.base import InitialMatch

    watch = Stopwatch()
    # before the initial map's work: a vertex couples with itself and its neighbours
    check_band_size(params.band_list(), source.n_vertices, target.n_vertices,
                    1 + _nonzeros_per_row(source.adjacency), 1 + _nonzeros_per_row(target.adjacency))
    if initial is None:  # nothing given (e.g. from the studio): refine the functional-maps baseline
        from corrlib.methods.baselines import FmapZoomOutParams, solve_fmap_zoomout

        yield Progress("initial map", 0.0, "functional maps + ZoomOut (no initial map given)")
        with watch("init"):
            fm = yield from solve_fmap_zoomout(source, target, FmapZoomOutParams(), token)
        initial = InitialMatch(map_xy=fm.map_xy)
    ix, iy = initial.pairs(source.n_vertices, target.n_vertices)
    yield Progress("eigenpairs", 0.0, f"{params.n_eigs} per shape")
    with watch("eigen"):
        fx, fy = pm.mesh_factor(source, params.n_eigs), pm.mesh_factor(target, params.n_eigs)
    map_xy, map_yx, extras = yield from refine(fx, fy, ix, iy, source.vertices, target.vertices, params, token,
                                               watch, source)
    if params.reorient and initial.map_xy is not None:
        from corrlib.methods.reorientation import turned_anything

        map_xy, map_yx = yield from _reoriented(source, target, fx, fy, map_xy, map_yx, extras, watch)
        if turned_anything(extras):
            map_xy, map_yx, extras = yield from _refined_again(source, target, fx, fy, map_xy, extras, params,
                                                               token, watch)
    yield Progress("done", 1.0, f"dense map from {ix.size} matches")
    return MatchResult("product-manifold", map_xy, map_yx, None, watch.times, extras=extras)


register(MethodSpec(
    name="product-manifold", label="Product-manifold refinement", inputs=("mesh", "mesh"),
    params=ProductManifoldParams, solve=solve_product_manifold, rank=-5, refines=True,
    description="Refines sparse or noisy matches into a dense map: heat diffusion of the matches on the "
                "product X × Y, then localized (Dirichlet) product harmonics on shrinking bands around the "
                "current map (thesis §9.4.2); a map the input sent left to right (whole, or mirrored limbs) is "
                "turned by a reflection and the turned map refined once more, as in kernel matching."))


# ----------------------------------------------------------------------------- basis comparison (Figure 9.6)


def _circular_error(map_xy: np.ndarray, truth: np.ndarray, arclength_y: np.ndarray) -> np.ndarray:
    """Distance along the closed target curve between found and true partners, as a fraction of its length."""
    d = np.abs(arclength_y[map_xy] - arclength_y[truth])
    return np.minimum(d, 1.0 - d)


def basis_reconstruction(fx: pm.Factor, fy: pm.Factor, truth: np.ndarray, target_points: np.ndarray, k: int,
                         bands=(0.01, 0.05, 0.25, 0.9)) -> dict:
    """Reconstruct a ground-truth map of two curves from ``k`` basis coefficients (thesis Figure 9.6).

    The map's density ``F = Π A_Y⁻¹`` is projected onto (a) the ``k_X × k_Y``
    truncated functional map (``k_X = k_Y = √k``), (b) the first ``k``
    product eigenfunctions (sorted by ``α + β``), and (c) ``k`` localized
    Dirichlet harmonics of a band around the true correspondence for each
    fraction in ``bands``; every reconstruction is turned into a map by
    maximum likelihood. Returns the mean error along Y (fraction of its
    length) and the fraction of points matched exactly, per basis.
    """
    truth = np.asarray(truth, dtype=np.int64)
    seg = np.linalg.norm(np.roll(target_points, -1, axis=0) - target_points, axis=1)
    arclength = np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / seg.sum()
    density = pm.map_density(truth, fy)
    coeffs = pm.product_coefficients(density, fx, fy)
    out = {}

    def record(name, map_xy):
        err = _circular_error(map_xy, truth, arclength)
        out[name] = {"mean_error": float(err.mean()), "exact": float(np.mean(map_xy == truth))}

    side = int(round(np.sqrt(k)))
    trunc = np.zeros_like(coeffs)
    trunc[:side, :side] = coeffs[:side, :side]
    record(f"functional map {side}x{side}", pm.ml_map(trunc, fx, fy))
    _, index = pm.product_eigenbasis(fx, fy, k)
    first = np.zeros_like(coeffs)
    first[index[:, 0], index[:, 1]] = coeffs[index[:, 0], index[:, 1]]
    record(f"product eigenbasis k={k}", pm.ml_map(first, fx, fy))
    dense = np.asarray(density.toarray() if hasattr(density, "toarray") else density)
    for fraction in bands:
        pairs = pm.band_around_map(truth, target_points, fraction)
        pairs = pm.largest_piece(fx, fy, pairs)
        kk = min(k, len(pairs) - 1)
        _, basis = pm.localized_harmonics(fx, fy, pairs, kk)
        _, band_mass = pm.product_operator(fx, fy, pairs)
        values = dense[pairs[:, 0], pairs[:, 1]]
        recon = basis @ (basis.T @ (band_mass @ values))
        best = np.full(fx.n, -np.inf)
        np.maximum.at(best, pairs[:, 0], recon)
        map_xy = truth.copy()  # rows outside a fallen-apart band keep no estimate: count them as exact misses
        map_xy[:] = -1
        winners = np.flatnonzero(recon >= best[pairs[:, 0]])
        map_xy[pairs[winners, 0]] = pairs[winners, 1]
        missing = map_xy < 0
        map_xy[missing] = (truth[missing] + fy.n // 2) % fy.n  # the worst partner: half a turn away
        record(f"localized {fraction:.0%} band", map_xy)
    return out
