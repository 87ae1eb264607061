"""2D-to-3D elastic matching (thesis ch. 7; Lähner, Rodolà, Schmidt, Bronstein, Cremers, CVPR 2016).

A closed 2D contour is matched to a triangle mesh as a cyclic shortest path on
the product of the contour and the mesh edge graph
(:mod:`corrlib.geometry.cyclic_paths`). The result is a closed curve on the
mesh with the contour point matched at every step.

Features: the contour's interior is triangulated (boundary vertices first)
and the first ``k`` Laplace–Beltrami eigenpairs of the filled silhouette and
of the mesh give (as in the paper's code)

* WKS (100 energies, variance 6, per-scale normalised), then every vertex's
  row divided by its maximum ("row-normalised WKS"), and
* HKS (100 times from ``4 ln10/λ_k`` to ``4 ln10/λ_2``, unnormalised), every
  row divided by its maximum, every column divided by its integral
  ``Σ_x M(x) HKS(x, t)``, and the whole divided by its maximum ("globally
  normalised scaled HKS"),

restricted to the boundary on the contour side. ``features="paper"`` uses
both, ``features="wks"`` (the default) the WKS alone: at large times the HKS
of a flat filled silhouette and of a closed surface follow how their area is
distributed, which differs between the two domains (a thin flat strip and a
thin tube do not cool alike), while every WKS energy is a band of the
spectrum normalised on its own. The node cost is the L1 distance of the
feature vectors, plus ``tau`` where both shapes carry part labels (non-zero)
that differ.

Axis term (ours; ``axis_weight``, 0 gives the paper's node cost): the
spectral features of a flat filled silhouette and of a closed surface differ
everywhere, so alone they do not tell the head end of a silhouette from its
tail end, and the optimum can run along a short stretch of the mesh. Both
shapes share one global, deformation-invariant coordinate: the position along
their longest intrinsic axis (:mod:`corrlib.geometry.intrinsic_axis`), the
continuous counterpart of the thesis' part labels. The node cost gains

    w · c · d̄ · |a_2D(i) − a_3D(j)|,

with the weight ``w``, the confidence ``c`` of the two axes (the smaller of
``1 - λ_1/λ_2`` of the two shapes: no term for round shapes) and the mean
feature distance ``d̄`` (so ``w`` is in units of the node cost). The axis
has no preferred direction, so one branch-and-bound runs over the product
graphs of both ``a_2D`` and ``1 − a_2D`` and keeps the lower energy. A
closed curve on the mesh may run either way, so the contour's orientation
and its mirror image need no extra search. ``axis_modes > 1`` adds the axes
of the next eigenfunctions (:func:`~corrlib.geometry.intrinsic_axis.intrinsic_axis`,
each with the confidence of its own spectral gaps) and searches every
combination of their signs.

Shape model (ours; ``model``): what the filled silhouette is matched as.
A silhouette of a bilaterally symmetric shape seen across its plane of
symmetry (an animal or a person from the side) is one half of the surface,
cut open along its curve of intrinsic symmetry and flattened: the outline
runs along that curve (back, belly, head, tail) and round the near limbs,
and the filled interior is a disk with a free (Neumann) boundary. Functions
on that half are the functions the reflection leaves unchanged, so its
spectrum is the even part of the surface's spectrum
(:mod:`corrlib.descriptors.symmetry`: the reflection from descriptors that
are even and odd under it, then Rayleigh–Ritz on the even subspace).
``model="half"`` computes the mesh features from those even eigenpairs,
so that both sides of every feature distance describe a disk with a
boundary; ``"whole"`` matches the whole closed surface against the
*doubled* silhouette, two copies of the filled outline glued along it (the
near and the far side of the shape; a person seen from the front). Its
spectrum is the union of the Neumann and the Dirichlet spectra of the filled
outline (:func:`~corrlib.geometry.spectrum.doubled_spectrum`), so that both
sides of every feature distance are closed surfaces of the same area and
their eigenvalues cover the same range. ``"auto"`` (default) reads a side
view (below) as the half model, which is what a side view is; any other
view it searches with both models and keeps the lower energy (both measured
in the unit of the whole model, as is the half model of a side view). It uses the whole model alone on a mesh
too coarse for the half model's eigenpairs or without an even subspace. ``"flat"`` compares the filled
outline itself with the whole surface, as the paper does. Half features are the same at a point and
at its mirror image, so the matched curve may pass on either side of the
body, as a silhouette cannot tell them apart either.

Side view (ours; ``view``, ``symmetry_weight``): an outline seen across the
shape's plane of symmetry (an animal from the side, or a section through
that plane) runs along the curve of symmetry except on the limbs, and goes
once round the body keeping one half on the same side
(:mod:`corrlib.descriptors.side_view`). The node cost of such a view gains
``w · c̄ · q(j)``, ``q`` the distance of vertex j to its mirror image (divided
by its mean, 0 on limbs: protrusions that the reflection exchanges), and
every directed mesh edge walked with the near half on the wrong side costs
``w · c̄`` times the negative part of ``(n × t) · ∇g`` (``g`` the lowest odd
eigenfunction, normalised) times its length; ``c̄`` is the mean node cost.
Which half is near is unknown, so every reading is searched with both signs
of ``g``. Without the orientation cost the curve could run out and back
along the back; without the distance cost it could circle a point on a
flank. A view *within* the plane of symmetry (a person from the front, an
animal from above) has an outline that is its own mirror image and that
crosses the curve of symmetry, so it gets neither term: ``view="auto"``
takes an outline for a side view only if it is neither its own mirror image
(:func:`~corrlib.descriptors.side_view.mirror_asymmetry`) nor intrinsically
symmetric (:func:`~corrlib.descriptors.side_view.intrinsic_asymmetry`: a
front view of a posed person is bent, not stretched); that is
``view="outline"``, one reading of a query for every mesh, which is what a
ranking needs (:mod:`corrlib.retrieval`). Matched to one mesh, ``"auto"``
asks the mesh as well: a side view is the natural outline only of a shape
that is thinnest across its plane of symmetry
(:func:`~corrlib.descriptors.side_view.seen_from_the_side`; a quadruped,
not a person, whose bent limbs can make a front view asymmetric in both
senses). The orientation
cost enters the first-order energies (``paper``, ``ratio``); the
second-order graphs take the distance cost only.

Sided front-view curves (``front_curve="sided"``, the default): a view
within the plane of symmetry has an outline that is its own intrinsic
mirror image (:func:`~corrlib.descriptors.side_view.mirror_shift` gives its
reflection), and the curve it is on the surface crosses the curve of
symmetry where the outline crosses its axis and keeps each half of the
outline on its own half of the surface. A free closed curve may instead run
down one flank and back up the same one (both halves of the outline and both
flanks have the same features). With ``"sided"`` the whole model's readings
forbid every match on the wrong half (:mod:`corrlib.geometry.symmetric_paths`;
the sign of the lowest odd eigenfunction), both ways round, and the search
stays exact. On a shape read as a side view, or where the half model wins
on energy (the animals' top views), nothing changes; it matters for people
seen from the front, whose posed outlines the free curve ran down one flank
and back (see ``docs/decisions.md``).

Part term (the thesis' automatic part features; ``parts="auto"``, not the
default): the protrusions of the filled silhouette and of the mesh
(:mod:`corrlib.geometry.segmentation`: heat-kernel persistence, the same
legs, head and tail in every pose) are matched by a small assignment on the
mean node cost of each reading of the axes, and a contour point and a mesh
vertex of parts that were not matched pay ``part_weight · d̄``. User part
labels on both shapes replace it. See ``docs/decisions.md`` for why it is
off by default.

Scale normalisation (our definition, documented because the paper's edge
length mixes 2D and 3D units): the mesh is scaled to unit surface area and
the contour to enclose area ``area_ratio`` (default 1/2: a silhouette covers
roughly one side of the surface). The spectra are rescaled the same way
before the features are computed (the WKS energy range
``log λ_max / 1.02`` is not scale-covariant, so without this the features
would depend on the input units). The matching and its energy therefore do
not depend on the units, position or orientation of either input, and
energies are comparable across meshes (retrieval ranks by them). The half
shape has half the surface's area, the same as the contour's.

Product metric (``metric``): the paper measures a step of the matching that
advances ``a`` along the contour and ``b`` on the mesh by ``sqrt(a² + b²)``,
so a step whose mesh vertex stays costs ``a`` and one that keeps pace ``√2 a``:
every step rewards a shorter curve on the mesh, and where the features do
not tell the true curve from a short one (a section's features rarely do)
the optimum shrinks onto a few vertices. ``metric="max"`` (default) measures
it by ``max(a, b)``: keeping pace costs what standing still costs, and only
stretching beyond the contour's step costs more
(:mod:`corrlib.geometry.cyclic_paths`).

Energies (``energy``): ``paper`` is the CVPR 2016 energy on the first-order
product graph (with ``metric="euclidean"``); ``elastic`` adds stretching, bending and the rule against
immediate reversals on the second-order graph of
:mod:`corrlib.geometry.elastic_paths` (Roetzer, Lähner, Bernard, CVPR 2023),
whose optimum does not collapse onto a few vertices; ``ratio`` divides the
paper's energy (``elastic-ratio``: the elastic energy) by the length of the
contour matched to a moving curve
(:func:`~corrlib.geometry.cyclic_paths.minimum_ratio_union`; Roetzer et al.,
CVPR 2025): a collapsed matching, whose contour points keep their mesh
vertex, earns no length however cheap it is. All are solved to the global
optimum (or a (1 + ε) approximation) by the same branch-and-bound, the ratio
by a parametric (Dinkelbach) sequence of them.

Map convention: ``map_xy[i]`` is the mesh vertex matched to contour point i
(where the path enters that contour point); ``map_yx`` is undefined (None).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, replace

import numba
import numpy as np
import scipy.sparse as sp

from corrlib.descriptors.side_view import (edge_orientation, intrinsic_asymmetry, mirror_asymmetry, mirror_shift,
                                           paired_limbs, seen_from_the_side, symmetry_curve_cost)
from corrlib.descriptors.spectral import hks, wks
from corrlib.descriptors.symmetry import K_FINAL, even_spectrum, mesh_reflection, odd_eigenfunction
from corrlib.errors import ContourError, InputError, MeshError, ParameterError
from corrlib.geometry.cyclic_paths import (GraphTopology, ProductGraph, Relaxation, branch_and_bound_union,
                                           SEARCH_ROUND, minimum_ratio_union)
from corrlib.geometry.remeshing import Remeshed, remeshed
from corrlib.geometry.elastic_paths import ElasticProductGraph
from corrlib.geometry.intrinsic_axis import IntrinsicAxis, axis_mismatch, spectral_axes
from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.geometry.segmentation import assign_parts, protrusion_parts
from corrlib.geometry.spectrum import available_eigenpairs, doubled_spectrum, eigenpairs, mesh_spectrum
from corrlib.geometry.symmetric_paths import sided_cost, symmetry_curve_vertices
from corrlib.geometry.triangulate import fill_contour
from corrlib.methods.base import ContourPath, MatchResult, SearchCertificate, param
from corrlib.methods.registry import MethodSpec, register
from corrlib.progress import Progress, Stopwatch
from corrlib.shapes import Contour2D, TriMesh


#: the shape models that each value of ``model`` matches against
MODELS = {"auto": ("whole", "half"), "half": ("half",), "whole": ("whole",), "flat": ("flat",)}
#: eigenpairs of the mesh per even eigenpair asked for (about half of the eigenfunctions are even)
HALF_EIGENPAIRS_PER_K = 3
#: ``view="auto"``: an outline farther than this from its own mirror image is a side view (measured on the
#: benchmark and retrieval queries: views within the plane of symmetry 0.001–0.025, side views and
#: sections 0.032–0.12; see docs/decisions.md)
SIDE_VIEW_ASYMMETRY = 0.03
#: ``view="auto"``: and farther than this from an intrinsic mirror symmetry (the best reflection of the outline
#: pairs points whose WKS differ by more than a third of what two random points' do; measured on the outlines
#: that are not their own mirror images: posed people from the front 0.12–0.17, side views and sections through
#: the plane of symmetry 0.42–0.81; see docs/decisions.md)
SIDE_VIEW_INTRINSIC_ASYMMETRY = 1 / 3
#: boundary points and eigenpairs at which the intrinsic asymmetry of an outline is measured
VIEW_POINTS, VIEW_K = 200, 25
#: the fewest points a contour is resampled to (the lower bound of ``n_contour``)
MIN_CONTOUR_POINTS = 10
#: the energies on the first-order product graph (the only ones that take directed edge costs)
FIRST_ORDER_ENERGIES = ("paper", "ratio")
#: a matched curve shorter than this fraction of the outline, both at the scale of the match, is reported as
#: collapsed (:func:`short_curve_note`): a warning threshold, below the ratios of curves that follow the outline
#: (measured in ``docs/decisions.md``)
SHORT_CURVE_RATIO = 0.5
#: the resolution meshes are matched at (``mesh_vertices``): the benchmarks' meshes (TOSCA and SHREC's 5k copies,
#: FAUST's 6.9k and the bundled meshes have 4.3k–7.2k vertices) and the speed target (a 200-point query against a
#: 5k mesh in 2 s) are at this size
DEFAULT_MESH_VERTICES = 5000
#: the smallest vertex budget ``mesh_vertices`` accepts (besides 0): the half model needs 75 eigenpairs, and a mesh
#: of fewer vertices would not show a limb
MIN_MESH_VERTICES = 500


@dataclass(frozen=True, kw_only=True)
class Contour3DParams:
    n_contour: int = param(200, label="Contour points", low=MIN_CONTOUR_POINTS, high=2000,
                           help="The contour is resampled by arc length to this many points (the product "
                                "graph has n_contour layers); fewer where the mesh's mean edge is longer "
                                "than that step.")
    mesh_vertices: int = param(DEFAULT_MESH_VERTICES, label="Mesh vertices", low=0, high=10_000_000,
                               help="Every mesh is remeshed to about this many vertices before matching "
                                    "(subdivided first unless finer, quadric edge collapse, then relaxed to even "
                                    "edges), and the curve is reported on its nearest input vertices: the "
                                    "product-graph energy depends on the resolution and the evenness of the mesh, "
                                    "so energies compare across meshes remeshed alike, and a finer graph is "
                                    "slower. 0: match the mesh as given (for man-made meshes with sharp edges, "
                                    "which the relaxation does not keep).")
    k: int = param(25, label="Eigenpairs", low=5, high=500,
                   help="Laplace–Beltrami eigenpairs for HKS/WKS; the paper's sensitivity study chose 25.")
    n_scales: int = param(100, label="Scales", low=2, high=500, help="Times of the HKS and energies of the WKS.")
    wks_variance: float = param(6.0, label="WKS variance", low=0.1, high=100.0,
                                help="WKS band width in units of the energy spacing.")
    eps: float = param(0.0, label="Approximation ε", low=0.0, high=0.9,
                       help="0: global optimum by branch-and-bound; ε > 0 stops once the closed path is "
                            "provably within a factor 1 + ε of the optimum.")
    tau: float = param(1e3, label="Label penalty τ", low=0.0, high=1e9,
                       help="Added to the node cost where contour and mesh part labels (non-zero) differ.")
    fill_density: float = param(1.0, label="Fill density", low=0.25, high=4.0,
                                help="Interior triangulation density of the silhouette relative to its "
                                     "boundary spacing.")
    area_ratio: float = param(0.5, label="Silhouette/surface area", low=0.01, high=10.0,
                              help="The contour is scaled to enclose this fraction of the mesh's surface area "
                                   "(the mesh is scaled to unit area); 1/2: a silhouette covers one side.")
    features: str = param("wks", label="Features", choices=("wks", "paper"),
                          help="Spectral features: the row-normalised WKS, or WKS and scaled HKS as in the "
                               "paper's code.")
    axis_weight: float = param(1.0, label="Axis weight", low=0.0, high=1e3,
                               help="Weight of the intrinsic-axis node cost, in units of the mean feature distance "
                                    "(0: the paper's node cost).")
    axis_modes: int = param(2, label="Axes", low=1, high=4,
                            help="Intrinsic axes (low eigenfunctions) in the axis term; every sign of every axis "
                                 "is searched (2^axes readings per shape model).")
    model: str = param("auto", label="Shape model", choices=("auto", "half", "whole", "flat"),
                       help="What the filled silhouette is matched as: half: one half of the mesh cut along its "
                            "curve of intrinsic symmetry (a view across the plane of symmetry, e.g. an animal "
                            "from the side); whole: the whole surface as the doubled silhouette (near and far "
                            "side, e.g. a person from the front); auto: both, the lower energy wins; flat: the "
                            "filled silhouette against the whole surface (the paper).")
    energy: str = param("paper", label="Energy", choices=("paper", "elastic", "ratio", "elastic-ratio"),
                        help="paper: feature cost times product length (CVPR 2016); elastic: plus stretching, "
                             "bending and no immediate reversal on the curve (second order, Roetzer et al. 2023); "
                             "ratio: the paper's energy per length of the contour matched to a moving curve "
                             "(minimum-ratio cycle, Roetzer et al. 2025); elastic-ratio: the elastic energy per that "
                             "length.")
    stretch: float = param(1.0, label="Stretching weight", low=0.0, high=1e3,
                           help="elastic energy: |3D step − 2D step| in units of the mean node cost.")
    bending: float = param(1.0, label="Bending weight", low=0.0, high=1e3,
                           help="elastic energy: (1 − cos θ) per turn, in units of the mean node cost times the "
                                "mean contour step.")
    view: str = param("auto", label="View", choices=("auto", "outline", "side", "front"),
                      help="side: the outline is seen across the shape's plane of symmetry (an animal from the side, "
                           "or a section through that plane), so it runs along the curve of symmetry except on "
                           "limbs and keeps one half of the shape on one side (the symmetry-curve weight applies); "
                           "front: seen within that plane (a person from the front, an animal from above), no such "
                           "term; outline: side unless the outline is its own mirror image in 2D or intrinsically "
                           "symmetric (a posed front view), one reading for every mesh (retrieval's default); "
                           "auto: side where the outline says so and the mesh is thinnest across its plane of "
                           "symmetry (a quadruped, not a person).")
    symmetry_weight: float = param(1.0, label="Symmetry-curve weight", low=0.0, high=1e3,
                                   help="Side views: cost of a point's distance to its mirror image (off the limbs) "
                                        "and of walking round the body the wrong way, in units of the mean node cost "
                                        "(0: off).")
    parts: str = param("none", label="Part features", choices=("auto", "none"),
                       help="auto: the protrusions of the filled silhouette and of the mesh (heat-kernel persistence) "
                            "are matched by a small assignment and points of non-matching parts pay the part "
                            "weight; user part labels override them. none: no part term.")
    part_weight: float = param(1.0, label="Part weight", low=0.0, high=1e3,
                               help="Cost of matching points of different parts, in units of the mean feature "
                                    "distance.")
    front_curve: str = param("sided", label="Front-view curve", choices=("free", "sided"),
                             help="A view within the plane of symmetry (not a side view) read as the whole surface: "
                                  "sided: each half of the outline (between the crossings of its axis of symmetry) "
                                  "is matched on its own half of the surface, both ways round; free: any closed "
                                  "curve.")
    metric: str = param("max", label="Product metric", choices=("max", "euclidean"),
                        help="Length of a step of the matching on the product graph that advances a along the "
                             "contour and b on the mesh: max(a, b) (a matched curve gains nothing by being shorter "
                             "than the contour) or sqrt(a² + b²) as in the paper (energy=paper with "
                             "metric=euclidean is the CVPR 2016 energy). First-order energies (paper, ratio).")
    max_iterations: int = param(10000, label="Max iterations", low=1, high=10_000_000,
                                help="Cap on branch-and-bound iterations (the bounds are reported).")

    def __post_init__(self):
        if isinstance(self.mesh_vertices, int) and 0 < self.mesh_vertices < MIN_MESH_VERTICES:
            raise ParameterError(f"mesh_vertices must be 0 (match as given) or at least {MIN_MESH_VERTICES}, "
                                 f"got {self.mesh_vertices}")
        if isinstance(self.k, int) and isinstance(self.axis_modes, int) and self.k < self.axis_modes + 2:
            raise ParameterError(f"axis_modes={self.axis_modes} needs at least k={self.axis_modes + 2} eigenpairs "
                                 f"(the eigenvalues around each axis give its confidence), got k={self.k}")


def row_normalised_wks(evals: np.ndarray, evecs: np.ndarray, n_scales: int = 100,
                       wks_variance: float = 6.0) -> np.ndarray:
    """WKS, every vertex's row divided by its maximum ((n, n_scales) float)."""
    w = wks(evals, evecs, n_scales, variance=wks_variance)
    return w / np.maximum(w.max(axis=1, keepdims=True), 1e-300)


