"""Kernel matching (thesis ch. 8; Vestner, Lähner, Boyarski et al., 3DV 2017).

The correspondence maximises the quadratic assignment objective

``f(Π) = <Π, K_Y Π K_X> + μ <Π, F_Y F_Xᵀ>``  over permutations Π,

with heat kernels ``K = Φ e^{-tΛ} Φᵀ`` (spectral form, values of the heat
kernel between vertices; Φ M-orthonormal). ``f`` is convex (both kernels are
positive semi-definite), so the DC algorithm — maximise the linearisation
``G = ∇f(Π_k) = K_Y Π_k K_X + μ F_Y F_Xᵀ`` (Eq. 8.13) by one linear
assignment — never decreases it (checked and reported per iteration). The
score is formed in spectral form on the rows and columns of the current
problem only: ``G = (Ψ_r e^{-tΛ_Y}) C (Φ_c e^{-tΛ_X})ᵀ`` with the k×k matrix
``C = Ψ[map]ᵀ Φ`` summed over the current matches, in float32.

The stages, each a function below sharing one :class:`KernelState`:

1. :func:`prepare` — spectra, surface seeds, sample orders of the finer scales.
2. :func:`initial_seed_map` — the seeds' initial assignment (descriptors, the
   functional-maps baseline, or a given map / landmarks).
3. :func:`seed_problem` — eigenfunctions, descriptor similarities and the
   anchors' alignment at the seeds (:class:`SeedProblem`).
4. :func:`choose_start` — DC iterations of the first (largest) time from the
   initial map and from the aligned start (:func:`aligned_start`, formed on a
   thread beside the first start's iterations); the higher objective goes on
   (landmarks: the aligned start alone).
5. :func:`dc_iterations` — DC iterations at one diffusion time, each one
   :func:`dc_step` (objective :func:`dc_objective`, score :func:`seed_score`);
   run over the decreasing time schedule (coarse, global alignment first).
6. :func:`multiscale_refinement` — finer vertex samples solved in Voronoi
   cells (§8.3.2). When a dense map is refined (``initial``, or
   ``init="fmap"``), rows moved by less than the smallest kernel's width keep
   their input partner (:mod:`.resolution`: the kernel cannot tell such
   partners apart).
7. :func:`kernel_result` — a map reversed on most of the shape, and limbs
   matched to their mirror-image limbs, turned by a reflection
   (:mod:`.reorientation`); final energy, optional pointwise smoothing, result.
8. :func:`reoptimised` — where stage 7 turned anything, stages 2–7 once more
   from the turned map (a turn by a computed reflection is a start, not an
   optimum). Where it turned regions or limbs, or released limbs, the result
   stands only if it is nearer an isometry than the map without those turns
   (:func:`declined_partial_turns`, the geodesic distortion).
9. :func:`replaced_disagreeing_part` — a final map made of two parts whose
   geodesic distances disagree (one turned against the other) has each part
   matched again with the other as landmarks; the run nearer an isometry
   replaces it.

Design choices, in brief (the measurements behind them are in
``docs/decisions.md``, "Kernel matching: measured design choices"):

* Times are relative to the surface area (``t = τ · area``), so the heat
  kernel is scale-invariant; the default τ from 0.0259 to 5.18e-4 equals
  500 → 10 at the TOSCA area scale of 1.93e4.
* The kernels cannot tell left from right, so the DC iterations keep the
  orientation each region starts with. Orientation-aware descriptors
  (:mod:`corrlib.descriptors.orientation`) therefore enter the initial
  assignment; the μ term of the iterations uses the plain descriptor (their
  local noise costs accuracy there).
* A second start is formed from the kernel score of only the most similar
  initial matches (``init_fraction``), which spreads their alignment over the
  shape where the initial assignment is a coin flip (thin parts). Both starts
  run the first time's DC iterations and the higher objective goes on: a
  multi-start of the same DC problem, no start is trusted blindly.
* Landmarks stay matched: the seeds and vertices at landmarks keep their
  partners (:func:`fixed_seeds`), every assignment places the others only, and
  the one start is the landmarks' kernel score (the other seeds have no
  partner of their own). A release pass (stage 8) thereby solves the released
  limbs only.
* Seeds are farthest points of the surfaces, not of their vertices
  (:func:`~corrlib.geometry.sampling.surface_farthest_points`): independently
  remeshed shapes differ in vertex density, and a bijection of vertex seeds
  must slide matches to absorb it, which the kernel energy hardly penalises.
* Multiscale (§8.3.2): after the seeds, a vertex sample grows by ``growth``
  per scale until every vertex is included. Each pass splits the source
  sample into geodesic Voronoi cells around matched centres (farthest points,
  and more inside any cell above ``max_cell``), transfers them through the
  current map and widens the target cells by ``cell_overlap`` (a vertex near a
  border can reach its partner beyond it) and by the neighbourhoods of its rows'
  current partners (where a change of pose moves the borders apart by more than
  the overlap); every cell is an independent
  partial assignment scored with all current matches as anchors. One pass
  per scale by default: a further pass at the same scale scores the cells
  with the previous pass's matches, including those that the capacities
  (below) pushed off their best partner, and pushes again, so the map
  drifts wherever the capacities are tight; the next scale's cells have new
  borders anyway.
* A source with more vertices than the target: the finer scales sample it up
  to the target's vertex count, and the surplus vertices take the partner of
  their nearest matched vertex before the final ZoomOut step (why:
  :mod:`.resolution`).
* Area capacities (``capacity="area"``): at the finer scales a target sample
  of area ``m_y`` may take up to ``ceil(n_x · m_y / A_Y)`` source samples, a
  transportation problem that couples the area measures instead of the
  vertex counts (for differently meshed shapes). The seeds stay matched by a
  permutation: with capacities the QAP gains by piling seeds onto one target
  (``k_Y(y, y)`` is the kernel's maximum).
* ``init="best"`` (the default, :func:`best_of_both_starts`): the whole
  pipeline from the descriptors and from the functional-maps baseline
  (sharing the spectra, samples and descriptors; side by side on two cores,
  :func:`both_starts`), keeping the functional map's start only where
  its map is better by every measure there is: a higher kernel energy, a
  higher orientation agreement (:func:`orientation_agreement`) and a lower
  geodesic distortion. Each alone is blind somewhere (the energy to a
  reflection of a symmetric shape, the agreement to a small flipped part,
  the distortion to the detail of a non-isometric pair).
* ``smooth_k``: a last pointwise step, one ZoomOut step (Melzi et al.
  2019): the map is projected onto the first eigenfunctions and every vertex
  takes its nearest partner in them (no longer bijective, which suits
  independently remeshed shapes). The functional map of that step is the
  mean of the estimates from the map and from its reverse
  (:func:`~corrlib.geometry.fmaps.pointwise_from_basis`), so that the coarser shape's samples do not
  carry their partners' offsets into it. The step is repeated from its own
  maps while it moves fewer partners each time (ZoomOut's alternation at one
  basis size, :func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis`), except for a map
  refined from outside the solver. By default the basis is what the smallest
  kernel resolves, the eigenfunctions with ``τ_min λ · area ≤ 1``: finer
  ones it cannot tell apart, coarser ones would blur what it resolved.
* Unequal vertex counts: rectangular assignments are padded; with
  ``partial=True`` slack variables (Eq. 8.15–8.16) let low-scoring vertices
  stay unmatched (-1 in the maps, reported).

Map convention: ``map_xy[i]`` = vertex of Y matched to vertex i of X.
"""

from __future__ import annotations

import functools
from concurrent.futures import wait
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.sparse.csgraph import dijkstra

from corrlib.assignment import area_capacities, linear_assignment
from corrlib.cores import InlineExecutor, side_threads
from corrlib.descriptors import DESCRIPTOR_KINDS, mesh_descriptors
from corrlib.errors import Cancelled, CorrError, ParameterError
from corrlib.geometry.distortion import PairDistances, geodesic_distortions, inconsistent_parts
from corrlib.geometry.fmaps import (ZoomOutSamples, pointwise_from_basis, repeated_pointwise_from_basis,
                                    resolved_eigenpairs)
from corrlib.geometry.sampling import (
    SurfaceSample,
    farthest_point_sampling,
    outermost_farthest_points,
    surface_farthest_points,
    voronoi_bands,
    voronoi_cells,
)
from corrlib.geometry.lifting import MatchedCopy, lifted_maps, matched_copy
from corrlib.geometry.spectrum import Spectrum, mesh_spectra
from corrlib.methods.base import InitialMatch, MatchResult, param
from corrlib.methods.registry import MethodSpec, register
from corrlib.methods.reorientation import (can_reorient, declined_extras, mean_agreement, nearer_isometry,
                                           orientation_blocks, reorient, standardised, turned_anything,
                                           with_first_pass)
from corrlib.methods.resolution import keep_input_partners, kernel_width, nearest_partners, surplus_partners
from corrlib.progress import (CancelToken, LatestReport, Progress, Stopwatch, paired_progress, run,
                              scaled_progress)

#: seconds between checks of the caller's cancellation while one start waits for the other (:func:`both_starts`)
WAIT_POLL = 0.1
#: threads solving the cells of a refinement pass: the auction releases the GIL, so cells can overlap; two,
#: for the two-core development machine (every cell in flight also holds its dense score block)
CELL_THREADS = 2
#: cells per pass: enough that an average cell holds this fraction of ``max_cell`` (headroom: geodesic Voronoi
#: cells are uneven)
CELL_FILL = 0.7
#: pass ``p`` starts its farthest-point cell centres at the ``p × CENTRE_STRIDE``-th matched vertex farthest
#: from the centroid, so that every pass draws its cells around different centres (no border stays fixed)
CENTRE_STRIDE = 7
#: a DC step that lowers the objective by more than this fraction of it clears the ``monotone`` flag (the
#: auction is ε-optimal and the score is float32)
MONOTONE_RTOL = 1e-5
#: the finer scales' samples are farthest-point prefixes up to ``n_seed × growth ** FPS_SCALES`` vertices
#: (the first finer scales); the rest, only in the last dense scales, are ordered by distance from the centroid
FPS_SCALES = 2
#: DC iterations per time and refinement passes per scale of the second pass from a turned map
#: (:func:`reoptimised`): its start went through the whole schedule once already
SECOND_PASS_ITERATIONS = SECOND_PASS_PASSES = 1
#: progress bar layout (start, width): DC iterations on the seeds, then the finer scales (the final ZoomOut
#: step reports at :data:`PROGRESS_SMOOTHING`, after them)
PROGRESS_DC = (0.1, 0.6)
PROGRESS_MULTISCALE = (0.7, 0.27)
#: progress fractions of the initial-map computation and of the final smoothing step
PROGRESS_INIT, PROGRESS_SMOOTHING = 0.05, 0.98
#: the default eigenpairs per shape and smallest relative diffusion time (divergence-free's final steps use the
#: same, so that a pair's spectra are shared through the cache and the basis is the same)
DEFAULT_EIGENPAIRS = 500
#: the resolution that ``mesh_vertices`` suggests for finer meshes: 500 eigenpairs, of which the smallest default time
#: resolves about 160, are represented accurately on 5,000 vertices (the benchmarks' meshes have 4.3k-7.2k)
SUGGESTED_MESH_VERTICES = 5000
#: meshes above this many vertices get the suggestion of ``mesh_vertices`` in the progress messages: at full
#: resolution their pairs take minutes and gigabytes (see docs/decisions.md)
LARGE_MESH_VERTICES = 40_000
DEFAULT_TAU_MIN = 5.18e-4


