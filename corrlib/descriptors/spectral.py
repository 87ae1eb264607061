"""Spectral point descriptors: heat kernel signature (HKS) and wave kernel signature (WKS).

Conventions (those of the 2D-to-3D matching paper's code, Lähner et al. 2016,
which follow Sun et al. 2009 and Aubry et al. 2011):

* The constant eigenpair (``evals[0] == 0``) is skipped, both in the choice of
  scales and in the sums; ``λ_2`` below is ``evals[1]``.
* HKS: ``n_scales`` times log-spaced from ``4 ln10 / λ_max`` to
  ``4 ln10 / λ_2``; ``HKS(x, t) = Σ_k e^{-t λ_k} φ_k(x)²``. With
  ``normalize="heat_trace"`` (default) every scale is divided by
  ``Σ_k e^{-t λ_k}`` (scale-normalised HKS); ``"none"`` leaves it raw.
* WKS: energies ``e = linspace(log λ_2, log λ_max / 1.02, n_scales)``,
  ``σ = variance × (e_1 - e_0)`` (variance 6 by default),
  ``WKS(x, e) = Σ_k exp(-(e - log λ_k)² / 2σ²) φ_k(x)²`` divided per scale by
  ``Σ_k exp(-(e - log λ_k)² / 2σ²)`` (``normalize="per_scale"``, default) or
  left raw (``"none"``).

The eigenvectors are M-orthonormal, so descriptor values scale like
1/area; compare shapes of similar area or rescale them first.

Output shape is ``(n_vertices, n_scales)``.
"""

from __future__ import annotations

import numpy as np

from corrlib.errors import InputError, ParameterError


def _check(evals, evecs, n_scales: int) -> tuple[np.ndarray, np.ndarray]:
    evals = np.asarray(evals, dtype=np.float64)
    evecs = np.asarray(evecs, dtype=np.float64)
    if evals.ndim != 1 or evecs.ndim != 2 or evecs.shape[1] != evals.shape[0]:
        raise InputError(f"evals (k,) and evecs (n, k) do not match: {evals.shape} vs {evecs.shape}")
    if evals.shape[0] < 3:
        raise InputError(f"spectral descriptors need at least 3 eigenpairs, got {evals.shape[0]}")
    if not (np.all(np.isfinite(evals)) and np.all(np.isfinite(evecs))):
        raise InputError("eigenpairs contain NaN or infinite values")
    if evals[1] <= 0:
        raise InputError("the second eigenvalue is not positive: the shape is disconnected or degenerate")
    if not isinstance(n_scales, (int, np.integer)) or n_scales < 1:
        raise ParameterError(f"n_scales must be a positive integer, got {n_scales!r}")
    return evals[1:], evecs[:, 1:]


def hks_times(evals, n_scales: int = 100) -> np.ndarray:
    """(n_scales,) float: log-spaced times from 4 ln10/λ_max to 4 ln10/λ_2."""
    evals = np.asarray(evals, dtype=np.float64)
    lo = 4.0 * np.log(10.0) / evals[-1]
    hi = 4.0 * np.log(10.0) / evals[1]
    return np.geomspace(lo, hi, n_scales)


def hks(evals, evecs, n_scales: int = 100, *, times=None, normalize: str = "heat_trace") -> np.ndarray:
    """Heat kernel signature.

    Parameters
    ----------
    evals : (k,) float
        Ascending eigenvalues, ``evals[0] == 0``.
    evecs : (n, k) float
        M-orthonormal eigenvectors.
    n_scales : int
        Number of times (ignored if ``times`` is given).
    times : (s,) float, optional
        Explicit diffusion times.
    normalize : {"heat_trace", "none"}

    Returns
    -------
    (n, s) float
    """
    t = hks_times(evals, n_scales) if times is None else np.asarray(times, dtype=np.float64)
    lam, phi = _check(evals, evecs, t.shape[0])
    weights = np.exp(-np.outer(lam, t))  # (k-1, s)
    desc = (phi ** 2) @ weights
    if normalize == "heat_trace":
        desc /= weights.sum(axis=0)[None, :]
    elif normalize != "none":
        raise ParameterError(f"unknown HKS normalisation {normalize!r}")
    return desc


def wks_energies(evals, n_scales: int = 100) -> np.ndarray:
    """(n_scales,) float: log-energies from log λ_2 to log λ_max / 1.02."""
    log_e = np.log(np.maximum(np.asarray(evals, dtype=np.float64)[1:], 1e-12))
    return np.linspace(log_e[0], log_e[-1] / 1.02, n_scales)


def wks(evals, evecs, n_scales: int = 100, *, variance: float = 6.0, normalize: str = "per_scale") -> np.ndarray:
    """Wave kernel signature.

    Parameters
    ----------
    evals : (k,) float
    evecs : (n, k) float
    n_scales : int
    variance : float
        Width of the band-pass filters in units of the energy spacing.
    normalize : {"per_scale", "none"}

    Returns
    -------
    (n, n_scales) float
    """
    if variance <= 0:
        raise ParameterError(f"WKS variance must be positive, got {variance}")
    lam, phi = _check(evals, evecs, n_scales)
    e = wks_energies(evals, n_scales)
    sigma = variance * (e[1] - e[0]) if n_scales > 1 else variance
    log_lam = np.log(np.maximum(lam, 1e-12))
    weights = np.exp(-((e[None, :] - log_lam[:, None]) ** 2) / (2.0 * sigma ** 2))  # (k-1, s)
    desc = (phi ** 2) @ weights
    if normalize == "per_scale":
        desc /= weights.sum(axis=0)[None, :]
    elif normalize != "none":
        raise ParameterError(f"unknown WKS normalisation {normalize!r}")
    return desc


#: the biharmonic sum keeps the eigenpairs whose weight ``λ_k⁻²`` is at least this fraction of the first one's
BIHARMONIC_RTOL = 1e-4


def biharmonic_embedding(evals: np.ndarray, evecs: np.ndarray) -> np.ndarray:
    """Points whose Euclidean distances are the biharmonic distances of a shape.

    ``d_B(x, y)² = Σ_{k ≥ 1} (φ_k(x) − φ_k(y))² / λ_k²`` (Lipman et al. 2010), so the embedding is
    ``φ_k / λ_k`` without the constant eigenpair. The terms fall as ``λ_k⁻²``; those below
    :data:`BIHARMONIC_RTOL` of the first are left out (``λ_k > 100 λ_1``).

    Parameters
    ----------
    evals : (k,) float
        Ascending, the first one zero (a connected shape).
    evecs : (n, k) float
        M-orthonormal eigenvectors.

    Returns
    -------
    (n, k - 1) float
    """
    keep = np.flatnonzero((np.arange(evals.size) >= 1) & (evals <= evals[1] / np.sqrt(BIHARMONIC_RTOL)))
    return evecs[:, keep] / evals[None, keep]