def scaled_hks(evals: np.ndarray, evecs: np.ndarray, mass_diag: np.ndarray, n_scales: int = 100) -> np.ndarray:
    """Globally normalised scaled HKS of the paper's code ((n, n_scales) float, see the module docstring)."""
    h = hks(evals, evecs, n_scales, normalize="none")
    h = h / np.maximum(h.max(axis=1, keepdims=True), 1e-300)
    h = h / np.maximum(mass_diag @ h, 1e-300)[None, :]
    return h / max(h.max(), 1e-300)


def paper_features(evals: np.ndarray, evecs: np.ndarray, mass_diag: np.ndarray, n_scales: int = 100,
                   wks_variance: float = 6.0) -> np.ndarray:
    """Row-normalised WKS and globally normalised scaled HKS (see the module docstring).

    Parameters
    ----------
    evals : (k,) float
    evecs : (n, k) float
    mass_diag : (n,) float
        Lumped vertex areas.

    Returns
    -------
    (n, 2 * n_scales) float
    """
    return np.hstack([row_normalised_wks(evals, evecs, n_scales, wks_variance),
                      scaled_hks(evals, evecs, mass_diag, n_scales)])


def spectral_features(evals: np.ndarray, evecs: np.ndarray, mass_diag: np.ndarray,
                      params: "Contour3DParams") -> np.ndarray:
    """The features chosen by ``params.features`` ((n, d) float)."""
    if params.features == "wks":
        return row_normalised_wks(evals, evecs, params.n_scales, params.wks_variance)
    return paper_features(evals, evecs, mass_diag, params.n_scales, params.wks_variance)


