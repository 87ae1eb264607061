"""Discrete Laplace–Beltrami operators in weak form ``S phi = lambda M phi``.

Sign convention: the stiffness matrix ``S`` is symmetric positive
semi-definite (``S @ ones == 0``); the mass matrix ``M`` is symmetric
positive definite. The operator ``M^{-1} S`` approximates ``-Δ``.

* Triangle meshes: linear FEM (cotangent) stiffness,
  ``S_ij = -(cot α_ij + cot β_ij) / 2`` for an edge ij with opposite angles
  α, β; consistent mass ``M_ij = A_f / 12`` (``A_f / 6`` on the diagonal)
  summed over faces; lumped mass = row sums (one third of the adjacent area).
  Boundary edges have a single cotangent term (natural, i.e. Neumann,
  boundary condition).
* Closed polylines (thesis Eq. 9.1–9.2): linear FEM on a cycle,
  ``S_ii = 1/l_{i-1} + 1/l_i``, ``S_{i,i+1} = -1/l_i``; consistent mass
  ``M_ii = (l_{i-1} + l_i)/3``, ``M_{i,i+1} = l_i / 6``; lumped mass
  ``(l_{i-1} + l_i)/2``. Here ``l_i`` is the length of segment i from
  point i to point i+1.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corrlib.errors import InputError, ParameterError


def _parallelogram_area(a: np.ndarray, b: np.ndarray, dot: np.ndarray) -> np.ndarray:
    """``|a × b|`` for rows of vectors in any dimension (e.g. a flat torus in R⁴): ``|a| · |b − (a·b / a·a) a|``,
    the length of ``a`` times the part of ``b`` orthogonal to it.

    Lagrange's identity ``|a|²|b|² − (a·b)²`` gives the same in exact arithmetic but cancels catastrophically for
    nearly parallel edges (relative error ``ε / sin²θ``): on a sliver triangle whose angle is 1e-7 it returns
    zero, and the cotangent weight becomes 1e296 instead of 1e7. The rejection loses only ``ε / sin θ``.

    Parameters
    ----------
    a, b : (f, d) float
    dot : (f,) float
        The row-wise ``a · b``.

    Returns
    -------
    (f,) float
    """
    aa = np.einsum("ij,ij->i", a, a)
    rejection = b - (dot / np.maximum(aa, 1e-300))[:, None] * a
    return np.sqrt(aa) * np.linalg.norm(rejection, axis=1)


def cotan_stiffness(vertices: np.ndarray, faces: np.ndarray) -> sp.csr_matrix:
    """Cotangent stiffness matrix of a triangle mesh.

    Parameters
    ----------
    vertices : (n, d) float
        Any embedding dimension d >= 2 (only edge lengths and angles matter).
    faces : (f, 3) int

    Returns
    -------
    (n, n) scipy.sparse.csr_matrix
        Symmetric positive semi-definite, rows sum to zero.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = v.shape[0]
    rows, cols, vals = [], [], []
    for k in range(3):
        # angle at corner k is opposite to edge (i, j)
        i, j, o = f[:, (k + 1) % 3], f[:, (k + 2) % 3], f[:, k]
        a = v[i] - v[o]
        b = v[j] - v[o]
        dot = np.einsum("ij,ij->i", a, b)
        cot = dot / np.maximum(_parallelogram_area(a, b, dot), 1e-300)
        w = 0.5 * cot
        rows += [i, j]
        cols += [j, i]
        vals += [-w, -w]
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    vals = np.concatenate(vals)
    off = sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    diag = -np.asarray(off.sum(axis=1)).ravel()
    return (off + sp.diags(diag)).tocsr()