@dataclass(frozen=True, kw_only=True)
class KernelMatchingParams:
    n_eigs: int = param(DEFAULT_EIGENPAIRS, label="Eigenpairs", low=10, high=3000,
                        help="Laplace–Beltrami eigenpairs of the heat kernels (spectral form).")
    init: str = param("best", label="Initialisation", choices=("best", "descriptors", "fmap"),
                      help="Both starts (\"best\"): a linear assignment on descriptors and the functional-maps "
                           "baseline's map, each solved to the end (side by side on two cores); the functional "
                           "map's start is kept only where its final map is better by kernel energy, "
                           "orientation agreement and geodesic distortion alike. Or one of the two alone "
                           "(\"descriptors\", \"fmap\"). A given map or landmarks can be passed to the solver "
                           "instead.")
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
    tau_min: float = param(DEFAULT_TAU_MIN, label="Smallest time / area", low=1e-8, high=10.0,
                           help="Last diffusion time divided by the surface area (10 at TOSCA scale).")
    n_times: int = param(10, label="Times", low=1, high=100, help="Log-spaced diffusion times.")
    times: str = param("", label="Explicit times / area",
                       help="Comma-separated relative times (decreasing) replacing the log-spaced schedule.")
    iters_per_time: int = param(2, label="Iterations per time", low=1, high=100,
                                help="DC iterations (linear assignments) per time; stops early when the "
                                     "map no longer changes.")
    n_seeds: int = param(2000, label="Seeds", low=10, high=100_000,
                         help="Farthest points of the surfaces (inside triangles too) matched first with the whole "
                              "schedule.")
    growth: float = param(3.0, label="Growth factor", low=1.5, high=100.0,
                          help="Sample growth per scale until every vertex is matched.")
    max_cell: int = param(1000, label="Max cell size", low=50, high=20_000,
                          help="Cell size at the finer scales: each pass uses enough Voronoi cells that an average "
                               "one holds 0.7 of it, and more where a cell would hold more than this many source "
                               "samples (the cells of farthest points are uneven on a shape with many limbs).")
    cell_overlap: float = param(0.1, label="Cell overlap", low=0.0, high=10.0,
                                help="Target cells are widened across their borders by about half this "
                                     "length (relative to √area) so that cells overlap; 0: disjoint cells.")
    passes: int = param(1, label="Passes per scale", low=1, high=20,
                        help="Refinement passes per finer scale, each with cells around new centres (each "
                             "further pass starts from the last one's matches, and drifts where the area "
                             "capacities are tight).")
    partial: bool = param(False, label="Partial matching",
                          help="Slack variables: vertices whose best score is low may stay unmatched.")
    slack_quantile: float = param(0.1, label="Slack quantile", low=0.0, high=1.0,
                                  help="With partial matching: the slack equals this quantile of the rows' "
                                       "best scores in each cell.")
    smooth_k: int = param(-1, label="Final ZoomOut basis", low=-1, high=3000,
                          help="Final pointwise steps: the map is projected onto this many eigenfunctions and "
                               "every vertex takes its nearest partner in them (ZoomOut steps on the mean "
                               "of the functional maps of the map and of its reverse, repeated while they move "
                               "fewer partners; removes the jitter a bijection forces between differently "
                               "sampled meshes). -1: the eigenfunctions the smallest kernel resolves "
                               "(τ λ·area ≤ 1); 0: off.")
    capacity: str = param("area", label="Finer-scale capacity", choices=("area", "one"),
                          help="Finer scales: a target sample may take as many source samples as its area "
                               "holds (measure-preserving; for differently meshed shapes) or exactly one "
                               "(a bijection within each cell; better for two meshes of the same connectivity).")
    reorient: bool = param(True, label="Turn a reversed map",
                           help="A final map that sends left to right on most of the shape (negative orientation "
                                "agreement) is composed with an intrinsic reflection (the target's or the source's, "
                                "the better) when that turns it, and a limb matched to the mirror-image limb is "
                                "turned when that fits its shoulder better (the kernel energy cannot tell either "
                                "apart); a turned map is then optimised once more. A final map made of two parts "
                                "whose geodesic distances disagree (one turned against the other) has each part "
                                "matched again from the other, and the result nearer an isometry is kept. Closed, "
                                "complete shapes only: a cut changes the reflection and the distances; at least 60 "
                                "eigenpairs.")
    mesh_vertices: int = param(0, label="Mesh vertices", low=0, high=10_000_000,
                               help="0: full resolution. Else a mesh with more than twice this many vertices is "
                                    f"matched on a copy remeshed to this many (e.g. {SUGGESTED_MESH_VERTICES}), and "
                                    "the map is carried to its own vertices by the final steps at full resolution "
                                    "in the copy's eigenfunctions: the smallest kernel resolves no finer detail, "
                                    "and the eigenpairs of a fine mesh take minutes. The copies are meshed "
                                    "differently, so a pair whose left and right are a close call can come out "
                                    "otherwise. Not with a given map or landmarks, which are refined at full "
                                    "resolution.")
    backend: str = param("auction", label="Assignment backend", choices=("auction", "scipy"),
                         help="ε-scaling auction (fast) or scipy's exact solver (slow, for checks).")

    def __post_init__(self):
        if isinstance(self.mesh_vertices, int) and isinstance(self.n_eigs, int) and \
                0 < self.mesh_vertices <= self.n_eigs:
            raise ParameterError(f"mesh_vertices must be 0 (full resolution) or more than the {self.n_eigs} "
                                 f"eigenpairs (n_eigs), got {self.mesh_vertices}")
        if isinstance(self.times, str) and isinstance(self.tau_min, (int, float)) and \
                isinstance(self.tau_max, (int, float)):
            try:
                _given_times(self)  # raises ParameterError on a bad schedule, before any run
            except ParameterError:
                raise
            except (TypeError, ValueError, OverflowError):
                pass  # a value of the wrong type or range: validate_params names the field


def _given_times(params: KernelMatchingParams) -> np.ndarray | None:
    """The relative times written out in ``times`` ((t,) float), or None for the geometric schedule.

    Checks what the per-field ranges cannot: the text of ``times``, and ``tau_min <= tau_max``. No
    arithmetic on the values, so that it can run before the ranges are validated.
    """
    if params.times.strip():
        try:
            taus = np.array([float(v) for v in params.times.replace(";", ",").split(",") if v.strip()])
        except ValueError:
            raise ParameterError(f"times must be comma-separated numbers, got {params.times!r}") from None
        if taus.size == 0 or not np.all(np.isfinite(taus)) or np.any(taus <= 0):
            raise ParameterError(f"times must be positive numbers, got {params.times!r}")
        if np.any(np.diff(taus) >= 0):  # the schedule goes from coarse to fine
            raise ParameterError(f"times must decrease (from the coarsest kernel to the finest), got {params.times!r}")
        return taus
    if params.tau_min > params.tau_max:
        raise ParameterError(f"tau_min ({params.tau_min}) must not exceed tau_max ({params.tau_max})")
    return None


def diffusion_times(params: KernelMatchingParams) -> np.ndarray:
    """(n_times,) float: relative times τ, decreasing."""
    taus = _given_times(params)
    if taus is not None:
        return taus
    return np.geomspace(params.tau_max, params.tau_min, params.n_times)


def kernel_energy(c: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray) -> float:
    """``<Π, K_Y Π K_X> = trace(D_Y C D_X Cᵀ)`` for ``C = Ψ[map]ᵀ Φ``."""
    return float(np.einsum("ij,i,ij,j->", c, decay_y, c, decay_x))


def _alignment(psi_rows, phi_rows):
    return psi_rows.T @ phi_rows


#: decays below this (relative to 1) are dropped from the spectral products: their terms are far below float32
#: precision, and e^{-tλ} of the high eigenvalues at large times would otherwise be float32 subnormals, on which
#: the products run an order of magnitude slower
DECAY_CUTOFF = 1e-12


def kernel_score(psi_rows, phi_cols, c, decay_y, decay_x):
    """(r, c) float32 kernel score block ``(Ψ_r D_Y) C (Φ_c D_X)ᵀ``.

    Only the eigenpairs with a decay above :data:`DECAY_CUTOFF` enter. Both products run in float32: the score
    is float32, and the auction resolves it only to that precision. The transposed block is
    ``kernel_score(phi_cols, psi_rows, c.T, decay_x, decay_y)``.
    """
    k_y = max(1, int(np.count_nonzero(decay_y > DECAY_CUTOFF)))
    k_x = max(1, int(np.count_nonzero(decay_x > DECAY_CUTOFF)))
    left = (psi_rows[:, :k_y] * decay_y[:k_y]).astype(np.float32) @ c[:k_y, :k_x].astype(np.float32)
    right = (phi_cols[:, :k_x] * decay_x[:k_x]).astype(np.float32)
    return left @ right.T


def _descriptor_similarity(f_rows: np.ndarray, f_cols: np.ndarray) -> np.ndarray:
    """(r, c) float32: negative squared descriptor distances between rows and columns, scaled to [-1, 0]."""
    fr32, fc32 = f_rows.astype(np.float32), f_cols.astype(np.float32)
    d2 = (fr32 ** 2).sum(1)[:, None] + (fc32 ** 2).sum(1)[None, :] - 2.0 * fr32 @ fc32.T
    return -d2 / max(float(d2.max()), 1e-30)


def _descriptors(source, target, spec_x, spec_y, kind: str):
    """Standardised descriptors of both shapes."""
    desc_x = mesh_descriptors(source, kind, spectrum=spec_x) if kind != "shot" else mesh_descriptors(source, kind)
    desc_y = mesh_descriptors(target, kind, spectrum=spec_y) if kind != "shot" else mesh_descriptors(target, kind)
    return standardised(desc_x, desc_y)


def _with_orientation(desc_x, desc_y, or_x, or_y, weight: float):
    """The descriptors with the standardised orientation blocks appended (total variance ``weight`` × theirs)."""
    if weight <= 0:
        return desc_x, desc_y
    scale = weight * np.sqrt(desc_x.shape[1] / or_x.shape[1])
    return np.hstack([desc_x, scale * or_x]), np.hstack([desc_y, scale * or_y])


def _sample_order(points: np.ndarray, n_seed: int, growth: float) -> np.ndarray:
    """Vertex order whose prefixes are the samples of the successive scales.

    Farthest-point order for the first ``n_seed × growth ** FPS_SCALES`` vertices (the
    first finer scales; the seeds themselves are surface points, see
    :func:`~corrlib.geometry.sampling.surface_farthest_points`); the rest
    follow ordered by their distance from the centroid (they only enter the
    last, dense scales).
    """
    n = points.shape[0]
    n_fps = int(min(n, n_seed * growth ** FPS_SCALES))
    radius = np.linalg.norm(points - points.mean(axis=0), axis=1)
    # the rest ordered by the distance from the centroid: the samples do not depend on the file's vertex order
    head = outermost_farthest_points(points, n_fps)
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
        g = kernel_score(phi[xs], psi[ys], c.T, decay_x, decay_y)  # (xs, ys)
        slack = None
        if params.partial:
            slack = float(np.quantile(g.max(axis=1), params.slack_quantile))
        cap = None if capacity_y is None else capacity_y[ys]
        return g, linear_assignment(g, slack=slack, method=params.backend, cancel=cancel, capacity=cap)

    map_x = []
    # reverse map, merged over overlapping cells: an assigned source beats an unassigned one, then the score
    rank_y = np.full((n_y, 2), -np.inf)
    map_yx = -np.ones(n_y, dtype=np.int64)
    with side_threads(CELL_THREADS) as pool:
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


# ---- the objective on the seeds and one DC step ---------------------------------------------------------------


@dataclass(frozen=True)
class SeedProblem:
    """The quadratic assignment on the seeds, without its diffusion time.

    Attributes
    ----------
    phi_s : (n_seed, k) float
        Source eigenfunctions Φ at the source seeds.
    psi_s : (n_seed, k) float
        Target eigenfunctions Ψ at the target seeds.
    anchor_c : (k, k) float or 0.0
        Alignment ``Ψ[anchors_y]ᵀ Φ[anchors_x]`` of fixed matches (landmarks), added to every ``C``.
    desc_block : (n_seed, n_seed) float32 or None
        Descriptor similarity ``F_Y F_Xᵀ`` as (seed x, seed y), scaled to [-1, 0]; None without μ term.
    mu : float
        Weight μ of the descriptor term.
    free_x, free_y : (f,) int and (g,) int, or None
        With landmarks: the x seeds the assignments place (the others are fixed at a landmark's partner,
        :func:`fixed_seeds`) and the y seeds not taken by a fixed one, ``f ≤ g``; None: every seed.
    """

    phi_s: np.ndarray
    psi_s: np.ndarray
    anchor_c: np.ndarray | float
    desc_block: np.ndarray | None
    mu: float
    free_x: np.ndarray | None = None
    free_y: np.ndarray | None = None

    @functools.cached_property
    def free_blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``Φ_s``, ``Ψ_s`` and the descriptor block on the free seeds only (the assignment's rows and
        columns), formed once per problem: the whole problem's arrays when every seed is free."""
        if self.free_x is None:
            return self.phi_s, self.psi_s, self.desc_block
        desc = None if self.desc_block is None else self.desc_block[np.ix_(self.free_x, self.free_y)]
        return self.phi_s[self.free_x], self.psi_s[self.free_y], desc

    @functools.cached_property
    def free_column(self) -> np.ndarray | None:
        """(n_seed,) int: the assignment column of every y seed that is free, -1 for the others; None when every
        seed is free (the column is the seed)."""
        if self.free_y is None:
            return None
        column = np.full(self.psi_s.shape[0], -1, dtype=np.int64)
        column[self.free_y] = np.arange(self.free_y.size)
        return column

    @property
    def n_columns(self) -> int:
        """Columns of the seed assignment (the size of its auction prices)."""
        return self.psi_s.shape[0] if self.free_y is None else self.free_y.size