@numba.njit(parallel=True, cache=True, nogil=True)
def _l1_costs(feat_a, feat_b, out):
    for i in numba.prange(feat_a.shape[0]):
        for j in range(feat_b.shape[0]):
            acc = 0.0
            for d in range(feat_a.shape[1]):
                acc += abs(feat_a[i, d] - feat_b[j, d])
            out[i, j] = acc


def feature_distances(feat_contour: np.ndarray, feat_mesh: np.ndarray) -> np.ndarray:
    """(m, n) float: L1 distances between contour and mesh feature vectors."""
    a = np.ascontiguousarray(feat_contour, dtype=np.float64)
    b = np.ascontiguousarray(feat_mesh, dtype=np.float64)
    if a.shape[1] != b.shape[1]:
        raise InputError(f"feature dimensions differ: {a.shape[1]} vs {b.shape[1]}")
    out = np.empty((a.shape[0], b.shape[0]))
    _l1_costs(a, b, out)
    return out


def mean_feature_distance(feat_contour: np.ndarray, feat_mesh: np.ndarray) -> float:
    """The mean of :func:`feature_distances` without the (m, n) matrix.

    The mean L1 distance is the sum over feature dimensions of the mean
    ``|a_i − b_j|`` of two sets of numbers, which sorting gives exactly:
    ``Σ_j |a − b_j| = a (2 r − n) − 2 Σ_{b_j < a} b_j + Σ_j b_j`` with ``r``
    the number of ``b_j`` below ``a``. O(d (n + m) log n) instead of O(m n d).
    """
    a = np.asarray(feat_contour, dtype=np.float64)
    b = np.sort(np.asarray(feat_mesh, dtype=np.float64), axis=0)
    if a.shape[1] != b.shape[1]:
        raise InputError(f"feature dimensions differ: {a.shape[1]} vs {b.shape[1]}")
    m, n = a.shape[0], b.shape[0]
    total = 0.0
    for dim in range(a.shape[1]):
        column = b[:, dim]
        below_sum = np.concatenate([[0.0], np.cumsum(column)])
        below = np.searchsorted(column, a[:, dim])
        total += float(np.sum(a[:, dim] * (2 * below - n) - 2 * below_sum[below] + below_sum[-1]))
    return total / (m * n)