def hat_gradients(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The gradients of the piecewise-linear hat functions on every face, and the face areas.

    ``∇φ_i = (n × e_i) / (2A)`` on a face of area ``A`` and unit normal ``n``, ``e_i`` the edge opposite its
    corner ``i`` (counter-clockwise). They span the face's plane and sum to zero, and
    ``Σ_f A_f ∇φ_i · ∇φ_j`` is :func:`cotan_stiffness`. A face of zero area gets zero gradients.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (f, 3) int

    Returns
    -------
    hat : (f, 3, 3) float
        ``hat[f, i]`` the gradient of the hat function of corner ``i`` of face ``f``.
    areas : (f,) float
    """
    p = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]  # (f, 3, 3)
    edges = np.stack([p[:, 2] - p[:, 1], p[:, 0] - p[:, 2], p[:, 1] - p[:, 0]], axis=1)
    normal = np.cross(edges[:, 2], -edges[:, 1])
    double_area = np.linalg.norm(normal, axis=1)
    flat = double_area <= 0
    safe = np.where(flat, 1.0, double_area)
    normal /= safe[:, None]
    hat = np.cross(normal[:, None, :], edges) / safe[:, None, None]
    hat[flat] = 0.0
    return hat, 0.5 * double_area


def gradient_operator(vertices: np.ndarray, faces: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """The gradient of a piecewise-linear vertex function on every face, as a matrix, and the face areas.

    ``G`` (3f × n) stacks :func:`hat_gradients`: rows ``3f .. 3f+2`` hold face ``f``'s gradient. Its weak
    divergence is ``Gᵀ diag(A)`` (each area repeated three times) and ``Gᵀ diag(A) G`` the cotangent stiffness,
    in which a face of zero area has no weight at all (:func:`cotan_stiffness` would give it near-infinite
    cotangents).

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (f, 3) int

    Returns
    -------
    gradient : (3f, n) csr_matrix
    areas : (f,) float
    """
    faces = np.asarray(faces, dtype=np.int64)
    hat, areas = hat_gradients(vertices, faces)
    rows = (3 * np.arange(faces.shape[0])[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1)
    cols = np.broadcast_to(faces[:, :, None], hat.shape)
    gradient = sp.csr_matrix((hat.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * faces.shape[0],
                                                                                  len(vertices)))
    return gradient, areas


def harmonic_extension(vertices: np.ndarray, faces: np.ndarray, values: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``values`` kept where ``known``, and elsewhere the harmonic function that takes them on: the minimiser of
    the Dirichlet energy ``uᵀ S u`` (cotangent stiffness ``S``, faces of zero area left out) with the known
    values fixed, ``S_uu u_u = −S_uk u_k``.

    Every unknown vertex connected (through faces of positive area) to a known one gets a weighted mean of the
    known values, as a membrane stretched over them would; a part of the mesh without a known vertex, and a
    vertex in no face of positive area, gets 0.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (f, 3) int
    values : (n,) or (n, d) float
        Read only where ``known``.
    known : (n,) bool

    Returns
    -------
    (n,) or (n, d) float
    """
    from scipy.sparse.csgraph import connected_components
    from scipy.sparse.linalg import splu

    values = np.asarray(values, dtype=np.float64)
    known = np.asarray(known, dtype=bool)
    out = np.where(known.reshape(known.shape + (1,) * (values.ndim - 1)), values, 0.0)
    if known.all() or not known.any():
        return out
    gradient, areas = gradient_operator(vertices, faces)
    stiffness = (gradient.T @ sp.diags(np.repeat(areas, 3)) @ gradient).tocsr()
    stiffness.eliminate_zeros()  # the zeros of flat faces are no edges of the graph below
    _, part = connected_components(stiffness, directed=False)  # a vertex in no face of positive area: alone
    anchored = np.isin(part, np.unique(part[known]))
    free = np.flatnonzero(~known & anchored)
    if free.size:
        fixed = np.flatnonzero(known)
        rhs = -(stiffness[free][:, fixed] @ values[fixed])
        out[free] = splu(stiffness[free][:, free].tocsc()).solve(np.asarray(rhs))
    return out


def mass_matrix(vertices: np.ndarray, faces: np.ndarray, kind: str = "lumped") -> sp.csr_matrix:
    """Mass matrix of a triangle mesh.

    Parameters
    ----------
    vertices : (n, d) float
    faces : (f, 3) int
    kind : {"lumped", "consistent"}
        Lumped: diagonal with one third of the adjacent triangle area per
        vertex. Consistent: the linear FEM Gram matrix.

    Returns
    -------
    (n, n) scipy.sparse.csr_matrix
        Symmetric positive definite; the entries sum to the surface area.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    n = v.shape[0]
    a = v[f[:, 1]] - v[f[:, 0]]
    b = v[f[:, 2]] - v[f[:, 0]]
    dot = np.einsum("ij,ij->i", a, b)
    area = 0.5 * np.sqrt(np.maximum(np.einsum("ij,ij->i", a, a) * np.einsum("ij,ij->i", b, b) - dot ** 2, 0.0))
    if kind == "lumped":
        lumped = np.zeros(n)
        for c in range(3):
            np.add.at(lumped, f[:, c], area / 3.0)
        return sp.diags(lumped).tocsr()
    if kind == "consistent":
        rows = np.concatenate([f[:, [0, 1, 2, 0, 1, 2, 0, 1, 2]].ravel()])
        cols = np.concatenate([f[:, [0, 0, 0, 1, 1, 1, 2, 2, 2]].ravel()])
        local = np.array([2, 1, 1, 1, 2, 1, 1, 1, 2], dtype=np.float64) / 12.0
        vals = (area[:, None] * local[None, :]).ravel()
        return sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsr()
    raise ParameterError(f"mass matrix kind must be 'lumped' or 'consistent', got {kind!r}")


def mesh_laplacian(mesh, mass: str = "lumped") -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Stiffness and mass matrices of a :class:`~corrlib.shapes.TriMesh`.

    Returns
    -------
    stiffness : (n, n) csr_matrix
    mass : (n, n) csr_matrix
    """
    return cotan_stiffness(mesh.vertices, mesh.faces), mass_matrix(mesh.vertices, mesh.faces, mass)


def curve_laplacian(points: np.ndarray, mass: str = "consistent") -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """FEM stiffness and mass of a closed polyline (thesis Eq. 9.1–9.2).

    Parameters
    ----------
    points : (m, d) float
        Polyline vertices in order; the segment from the last to the first
        point closes the curve. ``d`` may be 2 or 3.
    mass : {"consistent", "lumped"}

    Returns
    -------
    stiffness : (m, m) csr_matrix
        Symmetric positive semi-definite, rows sum to zero.
    mass : (m, m) csr_matrix
        Entries sum to the curve length.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] < 3:
        raise InputError(f"curve_laplacian needs at least 3 points of shape (m, d), got {p.shape}")
    m = p.shape[0]
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    if np.any(seg <= 0) or not np.all(np.isfinite(seg)):
        bad = np.flatnonzero(~(seg > 0))
        raise InputError(f"curve_laplacian: segments of zero or invalid length (e.g. segment {bad[0]})")
    i = np.arange(m)
    j = (i + 1) % m
    prev = np.roll(seg, 1)
    inv = 1.0 / seg
    stiffness = sp.coo_matrix(
        (np.concatenate([inv + np.roll(inv, 1), -inv, -inv]),
         (np.concatenate([i, i, j]), np.concatenate([i, j, i]))), shape=(m, m)).tocsr()
    if mass == "consistent":
        mass_mat = sp.coo_matrix(
            (np.concatenate([(prev + seg) / 3.0, seg / 6.0, seg / 6.0]),
             (np.concatenate([i, i, j]), np.concatenate([i, j, i]))), shape=(m, m)).tocsr()
    elif mass == "lumped":
        mass_mat = sp.diags((prev + seg) / 2.0).tocsr()
    else:
        raise ParameterError(f"mass matrix kind must be 'lumped' or 'consistent', got {mass!r}")
    return stiffness, mass_mat
