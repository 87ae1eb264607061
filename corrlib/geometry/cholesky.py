"""Sparse Cholesky solves for large symmetric positive definite systems.

SciPy's only sparse factorisation is SuperLU (an LU with partial pivoting and
a column ordering), which fills in badly on graphs that are not surfaces: the
band of a product manifold X × Y is four-dimensional. For those, this module
factors ``P A Pᵀ = L Lᵀ`` with CHOLMOD's supernodal Cholesky (through
``cvxopt``) in a METIS nested-dissection order ``P`` (through ``pymetis``).

CHOLMOD's solve (as cvxopt exposes it) treats one right-hand side at a time
and is bound by reading ``L`` from memory: on the 10 % band of two 1k-vertex
meshes (103k rows, 53M entries of ``L``) 81 ms per solve. For blocks of
right-hand sides (block Lanczos, :mod:`corrlib.geometry.lanczos`) the factor
is taken out of CHOLMOD once and regrouped into supernodes, dense panels of
columns with a common row pattern, and the solves multiply whole blocks in
BLAS: 14 ms per right-hand side in blocks of 16 on the same band.
"""

from __future__ import annotations

import warnings

import numba
import numpy as np
import scipy.sparse as sp

from corrlib.errors import SolverError


def nested_dissection(matrix: sp.spmatrix) -> np.ndarray:
    """(n,) int: METIS nested-dissection fill-reducing order of a symmetric sparsity pattern."""
    import pymetis

    graph = sp.csr_matrix(matrix, copy=True)
    graph.setdiag(0)
    graph.eliminate_zeros()
    graph = (abs(graph) + abs(graph).T).tocsr()
    graph.sort_indices()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        result = pymetis.nested_dissection(xadj=graph.indptr, adjncy=graph.indices)
    perm = result[0] if isinstance(result, tuple) else result
    return np.asarray(perm, dtype=np.int64)


#: a supernode's dense products go through BLAS from this many multiply-adds per right-hand side on
_BLAS_MIN_WORK = 2048


@numba.njit(cache=True)
def _fill_panels(indptr, indices, values, starts, ends, panel_ptr, panels):
    """Copy the columns of each supernode into its dense (w + r, w) panel: diagonal block, then the r rows below."""
    for s in range(starts.size):
        c0, c1 = starts[s], ends[s]
        w = c1 - c0
        panel = panels[panel_ptr[s]:panel_ptr[s + 1]].reshape((-1, w))
        for j in range(c0, c1):
            # column j holds rows j .. c1 - 1 of the diagonal block, then the supernode's rows below
            count = indptr[j + 1] - indptr[j]
            for q in range(count):
                panel[j - c0 + q, j - c0] = values[indptr[j] + q]


