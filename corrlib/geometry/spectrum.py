"""Generalized symmetric eigenproblem ``S phi = lambda M phi`` for the lowest eigenpairs.

Two solvers, same answer:

* ``"eigsh"``: one ARPACK shift-invert run (``scipy.sparse.linalg.eigsh``
  with ``sigma`` slightly below zero).
* ``"slicing"``: spectrum slicing. Several shift-invert runs with a modest
  number of eigenpairs each, at shifts moving up the spectrum. A run at shift
  ``sigma`` returns the eigenvalues nearest to it, i.e. *all* eigenvalues in
  ``[sigma - r, sigma + r]``; eigenvalues within a tolerance of the interval
  ends are discarded (a degenerate eigenspace may be only partly captured
  there) and the next shift is placed so that its interval overlaps the
  trusted part of the previous one. Consecutive intervals are glued at a cut
  that lies in a spectral gap, so no eigenvalue is lost or counted twice.
  ARPACK keeps a Krylov basis of about twice the eigenpairs asked for and
  re-orthogonalises every new vector against all of it, so a run costs
  about ``n s²`` for ``s`` eigenpairs, ``n s`` per eigenpair: small runs are
  cheaper per eigenpair, until the fixed cost of a run (its factorisation,
  its start, the overlap it discards) dominates. Between the two the cost
  is flat over a wide range of slice sizes (``docs/decisions.md``).

``"auto"`` (default) picks slicing for k > ``AUTO_SLICING_K`` (two slices). Output eigenvectors are
M-orthonormal (``evecs.T @ M @ evecs == I``); with a diagonal (lumped) mass
the problem is solved in the equivalent standard form
``M^{-1/2} S M^{-1/2} u = lambda u``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from corrlib import cache
from corrlib.errors import InputError, ParameterError, SolverError
from corrlib.geometry.lanczos import block_lanczos

#: eigenpairs per shift-invert run in spectrum slicing (the middle of the flat optimum measured on
#: 5k-20k-vertex meshes, docs/decisions.md)
SLICE_SIZE = 40
#: "auto" uses spectrum slicing above this many eigenpairs: from two slices on, slicing is the cheaper
AUTO_SLICING_K = 2 * SLICE_SIZE
#: problems with at most this many rows are solved densely
DENSE_LIMIT = 600
#: shift-invert runs below zero use a sparse Cholesky factorisation from this many rows on (SuperLU
#: is as fast on surface meshes up to here, far slower on product bands beyond); method="block"
#: always does
CHOLESKY_MIN_ROWS = 10000
#: SuperLU's diagonal pivot threshold in symmetric mode (:meth:`_ShiftInvert._symmetric_lu`): a diagonal entry
#: is the pivot if it is at least this fraction of its column's largest (1: partial pivoting, 0: none)
SYMMETRIC_PIVOT_THRESHOLD = 0.1
#: vectors per block of the block Lanczos runs: k / 12 within these bounds (a larger block makes the
#: solves cheaper per vector, a smaller one needs fewer vectors: 16 is best for 200 harmonics on a
#: 103k-row band, measured)
LANCZOS_BLOCK = (4, 16)


@dataclass(frozen=True)
class Spectrum:
    """Lowest eigenpairs of a shape's Laplacian.

    Attributes
    ----------
    evals : (k,) float
        Non-negative, ascending (the first is ~0 for a connected shape).
    evecs : (n, k) float
        M-orthonormal eigenvectors.
    stiffness : (n, n) scipy.sparse.csr_matrix
    mass : (n, n) scipy.sparse.csr_matrix
    """

    evals: np.ndarray
    evecs: np.ndarray
    stiffness: sp.csr_matrix
    mass: sp.csr_matrix

    @property
    def k(self) -> int:
        return int(self.evals.shape[0])

    def truncated(self, k: int) -> "Spectrum":
        """The first ``k`` eigenpairs."""
        return Spectrum(self.evals[:k], self.evecs[:, :k], self.stiffness, self.mass)

    def at_unit_area(self, area: float) -> "Spectrum":
        """The eigenpairs of the surface scaled to unit area (``area``: its area now).

        Scaling a surface by ``s`` multiplies its mass by ``s²`` and leaves the cotangent stiffness as it is,
        so the eigenvalues become ``λ s²`` and the mass-orthonormal eigenvectors ``φ s``. With ``s² = 1 /
        area``: eigenvalues ``λ · area``, eigenvectors ``φ √area``, orthonormal under ``M / area``. What is
        computed from this spectrum (spectral descriptors, functional maps, nearest neighbours in the
        eigenbasis) does not depend on the units of either shape of a pair.
        """
        if not area > 0:
            raise InputError(f"a spectrum is scaled to unit area by a positive area, got {area}")
        return Spectrum(self.evals * area, self.evecs * np.sqrt(area), self.stiffness, self.mass / area)


def _is_diagonal(m: sp.spmatrix) -> bool:
    m = sp.csr_matrix(m)
    return m.nnz == np.count_nonzero(m.diagonal()) and (m - sp.diags(m.diagonal())).count_nonzero() == 0


def _check_inputs(stiffness, mass, k: int, name: str):
    if not (sp.issparse(stiffness) and sp.issparse(mass)):
        raise InputError(f"{name}: stiffness and mass must be scipy.sparse matrices")
    n = stiffness.shape[0]
    if stiffness.shape != (n, n) or mass.shape != (n, n):
        raise InputError(f"{name}: stiffness {stiffness.shape} and mass {mass.shape} must be square and equal")
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ParameterError(f"{name}: the number of eigenpairs k must be a positive integer, got {k!r}")
    if k > n:
        raise ParameterError(f"{name}: {k} eigenpairs requested but the shape has only {n} vertices")
    if not (np.all(np.isfinite(stiffness.data)) and np.all(np.isfinite(mass.data))):
        raise InputError(f"{name}: the Laplacian has non-finite entries (degenerate geometry)")
    if np.any(mass.diagonal() <= 0):
        bad = np.flatnonzero(mass.diagonal() <= 0)
        raise InputError(f"{name}: {bad.size} vertices have zero or negative mass (e.g. vertex {bad[0]}): "
                         "unreferenced vertices or zero-area faces")


def _m_orthonormalize(evecs: np.ndarray, mass: sp.spmatrix) -> np.ndarray:
    gram = evecs.T @ (mass @ evecs)
    if np.max(np.abs(gram - np.eye(gram.shape[0]))) < 1e-10:
        return evecs
    chol = np.linalg.cholesky(0.5 * (gram + gram.T))
    return sla.solve_triangular(chol, evecs.T, lower=True).T


def _dense(stiffness, mass, k):
    evals, evecs = sla.eigh(stiffness.toarray(), mass.toarray(), subset_by_index=[0, k - 1])
    return evals, evecs


class _ShiftInvert:
    """Factorisation-backed eigsh runs at arbitrary shifts (standard form if the mass is diagonal).

    Below zero the shifted matrix is positive definite; large problems then
    use a sparse Cholesky factorisation (:mod:`corrlib.geometry.cholesky`)
    instead of eigsh's internal SuperLU.
    """

    def __init__(self, stiffness, mass):
        self.mass = mass.tocsc()
        self.diag_mass = _is_diagonal(mass)
        if self.diag_mass:
            self.scale = 1.0 / np.sqrt(mass.diagonal())
            d = sp.diags(self.scale)
            self.a = (d @ stiffness @ d).tocsc()
        else:
            self.a = stiffness.tocsc()

    def _cholesky(self, sigma: float, blocks: bool = False):
        """A Cholesky factorisation of the shifted matrix, or None where SuperLU is used."""
        from corrlib.geometry import cholesky

        n = self.a.shape[0]
        if sigma >= 0 or (n < CHOLESKY_MIN_ROWS and not blocks) or not cholesky.available():
            return None
        return cholesky.CholeskySolver(self._shifted(sigma), blocks=blocks)

    def _shifted(self, sigma: float) -> sp.csc_matrix:
        """``A − σM`` (``A − σI`` for a diagonal mass, which ``A`` is scaled by)."""
        n = self.a.shape[0]
        return (self.a - sigma * (sp.identity(n, format="csc") if self.diag_mass else self.mass)).tocsc()

    def _symmetric_lu(self, sigma: float) -> spla.LinearOperator:
        """``(A − σM)⁻¹`` by SuperLU in its symmetric mode: a minimum-degree ordering of ``A + Aᵀ`` and pivots
        taken from the diagonal where they are at least :data:`SYMMETRIC_PIVOT_THRESHOLD` of their column's
        largest entry (SuperLU's advice for matrices of symmetric structure). On a mesh Laplacian the factors
        are sparser than with eigsh's own column ordering (``docs/decisions.md``), and every Lanczos step is
        one solve."""
        n = self.a.shape[0]
        lu = spla.splu(self._shifted(sigma), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=SYMMETRIC_PIVOT_THRESHOLD,
                       options={"SymmetricMode": True})
        return spla.LinearOperator((n, n), matvec=lu.solve, matmat=lu.solve, dtype=np.float64)

    def run(self, k: int, sigma: float, ncv: int | None = None, tol: float = 0.0, blocks: bool = False):
        solver = self._cholesky(sigma, blocks)
        n = self.a.shape[0]
        if solver is not None and blocks:
            # blocks of right-hand sides: block Lanczos instead of ARPACK's one vector at a time
            mass = None if self.diag_mass else self.mass
            apply = solver.solve if mass is None else (lambda x: solver.solve(mass @ x))
            block = int(np.clip(k // 12, *LANCZOS_BLOCK))
            theta, u = block_lanczos(apply, n, k, mass=mass, block=block, tol=tol)
            w = sigma + 1.0 / theta
        else:
            if solver is not None:
                opinv = spla.LinearOperator((n, n), matvec=solver.solve, matmat=solver.solve, dtype=np.float64)
                # each Lanczos step reorthogonalises against the whole basis: a basis of 1.5k (instead of
                # ARPACK's 2k) costs a few more solves but less than it saves (measured on product bands)
                ncv = ncv or min(n - 1, max(int(1.5 * k) + 1, k + 20))
            else:
                opinv = self._symmetric_lu(sigma)
            # a fixed start vector makes results reproducible (ARPACK's default one is random)
            v0 = np.random.default_rng(0).standard_normal(n)
            if self.diag_mass:
                w, u = spla.eigsh(self.a, k, sigma=sigma, which="LM", ncv=ncv, v0=v0, tol=tol, OPinv=opinv)
            else:
                w, u = spla.eigsh(self.a, k, self.mass, sigma=sigma, which="LM", ncv=ncv, v0=v0, tol=tol,
                                  OPinv=opinv)
        v = u * self.scale[:, None] if self.diag_mass else u
        order = np.argsort(w)
        return w[order], v[:, order]


def _slicing(op: _ShiftInvert, k: int, sigma0: float, slice_size: int):
    n = op.a.shape[0]
    vals: list[np.ndarray] = []
    vecs: list[np.ndarray] = []
    count = 0
    cutoff = -np.inf
    sigma = sigma0
    ks = min(slice_size, n - 1)
    for _run in range(200):
        w, v = op.run(ks, sigma)
        r = float(np.abs(w - sigma).max())
        tol = 1e-8 * max(float(np.abs(w).max()), 1e-300)
        if not (sigma < 0 or (sigma - r + tol) < cutoff):
            # the interval does not reach back to the cut: move the shift towards it; if it is
            # already close, the slice is too narrow for the local eigenvalue density
            if sigma - cutoff < 0.1 * r:
                ks = min(2 * ks, n - 1)
            sigma = cutoff + 0.5 * (sigma - cutoff)
            continue
        upper = np.inf if ks >= n - 1 else sigma + r - tol
        take = (w >= cutoff) & (w < upper)
        if not np.any(take):
            ks = min(2 * ks, n - 1)  # a multiplet wider than the slice: widen it
            continue
        vals.append(w[take])
        vecs.append(v[:, take])
        count += int(take.sum())
        above = w[w >= upper]
        # no eigenvalue lies between the taken ones and `above`; with nothing above, none up to `upper`
        cutoff = 0.5 * (w[take].max() + above.min()) if above.size else upper
        if count >= k or not np.isfinite(cutoff):
            break
        # place the next shift so its interval reaches ~40 % of a half-width below the cut; the half-width of
        # the next slice is half the span of this one's eigenvalues (Weyl: a surface's eigenvalues are about
        # evenly spaced), not its radius r, which for the first, one-sided slice is the whole span
        sigma = cutoff + 0.6 * 0.5 * float(w.max() - w.min())
    else:
        raise SolverError("spectrum slicing did not converge (too many shifts)")
    evals = np.concatenate(vals)
    evecs = np.concatenate(vecs, axis=1)
    order = np.argsort(evals)[:k]
    return evals[order], evecs[:, order]


def _fixed_signs(evecs: np.ndarray, mass: sp.spmatrix) -> np.ndarray:
    """Eigenvectors ((n, k) float) signed so that their third moment ``Σ_i m_i φ_i³`` is positive.

    An eigensolver returns each eigenvector with an arbitrary sign, which can
    differ between two decompositions of one mesh (another ``k``, another
    solver); fixing it by the function itself makes everything computed from
    a cold cache equal to what a warm one gives. Where the moment vanishes
    to round-off (a function odd under a symmetry of the shape) no sign is
    distinguished and the solver's is kept.
    """
    mass_diag = mass.diagonal()
    # one pass each, no (n, k) temporaries (a power of an (n, k) array was a tenth of a 5k mesh's decomposition)
    moment = np.einsum("i,ij,ij,ij->j", mass_diag, evecs, evecs, evecs)
    scale = np.sqrt(np.einsum("ij,ij->j", evecs, evecs) / evecs.shape[0]) ** 3 * mass_diag.sum()
    flip = moment < -1e-6 * scale
    if np.any(flip):
        evecs = evecs.copy()
        evecs[:, flip] *= -1.0
    return evecs


def eigenpairs(stiffness: sp.spmatrix, mass: sp.spmatrix, k: int, *, method: str = "auto",
               name: str = "shape", check_connected: bool = True, tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``k`` eigenpairs of ``S phi = lambda M phi``.

    Parameters
    ----------
    stiffness : (n, n) sparse, symmetric positive semi-definite
    mass : (n, n) sparse, symmetric positive definite
    k : int
        Number of eigenpairs, ``1 <= k <= n``.
    method : {"auto", "eigsh", "slicing", "dense", "block"}
        "block": block Lanczos on a Cholesky factorisation
        (:mod:`corrlib.geometry.lanczos`); pays off where solves are expensive
        (four-dimensional product bands), not on surfaces (a 20k-vertex mesh,
        100 eigenpairs: 10.8 s against ARPACK's 2.0 s).
    name : str
        Used in error messages.
    check_connected : bool
        Raise if more than one eigenvalue is zero (disconnected shape).
    tol : float
        ARPACK's relative accuracy of the eigenvalues (0: machine precision).

    Returns
    -------
    evals : (k,) float
        Ascending; tiny negative round-off is clipped to zero.
    evecs : (n, k) float
        M-orthonormal.

    Raises
    ------
    ParameterError
        ``k`` out of range or unknown method.
    InputError
        Non-finite matrices, zero mass, a disconnected shape.
    SolverError
        ARPACK failed even after a regularised retry.
    """
    _check_inputs(stiffness, mass, k, name)
    if method not in {"auto", "eigsh", "slicing", "dense", "block"}:
        raise ParameterError(f"unknown eigensolver method {method!r}")
    n = stiffness.shape[0]
    stiffness = sp.csr_matrix(stiffness)
    mass = sp.csr_matrix(mass)
    # scale of the spectrum: mean Rayleigh quotient of the unit vectors (the solver's shifts and round-off)
    quotients = stiffness.diagonal() / mass.diagonal()
    scale = float(np.mean(quotients))
    # a second zero eigenvalue (a disconnected shape) is judged against the typical quotient: a few sliver
    # vertices (tiny mass, huge cotangents) inflate the mean by orders of magnitude, not the median
    typical = float(np.median(quotients))
    if method == "dense" or n <= DENSE_LIMIT or k >= n - 1:
        evals, evecs = _dense(stiffness, mass, k)
    else:
        if method == "auto":
            method = "slicing" if k > AUTO_SLICING_K else "eigsh"
        op = _ShiftInvert(stiffness, mass)
        evals = evecs = None
        last_exc: Exception | None = None
        for shift in (-1e-8 * scale, -1e-5 * scale):  # second try: a larger, regularising shift
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", sp.SparseEfficiencyWarning)
                    if method == "slicing":
                        evals, evecs = _slicing(op, k, shift, SLICE_SIZE)
                    else:
                        evals, evecs = op.run(k, shift, tol=tol, blocks=method == "block")
                break
            except (spla.ArpackNoConvergence, spla.ArpackError, RuntimeError, SolverError) as exc:
                last_exc = exc
        if evals is None:
            raise SolverError(f"{name}: the eigensolver failed ({last_exc})")
        evecs = _m_orthonormalize(evecs, mass)
    evals = np.where(np.abs(evals) < 1e-12 * scale, 0.0, evals)
    evals = np.maximum(evals, 0.0)
    evecs = _fixed_signs(evecs, mass)
    if check_connected and k >= 2 and evals[1] <= 1e-9 * typical:
        n_zero = int(np.sum(evals <= 1e-9 * typical))
        raise InputError(f"{name}: the shape is disconnected ({n_zero} zero eigenvalues of the Laplacian)")
    return evals, evecs


#: eigenpairs every spectral descriptor needs: the constant one and three more
MIN_EIGENPAIRS = 4


def available_eigenpairs(mesh, k: int, what: str = "spectral descriptors") -> int:
    """``min(k, n - 1)``, the eigenpairs a mesh of ``n`` vertices can give, at least :data:`MIN_EIGENPAIRS`.

    Raises
    ------
    InputError
        Naming the mesh when it is too small for ``what``.
    """
    from corrlib.errors import InputError

    n = int(mesh.n_vertices)
    if n - 1 < MIN_EIGENPAIRS:
        raise InputError(f"{mesh.name}: a mesh of {n} vertices is too small for {what} (at least "
                         f"{MIN_EIGENPAIRS + 1} vertices are needed)")
    return min(int(k), n - 1)


def _spectrum_key(mesh, mass: str) -> str:
    return cache.make_key("spectrum-v3", mesh.content_hash, mass)


def _cached_spectrum(mesh, k: int, key: str, stiffness, mass_mat) -> Spectrum | None:
    """The cached decomposition of ``mesh`` truncated to ``k`` eigenpairs, or ``None``."""
    entry = cache.load("spectra", key, {"evals": cache.Array("f", ("k",)),
                                        "evecs": cache.Array("f", (mesh.n_vertices, "k"))})
    if entry is not None and entry["evals"].shape[0] >= k:
        return Spectrum(entry["evals"][:k].copy(), entry["evecs"][:, :k].copy(), stiffness, mass_mat)
    return None


def mesh_spectrum(mesh, k: int, *, mass: str = "lumped", method: str = "auto", use_cache: bool = True) -> Spectrum:
    """Laplacian eigenpairs of a :class:`~corrlib.shapes.TriMesh`, cached on disk by mesh content.

    Parameters
    ----------
    mesh : TriMesh
    k : int
        Number of eigenpairs.
    mass : {"lumped", "consistent"}
    method : see :func:`eigenpairs`
    use_cache : bool
        Read and write the on-disk cache (:mod:`corrlib.cache`). A cached
        decomposition with at least ``k`` eigenpairs is truncated.

    Returns
    -------
    Spectrum
    """
    from corrlib.geometry.laplacian import mesh_laplacian

    stiffness, mass_mat = mesh_laplacian(mesh, mass=mass)
    key = _spectrum_key(mesh, mass)
    if use_cache:
        cached = _cached_spectrum(mesh, k, key, stiffness, mass_mat)
        if cached is not None:
            return cached
    return _decomposed(mesh, k, key, stiffness, mass_mat, use_cache, method)


def _decomposed(mesh, k: int, key: str, stiffness, mass_mat, use_cache: bool, method: str = "auto") -> Spectrum:
    """Decompose ``mesh`` (its Laplacian given) and store the result in the cache."""
    evals, evecs = eigenpairs(stiffness, mass_mat, k, method=method, name=mesh.name)
    if use_cache:
        cache.store("spectra", key, {"evals": evals, "evecs": evecs})
    return Spectrum(evals, evecs, stiffness, mass_mat)


#: vertices × eigenpairs from which :func:`mesh_spectra` hands a decomposition to a second process: below
#: it the process's start-up (an interpreter importing SciPy, about 0.7 s) is not paid back
PARALLEL_MIN_WORK = 1_000_000


def _second_process_allowed() -> bool:
    """Whether a second process may take a core: this process may keep two or more busy
    (:func:`~corrlib.cores.core_share`), and it is not a child process of any pool (a corrlib pool's worker
    records its share; another pool's, e.g. Dask's, shares the cores without saying so)."""
    import multiprocessing

    from corrlib.cores import core_share

    return core_share() >= 2 and multiprocessing.parent_process() is None


def _start_decomposition(mesh, k: int, stiffness, mass_mat, folder: str):
    """Start :mod:`corrlib.geometry.spectrum_worker` on ``mesh`` in ``folder`` (single-threaded BLAS); None where
    the process cannot be started (no writable temporary folder, no interpreter): the caller does the work."""
    import os
    import subprocess
    import sys

    given, result = os.path.join(folder, "in.npz"), os.path.join(folder, "out.npz")
    package_root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")]))}
    try:
        np.savez(given, k=k, name=mesh.name,
                 **{f"{prefix}_{part}": getattr(sp.csr_matrix(m), part)
                    for prefix, m in (("stiffness", stiffness), ("mass", mass_mat))
                    for part in ("data", "indices", "indptr")},
                 stiffness_shape=np.array(stiffness.shape), mass_shape=np.array(mass_mat.shape))
        return subprocess.Popen([sys.executable, "-m", "corrlib.geometry.spectrum_worker", given, result],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env=env)
    except OSError:
        return None


def _read_decomposition(folder: str, n: int, k: int):
    """``(evals, evecs)`` the second process wrote to ``folder``, or ``(None, None)`` if missing or malformed."""
    import os

    try:
        with np.load(os.path.join(folder, "out.npz"), allow_pickle=False) as data:
            evals, evecs = data["evals"], data["evecs"]
    except (OSError, ValueError, KeyError, EOFError):
        return None, None
    if evals.shape != (k,) or evecs.shape != (n, k):
        return None, None
    return evals, evecs


def mesh_spectra(meshes, k: int, *, mass: str = "lumped", use_cache: bool = True) -> list[Spectrum]:
    """:func:`mesh_spectrum` of several meshes (a pair, as every pairwise method needs), using two cores.

    Where two or more are not cached and large enough (:data:`PARALLEL_MIN_WORK`), the lightest of them
    (vertices × eigenpairs; it also pays the second process's start-up) is decomposed in a second Python
    process (:mod:`corrlib.geometry.spectrum_worker`) while this one decomposes the others, each with
    single-threaded BLAS (two multi-threaded BLAS on two cores slow each other down). The results are the
    same as one at a time: the solver is deterministic (fixed start vectors). If the second process fails
    for any reason, this one decomposes that mesh itself, so errors are those of :func:`mesh_spectrum`.

    Parameters
    ----------
    meshes : sequence of TriMesh
    k : int or sequence of int
        Eigenpairs of every mesh, or one number per mesh.
    mass, use_cache : see :func:`mesh_spectrum`

    Returns
    -------
    list of Spectrum
        In the order of ``meshes``.
    """
    import tempfile

    from threadpoolctl import threadpool_limits

    from corrlib.geometry.laplacian import mesh_laplacian

    meshes = list(meshes)
    ks = [int(k)] * len(meshes) if np.isscalar(k) else [int(v) for v in k]
    if len(ks) != len(meshes):
        raise ParameterError(f"mesh_spectra: {len(ks)} eigenpair counts for {len(meshes)} meshes")
    spectra: list[Spectrum | None] = [None] * len(meshes)
    matrices = [mesh_laplacian(mesh, mass=mass) for mesh in meshes]
    keys = [_spectrum_key(mesh, mass) for mesh in meshes]
    if use_cache:
        spectra = [_cached_spectrum(mesh, kk, key, *mats) for mesh, kk, key, mats in zip(meshes, ks, keys, matrices)]
    todo = [i for i, s in enumerate(spectra) if s is None]
    big = [i for i in todo if meshes[i].n_vertices * ks[i] >= PARALLEL_MIN_WORK and ks[i] < meshes[i].n_vertices]
    if len(todo) >= 2 and big and _second_process_allowed():
        first = min(big, key=lambda i: meshes[i].n_vertices * ks[i])  # the lighter one pays the start-up
        try:
            workspace = tempfile.TemporaryDirectory(prefix="corrlib-spectrum-")
        except OSError:  # no writable temporary folder: everything is decomposed here
            workspace = None
        if workspace is not None:
            with workspace as folder:
                child = _start_decomposition(meshes[first], ks[first], *matrices[first], folder)
                try:
                    with threadpool_limits(1):
                        for i in todo:
                            if i != first:
                                spectra[i] = _decomposed(meshes[i], ks[i], keys[i], *matrices[i], use_cache)
                    if child is not None and child.wait() == 0:
                        evals, evecs = _read_decomposition(folder, meshes[first].n_vertices, ks[first])
                        if evecs is not None:
                            if use_cache:
                                cache.store("spectra", keys[first], {"evals": evals, "evecs": evecs})
                            spectra[first] = Spectrum(evals, evecs, *matrices[first])
                finally:
                    if child is not None and child.poll() is None:
                        child.kill()
                        child.wait()
    for i, spectrum in enumerate(spectra):
        if spectrum is None:  # not handed over, or the second process failed: decomposed here
            spectra[i] = _decomposed(meshes[i], ks[i], keys[i], *matrices[i], use_cache)
    return spectra


def doubled_spectrum(stiffness: sp.spmatrix, mass: sp.spmatrix, boundary: np.ndarray, k: int, *,
                     neumann: tuple[np.ndarray, np.ndarray] | None = None,
                     name: str = "shape") -> tuple[np.ndarray, np.ndarray]:
    """Lowest ``k`` eigenpairs of the doubled domain, read on one of its two copies.

    Two copies of a planar domain glued along their common boundary form a
    closed surface without boundary (a flat "pillow"). The reflection that
    swaps the copies splits every eigenfunction of the pillow into an even
    part, a Neumann eigenfunction of the domain, and an odd part, a Dirichlet
    eigenfunction, which vanishes on the boundary. Its spectrum is therefore
    the union of the Neumann and the Dirichlet spectra of the domain, and an
    eigenfunction normalised on the pillow is the domain's eigenfunction
    divided by √2.

    Parameters
    ----------
    stiffness, mass : (n, n) sparse
        Laplacian of the domain (Neumann: every vertex free).
    boundary : (b,) int
        Boundary vertices (fixed to zero in the Dirichlet problem).
    k : int
    neumann : ((k,) float, (n, k) float), optional
        The domain's own lowest ``k`` eigenpairs, if already computed.

    Returns
    -------
    evals : (k,) float
        Ascending.
    evecs : (n, k) float
        The pillow's eigenfunctions on the domain's copy; Dirichlet ones are
        zero on the boundary. Within each parity orthonormal with respect to
        ``2 mass`` (across parities only on the whole pillow, where the odd
        ones change sign).
    """
    n = stiffness.shape[0]
    interior = np.setdiff1d(np.arange(n), np.asarray(boundary, dtype=np.int64))
    stiffness = sp.csr_matrix(stiffness)
    mass = sp.csr_matrix(mass)
    n_evals, n_evecs = neumann if neumann is not None else eigenpairs(stiffness, mass, k, name=name)
    k_dirichlet = min(k, interior.size)  # all of them on a domain with few interior vertices
    d_evals, d_evecs = np.zeros(0), np.zeros((n, 0))
    if k_dirichlet > 0:
        d_evals, d_interior = eigenpairs(stiffness[interior][:, interior], mass[interior][:, interior], k_dirichlet,
                                         name=f"{name} (Dirichlet)", check_connected=False)
        d_evecs = np.zeros((n, k_dirichlet))
        d_evecs[interior] = d_interior
    evals = np.concatenate([n_evals, d_evals])
    order = np.argsort(evals, kind="stable")[:k]
    return evals[order], np.hstack([n_evecs, d_evecs])[:, order] / np.sqrt(2.0)
