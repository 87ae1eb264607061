"""Kernel matching (thesis ch. 8; Vestner, Lähner, Boyarski et al., 3DV 2017).

The correspondence maximises the quadratic assignment objective

``f(Π) = <Π, K_Y Π K_X> + μ <Π, F_Y F_Xᵀ>``  over permutations Π,

with heat kernels ``K = Φ e^{-tΛ} Φᵀ`` (spectral form, values of the heat
kernel between vertices; Φ M-orthonormal). ``f`` is convex (both kernels are
positive semi-definite), so the DC algorithm — maximise the linearisation
``G = ∇f(Π_k) = K_Y Π_k K_X + μ F_Y F_Xᵀ`` (Eq. 8.13) by one linear
assignment — never decreases it (checked and reported per iteration). The
score is formed in spectral form only on the rows and columns of the current
problem: ``G = (Ψ_r e^{-tΛ_Y}) C (Φ_c e^{-tΛ_X})ᵀ`` with the k×k matrix
``C = Ψ[map]ᵀ Φ`` summed over the current matches, in float32. (Weighting
the matches by their sample areas was measured and dropped: with the exact
gradient, row weights of 0.05–5 on the wolf's seeds sent it to a mirrored
optimum; weighting only the anchors is no longer a DC step.)

Diffusion times decrease over a schedule (coarse, global alignment first;
detail last). Times are relative to the surface area (``t = τ · area``, the
heat kernel is then scale-invariant); the default τ from 0.0259 to 5.18e-4
equals 500 → 10 at the TOSCA area scale of 1.93e4.

Initialisation: a linear assignment on descriptors (SHOT by default). The
kernels cannot tell left from right, so the DC iterations keep the
orientation each region starts with; SHOT alone starts the TOSCA cats with a
mixture (41 % of the points nearer their true partner, 32 % nearer the
mirrored one), which ends as regions matched left-to-right next to regions
matched left-to-left, with seams of large error between them. Orientation-
aware descriptors (:mod:`corrlib.descriptors.orientation`, weight
``orientation``) in the initial assignment fix the orientation of most of
the shape. They are not used in the μ term of the iterations, where their
local noise costs accuracy (cats: 75.7 % instead of 78.8 % within 0.05,
cells of 3000).

Initial alignment (``init_fraction``): even so, the initial assignment on
thin parts is close to a coin flip (the cats' front legs: 31 % of the seeds
nearer the true partner, 39 % nearer the mirrored one), and a DC iteration
from the whole initial map keeps such a local majority: the front legs ended
swapped (cats: 77 % within 0.05 without symmetry, 84 % with). A second start
is therefore formed from only the most similar initial matches (default
30 %): their kernel score at the largest time spreads their alignment over
the whole shape, and the legs follow the body across the shoulders (87 % and
87 %; fractions from 0.1 to 0.6 give the same, 0.03 is too few, 0.7 keeps the
swap). Both starts run the DC iterations of the first time, and the one with
the higher objective goes on — a multi-start of the same DC problem, so no
start is trusted blindly: on a partial wolf (60 % of wolf1 against wolf0) the
aligned start is worse (39 % within 0.1 against 64 %) and loses. With
landmarks as the initialisation, the second start is the landmarks' kernel
score alone (instead of every seed taking its nearest landmark's partner):
15 random landmarks on the wolves, 99.5 % within 0.05 instead of 83 %.

Seeds: farthest points of the surfaces, not of their vertices
(:func:`~corrlib.geometry.sampling.surface_farthest_points`; eigenfunctions
and descriptors are interpolated inside the triangles). A vertex sample
follows the vertex density once it takes a good part of the vertices (3000
of the cats' 5000), and independently remeshed shapes differ in it: the tail
of cat1 carries 173 vertex seeds, the same part of cat0 98. A bijection of
the seeds then has to slide matches along the shape to absorb the
difference, a smooth distortion that the kernel energy hardly penalises
(the DC seeds had higher energy than the ground truth projected onto them,
yet only 79 % of them within 0.05). With surface seeds the projected ground
truth is 93 % within 0.05 (vertex seeds: 87 %), and the DC iterations
started from it reach a higher energy than those started from the
descriptors at the larger times (418.5 against 416.2 at the first).

Multiscale (§8.3.2): the seeds (default 3000) are matched first with the
full schedule. Then a vertex sample is grown by ``growth`` per scale
(farthest-point prefixes) until every vertex is included; there is always at
least one finer scale, whose first pass takes the seeds' matches as anchors
(their interpolated eigenfunctions). At each scale
the source sample is split into geodesic Voronoi cells of at most
``max_cell`` points around matched centres; the cells are transferred to the
target through the current map (Voronoi cells around the centres' images,
widened across their borders by ``cell_overlap`` so that a source vertex
near a border can still reach its partner beyond the transferred border —
with disjoint cells the cats lose 4 points within 0.05), and every cell is
an independent partial assignment whose score uses the kernel alignment with
all current matches as anchors. Cells are redrawn around different centres
at every refinement pass; cells run in threads (the auction releases the
GIL).

Area capacities (``capacity="area"``, default): at the finer scales the
samples are no longer uniform (the last scale is every vertex, and
independently remeshed shapes differ in vertex density by up to two orders of
magnitude), so a bijection has to slide vertices to absorb the density
difference. There the assignment couples the area measures instead of the
vertex counts: a target sample of area ``m_y`` may take up to
``ceil(n_x · m_y / A_Y)`` source samples (``n_x`` source samples; the mass
of a sample is the area of its Euclidean Voronoi cell), a transportation
problem solved exactly as an assignment on copies of the columns. Measured
on the TOSCA cats: their ground truth projected onto the nearest bijection
has only 68 % of points within 0.05; onto the nearest map with area
capacities, 99 %. The seeds stay matched by a permutation: with capacities
the QAP gains by piling several seeds onto one target (``k_Y(y, y)`` is the
kernel's maximum) and the DC iterations collapse (measured: 36 %).

A last pointwise step (``smooth_k``) projects the map onto the first
eigenfunctions and gives every vertex its best-scoring partner; the maps are
then no longer bijective, which suits independently remeshed shapes.

Unequal vertex counts: rectangular assignments are padded; with
``partial=True`` slack variables (Eq. 8.15–8.16) let low-scoring vertices
stay unmatched (-1 in the maps, reported).

Map convention: ``map_xy[i]`` = vertex of Y matched to vertex i of X.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from corrlib.assignment import linear_assignment
from corrlib.descriptors import DESCRIPTOR_KINDS, mesh_descriptors
from corrlib.descriptors.orientation import orientation_descriptors
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.sampling import farthest_point_sampling, surface_farthest_points, voronoi_bands, voronoi_cells
from corrlib.geometry.spectrum import mesh_spectrum
from corrlib.methods.base import MatchResult, param
from corrlib.methods.registry import MethodSpec, register
from corrlib.progress import Progress, Stopwatch


@dataclass(frozen=True, kw_only=True)
class KernelMatchingParams:
    n_eigs: int = param(500, label="Eigenpairs", low=10, high=3000,
                        help="Laplace–Beltrami eigenpairs of the heat kernels (spectral form).")
    init: str = param("descriptors", label="Initialisation", choices=("descriptors", "fmap"),
                      help="Linear assignment on descriptors, or the functional-maps baseline's map "
                           "(a given map or landmarks can be passed to the solver instead).")
    descriptor: str = param("shot", label="Descriptor", choices=DESCRIPTOR_KINDS,
                            help="Descriptor of the initial assignment and of the μ term (SHOT tells left "
                                 "from right, the spectral ones do not).")
    orientation: float = param(3.0, label="Orientation weight", low=0.0, high=100.0,
                               help="Weight of the orientation-aware descriptors (signed area forms of HKS "
                                    "pairs, which tell left from right) in the initial assignment, relative to "
                                    "the main descriptor (1: as much variance); 0: off (left and right may then "
                                    "be matched differently in different regions).")
    init_fraction: float = param(0.3, label="Initial alignment fraction", low=0.01, high=1.0,
                                 help="Second start of the DC iterations: the kernel score of the largest time from "
                                      "only this fraction of the initial descriptor matches (the most similar "
                                      "pairs); the start with the higher objective after the first time goes on. "
                                      "1: no second start.")
    mu: float = param(0.1, label="Descriptor weight μ", low=0.0, high=1e6,
                      help="Weight of the descriptor term F_Y F_Xᵀ in the score (relative to the kernel "
                           "term, both scaled to unit maximum).")
    tau_max: float = param(0.0259, label="Largest time / area", low=1e-7, high=10.0,
                           help="First diffusion time divided by the surface area (500 at TOSCA scale).")
    tau_min: float = param(5.18e-4, label="Smallest time / area", low=1e-8, high=10.0,
                           help="Last diffusion time divided by the surface area (10 at TOSCA scale).")
    n_times: int = param(10, label="Times", low=1, high=100, help="Log-spaced diffusion times.")
    times: str = param("", label="Explicit times / area",
                       help="Comma-separated relative times (decreasing) replacing the log-spaced schedule.")
    iters_per_time: int = param(3, label="Iterations per time", low=1, high=100,
                                help="DC iterations (linear assignments) per time; stops early when the "
                                     "map no longer changes.")
    n_seeds: int = param(3000, label="Seeds", low=10, high=100_000,
                         help="Farthest points of the surfaces (inside triangles too) matched first with the whole "
                              "schedule.")
    growth: float = param(3.0, label="Growth factor", low=1.5, high=100.0,
                          help="Sample growth per scale until every vertex is matched.")
    max_cell: int = param(1000, label="Max cell size", low=50, high=20_000,
                          help="Largest Voronoi cell solved as one assignment at the finer scales.")
    cell_overlap: float = param(0.1, label="Cell overlap", low=0.0, high=10.0,
                                help="Target cells are widened across their borders by about half this "
                                     "length (relative to √area) so that cells overlap; 0: disjoint cells.")
    passes: int = param(2, label="Passes per scale", low=1, high=20,
                        help="Refinement passes per finer scale, each with cells around new centres.")
    partial: bool = param(False, label="Partial matching",
                          help="Slack variables: vertices whose best score is low may stay unmatched.")
    slack_quantile: float = param(0.1, label="Slack quantile", low=0.0, high=1.0,
                                  help="With partial matching: the slack equals this quantile of the rows' "
                                       "best scores in each cell.")
    smooth_k: int = param(0, label="Final smoothing basis", low=0, high=3000,
                          help="Final pointwise step: the map is projected onto this many eigenfunctions and "
                               "every vertex takes the best-scoring partner (one ZoomOut-style step; removes "
                               "the jitter a bijection forces between differently sampled meshes). 0: off.")
    capacity: str = param("area", label="Finer-scale capacity", choices=("area", "one"),
                          help="Finer scales: a target sample may take as many source samples as its area "
                               "holds (measure-preserving; for differently meshed shapes) or exactly one "
                               "(a bijection within each cell; better for two meshes of the same connectivity).")
    backend: str = param("auction", label="Assignment backend", choices=("auction", "scipy"),
                         help="ε-scaling auction (fast) or scipy's exact solver (slow, for checks).")

    def __post_init__(self):
        if isinstance(self.times, str) and isinstance(self.tau_min, (int, float)) and \
                isinstance(self.tau_max, (int, float)):
            diffusion_times(self)  # raises ParameterError on a bad schedule, before any run


@dataclass
class InitialMatch:
    """A starting point for kernel matching (refinement of another method's output).

    Either a dense map (``map_xy``, -1 allowed) or sparse landmarks
    (``landmarks_x``, ``landmarks_y``). Landmarks are kept as anchors in every
    score, so they stay matched.
    """

    map_xy: np.ndarray | None = None
    landmarks_x: np.ndarray | None = None
    landmarks_y: np.ndarray | None = None

    def pairs(self, n_x: int, n_y: int) -> tuple[np.ndarray, np.ndarray]:
        if self.map_xy is not None:
            mp = np.asarray(self.map_xy, dtype=np.int64)
            if mp.shape != (n_x,):
                raise InputError(f"the initial map has {mp.shape[0]} entries, the source {n_x} vertices")
            if mp.max() >= n_y:
                raise InputError(f"the initial map points to vertex {mp.max()} of a {n_y}-vertex target")
            keep = np.flatnonzero(mp >= 0)
            if keep.size == 0:
                raise InputError("the initial map matches no vertex")
            return keep, mp[keep]
        lx = np.asarray(self.landmarks_x, dtype=np.int64)
        ly = np.asarray(self.landmarks_y, dtype=np.int64)
        if lx.size == 0 or lx.shape != ly.shape:
            raise InputError(f"landmarks need equally many source and target indices, got {lx.size} and {ly.size}")
        if lx.min() < 0 or lx.max() >= n_x or ly.min() < 0 or ly.max() >= n_y:
            raise InputError("landmark index out of range")
        return lx, ly


def diffusion_times(params: KernelMatchingParams) -> np.ndarray:
    """(n_times,) float: relative times τ, decreasing."""
    if params.times.strip():
        try:
            taus = np.array([float(v) for v in params.times.replace(";", ",").split(",") if v.strip()])
        except ValueError:
            raise ParameterError(f"times must be comma-separated numbers, got {params.times!r}") from None
        if taus.size == 0 or not np.all(np.isfinite(taus)) or np.any(taus <= 0):
            raise ParameterError(f"times must be positive numbers, got {params.times!r}")
        return taus
    if params.tau_min > params.tau_max:
        raise ParameterError(f"tau_min ({params.tau_min}) must not exceed tau_max ({params.tau_max})")
    return np.geomspace(params.tau_max, params.tau_min, params.n_times)


def _pointwise_from_basis(map_xy, map_yx, phi, psi, k, chunk: int = 1024):
    """Best-scoring partners of ``Ψ_k C Φ_kᵀ`` with ``C = Ψ_k[map]ᵀ Φ_k`` (unmatched vertices stay -1)."""
    valid = map_xy >= 0
    c = psi[map_xy[valid], :k].T @ phi[valid, :k]
    left = (psi[:, :k] @ c).astype(np.float32)  # (n_y, k): rows of the score, one per target vertex
    right = phi[:, :k].astype(np.float32)
    new_xy = map_xy.copy()
    for start in range(0, right.shape[0], chunk):
        best = np.argmax(left @ right[start:start + chunk].T, axis=0)
        block = slice(start, start + chunk)
        new_xy[block] = np.where(valid[block], best, -1)
    new_yx = map_yx.copy()
    for start in range(0, left.shape[0], chunk):
        best = np.argmax(left[start:start + chunk] @ right.T, axis=1)
        block = slice(start, start + chunk)
        new_yx[block] = np.where(map_yx[block] >= 0, best, -1)
    return new_xy, new_yx


def kernel_energy(c: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray) -> float:
    """``<Π, K_Y Π K_X> = trace(D_Y C D_X Cᵀ)`` for ``C = Ψ[map]ᵀ Φ``."""
    return float(np.einsum("ij,i,ij,j->", c, decay_y, c, decay_x))


def _alignment(psi_rows, phi_rows):
    return psi_rows.T @ phi_rows


#: decays below this (relative to 1) are dropped from the spectral products: their terms are far below float32
#: precision, and e^{-tλ} of the high eigenvalues at large times would otherwise be float32 subnormals, on which
#: the products run ~15x slower (measured: 1.1 s instead of 0.076 s per 3000 x 3000 score at the largest time)
DECAY_CUTOFF = 1e-12


def _score(psi_rows, phi_cols, c, decay_y, decay_x):
    """(r, c) float32 kernel score block ``(Ψ_r D_Y) C (Φ_c D_X)ᵀ``.

    Only the eigenpairs with a decay above :data:`DECAY_CUTOFF` enter. The transposed block is
    ``_score(phi_cols, psi_rows, c.T, decay_x, decay_y)``.
    """
    k_y = max(1, int(np.count_nonzero(decay_y > DECAY_CUTOFF)))
    k_x = max(1, int(np.count_nonzero(decay_x > DECAY_CUTOFF)))
    left = ((psi_rows[:, :k_y] * decay_y[:k_y]) @ c[:k_y, :k_x]).astype(np.float32)
    right = (phi_cols[:, :k_x] * decay_x[:k_x]).astype(np.float32)
    return left @ right.T


def _descriptor_similarity(f_rows: np.ndarray, f_cols: np.ndarray) -> np.ndarray:
    """(r, c) float32: negative squared descriptor distances between rows and columns, scaled to [-1, 0]."""
    fr32, fc32 = f_rows.astype(np.float32), f_cols.astype(np.float32)
    d2 = (fr32 ** 2).sum(1)[:, None] + (fc32 ** 2).sum(1)[None, :] - 2.0 * fr32 @ fc32.T
    return -d2 / max(float(d2.max()), 1e-30)


def _standardised(desc_x: np.ndarray, desc_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both descriptor sets with every dimension divided by its joint standard deviation."""
    scale = np.concatenate([desc_x, desc_y]).std(axis=0)
    scale[scale == 0] = 1.0
    return desc_x / scale, desc_y / scale


def _descriptors(source, target, spec_x, spec_y, kind: str):
    """Standardised descriptors of both shapes."""
    desc_x = mesh_descriptors(source, kind, spectrum=spec_x) if kind != "shot" else mesh_descriptors(source, kind)
    desc_y = mesh_descriptors(target, kind, spectrum=spec_y) if kind != "shot" else mesh_descriptors(target, kind)
    return _standardised(desc_x, desc_y)


def _with_orientation(desc_x, desc_y, source, target, spec_x, spec_y, weight: float):
    """The descriptors with the standardised orientation block appended (total variance ``weight`` × theirs)."""
    if weight <= 0:
        return desc_x, desc_y
    or_x, or_y = _standardised(orientation_descriptors(source, spec_x), orientation_descriptors(target, spec_y))
    scale = weight * np.sqrt(desc_x.shape[1] / or_x.shape[1])
    return np.hstack([desc_x, scale * or_x]), np.hstack([desc_y, scale * or_y])


def _sample_order(points: np.ndarray, n_seed: int, growth: float) -> np.ndarray:
    """Vertex order whose prefixes are the samples of the successive scales.

    Farthest-point order for the first ``n_seed × growth²`` vertices (the
    first finer scales; the seeds themselves are surface points, see
    :func:`~corrlib.geometry.sampling.surface_farthest_points`); the rest
    follow ordered by their distance from the centroid (they only enter the
    last, dense scales).
    """
    n = points.shape[0]
    n_fps = int(min(n, n_seed * growth ** 2))
    radius = np.linalg.norm(points - points.mean(axis=0), axis=1)
    # start at the vertex farthest from the centroid and order the rest by that distance: the samples
    # do not depend on the vertex order of the file
    head = farthest_point_sampling(points, n_fps, start=int(np.argmax(radius)))
    rest = np.setdiff1d(np.arange(n), head)
    return np.concatenate([head, rest[np.argsort(-radius[rest], kind="stable")]])


def _nearest_point(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """(q,) int: for every query position (q, 3) the index of the nearest of ``points`` (p, 3) (Euclidean)."""
    from scipy.spatial import cKDTree

    return cKDTree(points).query(queries)[1]


def _sample_masses(mesh, mass_diag: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """(s,) float: area of every sample's Euclidean Voronoi cell (vertex areas summed to the nearest sample)."""
    from scipy.spatial import cKDTree

    if sample.size == mesh.n_vertices:
        return mass_diag[sample]
    owner = cKDTree(mesh.vertices[sample]).query(mesh.vertices)[1]
    return np.bincount(owner, weights=mass_diag, minlength=sample.size)


def _capacities(n_source: int, masses_y: np.ndarray) -> np.ndarray:
    """(s,) int ≥ 1: source samples a target sample may take, ``ceil(n_source · m_y / Σ m_y)``."""
    share = n_source * masses_y / masses_y.sum()
    return np.maximum(1, np.ceil(share - 1e-9)).astype(np.int64)


def _best_row_per_column(rows: np.ndarray, cols: np.ndarray, values: np.ndarray, n_cols: int) -> np.ndarray:
    """(n_cols,) int: for every column the row with the highest value among the given (row, col) pairs, -1 if none."""
    out = -np.ones(n_cols, dtype=np.int64)
    if rows.size:
        order = np.lexsort((-values, cols))
        first = np.concatenate([[True], cols[order][1:] != cols[order][:-1]])
        out[cols[order][first]] = rows[order][first]
    return out


def _solve_cells(x_cells, y_cells, psi, phi, c, decay_y, decay_x, params, cancel, n_y, capacity_y=None):
    """One refinement pass: every cell is a (partial) assignment.

    Parameters
    ----------
    x_cells : list of (a_c,) int
        Source samples of every cell (a partition of the sample).
    y_cells : list of (b_c,) int
        Target samples of every cell (they may overlap: widened cells).
    capacity_y : (n_y,) int, optional
        How many source samples each target vertex may take (None: one).

    Returns
    -------
    map_x : (n_x_sample,) int, aligned with ``np.concatenate(x_cells)``
        Target of every source sample (-1: unmatched).
    map_yx : (n_y,) int
        For target vertices in some cell: the best-scoring source sample assigned to it, or (without
        partial matching) the best-scoring source sample of its cells; -1 elsewhere.
    """
    def cell(cid):
        xs, ys = x_cells[cid], y_cells[cid]
        if xs.size == 0 or ys.size == 0:
            return None
        g = _score(phi[xs], psi[ys], c.T, decay_x, decay_y)  # (xs, ys)
        slack = None
        if params.partial:
            slack = float(np.quantile(g.max(axis=1), params.slack_quantile))
        cap = None if capacity_y is None else capacity_y[ys]
        return g, linear_assignment(g, slack=slack, method=params.backend, cancel=cancel, capacity=cap)

    map_x = []
    # reverse map, merged over overlapping cells: an assigned source beats an unassigned one, then the score
    rank_y = np.full((n_y, 2), -np.inf)
    map_yx = -np.ones(n_y, dtype=np.int64)
    with ThreadPoolExecutor(max_workers=2) as pool:
        for cid, out in enumerate(pool.map(cell, range(len(x_cells)))):
            xs, ys = x_cells[cid], y_cells[cid]
            if out is None:
                map_x.append(-np.ones(xs.size, dtype=np.int64))
                continue
            g, cols = out
            mx = np.where(cols >= 0, ys[np.clip(cols, 0, None)], -1)
            if not params.partial:
                mx = np.where(mx >= 0, mx, ys[np.argmax(g, axis=1)])  # smaller target cell: best score
            map_x.append(mx)
            matched = np.flatnonzero(cols >= 0)
            best_in = _best_row_per_column(matched, cols[matched], g[matched, cols[matched]], ys.size)
            assigned = best_in >= 0
            cand = np.where(assigned, best_in, np.argmax(g, axis=0))
            key = np.column_stack([assigned.astype(float), g[cand, np.arange(ys.size)]])
            if params.partial:
                key[~assigned] = -np.inf
            better = (key[:, 0] > rank_y[ys, 0]) | ((key[:, 0] == rank_y[ys, 0]) & (key[:, 1] > rank_y[ys, 1]))
            rank_y[ys[better]] = key[better]
            map_yx[ys[better]] = xs[cand[better]]
    return np.concatenate(map_x), map_yx


def kernel_matching(source, target, params: KernelMatchingParams, token, initial: InitialMatch | None = None):
    """Solver generator (see the module docstring); returns a :class:`MatchResult`."""
    watch = Stopwatch()
    cancel = token.flag
    n_x, n_y = source.n_vertices, target.n_vertices
    for mesh in (source, target):
        if params.n_eigs >= mesh.n_vertices:
            raise ParameterError(f"{params.n_eigs} eigenpairs requested but {mesh.name} has only "
                                 f"{mesh.n_vertices} vertices (lower n_eigs)")
    k = params.n_eigs
    taus = diffusion_times(params)
    yield Progress("eigenpairs", 0.0, f"{k} eigenpairs per shape")
    with watch("eigen"):
        spec_x = mesh_spectrum(source, k)
        spec_y = mesh_spectrum(target, k)
    phi, psi = spec_x.evecs, spec_y.evecs
    mass_y = spec_y.mass.diagonal()
    token.raise_if_cancelled()

    def decays(tau):
        return np.exp(-tau * target.area * spec_y.evals), np.exp(-tau * source.area * spec_x.evals)

    # farthest-point orders: every prefix is a well-spread sample
    with watch("sampling"):
        n_seed = min(params.n_seeds, n_x, n_y)
        # the seeds are points of the surfaces (see the module docstring); the finer scales sample vertices
        seeds_x = surface_farthest_points(source, n_seed)
        seeds_y = surface_farthest_points(target, n_seed)
        order_x = _sample_order(source.vertices, n_seed, params.growth)
        order_y = _sample_order(target.vertices, n_seed, params.growth)

    anchors_x = anchors_y = np.zeros(0, dtype=np.int64)
    desc_x = desc_y = None
    confidence = None  # (n_seed,) similarity of every initial descriptor match
    if initial is not None:
        ix, iy = initial.pairs(n_x, n_y)
        if initial.map_xy is None:
            anchors_x, anchors_y = ix, iy
        yield Progress("initial map", 0.1, f"{ix.size} given matches")
        # each seed follows its nearest matched vertex; the partner snaps to the nearest target seed
        partner_of = -np.ones(n_x, dtype=np.int64)
        partner_of[ix] = iy
        partner = partner_of[ix[_nearest_point(source.vertices[ix], seeds_x.points)]]
        seed_map = _nearest_point(seeds_y.points, target.vertices[partner])
    elif params.init == "fmap":
        from corrlib.methods.baselines import FmapZoomOutParams, solve_fmap_zoomout
        from corrlib.progress import run

        yield Progress("initial map", 0.05, "functional maps + ZoomOut")
        with watch("init"):
            fm = run(solve_fmap_zoomout(source, target, FmapZoomOutParams(), token))
        partner = fm.map_xy[seeds_x.nearest_corners(source)]
        seed_map = _nearest_point(seeds_y.points, target.vertices[partner])
    else:
        yield Progress("descriptors", 0.05, params.descriptor)
        with watch("descriptors"):
            desc_x, desc_y = _descriptors(source, target, spec_x, spec_y, params.descriptor)
            init_x, init_y = _with_orientation(desc_x, desc_y, source, target, spec_x, spec_y, params.orientation)
        with watch("assignment"):
            sim = _descriptor_similarity(seeds_x.interpolate(source, init_x), seeds_y.interpolate(target, init_y))
            seed_map = linear_assignment(sim, method=params.backend, cancel=cancel)  # seed x -> seed y
            confidence = sim[np.arange(n_seed), seed_map]
    token.raise_if_cancelled()

    # ---- coarse scale: DC iterations over the time schedule on the seeds
    psi_s, phi_s = seeds_y.interpolate(target, psi), seeds_x.interpolate(source, phi)  # eigenfunctions at the seeds
    desc_block = None
    if params.mu > 0:
        # the plain descriptor: the orientation features only decide the initial orientation (see the module
        # docstring)
        if desc_x is None:
            desc_x, desc_y = _descriptors(source, target, spec_x, spec_y, params.descriptor)
        desc_block = _descriptor_similarity(seeds_x.interpolate(source, desc_x),
                                            seeds_y.interpolate(target, desc_y))  # (seed x, seed y)
    anchor_c = _alignment(psi[anchors_y], phi[anchors_x]) if anchors_x.size else 0.0
    trace, monotone = [], True
    landmarks_only = initial is not None and initial.map_xy is None
    aligned = (confidence is not None and params.init_fraction < 1) or landmarks_only
    total_steps = (len(taus) + aligned) * params.iters_per_time
    step = 0
    seed_cols = np.arange(n_seed)

    def objective(mapping, c_mat, scale, decay_y, decay_x):
        # the function the DC steps maximise at this time: ½ kernel term (its gradient is K_Y Π K_X)
        # plus μ × descriptor similarity, with the kernel term scaled by a constant of this time
        value = 0.5 * kernel_energy(c_mat, decay_y, decay_x) / scale
        if desc_block is not None:
            value += params.mu * float(desc_block[seed_cols, mapping].sum())
        return value

    def seed_score(c, decay_y, decay_x, kernel_scale):
        """(n_seed, n_seed) float32 score (seed x, seed y) of the alignment ``c``, and the time's kernel scale.

        The kernel term is divided by ``kernel_scale`` (None: its own maximum) before μ × descriptor term is added.
        """
        g = _score(phi_s, psi_s, c.T, decay_x, decay_y)  # the assignment's rows are the x seeds
        if kernel_scale is None:
            kernel_scale = max(float(np.abs(g).max()), 1e-30)
        if desc_block is not None:
            g = g / np.float32(kernel_scale) + np.float32(params.mu) * desc_block
        return g, kernel_scale

    def dc_iterations(seed_map, prices, t_index, kernel_scale, warm_first):
        """DC iterations at one time (a generator: yields progress, returns the map and the time's state).

        ``prices`` (the auction's warm start) is updated in place; ``kernel_scale`` None: set from the first
        score; ``warm_first``: the first score is far from the last one (a larger first ε).
        """
        nonlocal step, monotone
        tau = taus[t_index]
        decay_y, decay_x = decays(tau)
        entries, value = [], None
        for it in range(params.iters_per_time):
            token.raise_if_cancelled()
            with watch("kernels"):
                c = _alignment(psi_s[seed_map], phi_s) + anchor_c
                g, kernel_scale = seed_score(c, decay_y, decay_x, kernel_scale)
                before = objective(seed_map, c, kernel_scale, decay_y, decay_x)
            with watch("assignment"):
                # the first score of a new time, or after the initial alignment, is further from the last one: a
                # larger first ε (measured on the cats: 1.1 s instead of 3.3 s for the first change of time,
                # 0.85 s instead of 5.1 s after the initial alignment, no cost later)
                new_map = linear_assignment(g, method=params.backend, cancel=cancel, prices=prices,
                                            eps_start=1e-2 if it == 0 and warm_first else None)
            changed = int(np.sum(new_map != seed_map))
            value = objective(new_map, _alignment(psi_s[new_map], phi_s) + anchor_c, kernel_scale, decay_y, decay_x)
            # the DC guarantee holds from a permutation (a given initial map may map seeds together)
            if np.unique(seed_map).size == seed_map.size and value < before - 1e-5 * abs(before):
                monotone = False
            seed_map = new_map
            entries.append({"tau": float(tau), "iteration": it, "energy": value, "changed": changed})
            step += 1
            yield Progress("kernel matching", 0.1 + 0.6 * step / total_steps,
                           f"time {t_index + 1}/{len(taus)}, iteration {it + 1}: energy {value:.6g}, "
                           f"{changed} changed")
            if changed == 0:
                step += params.iters_per_time - it - 1
                break
        return seed_map, kernel_scale, entries, value

    # ---- coarse scale, first time: DC from the initial map, and (descriptor or landmark initialisation) DC from
    # the initial alignment; the start that ends with the higher objective goes on (see the module docstring)
    prices = np.zeros(n_seed)  # auction prices carried from one assignment to the next (warm start)
    start_map = seed_map
    seed_map, kernel_scale, entries, value = yield from dc_iterations(start_map, prices, 0, None, False)
    dc_start = "initial map"
    if aligned:
        if landmarks_only:
            keep = np.zeros(0, dtype=np.int64)  # the landmarks (anchors) alone
            yield Progress("initial alignment", 0.1, f"kernel score of the {anchors_x.size} landmarks")
        else:
            keep = np.argsort(-confidence, kind="stable")[:max(1, int(round(params.init_fraction * n_seed)))]
            yield Progress("initial alignment", 0.1, f"kernel score of the {keep.size} most similar initial matches")
        with watch("kernels"):
            g, _ = seed_score(_alignment(psi_s[start_map[keep]], phi_s[keep]) + anchor_c, *decays(taus[0]), None)
        other_prices = np.zeros(n_seed)
        with watch("assignment"):
            other_start = linear_assignment(g, method=params.backend, cancel=cancel, prices=other_prices)
        other = yield from dc_iterations(other_start, other_prices, 0, kernel_scale, True)
        if other[3] > value:
            seed_map, _, entries, value = other
            prices, dc_start = other_prices, "initial alignment"
    trace.extend(entries)
    for t_index in range(1, len(taus)):
        seed_map, _, entries, _ = yield from dc_iterations(seed_map, prices, t_index, None, True)
        trace.extend(entries)

    # ---- finer scales: grow the vertex sample, solve Voronoi cells with all current matches as anchors; there
    # is always at least one (the seeds are surface points, the last scale is every vertex)
    rows_y, rows_x = psi_s[seed_map], phi_s  # eigenfunctions at the current matches (first: the seeds)
    matched_x = seeds_x.nearest_corners(source)  # vertices of the matches (cell centres)
    matched_y = seeds_y.nearest_corners(target)[seed_map]
    seed_vertices_x, seed_vertices_y = matched_x.copy(), matched_y.copy()
    decay_y, decay_x = decays(taus[-1])
    size = n_seed
    last = False
    while not last:
        size = int(min(max(n_x, n_y), np.ceil(size * params.growth)))
        last = size >= max(n_x, n_y)
        x_idx = order_x[:size]
        y_idx = order_y[:size]
        capacity_y = None
        if params.capacity == "area":
            capacity_y = np.ones(n_y, dtype=np.int64)
            capacity_y[y_idx] = _capacities(x_idx.size, _sample_masses(target, mass_y, y_idx))
        for p in range(params.passes):
            token.raise_if_cancelled()
            with watch("kernels"):
                c = _alignment(rows_y, rows_x) + anchor_c
            n_cells = max(1, int(np.ceil(x_idx.size / (0.7 * params.max_cell))))
            # cell centres: matched vertices, a different farthest-point set every pass
            matched_pts = source.vertices[matched_x]
            radius = np.linalg.norm(matched_pts - matched_pts.mean(axis=0), axis=1)
            start = int(np.argsort(-radius, kind="stable")[min(p * 7, radius.size - 1)])
            centres_pos = farthest_point_sampling(matched_pts, min(n_cells, matched_x.size), start=start)
            # distinct centres on both sides (seeds snapped to their vertices may share one)
            _, first_x = np.unique(matched_x[centres_pos], return_index=True)
            centres_pos = centres_pos[np.sort(first_x)]
            _, first_y = np.unique(matched_y[centres_pos], return_index=True)
            centres_pos = centres_pos[np.sort(first_y)]
            centres_x, centres_y = matched_x[centres_pos], matched_y[centres_pos]
            with watch("cells"):
                lab_x, _ = voronoi_cells(source, centres_x)
                # target cells widened across their borders: a source vertex near a border can reach its
                # partner beyond the transferred border
                _, band_y = voronoi_bands(target, centres_y, params.cell_overlap * np.sqrt(target.area))
                in_y = np.zeros(n_y, dtype=bool)
                in_y[y_idx] = True
                x_cells = [x_idx[lab_x[x_idx] == cid] for cid in range(centres_x.size)]
                y_cells = [members[in_y[members]] for members in band_y]
            with watch("assignment"):
                cell_map, cell_map_yx = _solve_cells(x_cells, y_cells, psi, phi, c, decay_y, decay_x, params,
                                                     cancel, n_y, capacity_y)
            keys = np.concatenate(x_cells)
            ok = cell_map >= 0
            matched_x, matched_y = keys[ok], cell_map[ok]
            rows_y, rows_x = psi[matched_y], phi[matched_x]
            yield Progress("multiscale", 0.7 + 0.3 * size / max(n_x, n_y),
                           f"{size} samples, pass {p + 1}/{params.passes}: {centres_x.size} cells")
    full_map_xy = -np.ones(n_x, dtype=np.int64)
    full_map_xy[keys] = cell_map
    full_map_yx = cell_map_yx
    c = _alignment(psi[full_map_xy[full_map_xy >= 0]], phi[full_map_xy >= 0]) + anchor_c
    energy = kernel_energy(c, decay_y, decay_x)
    if params.smooth_k > 0:
        yield Progress("smoothing", 0.98, f"pointwise map from a {min(params.smooth_k, k)}-dimensional basis")
        with watch("smoothing"):
            full_map_xy, full_map_yx = _pointwise_from_basis(full_map_xy, full_map_yx, phi, psi,
                                                             min(params.smooth_k, k))
    extras = {
        "energy_trace": np.array([e["energy"] for e in trace]),
        "changed_trace": np.array([e["changed"] for e in trace]),
        "tau_trace": np.array([e["tau"] for e in trace]),
        "monotone": monotone, "start": dc_start, "unmatched_x": int(np.sum(full_map_xy < 0)),
        "unmatched_y": int(np.sum(full_map_yx < 0)), "n_eigs": k, "n_seeds": n_seed,
        "seeds_x": seed_vertices_x, "seeds_matched_y": seed_vertices_y,
        "energy_meaning": "QAP kernel energy <Π, K_Y Π K_X> at the smallest time (higher is better); "
                          "energy_trace: the objective of each time (½ scaled kernel term + μ descriptor term)",
        "energy_sense": "max",
    }
    yield Progress("done", 1.0, f"energy {energy:.6g}")
    return MatchResult("kernel-matching", full_map_xy, full_map_yx, energy, watch.times, extras=extras)


def solve_kernel_matching(source, target, params: KernelMatchingParams, token,
                          initial: InitialMatch | None = None):
    """Registered solver (``initial``: optional :class:`InitialMatch` for refinement)."""
    return (yield from kernel_matching(source, target, params, token, initial))


register(MethodSpec(
    name="kernel-matching", label="Kernel matching", inputs=("mesh", "mesh"), params=KernelMatchingParams,
    solve=solve_kernel_matching, rank=20, refines=True,
    description="Heat-kernel quadratic assignment solved as a sequence of linear assignments over decreasing "
                "diffusion times, multiscale, with slack for partial shapes (Vestner et al. 3DV 2017)."))