@numba.njit(cache=True, fastmath=True)
def _supernodal_solve(starts, ends, row_ptr, rows, panel_ptr, panels, x):
    """Overwrite ``x`` (n, m) with ``(L Lᵀ)⁻¹ x``.

    Each supernode s (columns ``starts[s]:ends[s]`` of ``L``, sharing the rows
    ``rows[row_ptr[s]:row_ptr[s + 1]]`` below their diagonal block) is a dense
    panel: its lower-triangular diagonal block ``D``, then the block ``B`` below
    it. Forward: ``x_s ← D⁻¹ x_s``, ``x_R -= B x_s``; backward:
    ``x_s ← D⁻ᵀ (x_s − Bᵀ x_R)``. Small supernodes are solved by substitution;
    large ones hold ``D⁻¹`` instead of ``D`` (see :meth:`CholeskySolver._supernodes`)
    and multiply by it in BLAS.
    """
    m = x.shape[1]
    count = starts.size
    for s in range(count):
        c0, c1 = starts[s], ends[s]
        w = c1 - c0
        below = rows[row_ptr[s]:row_ptr[s + 1]]
        panel = panels[panel_ptr[s]:panel_ptr[s + 1]].reshape((-1, w))
        if w * (w + below.size) < _BLAS_MIN_WORK:
            for i in range(w):
                for j in range(i):
                    v = panel[i, j]
                    for c in range(m):
                        x[c0 + i, c] -= v * x[c0 + j, c]
                inv = 1.0 / panel[i, i]
                for c in range(m):
                    x[c0 + i, c] *= inv
            for a in range(below.size):
                i = below[a]
                for j in range(w):
                    v = panel[w + a, j]
                    for c in range(m):
                        x[i, c] -= v * x[c0 + j, c]
        else:
            block = np.dot(panel[:w], x[c0:c1])
            x[c0:c1] = block
            if below.size:
                update = np.dot(panel[w:], block)
                for a in range(below.size):
                    x[below[a]] -= update[a]
    for s in range(count - 1, -1, -1):
        c0, c1 = starts[s], ends[s]
        w = c1 - c0
        below = rows[row_ptr[s]:row_ptr[s + 1]]
        panel = panels[panel_ptr[s]:panel_ptr[s + 1]].reshape((-1, w))
        if w * (w + below.size) < _BLAS_MIN_WORK:
            for a in range(below.size):
                i = below[a]
                for j in range(w):
                    v = panel[w + a, j]
                    for c in range(m):
                        x[c0 + j, c] -= v * x[i, c]
            for i in range(w - 1, -1, -1):
                inv = 1.0 / panel[i, i]
                for c in range(m):
                    x[c0 + i, c] *= inv
                for j in range(i):
                    v = panel[i, j]
                    for c in range(m):
                        x[c0 + j, c] -= v * x[c0 + i, c]
        else:
            block = x[c0:c1].copy()
            if below.size:
                gathered = np.empty((below.size, m))
                for a in range(below.size):
                    gathered[a] = x[below[a]]
                block -= np.dot(panel[w:].T, gathered)
            x[c0:c1] = np.dot(panel[:w].T, block)


