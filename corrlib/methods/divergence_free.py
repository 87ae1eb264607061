"""Divergence-free deformation (thesis ch. 10; Eisenberger, Lähner, Cremers, CGF 2019).

The source is deformed into the target by the time-1 flow of a stationary,
divergence-free velocity field ``v = Σ_k a_k v_k`` in the closed-form basis
of :mod:`corrlib.deformation.basis` (volume preserving, no flux through the
unit cube), integrated by RK2 (:mod:`corrlib.deformation.flow`). The
correspondence and the coefficients are estimated jointly by EM:

* Pre-processing: the source is scaled to the target's surface area
  (:func:`size_ratio`; a volume-preserving flow cannot change the size, so
  shapes in different units would otherwise be matched part to whole), then
  both are mapped into Ω = [0, 1]³ by one common
  scale (the larger shape fills ``1 - 2 margin``), each centred; the source
  is rotated by the rigid PCA alignment whose proper axis orientation (or
  no rotation at all) has the lowest Eq. 10.17 energy (mean over source
  samples of the distance to the nearest target sample). Euclidean
  farthest-point samples of both shapes (``n_samples`` each) are fitted.
* Distance (Eq. 10.17): ``d(x, y) = |x - y|² + w |f(x) - f(y)|²`` with
  features ``f`` computed once on the original meshes: SHOT, as in the
  paper, and (our addition, ``features="shot+wks"``) the wave kernel
  signature of each shape's eigenpairs at unit area, each block scaled to
  unit mean pair distance. SHOT describes the local extrinsic shape, which
  a bent limb changes; the WKS is intrinsic and nearly the same in every
  pose. It cannot tell left from right (a reflection keeps it); the
  coordinates of the pre-aligned shapes do.
  Point clouds (:func:`fit`): coordinates only, or features given by the
  caller. ``w`` makes the mean of both terms over all sample pairs equal
  at the start (times ``feature_weight``).
* E-step (Eq. 10.14): soft correspondences of a Gaussian mixture with a
  uniform outlier term, ``P_nm = e^{-d_nm / 2σ²} / (Σ_m' e^{-d_nm' / 2σ²} + c)``
  with ``c = (2πσ²)^{3/2} ω/(1 - ω) · M/N`` (the CPD form).
* M-step: one Gauss–Newton step (Eq. C.12) on
  ``E(a) = 1/N Σ_n p_n ρ(|x_n(a) - ŷ_n|) / σ² + β/2 Σ_k a_k² / λ_k``
  with ``p_n = Σ_m P_nm``, ``ŷ_n`` the P-weighted target mean, the Huber
  penalty ``ρ`` (threshold ``r₀``, §C.2.2, by iteratively reweighted least
  squares) and the prior variances ``λ_k`` of Eq. 10.18. The data term is
  averaged over the N samples (the paper sums it; β = 0.1 here is β = 0.1 N
  there), so β does not depend on the sample count; a weaker prior lets
  high frequencies grow until RK2 no longer follows the field.
* Derivative of the flow (our addition, documented): the exact derivative
  (Eq. C.15) is formed every ``jacobian_every`` iterations; in between the
  samples are flowed alone and the last derivative gets Broyden's secant
  update along the coefficient change (:class:`FlowLinearisation`).
* Annealing (our addition, documented): the E-step variance starts at σ²
  and is multiplied by ``anneal`` after every iteration down to
  ``sigma2_min``; the feature term of the E-step distance is scaled by the
  same factor, so its share of the exponent stays that of Eq. 10.17 at σ²
  while the coordinates sharpen. Without it the fixed σ² = 0.01 (σ = 0.1,
  a seventh of a shape's size) averages the targets over a wide
  neighbourhood and the fit stalls at a blurred surface. The Gauss–Newton
  data weight keeps σ². ``anneal = 1`` reproduces the fixed-σ² EM.
* A given map (another method's result, ``init``, or ``--init`` of
  ``corr refine``; our addition, documented): it enters Eq. 10.17 as one
  more feature, the position of every source vertex's partner on the target
  against every target vertex's own position, ``|y_map(x) - y|²`` (each
  feature block scaled to unit mean pair distance before ``w`` is set), so a
  sample is drawn towards the neighbourhood of its given partner while the
  flow stays divergence-free and wrong matches are outvoted by coordinates
  and SHOT. The rigid (Kabsch) alignment of the source onto its partners
  joins the candidate pre-alignments.
* Dense result: every source vertex is flowed (linear in the vertex count)
  and matched to its nearest target vertex in the Eq. 10.17 metric (with
  the feature factor at the final annealed variance); the
  reverse map matches every target vertex to the nearest flowed source
  vertex.
* Final ZoomOut (``smooth_k``; our addition): each of the two maps is
  zoomed out (Melzi et al. 2019) from its functional map on the first
  :data:`~corrlib.methods.baselines.ZOOMOUT_K_INIT` Laplace–Beltrami
  eigenfunctions to the final basis, the functional-map baseline's
  schedule (:func:`~corrlib.geometry.fmaps.zoomout_both_ways`); then, as
  in kernel matching, the maps are projected onto the final basis and
  every vertex takes its nearest partner in it, with one functional map
  estimated from both directions, the step repeated while it moves fewer
  partners (:func:`~corrlib.geometry.fmaps.repeated_pointwise_from_basis`).
  A flow fits the shapes' overall position and volume but not every limb:
  a posed arm can end on the body. What the flow's map gets right is its
  low frequencies, from which ZoomOut rebuilds the rest; started in the
  final basis, the steps kept a misplaced limb. By default the
  basis is the eigenfunctions kernel matching's smallest default time
  resolves (``τ λ · area ≤ 1`` at :data:`FINAL_STEP_TAU`, about 160 by Weyl's
  law), from the pair's 500 eigenpairs (kernel matching's default, so the
  spectra cache serves both). The flow's own nearest-neighbour map stays
  in ``extras["flow_map_xy"]``; the deformation (morphs, sequences) is the
  flow's.

The flow can be evaluated at any time (interpolation t ∈ [0, 1],
extrapolation t > 1) and resolution through :class:`Deformation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist

from corrlib.deformation.basis import DivFreeBasis
from corrlib.deformation.flow import check_points, flow, flow_with_jacobian
from corrlib.deformation.mixture import mixture_moments
from corrlib.deformation.model import Deformation, Frames, StoredSteps
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.fmaps import (ZoomOutSamples, repeated_pointwise_from_basis, resolved_eigenpairs,
                                   zoomout_both_ways)
from corrlib.geometry.sampling import farthest_point_sampling
from corrlib.methods.base import MatchResult, param
from corrlib.methods.baselines import ZOOMOUT_K_INIT, ZOOMOUT_STEP
from corrlib.methods.kernel_matching import DEFAULT_EIGENPAIRS, DEFAULT_TAU_MIN
from corrlib.methods.registry import MethodSpec, register
from corrlib.neighbours import nearest_rows
from corrlib.progress import Progress, Stopwatch
from corrlib.shapes import relative_volume_change, signed_volume

#: eigenpairs computed for the final ZoomOut steps: kernel matching's default count, so that a pair's spectra
#: are computed once for both methods (the on-disk cache truncates a larger decomposition)
FINAL_STEP_EIGENPAIRS = DEFAULT_EIGENPAIRS
#: the relative diffusion time whose resolved eigenfunctions form the final steps' basis by default (kernel
#: matching's smallest default time, :func:`~corrlib.geometry.fmaps.resolved_eigenpairs`)
FINAL_STEP_TAU = DEFAULT_TAU_MIN

#: the result stores the flow of the source vertices at every RK2 step up to this time (scrubbing, export)
SEQUENCE_T_MAX = 3.0


@dataclass(frozen=True, kw_only=True)
class DivergenceFreeParams:
    n_fields: int = param(3000, label="Basis fields K", low=1, high=30000,
                          help="Divergence-free basis fields (Eq. 10.11), lowest frequencies first.")
    n_steps: int = param(20, label="Flow steps T", low=1, high=1000, help="RK2 steps of the flow (Eq. 10.13).")
    n_samples: int = param(3000, label="Samples", low=10, high=20000,
                           help="Farthest-point samples per shape used in the EM fit.")
    sigma2: float = param(0.01, label="σ²", low=1e-8, high=10.0,
                          help="Variance of the Gaussian mixture (unit-cube units², Eq. 10.14).")
    outlier: float = param(0.1, label="Outlier weight ω", low=0.0, high=0.99,
                           help="Weight of the uniform outlier component of the mixture.")
    sigma2_min: float = param(1e-4, label="Smallest σ²", low=1e-10, high=10.0,
                              help="Floor of the annealed E-step variance.")
    anneal: float = param(0.8, label="σ² annealing", low=0.0, high=1.0,
                          help="Factor applied to the E-step variance after every iteration (1: no annealing).")
    huber: float = param(0.01, label="Huber r₀", low=1e-8, high=10.0,
                         help="Residual length above which the penalty grows linearly (§C.2.2).")
    prior_weight: float = param(0.1, label="Prior weight β", low=0.0, high=1e8,
                                help="Weight of the smoothness prior Σ a_k²/λ_k (Eq. 10.18).")
    features: str = param("shot+wks", label="Features", choices=("shot+wks", "shot", "wks", "none"),
                          help="Features of the Eq. 10.17 distance: SHOT (extrinsic, local) and the wave kernel "
                               "signature (intrinsic, the same in every pose), each block at unit mean pair "
                               "distance; one of them; or coordinates only.")
    feature_weight: float = param(1.0, label="Feature weight", low=0.0, high=1e6,
                                  help="Multiplies the factor that equalises the means of the coordinate "
                                       "and feature terms.")
    max_iter: int = param(40, label="EM iterations", low=1, high=10000, help="Iteration cap.")
    jacobian_every: int = param(2, label="Exact derivative every", low=1, high=10000,
                                help="EM iterations per exact flow derivative (Eq. C.15); in between, the flow "
                                     "alone and Broyden's secant update of the last derivative (1: exact always).")
    tol: float = param(1e-4, label="Tolerance", low=0.0, high=1.0,
                       help="Stop when the coefficient update is below tol × |a| (and 1e-8).")
    init: str = param("none", label="Initial map", choices=("none", "fmap-zoomout", "kernel-matching"),
                      help="Another method's map as a feature of the E-step distance (the partner's position), "
                           "and its rigid alignment as a pre-alignment candidate; none: the features and "
                           "coordinates only.")
    prealign: str = param("pca", label="Pre-alignment", choices=("pca", "none"),
                          help="Rigid PCA alignment (best proper axis orientation or none), or none.")
    margin: float = param(0.15, label="Margin", low=0.0, high=0.45,
                          help="Free border of the unit cube around the shapes.")
    seed: int = param(0, label="Seed", low=0, high=2 ** 31 - 1, help="Start of the farthest-point sampling.")
    smooth_k: int = param(-1, label="Final ZoomOut basis", low=-1, high=FINAL_STEP_EIGENPAIRS,
                          help="Final ZoomOut after the flow: both maps are zoomed out from "
                               f"{ZOOMOUT_K_INIT} eigenfunctions to this many, then every vertex takes its nearest "
                               "partner in them (steps on the mean of the functional maps of the map and of its "
                               "reverse, repeated while they move fewer partners). -1: the eigenfunctions resolved "
                               "at kernel matching's "
                               f"smallest default time (τ λ·area ≤ 1, τ = {FINAL_STEP_TAU:g}); 0: off "
                               "(the flow's map).")


def _bbox_centre(p: np.ndarray) -> np.ndarray:
    return 0.5 * (p.min(axis=0) + p.max(axis=0))


def _frames_for(points_x: np.ndarray, points_y: np.ndarray, rotation: np.ndarray, margin: float,
                source_scale: float = 1.0) -> Frames:
    linear = source_scale * rotation
    rx = points_x @ linear.T
    extent = max(np.ptp(rx, axis=0).max(), np.ptp(points_y, axis=0).max())
    if extent <= 0:
        raise InputError("the shapes have zero extent")
    return Frames(linear, (1.0 - 2.0 * margin) / extent, _bbox_centre(rx), _bbox_centre(points_y))


def size_ratio(source, target) -> float:
    """The target's size relative to the source's, ``√(A_Y / A_X)`` for surface areas ``A``: the scale factor that
    gives the source the target's area. An isometry keeps the area, so for two poses of one shape in different
    units this is exactly the change of units."""
    if not (source.area > 0 and target.area > 0):
        raise InputError(f"{source.name} and {target.name} must have positive surface areas "
                         f"(got {source.area:g} and {target.area:g})")
    return math.sqrt(target.area / source.area)


def _principal_axes(p: np.ndarray) -> np.ndarray:
    """(3, 3): columns are the principal axes, largest variance first."""
    c = p - p.mean(axis=0)
    evals, evecs = np.linalg.eigh(c.T @ c)
    return evecs[:, ::-1]


def kabsch_rotation(points_x: np.ndarray, partners: np.ndarray) -> np.ndarray:
    """(3, 3) proper rotation best taking the centred ``points_x`` onto their centred ``partners`` (n, 3)."""
    u, _, vt = np.linalg.svd((partners - partners.mean(0)).T @ (points_x - points_x.mean(0)))
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def map_features(points_y: np.ndarray, map_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The map (n_x,) int, every vertex matched, as a feature pair: the partner's position on the target
    ((n_x, 3)) and every target vertex's own position ((n_y, 3))."""
    map_xy = np.asarray(map_xy, dtype=np.int64)
    return np.asarray(points_y)[map_xy], np.asarray(points_y, dtype=np.float64)


