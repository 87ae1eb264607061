"""Sparse Cholesky solves for large symmetric positive definite systems.

SciPy's only sparse factorisation is SuperLU (an LU with partial pivoting and
a column ordering), which fills in badly on graphs that are not surfaces: the
band of a product manifold X × Y is four-dimensional. For those, this module
factors ``A = L Lᵀ`` with CHOLMOD's supernodal Cholesky (through ``cvxopt``)
in a METIS nested-dissection order (through ``pymetis``). Measured on the
10 % band of two 1k-vertex meshes (103k rows): factorisation 4 s and 45 ms
per solve, against about 170 s for SuperLU's factorisation.
"""

from __future__ import annotations

import warnings

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


class CholeskySolver:
    """Factorisation ``A = L Lᵀ`` of a sparse symmetric positive definite matrix.

    Parameters
    ----------
    matrix : (n, n) sparse
        Symmetric positive definite (only the lower triangle is read).

    Raises
    ------
    SolverError
        If the matrix is not positive definite.
    """

    def __init__(self, matrix: sp.spmatrix):
        from cvxopt import cholmod, matrix as cvx_matrix, spmatrix

        lower = sp.tril(sp.csr_matrix(matrix)).tocoo()
        self.n = int(matrix.shape[0])
        a = spmatrix(cvx_matrix(lower.data.astype(np.float64)), cvx_matrix(lower.row.astype(np.int64)),
                     cvx_matrix(lower.col.astype(np.int64)), (self.n, self.n))
        perm = nested_dissection(matrix)
        self._cholmod = cholmod
        self._matrix = cvx_matrix
        options = cholmod.options
        saved = dict(options)
        options["supernodal"] = 2
        options["postorder"] = True
        try:
            self._factor = cholmod.symbolic(a, p=cvx_matrix(perm.tolist()))
            cholmod.numeric(a, self._factor)
        except ArithmeticError as exc:
            raise SolverError(f"the matrix is not positive definite ({exc})") from None
        finally:
            options.clear()
            options.update(saved)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Solve ``A x = rhs``; ``rhs`` is (n,) or (n, m), the result has the same shape."""
        rhs = np.asarray(rhs, dtype=np.float64)
        b = self._matrix(np.asfortranarray(rhs.reshape(self.n, -1)))
        self._cholmod.solve(self._factor, b)
        return np.array(b).reshape(rhs.shape)


def available() -> bool:
    """True if the CHOLMOD (cvxopt) and METIS (pymetis) bindings import."""
    try:
        import cvxopt.cholmod  # noqa: F401
        import pymetis  # noqa: F401
    except ImportError:
        return False
    return True
