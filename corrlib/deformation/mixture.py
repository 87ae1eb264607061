"""The E-step of the divergence-free EM, fused (thesis Eq. 10.14 and the M-step's targets).

The M-step needs only two moments of the soft correspondences of every
source sample ``n``: its matched mass ``p_n = Σ_m P_nm`` and the P-weighted
mean ``ŷ_n = Σ_m P_nm y_m / p_n`` of the target samples, with

    P_nm = e^{-d_nm / 2σ²} / (Σ_m' e^{-d_nm' / 2σ²} + c),
    d_nm = |x_n - y_m|² + s f_nm,

``f`` the fixed feature distances of Eq. 10.17 scaled by ``s`` and ``c`` the
outlier constant of the CPD form. :func:`mixture_moments` computes both row
by row without forming the (N, M) arrays of distances and probabilities:
one pass over the feature distances per iteration instead of several passes
over three float64 arrays of that size.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from corrlib.errors import InputError

#: terms below e^SMALLEST_EXPONENT of their row's best are exact zeros (no slow subnormals)
SMALLEST_EXPONENT = -60.0
#: the outlier term's exponent is clipped below the float64 overflow of exp (e^709.8)
LARGEST_EXPONENT = 700.0


def outlier_log_constant(sigma2: float, outlier: float, n_source: int, n_target: int) -> float:
    """log c of the uniform outlier term, ``c = (2πσ²)^{3/2} ω/(1 - ω) · M/N`` (ω > 0)."""
    return 1.5 * math.log(2.0 * math.pi * sigma2) + math.log(outlier / (1.0 - outlier) * n_target / n_source)


@numba.njit(cache=True, parallel=True, nogil=True)
def _moments_kernel(pos, targets, feats, feat_scale, half_precision, log_const, mass, y_hat):
    n_target = targets.shape[0]
    with_feats = feats.shape[0] > 0
    with_outlier = not math.isnan(log_const)
    for n in numba.prange(pos.shape[0]):
        dist = np.empty(n_target)
        best = np.inf
        for m in range(n_target):
            dx = pos[n, 0] - targets[m, 0]
            dy = pos[n, 1] - targets[m, 1]
            dz = pos[n, 2] - targets[m, 2]
            d = dx * dx + dy * dy + dz * dz
            if with_feats:
                d += feat_scale * feats[n, m]
            dist[m] = d
            if d < best:
                best = d
        total = 0.0
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for m in range(n_target):
            z = (best - dist[m]) * half_precision
            if z > SMALLEST_EXPONENT:
                e = math.exp(z)
                total += e
                sx += e * targets[m, 0]
                sy += e * targets[m, 1]
                sz += e * targets[m, 2]
        denom = total
        if with_outlier:
            denom += math.exp(min(log_const + best * half_precision, LARGEST_EXPONENT))
        mass[n] = total / denom
        # the best target's term is e^0 = 1, so total >= 1
        y_hat[n, 0] = sx / total
        y_hat[n, 1] = sy / total
        y_hat[n, 2] = sz / total


def mixture_moments(pos, targets, sigma2: float, outlier: float, feats=None, feat_scale: float = 1.0):
    """Matched mass and weighted target mean of every source sample (Eq. 10.14).

    Parameters
    ----------
    pos : (N, 3) float
        Source samples (flowed).
    targets : (M, 3) float
        Target samples.
    sigma2 : float
        E-step variance σ² > 0.
    outlier : float
        ω in [0, 1).
    feats : (N, M) float, optional
        Feature distances ``f_nm`` of the Eq. 10.17 distance.
    feat_scale : float
        ``s``, their factor.

    Returns
    -------
    mass : (N,) float
        ``p_n = Σ_m P_nm`` (at most 1; the rest is the outlier's share).
    y_hat : (N, 3) float
        ``Σ_m P_nm y_m / p_n``.
    """
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    targets = np.ascontiguousarray(targets, dtype=np.float64)
    feats = np.zeros((0, 0)) if feats is None else np.ascontiguousarray(feats, dtype=np.float64)
    if feats.shape[0] and feats.shape != (len(pos), len(targets)):
        raise InputError(f"feature distances {feats.shape} do not fit {len(pos)} x {len(targets)} samples")
    log_const = outlier_log_constant(sigma2, outlier, len(pos), len(targets)) if outlier > 0 else math.nan
    mass = np.empty(len(pos))
    y_hat = np.empty((len(pos), 3))
    _moments_kernel(pos, targets, feats, float(feat_scale), 0.5 / sigma2, log_const, mass, y_hat)
    return mass, y_hat
