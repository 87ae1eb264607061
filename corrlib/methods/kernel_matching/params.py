"""Kernel matching's parameters (:class:`KernelMatchingParams`), its schedule of relative diffusion times
(:func:`diffusion_times`) and the defaults that divergence-free shares (eigenpairs, smallest time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.descriptors import DESCRIPTOR_KINDS
from corrlib.errors import ParameterError
from corrlib.methods.base import param


#: progress bar layout (start, width): DC iterations on the seeds, then the finer scales (the final ZoomOut
#: step reports at :data:`PROGRESS_SMOOTHING`, after them)
PROGRESS_DC = (0.1, 0.6)
PROGRESS_MULTISCALE = (0.7, 0.27)
#: progress fractions of the initial-map computation and of the final smoothing step
PROGRESS_INIT, PROGRESS_SMOOTHING = 0.05, 0.98


#: the default eigenpairs per shape and smallest relative diffusion time (divergence-free's final steps use the
#: same, so that a pair's spectra are shared through the cache and the basis is the same)
DEFAULT_EIGENPAIRS = 500
DEFAULT_TAU_MIN = 5.18e-4
#: the resolution that ``mesh_vertices`` suggests for finer meshes: 500 eigenpairs, of which the smallest default time
#: resolves about 160, are represented accurately on 5,000 vertices (the benchmarks' meshes have 4.3k-7.2k)
SUGGESTED_MESH_VERTICES = 5000


@dataclass(frozen=True, kw_only=True)
class KernelMatchingParams:
    n_eigs: int = param(DEFAULT_EIGENPAIRS, label="Eigenpairs", low=10, high=3000,
                        help="Laplace–Beltrami eigenpairs of the heat kernels (spectral form).")
    init: str = param("best", label="Initialisation", choices=("best", "descriptors", "fmap"),
                      help="Both starts (\"best\"): a linear assignment on descriptors and the functional-maps "
                           "baseline's map, each solved to the end (side by side on two cores); the functional "
                           "map's start is kept only where its final map is better by kernel energy, "
                           "orientation agreement and geodesic distortion alike, or keeps the orientation that "
                           "the other's reverses. Or one of the two alone "
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
