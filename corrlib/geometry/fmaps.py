"""Functional maps: the least-squares map and ZoomOut refinement.

Convention (pyFM's): ``C_yx`` of shape (k_Y, k_X) carries the spectral
coefficients of a function on X to those of its pull-back on Y,
``C_yx = Ψᵀ M_Y Π_yx Φ`` with ``Π_yx[j, map_yx[j]] = 1``. The pointwise map
``map_yx`` is recovered by nearest neighbours between ``Ψ`` (rows of Y) and
``Φ C_yxᵀ`` (rows of X).
"""

from __future__ import annotations

import numpy as np

from corrlib.neighbours import nearest_rows


def fmap_least_squares(coef_x: np.ndarray, coef_y: np.ndarray, evals_x: np.ndarray, evals_y: np.ndarray,
                       weight: float) -> np.ndarray:
    """Functional map from descriptor coefficients and Laplacian commutativity.

    Minimises ``||C A - B||² + weight ||C Λ_X - Λ_Y C||²`` row by row.

    Parameters
    ----------
    coef_x : (k_X, d) float
        Spectral coefficients of the descriptors on X (``A``).
    coef_y : (k_Y, d) float
        On Y (``B``).
    evals_x : (k_X,) float
    evals_y : (k_Y,) float
    weight : float

    Returns
    -------
    (k_Y, k_X) float
        ``C_yx``.
    """
    scale = max(evals_x.max(), evals_y.max(), 1e-300)
    lx, ly = evals_x / scale, evals_y / scale
    gram = coef_x @ coef_x.T
    rhs = coef_y @ coef_x.T  # (k_Y, k_X)
    c = np.empty((coef_y.shape[0], coef_x.shape[0]))
    for i in range(coef_y.shape[0]):
        reg = weight * (lx - ly[i]) ** 2
        c[i] = np.linalg.solve(gram + np.diag(reg) + 1e-12 * np.eye(gram.shape[0]), rhs[i])
    return c


def zoomout(evecs_x: np.ndarray, evecs_y: np.ndarray, mass_y, c_yx: np.ndarray, k_final: int, step: int,
            token=None):
    """ZoomOut refinement (Melzi et al. 2019).

    Parameters
    ----------
    evecs_x : (n_x, K) float
    evecs_y : (n_y, K) float
    mass_y : (n_y, n_y) sparse
    c_yx : (k, k) float
        Initial functional map.
    k_final : int
    step : int

    Yields
    ------
    int
        The current basis size (for progress).

    Returns
    -------
    map_yx : (n_y,) int
    c_yx : (k_final, k_final) float
    """
    k = c_yx.shape[1]
    while True:
        if token is not None:
            token.raise_if_cancelled()
        map_yx = nearest_rows(evecs_y[:, :c_yx.shape[0]], evecs_x[:, :k] @ c_yx.T)
        if k >= k_final:
            return map_yx, c_yx
        k = min(k + step, k_final)
        c_yx = evecs_y[:, :k].T @ (mass_y @ evecs_x[map_yx, :k])
        yield k