def label_penalty(labels_contour, labels_mesh, tau: float) -> np.ndarray | float:
    """(m, n) float: ``tau`` where both part labels are non-zero and differ (0. without labels)."""
    if labels_contour is None or labels_mesh is None:
        return 0.0
    lc = np.asarray(labels_contour)[:, None]
    lm = np.asarray(labels_mesh)[None, :]
    return tau * ((lc != lm) & (lc != 0) & (lm != 0))


def node_costs(feat_contour: np.ndarray, feat_mesh: np.ndarray, labels_contour=None, labels_mesh=None,
               tau: float = 1e3) -> np.ndarray:
    """(m, n) float: the paper's node cost, L1 feature distances plus ``tau`` where part labels differ."""
    return feature_distances(feat_contour, feat_mesh) + label_penalty(labels_contour, labels_mesh, tau)


@dataclass
class PreparedQuery:
    """A contour ready for matching: normalised points and features (reusable across meshes).

    Attributes
    ----------
    points : (m, 2) float
        Contour points scaled to enclose area 1/2 and centred.
    features : (m, d) float
        Features of the filled silhouette (a disk with a free boundary), the
        half model's.
    labels : (m,) int or None
    contour : Contour2D
        The resampled input contour (original units).
    axes : dict of str -> list of IntrinsicAxis
        Per shape model, the intrinsic axes (modes ``1 .. axis_modes``) of the
        filled silhouette (half) or of the doubled silhouette (whole) at the
        contour points ((m,) coordinates).
    doubled_features : (m, d) float or None
        Features of the doubled silhouette, the whole model's (None if the
        query was prepared for the half model only).
    parts : (m,) int or None
        Protrusions of the filled silhouette at the contour points (0: body;
        None unless ``parts="auto"``).
    asymmetry : float
        :func:`~corrlib.descriptors.side_view.mirror_asymmetry` of the outline
        (0: its own mirror image, a view within the plane of symmetry).
    intrinsic_asymmetry : float
        :func:`~corrlib.descriptors.side_view.intrinsic_asymmetry` of the
        outline's WKS (0: intrinsically symmetric, e.g. a posed person from
        the front).
    source : Contour2D or None
        The contour as given, before resampling: a mesh coarser than the
        contour's step asks for fewer points (:func:`query_for_mesh`).
    """

    points: np.ndarray
    features: np.ndarray
    labels: np.ndarray | None
    contour: Contour2D
    axes: dict[str, list[IntrinsicAxis]]
    doubled_features: np.ndarray | None = None
    parts: np.ndarray | None = None
    asymmetry: float = 0.0
    intrinsic_asymmetry: float = 0.0
    source: Contour2D | None = None

    @functools.cached_property
    def reflection_shift(self) -> int:
        """The outline's best intrinsic reflection ``i ↦ (s − i) mod m`` at the matching's points
        (:func:`~corrlib.descriptors.side_view.mirror_shift` of ``features``), computed once when the sided
        front-view curves ask for it."""
        return mirror_shift(self.features)

    def is_side_view(self, params: "Contour3DParams") -> bool:
        """Whether the outline is read as a side view: ``view``, or for ``outline`` and ``auto`` an outline that
        is neither its own mirror image nor intrinsically symmetric (see :mod:`corrlib.descriptors.side_view`;
        ``auto`` also asks the mesh, in :func:`match_prepared`)."""
        if params.symmetry_weight == 0.0 or params.view == "front":
            return False
        return params.view == "side" or (self.asymmetry > SIDE_VIEW_ASYMMETRY
                                         and self.intrinsic_asymmetry > SIDE_VIEW_INTRINSIC_ASYMMETRY)

    def model_features(self, model: str) -> np.ndarray:
        """(m, d) float: the contour's features under a shape model (see the module docstring)."""
        if model in ("half", "flat"):
            return self.features
        if self.doubled_features is None:
            raise ParameterError("the query was prepared without the whole-surface model's features; prepare it "
                                 "with model='whole' or 'auto'")
        return self.doubled_features


@dataclass
class PreparedMesh:
    """A mesh ready for matching.

    Attributes
    ----------
    vertices : (n, 3) float
        Centred and scaled to unit surface area.
    features : dict of str -> (n, d) float
        The features of every shape model asked for (``"whole"``, ``"half"``).
    axes : dict of str -> list of IntrinsicAxis
        Per shape model, the intrinsic axes of the surface (whole) or of its
        even eigenfunctions (half).
    parts : (n,) int or None
        Protrusions of the surface (0: body; None unless ``parts="auto"``).
    """

    vertices: np.ndarray
    features: dict[str, np.ndarray]
    axes: dict[str, list[IntrinsicAxis]]
    parts: np.ndarray | None = None


