"""The product manifold X × Y of two shapes (thesis ch. 9; Rodolà, Lähner et al. CGF 2019).

A function on X × Y is an (n_X, n_Y) array ``F[i, j] = f(x_i, y_j)`` (row
index on X, column index on Y; ``vec`` stacks rows, so the product vertex
(i, j) has index ``i n_Y + j``).

* Discrete product Laplacian (Theorem 4, Corollaries 3–4): mass
  ``A = A_X ⊗ A_Y``, stiffness ``S = S_X ⊗ A_Y + A_X ⊗ S_Y``.
* Product eigenbasis: eigenvalues ``α_i + β_j``, eigenfunctions
  ``φ_i ⊗ ψ_j`` (A-orthonormal when the factors are), never materialised.
* Product coefficients of a function: ``c_ab = <F, φ_a ⊗ ψ_b>_A = (Φᵀ A_X F A_Y Ψ)_ab``.
  A point-to-point map ``T`` as a density ``F = Π A_Y⁻¹`` (a delta at
  ``(x, T(x))`` normalised on Y, so ``∫ F(x, y) g(y) dy = g(T(x))``) has
  coefficients ``Φᵀ A_X Π Ψ``: exactly the functional map that pulls
  functions on Y back to X (Theorem 5).
* Heat diffusion on the product is a filter on the coefficients:
  ``e^{-tα} C e^{-tβ}``.
* Localized harmonics (Eq. 9.19): eigenfunctions of the product Laplacian
  restricted to a band P of product vertices with Dirichlet boundary
  (rows and columns outside P removed); the Hamiltonian variant
  ``S + V A`` (Eq. 9.17–9.18) puts a step potential on a domain around P.
  Built from the factors' sparse matrices for the band only: the cost grows
  with |P|, not with n_X n_Y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from corrlib.errors import InputError, ParameterError

#: relative accuracy of the localized harmonics' eigenvalues (ARPACK ``tol``); machine precision
#: costs about 10 % more Lanczos steps on large bands and changes nothing downstream
HARMONICS_TOL = 1e-8
#: bands of two surfaces from this many product vertices on use block Lanczos (measured, 200 harmonics
#: on bands of two 1k-vertex meshes, ARPACK against block Lanczos: 1 % band, 10.6k rows, 4.5 s against
#: 5.4 s; 2 %, 21k rows, 10.1 s against 7.6 s; 10 %, 103k rows, 97 s against 37-41 s)
BLOCK_LANCZOS_MIN_ROWS = 16000


@dataclass(frozen=True)
class Factor:
    """One factor of the product: its FEM matrices and lowest eigenpairs.

    Attributes
    ----------
    stiffness, mass : (n, n) sparse
    evals : (k,) float
    evecs : (n, k) float, mass-orthonormal
    unit : float
        Squared length scale (area of a surface, squared length of a curve):
        ``evals * unit`` are scale-free, so diffusion times can be given
        relative to it.
    dim : int
        1 for a curve, 2 for a surface.
    """

    stiffness: sp.csr_matrix
    mass: sp.csr_matrix
    evals: np.ndarray
    evecs: np.ndarray
    unit: float = 1.0
    dim: int = 2

    @property
    def n(self) -> int:
        return int(self.stiffness.shape[0])

    @property
    def k(self) -> int:
        return int(self.evals.shape[0])


def curve_factor(points, k: int, mass: str = "consistent") -> Factor:
    """Factor of a closed curve (FEM of Eq. 9.1–9.2, consistent mass by default)."""
    from corrlib.geometry.laplacian import curve_laplacian
    from corrlib.geometry.spectrum import eigenpairs

    stiff, m = curve_laplacian(points, mass=mass)
    k = min(int(k), stiff.shape[0])
    evals, evecs = eigenpairs(stiff, m, k, name="curve")
    return Factor(stiff, m, evals, evecs, float(m.sum()) ** 2, dim=1)


def mesh_factor(mesh, k: int) -> Factor:
    """Factor of a triangle mesh (cotangent Laplacian, lumped mass; spectrum from the disk cache)."""
    from corrlib.geometry.spectrum import available_eigenpairs, mesh_spectrum

    spec = mesh_spectrum(mesh, available_eigenpairs(mesh, k, "the product manifold"))
    return Factor(spec.stiffness, spec.mass, spec.evals, spec.evecs, float(mesh.area))


# ----------------------------------------------------------------------------- operators


def product_operator(fx: Factor, fy: Factor, pairs=None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Stiffness and mass of X × Y, optionally restricted to product vertices (Dirichlet outside).

    Parameters
    ----------
    fx, fy : Factor
    pairs : (p, 2) int, optional
        Product vertices ``(i, j)`` of the band, unique; all of X × Y if omitted
        (only sensible for small factors).

    Returns
    -------
    stiffness, mass : (p, p) csr_matrix
        ``S_X ⊗ A_Y + A_X ⊗ S_Y`` and ``A_X ⊗ A_Y`` on the band, in the order of ``pairs``.
    """
    if pairs is None:
        return ((sp.kron(fx.stiffness, fy.mass) + sp.kron(fx.mass, fy.stiffness)).tocsr(),
                sp.kron(fx.mass, fy.mass).tocsr())
    pairs = check_pairs(pairs, fx.n, fy.n)
    keys = pairs[:, 0] * fy.n + pairs[:, 1]
    order = np.argsort(keys)
    sorted_keys = keys[order]
    # every nonzero couples (i, j) with (k, l), k in the X-stencil of i and l in the Y-stencil of j
    pattern_x = (abs(fx.stiffness) + abs(fx.mass)).tocsr()
    pattern_y = (abs(fy.stiffness) + abs(fy.mass)).tocsr()
    sx, ax = fx.stiffness.tocsr(), fx.mass.tocsr()
    sy, ay = fy.stiffness.tocsr(), fy.mass.tocsr()
    rows_x = np.repeat(np.arange(len(pairs)), np.diff(pattern_x.indptr)[pairs[:, 0]])
    cols_x = pattern_x.indices[_ranges(pattern_x.indptr[pairs[:, 0]], pattern_x.indptr[pairs[:, 0] + 1])]
    j_of_row = pairs[rows_x, 1]
    counts_y = np.diff(pattern_y.indptr)[j_of_row]
    rows = np.repeat(rows_x, counts_y)
    ks = np.repeat(cols_x, counts_y)
    ls = pattern_y.indices[_ranges(pattern_y.indptr[j_of_row], pattern_y.indptr[j_of_row + 1])]
    target = ks * fy.n + ls
    pos = np.searchsorted(sorted_keys, target)
    pos = np.minimum(pos, len(sorted_keys) - 1)
    inside = sorted_keys[pos] == target
    rows, ks, ls, cols = rows[inside], ks[inside], ls[inside], order[pos[inside]]
    i, j = pairs[rows, 0], pairs[rows, 1]
    sx_v, ax_v = _entries(sx, i, ks), _entries(ax, i, ks)
    sy_v, ay_v = _entries(sy, j, ls), _entries(ay, j, ls)
    n = len(pairs)
    stiffness = sp.csr_matrix((sx_v * ay_v + ax_v * sy_v, (rows, cols)), shape=(n, n))
    mass = sp.csr_matrix((ax_v * ay_v, (rows, cols)), shape=(n, n))
    stiffness.eliminate_zeros()
    mass.eliminate_zeros()
    return stiffness, mass


