"""What kernel matching's stages share (:class:`KernelState`) and stage 1, :func:`prepare`: the spectra, the
surface seeds and the sample orders of the finer scales.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corrlib.cores import side_threads
from corrlib.errors import ParameterError
from corrlib.geometry.distortion import PairDistances
from corrlib.geometry.sampling import SurfaceSample, outermost_farthest_points, surface_farthest_points
from corrlib.geometry.spectrum import Spectrum, mesh_spectra
from corrlib.methods.kernel_matching.dc import SeedProblem
from corrlib.methods.kernel_matching.params import KernelMatchingParams, diffusion_times
from corrlib.methods.kernel_matching.scores import descriptor_similarity, heat_decays, shape_descriptors
from corrlib.methods.reorientation import orientation_blocks
from corrlib.progress import Progress, Stopwatch


#: the finer scales' samples are farthest-point prefixes up to ``n_seed × growth ** FPS_SCALES`` vertices
#: (the first finer scales); the rest, only in the last dense scales, are ordered by distance from the centroid
FPS_SCALES = 2


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


def nearest_point(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """(q,) int: for every query position (q, 3) the index of the nearest of ``points`` (p, 3) (Euclidean)."""
    from scipy.spatial import cKDTree

    return cKDTree(points).query(queries)[1]


def sample_masses(mesh, mass_diag: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """(s,) float: area of every sample's Euclidean Voronoi cell (vertex areas summed to the nearest sample)."""
    from scipy.spatial import cKDTree

    if sample.size == mesh.n_vertices:
        return mass_diag[sample]
    owner = cKDTree(mesh.vertices[sample]).query(mesh.vertices)[1]
    return np.bincount(owner, weights=mass_diag, minlength=sample.size)


@dataclass(eq=False)
class KernelState:
    """What the stages of :func:`~.solver.kernel_matching` share.

    Set by :func:`prepare`: the inputs, the spectra (Φ = ``spec_x.evecs`` (n_x, k), Ψ = ``spec_y.evecs``
    (n_y, k)), the relative times ``taus`` (n_times,), the surface seeds and the sample orders (n_x,), (n_y,)
    of the finer scales. Then, stage by stage: the anchors and the initial ``seed_map`` (n_seed,) with its
    descriptor ``confidence``, the :class:`~.dc.SeedProblem`, the current ``seed_map`` with its auction
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
    free_x: np.ndarray | None = None  # with landmarks: the seeds the assignments place (fixed_seeds)
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
    # whole-map turn, if any), (map_xy, map_yx): the alternative a second pass must beat (:func:`~.passes.reoptimised`)
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
                self.desc_x, self.desc_y = shape_descriptors(self.source, self.target, self.spec_x, self.spec_y,
                                                        self.params.descriptor)
        return self.desc_x, self.desc_y

    def seed_descriptor_similarity(self) -> np.ndarray:
        """The seeds' plain descriptor similarity (n_seed, n_seed), computed once."""
        if self.seed_similarity is None:
            desc_x, desc_y = self.descriptors()
            self.seed_similarity = descriptor_similarity(self.seeds_x.interpolate(self.source, desc_x),
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
        descriptor assignment (landmarks have one start, :func:`~.seed_stage.choose_start`)."""
        return (self.confidence is not None and self.params.init_fraction < 1) or self.descriptor_start

    @property
    def total_steps(self) -> int:
        return (len(self.taus) + self.has_second_start) * self.params.iters_per_time

    def decays(self, tau: float) -> tuple[np.ndarray, np.ndarray]:
        """``(e^{-tΛ_Y}, e^{-tΛ_X})`` at the relative time ``tau``, each (k,)."""
        return heat_decays(self.spec_y.evals, self.target.area, tau), \
            heat_decays(self.spec_x.evals, self.source.area, tau)


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