def prepare_query(contour: Contour2D, params: Contour3DParams,
                  finer: str = "raise n_contour or fill_density", *, view_measures: bool = True) -> PreparedQuery:
    """Resample, normalise and compute features of a query contour.

    Part labels of the contour (``contour.labels``), if any, follow the
    resampling (label of the segment each new point falls on). ``finer`` tells the user how to make the
    filled outline finer, in the parameters of the method that asks (contour2d has its own).
    ``view_measures=False`` skips the outline's intrinsic asymmetry (left at 0), which only the choice of a
    view reads (:meth:`PreparedQuery.is_side_view`): 2D-to-2D matching does not.
    """
    if not isinstance(contour, Contour2D):
        raise InputError(f"the query must be a Contour2D, got {type(contour).__name__}")
    if contour.n_points < 10:
        raise ContourError(f"{contour.name}: the contour has {contour.n_points} points; at least 10 are needed")
    resampled, canonical = canonical_outline(contour, params.n_contour, params.area_ratio)
    filled = fill_contour(canonical, density=params.fill_density)
    stiffness, mass = mesh_laplacian(filled)
    if filled.n_vertices <= params.k:
        raise ContourError(f"{contour.name}: the filled silhouette has {filled.n_vertices} vertices, too few for "
                           f"k={params.k} eigenpairs; {finer}, or lower k")
    try:
        evals, evecs = eigenpairs(stiffness, mass, params.k, name=contour.name)
    except InputError as exc:  # a triangulation of a polygon is connected: only slivers of no area cut it apart
        raise ContourError(f"{contour.name}: the outline is too thin somewhere to be filled: triangles of no area "
                           f"cut its triangulation apart ({str(exc).removeprefix(contour.name + ': ')}); draw it "
                           "wider there") from exc
    feats = spectral_features(evals, evecs, mass.diagonal(), params)
    m = canonical.n_points
    doubled = None
    axes = {"half": _axes_at(spectral_axes(evals, evecs, mass.diagonal(), params.axis_modes), m)}
    axes["flat"] = axes["half"]
    if "whole" in MODELS[params.model]:
        d_evals, d_evecs = doubled_spectrum(stiffness, mass, np.arange(m), params.k, neumann=(evals, evecs),
                                            name=contour.name)
        doubled = spectral_features(d_evals, d_evecs, mass.diagonal(), params)[:m]
        axes["whole"] = _axes_at(spectral_axes(d_evals, d_evecs, mass.diagonal(), params.axis_modes), m)
    parts = None
    if params.parts == "auto":
        parts = protrusion_parts(evals, evecs, filled.adjacency, params.area_ratio).labels[:m]
    if not view_measures:
        intrinsic = 0.0
    elif (m, params.k, params.fill_density) == (VIEW_POINTS, VIEW_K, 1.0):  # the view's own setting: reuse
        intrinsic = intrinsic_asymmetry(row_normalised_wks(evals, evecs)[:m])
    else:
        intrinsic = outline_intrinsic_asymmetry(contour, params.area_ratio)
    return PreparedQuery(canonical.points, feats[:m], resampled.labels, resampled, axes, doubled, parts,
                         mirror_asymmetry(canonical.points), intrinsic, contour)


def contour_points_for(query: PreparedQuery, mesh: TriMesh) -> int:
    """How many contour points have a step no shorter than the mesh's mean edge (both shapes at the matching's
    scale: the mesh at unit area, the outline enclosing ``area_ratio``).

    A step of the product graph along a mesh edge of length ``b`` that advances the contour by ``a`` costs
    ``c · max(a, b)`` (the max metric). Where the mesh's edges are longer than the contour's step, no step
    keeps pace: the path also needs steps along the contour alone, and each unit of length on the mesh costs
    ``1 − a/b`` on top of the contour's length, a pressure towards short curves on the mesh that the continuous
    energy does not have. A contour at least as coarse as the mesh has a step that keeps pace on a typical edge.

    Parameters
    ----------
    query : PreparedQuery
    mesh : TriMesh
    """
    closed = np.vstack([query.points, query.points[:1]])
    length = float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())
    return int(length / mesh.relative_edge_length)


def query_for_mesh(query: PreparedQuery, mesh: TriMesh, params: Contour3DParams) -> PreparedQuery:
    """The query itself, or where the mesh is coarser than its step, the same contour prepared with
    :func:`contour_points_for` points (kept where so few points leave the filled silhouette too few vertices
    for its eigenpairs)."""
    n_points = max(contour_points_for(query, mesh), MIN_CONTOUR_POINTS)
    if n_points >= len(query.points) or query.source is None:
        return query
    try:
        return prepare_query(query.source, replace(params, n_contour=n_points))
    except ContourError:
        return query


def canonical_outline(contour: Contour2D, n_points: int, area_ratio: float) -> tuple[Contour2D, Contour2D]:
    """The contour counter-clockwise, resampled by arc length to ``n_points``, and the same in canonical pose
    and scale (centred, principal axes, enclosing ``area_ratio``; axis signs fixed by third moments, a
    reflection that keeps every length and the intrinsic geometry): the triangulation of the canonical
    outline, hence its features, do not depend on the input's position, orientation or units."""
    resampled = contour.ccw().resample(n_points)
    if not resampled.area > 0:  # a contour made without validation (Contour2D(validate=False)) may fold flat
        raise ContourError(f"{contour.name}: the contour encloses no area (it folds back on itself)")
    pts = resampled.points - resampled.points.mean(axis=0)
    pts = pts * np.sqrt(area_ratio / resampled.area)
    _, _, vt = np.linalg.svd(pts, full_matrices=False)
    rotated = pts @ vt.T
    rotated *= np.where(np.sum(rotated ** 3, axis=0) < 0, -1.0, 1.0)
    return resampled, Contour2D(rotated, name=contour.name, validate=False, labels=resampled.labels)


def outline_intrinsic_asymmetry(contour: Contour2D, area_ratio: float = 0.5) -> float:
    """:func:`~corrlib.descriptors.side_view.intrinsic_asymmetry` of a closed outline, from the default WKS
    of its filled interior at :data:`VIEW_POINTS` boundary points and :data:`VIEW_K` eigenpairs.

    The view is a property of the outline, so it is measured at one resolution with one descriptor whatever
    the matching's ``n_contour``, ``k``, ``features`` and ``fill_density`` (coarser outlines have a higher
    floor: a symmetric outline reads 0.05 at 200 points and up to 0.2 at 100), on the canonical outline
    (:func:`canonical_outline`), so that its triangulation does not depend on the input's pose or units.
    :func:`prepare_query` at those settings computes the same eigenpairs and reuses them.
    """
    _, outline = canonical_outline(contour, VIEW_POINTS, area_ratio)
    filled = fill_contour(outline)
    stiffness, mass = mesh_laplacian(filled)
    evals, evecs = eigenpairs(stiffness, mass, VIEW_K, name=contour.name)
    return intrinsic_asymmetry(row_normalised_wks(evals, evecs)[:VIEW_POINTS])


def _axes_at(axes: list[IntrinsicAxis], m: int) -> list[IntrinsicAxis]:
    """The axes restricted to the first ``m`` vertices (the contour points of a filled silhouette)."""
    return [IntrinsicAxis(axis.coordinate[:m], axis.confidence) for axis in axes]