def free_assignment(problem: SeedProblem, seed_map: np.ndarray, score: np.ndarray, **auction) -> np.ndarray:
    """(n_seed,) int: ``seed_map`` with its free seeds placed by one linear assignment on ``score`` (free x seeds,
    free y seeds), :func:`~corrlib.assignment.linear_assignment` with ``auction``'s arguments; the whole map
    when every seed is free."""
    warm = warm_columns(problem, seed_map)
    if problem.free_x is None:
        return linear_assignment(score, warm_map=warm, **auction)
    placed = seed_map.copy()
    if problem.free_x.size:
        placed[problem.free_x] = problem.free_y[linear_assignment(score, warm_map=warm, **auction)]
    return placed


def warm_columns(problem: SeedProblem, seed_map: np.ndarray) -> np.ndarray | None:
    """The columns of the seed assignment that ``seed_map`` (n_seed,) gives its free seeds, if that is a
    permutation of them (the warm start of the next auction, see
    :func:`~corrlib.assignment.linear_assignment`'s ``warm_map``); None otherwise (e.g. a given map that sends
    seeds together)."""
    columns = seed_map if problem.free_x is None else problem.free_column[seed_map[problem.free_x]]
    if columns.size != problem.n_columns or not np.array_equal(np.sort(columns), np.arange(columns.size)):
        return None
    return columns


def seed_alignment(problem: SeedProblem, seed_map: np.ndarray) -> np.ndarray:
    """(k, k) float: ``C = Ψ_s[seed_map]ᵀ Φ_s + C_anchors``, the spectral form of Π (and the anchors)."""
    return _alignment(problem.psi_s[seed_map], problem.phi_s) + problem.anchor_c


def updated_alignment(problem: SeedProblem, c: np.ndarray, old_map: np.ndarray, new_map: np.ndarray) -> np.ndarray:
    """(k, k) float: :func:`seed_alignment` of ``new_map`` from ``c``, that of ``old_map`` (both (n_seed,)).

    ``C`` is a sum over the seeds, so only the changed seeds' terms are exchanged:
    ``C' = C + (Ψ_s[new_map[ch]] − Ψ_s[old_map[ch]])ᵀ Φ_s[ch]``, at a cost proportional to the changed seeds (the
    later DC steps change a few per cent). Where half or more changed, ``C'`` is formed afresh. Equal to the
    direct product up to round-off.
    """
    changed = np.flatnonzero(new_map != old_map)
    if changed.size == 0:
        return c
    if 2 * changed.size >= new_map.size:
        return seed_alignment(problem, new_map)
    return c + _alignment(problem.psi_s[new_map[changed]] - problem.psi_s[old_map[changed]], problem.phi_s[changed])


def dc_objective(seed_map: np.ndarray, c: np.ndarray, kernel_scale: float, decay_y: np.ndarray,
                 decay_x: np.ndarray, desc_block: np.ndarray | None = None, mu: float = 0.0) -> float:
    """The function the DC steps of one time maximise.

    ``f(Π) = ½ <Π, K_Y Π K_X> / s + μ <Π, F_Y F_Xᵀ>``, the kernel term in spectral form
    ``<Π, K_Y Π K_X> = trace(D_Y C D_X Cᵀ)`` (:func:`kernel_energy`) and ``s`` a constant of the time (the
    kernel score's maximum, see :func:`seed_score`). The ½ makes ``K_Y Π K_X / s`` its exact gradient.

    Parameters
    ----------
    seed_map : (n_seed,) int
        Seed x -> seed y (Π).
    c : (k, k) float
        ``Ψ_s[seed_map]ᵀ Φ_s`` (plus the anchors), see :func:`seed_alignment`.
    kernel_scale : float
        ``s``.
    decay_y, decay_x : (k,) float
        ``e^{-tΛ_Y}``, ``e^{-tΛ_X}``.
    desc_block : (n_seed, n_seed) float32, optional
        ``F_Y F_Xᵀ`` as (seed x, seed y); None: no descriptor term.
    mu : float
        μ.
    """
    value = 0.5 * kernel_energy(c, decay_y, decay_x) / kernel_scale
    if desc_block is not None:
        value += mu * float(desc_block[np.arange(seed_map.size), seed_map].sum())
    return value


def seed_score(phi_s: np.ndarray, psi_s: np.ndarray, c: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray,
               kernel_scale: float | None = None, desc_block: np.ndarray | None = None,
               mu: float = 0.0) -> tuple[np.ndarray, float]:
    """The linearisation (Eq. 8.13) of :func:`dc_objective` on the seeds, as an assignment score.

    ``G = (K_Y Π K_X)ᵀ / s + μ (F_Y F_Xᵀ)ᵀ``, rows the x seeds, formed in spectral form as
    ``(Φ_s D_X) Cᵀ (Ψ_s D_Y)ᵀ / s + μ desc_block`` (:func:`kernel_score`, float32).

    Parameters
    ----------
    phi_s, psi_s : (n_seed, k) float
        Eigenfunctions at the source and target seeds.
    c : (k, k) float
        Current alignment ``C``.
    decay_y, decay_x : (k,) float
        ``e^{-tΛ_Y}``, ``e^{-tΛ_X}``.
    kernel_scale : float, optional
        ``s``; None: the kernel term's own largest magnitude.
    desc_block : (n_seed, n_seed) float32, optional
        ``F`` as (seed x, seed y); None: the kernel term alone, unscaled.
    mu : float
        μ.

    Returns
    -------
    g : (n_seed, n_seed) float32
        Score (seed x, seed y).
    kernel_scale : float
        ``s`` (as given, or the one found).
    """
    g = kernel_score(phi_s, psi_s, c.T, decay_x, decay_y)  # the assignment's rows are the x seeds
    if kernel_scale is None:
        kernel_scale = max(float(np.abs(g).max(initial=0.0)), 1e-30)
    if desc_block is not None:
        g = g / np.float32(kernel_scale) + np.float32(mu) * desc_block
    return g, kernel_scale


@dataclass(frozen=True)
class DCStep:
    """One DC step: the new map, its alignment ``C`` (:func:`seed_alignment`) and the objective before and after
    (same ``kernel_scale``)."""

    seed_map: np.ndarray
    before: float
    value: float
    changed: int
    kernel_scale: float
    from_permutation: bool
    alignment: np.ndarray

    @property
    def decreased(self) -> bool:
        """The objective fell (beyond :data:`MONOTONE_RTOL`) from a permutation, against the DC guarantee."""
        return self.from_permutation and self.value < self.before - MONOTONE_RTOL * abs(self.before)


def dc_step(problem: SeedProblem, seed_map: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray,
            kernel_scale: float | None = None, *, prices: np.ndarray | None = None,
            eps_start: float | None = None, backend: str = "auction", cancel: np.ndarray | None = None,
            watch: Stopwatch | None = None, alignment: np.ndarray | None = None) -> DCStep:
    """One DC step (Eq. 8.13): ``Π_{k+1} = argmax_Π <Π, ∇f(Π_k)>``, one linear assignment on :func:`seed_score`.

    ``f`` (:func:`dc_objective`) is convex, so ``f(Π_{k+1}) ≥ f(Π_k) + <Π_{k+1} - Π_k, ∇f(Π_k)> ≥ f(Π_k)``
    when ``Π_k`` is a permutation (the assignment's optimum is at least the score of ``Π_k`` itself). With
    seeds fixed by landmarks, the assignment places the free seeds only (:attr:`SeedProblem.free_blocks`): the
    maximum over the permutations that keep the fixed ones, among which ``Π_k`` is, so the same holds.

    Parameters
    ----------
    seed_map : (n_seed,) int
        ``Π_k``, seed x -> seed y.
    kernel_scale : float, optional
        ``s`` of the time; None: from this step's score.
    prices : (n_columns,) float, optional
        The auction's prices (warm start, :attr:`SeedProblem.n_columns`), updated in place.
    eps_start : float, optional
        The auction's first ε.
    alignment : (k, k) float, optional
        ``C`` of ``seed_map`` if known (the previous step's :attr:`DCStep.alignment`); None: formed here.
    """
    watch = Stopwatch() if watch is None else watch
    with watch("kernels"):
        c = seed_alignment(problem, seed_map) if alignment is None else alignment
        phi_rows, psi_cols, desc = problem.free_blocks
        g, kernel_scale = seed_score(phi_rows, psi_cols, c, decay_y, decay_x, kernel_scale, desc, problem.mu)
        before = dc_objective(seed_map, c, kernel_scale, decay_y, decay_x, problem.desc_block, problem.mu)
    with watch("assignment"):
        new_map = free_assignment(problem, seed_map, g, method=backend, cancel=cancel, prices=prices,
                                  eps_start=eps_start)
    changed = int(np.sum(new_map != seed_map))
    with watch("kernels"):
        c_new = updated_alignment(problem, c, seed_map, new_map)
    value = dc_objective(new_map, c_new, kernel_scale, decay_y, decay_x, problem.desc_block, problem.mu)
    # the DC guarantee holds from a permutation (a given initial map may map seeds together)
    from_permutation = np.unique(seed_map).size == seed_map.size
    return DCStep(new_map, before, value, changed, kernel_scale, from_permutation, c_new)


def heat_decays(evals: np.ndarray, area: float, tau: float) -> np.ndarray:
    """(k,) float: ``e^{-tλ}`` at the time ``t = τ · area`` (relative times make the kernel scale-invariant)."""
    return np.exp(-tau * area * evals)


def most_similar_matches(confidence: np.ndarray, fraction: float) -> np.ndarray:
    """Indices of the ``max(1, round(fraction · n))`` matches with the highest ``confidence`` (n,), best first."""
    return np.argsort(-confidence, kind="stable")[:max(1, round(fraction * confidence.size))]


# ---- the state the stages share -------------------------------------------------------------------------------


