"""Block Lanczos for the largest eigenpairs of an operator self-adjoint in a mass inner product.

Used for shift-invert on large problems whose solves are cheaper per
right-hand side in blocks (:class:`corrlib.geometry.cholesky.CholeskySolver`):
ARPACK applies the operator to one vector at a time and re-orthogonalises
every new vector against its whole basis with matrix-vector products, both
bound by memory traffic. Here the operator ``K = (S - σM)⁻¹ M`` acts on
blocks of ``b`` vectors and nothing is restarted: the Krylov space grows
until the ``k`` wanted Ritz pairs have converged.

Each step applies the three-term recurrence ``K Q_j = Q_{j-1} R_{j-1}ᵀ +
Q_j C_j + Q_{j+1} R_j``, then (every ``REORTH_PERIOD`` blocks, and every block
once a loss of orthogonality above ``DRIFT_LIMIT`` was seen) one classical
Gram–Schmidt pass against the whole basis in matrix-matrix products, a second
one only if the first removed much (the DGKS test). Its coefficients are kept,
so ``H = Qᵀ M K Q`` is the full projection, symmetrised. The new block is
M-orthonormalised twice (the Gram matrix squares the block's condition
number). The start block is ``K`` applied to a random block: a random block's
high frequencies would otherwise stay in the Ritz vectors and be amplified
by the largest eigenvalue of ``S`` in their residuals.

A Ritz pair ``(θ, x = Q s)`` has the residual ``K x - θ x = W s_j``
(``W``: the orthogonalised remainder of the last step, ``s_j``: the last block
of ``s``); its M-norm relative to ``θ`` is the convergence test, as in ARPACK.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg as sla

from corrlib.errors import SolverError


#: the basis is re-orthogonalised in full every this many blocks (partial re-orthogonalisation), and
#: at every block once a full pass has found a loss of orthogonality above DRIFT_LIMIT
REORTH_PERIOD = 2
DRIFT_LIMIT = 1e-12


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` (2-D float64) through SciPy's BLAS.

    The compiled Cholesky solves call SciPy's BLAS too; NumPy bundles a second
    copy whose idle threads keep spinning after each product and slowed the
    solves that follow by 45 % (measured on a 103k-row band).
    """
    from scipy.linalg.blas import dgemm

    trans_a = not a.flags.f_contiguous
    trans_b = not b.flags.f_contiguous
    return dgemm(1.0, a.T if trans_a else a, b.T if trans_b else b, trans_a=trans_a, trans_b=trans_b)


def _mass_product(mass, x: np.ndarray) -> np.ndarray:
    return x if mass is None else mass @ x


