"""Functional maps: the energies of the standard pipeline and ZoomOut refinement.

:func:`functional_map` minimises the quadratic energy of descriptor
preservation and commutativity with operators (Laplacian, descriptors,
orientation) exactly; :func:`zoomout` refines a map by spectral upsampling;
:func:`pointwise_from_basis` and :func:`repeated_pointwise_from_basis` are
the final ZoomOut steps of a map and its reverse at one basis size (kernel
matching's and divergence-free's last stage), the basis chosen by
:func:`resolved_eigenpairs`. On meshes finer than the basis needs,
ZoomOut iterates on samples (:class:`ZoomOutSamples`) and only the last
pointwise map is formed for every vertex (:func:`nearest_rows_through_samples`).

Convention (pyFM's): ``C_yx`` of shape (k_Y, k_X) carries the spectral
coefficients of a function on X to those of its pull-back on Y,
``C_yx = Ψᵀ M_Y Π_yx Φ`` with ``Π_yx[j, map_yx[j]] = 1``. The pointwise map
``map_yx`` is recovered by nearest neighbours between ``Ψ`` (rows of Y) and
``Φ C_yxᵀ`` (rows of X).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from corrlib.geometry.sampling import farthest_point_sampling, voronoi_cells
from corrlib.neighbours import descended_nearest_rows, nearest_rows
from corrlib.progress import run

#: ZoomOut's iterations run on this many farthest-point samples of a mesh more than twice as fine (Melzi et al.
#: 2019 run it on subsamples too): thirty and more samples per basis function at the sizes ZoomOut is given here
#: (60-160), and the size of the meshes the methods are measured on
ZOOMOUT_SAMPLES = 5000


@dataclass(frozen=True)
class ZoomOutSamples:
    """Vertices that stand for a mesh in ZoomOut's iterations, with what the last step needs.

    Attributes
    ----------
    index : (s,) int
        The sampled vertices.
    owner : (n,) int
        For every vertex, the position in ``index`` of the sample whose geodesic Voronoi cell holds it.
    weight : (s,) float
        The lumped mass of every sample's cell (the samples' stand-in for the mass matrix).
    indptr, indices : int arrays
        The mesh's vertex adjacency (CSR), over which the last step searches from the samples' partners.
    """

    index: np.ndarray
    owner: np.ndarray
    weight: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray

    @classmethod
    def of(cls, mesh, mass_diag: np.ndarray, count: int = ZOOMOUT_SAMPLES) -> "ZoomOutSamples | None":
        """Farthest-point samples of ``mesh`` and their geodesic Voronoi cells; ``None`` where the mesh has
        at most twice ``count`` vertices (ZoomOut then runs on every vertex: fewer than two vertices per
        cell would save less than three quarters of the search, and change its answers). The samples and
        cells of the last few meshes are kept in memory (both starts of kernel matching, its functional-map
        start and the final steps ask for the same ones)."""
        if mesh.n_vertices <= 2 * count:
            return None
        index, owner = _sampled_cells(mesh, count)
        weight = np.bincount(owner, weights=np.asarray(mass_diag, dtype=float), minlength=count)
        graph = mesh.adjacency
        return cls(index, owner, weight, graph.indptr, graph.indices)

    @classmethod
    def of_pair(cls, source, target, mass_x: np.ndarray, mass_y: np.ndarray, count: int = ZOOMOUT_SAMPLES):
        """``(samples_x, samples_y)`` where both meshes are finer than twice ``count``, else ``(None, None)``:
        a search goes through samples only where both sides have them (:func:`nearest_rows_through_samples`)."""
        if min(source.n_vertices, target.n_vertices) <= 2 * count:
            return None, None
        return cls.of(source, mass_x, count), cls.of(target, mass_y, count)


#: meshes whose samples and cells :meth:`ZoomOutSamples.of` keeps, by content and count (most recent last)
_CELLS: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}
_CELLS_KEPT = 4
_CELLS_LOCK = threading.Lock()


def _sampled_cells(mesh, count: int) -> tuple[np.ndarray, np.ndarray]:
    """(index, owner) of :class:`ZoomOutSamples`: farthest-point samples and the sample whose geodesic
    Voronoi cell holds each vertex; computed once per mesh content among the last few asked for."""
    key = (mesh.content_hash, count)
    with _CELLS_LOCK:
        if key in _CELLS:
            _CELLS[key] = _CELLS.pop(key)  # most recent last
            return _CELLS[key]
        index = farthest_point_sampling(mesh.vertices, count)
        owner, _ = voronoi_cells(mesh, index)
        stray = owner < 0  # a component no sample reached: the Euclidean nearest sample stands for it
        if stray.any():
            owner[stray] = cKDTree(mesh.vertices[index]).query(mesh.vertices[stray])[1]
        for array in (index, owner):
            array.flags.writeable = False
        _CELLS[key] = (index, owner)
        while len(_CELLS) > _CELLS_KEPT:
            _CELLS.pop(next(iter(_CELLS)))
        return index, owner


def nearest_rows_through_samples(query: np.ndarray, data: np.ndarray, query_samples: ZoomOutSamples | None,
                                 data_samples: ZoomOutSamples | None, sampled_partners: np.ndarray | None = None,
                                 current: np.ndarray | None = None) -> np.ndarray:
    """(q,) int: the nearest row of ``data`` for every row of ``query``, searched through samples.

    The query's samples take their nearest rows among the data's samples (or ``sampled_partners``, rows of
    ``data`` already found for them); every query row then starts from the partner of its own sample and
    descends over the data mesh's edges to the nearest row there
    (:func:`~corrlib.neighbours.descended_nearest_rows`); with ``current`` partners it descends from those
    too and keeps the nearer of the two rows. A smooth embedding (a few eigenfunctions) has few minima
    within a sample's cell, so this is close to the brute-force search, at the cost of ``s²`` distances and
    a walk or two per row instead of ``q × d`` distances. Without samples on either side it is
    :func:`nearest_rows` itself.

    Parameters
    ----------
    query : (q, k) float
    data : (d, k) float
    query_samples, data_samples : ZoomOutSamples or None
        Samples of the shapes whose vertices the rows are.
    sampled_partners : (s_q,) int, optional
        Rows of ``data`` for the query's samples, if known.
    current : (q,) int, optional
        Rows of ``data`` to descend from as well (a map being refined); -1 for none.
    """
    if query_samples is None or data_samples is None:
        return nearest_rows(query, data)
    if sampled_partners is None:
        sampled_partners = data_samples.index[nearest_rows(query[query_samples.index], data[data_samples.index])]
    graph = data_samples.indptr, data_samples.indices
    found = descended_nearest_rows(query, data, sampled_partners[query_samples.owner], *graph)
    if current is None:
        return found
    other = descended_nearest_rows(query, data, np.where(current >= 0, current, found), *graph)
    nearer = np.einsum("ij,ij->i", query - data[other], query - data[other]) < np.einsum(
        "ij,ij->i", query - data[found], query - data[found])
    return np.where(nearer, other, found)


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
            token=None, samples_x: ZoomOutSamples | None = None, samples_y: ZoomOutSamples | None = None):
    """ZoomOut refinement (Melzi et al. 2019).

    Alternates the pointwise map of the current functional map with the functional map of that pointwise map,
    adding ``step`` basis functions each time. With samples of both shapes the iterations run on them (the
    paper's subsampled ZoomOut): the map of Y's samples to X's samples, and the functional map as the
    least-squares fit ``C = argmin Σ_s w_s |Ψ(s) C − Φ(m(s))|²`` over Y's samples weighted by their cells'
    masses, which for every vertex and the mass matrix is ``Ψᵀ M_Y Π Φ`` itself (``Ψᵀ M_Y Ψ = I``). The last
    pointwise map is formed for every vertex of Y (:func:`nearest_rows_through_samples`).

    Parameters
    ----------
    evecs_x : (n_x, K) float
    evecs_y : (n_y, K) float
    mass_y : (n_y, n_y) sparse
    c_yx : (k, k) float
        Initial functional map.
    k_final : int
    step : int
    token : CancelToken, optional
    samples_x, samples_y : ZoomOutSamples, optional
        Both, or ZoomOut runs on every vertex.

    Yields
    ------
    int
        The current basis size (for progress).

    Returns
    -------
    map_yx : (n_y,) int
    c_yx : (k_final, k_final) float
    """
    sampled = samples_x is not None and samples_y is not None
    if sampled:
        rows_x, rows_y = evecs_x[samples_x.index], evecs_y[samples_y.index]
        weight_y = samples_y.weight
    else:
        rows_x, rows_y = evecs_x, evecs_y
    k = c_yx.shape[1]
    while True:
        if token is not None:
            token.raise_if_cancelled()
        partners = nearest_rows(rows_y[:, :c_yx.shape[0]], rows_x[:, :k] @ c_yx.T)  # rows of rows_x
        if k >= k_final:
            if not sampled:
                return partners, c_yx
            map_yx = nearest_rows_through_samples(evecs_y[:, :c_yx.shape[0]], evecs_x[:, :k] @ c_yx.T, samples_y,
                                                  samples_x, samples_x.index[partners])
            return map_yx, c_yx
        k = min(k + step, k_final)
        if sampled:
            psi = rows_y[:, :k]
            gram = psi.T @ (weight_y[:, None] * psi)
            c_yx = np.linalg.solve(gram, psi.T @ (weight_y[:, None] * rows_x[partners, :k]))
        else:
            c_yx = pointwise_to_functional(partners, evecs_x[:, :k], evecs_y[:, :k], mass_y)
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
    """Hessian of ``Σ_d ‖C X_d − Y_d C‖²`` in row-major ``vec(C)`` ((k_Y k_X, k_Y k_X) float).

    With ``vec(C X) = (I ⊗ Xᵀ) vec(C)`` and ``vec(Y C) = (Y ⊗ I) vec(C)``, the commutator is
    ``K_d = I ⊗ X_dᵀ − Y_d ⊗ I`` and its Gram matrix, by ``(A ⊗ B)(C ⊗ D) = AC ⊗ BD``,
    ``K_dᵀ K_d = I ⊗ X_d X_dᵀ − Y_d ⊗ X_d − Y_dᵀ ⊗ X_dᵀ + Y_dᵀ Y_d ⊗ I``: the sums of the outer terms
    are three Kronecker-shaped sums in all, and no ``(k_Y k_X)²`` product of commutators is formed.
    """
    k_y, k_x = ops_y.shape[1], ops_x.shape[1]
    gram = np.kron(np.eye(k_y), np.einsum("dij,dkj->ik", ops_x, ops_x))
    gram += np.kron(np.einsum("dji,djk->ik", ops_y, ops_y), np.eye(k_x))
    # Σ_d Y_d ⊗ X_d, entry ((a, c), (b, e)) = Σ_d Y_d[a, b] X_d[c, e]
    cross = np.einsum("dab,dce->acbe", ops_y, ops_x, optimize=True).reshape(k_y * k_x, k_y * k_x)
    gram -= cross + cross.T  # (Y ⊗ X)ᵀ = Yᵀ ⊗ Xᵀ
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


def resolved_eigenpairs(evals: np.ndarray, area: float, tau: float) -> int:
    """How many eigenfunctions the heat kernel of relative time ``tau`` resolves: those with ``τ λ · area ≤ 1``
    (the decay ``e^{-tλ}`` above ``1/e``; at least one)."""
    return max(1, int(np.count_nonzero(np.asarray(evals) * area * tau <= 1.0)))


def _unit_area_bases(spec_x, spec_y, k: int):
    """The first ``k`` eigenpairs of both shapes scaled to unit area (the lumped masses sum to the area): the
    partners are searched in one embedding whatever the two shapes' sizes. Unscaled, the images of one shape's
    basis functions in the other's are off by the ratio of their areas (``C_xy = Φᵀ M_X Π Ψ`` grows as
    ``√(A_X / A_Y)``)."""
    return (spec_x.truncated(k).at_unit_area(float(spec_x.mass.diagonal().sum())),
            spec_y.truncated(k).at_unit_area(float(spec_y.mass.diagonal().sum())))


def pointwise_from_basis(map_xy, map_yx, spec_x, spec_y, k, both_directions: bool = True,
                         samples_x: ZoomOutSamples | None = None, samples_y: ZoomOutSamples | None = None):
    """One ZoomOut step (Melzi et al. 2019, the pointwise maps from a functional map) with one functional map
    estimated from both directions of the map.

    The pull-back of functions on Y along ``m = map_xy`` is estimated twice: from ``m`` itself,
    ``C_xy = Φ_kᵀ M_X Π_m Ψ_k`` (an integral over X), and as the adjoint of the pull-back along the reverse map
    ``n = map_yx``, ``C_yxᵀ`` with ``C_yx = Ψ_kᵀ M_Y Π_n Φ_k`` (an integral over Y). For an area-preserving
    bijection ``n = m⁻¹`` the two are equal; for the maps kernel matching or nearest neighbours after a
    deformation end with they are not: every sample of the coarser side carries its partner's offset into
    its own estimate (e.g. one target edge where the source's vertices take target samples), while the other
    side's many vertices per partner average it out. The step uses their mean ``Ĉ_xy = (C_xy + C_yxᵀ) / 2``
    for both maps: ``m(x)`` is the vertex ``y`` whose image ``(Ψ_k Ĉ_xyᵀ)(y)`` in X's basis is nearest
    ``Φ_k(x)``, and ``n(y)`` the vertex ``x`` with ``(Φ_k Ĉ_xy)(x)`` nearest ``Ψ_k(y)`` (the nearest
    neighbour, not the best inner product, which favours vertices whose spectral embedding is long).
    Unmatched vertices (-1) stay unmatched.

    A map that carries information its reverse map does not have (kernel matching's refinement of a map from
    outside the solver, which keeps that map's partners, :func:`~corrlib.methods.resolution.keep_input_partners`) is
    instead projected with its own estimate, and the reverse map with its own (``both_directions=False``):
    the mean would dilute the given partners with the reverse map's, which the kernels resolve less finely.

    Parameters
    ----------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    spec_x, spec_y : Spectrum
        With at least ``k`` eigenpairs.
    k : int
    both_directions : bool
    samples_x, samples_y : ZoomOutSamples, optional
        Samples of finer meshes: the partners are searched through them
        (:func:`nearest_rows_through_samples`) instead of over all pairs of vertices.

    Returns
    -------
    new_xy : (n_x,) int
    new_yx : (n_y,) int
    """
    return _global_step(map_xy, map_yx, *_unit_area_bases(spec_x, spec_y, k), both_directions, samples_x, samples_y)


def _global_step(map_xy, map_yx, unit_x, unit_y, both_directions: bool = True, samples_x=None, samples_y=None):
    """:func:`pointwise_from_basis` on bases already at unit area (:func:`_unit_area_bases`)."""
    phi, psi = unit_x.evecs, unit_y.evecs
    c_xy = pointwise_to_functional(map_xy, psi, phi, unit_x.mass.diagonal())  # pulls Y's functions back to X
    c_yx = pointwise_to_functional(map_yx, phi, psi, unit_y.mass.diagonal())
    if not both_directions:
        return (np.where(map_xy >= 0, nearest_rows_through_samples(phi @ c_xy, psi, samples_x, samples_y,
                                                                   current=map_xy), -1),
                np.where(map_yx >= 0, nearest_rows_through_samples(psi @ c_yx, phi, samples_y, samples_x,
                                                                   current=map_yx), -1))
    both = 0.5 * (c_xy + c_yx.T)
    new_xy = np.where(map_xy >= 0, nearest_rows_through_samples(phi, psi @ both.T, samples_x, samples_y,
                                                                current=map_xy), -1)
    new_yx = np.where(map_yx >= 0, nearest_rows_through_samples(psi, phi @ both, samples_y, samples_x,
                                                                current=map_yx), -1)
    return new_xy, new_yx


def zoomout_both_ways(map_xy, map_yx, spec_x, spec_y, k_init: int, k_final: int, step: int, token=None,
                      samples_x: ZoomOutSamples | None = None, samples_y: ZoomOutSamples | None = None):
    """ZoomOut (Melzi et al. 2019) of both maps of a pair: each one's functional map on the first ``k_init``
    eigenfunctions (at unit area), upsampled by :func:`zoomout` to ``k_final``, and the pointwise map of the
    last one. A map whose fine detail is wrong (a limb placed on its neighbour) keeps what is right at low
    frequencies and gets the rest from the spectral alternation; started at ``k_final`` it would keep its
    errors. Unmatched vertices (-1) stay unmatched.

    Parameters
    ----------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    spec_x, spec_y : Spectrum
        With at least ``k_final`` eigenpairs.
    k_init, k_final, step : int
        ``2 <= k_init <= k_final``.
    token : CancelToken, optional
    samples_x, samples_y : ZoomOutSamples, optional
        Samples of finer meshes (see :func:`zoomout`).

    Returns
    -------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    """
    unit_x, unit_y = _unit_area_bases(spec_x, spec_y, k_final)
    phi, psi = unit_x.evecs, unit_y.evecs

    def zoomed(m, evecs_from, evecs_to, mass_from, samples_from, samples_to):  # the map from the `from` side
        c = pointwise_to_functional(m, evecs_to[:, :k_init], evecs_from[:, :k_init], mass_from)
        new, _ = run(zoomout(evecs_to, evecs_from, mass_from, c, k_final, step, token, samples_to, samples_from))
        return np.where(m >= 0, new, -1)

    return (zoomed(map_xy, phi, psi, unit_x.mass.diagonal(), samples_x, samples_y),
            zoomed(map_yx, psi, phi, unit_y.mass.diagonal(), samples_y, samples_x))


def repeated_pointwise_from_basis(map_xy, map_yx, spec_x, spec_y, k, graph_x, graph_y, token=None,
                                  samples_x: ZoomOutSamples | None = None, samples_y: ZoomOutSamples | None = None):
    """The step of :func:`pointwise_from_basis`, then the same step repeated from its own maps while the
    number of partners a step changes decreases (and is not zero), each partner searched by descent from the
    current one.

    Every step re-estimates ``Ĉ_xy = (C_xy + C_yxᵀ) / 2`` from the maps the previous one made and moves each
    vertex to its nearest partner in that basis, so the repetition is ZoomOut's alternation (Melzi et al.
    2019) at a fixed basis size, towards maps consistent with one functional map. A falling count of moved
    partners says the alternation is settling; once a step moves as many as the one before, the maps
    oscillate between near-ties, and the repetition stops there (that step's maps are returned). The count
    is a whole number that must fall at every repetition, so the loop ends. The partners move by about an
    edge per step, so each is searched by steepest descent over the other shape's edge graph from the
    current partner (:func:`~corrlib.neighbours.descended_nearest_rows`) instead of over all vertices, and
    the two estimates are updated by the moved rows only (:func:`moved_rows_change`).

    Parameters
    ----------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
        The maps to refine; -1 rows stay -1.
    spec_x, spec_y : Spectrum
    k : int
    graph_x, graph_y : (n, n) sparse
        The shapes' vertex adjacencies.
    token : CancelToken, optional
        Checked before every step.
    samples_x, samples_y : ZoomOutSamples, optional
        Samples of finer meshes, through which the first (global) step searches.

    Returns
    -------
    map_xy : (n_x,) int
    map_yx : (n_y,) int
    """
    spec_x, spec_y = _unit_area_bases(spec_x, spec_y, k)
    map_xy, map_yx = _global_step(map_xy, map_yx, spec_x, spec_y, True, samples_x, samples_y)  # a global search
    phi, psi = np.ascontiguousarray(spec_x.evecs), np.ascontiguousarray(spec_y.evecs)
    mass_x, mass_y = spec_x.mass.diagonal(), spec_y.mass.diagonal()
    c_xy = pointwise_to_functional(map_xy, psi, phi, mass_x)
    c_yx = pointwise_to_functional(map_yx, phi, psi, mass_y)
    changed_before = None
    while True:
        if token is not None:
            token.raise_if_cancelled()
        both = 0.5 * (c_xy + c_yx.T)
        new_xy = descended_nearest_rows(phi, psi @ both.T, map_xy, graph_y.indptr, graph_y.indices)
        new_yx = descended_nearest_rows(psi, phi @ both, map_yx, graph_x.indptr, graph_x.indices)
        c_xy += moved_rows_change(map_xy, new_xy, psi, phi, mass_x)
        c_yx += moved_rows_change(map_yx, new_yx, phi, psi, mass_y)
        changed = int(np.count_nonzero(new_xy != map_xy) + np.count_nonzero(new_yx != map_yx))
        map_xy, map_yx = new_xy, new_yx
        if changed == 0 or (changed_before is not None and changed >= changed_before):
            return map_xy, map_yx
        changed_before = changed


def moved_rows_change(old_map, new_map, evecs_to, evecs_from, mass_from):
    """The change of ``Φᵀ M Π Ψ`` (:func:`pointwise_to_functional`, here with ``Φ = evecs_from``,
    ``Ψ = evecs_to``) when ``old_map`` becomes ``new_map``: only the moved rows ``r`` contribute,
    ``Φ[r]ᵀ M[r] (Ψ[new[r]] − Ψ[old[r]])``.

    Parameters
    ----------
    old_map, new_map : (n,) int
        Partners on the other shape; -1 on the same rows in both.
    evecs_to : (n_other, k) float
    evecs_from : (n, k) float
    mass_from : (n,) float
        Lumped masses of the shape the maps start from.

    Returns
    -------
    (k, k) float
    """
    moved = np.flatnonzero(new_map != old_map)
    weighted = mass_from[moved, None] * (evecs_to[new_map[moved]] - evecs_to[old_map[moved]])
    return evecs_from[moved].T @ weighted