@dataclass(eq=False)
class KernelState:
    """What the stages of :func:`kernel_matching` share.

    Set by :func:`prepare`: the inputs, the spectra (Φ = ``spec_x.evecs`` (n_x, k), Ψ = ``spec_y.evecs``
    (n_y, k)), the relative times ``taus`` (n_times,), the surface seeds and the sample orders (n_x,), (n_y,)
    of the finer scales. Then, stage by stage: the anchors and the initial ``seed_map`` (n_seed,) with its
    descriptor ``confidence``, the :class:`SeedProblem`, the current ``seed_map`` with its auction
    ``prices``, the ``trace`` of the DC iterations (one dict per iteration), the ``monotone`` flag and the
    start that won.
    """

    source: object
    target: object
    params: KernelMatchingParams
    token: object
    watch: Stopwatch
    taus: np.ndarray
    spec_x: Spectrum
    spec_y: Spectrum
    seeds_x: SurfaceSample
    seeds_y: SurfaceSample
    order_x: np.ndarray
    order_y: np.ndarray
    n_seed: int
    anchors_x: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    anchors_y: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    landmarks_only: bool = False
    descriptor_start: bool = False  # a given map competes with the descriptor assignment (the second start)
    refined_map: tuple | None = None  # the dense map being refined, as (source, target) vertex pairs
    outside_map: bool = False  # that map came from outside the solver (the caller's, init="fmap"), not a first pass
    orientation: tuple | None = None  # standardised orientation-aware descriptors of both shapes, once computed
    desc_x: np.ndarray | None = None  # standardised plain descriptors, once computed
    desc_y: np.ndarray | None = None
    seed_similarity: np.ndarray | None = None  # (n_seed, n_seed) the seeds' plain descriptor similarity, once computed
    confidence: np.ndarray | None = None  # (n_seed,) similarity of every initial descriptor match
    seed_map: np.ndarray | None = None  # (n_seed,) seed x -> seed y
    free_x: np.ndarray | None = None  # with landmarks: the seeds the assignments place (:func:`fixed_seeds`)
    free_y: np.ndarray | None = None
    problem: SeedProblem | None = None
    prices: np.ndarray | None = None
    trace: list = field(default_factory=list)
    monotone: bool = True
    dc_start: str = "initial map"
    start_alignment: np.ndarray | None = None  # C of the seed map the first time's DC iterations ended with
    step: int = 0  # DC iterations counted for the progress bar
    seed_vertices_x: np.ndarray | None = None  # the seeds' matches snapped to vertices (reported)
    seed_vertices_y: np.ndarray | None = None
    # the final map as it was before the orientation stage turned regions or parts or released limbs (after a
    # whole-map turn, if any), (map_xy, map_yx): the alternative a second pass must beat (:func:`reoptimised`)
    before_partial_turns: tuple | None = None
    distances: PairDistances | None = None  # the pair's edge-path distances for the judges of maps, once computed

    def prepared(self) -> "KernelState":
        """A state as :func:`prepare` left it (spectra, times, seeds, sample orders), with the descriptors (plain
        and orientation-aware, and the seeds' similarity) kept once computed: they depend on the shapes and the
        seeds only. Every later stage's field at its default."""
        fresh = KernelState(self.source, self.target, self.params, self.token, self.watch, self.taus, self.spec_x,
                            self.spec_y, self.seeds_x, self.seeds_y, self.order_x, self.order_y, self.n_seed)
        fresh.orientation = self.orientation
        fresh.desc_x, fresh.desc_y, fresh.seed_similarity = self.desc_x, self.desc_y, self.seed_similarity
        fresh.distances = self.pair_distances()
        return fresh

    def pair_distances(self) -> PairDistances:
        """The pair's :class:`~corrlib.geometry.distortion.PairDistances` (created once, shared by the states
        :meth:`prepared` makes, so that every judge of a map measures it once)."""
        if self.distances is None:
            self.distances = PairDistances(self.source, self.target)
        return self.distances

    def descriptors(self) -> tuple[np.ndarray, np.ndarray]:
        """The standardised plain descriptors of both shapes, (n_x, d) and (n_y, d) (computed once)."""
        if self.desc_x is None:
            with self.watch("descriptors"):
                self.desc_x, self.desc_y = _descriptors(self.source, self.target, self.spec_x, self.spec_y,
                                                        self.params.descriptor)
        return self.desc_x, self.desc_y

    def seed_descriptor_similarity(self) -> np.ndarray:
        """The seeds' plain descriptor similarity (n_seed, n_seed), computed once."""
        if self.seed_similarity is None:
            desc_x, desc_y = self.descriptors()
            self.seed_similarity = _descriptor_similarity(self.seeds_x.interpolate(self.source, desc_x),
                                                          self.seeds_y.interpolate(self.target, desc_y))
        return self.seed_similarity

    def orientation_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """The standardised orientation-aware descriptors (computed once: initial assignment and result)."""
        if self.orientation is None:
            self.orientation = orientation_blocks(self.source, self.target, self.spec_x, self.spec_y)
        return self.orientation

    @property
    def n_x(self) -> int:
        return self.source.n_vertices

    @property
    def n_y(self) -> int:
        return self.target.n_vertices

    @property
    def k(self) -> int:
        return self.params.n_eigs

    @property
    def phi(self) -> np.ndarray:
        return self.spec_x.evecs

    @property
    def psi(self) -> np.ndarray:
        return self.spec_y.evecs

    @property
    def cancel(self) -> np.ndarray:
        return self.token.flag

    @property
    def has_second_start(self) -> bool:
        """A descriptor initialisation with ``init_fraction < 1``, or a given map that competes with the
        descriptor assignment (landmarks have one start, :func:`choose_start`)."""
        return (self.confidence is not None and self.params.init_fraction < 1) or self.descriptor_start

    @property
    def total_steps(self) -> int:
        return (len(self.taus) + self.has_second_start) * self.params.iters_per_time

    def decays(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """``(e^{-tΛ_Y}, e^{-tΛ_X})`` at the relative time ``tau``, each (k,)."""
        return heat_decays(self.spec_y.evals, self.target.area, tau), \
            heat_decays(self.spec_x.evals, self.source.area, tau)


# ---- stages ---------------------------------------------------------------------------------------------------


def prepare(source, target, params: KernelMatchingParams, token):
    """Stage 1: spectra (k eigenpairs per shape), relative times, surface seeds, sample orders.

    A generator (yields :class:`Progress`); returns a :class:`KernelState`. The seeds are
    ``min(n_seeds, n_x, n_y)`` farthest points of each surface; the finer scales' samples are prefixes of
    :func:`_sample_order`.
    """
    watch = Stopwatch()
    n_x, n_y = source.n_vertices, target.n_vertices
    for mesh in (source, target):
        if params.n_eigs >= mesh.n_vertices:
            raise ParameterError(f"{params.n_eigs} eigenpairs requested but {mesh.name} has only "
                                 f"{mesh.n_vertices} vertices (lower n_eigs)")
    k = params.n_eigs
    taus = diffusion_times(params)
    n_seed = min(params.n_seeds, n_x, n_y)

    def samples(mesh):  # the greedy farthest points release the GIL: one shape per thread
        return surface_farthest_points(mesh, n_seed), _sample_order(mesh.vertices, n_seed, params.growth)

    yield Progress("eigenpairs", 0.0, f"{k} eigenpairs per shape")
    # the samples need the geometry only: they are drawn beside the eigensolvers, on the core that the first
    # of the two decompositions to finish leaves idle (in a pool's worker with one core: before them)
    with side_threads(2) as pool:
        with watch("sampling"):  # a thread's start; inline, the samples themselves
            sampled = [pool.submit(samples, mesh) for mesh in (source, target)]
        with watch("eigen"):
            spec_x, spec_y = mesh_spectra((source, target), k)
        with watch("sampling"):
            (seeds_x, order_x), (seeds_y, order_y) = (future.result() for future in sampled)
    token.raise_if_cancelled()
    return KernelState(source, target, params, token, watch, taus, spec_x, spec_y, seeds_x, seeds_y,
                       order_x, order_y, n_seed)


def initial_seed_map(state: KernelState, initial: InitialMatch | None, compete: bool = True):
    """Stage 2: the seeds' initial assignment (sets ``seed_map``, and ``confidence`` or the anchors).

    A given map or landmarks: every source seed follows its nearest matched vertex, whose partner snaps to
    the nearest target seed (landmarks also become anchors). A given map competes with the method's own
    start, the descriptor assignment (``compete``; :func:`aligned_start`, :func:`choose_start`): a map given
    to be refined can be far worse than that start (a nearest-neighbour map of a non-isometric pair, 0.64
    √area), and its refinement then stays in a wrong basin. ``init="fmap"``: the same from the
    functional-maps baseline's map. Otherwise one linear assignment on the descriptor similarity
    (:func:`_descriptor_similarity`, with the orientation block), whose row values are the ``confidence``.
    A generator (yields :class:`Progress`).
    """
    params, source, target = state.params, state.source, state.target
    if initial is not None:
        ix, iy = initial.pairs(state.n_x, state.n_y)
        state.landmarks_only = initial.map_xy is None
        if state.landmarks_only:
            state.anchors_x, state.anchors_y = ix, iy
        yield Progress("initial map", PROGRESS_DC[0], f"{ix.size} given matches")
        if not state.landmarks_only:
            state.refined_map = (ix, iy)
            state.descriptor_start = state.outside_map = compete
        partner_of = -np.ones(state.n_x, dtype=np.int64)
        partner_of[ix] = iy
        if state.landmarks_only:
            state.seed_map, state.free_x, state.free_y = fixed_seeds(state, partner_of)
        else:
            partner = partner_of[ix[_nearest_point(source.vertices[ix], state.seeds_x.points)]]
            state.seed_map = _nearest_point(state.seeds_y.points, target.vertices[partner])
    elif params.init == "fmap":
        from corrlib.methods.baselines import FmapZoomOutParams, solve_fmap_zoomout

        yield Progress("initial map", PROGRESS_INIT, "functional maps + ZoomOut")
        with state.watch("init"):
            fm = run(solve_fmap_zoomout(source, target, FmapZoomOutParams(), state.token))
        state.refined_map, state.outside_map = (np.arange(state.n_x), fm.map_xy), True
        partner = fm.map_xy[state.seeds_x.nearest_corners(source)]
        state.seed_map = _nearest_point(state.seeds_y.points, target.vertices[partner])
    else:
        yield Progress("descriptors", PROGRESS_INIT, params.descriptor)
        state.descriptors()
        state.seed_map, state.confidence = descriptor_assignment(state, state.watch)
    state.token.raise_if_cancelled()


def fixed_seeds(state: KernelState, partner_of: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeds that landmarks fix: every x seed whose nearest vertex is a landmark is matched to the y seed
    nearest to that landmark's partner (of several x seeds that snap to one y seed, the first keeps it).

    Landmarks stay matched (:class:`~corrlib.methods.base.InitialMatch`), so the assignments only place the
    other seeds, on the y seeds the fixed ones leave (the placed seeds of a release pass are the released
    limbs: the problem shrinks to them).

    Parameters
    ----------
    partner_of : (n_x,) int
        The landmark partner of every source vertex, -1 where it is no landmark.

    Returns
    -------
    seed_map : (n_seed,) int
        The fixed seeds' partners, -1 for the free ones.
    free_x, free_y : (f,) int
        The free x seeds and the y seeds no fixed seed takes (as many).
    """
    source, target = state.source, state.target
    partner = partner_of[state.seeds_x.nearest_corners(source)]
    fixed = np.flatnonzero(partner >= 0)
    snapped = _nearest_point(state.seeds_y.points, target.vertices[partner[fixed]])
    _, first = np.unique(snapped, return_index=True)
    seed_map = -np.ones(state.n_seed, dtype=np.int64)
    seed_map[fixed[first]] = snapped[first]
    taken = np.zeros(state.n_seed, dtype=bool)
    taken[seed_map[seed_map >= 0]] = True
    return seed_map, np.flatnonzero(seed_map < 0), np.flatnonzero(~taken)


def seed_problem(state: KernelState) -> SeedProblem:
    """Stage 3: the :class:`SeedProblem` — eigenfunctions interpolated at the seeds, ``F_Y F_Xᵀ`` of the plain
    descriptor (the orientation block only decides the initial orientation), the anchors' ``C``."""
    params, source, target = state.params, state.source, state.target
    psi_s = state.seeds_y.interpolate(target, state.psi)
    phi_s = state.seeds_x.interpolate(source, state.phi)
    desc_block = state.seed_descriptor_similarity() if params.mu > 0 else None  # (seed x, seed y)
    anchor_c = _alignment(state.psi[state.anchors_y], state.phi[state.anchors_x]) if state.anchors_x.size else 0.0
    state.problem = SeedProblem(phi_s, psi_s, anchor_c, desc_block, params.mu, state.free_x, state.free_y)
    return state.problem


@dataclass(frozen=True)
class DCRun:
    """DC iterations at one time: the last map and its alignment ``C``, the time's kernel scale, one trace
    entry per iteration and the last objective."""

    seed_map: np.ndarray
    kernel_scale: float
    entries: list
    value: float | None
    alignment: np.ndarray | None = None


def dc_iterations(state: KernelState, seed_map: np.ndarray, prices: np.ndarray, t_index: int,
                  kernel_scale: float | None = None, alignment: np.ndarray | None = None):
    """Stage 5: up to ``iters_per_time`` :func:`dc_step` at the time ``taus[t_index]``; stops when the map
    no longer changes.

    A generator (yields :class:`Progress`); returns a :class:`DCRun`. ``prices`` (the auction's warm start) is
    updated in place (each auction's first ε follows from how far they are from ``seed_map``'s score,
    :func:`warm_columns`); ``kernel_scale`` None: set from the first score; ``alignment``: ``C`` of ``seed_map`` if
    known (it does not depend on the time, so it is carried from one time to the next). Clears
    ``state.monotone`` if a step lowers the objective.
    """
    params = state.params
    tau = state.taus[t_index]
    decay_y, decay_x = state.decays(tau)
    entries, value = [], None
    for it in range(params.iters_per_time):
        state.token.raise_if_cancelled()
        step = dc_step(state.problem, seed_map, decay_y, decay_x, kernel_scale, prices=prices, backend=params.backend,
                       cancel=state.cancel, watch=state.watch, alignment=alignment)
        kernel_scale, value, seed_map, alignment = step.kernel_scale, step.value, step.seed_map, step.alignment
        if step.decreased:
            state.monotone = False
        entries.append({"tau": float(tau), "iteration": it, "energy": value, "changed": step.changed})
        state.step += 1
        yield Progress("kernel matching", PROGRESS_DC[0] + PROGRESS_DC[1] * state.step / state.total_steps,
                       f"time {t_index + 1}/{len(state.taus)}, iteration {it + 1}: energy {value:.6g}, "
                       f"{step.changed} changed")
        if step.changed == 0:
            state.step += params.iters_per_time - it - 1
            break
    return DCRun(seed_map, kernel_scale, entries, value, alignment)


def aligned_start(state: KernelState, start_map: np.ndarray, watch: Stopwatch) -> tuple[np.ndarray, np.ndarray]:
    """The second start: one assignment on the kernel score at the largest time of only the most similar
    initial matches (``init_fraction`` of them; with landmarks: the anchors alone), i.e. ``G`` of
    :func:`seed_score` with ``C = Ψ_s[start_map[keep]]ᵀ Φ_s[keep] + C_anchors``.

    A given map's second start is instead the descriptor assignment of the descriptor initialisation
    (:func:`descriptor_assignment`).

    Reads ``state`` only (it runs on a thread beside the first start's DC iterations) and times itself on
    ``watch``. Returns the start map (n_seed,) and its auction prices (:attr:`SeedProblem.n_columns`,).
    With landmarks it is the only start (:func:`choose_start`) and places the free seeds only.
    """
    if state.descriptor_start:
        return descriptor_assignment(state, watch)[0], np.zeros(state.n_seed)
    problem = state.problem
    keep = np.zeros(0, dtype=np.int64) if state.landmarks_only else \
        most_similar_matches(state.confidence, state.params.init_fraction)
    with watch("kernels"):
        c = _alignment(problem.psi_s[start_map[keep]], problem.phi_s[keep]) + problem.anchor_c
        phi_rows, psi_cols, desc = problem.free_blocks
        g, _ = seed_score(phi_rows, psi_cols, c, *state.decays(state.taus[0]), None, desc, problem.mu)
    prices = np.zeros(problem.n_columns)
    with watch("assignment"):
        other_start = free_assignment(problem, start_map, g, method=state.params.backend, cancel=state.cancel,
                                      prices=prices)
    return other_start, prices


def descriptor_assignment(state: KernelState, watch: Stopwatch) -> tuple[np.ndarray, np.ndarray]:
    """The descriptor initialisation's start: one linear assignment of the seeds on the similarity of their
    descriptors with the orientation block (:func:`_descriptor_similarity`). Returns the seed map (n_seed,)
    and every match's similarity (n_seed,). Reads ``state`` only (the descriptors of :func:`seed_problem` when
    it computed them)."""
    params, source, target = state.params, state.source, state.target
    with watch("descriptors"):
        desc_x, desc_y = (state.desc_x, state.desc_y) if state.desc_x is not None else \
            _descriptors(source, target, state.spec_x, state.spec_y, params.descriptor)
        init_x, init_y = _with_orientation(desc_x, desc_y, *state.orientation_blocks(), params.orientation)
    with watch("assignment"):
        sim = _descriptor_similarity(state.seeds_x.interpolate(source, init_x),
                                     state.seeds_y.interpolate(target, init_y))
        seed_map = linear_assignment(sim, method=params.backend, cancel=state.cancel)
    return seed_map, sim[np.arange(state.n_seed), seed_map]


def choose_start(state: KernelState):
    """Stage 4: DC iterations of the first time from the initial map and (descriptor initialisation, or a
    given map) from the :func:`aligned_start`; the start with the higher :func:`dc_objective` goes on (both at
    the first start's kernel scale). A generator; sets ``seed_map``, ``prices``, ``dc_start``.

    The aligned start's score and assignment do not depend on the first start's iterations, so they run on
    a thread beside them (the auctions release the GIL; two cores each take one); their time is reported
    as ``"second start (concurrent)"``. A pool's worker with one core's share runs them first instead
    (:func:`~corrlib.cores.side_threads`), reported as ``"second start"``.

    Landmarks have the aligned start only (the kernel score of the landmarks alone): the seeds they do not fix
    have no partner of their own to start from (:func:`fixed_seeds`).
    """
    if state.landmarks_only:
        yield Progress("initial alignment", PROGRESS_DC[0], f"kernel score of the {state.anchors_x.size} landmarks")
        start_map, prices = aligned_start(state, state.seed_map, state.watch)
        best = yield from dc_iterations(state, start_map, prices, 0, None)
        dc_start = "initial alignment"
    else:
        best, prices, dc_start = yield from _better_of_two_starts(state)
    state.seed_map, state.prices, state.dc_start = best.seed_map, prices, dc_start
    state.start_alignment = best.alignment
    state.trace.extend(best.entries)


def _better_of_two_starts(state: KernelState):
    """:func:`choose_start` without landmarks: the initial map's first time and, beside it, the
    :func:`aligned_start`'s; returns the better :class:`DCRun`, its auction prices and the start's name."""
    prices = np.zeros(state.problem.n_columns)  # auction prices carried from one assignment to the next
    start_map = state.seed_map
    with side_threads(1) as pool:
        second_watch = Stopwatch()
        second = pool.submit(aligned_start, state, start_map, second_watch) if state.has_second_start else None
        best = yield from dc_iterations(state, start_map, prices, 0, None)
        dc_start = "initial map"
        if second is not None:
            what = ("descriptor assignment, against the given map" if state.descriptor_start else
                    f"kernel score of the most similar {state.params.init_fraction:.0%} of the initial matches")
            yield Progress("initial alignment", PROGRESS_DC[0] + PROGRESS_DC[1] * state.step / state.total_steps, what)
            other_start, other_prices = second.result()
            concurrent = not isinstance(pool, InlineExecutor)
            state.watch.times["second start (concurrent)" if concurrent else "second start"] = \
                sum(second_watch.times.values())
            other = yield from dc_iterations(state, other_start, other_prices, 0, best.kernel_scale)
            if other.value > best.value:
                best, prices = other, other_prices
                dc_start = "descriptors" if state.descriptor_start else "initial alignment"
    return best, prices, dc_start


def cell_centres(vertices: np.ndarray, matched_x: np.ndarray, matched_y: np.ndarray, n_cells: int,
                 pass_index: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the cells of one pass: farthest points among the matched source vertices.

    The farthest-point set starts at the ``pass_index × CENTRE_STRIDE``-th matched vertex farthest from their
    centroid, so every pass draws different centres; centres are made distinct on both sides (seeds
    snapped to their vertices may share one).

    Returns
    -------
    centres_x, centres_y : (c,) int
        Source vertices and their matched target vertices, ``c ≤ n_cells``.
    """
    matched_pts = vertices[matched_x]
    radius = np.linalg.norm(matched_pts - matched_pts.mean(axis=0), axis=1)
    start = int(np.argsort(-radius, kind="stable")[min(pass_index * CENTRE_STRIDE, radius.size - 1)])
    centres_pos = farthest_point_sampling(matched_pts, min(n_cells, matched_x.size), start=start)
    _, first_x = np.unique(matched_x[centres_pos], return_index=True)
    centres_pos = centres_pos[np.sort(first_x)]
    _, first_y = np.unique(matched_y[centres_pos], return_index=True)
    centres_pos = centres_pos[np.sort(first_y)]
    return matched_x[centres_pos], matched_y[centres_pos]


def split_large_cells(source, centres_x: np.ndarray, centres_y: np.ndarray, matched_x: np.ndarray,
                      matched_y: np.ndarray, x_idx: np.ndarray, max_cell: int) -> tuple[np.ndarray, np.ndarray]:
    """More centres until no geodesic Voronoi cell holds more than ``max_cell`` of the sample ``x_idx``: the
    largest cell gets a new centre at its matched vertex farthest from its centre (a farthest-point step
    inside that cell).

    Farthest points of the whole shape go to its extremities first, so on a shape with many protrusions a
    few centres leave the trunk to one cell, and an assignment's cost grows faster than its
    size. Returns the centres with the added ones at the end, (c',) each, distinct on both sides.
    """
    centres_x, centres_y = list(centres_x), list(centres_y)
    while True:
        labels, distances = voronoi_cells(source, np.asarray(centres_x))
        sizes = np.bincount(labels[x_idx], minlength=len(centres_x))
        largest = int(np.argmax(sizes))
        if sizes[largest] <= max_cell:
            break
        inside = (labels[matched_x] == largest) & ~np.isin(matched_x, centres_x) & ~np.isin(matched_y, centres_y)
        if not inside.any():
            break
        far = np.flatnonzero(inside)[np.argmax(distances[matched_x[inside]])]
        centres_x.append(int(matched_x[far]))
        centres_y.append(int(matched_y[far]))
    return np.asarray(centres_x, dtype=np.int64), np.asarray(centres_y, dtype=np.int64)


def transferred_cells(source, target, centres_x, centres_y, x_idx, y_idx, overlap: float, matched_x, matched_y):
    """Geodesic Voronoi cells of the source sample ``x_idx`` around ``centres_x``, and their target cells.

    A target cell holds the Voronoi cell of the sample ``y_idx`` around the centre's image ``centres_y``, widened
    across its borders by about ``overlap × √area / 2``, and every target vertex within that width of the current
    partner of one of the source cell's rows (the partner of the row's nearest matched vertex, ``matched_x`` →
    ``matched_y``). The Voronoi cells of the two shapes are transferred through the centres only, and where the
    shapes differ in pose their borders part by more than the overlap (at a joint): a row near such a border would
    find no partner near its own in its target cell and take the best one anywhere in it. Through the current
    map every row can reach the neighbourhood of its partner. Returns two lists of index arrays, one entry per
    centre.
    """
    lab_x, _ = voronoi_cells(source, centres_x)
    margin = overlap * np.sqrt(target.area)
    _, band_y = voronoi_bands(target, centres_y, margin)  # each border widened by about margin / 2
    x_cells = [x_idx[lab_x[x_idx] == cid] for cid in range(centres_x.size)]
    partner = nearest_partners(source, matched_x, matched_y)
    in_y = np.zeros(target.n_vertices, dtype=bool)
    in_y[y_idx] = True
    y_cells = []
    for rows, members in zip(x_cells, band_y):
        partners = np.unique(partner[rows][partner[rows] >= 0])
        if partners.size:
            near = dijkstra(target.adjacency, directed=False, indices=partners, limit=margin / 2, min_only=True)
            members = np.union1d(members, np.flatnonzero(np.isfinite(near)))
        y_cells.append(members[in_y[members]])
    return x_cells, y_cells


def multiscale_refinement(state: KernelState):
    """Stage 6 (§8.3.2): grow the vertex sample by ``growth`` per scale until every vertex is included; at
    each scale run ``passes`` refinement passes, each solving Voronoi cells (:func:`cell_centres`,
    :func:`split_large_cells`, :func:`transferred_cells`, :func:`_solve_cells`) at the smallest time with all
    current matches as anchors.

    There is always at least one finer scale (the seeds are surface points); its first pass takes the seeds'
    matches (interpolated eigenfunctions) as anchors. Landmarks stay matched: their vertices and partners are
    left out of the cells (and the cells are centred on the other matches). The source sample grows to at
    most the target's vertex count (:func:`surplus_partners` places the rest). A generator; returns
    ``map_xy`` (n_x,) and ``map_yx`` (n_y,) of the last pass (-1: unmatched).
    """
    params, source, target, watch = state.params, state.source, state.target, state.watch
    n_x, n_y, psi, phi = state.n_x, state.n_y, state.psi, state.phi
    rows_y, rows_x = state.problem.psi_s[state.seed_map], state.problem.phi_s  # eigenfunctions at the matches
    matched_x = state.seeds_x.nearest_corners(source)  # vertices of the matches (cell centres)
    matched_y = state.seeds_y.nearest_corners(target)[state.seed_map]
    state.seed_vertices_x, state.seed_vertices_y = matched_x.copy(), matched_y.copy()
    decay_y, decay_x = state.decays(state.taus[-1])
    mass_y = state.spec_y.mass.diagonal()
    landmark_x, landmark_y = np.zeros(n_x, dtype=bool), np.zeros(n_y, dtype=bool)
    landmark_x[state.anchors_x], landmark_y[state.anchors_y] = True, True
    size, last = state.n_seed, False
    keys, cell_map, cell_map_yx = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), -np.ones(n_y, np.int64)
    # a source with more vertices than the target is sampled up to the target's count (partial matching
    # decides every vertex by the slack)
    top_x = n_x if params.partial else min(n_x, n_y)
    while not last:
        size = int(min(max(top_x, n_y), np.ceil(size * params.growth)))
        last = size >= max(top_x, n_y)
        x_idx, y_idx = state.order_x[:min(size, top_x)], state.order_y[:size]
        x_idx, y_idx = x_idx[~landmark_x[x_idx]], y_idx[~landmark_y[y_idx]]
        if x_idx.size == 0 or y_idx.size == 0 or landmark_x[matched_x].all():
            continue
        capacity_y = None
        if params.capacity == "area":
            capacity_y = np.ones(n_y, dtype=np.int64)
            capacity_y[y_idx] = area_capacities(x_idx.size, _sample_masses(target, mass_y, y_idx))
        for p in range(params.passes):
            state.token.raise_if_cancelled()
            with watch("kernels"):
                c = _alignment(rows_y, rows_x) + state.problem.anchor_c
            n_cells = max(1, int(np.ceil(x_idx.size / (CELL_FILL * params.max_cell))))
            free = ~landmark_x[matched_x]
            centres_x, centres_y = cell_centres(source.vertices, matched_x[free], matched_y[free], n_cells, p)
            centres_x, centres_y = split_large_cells(source, centres_x, centres_y, matched_x[free],
                                                     matched_y[free], x_idx, params.max_cell)
            with watch("cells"):
                x_cells, y_cells = transferred_cells(source, target, centres_x, centres_y, x_idx, y_idx,
                                                     params.cell_overlap, matched_x, matched_y)
            with watch("assignment"):
                cell_map, cell_map_yx = _solve_cells(x_cells, y_cells, psi, phi, c, decay_y, decay_x, params,
                                                     state.cancel, n_y, capacity_y)
            keys = np.concatenate(x_cells)
            ok = cell_map >= 0
            matched_x, matched_y = keys[ok], cell_map[ok]
            rows_y, rows_x = psi[matched_y], phi[matched_x]
            yield Progress("multiscale", PROGRESS_MULTISCALE[0] + PROGRESS_MULTISCALE[1] * size / max(n_x, n_y),
                           f"{size} samples, pass {p + 1}/{params.passes}: {centres_x.size} cells")
    full_map_xy = -np.ones(n_x, dtype=np.int64)
    full_map_xy[keys] = cell_map
    if top_x < n_x:
        surplus_partners(source, full_map_xy, keys, state.anchors_x)
    full_map_xy[state.anchors_x] = state.anchors_y
    cell_map_yx[state.anchors_y] = state.anchors_x
    return full_map_xy, cell_map_yx


def reorients(state: KernelState) -> bool:
    """Whether the orientation stage and the check of disagreeing parts apply: ``reorient`` on, no landmarks
    (they fix the orientation themselves), complete closed shapes (a cut changes a shape's reflection and
    geodesic distances; :func:`~.reorientation.can_reorient`)."""
    return state.params.reorient and state.anchors_x.size == 0 and not state.params.partial and \
        can_reorient(state.source, state.target, state.spec_y)


def final_basis_size(params: KernelMatchingParams, spec_x: Spectrum, spec_y: Spectrum, area_x: float,
                     area_y: float) -> int:
    """The eigenfunctions of the final steps: ``smooth_k`` (at most the eigenpairs computed), or for -1 those
    the smallest kernel resolves on both shapes (:func:`~corrlib.geometry.fmaps.resolved_eigenpairs`)."""
    if params.smooth_k >= 0:
        return min(params.smooth_k, spec_x.k, spec_y.k)
    tau_last = diffusion_times(params)[-1]
    return min(resolved_eigenpairs(spec_x.evals, area_x, tau_last), resolved_eigenpairs(spec_y.evals, area_y, tau_last))


def kernel_result(state: KernelState, full_map_xy: np.ndarray, full_map_yx: np.ndarray, orient: bool = True):
    """Stage 7: the turns of reversed regions, the final ZoomOut steps
    (:func:`~corrlib.geometry.fmaps.pointwise_from_basis`, repeated by
    :func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis` unless the map came from outside the solver),
    the kernel energy ``<Π, K_Y Π K_X>`` of the final map at the smallest time, the :class:`MatchResult`. A
    generator. ``orient=False`` skips the orientation stage (a map the stage has seen already)."""
    params, k, watch = state.params, state.k, state.watch
    psi, phi, trace = state.psi, state.phi, state.trace
    monotone, dc_start, n_seed = state.monotone, state.dc_start, state.n_seed
    seed_vertices_x, seed_vertices_y = state.seed_vertices_x, state.seed_vertices_y
    decay_y, decay_x = state.decays(state.taus[-1])
    turned = turned_regions = turned_parts = released = None
    released_regions = ()
    # landmarks fix the orientation themselves; a cut changes a shape's reflection and biharmonic distances
    if orient and reorients(state):
        with watch("orientation"):
            done = reorient(state.source, state.target, state.spec_x, state.spec_y, full_map_xy, full_map_yx,
                            state.orientation_blocks)
        state.before_partial_turns = done.before_partial
        full_map_xy, full_map_yx = done.map_xy, done.map_yx
        turned, turned_regions, turned_parts = done.turned, done.turned_regions, done.turned_parts
        released, released_regions = done.released, done.released_regions
    smooth_k = final_basis_size(params, state.spec_x, state.spec_y, state.source.area, state.target.area)
    if smooth_k > 0:
        yield Progress("final ZoomOut step", PROGRESS_SMOOTHING, f"nearest partners in {smooth_k} eigenfunctions")
        with watch("zoomout"):
            samples_x, samples_y = ZoomOutSamples.of_pair(state.source, state.target, state.spec_x.mass.diagonal(),
                                                          state.spec_y.mass.diagonal())
            if state.outside_map:  # a map refined from outside keeps its partners, which the reverse map lacks
                full_map_xy, full_map_yx = pointwise_from_basis(
                    full_map_xy, full_map_yx, state.spec_x, state.spec_y, smooth_k, both_directions=False,
                    samples_x=samples_x, samples_y=samples_y)
            else:
                full_map_xy, full_map_yx = repeated_pointwise_from_basis(
                    full_map_xy, full_map_yx, state.spec_x, state.spec_y, smooth_k, state.source.adjacency,
                    state.target.adjacency, state.token, samples_x, samples_y)
    # the map's own energy: landmarks are rows of the dense map already (their anchor term is the solver's)
    c = _alignment(psi[full_map_xy[full_map_xy >= 0]], phi[full_map_xy >= 0])
    energy = kernel_energy(c, decay_y, decay_x)
    extras = {
        "orientation_agreement": mean_agreement(*state.orientation_blocks(), full_map_xy),
        "turned": turned is not None,
        "agreement_before_turn": None if turned is None else turned.agreement_before,
        "turned_regions": 0 if turned_regions is None else len(turned_regions.parts),
        "turned_parts": 0 if turned_parts is None else len(turned_parts.parts),
        "released_regions": len(released_regions), "released_x": released,
        "changed_trace": np.array([e["changed"] for e in trace]),
        "tau_trace": np.array([e["tau"] for e in trace]),
        "monotone": monotone, "start": dc_start, "unmatched_x": int(np.sum(full_map_xy < 0)),
        "unmatched_y": int(np.sum(full_map_yx < 0)), "n_eigs": k, "n_seeds": n_seed,
        "seeds_x": seed_vertices_x, "seeds_matched_y": seed_vertices_y,
    }
    return MatchResult("kernel-matching", full_map_xy, full_map_yx, energy, watch.times, energy_sense="max",
                       energy_meaning="QAP kernel energy <Π, K_Y Π K_X> at the smallest time (higher is better); "
                                      "energy_trace: the objective after each DC iteration (½ scaled kernel term "
                                      "+ μ descriptor term)",
                       energy_trace=np.array([e["energy"] for e in trace]), extras=extras)


def kernel_matching(source, target, params: KernelMatchingParams, token, initial: InitialMatch | None = None):
    """Solver generator (thesis ch. 8, see the module docstring); returns a :class:`MatchResult`.

    Prepare the spectra and seeds, assign the seeds initially, run the DC iterations of the first time from
    one or two starts and keep the better, continue over the decreasing times, refine on finer scales; a
    refined dense map keeps its partners within the smallest kernel's width, and farther moved ones where they are
    the more isometric partner (:mod:`corrlib.methods.resolution`; ``extras["kept_matches"]``, the latter also
    in ``extras["isometric_matches"]``). Where the orientation stage turned anything, the turned map is
    optimised once more (:func:`reoptimised`).
    """
    state = yield from prepare(source, target, params, token)
    result = yield from solved(state, initial)
    result = yield from replaced_disagreeing_part(state, result)
    yield Progress("done", 1.0, f"energy {result.energy:.6g}")
    return result


def solved(state: KernelState, initial: InitialMatch | None = None):
    """Stages 2–7 on a prepared :class:`KernelState` and, where the orientation stage turned anything, the
    second pass (:func:`reoptimised`); a generator, returns the :class:`MatchResult`."""
    result = yield from solve_prepared(state, initial)
    if turned_anything(result.extras):
        result = yield from reoptimised(state, result)
    return result


def reoptimised(state: KernelState, turned: MatchResult):
    """The DC iterations and the finer scales run once more from a map the orientation stage turned, or with
    the rest of the map as landmarks where it found swapped limbs (a generator; returns the new
    :class:`MatchResult`).

    The first pass's decisions and map go to ``extras`` (:func:`~.reorientation.with_first_pass`).

    A turn composes the map with a *computed* reflection (:mod:`.reorientation`), which is only as exact as
    that reflection: a posed person's can be 0.02–0.07 √area off on the limbs, and the turned limbs are then
    a rough copy of the right ones, not an optimum of the kernel energy. The map is therefore a start, and
    kernel matching refines it as it refines any given map (``initial``; the partners within the smallest
    kernel's width are kept, :mod:`corrlib.methods.resolution`). The orientation stage runs again on the
    result, without a third pass. The prepared spectra, samples and descriptors are reused. From a turned map
    the pass is lighter than the first (:data:`SECOND_PASS_ITERATIONS` DC steps per time,
    :data:`SECOND_PASS_PASSES` refinement passes per scale): the map it starts from has been through the whole
    schedule already. Released limbs (below) have no start at all, so their pass is a full one.

    Swapped limbs (``extras["released_x"]``, :func:`~.reorientation.swapped_pairs`: a mirror pair of limbs, each
    sent mirror-inverted onto the other's image) are not turned by a reflection: a posed target's reflection
    is too poor on its limbs to carry them back (measured: the turned legs stay 0.27 √area off). Their
    matches are dropped, and the rest of the map becomes landmarks (anchors of every stage, kept as they are,
    :class:`~corrlib.methods.base.InitialMatch`), so the kernel energy places the limbs by their heat-kernel
    relation to the body, whose left and right the landmarks fix. A landmark run has no orientation stage,
    so there is no third pass here either.

    Turned regions and parts and released limbs are hypotheses: the region rule reads a region whose
    orientation is reversed as a left–right flip, but on a body with a second near-symmetry (an upper body
    alike in front and behind) it can be the other flip, which the left–right reflection turns into a half
    turn with the arms swapped. The result of this pass is therefore kept only where it is nearer an isometry
    than the map without those turns (:func:`declined_partial_turns`). A turn of the whole map is not judged
    so: it composes the map with a reflection, an isometry, which leaves the distortion as it was.
    """
    # the first pass reports at most PROGRESS_SMOOTHING: the second fills the rest of the bar, which never goes back
    yield Progress("re-optimising", PROGRESS_SMOOTHING, "the turned map, refined once more")
    released = turned.extras.get("released_x")
    if released is None:
        start = InitialMatch(map_xy=turned.map_xy)
    else:  # swapped limbs: re-placed by the kernel energy from the rest of the map, kept as landmarks
        kept = np.flatnonzero(~released & (turned.map_xy >= 0))
        start = InitialMatch(landmarks_x=kept, landmarks_y=turned.map_xy[kept])
    fresh = state.prepared()
    if released is None:  # a turned map: every vertex starts from a map that went through the whole schedule
        fresh.params = replace(state.params, iters_per_time=min(state.params.iters_per_time, SECOND_PASS_ITERATIONS),
                               passes=min(state.params.passes, SECOND_PASS_PASSES))
    result = yield from scaled_progress(solve_prepared(fresh, start, compete=False),
                                        PROGRESS_SMOOTHING, 1.0, "second pass")
    with_first_pass(result.extras, turned.extras, turned.map_xy, turned.energy)
    if state.before_partial_turns is not None:
        kept = yield from declined_partial_turns(state, turned, result)
        if kept is not None:
            return kept
    return result


def declined_partial_turns(state: KernelState, first: MatchResult, second: MatchResult):
    """The first pass's map without its partial turns, where the second pass made the map farther from an
    isometry; else None (a generator).

    Compares the geodesic distortion of the map before the orientation stage turned regions or parts or
    released limbs (``state.before_partial_turns``; after a whole-map turn, if any) with that of the second
    pass's result (:func:`~corrlib.methods.reorientation.nearer_isometry`: a right turn removes a
    mirror-inverted stretch of the map and lowers it; a turn by the wrong symmetry swaps limbs and raises it;
    the kernel energy is higher after either). The distortions go to ``extras`` of the map returned; a
    declined result is the first pass's map through the final ZoomOut steps, with its energy and trace, and
    ``declined_turns`` (:func:`~corrlib.methods.reorientation.declined_extras`).
    """
    before_xy, before_yx = state.before_partial_turns
    with state.watch("orientation"):
        keep_after, measured = nearer_isometry(state.source, state.target, before_xy, second.map_xy,
                                               state.pair_distances())
    second.extras.update(measured)
    if keep_after:
        return None
    kept = yield from scaled_progress(kernel_result(state, before_xy, before_yx, orient=False), 1.0, 1.0,
                                      "the turns undone")
    kept.extras.update(declined_extras(first.extras, measured))
    return kept


def replaced_disagreeing_part(state: KernelState, found: MatchResult):
    """Stage 9: a map made of two parts that disagree, each part placed again from the other; a generator,
    returns the :class:`MatchResult` kept.

    The DC iterations keep what the first times decided, and a body alike in front and behind (an upper body
    of limbs and a torso without a face) can leave the first times with one part turned half round against
    the rest: arms swapped, chest onto back, hips and legs right. Each part is then nearly an isometry of its
    own, and the kernel energy at the smallest time hardly sees the seam, but the geodesic distances between
    the parts are off by the body's width. :func:`~corrlib.geometry.distortion.inconsistent_parts` finds the
    two parts; where they disagree (:attr:`~corrlib.geometry.distortion.MapParts.disagree`), each part in
    turn is kept as landmarks and the other matched again from it (two landmark runs, side by side,
    :func:`side_by_side`), as a release pass places swapped limbs. The run of least geodesic distortion
    replaces the map where it is nearer an isometry than the map found; which part was wrong is not
    guessed. ``extras``: ``disagreement_ratio`` always, and where the runs were made
    ``disagreement_distortions`` (the map found, then the run keeping the first part, then the second; ``inf``
    for a run that failed) and
    ``replaced_part`` (the count of source vertices matched again, 0 where the map found was kept).
    """
    if not reorients(state):
        return found
    with state.watch("disagreeing parts"):
        parts = inconsistent_parts(state.source, state.target, found.map_xy, state.pair_distances())
    if parts is None:
        return found
    found.extras["disagreement_ratio"] = parts.ratio
    if not parts.disagree:
        return found
    yield Progress("disagreeing parts", 1.0, f"two parts of the map disagree ({parts.ratio:.1f}× the distortion "
                                             "within them); each is matched again from the other")
    states, landmarks = [], []
    for kept in (parts.part, ~parts.part):
        states.append(state.prepared())
        states[-1].watch = Stopwatch()
        landmarks.append(np.flatnonzero(kept & (found.map_xy >= 0)))

    def placing(index):  # the run keeping part `index`; a failed run returns its error instead of a map
        start = InitialMatch(landmarks_x=landmarks[index], landmarks_y=found.map_xy[landmarks[index]])
        return lambda fresh: _or_its_error(solve_prepared(fresh, start, compete=False))

    with state.watch("disagreeing parts"):  # the bar stays full: the match was complete before this stage
        placed = yield from scaled_progress(side_by_side(states[0], states[1], placing(0), placing(1), (
            "keeping the first part", "keeping the second part")), 1.0, 1.0)
        maps = [found.map_xy] + [outcome.map_xy for outcome in placed if isinstance(outcome, MatchResult)]
        measured = iter(geodesic_distortions(state.source, state.target, maps, state.pair_distances()))
    distortions = [next(measured)] + [next(measured) if isinstance(outcome, MatchResult) else float("inf")
                                      for outcome in placed]
    found.extras.update(disagreement_distortions=distortions, replaced_part=0)
    best = int(np.argmin(distortions))  # the map found on a tie
    if best == 0:
        return found
    result = placed[best - 1]
    replaced = int(found.map_xy.size - landmarks[best - 1].size)  # the source vertices matched again
    result.extras = {**found.extras, **result.extras, "replaced_part": replaced}
    result.timings = found.timings  # with this stage's time (the landmark runs' own timings are its parts)
    return result


def solve_prepared(state: KernelState, initial: InitialMatch | None, compete: bool = True):
    """Stages 2–7 on a prepared :class:`KernelState` (a generator; returns the :class:`MatchResult`);
    ``compete=False``: a given map does not compete with the descriptor start (a second pass, whose first
    pass had that start already)."""
    source, target = state.source, state.target
    yield from initial_seed_map(state, initial, compete)
    seed_problem(state)
    yield from choose_start(state)
    alignment = state.start_alignment
    for t_index in range(1, len(state.taus)):
        run = yield from dc_iterations(state, state.seed_map, state.prices, t_index, alignment=alignment)
        state.seed_map, alignment = run.seed_map, run.alignment
        state.trace.extend(run.entries)
    full_map_xy, full_map_yx = yield from multiscale_refinement(state)
    kept = None
    if state.refined_map is not None:  # below the smallest kernel's width the input map's partners stand
        width_x, width_y = kernel_width(state.taus[-1], source.area), kernel_width(state.taus[-1], target.area)
        kept, isometric = keep_input_partners(full_map_xy, *state.refined_map, source.vertices, target.vertices,
                                              width_x, width_y)
    result = yield from kernel_result(state, full_map_xy, full_map_yx)
    if kept is not None:
        result.extras.update(kept_matches=kept | isometric, isometric_matches=isometric)
    return result


def orientation_agreement(source, target, map_xy: np.ndarray, spec_x: Spectrum, spec_y: Spectrum) -> float:
    """Mean agreement ``<O_X(x), O_Y(m(x))>`` of the standardised orientation-aware descriptors along a map.

    The descriptors (:func:`~corrlib.descriptors.orientation.orientation_descriptors`, signed area forms of
    heat kernel signature pairs) change sign under a reflection, so the agreement is large for a map that
    keeps left on left and negative for its mirror image — which the kernel energy cannot tell apart, since
    a reflection of a symmetric shape preserves the heat kernels. Unmatched vertices (-1) are left out.
    """
    return mean_agreement(*orientation_blocks(source, target, spec_x, spec_y), map_xy)


def copies_note(extras: dict) -> str | None:
    """What the user is told when finer meshes were matched on remeshed copies (``mesh_vertices``), else None."""
    if not extras or "matched_on" not in extras:
        return None
    n_x, n_y = extras["matched_on"]
    return (f"matched on copies remeshed to {n_x} and {n_y} vertices and carried to every vertex by the final steps "
            f"(mesh_vertices; 0 matches at full resolution, slower)")


def turn_note(extras: dict) -> str | None:
    """What the user is told when the map, or some of its limbs, was turned by the target's reflection
    (:mod:`.reorientation`), else None."""
    if not extras:
        return None
    said = []
    if extras.get("turned"):
        said.append(f"the map sent left to right on most of the shape (orientation agreement "
                    f"{extras['agreement_before_turn']:.2f}); it was composed with an intrinsic "
                    f"reflection (agreement now {extras['orientation_agreement']:.2f})")
    if extras.get("turned_regions"):
        count = extras["turned_regions"]
        said.append(f"{count} region{'s' if count > 1 else ''} (a protrusion with the body beside it) matched "
                    f"mirror-inverted {'were' if count > 1 else 'was'} turned by a reflection (a mirrored pair by the "
                    f"source's or the target's, whichever is nearer an isometry; a limb crossed onto another limb's "
                    f"image by the target's)")
    if extras.get("turned_parts"):
        count = extras["turned_parts"]
        said.append(f"{count} protrusion{'s' if count > 1 else ''} (limbs) matched to the mirror-image limb "
                    f"{'were' if count > 1 else 'was'} turned by the target's reflection")
    if extras.get("released_regions"):
        said.append(f"{extras['released_regions']} regions (a mirror pair of limbs with the body beside them) were "
                    f"matched swapped, each onto the other's mirror image; they were matched again with the rest "
                    f"of the map as landmarks")
    declined = extras.get("declined_turns") or {}
    if any(declined.values()):
        what = [f"{declined[key]} {name}{'s' if declined[key] > 1 else ''}" for key, name in
                (("turned_regions", "turned region"), ("turned_parts", "turned limb"),
                 ("released_regions", "released region")) if declined.get(key)]
        said.append(f"the orientation stage turned or released parts of the map ({', '.join(what)}), but the map "
                    f"optimised after that was farther from an isometry (geodesic distortion "
                    f"{extras['distortion_after_turns']:.4f} against {extras['distortion_before_turns']:.4f} "
                    f"√area), so the map as found before those turns was kept")
    if extras.get("swapped_regions"):
        said.append(f"{extras['swapped_regions']} regions (a mirror pair of limbs with the body beside them) are "
                    f"matched swapped, each onto the other's mirror image, and were left as found (kernel matching "
                    f"matches such limbs again from the rest of the map)")
    if extras.get("replaced_part"):
        distortions = extras["disagreement_distortions"]
        said.append(f"two parts of the map disagreed (the geodesic distances between them distorted "
                    f"{extras['disagreement_ratio']:.1f}× as much as within them); {extras['replaced_part']} source "
                    f"vertices were matched again with the rest of the map as landmarks (geodesic distortion "
                    f"{distortions[0]:.4f} → {min(distortions[1:]):.4f} √area)")
    if not said:
        return None
    again = "; the turned map was then optimised once more" if "first_pass" in extras and (
        extras.get("turned") or extras.get("turned_regions") or extras.get("turned_parts")) else ""
    return "; ".join(said) + again + " (reorient=false keeps the map as found)"


def start_note(extras: dict) -> str | None:
    """What the user is told about the start of a map: for ``init="best"``, that the functional map's start
    was kept (``extras["init"] == "fmap"``, with the measures that kept it) or failed
    (``extras["other_start_error"]``); for a refined map, that its own start lost to the descriptor assignment
    (``extras["start"] == "descriptors"``, :func:`choose_start`); else None (the descriptor start kept, as
    usual)."""
    if extras and extras.get("other_start_error"):
        return (f"the functional map's start failed ({extras['other_start_error']}), so the map is the descriptor "
                "start's alone")
    if extras and extras.get("init") == "fmap" and extras.get("start_measures"):
        kept, other = extras["start_measures"]["fmap"], extras["start_measures"]["descriptors"]
        return ("of the two starts the functional map's was kept, its map being better by every measure: kernel "
                f"energy {kept['energy'] / other['energy']:.4f}× the descriptor start's, orientation agreement "
                f"{kept['agreement']:.2f} against {other['agreement']:.2f}, geodesic distortion "
                f"{kept['distortion']:.4f} against {other['distortion']:.4f} √area")
    if not extras or extras.get("start") != "descriptors":
        return None
    return ("the given map reached a lower kernel objective than the method's own start (the descriptor "
            "assignment) at the first time, so the refinement continued from the descriptor assignment; the given "
            "partners stand only where the result lies within the smallest kernel's width of them, or where they are "
            "the more isometric partner")


def reversal_note(extras: dict) -> str | None:
    """A warning when a map reverses orientation on most of the shape (its
    :func:`orientation_agreement`, ``extras["orientation_agreement"]``, is negative: left matched to right), else
    None. The kernel energy cannot see this (a reflection of a symmetric shape keeps every heat kernel), so it
    is said with the result rather than left to the user's eye."""
    agreement = extras.get("orientation_agreement") if extras else None
    if agreement is None or not agreement < 0:
        return None
    return (f"the map reverses orientation on most of the shape (orientation agreement {agreement:.2f} < 0: left "
            "matched to right); try landmarks (--init), or check the target is not a mirror image")


def start_measures(source, target, results: dict, distances: PairDistances | None = None) -> dict:
    """The three measures by which :func:`best_of_both_starts` compares its maps, per start.

    Returns ``{init: {"energy", "agreement", "distortion"}}``: the final kernel energy (higher is better;
    both runs share the spectra and times, so the energies compare), the :func:`orientation_agreement`
    (higher) and the geodesic distortion per √area
    (:func:`~corrlib.geometry.distortion.geodesic_distortions`, lower; ``distances``: the pair's, shared).
    """
    inits = list(results)
    distortions = geodesic_distortions(source, target, [results[init].map_xy for init in inits], distances)
    return {init: {"energy": float(results[init].energy),
                   "agreement": float(results[init].extras["orientation_agreement"]),
                   "distortion": float(d)} for init, d in zip(inits, distortions)}


def dominates(a: dict, b: dict) -> bool:
    """Whether the measures ``a`` are better than ``b`` in all three (:func:`start_measures`)."""
    return a["energy"] > b["energy"] and a["agreement"] > b["agreement"] and a["distortion"] < b["distortion"]


def _or_its_error(solver):
    """A solver generator that returns its :class:`~corrlib.errors.CorrError` instead of raising it (a
    cancellation is still raised): the second start's failure leaves the first start's map
    (:func:`best_of_both_starts`)."""
    try:
        return (yield from solver)
    except Cancelled:
        raise
    except CorrError as exc:
        return exc


def both_starts(first: KernelState, second: KernelState):
    """Kernel matching from two prepared states (:func:`side_by_side`, each :func:`solved`). A generator; returns
    ``{init: MatchResult}``, where the second start's value is its :class:`~corrlib.errors.CorrError` if it
    failed (the first start's errors, and a cancellation, are raised)."""
    inits = (first.params.init, second.params.init)
    results = yield from side_by_side(first, second, solved, solved,
                                      (f"start 1/2 ({inits[0]})", f"start 2/2 ({inits[1]})"))
    return dict(zip(inits, results))


def side_by_side(first: KernelState, second: KernelState, run_first, run_second, labels: tuple[str, str]):
    """Two runs of the solver, ``run_first(first)`` in the calling thread (its progress reported) and
    ``run_second(second)`` on a thread beside it where this process may use two cores, else after it. A
    generator; returns both results, the second run's being its :class:`~corrlib.errors.CorrError` if it failed
    (the first run's errors, and a cancellation, are raised).

    After the spectra the solver keeps one core busy (assignments, score products, cells), so the second
    run costs no wall time on two cores, provided that BLAS does not spread either run over both cores
    as well: within the two runs it is limited to one thread (the same maps; sums may differ in the last bit).
    The second run has its own cancel token, set when the first ends in any way (the caller's
    cancellation included), so that neither an error nor a cancellation waits for the second run. Side by side,
    the fraction reported is that of both runs' work (:func:`~corrlib.progress.paired_progress`); once the first
    has ended, each report of the second is relayed once, labelled.
    """
    from threadpoolctl import threadpool_limits

    with side_threads(1) as pool:
        if isinstance(pool, InlineExecutor):  # one core's share: one run after the other
            mine = yield from scaled_progress(run_first(first), 0.0, 0.5, labels[0])
            theirs = yield from scaled_progress(_or_its_error(run_second(second)), 0.5, 1.0, labels[1])
            return mine, theirs
        caller, second.token = second.token, CancelToken()
        latest = LatestReport()
        try:
            with threadpool_limits(1):
                other = pool.submit(run, _or_its_error(run_second(second)), latest, second.token)
                yield Progress("kernel matching", 0.0, f"{labels[1]} runs beside this one, on the other core")
                mine = yield from paired_progress(scaled_progress(run_first(first), 0.0, 1.0, labels[0]), latest)
                relayed = None
                while not wait([other], timeout=WAIT_POLL).done:
                    caller.raise_if_cancelled()
                    report = latest.report
                    if report is not relayed:  # each of its reports once, not one per poll
                        relayed = report
                        yield Progress(report.stage, (1.0 + latest.fraction) / 2,
                                       f"{labels[1]}: {report.message}" if report.message else labels[1])
                theirs = other.result()
        finally:
            second.token.cancel()  # a finished run ignores it; a running one stops at its next check
    return mine, theirs


def best_of_both_starts(source, target, params: KernelMatchingParams, token):
    """``init="best"``: kernel matching from the descriptor start and from the functional-maps baseline's
    map; the latter is kept only where its map is better by all three measures of :func:`start_measures`
    (higher kernel energy, higher orientation agreement, lower geodesic distortion), else the descriptor
    start's.

    Why both: the descriptor start (SHOT and the orientation-aware descriptors, point by point) can commit
    part of a non-isometric pair, or of a noisy one, to the wrong limb, where the functional map (a
    spectral fit of the whole shape, :mod:`~corrlib.methods.baselines`) holds; on a symmetric body the
    functional map can be a half turn or a partial flip that the descriptor start avoids. Why all three:
    each measure alone is blind somewhere — the kernel energy to maps that differ by a symmetry, the
    orientation agreement to a flip of a small part, the distortion to the detail of a non-isometric
    pair — so the default start gives way only to a map that no measure finds worse (see
    ``docs/decisions.md``). ``extras["init"]`` names the start kept and ``extras["start_measures"]`` holds
    both starts' measures; the timings are those of the map kept plus ``"other start"`` (the other run's
    sum). Where the functional map's start fails (a :class:`~corrlib.errors.CorrError`, e.g. descriptors that
    are the same at every vertex of a very regular shape), the descriptor start's map is returned with
    ``extras["other_start_error"]`` (the message; :func:`start_note` tells the user).
    """
    state = yield from prepare(source, target, params, token)
    yield Progress("descriptors", 0.0, f"{params.descriptor}, shared by both starts")  # each start reports from 0
    state.descriptors()
    if params.mu > 0:
        state.seed_descriptor_similarity()
    with state.watch("orientation"):
        state.orientation_blocks()
    starts = {}
    for init in ("descriptors", "fmap"):
        starts[init] = state.prepared()  # the spectra, samples and descriptors
        starts[init].params, starts[init].watch = replace(params, init=init), Stopwatch()  # each times itself
    results = yield from both_starts(starts["descriptors"], starts["fmap"])
    if isinstance(results["fmap"], CorrError):  # e.g. descriptors that cannot tell a shape's points apart
        kept, result = "descriptors", results["descriptors"]
        result.extras.update({"init": kept, "start_measures": None, "other_start_error": str(results["fmap"])})
    else:
        with state.watch("orientation"):
            measures = start_measures(source, target, results, state.pair_distances())
        kept = "fmap" if dominates(measures["fmap"], measures["descriptors"]) else "descriptors"
        other = "fmap" if kept == "descriptors" else "descriptors"
        result = results[kept]
        result.extras.update({"init": kept, "start_measures": measures})
        result.timings["other start"] = float(sum(results[other].timings.values()))
    result = yield from replaced_disagreeing_part(state, result)
    for stage, seconds in state.watch.times.items():  # the shared stages: spectra, samples, the judge
        result.timings[stage] = result.timings.get(stage, 0.0) + seconds
    yield Progress("done", 1.0, f"{kept} start kept, energy {result.energy:.6g}")
    return result


def solve_kernel_matching(source, target, params: KernelMatchingParams, token, *,
                          initial: InitialMatch | None = None):
    """Registered solver (``initial``: optional :class:`InitialMatch` for refinement)."""
    if initial is None:
        if 0 < 2 * params.mesh_vertices < max(source.n_vertices, target.n_vertices):
            yield Progress("remeshing", 0.0, f"copies of {params.mesh_vertices} vertices (mesh_vertices)")
        copy_x, copy_y = matched_copy(source, params.mesh_vertices), matched_copy(target, params.mesh_vertices)
        if copy_x.remeshed or copy_y.remeshed:
            return (yield from matched_on_copies(source, target, copy_x, copy_y, params, token))
        if max(source.n_vertices, target.n_vertices) > LARGE_MESH_VERTICES:
            yield Progress("eigenpairs", 0.0, f"{max(source.n_vertices, target.n_vertices)} vertices at full "
                                              f"resolution take minutes; mesh_vertices={SUGGESTED_MESH_VERTICES} "
                                              "matches on remeshed copies in seconds")
    if initial is None and params.init == "best":
        return (yield from best_of_both_starts(source, target, params, token))
    return (yield from kernel_matching(source, target, params, token, initial))


#: the share of the progress bar of the match on the copies (the rest: carrying the map to the fine meshes)
PROGRESS_COPIES = 0.9


def matched_on_copies(source, target, copy_x: MatchedCopy, copy_y: MatchedCopy, params: KernelMatchingParams,
                      token):
    """Kernel matching of meshes finer than ``mesh_vertices``: the copies matched, the maps carried to the
    originals (:mod:`corrlib.geometry.lifting`) with the final steps' basis (``smooth_k``).

    Diagnostics that name vertices of the copies (arrays in ``extras``) are dropped; ``extras["matched_on"]``
    gives the copies' vertex counts.
    """
    inner = replace(params, mesh_vertices=0)
    label = f"matched on copies of {copy_x.mesh.n_vertices} and {copy_y.mesh.n_vertices} vertices"
    solver = (best_of_both_starts(copy_x.mesh, copy_y.mesh, inner, token) if params.init == "best" else
              kernel_matching(copy_x.mesh, copy_y.mesh, inner, token, None))
    result = yield from scaled_progress(solver, 0.0, PROGRESS_COPIES, label)
    spec_x, spec_y = mesh_spectra((copy_x.mesh, copy_y.mesh), params.n_eigs)  # the copies' (cached)
    k = final_basis_size(params, spec_x, spec_y, copy_x.mesh.area, copy_y.mesh.area)
    yield Progress("final ZoomOut step", PROGRESS_COPIES,
                   f"the map carried to {source.n_vertices} and {target.n_vertices} vertices, {k} eigenfunctions")
    watch = Stopwatch()
    with watch("lift"):
        result.map_xy, result.map_yx = lifted_maps(result.map_xy, result.map_yx, source, target, copy_x, copy_y,
                                                   spec_x, spec_y, k, token)
    result.timings.update(watch.times)
    result.extras = {key: value for key, value in result.extras.items() if not isinstance(value, np.ndarray)}
    result.extras["matched_on"] = (copy_x.mesh.n_vertices, copy_y.mesh.n_vertices)
    return result


register(MethodSpec(
    name="kernel-matching", label="Kernel matching", inputs=("mesh", "mesh"), params=KernelMatchingParams,
    solve=solve_kernel_matching, rank=20, refines=True,
    description="Heat-kernel quadratic assignment solved as a sequence of linear assignments over decreasing "
                "diffusion times, multiscale, with slack for partial shapes (Vestner et al. 3DV 2017)."))
