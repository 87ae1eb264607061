"""Sparse Cholesky solves for large symmetric positive definite systems.

SciPy's only sparse factorisation is SuperLU (an LU with partial pivoting and
a column ordering), which fills in badly on graphs that are not surfaces: the
band of a product manifold X × Y is four-dimensional. For those, this module
factors ``P A Pᵀ = L Lᵀ`` in a METIS nested-dissection order ``P`` (through
``pymetis``), post-ordered along the elimination tree.

For blocks of right-hand sides (block Lanczos, :mod:`corrlib.geometry.lanczos`)
the factorisation is this module's own supernodal multifrontal Cholesky
(symbolic analysis and the assembly in numba, the dense fronts in SciPy's
LAPACK/BLAS: ``dpotrf``, ``dtrsm``, ``dsyrk``), stored as supernodes — dense
panels of columns with a common row pattern — so that the solves multiply
whole blocks in BLAS, which CHOLMOD's one-at-a-time solves (and its
bundled single-threaded BLAS) cannot (measured: ``docs/decisions.md``).

Single right-hand sides (``blocks=False``, ARPACK) use CHOLMOD's supernodal
factorisation and solve (through ``cvxopt``).
"""

from __future__ import annotations

import warnings

import llvmlite.binding as llvm
import numba
import numpy as np
import scipy.sparse as sp
from numba import types
from numba.extending import get_cython_function_address

from corrlib.errors import SolverError

# SciPy's LAPACK/BLAS (Fortran calling convention: every argument by address) as external symbols of the
# compiled code, so that it can be cached on disk (ctypes pointers cannot)
for _module, _name in (("cython_lapack", "dpotrf"), ("cython_blas", "dtrsm"), ("cython_blas", "dsyrk")):
    llvm.add_symbol(f"corrlib_{_name}", get_cython_function_address(f"scipy.linalg.{_module}", _name))
_dpotrf = types.ExternalFunction("corrlib_dpotrf", types.void(*([types.intp] * 5)))
_dtrsm = types.ExternalFunction("corrlib_dtrsm", types.void(*([types.intp] * 11)))
_dsyrk = types.ExternalFunction("corrlib_dsyrk", types.void(*([types.intp] * 10)))


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
def _elimination_tree(row_ptr, cols):
    """(n,) int: parent of every column in the elimination tree (-1: root); the lower triangle by rows."""
    n = row_ptr.size - 1
    parent = -np.ones(n, dtype=np.int64)
    ancestor = -np.ones(n, dtype=np.int64)  # path-compressed ancestors (Liu)
    for k in range(n):
        for p in range(row_ptr[k], row_ptr[k + 1]):
            j = cols[p]
            while j != -1 and j < k:
                nxt = ancestor[j]
                ancestor[j] = k
                if nxt == -1:
                    parent[j] = k
                    break
                j = nxt
    return parent


@numba.njit(cache=True)
def _postorder(parent):
    """(n,) int: the columns in a depth-first postorder of the forest (children in increasing order)."""
    n = parent.size
    head = -np.ones(n, dtype=np.int64)
    sibling = -np.ones(n, dtype=np.int64)
    for j in range(n - 1, -1, -1):
        if parent[j] >= 0:
            sibling[j] = head[parent[j]]
            head[parent[j]] = j
    order = np.empty(n, dtype=np.int64)
    stack = np.empty(n, dtype=np.int64)
    k = 0
    for root in range(n):
        if parent[root] != -1:
            continue
        top = 0
        stack[0] = root
        while top >= 0:
            j = stack[top]
            child = head[j]
            if child == -1:
                top -= 1
                order[k] = j
                k += 1
            else:
                head[j] = sibling[child]
                top += 1
                stack[top] = child
    return order


@numba.njit(cache=True)
def _column_counts(row_ptr, cols, parent):
    """(n,) int: entries of every column of L (diagonal included).

    Row i of L holds the columns on the tree paths from each k with ``A[i, k] != 0`` (k < i) up to i.
    """
    n = parent.size
    count = np.ones(n, dtype=np.int64)
    mark = -np.ones(n, dtype=np.int64)
    for i in range(n):
        mark[i] = i
        for p in range(row_ptr[i], row_ptr[i + 1]):
            j = cols[p]
            while mark[j] != i:
                count[j] += 1
                mark[j] = i
                j = parent[j]
    return count


@numba.njit(cache=True)
def _append_rows(candidates, first, mark, stamp, out, m):
    """Append the candidates >= ``first`` not yet marked with ``stamp`` to ``out`` from position m; the new m."""
    for i in candidates:
        if i >= first and mark[i] != stamp:
            mark[i] = stamp
            out[m] = i
            m += 1
    return m