def _ranges(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(s, e)`` for every pair (vectorised)."""
    lengths = stops - starts
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    offsets = np.repeat(starts - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
    return np.arange(total) + offsets


def _entries(matrix: sp.csr_matrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Values ``matrix[rows, cols]`` (0 where there is no entry), vectorised."""
    return np.asarray(matrix[rows, cols]).ravel()


def check_pairs(pairs, n_x: int, n_y: int) -> np.ndarray:
    """(p, 2) int64 product vertices, validated (in range, unique, non-empty)."""
    p = np.asarray(pairs)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise InputError(f"product vertices must be a non-empty (p, 2) array of (i, j), got shape {p.shape}")
    p = p.astype(np.int64)
    if p[:, 0].min() < 0 or p[:, 0].max() >= n_x or p[:, 1].min() < 0 or p[:, 1].max() >= n_y:
        raise InputError(f"product vertices out of range for {n_x} x {n_y}")
    if len(np.unique(p[:, 0] * n_y + p[:, 1])) != len(p):
        raise InputError("product vertices contain duplicates")
    return p


# ----------------------------------------------------------------------------- product eigenbasis


def product_eigenbasis(fx: Factor, fy: Factor, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` lowest product eigenpairs from the factors' (Theorem 4).

    Returns
    -------
    evals : (k,) float
        ``α_i + β_j`` ascending (ties: smaller i first).
    index : (k, 2) int
        ``(i, j)``: the eigenfunction is ``φ_i ⊗ ψ_j``.
    """
    if k < 1 or k > fx.k * fy.k:
        raise ParameterError(f"k = {k} product eigenpairs requested from {fx.k} x {fy.k} factor eigenpairs")
    sums = fx.evals[:, None] + fy.evals[None, :]
    flat = np.lexsort((np.repeat(np.arange(fx.k), fy.k), sums.ravel()))[:k]
    index = np.column_stack(np.unravel_index(flat, sums.shape))
    return sums.ravel()[flat], index


def product_coefficients(values, fx: Factor, fy: Factor) -> np.ndarray:
    """(k_X, k_Y) coefficients ``Φᵀ A_X F A_Y Ψ`` of a product function ``F`` (n_X, n_Y), dense or sparse."""
    left = np.asarray(fx.evecs.T @ (fx.mass @ values))  # (k_X, n_Y) dense even for a sparse F
    return left @ (fy.mass @ fy.evecs)


def map_density(map_xy, fy: Factor):
    """A point-to-point map as a density on X × Y: ``F = Π A_Y⁻¹`` (n_X, n_Y).

    ``∫ F(x, y) g(y) dy = g(T(x))`` for nodal functions g, which makes its product
    coefficients the functional map (Theorem 5). Sparse for a diagonal (lumped)
    target mass, dense otherwise.
    """
    m = np.asarray(map_xy, dtype=np.int64)
    if m.ndim != 1 or m.size == 0 or m.min() < 0 or m.max() >= fy.n:
        raise InputError(f"the map must hold {fy.n}-vertex target indices for every source vertex")
    mass = fy.mass.tocsr()
    if mass.nnz == np.count_nonzero(mass.diagonal()):
        return sp.csr_matrix((1.0 / mass.diagonal()[m], (np.arange(m.size), m)), shape=(m.size, fy.n))
    import scipy.sparse.linalg as spla

    inverse_rows = spla.splu(mass.tocsc()).solve(np.eye(fy.n)[:, np.unique(m)])  # A_Y⁻¹ e_j (symmetric)
    lookup = np.searchsorted(np.unique(m), m)
    return inverse_rows[:, lookup].T


def functional_map(map_xy, fx: Factor, fy: Factor) -> np.ndarray:
    """(k_X, k_Y) functional map pulling functions on Y back to X: ``Φᵀ A_X Π Ψ``."""
    m = np.asarray(map_xy, dtype=np.int64)
    return fx.evecs.T @ (fx.mass @ fy.evecs[m])


def diffuse(coeffs: np.ndarray, fx: Factor, fy: Factor, t: float) -> np.ndarray:
    """Heat diffusion on the product in spectral form: ``e^{-tα} C e^{-tβ}``.

    ``t`` is relative to the factors' scales (each factor's eigenvalues are
    multiplied by its ``unit``), so both shapes diffuse alike whatever their size.
    """
    return np.exp(-t * fx.unit * fx.evals)[:, None] * coeffs * np.exp(-t * fy.unit * fy.evals)[None, :]


def density_values(coeffs: np.ndarray, fx: Factor, fy: Factor, rows=None) -> np.ndarray:
    """(r, n_Y) values ``Φ C Ψᵀ`` of a product function on the given rows of X (all by default)."""
    phi = fx.evecs if rows is None else fx.evecs[rows]
    return (phi @ coeffs) @ fy.evecs.T


def ml_map(coeffs: np.ndarray, fx: Factor, fy: Factor, chunk: int = 2048) -> np.ndarray:
    """(n_X,) maximum-likelihood map of a density: ``argmax_j F[i, j]`` for every row (chunked)."""
    out = np.empty(fx.n, dtype=np.int64)
    for start in range(0, fx.n, chunk):
        rows = np.arange(start, min(fx.n, start + chunk))
        out[rows] = density_values(coeffs, fx, fy, rows).argmax(axis=1)
    return out


# ----------------------------------------------------------------------------- localized harmonics


def band_components(stiffness: sp.csr_matrix) -> tuple[int, np.ndarray]:
    """Connected components of a band (from its operator's sparsity): count and (p,) labels."""
    from scipy.sparse.csgraph import connected_components

    count, labels = connected_components(stiffness, directed=False)
    return int(count), labels


def largest_piece(fx: Factor, fy: Factor, pairs) -> np.ndarray:
    """The product vertices of the largest connected piece of a band."""
    pairs = check_pairs(pairs, fx.n, fy.n)
    count, labels = band_components(product_operator(fx, fy, pairs)[0])
    if count == 1:
        return pairs
    return pairs[labels == np.bincount(labels).argmax()]


def localized_harmonics(fx: Factor, fy: Factor, pairs, k: int, *, potential: float | None = None,
                        domain=None) -> tuple[np.ndarray, np.ndarray]:
    """Eigenfunctions of the product Laplacian localized on a band.

    Parameters
    ----------
    fx, fy : Factor
    pairs : (p, 2) int
        The band P (product vertices).
    k : int
        Number of harmonics.
    potential : float, optional
        Hamiltonian variant (Eq. 9.17–9.18): ``S + v A_out`` on ``domain`` with
        the step potential ``v`` outside P. Default: Dirichlet boundary on P (Eq. 9.19).
    domain : (q, 2) int, optional
        For the Hamiltonian: a superset of P (default: P plus every product
        vertex adjacent to it).

    Returns
    -------
    evals : (k,) float
    evecs : (|P|, k) or (|domain|, k) float
        Mass-orthonormal on the band (or domain), rows in the order of ``pairs`` (or ``domain``).

    Raises
    ------
    InputError
        If the band disconnects (its harmonics would split into unrelated pieces).
    """
    from corrlib.geometry.spectrum import eigenpairs

    pairs = check_pairs(pairs, fx.n, fy.n)
    if potential is None:
        stiff, mass = product_operator(fx, fy, pairs)
    else:
        if domain is None:
            domain = dilate(fx, fy, pairs)
        domain = check_pairs(domain, fx.n, fy.n)
        stiff, mass = product_operator(fx, fy, domain)
        outside = ~np.isin(domain[:, 0] * fy.n + domain[:, 1], pairs[:, 0] * fy.n + pairs[:, 1])
        lumped = np.asarray(mass.sum(axis=1)).ravel()
        stiff = (stiff + sp.diags(potential * lumped * outside)).tocsr()
    n_parts = band_components(stiff)[0]
    if n_parts > 1:
        raise InputError(f"the band of {len(pairs)} product vertices falls apart into {n_parts} pieces; "
                         f"widen it (a larger band fraction) or start from a smoother map")
    if k < 1 or k >= stiff.shape[0]:
        raise ParameterError(f"k = {k} harmonics requested on a band of {stiff.shape[0]} product vertices")
    # a band of a product of two surfaces is four-dimensional: its Cholesky factor fills in so much
    # that block solves (block Lanczos) beat ARPACK's single ones from BLOCK_LANCZOS_MIN_ROWS rows on
    block = fx.dim + fy.dim >= 4 and stiff.shape[0] >= BLOCK_LANCZOS_MIN_ROWS
    return eigenpairs(stiff, mass, k, name="band", check_connected=False, tol=HARMONICS_TOL,
                      method="block" if block else "auto")


def dilate(fx: Factor, fy: Factor, pairs) -> np.ndarray:
    """P plus every product vertex adjacent to it (one ring in X × Y)."""
    pairs = check_pairs(pairs, fx.n, fy.n)
    adj_x = (abs(fx.stiffness) + sp.identity(fx.n)).tocsr()
    adj_y = (abs(fy.stiffness) + sp.identity(fy.n)).tocsr()
    ind = sp.csr_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(fx.n, fy.n))
    grown = (adj_x @ ind @ adj_y).tocoo()
    return np.column_stack([grown.row, grown.col]).astype(np.int64)


def band_around_map(map_xy, target_points: np.ndarray, fraction: float) -> np.ndarray:
    """(p, 2) band: for every source vertex i the ``ceil(fraction n_Y)`` target vertices nearest to
    ``map_xy[i]`` (Euclidean on the target), so |P| ≈ fraction · n_X · n_Y."""
    from scipy.spatial import cKDTree

    if not 0 < fraction <= 1:
        raise ParameterError(f"the band fraction must lie in (0, 1], got {fraction}")
    m = np.asarray(map_xy, dtype=np.int64)
    n_y = len(target_points)
    width = max(1, int(np.ceil(fraction * n_y)))
    if width >= n_y:
        cols = np.tile(np.arange(n_y), (m.size, 1))
    else:
        _, cols = cKDTree(target_points).query(target_points[m], k=width)
        cols = np.asarray(cols).reshape(m.size, width)
    return np.column_stack([np.repeat(np.arange(m.size), cols.shape[1]), cols.ravel()]).astype(np.int64)