def prepare_mesh(mesh: TriMesh, params: Contour3DParams) -> PreparedMesh:
    """Mesh vertices scaled to unit area, their features and the mesh's intrinsic axis."""
    if not isinstance(mesh, TriMesh):
        raise InputError(f"the target must be a TriMesh, got {type(mesh).__name__}")
    if mesh.n_vertices <= params.k:
        raise InputError(f"{mesh.name}: {mesh.n_vertices} vertices are too few for k={params.k} Laplace–Beltrami "
                         f"eigenpairs (at most {mesh.n_vertices - 1}); lower k or use a finer mesh")
    models = MODELS[params.model]
    k_mesh = params.k if "half" not in models else max(HALF_EIGENPAIRS_PER_K * params.k, K_FINAL)
    if mesh.n_vertices <= k_mesh:
        if params.model == "half":
            raise InputError(f"{mesh.name}: {mesh.n_vertices} vertices are too few for the {k_mesh} eigenpairs "
                             f"that model='half' needs; use model='whole', lower k or a finer mesh")
        models, k_mesh = ("whole",), params.k  # auto: only the whole model fits so coarse a mesh
    spectrum = mesh_spectrum(mesh, k_mesh)
    mass = spectrum.mass.diagonal()
    features = {}
    axes = {}
    # eigenvalues of the mesh scaled to unit area (see the module docstring)
    for model in {"whole", "flat"}.intersection(models):  # the closed surface's own eigenpairs
        features[model] = spectral_features(spectrum.evals[:params.k] * mesh.area, spectrum.evecs[:, :params.k],
                                            mass, params)
        axes[model] = spectral_axes(spectrum.evals[:params.k], spectrum.evecs[:, :params.k], mass,
                                    params.axis_modes)
    if "half" in models:
        try:
            evals, evecs = even_spectrum(spectrum, mesh_reflection(mesh, spectrum), params.k)
        except ParameterError as err:  # a shape far from any left-right symmetry
            if params.model == "half":
                raise InputError(f"{mesh.name}: {err}; use model='whole' or 'auto', or lower k") from None
            evals = None  # auto: the whole model alone
        if evals is not None:
            features["half"] = spectral_features(evals * mesh.area, evecs, mass, params)
            axes["half"] = spectral_axes(evals, evecs, mass, params.axis_modes)
    verts = (mesh.vertices - mesh.vertices.mean(axis=0)) / np.sqrt(mesh.area)
    parts = None
    if params.parts == "auto":
        parts = protrusion_parts(spectrum.evals, spectrum.evecs, mesh.adjacency, mesh.area).labels
    return PreparedMesh(verts, features, axes, parts)


@dataclass
class SideViewTerms:
    """A mesh's side-view terms (:mod:`corrlib.descriptors.side_view`).

    Attributes
    ----------
    curve_cost : (n,) float
        Distance to the mirror image divided by its mean, 0 on limbs.
    orientation : (n, n) sparse
        ``(n̂ × t) · ∇g / mean |∇g|`` of every directed edge (``g`` the lowest
        odd eigenfunction): positive where the edge keeps ``g > 0`` on its left.
    """

    curve_cost: np.ndarray
    orientation: sp.csr_matrix

    def wrong_way(self, sign: float) -> sp.csr_matrix:
        """(n, n) sparse ≥ 0: the part of ``sign · orientation`` below zero, per directed edge."""
        out = self.orientation.copy()
        out.data = np.maximum(0.0, -sign * out.data)
        return out


def _mesh_reflection(mesh: TriMesh, params: Contour3DParams):
    """(spectrum, mirror) of a mesh for the side-view terms and the sided front-view curves, or None on a mesh
    too coarse for the eigenpairs the reflection needs (both cached on disk by mesh content)."""
    k_mesh = max(HALF_EIGENPAIRS_PER_K * params.k, K_FINAL)
    if mesh.n_vertices <= k_mesh:
        return None
    spectrum = mesh_spectrum(mesh, k_mesh)
    return spectrum, mesh_reflection(mesh, spectrum)


def side_view_terms(mesh: TriMesh, params: Contour3DParams) -> SideViewTerms | None:
    """The side-view terms of a mesh, or None where it has no usable reflection (too coarse for the
    eigenpairs, no odd eigenfunction, a reflection that fixes every vertex); the match then goes on without
    them and says so (``extras["view"] == "front"``)."""
    reflection = _mesh_reflection(mesh, params)
    if reflection is None:
        return None
    spectrum, mirror = reflection
    try:
        odd = odd_eigenfunction(spectrum, mirror)
        limbs = paired_limbs(protrusion_parts(spectrum.evals, spectrum.evecs, mesh.adjacency, mesh.area).labels,
                             mirror)
        return SideViewTerms(symmetry_curve_cost(mesh.vertices, mirror, limbs),
                             edge_orientation(mesh.vertices, mesh.faces, mesh.adjacency, odd))
    except (ParameterError, InputError):  # no reflection to speak of
        return None


def mesh_seen_from_side(mesh: TriMesh, params: Contour3DParams) -> bool | None:
    """Whether the mesh is thinnest across its plane of symmetry, so that its natural outline is a side view
    (:func:`~corrlib.descriptors.side_view.seen_from_the_side`), or None where it has no reflection (too coarse
    for the eigenpairs)."""
    reflection = _mesh_reflection(mesh, params)
    if reflection is None:
        return None
    spectrum, mirror = reflection
    return seen_from_the_side(mesh.vertices, mirror, spectrum.mass.diagonal())


@dataclass
class MeshSymmetry:
    """A mesh's halves for front views (:mod:`corrlib.geometry.symmetric_paths`).

    Attributes
    ----------
    odd : (n,) float
        The lowest odd eigenfunction: one sign on each half, zero on the curve of symmetry.
    on_curve : (n,) bool
        Vertices next to the curve of symmetry (where ``odd`` changes sign).
    """

    odd: np.ndarray
    on_curve: np.ndarray


def mesh_symmetry(mesh: TriMesh, params: Contour3DParams) -> MeshSymmetry | None:
    """The mesh's halves, or None where it has no usable reflection (too coarse for the eigenpairs, no odd
    eigenfunction); front views are then matched by free closed curves."""
    reflection = _mesh_reflection(mesh, params)
    if reflection is None:
        return None
    try:
        odd = odd_eigenfunction(*reflection)
    except (ParameterError, InputError):
        return None
    if not (np.all(np.isfinite(odd)) and (odd > 0).any() and (odd < 0).any()):
        return None
    return MeshSymmetry(odd, symmetry_curve_vertices(mesh.adjacency, odd))


def _near_halves(side: SideViewTerms | None, params: Contour3DParams) -> tuple[float, ...]:
    """Signs of the odd function searched: both halves where the orientation cost enters the graph, one
    where only the distance cost does (the elastic energies: both signs would give the same graph), none
    (0) without side-view terms."""
    if side is None:
        return (0.0,)
    return (1.0, -1.0) if params.energy in FIRST_ORDER_ENERGIES else (1.0,)


def axis_scales(query: PreparedQuery, mesh: PreparedMesh, model: str, mean_distance: float,
                params: Contour3DParams) -> np.ndarray:
    """Factors ``w c_d d̄`` of the axis terms of one shape model ((axis_modes,) float; 0 turns a term off)."""
    confidence = np.array([min(a.confidence, b.confidence) for a, b in zip(query.axes[model], mesh.axes[model])])
    return params.axis_weight * confidence * mean_distance


def axis_cost(query: PreparedQuery, mesh: PreparedMesh, model: str, scales: np.ndarray,
              signs: tuple[bool, ...], terms: dict | None = None) -> np.ndarray | float:
    """``Σ_d w c_d d̄ |a_d(i) − b_d(j)|`` ((m, n) float) for one reading of the axes' signs (True: reversed).

    ``terms`` (optional, initially empty) keeps every axis's term by ``(model, axis, reversed)`` for the
    next reading of the same query and mesh.
    """
    terms = {} if terms is None else terms
    cost = 0.0
    for axis, (scale, flipped, a, b) in enumerate(zip(scales, signs, query.axes[model], mesh.axes[model])):
        if scale > 0:
            key = (model, axis, bool(flipped))
            if key not in terms:
                terms[key] = scale * axis_mismatch(a.coordinate, b.coordinate, flipped=flipped)
            cost = cost + terms[key]
    return cost