def _unit_blocks(blocks_x: list, blocks_y: list) -> tuple[np.ndarray, np.ndarray]:
    """Feature blocks of both shapes scaled to unit mean pair distance each, side by side."""
    out_x, out_y = [], []
    for fx, fy in zip(blocks_x, blocks_y):
        scale = math.sqrt(max(_mean_sq_distance(fx, fy), 1e-300))
        out_x.append(fx / scale)
        out_y.append(fy / scale)
    return np.hstack(out_x), np.hstack(out_y)


def candidate_rotations(points_x: np.ndarray, points_y: np.ndarray) -> list[np.ndarray]:
    """No rotation, and the four proper rotations taking the source's principal axes onto the target's."""
    ux, uy = _principal_axes(points_x), _principal_axes(points_y)
    out = [np.eye(3)]
    for signs in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)):
        r = uy @ np.diag(signs) @ ux.T
        if np.linalg.det(r) < 0:  # one of the factors is a reflection: flip the last axis
            r = uy @ np.diag(np.array(signs) * np.array([1, 1, -1])) @ ux.T
        out.append(r)
    return out


# ----------------------------------------------------------------------------- distances


def _sq_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m) float64 squared Euclidean distances (clipped at 0)."""
    if a.shape[1] <= 8:  # coordinates: a direct loop is exact and faster than the BLAS expansion
        return cdist(a, b, "sqeuclidean")
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)
    return np.maximum(d, 0.0, out=d)


def _mean_sq_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean of |a_n - b_m|² over all pairs, without forming them."""
    return float((a * a).sum(1).mean() + (b * b).sum(1).mean() - 2.0 * a.mean(0) @ b.mean(0))