@numba.njit(cache=True)
def _supernode_rows(col_ptr, rows_a, starts, ends, parent, row_ptr):
    """Rows below the diagonal block of every supernode, and the supernodal tree.

    The rows of supernode s are those of its columns in A below the supernode, and those of its child
    supernodes' rows below it.

    Returns
    -------
    rows : (row_ptr[-1],) int
        Sorted rows of every supernode.
    child_ptr, children : int
        The child supernodes of s: ``children[child_ptr[s]:child_ptr[s + 1]]``.
    """
    n = parent.size
    count = starts.size
    snode_of = np.empty(n, dtype=np.int64)
    for s in range(count):
        snode_of[starts[s]:ends[s]] = s
    snode_parent = -np.ones(count, dtype=np.int64)
    child_ptr = np.zeros(count + 1, dtype=np.int64)
    for s in range(count):
        if parent[ends[s] - 1] >= 0:
            snode_parent[s] = snode_of[parent[ends[s] - 1]]
            child_ptr[snode_parent[s] + 1] += 1
    child_ptr = np.cumsum(child_ptr)
    fill = child_ptr[:-1].copy()
    children = np.empty(max(child_ptr[-1], 1), dtype=np.int64)
    for s in range(count):
        if snode_parent[s] >= 0:
            children[fill[snode_parent[s]]] = s
            fill[snode_parent[s]] += 1
    rows = np.empty(row_ptr[-1], dtype=np.int64)
    mark = -np.ones(n, dtype=np.int64)
    for s in range(count):
        c1 = ends[s]
        out = rows[row_ptr[s]:row_ptr[s + 1]]
        m = _append_rows(rows_a[col_ptr[starts[s]]:col_ptr[c1]], c1, mark, s, out, 0)
        for q in range(child_ptr[s], child_ptr[s + 1]):
            t = children[q]
            m = _append_rows(rows[row_ptr[t]:row_ptr[t + 1]], c1, mark, s, out, m)
        out.sort()
    return rows, child_ptr, children


@numba.njit(cache=True)
def _multifrontal(col_ptr, rows_a, values, starts, ends, row_ptr, rows, child_ptr, children, panel_ptr, panels,
                  chars, scalars, dims):
    """Numeric factorisation into the supernodes' panels (layout of :func:`_supernodal_solve`).

    Supernode s's front (its columns, then its rows below) is assembled from A's lower triangle and its
    children's update matrices (extend-add), then ``L11 = chol(F11)``, ``L21 = F21 L11⁻ᵀ`` and the update
    ``F22 - L21 L21ᵀ`` for its parent. The fronts are C-ordered lower triangles, i.e. upper triangles for
    the column-major LAPACK/BLAS calls.

    ``chars`` (b"LUTN" as uint8), ``scalars`` ([1.0, -1.0]) and ``dims`` ((4,) int32: w, r, f, info) hold
    the by-address arguments of the LAPACK/BLAS calls; the caller owns them (numba may free an array it
    created after its last use in the code, before the foreign call has read it).

    Returns
    -------
    int
        -1, or the supernode whose diagonal block is not positive definite.
    """
    n = ends[-1]
    pos = np.empty(n, dtype=np.int64)
    fronts = [np.empty((0, 0)) for _ in range(starts.size)]
    side, upper, trans, nonunit = chars.ctypes.data, chars.ctypes.data + 1, chars.ctypes.data + 2, \
        chars.ctypes.data + 3
    one, minus_one = scalars.ctypes.data, scalars.ctypes.data + 8
    w_p, r_p, f_p, info_p = dims.ctypes.data, dims.ctypes.data + 4, dims.ctypes.data + 8, dims.ctypes.data + 12
    for s in range(starts.size):
        c0, c1 = starts[s], ends[s]
        w = c1 - c0
        below = rows[row_ptr[s]:row_ptr[s + 1]]
        r = below.size
        f = w + r
        front = np.zeros((f, f))
        for q in range(w):
            pos[c0 + q] = q
        for a in range(r):
            pos[below[a]] = w + a
        for col in range(c0, c1):
            for p in range(col_ptr[col], col_ptr[col + 1]):
                front[pos[rows_a[p]], col - c0] += values[p]
        for q in range(child_ptr[s], child_ptr[s + 1]):
            t = children[q]
            wt = ends[t] - starts[t]
            rows_t = rows[row_ptr[t]:row_ptr[t + 1]]
            update = fronts[t]
            for a in range(rows_t.size):
                ia = pos[rows_t[a]]
                for b in range(a + 1):
                    front[ia, pos[rows_t[b]]] += update[wt + a, wt + b]
            fronts[t] = np.empty((0, 0))
        dims[0], dims[1], dims[2] = w, r, f
        base = front.ctypes.data
        _dpotrf(upper, w_p, base, f_p, info_p)
        if dims[3] != 0:
            return s
        if r > 0:
            lower_block = base + 8 * w * f  # column-major (0, w): F21ᵀ
            _dtrsm(side, upper, trans, nonunit, w_p, r_p, one, base, f_p, lower_block, f_p)
            _dsyrk(upper, trans, r_p, w_p, minus_one, lower_block, f_p, one, lower_block + 8 * w, f_p)
            fronts[s] = front
        panel = panels[panel_ptr[s]:panel_ptr[s + 1]].reshape((f, w))
        for i in range(f):
            for j in range(min(i + 1, w)):
                panel[i, j] = front[i, j]
    return -1