def part_cost(query: PreparedQuery, mesh: PreparedMesh, cost: np.ndarray, mean_distance: float,
              params: Contour3DParams) -> np.ndarray | float:
    """``w_p d̄`` where the contour's part, matched to the mesh's parts under ``cost``, differs ((m, n) float).

    The protrusions are matched by :func:`~corrlib.geometry.segmentation.assign_parts`
    on the node cost of the reading (features and axis term), so that each
    reading of the axes gets the part matching that agrees with it. A
    protrusion of the contour without a partner costs nothing anywhere.
    """
    if query.parts is None or mesh.parts is None or params.part_weight == 0.0:
        return 0.0
    as_mesh = assign_parts(cost, query.parts, mesh.parts)[:, None]
    return params.part_weight * mean_distance * ((as_mesh >= 0) & (as_mesh != mesh.parts[None, :]))


def product_graph(cost: np.ndarray, contour_points: np.ndarray, mesh_vertices: np.ndarray, adjacency,
                  params: Contour3DParams, unit_cost: float, edge_penalty=None,
                  topology: GraphTopology | None = None) -> ProductGraph:
    """The product graph of the chosen energy.

    The elastic weights are unit-free: the stretching weight is in units of
    ``unit_cost``, the mean node cost without the axis term (a unit of length
    mismatch costs as much as a unit of length matched at the mean feature
    distance), the bending weight in units of ``unit_cost`` times the mean
    contour step. Both readings of the axis therefore get the same weights.
    ``edge_penalty`` (directed, per unit length; the side view's wrong-way
    cost) enters the first-order graphs; the second-order graphs of the
    elastic energies do not take it. ``topology``: the mesh graph's arrays,
    built once for all the readings of a match (first-order graphs).
    """
    if params.energy in FIRST_ORDER_ENERGIES:
        return ProductGraph(cost, contour_points, mesh_vertices, adjacency, edge_penalty=edge_penalty,
                            metric=params.metric, topology=topology)
    step = float(np.mean(np.linalg.norm(np.roll(contour_points, -1, axis=0) - contour_points, axis=1)))
    return ElasticProductGraph(cost, contour_points, mesh_vertices, adjacency, stretch=params.stretch * unit_cost,
                               bending=params.bending * unit_cost * step)


def relaxation_tree(graphs: list[ProductGraph], readings: list[tuple]) -> list[Relaxation]:
    """Lower-bounding graphs for the search: one per shape model over all its readings.

    The readings of one model share the feature distances and differ by the
    axis and side-view terms, so their element-wise cheapest costs (without
    the directed penalties) bound them all; a model that cannot win then
    costs one backward search instead of one per reading, and the others'
    searches skip what the first closed path beats
    (:func:`~corrlib.geometry.cyclic_paths.branch_and_bound_union`).
    """
    roots = []
    for model in dict.fromkeys(reading[0] for reading in readings):
        members = [index for index, reading in enumerate(readings) if reading[0] == model]
        if len(members) > 1:
            roots.append(Relaxation(ProductGraph.relaxation([graphs[i] for i in members]), members))
    return roots


def _view_models(models, side_view: bool) -> list[str]:
    """The shape models a view is read as: a side view is the half model (an outline seen across the plane
    of symmetry is one half of the surface, see the module docstring) where the mesh has one; any other view,
    every model asked for."""
    if side_view and "half" in models:
        return ["half"]
    return list(models)


def match_prepared(query: PreparedQuery, mesh: TriMesh, params: Contour3DParams, token, *,
                   as_given_if_unremeshable: bool = True):
    """Solver generator for a prepared query against one mesh (see :func:`solve_contour3d`).

    The mesh is matched remeshed to ``params.mesh_vertices`` vertices
    (:func:`~corrlib.geometry.remeshing.remeshed`), and the map and the curve are reported on the input
    vertices nearest to the remeshed ones (``extras["matched_vertices"]`` says how many were matched). Where
    the remeshing cannot give a valid mesh, the mesh is matched as given and ``extras["remeshing_failed"]``
    says why (:func:`remeshing_note`); ``as_given_if_unremeshable=False`` raises the remeshing's
    :class:`~corrlib.errors.MeshError` instead (a ranking, whose energies compare only between meshes remeshed
    alike). A mesh too small for a spectrum of its own (a tetrahedron) is refused: the curve is reported on
    its vertices, and on four vertices every contour point lands on one.
    """
    available_eigenpairs(mesh, params.k, "2D-to-3D matching")
    if not params.mesh_vertices:
        return (yield from _match_mesh(query, mesh, params, token))
    try:
        coarse = remeshed(mesh, params.mesh_vertices)
    except MeshError as err:
        if not as_given_if_unremeshable:
            raise
        result = yield from _match_mesh(query, mesh, params, token)
        return replace(result, extras={**result.extras, "remeshing_failed": str(err)})
    result = yield from _match_mesh(query, coarse.mesh, params, token)
    return on_input_vertices(result, coarse)


def curve_length_ratio(mesh_vertices: np.ndarray, path_vertices: np.ndarray, outline_length: float) -> float:
    """Length of the matched closed curve over the length of the outline, both at the scale of the match.

    Parameters
    ----------
    mesh_vertices : (n, 3) float
        The mesh scaled to unit area (:class:`PreparedMesh`).
    path_vertices : (p,) int
        The matched curve's vertices in order (a vertex repeats where the curve stays on it; the last joins the
        first).
    outline_length : float
        The query's length in canonical pose, enclosing ``area_ratio`` of the unit area
        (:attr:`~corrlib.geometry.cyclic_paths.ProductGraph.curve_length`).

    A curve that follows the outline round the surface is about as long as the outline at this scale, the
    scale at which the filled outline is the part of the surface it shows; a curve crowded onto a limb or a
    flank, which no feature of the outline told from its true place, is much shorter
    (:func:`short_curve_note`).
    """
    closed_path = np.r_[path_vertices, path_vertices[:1]]
    curve = float(np.linalg.norm(np.diff(mesh_vertices[closed_path], axis=0), axis=1).sum())
    return curve / max(outline_length, 1e-300)


def curve_collapsed(ratio: float | None) -> bool:
    """Whether a matched curve of :func:`curve_length_ratio` ``ratio`` is short enough to have collapsed (below
    :data:`SHORT_CURVE_RATIO`; an unknown ratio, None or NaN, is not)."""
    return ratio is not None and ratio < SHORT_CURVE_RATIO


def short_curve_note(extras: dict) -> str | None:
    """A warning when the matched curve is shorter than :data:`SHORT_CURVE_RATIO` of the outline
    (:func:`curve_length_ratio`), else None: the search proves the curve optimal for the energy, not that the
    energy found the outline's place."""
    ratio = (extras or {}).get("curve_length_ratio")
    if not curve_collapsed(ratio):
        return None
    return (f"the matched curve is {ratio:.2f} of the outline's length at the scale of the match: it has probably "
            "collapsed onto a part of the mesh instead of running round the outline's place (the curve is optimal "
            "for the energy, whose features did not find that place on this mesh); a mesh in the pose of the "
            "drawing matches more reliably through its rendered views (method contour-views)")