def feature_factor(coords_x, coords_y, feats_x, feats_y) -> float:
    """The factor w of Eq. 10.17 that equalises the mean coordinate and feature terms."""
    f = _mean_sq_distance(feats_x, feats_y)
    return _mean_sq_distance(coords_x, coords_y) / f if f > 0 else 0.0


# ----------------------------------------------------------------------------- EM


def huber_weights(residual_norm: np.ndarray, r0: float) -> np.ndarray:
    """IRLS weights of the Huber penalty: 1 below ``r0``, ``r0 / r`` above."""
    return np.minimum(1.0, r0 / np.maximum(residual_norm, 1e-300))


def huber_penalty(residual_norm: np.ndarray, r0: float) -> np.ndarray:
    """ρ(r) = r²/2 below ``r0``, ``r0 (r - r0/2)`` above."""
    r = residual_norm
    return np.where(r <= r0, 0.5 * r * r, r0 * (r - 0.5 * r0))


#: relative residual at which the conjugate gradients of a Gauss–Newton step stop (the forcing term)
GN_RTOL = 1e-2


def gauss_newton_step(positions, jac, targets, weights, coeffs, prior_precision, *,
                      rtol: float = GN_RTOL) -> np.ndarray:
    """One (inexact) Gauss–Newton step on ``Σ_n w_n |x_n(a) - ŷ_n|²/2 + Σ_k a_k² / (2 λ_k)`` (Eq. C.12).

    The normal equations ``(Jᵀ W J + Λ⁻¹) δ = -(Jᵀ W r + Λ⁻¹ a)`` are solved by conjugate gradients
    preconditioned with their diagonal, with ``J`` applied as it is (two products of the (3N, K) matrix per
    CG iteration) instead of forming and factorising the (K, K) matrix ``Jᵀ W J`` (N K² + K³/3 operations
    per step). The iteration stops at a residual below ``rtol`` times the right-hand side: an inexact
    Newton step (Dembo, Eisenstat & Steihaug 1982; Nocedal & Wright 2006, §7.1). Every CG iterate from 0
    lowers the quadratic model, so a truncated step is a descent direction; within the EM the step's error
    at the default ``rtol`` is far below what the next E-step changes (see the decisions record).

    Parameters
    ----------
    positions : (N, 3) float
        ``x_n(a)``.
    jac : (N, 3, K) float
        ``∂x_n/∂a`` (not modified).
    targets : (N, 3) float
        ``ŷ_n``.
    weights : (N,) float
        ``w_n ≥ 0``.
    coeffs : (K,) float
        ``a``.
    prior_precision : (K,) float
        ``1/λ_k`` times the prior weight.
    rtol : float
        Relative residual of the normal equations at which CG stops (at most K iterations).

    Returns
    -------
    (K,) float
        The update δ.
    """
    n, _, k = jac.shape
    sw = np.sqrt(weights)
    jw = (jac * sw.astype(jac.dtype)[:, None, None]).reshape(3 * n, k)  # W^½ J
    residual = ((positions - targets) * sw[:, None]).reshape(-1).astype(jw.dtype)
    rhs = -(jw.T @ residual).astype(np.float64) - prior_precision * coeffs
    diagonal = np.einsum("ij,ij->j", jw, jw, dtype=np.float64) + prior_precision
    diagonal[diagonal <= 0] = 1.0  # a field no sample moves and no prior holds: unpreconditioned

    def normal_times(v):  # (Jᵀ W J + Λ⁻¹) v; numpy's products release the GIL, so the studio stays responsive
        return (jw.T @ (jw @ v.astype(jw.dtype))).astype(np.float64) + prior_precision * v

    delta = np.zeros(k)
    r = rhs.copy()
    z = r / diagonal
    direction = z.copy()
    rz = r @ z
    stop = rtol * np.linalg.norm(rhs)
    for _ in range(k):
        if np.linalg.norm(r) <= stop:
            break
        a_dir = normal_times(direction)
        curvature = direction @ a_dir
        if curvature <= 0:  # singular without a prior: the least-norm part found so far is the step
            break
        alpha = rz / curvature
        delta += alpha * direction
        r -= alpha * a_dir
        z = r / diagonal
        rz_next = r @ z
        direction = z + (rz_next / rz) * direction
        rz = rz_next
    return delta


