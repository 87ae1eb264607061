"""Orientation-aware descriptors: tell a point from its mirror image.

Intrinsic descriptors (HKS, WKS, heat kernels) are invariant under every
isometry, also the orientation-reversing ones, so they cannot tell the left
from the right side of a bilaterally symmetric shape. For two intrinsic
functions ``f``, ``g`` the signed area form

``o(x) = n(x) · (∇f(x) × ∇g(x))``

is preserved by orientation-preserving isometries and changes sign under
orientation-reversing ones (it is the pointwise version of the
orientation-preserving operator of Ren et al., "Continuous and
orientation-preserving correspondences via functional maps", SIGGRAPH Asia
2018). Evaluated for pairs of HKS scales it gives descriptors that are equal
at corresponding points and opposite at mirrored points.

The normals must point outward on both shapes: on a closed mesh the sign is
taken from the enclosed volume, so an inward-oriented file gives the same
features; on open meshes the file's orientation is used.
"""

from __future__ import annotations

import numpy as np

from corrlib.errors import InputError
from corrlib.geometry.laplacian import hat_gradients, mass_matrix


def face_gradients(vertices: np.ndarray, faces: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Gradients of piecewise-linear functions, one per face.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (f, 3) int
    values : (n, d) float
        ``d`` functions given at the vertices.

    Returns
    -------
    (f, d, 3) float
        ``∇u = Σ_i u_i (n × e_i) / (2A)`` on every face, ``e_i`` the edge
        opposite vertex ``i`` (counter-clockwise), ``n`` the unit normal.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[0] != vertices.shape[0]:
        raise InputError(f"values must have shape (n_vertices, d) = ({vertices.shape[0]}, d), got {values.shape}")
    hat, areas = hat_gradients(vertices, faces)  # (f, 3 corners, 3)
    if np.any(areas <= 0):
        raise InputError("face_gradients: the mesh has faces of zero area")
    return np.einsum("fcd,fck->fdk", values[faces], hat)


def corner_integrals(mesh, face_values: np.ndarray) -> np.ndarray:
    """``(n, d)``: every face's ``(f, d)`` values times a third of its area, summed at its corners
    (the integral against the lumped hat functions)."""
    weighted = face_values * (mesh.face_areas / 3.0)[:, None]
    out = np.zeros((mesh.n_vertices, face_values.shape[1]))
    for corner in range(3):
        np.add.at(out, mesh.faces[:, corner], weighted)
    return out


def outward_sign(mesh) -> float:
    """-1 for a closed mesh whose normals point inward (negative enclosed volume), else 1."""
    volume = mesh.enclosed_volume() if mesh.is_closed else None
    return -1.0 if volume is not None and volume < 0 else 1.0


def orientation_features(mesh, functions: np.ndarray, pairs=None) -> np.ndarray:
    """Signed area forms ``n · (∇f_a × ∇f_b)`` of pairs of functions, averaged to the vertices.

    Parameters
    ----------
    mesh : TriMesh
    functions : (n, d) float
        Intrinsic functions (e.g. HKS scales).
    pairs : sequence of (a, b), optional
        Column pairs (default: every ``a < b``).

    Returns
    -------
    (n, len(pairs)) float
        Area-weighted vertex averages of the face values, multiplied by the
        surface area (scale-invariant when the functions are).
    """
    functions = np.asarray(functions, dtype=np.float64)
    d = functions.shape[1] if functions.ndim == 2 else 0
    if pairs is None:
        pairs = [(a, b) for a in range(d) for b in range(a + 1, d)]
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size == 0 or pairs.min() < 0 or pairs.max() >= d:
        raise InputError(f"orientation_features needs pairs of columns of the {d} functions")
    grads = face_gradients(mesh.vertices, mesh.faces, functions)
    form = np.einsum("fk,fpk->fp", mesh.face_normals, np.cross(grads[:, pairs[:, 0]], grads[:, pairs[:, 1]]))
    out = corner_integrals(mesh, form) / mass_matrix(mesh.vertices, mesh.faces, "lumped").diagonal()[:, None]
    return outward_sign(mesh) * mesh.area * out


def orientation_descriptors(mesh, spectrum, n_channels: int = 8) -> np.ndarray:
    """Orientation-aware descriptors from pairs of HKS scales.

    Parameters
    ----------
    mesh : TriMesh
    spectrum : Spectrum
        Eigenpairs of the mesh (the HKS uses them).
    n_channels : int
        HKS scales (log-spaced over the standard range); every pair of them
        gives one feature.

    Returns
    -------
    (n, n_channels · (n_channels - 1) / 2) float
    """
    from corrlib.descriptors.spectral import hks

    if n_channels < 2:
        raise InputError(f"orientation descriptors need at least 2 HKS scales, got {n_channels}")
    # the heat-trace-normalised HKS scales like 1 / area: HKS · area is scale-invariant, and so are the features
    return orientation_features(mesh, mesh.area * hks(spectrum.evals, spectrum.evecs, n_channels))


def orientation_operators(mesh, evecs: np.ndarray, functions: np.ndarray) -> np.ndarray:
    """Orientation-preserving operators in the eigenbasis (Ren, Poulenard, Wonka, Ovsjanikov 2018).

    For a function ``f`` the operator ``g ↦ n · (∇f × ∇g)`` commutes with
    the pull-back of every orientation-preserving isometry and anticommutes
    with a reflection; its matrix in the basis is ``Φᵀ M (n · (∇f × ∇Φ))``
    (face values given to the corners by a third of the face's area, like
    the lumped mass). A functional map asked to commute with these operators
    keeps left on left.

    Parameters
    ----------
    mesh : TriMesh
    evecs : (n, k) float
    functions : (n, d) float

    Returns
    -------
    (d, k, k) float
    """
    grad_basis = face_gradients(mesh.vertices, mesh.faces, evecs)  # (f, k, 3)
    grad_f = face_gradients(mesh.vertices, mesh.faces, functions)  # (f, d, 3)
    normals = outward_sign(mesh) * mesh.face_normals
    # n · (∇f × ∇φ) = (n × ∇f) · ∇φ
    values = np.einsum("fdc,fkc->fdk", np.cross(normals[:, None, :], grad_f), grad_basis)
    return np.stack([evecs.T @ corner_integrals(mesh, values[:, d, :]) for d in range(functions.shape[1])])