def _orthonormal_block(w: np.ndarray, basis: np.ndarray, mass, scale: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """M-orthonormalise a block against the basis and itself.

    Parameters
    ----------
    w : (n, b) float
        Already M-orthogonal to ``basis``.
    basis : (n, m) float
    scale : float
        Norm of the block before its orthogonalisation: directions shorter than
        ``1e-10 * scale`` are linearly dependent (an invariant subspace was found)
        and are replaced by random directions with zero coefficient.

    Returns
    -------
    q : (n, b) float
        ``qᵀ M q = I``, ``qᵀ M basis = 0``.
    r : (b, b) float
        ``w = q r``.
    """
    gram = _matmul(w.T, _mass_product(mass, w))
    d, v = np.linalg.eigh(0.5 * (gram + gram.T))
    keep = d > (1e-10 * scale) ** 2
    q = _matmul(w, np.ascontiguousarray(v[:, keep])) / np.sqrt(d[keep])
    r = np.zeros_like(gram)
    r[keep] = np.sqrt(d[keep])[:, None] * v[:, keep].T
    # the Gram matrix squares the block's condition number: orthonormality after one pass is only
    # ~ eps cond²; a second pass on the nearly orthonormal result restores it (and, for an
    # ill-conditioned block, the orthogonality to the basis first)
    if keep.any():
        if d[keep].min() < 1e-8 * d.max():
            q -= _matmul(basis, _matmul(basis.T, _mass_product(mass, q)))
        gram = _matmul(q.T, _mass_product(mass, q))
        d2, v2 = np.linalg.eigh(0.5 * (gram + gram.T))
        q = _matmul(q, np.ascontiguousarray(v2)) / np.sqrt(d2)
        r[keep] = (np.sqrt(d2)[:, None] * v2.T) @ r[keep]
    if not keep.all():
        fresh = rng.standard_normal((w.shape[0], int((~keep).sum())))
        for _ in range(2):
            for other in (basis, q):
                fresh -= other @ (other.T @ _mass_product(mass, fresh))
        gram = fresh.T @ _mass_product(mass, fresh)
        fresh = sla.solve_triangular(np.linalg.cholesky(gram), fresh.T, lower=True).T
        q = np.concatenate([q, fresh], axis=1)
        r = np.concatenate([r[keep], r[~keep]])
    return q, r


#: a re-orthogonalisation pass that keeps less than this share of a vector's norm is repeated (DGKS)
DGKS_KEEP = 0.7


def _reorthogonalise(w: np.ndarray, span: np.ndarray, h_column: np.ndarray, mass) -> bool:
    """Full re-orthogonalisation of the block ``w`` (n, b) against the basis ``span`` (n, d), in place.

    ``w ← w - Q (Qᵀ M w)``, repeated once if the first pass removed more than
    a share ``1 - DGKS_KEEP`` of a column (Daniel–Gragg–Kaufman–Stewart). The
    removed coefficients are added to ``h_column`` (d, b), the block column
    of ``H = Qᵀ M K Q``. Returns whether the loss of orthogonality exceeded
    :data:`DRIFT_LIMIT` (then every later step re-orthogonalises).
    """
    drifted = False
    for _ in range(2):
        before = np.linalg.norm(w, axis=0)
        correction = _matmul(span.T, _mass_product(mass, w))
        w -= _matmul(span, correction)
        h_column += correction
        if float(np.abs(correction).max() / before.min()) > DRIFT_LIMIT:
            drifted = True
        if np.all(np.linalg.norm(w, axis=0) > DGKS_KEEP * before):
            break
    return drifted


def _ritz_pairs(h: np.ndarray, w: np.ndarray, k: int, block: int, mass):
    """The ``k`` largest Ritz pairs of the basis and the M-norms of their residuals.

    ``H = Qᵀ M K Q`` (d, d) is symmetrised from its upper block triangle (the
    coefficients ``R_{j-1}ᵀ``, ``C_j`` and what re-orthogonalisation removed);
    with ``H s = θ s`` the residual of the Ritz vector ``Q s`` is
    ``Q_{j+1} R_j s_j = w s_j``, ``s_j`` the last block rows of ``s``.

    Returns
    -------
    theta : (k,) float, descending
    s : (d, k) float
    residual : (k,) float
    """
    dim = h.shape[0]
    hh = np.triu(h)
    hh = hh + np.triu(hh, 1).T
    theta, s = np.linalg.eigh(hh)
    theta, s = theta[::-1][:k], np.asfortranarray(s[:, ::-1][:, :k])
    tail = _matmul(w, s[dim - block:dim])
    return theta, s, np.sqrt(np.einsum("ij,ij->j", tail, _mass_product(mass, tail)))


def block_lanczos(apply: Callable[[np.ndarray], np.ndarray], n: int, k: int, *, mass=None, block: int = 32,
                  tol: float = 1e-10, max_dim: int | None = None, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest eigenpairs of an operator self-adjoint in the ``mass`` inner product.

    Parameters
    ----------
    apply : callable
        ``apply(x)`` returns ``K x`` for an (n, b) block.
    n : int
        Dimension.
    k : int
        Number of eigenpairs, ``1 <= k < n``.
    mass : (n, n) sparse, optional
        Symmetric positive definite inner product (default: the identity).
    block : int
        Vectors per Lanczos block.
    tol : float
        A Ritz pair has converged when its residual's M-norm is at most ``tol * |θ|``
        (0: 1e-14, near machine precision).
    max_dim : int, optional
        Largest basis before giving up (default: ``max(10 k, 1000)``, at most n; memory is
        taken as the basis grows).
    seed : int
        Of the random start block (results are reproducible).

    Returns
    -------
    theta : (k,) float
        Descending.
    vectors : (n, k) float
        M-orthonormal.

    Raises
    ------
    SolverError
        If the wanted pairs have not converged within ``max_dim`` basis vectors.
    """
    tol = tol if tol > 0 else 1e-14
    block = max(1, min(block, n))
    max_dim = min(n, max_dim or max(10 * k, 1000))
    rng = np.random.default_rng(seed)
    basis = np.empty((max_dim + block, n))  # one vector per row: pages are touched only when used
    if max_dim < k + block:
        raise SolverError(f"block Lanczos: {k} eigenpairs need a basis larger than {max_dim}")
    # start in the range of K: a random block has high-frequency content that no later step removes
    # and that the final residuals S x - λ M x would amplify by the largest eigenvalue of S
    start = apply(rng.standard_normal((n, block)))
    q, _ = _orthonormal_block(start, basis[:0].T, mass, float(np.abs(start).max()), rng)
    basis[:block] = q.T
    h = np.zeros((max_dim + block, max_dim + block))
    dim = 0  # columns of the basis whose images are known
    checked = 0  # basis size at the last convergence test
    r = None
    period = REORTH_PERIOD
    while True:
        new = slice(dim, dim + block)
        current = basis[new].T
        w = apply(current)
        scale = float(np.sqrt(np.max(np.einsum("ij,ij->j", w, _mass_product(mass, w)))))
        # three-term recurrence: K Q_j = Q_{j-1} R_{j-1}ᵀ + Q_j C_j + Q_{j+1} R_j
        if r is not None:
            w -= _matmul(basis[dim - block:dim].T, r.T)
            h[dim - block:dim, new] = r.T
        c = _matmul(current.T, _mass_product(mass, w))
        w -= _matmul(current, c)
        h[new, new] = c
        if (dim // block) % period == 0:
            if _reorthogonalise(w, basis[:dim + block].T, h[:dim + block, new], mass):
                period = 1
        dim += block
        done = dim + block > max_dim  # no room for another block
        if (dim >= k + block and dim >= 1.08 * checked) or done:
            checked = dim
            theta, s, residual = _ritz_pairs(h[:dim, :dim], w, k, block, mass)
            if np.all(residual <= tol * np.abs(theta)):
                return theta, _matmul(basis[:dim].T, s)
            if done:
                raise SolverError(f"block Lanczos: {int(np.sum(residual > tol * np.abs(theta)))} of {k} "
                                  f"eigenpairs have not converged with {dim} basis vectors")
        q, r = _orthonormal_block(w, basis[:dim].T, mass, scale, rng)
        basis[dim:dim + block] = q.T  # R_j enters H as R_jᵀ, above the diagonal, at the next step