@numba.njit(cache=True, fastmath=True)
def _supernodal_solve(starts, ends, row_ptr, rows, panel_ptr, panels, x):
    """Overwrite ``x`` (n, m) with ``(L Lᵀ)⁻¹ x``.

    Each supernode s (columns ``starts[s]:ends[s]`` of ``L``, sharing the rows
    ``rows[row_ptr[s]:row_ptr[s + 1]]`` below their diagonal block) is a dense
    panel: its lower-triangular diagonal block ``D``, then the block ``B`` below
    it. Forward: ``x_s ← D⁻¹ x_s``, ``x_R -= B x_s``; backward:
    ``x_s ← D⁻ᵀ (x_s − Bᵀ x_R)``. Small supernodes are solved by substitution;
    large ones hold ``D⁻¹`` instead of ``D`` (see :meth:`CholeskySolver._multifrontal`)
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
        Symmetric positive definite.
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
        If the matrix is not symmetric or not positive definite.
    """

    def __init__(self, matrix: sp.spmatrix, *, blocks: bool = True):
        self.n = int(matrix.shape[0])
        square = matrix.shape == (self.n, self.n)
        asymmetry = abs(matrix - matrix.T).max() if square and matrix.nnz else 0.0
        if not square or asymmetry > 1e-12 * abs(matrix).max():
            raise SolverError(f"the Cholesky factorisation needs a square symmetric matrix "
                              f"(shape {matrix.shape}, largest asymmetry {asymmetry:.3g})")
        self.perm = nested_dissection(matrix)
        self._factor = None
        if blocks:
            self._multifrontal(sp.csr_matrix(matrix))
            return
        from cvxopt import cholmod, matrix as cvx_matrix, spmatrix

        lower = sp.tril(sp.csr_matrix(matrix)).tocoo()
        a = spmatrix(cvx_matrix(lower.data.astype(np.float64)), cvx_matrix(lower.row.astype(np.int64)),
                     cvx_matrix(lower.col.astype(np.int64)), (self.n, self.n))
        del lower
        options = cholmod.options
        saved = dict(options)
        # supernodal; CHOLMOD may try AMD too and keep the better order (the 5 % contour band: 1.7 s
        # against 2.2 s with the METIS order forced)
        options["supernodal"] = 2
        options["postorder"] = True
        try:
            factor = cholmod.symbolic(a, p=cvx_matrix(self.perm.tolist()))
            cholmod.numeric(a, factor)
        except ArithmeticError as exc:
            raise SolverError(f"the matrix is not positive definite ({exc})") from None
        finally:
            options.clear()
            options.update(saved)
        self._cholmod, self._matrix, self._factor = cholmod, cvx_matrix, factor
        self.nnz = None

    def _multifrontal(self, matrix: sp.csr_matrix) -> None:
        """Symbolic analysis and numeric factorisation into supernodal panels (see :func:`_multifrontal`)."""
        def lower_by_rows(perm):
            low = sp.tril(matrix[perm][:, perm]).tocsr()
            low.sort_indices()
            return low.indptr.astype(np.int64), low.indices.astype(np.int64), low

        # post-ordering the elimination tree makes every supernode a run of consecutive columns
        self.perm = self.perm[_postorder(_elimination_tree(*lower_by_rows(self.perm)[:2]))]
        row_ptr_a, cols_a, low = lower_by_rows(self.perm)
        parent = _elimination_tree(row_ptr_a, cols_a)
        count = _column_counts(row_ptr_a, cols_a, parent)
        self.nnz = int(count.sum())
        n = self.n
        # column j + 1 continues the supernode of column j if it is j's parent and has one entry less
        # (its rows are then exactly j's rows without j + 1)
        continues = np.zeros(n, dtype=bool)
        continues[1:] = (parent[:-1] == np.arange(1, n)) & (count[:-1] == count[1:] + 1)
        self.starts = np.flatnonzero(~continues)
        self.ends = np.append(self.starts[1:], n)
        width = self.ends - self.starts
        n_below = count[self.starts] - width
        self.row_ptr = np.concatenate([[0], np.cumsum(n_below)]).astype(np.int64)
        by_cols = low.T.tocsr()  # the lower triangle by columns (rows >= j in column j)
        by_cols.sort_indices()
        col_ptr, rows_a = by_cols.indptr.astype(np.int64), by_cols.indices.astype(np.int64)
        self.rows, child_ptr, children = _supernode_rows(col_ptr, rows_a, self.starts, self.ends, parent,
                                                         self.row_ptr)
        self.panel_ptr = np.concatenate([[0], np.cumsum(width * (width + n_below))]).astype(np.int64)
        self.panels = np.empty(int(self.panel_ptr[-1]))
        failed = _multifrontal(col_ptr, rows_a, by_cols.data.astype(np.float64), self.starts, self.ends,
                               self.row_ptr, self.rows, child_ptr, children, self.panel_ptr, self.panels,
                               np.frombuffer(b"LUTN", dtype=np.uint8).copy(), np.array([1.0, -1.0]),
                               np.zeros(4, dtype=np.int32))
        if failed >= 0:
            raise SolverError(f"the matrix is not positive definite (pivot failure in columns "
                              f"{self.starts[failed]}..{self.ends[failed] - 1} of its Cholesky factor)")
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
