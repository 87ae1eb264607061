"""Functional maps: the energies of the standard pipeline and ZoomOut refinement.

:func:`functional_map` minimises the quadratic energy of descriptor
preservation and commutativity with operators (Laplacian, descriptors,
orientation) exactly; :func:`zoomout` refines a map by spectral upsampling.

Convention (pyFM's): ``C_yx`` of shape (k_Y, k_X) carries the spectral
coefficients of a function on X to those of its pull-back on Y,
``C_yx = Ψᵀ M_Y Π_yx Φ`` with ``Π_yx[j, map_yx[j]] = 1``. The pointwise map
``map_yx`` is recovered by nearest neighbours between ``Ψ`` (rows of Y) and
``Φ C_yxᵀ`` (rows of X).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corrlib.neighbours import nearest_rows


def pointwise_to_functional(map_yx: np.ndarray, evecs_x: np.ndarray, evecs_y: np.ndarray, mass_y) -> np.ndarray:
    """The functional map of a pointwise map, ``C_yx = Ψᵀ M_Y Π_yx Φ`` (the module's convention).

    Parameters
    ----------
    map_yx : (n_y,) int
        ``map_yx[j]``: the vertex of X matched to vertex j of Y; -1 for none (a zero row of ``Π_yx``).
    evecs_x : (n_x, k_x) float
    evecs_y : (n_y, k_y) float
    mass_y : (n_y, n_y) sparse or (n_y,) float
        The mass matrix of Y, or its diagonal (lumped masses).

    Returns
    -------
    (k_y, k_x) float
    """
    map_yx = np.asarray(map_yx)
    valid = map_yx >= 0
    if valid.all():  # ZoomOut's maps: no masking on its hot path
        pulled_back = evecs_x[map_yx]
    else:
        pulled_back = np.zeros((map_yx.size, evecs_x.shape[1]))
        pulled_back[valid] = evecs_x[map_yx[valid]]
    weighted = mass_y @ pulled_back if sp.issparse(mass_y) else np.asarray(mass_y)[:, None] * pulled_back
    return evecs_y.T @ weighted


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
        c_yx = pointwise_to_functional(map_yx, evecs_x[:, :k], evecs_y[:, :k], mass_y)
        yield k


def resolvent_mask(evals_x: np.ndarray, evals_y: np.ndarray, gamma: float = 0.5) -> np.ndarray:
    """Penalty weights of the resolvent Laplacian commutativity (Ren, Panine, Wonka, Ovsjanikov 2019).

    With the eigenvalues scaled by the larger maximum of both shapes,
    ``M_ij = (μ_i^γ/(μ_i^{2γ}+1) − λ_j^γ/(λ_j^{2γ}+1))² + (1/(μ_i^{2γ}+1) − 1/(λ_j^{2γ}+1))²``
    (``μ`` on Y, ``λ`` on X); ``Σ_ij M_ij C_ij²`` is the commutativity of C
    with the resolvent ``(Δ − i)^{-1}``, which unlike ``‖CΛ − ΛC‖²`` does not
    let the high frequencies dominate.

    Returns
    -------
    (k_Y, k_X) float
    """
    scale = max(float(np.max(evals_x)), float(np.max(evals_y)), 1e-300)
    lx = np.clip(np.asarray(evals_x, dtype=np.float64) / scale, 0.0, None) ** gamma
    ly = np.clip(np.asarray(evals_y, dtype=np.float64) / scale, 0.0, None) ** gamma
    return ((ly / (ly ** 2 + 1))[:, None] - (lx / (lx ** 2 + 1))[None, :]) ** 2 + \
        ((1 / (ly ** 2 + 1))[:, None] - (1 / (lx ** 2 + 1))[None, :]) ** 2


def multiplication_operators(evecs: np.ndarray, mass: np.ndarray, functions: np.ndarray) -> np.ndarray:
    """``Φᵀ M diag(f) Φ`` for every column ``f`` of ``functions`` ((d, k, k) float; Nogneng & Ovsjanikov 2017)."""
    weighted = mass[:, None] * evecs
    return np.stack([weighted.T @ (f[:, None] * evecs) for f in functions.T])


def _commutator_gram(ops_x: np.ndarray, ops_y: np.ndarray) -> np.ndarray:
    """Hessian of ``Σ_d ‖C X_d − Y_d C‖²`` in row-major ``vec(C)`` ((k_Y k_X, k_Y k_X) float)."""
    k_y, k_x = ops_y.shape[1], ops_x.shape[1]
    eye_x, eye_y = np.eye(k_x), np.eye(k_y)
    gram = np.zeros((k_y * k_x, k_y * k_x))
    for op_x, op_y in zip(ops_x, ops_y):
        # vec(C X) = (I ⊗ Xᵀ) vec(C), vec(Y C) = (Y ⊗ I) vec(C)
        commutator = np.kron(eye_y, op_x.T) - np.kron(op_y, eye_x)
        gram += commutator.T @ commutator
    return gram


def functional_map(coef_x: np.ndarray, coef_y: np.ndarray, mask: np.ndarray, operator_pairs=(),
                   weights=(1.0, 1.0)) -> np.ndarray:
    """The functional map minimising a sum of quadratic terms, solved exactly.

    ``E(C) = w_0 ‖C A − B‖² + w_1 Σ_ij M_ij C_ij² + Σ_t w_t Σ_d ‖C X_d^t − Y_d^t C‖²``:
    descriptor preservation, Laplacian (resolvent) commutativity and, for
    every family ``t`` of operators, commutativity with them (descriptor
    multiplication, Nogneng & Ovsjanikov 2017; orientation, Ren et al. 2018).
    Every term's Hessian is divided by its trace, so the weights are
    relative and do not depend on how the descriptors are scaled. ``E`` is
    quadratic in C, so its minimiser is one linear solve (no iterative
    optimiser and no starting point).

    Parameters
    ----------
    coef_x : (k_X, d) float
        ``A``, the descriptors' coefficients on X.
    coef_y : (k_Y, d) float
        ``B``, on Y.
    mask : (k_Y, k_X) float
        Laplacian commutativity weights (:func:`resolvent_mask`).
    operator_pairs : sequence of ((p, k_X, k_X), (p, k_Y, k_Y)) float
        Operators that C should commute with, one pair of stacks per family.
    weights : sequence of float
        ``w_0, w_1`` and one weight per operator family.

    Returns
    -------
    (k_Y, k_X) float
        ``C_yx``.
    """
    k_x, k_y = coef_x.shape[0], coef_y.shape[0]
    if len(weights) != 2 + len(operator_pairs):
        raise ValueError(f"{len(weights)} weights for {2 + len(operator_pairs)} terms")
    descriptors = np.kron(np.eye(k_y), coef_x @ coef_x.T)
    rhs = (coef_y @ coef_x.T).ravel()
    terms = [descriptors, np.diag(mask.ravel())] + [_commutator_gram(ox, oy) for ox, oy in operator_pairs]
    traces = [max(np.trace(t), 1e-300) for t in terms]
    hessian = sum(w * t / tr for w, t, tr in zip(weights, terms, traces))
    solution = np.linalg.solve(hessian + 1e-12 * np.eye(k_x * k_y), weights[0] * rhs / traces[0])
    return solution.reshape(k_y, k_x)