def remeshing_note(extras: dict) -> str | None:
    """What the user is told when the target could not be remeshed to ``mesh_vertices`` and was matched as
    given (:func:`match_prepared`), else None: its energy does not compare with those of meshes remeshed
    alike."""
    reason = (extras or {}).get("remeshing_failed")
    if not reason:
        return None
    return (f"the target could not be remeshed ({reason}); it was matched at its own resolution, so its energy "
            "does not compare with those of meshes remeshed to the budget (mesh_vertices=0 matches every mesh "
            "as given)")


def on_input_vertices(result: MatchResult, coarse: Remeshed) -> MatchResult:
    """A match on a remeshed mesh with its map and curve on the input mesh's vertices."""
    to_original = coarse.to_original
    path = replace(result.path, vertices=to_original[result.path.vertices])
    extras = {**result.extras, "matched_vertices": coarse.mesh.n_vertices, "input_vertices": coarse.n_original}
    meaning = (f"{result.energy_meaning}, on the mesh remeshed from {coarse.n_original} to "
               f"{coarse.mesh.n_vertices} vertices")
    return replace(result, map_xy=to_original[result.map_xy], path=path, extras=extras, energy_meaning=meaning)


def reading_extras(model: str, signs: tuple, near: float, side_view: bool, sided: bool) -> dict:
    """How the winning reading read the query: its shape model, the signs of its axes (``axis_reversed``: the
    first), the view, the near half of a side view and whether a front view was matched half by half."""
    return {"axis_reversed": bool(signs[0]) if signs else False, "axis_signs": [bool(s) for s in signs],
            "model": model, "view": "side" if side_view else "front", "near_half": int(near),
            "sided": sided and model == "whole"}


def _match_mesh(query: PreparedQuery, mesh: TriMesh, params: Contour3DParams, token):
    """:func:`match_prepared` on the mesh as given."""
    watch = Stopwatch()
    yield Progress("mesh features", 0.05)
    with watch("features"):
        target = prepare_mesh(mesh, params)
        query = query_for_mesh(query, mesh, params)
        # view=auto: a side view by the outline is one only on a mesh seen from the side (a person in profile is
        # rarely drawn); None where the mesh was not asked
        seen_from_side = (mesh_seen_from_side(mesh, params)
                          if params.view == "auto" and query.is_side_view(params) else None)
        side = (side_view_terms(mesh, params)
                if query.is_side_view(params) and seen_from_side is not False else None)
        labels = label_penalty(query.labels, mesh.labels, params.tau)
        # one unit for every model, so that their energies compare: the mean distance of the first model
        # asked for (also where a side view reads the half model alone)
        first_model = next(iter(target.features))
        unit_distance = mean_feature_distance(query.model_features(first_model), target.features[first_model])
        unit_cost = unit_distance + float(np.mean(labels))
        distances = {model: feature_distances(query.model_features(model), target.features[model])
                     for model in _view_models(target.features, side is not None)}
        scales = {model: axis_scales(query, target, model, unit_distance, params) for model in distances}
        axis_terms: dict = {}  # the axis terms, shared by the readings
    token.raise_if_cancelled()
    # an axis has no direction, a front view's model is chosen by energy, and which half of a side view is near is
    # unknown (the sign of the orientation term): one branch-and-bound over every combination
    # a front view read as the whole surface: its halves on the two halves of the surface, either way round
    sided = None
    if side is None and params.front_curve == "sided" and "whole" in distances:
        with watch("features"):
            sided = mesh_symmetry(mesh, params)
    readings = [(model, signs, near) for model in distances
                for signs in itertools.product(*[(False, True) if scale > 0 else (False,)
                                                 for scale in scales[model]])
                for near in (_near_halves(side, params) if sided is None or model != "whole" else (1.0, -1.0))]
    graphs = []
    topology = GraphTopology.of(target.vertices, mesh.adjacency)
    for model, signs, near in readings:
        cost = distances[model] + labels + axis_cost(query, target, model, scales[model], signs, axis_terms)
        if not isinstance(labels, np.ndarray):  # user part labels on both shapes replace the automatic parts
            cost = cost + part_cost(query, target, cost, unit_distance, params)
        if sided is not None and model == "whole":
            cost = sided_cost(cost, query.reflection_shift, sided.odd, sided.on_curve, near)
        penalty = None
        if side is not None:
            weight = params.symmetry_weight * unit_cost
            cost = cost + weight * side.curve_cost[None, :]
            if params.energy in FIRST_ORDER_ENERGIES:
                penalty = weight * side.wrong_way(near)
        graphs.append(product_graph(cost, query.points, target.vertices, mesh.adjacency, params, unit_cost,
                                    edge_penalty=penalty, topology=topology))
    yield Progress("branch and bound", 0.1, f"{graphs[0].m} x {graphs[0].n} product graph, {len(graphs)} readings "
                                            "(shape model, direction of the axis, half of the surface)")
    with watch("search"):
        search = minimum_ratio_union if params.energy.endswith("ratio") else branch_and_bound_union
        # graphs that fit in one round of backward searches gain nothing from relaxations
        relaxed = params.energy in FIRST_ORDER_ENERGIES and len(graphs) > SEARCH_ROUND
        relaxations = relaxation_tree(graphs, readings) if relaxed else []
        bb = yield from search(graphs, eps=params.eps, token=token, max_iterations=params.max_iterations,
                               relaxations=relaxations)
    path = bb.path
    matched = path.matched_vertices(graphs[bb.graph_index].m)
    model, signs, near = readings[bb.graph_index]
    extras = {**reading_extras(model, signs, near, side is not None, sided is not None),
              "asymmetry": query.asymmetry, "intrinsic_asymmetry": query.intrinsic_asymmetry,
              "mesh_seen_from_side": seen_from_side, "contour_points": len(query.points),
              "contour_points_asked": params.n_contour, "curve_length_ratio": curve_length_ratio(
                  target.vertices, path.vertices, graphs[bb.graph_index].curve_length)}
    certificate = SearchCertificate.of(bb, params.eps)
    yield Progress("done", 1.0, f"energy {bb.energy:.6g} after {bb.iterations} iterations, {certificate.describe()}")
    per_length = " per contour length matched to a moving curve" if params.energy.endswith("ratio") else ""
    metric = f"{params.metric} product metric, " if params.energy in FIRST_ORDER_ENERGIES else ""
    return MatchResult("contour3d", map_xy=matched, map_yx=None, energy=bb.energy, timings=watch.times,
                       path=ContourPath(query.contour.points, path.vertices, path.curve_index, path.layers),
                       search=certificate, extras=extras,
                       energy_meaning=f"{params.energy} product-graph path energy{per_length} ({metric}{model} shape model, unit-area "
                                      f"mesh, contour area {params.area_ratio:g}, axis weight {params.axis_weight:g}"
                                      + (f", side view, symmetry-curve weight {params.symmetry_weight:g})"
                                         if side is not None else
                                         ", sided: each half of the outline on its own half of the surface)"
                                         if extras["sided"] else ")"))


def solve_contour3d(source: Contour2D, target: TriMesh, params: Contour3DParams, token):
    """Registered solver: match a closed contour (source) to a mesh (target)."""
    yield Progress("query features", 0.0)
    query = prepare_query(source, params)
    token.raise_if_cancelled()
    return (yield from match_prepared(query, target, params, token))


register(MethodSpec(
    name="contour3d", label="2D-to-3D elastic matching", inputs=("contour", "mesh"),
    params=Contour3DParams, solve=solve_contour3d, rank=10,
    description="Closed contour to mesh as a cyclic shortest path on the product graph, globally optimal by "
                "branch-and-bound (Lähner et al. CVPR 2016)."))