def broyden_update(jac, delta_coeffs, delta_positions) -> None:
    """Broyden's rank-one secant update of a derivative, in place (Broyden 1965; Dennis & Schnabel 1996, §8.1).

    ``J ← J + (Δx − J Δa) Δaᵀ / (Δaᵀ Δa)``: the least change of ``J`` (in the Frobenius norm) after which
    ``J Δa = Δx``, the observed change of the end points. Directions orthogonal to ``Δa`` keep their
    derivative.

    Parameters
    ----------
    jac : (N, 3, K) float
        ``∂x_n/∂a`` at the previous coefficients; updated in place.
    delta_coeffs : (K,) float
        ``Δa``, the coefficient change since then.
    delta_positions : (N, 3) float
        ``Δx``, the change of the end points it caused.
    """
    da = np.asarray(delta_coeffs, dtype=np.float64)
    norm2 = float(da @ da)
    if norm2 == 0.0:
        return
    flat = jac.reshape(-1, jac.shape[2])
    miss = np.asarray(delta_positions, dtype=np.float64).reshape(-1) - flat @ da.astype(flat.dtype)
    flat += np.outer((miss / norm2).astype(flat.dtype), da.astype(flat.dtype))


class FlowLinearisation:
    """End points of the samples' flow and their derivative in the coefficients, for Gauss–Newton.

    The exact derivative (Eq. C.15) costs several flows: it carries a (3, K) sensitivity per sample through
    every RK2 step. When asked for an approximate one, the end points come from the flow alone and the
    last derivative is corrected by :func:`broyden_update` along the coefficient change since it was
    formed: Gauss–Newton with a secant update of the Jacobian (Dennis & Schnabel 1996, §8). The EM's
    coefficient updates shrink as it anneals, so the derivative changes little between iterations.

    Parameters
    ----------
    basis : DivFreeBasis
    start : (N, 3) float
        Samples at t = 0 (unit cube).
    n_steps : int
        RK2 steps T.
    """

    def __init__(self, basis: DivFreeBasis, start: np.ndarray, n_steps: int):
        self.basis, self.start, self.n_steps = basis, start, n_steps
        self.coeffs = self.positions = self.jac = None

    def __call__(self, coeffs: np.ndarray, exact: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(x, ∂x/∂a)`` at ``coeffs``: (N, 3) float64 and (N, 3, K) float32 (kept; do not modify)."""
        if exact or self.jac is None:
            positions, jac = flow_with_jacobian(self.basis, self.start, coeffs, self.n_steps, dtype=np.float32)
        else:
            positions, jac = flow(self.basis, self.start, coeffs, 1.0, self.n_steps), self.jac
            broyden_update(jac, coeffs - self.coeffs, positions - self.positions)
        self.coeffs, self.positions, self.jac = np.array(coeffs, dtype=np.float64), positions, jac
        return positions, jac


def em_iteration(linearisation: FlowLinearisation, targets_y, feature_dist, coeffs, sigma2_e, precision, params,
                 watch, feature_scale: float = 1.0, exact: bool = True):
    """One EM iteration: flow (with its derivative), E-step, one Gauss–Newton step.

    Parameters
    ----------
    linearisation : FlowLinearisation
        The flow of the source samples (N of them).
    targets_y : (M, 3) float
        Target samples in the unit cube.
    feature_dist : (N, M) float or None
        Feature distances of the E-step distance.
    coeffs : (K,) float
    sigma2_e : float
        E-step variance.
    precision : (K,) float
        β / λ_k.
    params : DivergenceFreeParams
    watch : Stopwatch
    feature_scale : float
        Factor of ``feature_dist`` in the E-step distance (its annealed weight).
    exact : bool
        Form the exact flow derivative (else the secant update of the last one).

    Returns
    -------
    delta : (K,) float
        Coefficient update.
    energy : float
        The M-step objective at the current coefficients.
    rnorm : (N,) float
        Residual lengths.
    """
    n = len(linearisation.start)
    with watch("flow"):
        pos, jac = linearisation(coeffs, exact)
    with watch("e-step"):
        mass, y_hat = mixture_moments(pos, targets_y, sigma2_e, params.outlier, feature_dist, feature_scale)
        rnorm = np.linalg.norm(pos - y_hat, axis=1)
        robust = huber_weights(rnorm, params.huber)
        weights = mass * robust / (params.sigma2 * n)
        energy = float((mass * huber_penalty(rnorm, params.huber)).sum() / (params.sigma2 * n)
                       + 0.5 * (precision * coeffs ** 2).sum())
    with watch("gauss-newton"):
        delta = gauss_newton_step(pos, jac, y_hat, weights, coeffs, precision)
    return delta, energy, rnorm


@dataclass
class FitResult:
    """Outcome of :func:`fit`: coefficients in the unit-cube frame and the EM record."""

    basis: DivFreeBasis
    coeffs: np.ndarray
    frames: Frames
    feature_factor: float
    energy_trace: list
    iterations: int
    converged: bool


def prepare_fit(points_x, points_y, feats_x, feats_y, params, watch, extra_rotations=(), source_scale: float = 1.0):
    """Frames (pre-alignment), samples and the fixed feature distances."""
    rng_start = params.seed % len(points_x)
    with watch("sampling"):
        sx = farthest_point_sampling(points_x, min(params.n_samples, len(points_x)), start=rng_start)
        sy = farthest_point_sampling(points_y, min(params.n_samples, len(points_y)),
                                     start=params.seed % len(points_y))
    feat_dist = None
    if feats_x is not None:
        feat_dist = _sq_distances(feats_x[sx], feats_y[sy])
    rotations = candidate_rotations(points_x, points_y) if params.prealign == "pca" else [np.eye(3)]
    rotations = rotations + list(extra_rotations)
    best = None
    w = 0.0
    with watch("alignment"):
        for rot in rotations:
            frames = _frames_for(points_x, points_y, rot, params.margin, source_scale)
            ux, uy = frames.source_to_cube(points_x[sx]), frames.target_to_cube(points_y[sy])
            dist = _sq_distances(ux, uy)
            if feat_dist is not None:
                if best is None:  # one factor for all candidates (from the unrotated placement)
                    w = params.feature_weight * feature_factor(ux, uy, feats_x[sx], feats_y[sy])
                dist += w * feat_dist
            energy = float(dist.min(axis=1).mean())
            if best is None or energy < best[0] - 1e-12:
                best = (energy, frames)
    return sx, sy, feat_dist, best[1], w


def fit(points_x, points_y, params: DivergenceFreeParams | None = None, token=None, *,
        feats_x=None, feats_y=None, watch: Stopwatch | None = None, extra_rotations=(), source_scale: float = 1.0):
    """EM fit of the divergence-free deformation of ``points_x`` onto ``points_y`` (generator).

    Parameters
    ----------
    points_x : (n_x, 3) float
        Source points (mesh vertices or a point cloud).
    points_y : (n_y, 3) float
        Target points.
    params : DivergenceFreeParams
    token : CancelToken, optional
    feats_x : (n_x, f) float, optional
        Features of the Eq. 10.17 distance (none: coordinates only).
    feats_y : (n_y, f) float, optional
    watch : Stopwatch, optional
    extra_rotations : sequence of (3, 3) float
        Pre-alignment candidates besides the PCA ones (e.g. the rigid fit of a given map).
    source_scale : float
        Factor the source is scaled by before the flow (:func:`size_ratio` for two surfaces), so that shapes of
        different sizes or units meet at one size: the flow preserves volume and cannot change it.

    Yields
    ------
    Progress
        One per EM iteration (energy, update size).

    Returns
    -------
    FitResult
    """
    params = params or DivergenceFreeParams()
    watch = watch or Stopwatch()
    px, py = check_points(points_x, "the source points", 4), check_points(points_y, "the target points", 4)
    if (feats_x is None) != (feats_y is None):
        raise InputError("features must be given for both shapes or for neither")
    if feats_x is not None:
        feats_x, feats_y = np.asarray(feats_x, dtype=np.float64), np.asarray(feats_y, dtype=np.float64)
        if feats_x.shape[0] != len(px) or feats_y.shape[0] != len(py) or feats_x.shape[1:] != feats_y.shape[1:]:
            raise InputError(f"feature arrays {feats_x.shape} and {feats_y.shape} do not fit the point counts "
                             f"{len(px)} and {len(py)}")
    yield Progress("preparing", 0.02, "samples and pre-alignment")
    if not (np.isfinite(source_scale) and source_scale > 0):
        raise ParameterError(f"source_scale must be a positive number, got {source_scale!r}")
    sx, sy, feat_dist, frames, w = prepare_fit(px, py, feats_x, feats_y, params, watch, extra_rotations,
                                               source_scale)
    basis = DivFreeBasis(params.n_fields)
    start = frames.source_to_cube(px[sx])
    targets_y = frames.target_to_cube(py[sy])
    precision = params.prior_weight / basis.prior_variance
    coeffs = np.zeros(basis.n_fields)
    linearisation = FlowLinearisation(basis, start, params.n_steps)
    trace = []
    converged = False
    it = 0
    sigma2_e = params.sigma2
    for it in range(1, params.max_iter + 1):
        if token is not None:
            token.raise_if_cancelled()
        # the feature term shrinks with σ² so its share of the exponent stays that of Eq. 10.17 at σ²
        delta, energy, rnorm = em_iteration(linearisation, targets_y, feat_dist, coeffs, sigma2_e, precision,
                                            params, watch, feature_scale=w * sigma2_e / params.sigma2,
                                            exact=(it - 1) % params.jacobian_every == 0)
        coeffs = coeffs + delta
        sigma2_e = max(params.sigma2_min, sigma2_e * params.anneal)
        step = float(np.linalg.norm(delta))
        trace.append(energy)
        yield Progress(f"iteration {it}", 0.05 + 0.85 * it / params.max_iter,
                       f"energy {energy:.6g}, update {step:.3g}, mean residual {rnorm.mean():.4f}")
        if step <= params.tol * np.linalg.norm(coeffs) + 1e-8:
            converged = True
            break
    # the dense map uses the Eq. 10.17 metric at the final E-step variance (see the annealing above)
    return FitResult(basis, coeffs, frames, w * sigma2_e / params.sigma2, trace, it, converged)


# ----------------------------------------------------------------------------- dense maps


def dense_maps(frames: Frames, morphed, points_y, w: float, feats_x=None, feats_y=None):
    """Nearest neighbours in the Eq. 10.17 metric between the flowed source and the target.

    Parameters
    ----------
    frames : Frames
    morphed : (n_x, 3) float
        The source flowed to t = 1 (target coordinates).
    points_y : (n_y, 3) float
    w : float
        Feature factor of the metric.
    feats_x, feats_y : (n_x, f), (n_y, f) float, optional

    Returns
    -------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    """

    ux = frames.target_to_cube(morphed)
    uy = frames.target_to_cube(points_y)
    if feats_x is not None and w > 0:
        ux = np.hstack([ux, math.sqrt(w) * feats_x])
        uy = np.hstack([uy, math.sqrt(w) * feats_y])
    return nearest_rows(ux, uy), nearest_rows(uy, ux)


def _initial_map(source, target, params: DivergenceFreeParams, token, initial, watch):
    """(n_x,) int map to use as a feature, or None: a given map or landmarks, else the ``init`` method's map.

    Source vertices without a match (landmarks, a partial map) take the partner of their nearest matched vertex.
    """
    from corrlib.methods.base import InitialMatch

    if initial is None:
        if params.init == "none":
            return None
        from corrlib.methods.registry import solve_iter

        with watch("init"):
            initial = InitialMatch(map_xy=(yield from solve_iter(params.init, source, target, token=token)).map_xy)
    ix, iy = initial.pairs(source.n_vertices, target.n_vertices)  # named errors for empty or bad maps
    if ix.size == source.n_vertices:
        return iy
    return iy[nearest_rows(source.vertices, source.vertices[ix])]


def pair_spectra(source, target, watch):
    """The pair's :data:`FINAL_STEP_EIGENPAIRS` eigenpairs (fewer on a coarse mesh), shared by the wave kernel
    signatures and the final ZoomOut steps, and cached on disk for kernel matching (:class:`Spectrum` of each)."""
    from corrlib.geometry.spectrum import available_eigenpairs, mesh_spectra

    what = "the wave kernel signatures and the final ZoomOut steps (features=shot and smooth_k=0 need none)"
    with watch("eigen"):
        return mesh_spectra((source, target), (available_eigenpairs(source, FINAL_STEP_EIGENPAIRS, what),
                                               available_eigenpairs(target, FINAL_STEP_EIGENPAIRS, what)))


def pair_descriptors(source, target, kind: str, spectra) -> tuple[np.ndarray, np.ndarray]:
    """One feature block of Eq. 10.17 on both shapes, (n_x, d) and (n_y, d): SHOT, or the WKS of each shape's
    eigenpairs taken at unit area (``spectra``, :func:`pair_spectra`), so that the same shape in other units
    has the same signatures."""
    from corrlib.descriptors import mesh_descriptors

    if kind == "shot":
        return mesh_descriptors(source, "shot"), mesh_descriptors(target, "shot")
    spec_x, spec_y = spectra
    return (mesh_descriptors(source, kind, spectrum=spec_x.at_unit_area(source.area)),
            mesh_descriptors(target, kind, spectrum=spec_y.at_unit_area(target.area)))


def final_zoomout_steps(source, target, map_xy, map_yx, smooth_k: int, token, watch, spectra=None):
    """The flow's maps after the final ZoomOut steps (see the module docstring).

    Parameters
    ----------
    source, target : TriMesh
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    smooth_k : int
        The basis size, or -1 for the eigenfunctions resolved at :data:`FINAL_STEP_TAU`.
    token : CancelToken
    watch : Stopwatch
    spectra : (Spectrum, Spectrum), optional
        The pair's eigenpairs (:func:`pair_spectra`, computed here if not given).

    Returns
    -------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    """
    spec_x, spec_y = spectra if spectra is not None else pair_spectra(source, target, watch)
    k = min(spec_x.evecs.shape[1], spec_y.evecs.shape[1])
    if smooth_k > 0:
        k = min(k, smooth_k)
    else:
        k = min(resolved_eigenpairs(spec_x.evals, source.area, FINAL_STEP_TAU),
                resolved_eigenpairs(spec_y.evals, target.area, FINAL_STEP_TAU), k)
    with watch("zoomout"):
        samples = ZoomOutSamples.of_pair(source, target, spec_x.mass.diagonal(), spec_y.mass.diagonal())
        map_xy, map_yx = zoomout_both_ways(map_xy, map_yx, spec_x, spec_y, min(ZOOMOUT_K_INIT, k), k, ZOOMOUT_STEP,
                                           token, *samples)
        return repeated_pointwise_from_basis(map_xy, map_yx, spec_x, spec_y, k, source.adjacency,
                                             target.adjacency, token, *samples)


def solve_divergence_free(source, target, params: DivergenceFreeParams, token, *, initial=None):
    """Registered solver: fit, dense maps, deformation record (generator returning a MatchResult)."""
    watch = Stopwatch()
    blocks_x, blocks_y = [], []
    spectra = None
    if "wks" in params.features or params.smooth_k != 0:
        yield Progress("eigenpairs", 0.0, f"{FINAL_STEP_EIGENPAIRS} per shape")
        spectra = pair_spectra(source, target, watch)
    if params.features != "none":
        yield Progress("features", 0.0, params.features.upper().replace("+", " and "))
        with watch("descriptors"):
            for kind in params.features.split("+"):
                block_x, block_y = pair_descriptors(source, target, kind, spectra)
                blocks_x.append(block_x)
                blocks_y.append(block_y)
    if initial is not None or params.init != "none":
        yield Progress("initial map", 0.0, "given map" if initial is not None else params.init)
    map_xy = yield from _initial_map(source, target, params, token, initial, watch)
    extra_rotations = []
    if map_xy is not None:
        partner_x, own_y = map_features(target.vertices, map_xy)
        blocks_x.append(partner_x)
        blocks_y.append(own_y)
        extra_rotations.append(kabsch_rotation(source.vertices, partner_x))
    feats_x = feats_y = None
    if blocks_x:
        feats_x, feats_y = _unit_blocks(blocks_x, blocks_y) if len(blocks_x) > 1 else (blocks_x[0], blocks_y[0])
    source_scale = size_ratio(source, target)
    fitted = yield from fit(source.vertices, target.vertices, params, token, feats_x=feats_x, feats_y=feats_y,
                            watch=watch, extra_rotations=extra_rotations, source_scale=source_scale)
    deformation = Deformation(fitted.basis, fitted.coeffs, fitted.frames, params.n_steps)
    yield Progress("dense map", 0.95, f"flowing {source.n_vertices} vertices")
    with watch("trajectory"):  # every RK2 step up to SEQUENCE_T_MAX; step T is t = 1 (same step size)
        steps = deformation.trajectory(source.vertices, SEQUENCE_T_MAX)
        deformation.source_steps = StoredSteps(steps.times, steps.positions.astype(np.float32))
    morphed = steps.positions[params.n_steps]
    with watch("dense map"):
        map_xy, map_yx = dense_maps(fitted.frames, morphed, target.vertices, fitted.feature_factor, feats_x, feats_y)
    flow_map_xy = map_xy
    if params.smooth_k != 0:
        yield Progress("final ZoomOut steps", 0.97, "nearest partners in the Laplace–Beltrami eigenfunctions")
        map_xy, map_yx = final_zoomout_steps(source, target, map_xy, map_yx, params.smooth_k, token, watch, spectra)
    extras = {
        "flow_map_xy": flow_map_xy,
        "morphed_vertices": morphed,
        "iterations": fitted.iterations,
        "converged": bool(fitted.converged),
        "feature_factor": fitted.feature_factor,
        "source_scale": source_scale,
    }
    volume = source.enclosed_volume()  # the flow preserves the volume of the source brought to the target's size
    change = relative_volume_change(signed_volume(morphed, source.faces),
                                    None if volume is None else volume * source_scale ** 3,
                                    source.area * source_scale ** 2)
    if change is not None:
        extras["volume_change"] = change
    yield Progress("done", 1.0, f"{fitted.iterations} EM iterations, energy {fitted.energy_trace[-1]:.6g}")
    return MatchResult("divergence-free", map_xy, map_yx, fitted.energy_trace[-1], watch.times,
                       energy_meaning="EM objective: weighted data term plus the Eq. 10.18 prior",
                       energy_trace=np.asarray(fitted.energy_trace), deformation=deformation, extras=extras)


register(MethodSpec(
    name="divergence-free", label="Divergence-free deformation", inputs=("mesh", "mesh"),
    params=DivergenceFreeParams, solve=solve_divergence_free, rank=15, refines=True, deforms=True,
    description="Volume-preserving deformation of the source into the target by the flow of a divergence-free "
                "field (closed-form curl basis on the unit cube), fitted jointly with soft correspondences by EM; "
                "the flow gives interpolation and extrapolation sequences at any resolution.",
))