class CholeskySolver:
    """Factorisation ``P A Pᵀ = L Lᵀ`` of a sparse symmetric positive definite matrix.

    Parameters
    ----------
    matrix : (n, n) sparse
        Symmetric positive definite (only the lower triangle is read).
    blocks : bool
        Solve with the supernodal panels (fast for blocks of right-hand sides);
        otherwise with CHOLMOD's own solve (faster for single vectors).

    Attributes
    ----------
    n : int
    nnz : int or None
        Entries of the factor ``L`` (with ``blocks``).

    Raises
    ------
    SolverError
        If the matrix is not positive definite.
    """

    def __init__(self, matrix: sp.spmatrix, *, blocks: bool = True):
        from cvxopt import cholmod, matrix as cvx_matrix, spmatrix

        lower = sp.tril(sp.csr_matrix(matrix)).tocoo()
        self.n = int(matrix.shape[0])
        a = spmatrix(cvx_matrix(lower.data.astype(np.float64)), cvx_matrix(lower.row.astype(np.int64)),
                     cvx_matrix(lower.col.astype(np.int64)), (self.n, self.n))
        del lower
        self.perm = nested_dissection(matrix)
        options = cholmod.options
        saved = dict(options)
        options["supernodal"] = 2
        if blocks:
            # keep P exactly the METIS order (no post-ordering, no other ordering tried in its place):
            # the supernodal solves apply it themselves
            options["postorder"] = False
            options["nmethods"] = 1
        else:
            # CHOLMOD may try AMD too and keep the better order (the 5 % contour band: 1.7 s against
            # 2.2 s with the METIS order forced)
            options["postorder"] = True
        try:
            factor = cholmod.symbolic(a, p=cvx_matrix(self.perm.tolist()))
            cholmod.numeric(a, factor)
        except ArithmeticError as exc:
            raise SolverError(f"the matrix is not positive definite ({exc})") from None
        finally:
            options.clear()
            options.update(saved)
        del a
        self._cholmod, self._matrix, self._factor = cholmod, cvx_matrix, None
        if not blocks:  # CHOLMOD's own solves, one right-hand side at a time
            self._factor = factor
            self.nnz = None
            return
        # L as compressed columns (CHOLMOD keeps each column's diagonal entry first)
        indptr, indices, values = (np.asarray(memoryview(part)).ravel() for part in cholmod.getfactor(factor).CCS)
        del factor
        self.nnz = int(values.size)
        # diag(L Lᵀ) = diag(P A Pᵀ): catches a factor of another ordering than ``perm``
        diag_llt = np.bincount(indices, weights=values * values, minlength=self.n)
        diag_a = matrix.diagonal()[self.perm]
        if not np.allclose(diag_llt, diag_a, rtol=1e-8, atol=1e-12 * np.abs(diag_a).max()):
            raise SolverError("the Cholesky factor does not reproduce the matrix (ordering not applied)")
        self._supernodes(indptr.astype(np.int64), indices, values)

    def _supernodes(self, indptr: np.ndarray, indices: np.ndarray, values: np.ndarray) -> None:
        """Group the columns of L into supernodes and store each as a dense panel (see :func:`_supernodal_solve`)."""
        n = self.n
        count = np.diff(indptr)
        below = np.full(n, -1)
        below[count > 1] = indices[indptr[:-1][count > 1] + 1]
        # column j + 1 continues the supernode of column j if it is j's first row below the diagonal and
        # has one row less (its rows are then exactly j's rows without j + 1: the elimination tree)
        continues = np.zeros(n, dtype=bool)
        continues[1:] = (count[:-1] == count[1:] + 1) & (below[:-1] == np.arange(1, n))
        self.starts = np.flatnonzero(~continues)
        self.ends = np.append(self.starts[1:], n)
        width = self.ends - self.starts
        n_below = count[self.starts] - width
        self.row_ptr = np.concatenate([[0], np.cumsum(n_below)])
        from corrlib.geometry.product import _ranges

        self.rows = indices[_ranges(indptr[self.starts] + width, indptr[self.starts + 1])].astype(np.int64)
        self.panel_ptr = np.concatenate([[0], np.cumsum(width * (width + n_below))])
        self.panels = np.zeros(int(self.panel_ptr[-1]))
        _fill_panels(indptr, indices, values, self.starts, self.ends, self.panel_ptr, self.panels)
        # the diagonal blocks of large supernodes are inverted once, so that the solves multiply in BLAS
        # (SciPy's, the one numba calls); their accuracy equals substitution's on the test matrices
        from scipy.linalg.lapack import dtrtri

        for s in np.flatnonzero(width * (width + n_below) >= _BLAS_MIN_WORK):
            w = int(width[s])
            diag = self.panels[self.panel_ptr[s]:self.panel_ptr[s] + w * w].reshape(w, w)
            inverse, info = dtrtri(diag, lower=1)
            if info != 0:
                raise SolverError("the Cholesky factor is singular")
            diag[:] = np.tril(inverse)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve ``A x = rhs``; ``rhs`` is (n,) or (n, m), the result has the same shape."""
        rhs = np.asarray(rhs, dtype=np.float64)
        if self._factor is not None:
            b = self._matrix(np.asfortranarray(rhs.reshape(self.n, -1)))
            self._cholmod.solve(self._factor, b)
            return np.array(b).reshape(rhs.shape)
        x = np.ascontiguousarray(rhs.reshape(self.n, -1)[self.perm])
        _supernodal_solve(self.starts, self.ends, self.row_ptr, self.rows, self.panel_ptr, self.panels, x)
        out = np.empty_like(x)
        out[self.perm] = x
        return out.reshape(rhs.shape)


def available() -> bool:
    """True if the CHOLMOD (cvxopt) and METIS (pymetis) bindings import."""
    try:
        import cvxopt.cholmod  # noqa: F401
        import pymetis  # noqa: F401
    except ImportError:
        return False
    return True
