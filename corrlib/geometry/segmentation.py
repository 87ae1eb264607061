"""Deformation-invariant parts of a shape: its protrusions, by persistence of the heat kernel signature.

The heat kernel signature at one diffusion time ``t``,

.. math::

    h_t(x) = \\sum_k e^{-λ_k t} φ_k(x)^2,

is the heat that stays at ``x`` after time ``t`` (Sun, Ovsjanikov, Guibas,
SGP 2009). Heat leaves a point on a broad body faster than a point at the
tip of a limb, so at a time where heat spreads over about a limb's length,
``h_t`` has one maximum per protrusion (each leg, the head, the tail, an ear
of large enough size). It depends on the intrinsic geometry only, so the same
parts come out of every pose of a shape, of a remeshed copy, of a mirror image
and of a filled silhouette of it (Neumann boundary).

The parts are read off the superlevel sets of ``h_t`` with 0-dimensional
persistence (Skraba, Ovsjanikov, Chazal, Guibas, *Persistence-based
segmentation of deformable shapes*, NORDIA 2010). Vertices are added in
decreasing order of ``h_t``; the connected components of the added vertices
grow around the maxima and merge at saddles. A component is *significant*
while its peak lies more than ``persistence`` (a fraction of the range of
``h_t``) above the level at which it meets another one; smaller bumps (noise,
a mesh's sampling) merge into their neighbour without a trace. When two
significant components meet, each is a protrusion: its vertices so far (the
limb up to the saddle where it joins the body) become one part, and the rest
of the shape, added after every protrusion has closed, is the body.

Time and threshold are unit-free: ``t = time · A`` for a domain of area
``A`` (heat spreads over a distance of about ``√(4t)``, 0.45 √A at the
default ``time = 0.05``), and the threshold is relative to the range of
``h_t``, which makes the parts invariant to the units of the input.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp

from corrlib.errors import ParameterError

#: default diffusion time in units of the domain's area
PART_TIME = 0.05
#: default persistence threshold, a fraction of the range of the heat kernel signature
PART_PERSISTENCE = 0.1


@dataclass(frozen=True)
class Parts:
    """A shape's protrusions.

    Attributes
    ----------
    labels : (n,) int
        0 on the body, ``p`` in ``1 .. n_parts`` on the ``p``-th protrusion
        (ordered by decreasing peak of the signature).
    signature : (n,) float
        The heat kernel signature the parts were read from.
    """

    labels: np.ndarray
    signature: np.ndarray

    @property
    def n_parts(self) -> int:
        return int(self.labels.max(initial=0))


def heat_signature(evals: np.ndarray, evecs: np.ndarray, t: float) -> np.ndarray:
    """(n,) float: ``h_t(x) = Σ_k exp(−λ_k t) φ_k(x)²`` over the given eigenpairs (M-orthonormal)."""
    evals = np.asarray(evals, dtype=np.float64)
    return (np.asarray(evecs, dtype=np.float64) ** 2) @ np.exp(-evals * t)


@numba.njit(cache=True)
def _superlevel_protrusions(f, order, indptr, indices, threshold):
    """The kernel of :func:`persistent_protrusions`: union-find over the vertices in ``order``.

    A component's vertices, while it is *open* (none of its parts has closed
    yet), are a linked list (``head``, ``tail``, ``following``) so that merging
    two components and closing one as a part cost O(1). Returns the part of
    every vertex (-1: body) numbered in the order the parts closed.
    """
    n = f.shape[0]
    parent = np.full(n, -1, dtype=np.int64)
    peak = np.zeros(n)
    is_open = np.zeros(n, dtype=np.bool_)
    head = np.full(n, -1, dtype=np.int64)
    tail = np.full(n, -1, dtype=np.int64)
    following = np.full(n, -1, dtype=np.int64)
    part_of = np.full(n, -1, dtype=np.int64)
    n_parts = 0
    roots = np.empty(n, dtype=np.int64)
    for v in order:
        n_roots = 0
        for e in range(indptr[v], indptr[v + 1]):
            u = indices[e]
            if parent[u] < 0:
                continue
            while parent[u] != u:  # find, with path halving
                parent[u] = parent[parent[u]]
                u = parent[u]
            seen = False
            for r in range(n_roots):
                seen = seen or roots[r] == u
            if not seen:
                roots[n_roots] = u
                n_roots += 1
        parent[v] = v
        if n_roots == 0:  # a new maximum
            peak[v] = f[v]
            is_open[v] = True
            head[v] = tail[v] = v
            continue
        significant = 0
        for r in range(n_roots):
            if peak[roots[r]] - f[v] > threshold:
                significant += 1
        if significant >= 2:  # two protrusions meet at a saddle: each open one is a part, up to here
            for r in range(n_roots):
                root = roots[r]
                if peak[root] - f[v] > threshold and is_open[root]:
                    x = head[root]
                    while x >= 0:
                        part_of[x] = n_parts
                        x = following[x]
                    n_parts += 1
                    is_open[root] = False
        top = roots[0]
        still_open = True
        for r in range(n_roots):
            root = roots[r]
            if peak[root] > peak[top]:
                top = root
            still_open = still_open and is_open[root]
        if still_open:  # one open component: the lists joined, v appended
            first, last = -1, -1
            for r in range(n_roots):
                root = roots[r]
                if first < 0:
                    first = head[root]
                else:
                    following[last] = head[root]
                last = tail[root]
            following[last] = v
            head[top], tail[top] = first, v
        for r in range(n_roots):
            is_open[roots[r]] = False
            parent[roots[r]] = top
        parent[v] = top
        is_open[top] = still_open
    return part_of, n_parts


def persistent_protrusions(signature: np.ndarray, adjacency: sp.spmatrix, persistence: float) -> np.ndarray:
    """Protrusions of a function on a graph by superlevel-set persistence (see the module docstring).

    Parameters
    ----------
    signature : (n,) float
        The function (its maxima are the tips of the protrusions).
    adjacency : (n, n) sparse
        The graph; any non-zero entry is an edge.
    persistence : float
        Significance threshold as a fraction of ``signature.max() − signature.min()``.

    Returns
    -------
    (n,) int
        0 on the body, ``1 .. p`` on the protrusions by decreasing peak.
    """
    f = np.ascontiguousarray(signature, dtype=np.float64)
    if not 0.0 <= persistence < 1.0:
        raise ParameterError(f"persistence must be in [0, 1), got {persistence!r}")
    graph = sp.csr_matrix(adjacency)
    threshold = persistence * float(f.max() - f.min())
    order = np.argsort(-f, kind="stable").astype(np.int64)
    part_of, n_parts = _superlevel_protrusions(f, order, graph.indptr.astype(np.int64),
                                               graph.indices.astype(np.int64), threshold)
    labels = np.zeros(f.shape[0], dtype=np.int64)
    if n_parts == 0:
        return labels
    in_part = part_of >= 0
    part_peak = np.full(n_parts, -np.inf)
    np.maximum.at(part_peak, part_of[in_part], f[in_part])
    rank = np.empty(n_parts, dtype=np.int64)
    rank[np.argsort(-part_peak, kind="stable")] = np.arange(1, n_parts + 1)
    labels[in_part] = rank[part_of[in_part]]
    return labels


def protrusion_parts(evals: np.ndarray, evecs: np.ndarray, adjacency: sp.spmatrix, area: float, *,
                     time: float = PART_TIME, persistence: float = PART_PERSISTENCE) -> Parts:
    """The protrusions of a shape from its Laplace–Beltrami eigenpairs (see the module docstring).

    Parameters
    ----------
    evals : (k,) float
        Ascending eigenvalues of the shape in its own units.
    evecs : (n, k) float
        M-orthonormal eigenvectors.
    adjacency : (n, n) sparse
        The shape's edge graph.
    area : float
        The shape's area (the time is ``time · area``).
    time, persistence : float
        See the module docstring.
    """
    if time <= 0.0 or area <= 0.0:
        raise ParameterError(f"time and area must be positive, got time={time!r}, area={area!r}")
    signature = heat_signature(evals, evecs, time * area)
    return Parts(persistent_protrusions(signature, adjacency, persistence), signature)


def part_costs(cost: np.ndarray, labels_a: np.ndarray, labels_b: np.ndarray) -> np.ndarray:
    """Mean of a point-to-point cost over every pair of parts.

    Parameters
    ----------
    cost : (m, n) float
        Cost of matching point i of shape A to point j of shape B.
    labels_a : (m,) int
        Parts of A (0 = body, 1 .. p_a).
    labels_b : (n,) int
        Parts of B (0 = body, 1 .. p_b).

    Returns
    -------
    (p_a + 1, p_b + 1) float
        ``C[a, b]``: the mean of ``cost`` over the points of part ``a`` and of part
        ``b`` (inf where a part of A has no point, e.g. a part that does not reach
        the boundary of a filled silhouette).
    """
    pa, pb = int(labels_a.max(initial=0)) + 1, int(labels_b.max(initial=0)) + 1
    ind_a = sp.csr_matrix((np.ones(labels_a.shape[0]), (labels_a, np.arange(labels_a.shape[0]))), shape=(pa, cost.shape[0]))
    ind_b = sp.csr_matrix((np.ones(labels_b.shape[0]), (np.arange(labels_b.shape[0]), labels_b)), shape=(cost.shape[1], pb))
    sums = np.asarray(ind_b.T @ (ind_a @ cost).T).T
    counts = np.outer(np.bincount(labels_a, minlength=pa), np.bincount(labels_b, minlength=pb)).astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1.0), np.inf)


def assign_parts(cost: np.ndarray, labels_a: np.ndarray, labels_b: np.ndarray) -> np.ndarray:
    """The parts of A expressed as parts of B: body to body, protrusions by a small assignment.

    The protrusions of A and of B are matched one to one by the least total
    mean cost (:func:`part_costs`; Hungarian method). A protrusion of A left
    without a partner (A shows more protrusions than B has) is unknown.

    Returns
    -------
    (m,) int
        For every point of A: 0 (body), the matched part of B, or −1 (unknown).
    """
    from scipy.optimize import linear_sum_assignment

    table = part_costs(cost, labels_a, labels_b)[1:, 1:]
    mapping = np.full(table.shape[0] + 1, -1, dtype=np.int64)
    mapping[0] = 0
    usable = np.isfinite(table).all(axis=1)
    if table.size and usable.any():
        rows, cols = linear_sum_assignment(table[usable])
        mapping[1 + np.flatnonzero(usable)[rows]] = cols + 1
    return mapping[labels_a]
