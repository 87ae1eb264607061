"""The spectral forms of kernel matching's objective: the kernel energy, the alignment ``C = Ψ[map]ᵀ Φ``, the
float32 kernel scores ``(Ψ_r e^{-tΛ_Y}) C (Φ_c e^{-tΛ_X})ᵀ``, and the descriptor similarities of the μ term
and of the initial assignment.
"""

from __future__ import annotations

import numpy as np

from corrlib.descriptors import mesh_descriptors
from corrlib.methods.reorientation import standardised


def kernel_energy(c: np.ndarray, decay_y: np.ndarray, decay_x: np.ndarray) -> float:
    """``<Π, K_Y Π K_X> = trace(D_Y C D_X Cᵀ)`` for ``C = Ψ[map]ᵀ Φ``."""
    return float(np.einsum("ij,i,ij,j->", c, decay_y, c, decay_x))


def alignment(psi_rows, phi_rows):
    return psi_rows.T @ phi_rows


#: decays below this (relative to 1) are dropped from the spectral products: their terms are far below float32
#: precision, and e^{-tλ} of the high eigenvalues at large times would otherwise be float32 subnormals, on which
#: the products run an order of magnitude slower
DECAY_CUTOFF = 1e-12


def kernel_score(psi_rows, phi_cols, c, decay_y, decay_x):
    """(r, c) float32 kernel score block ``(Ψ_r D_Y) C (Φ_c D_X)ᵀ``.

    Only the eigenpairs with a decay above :data:`DECAY_CUTOFF` enter. Both products run in float32: the score
    is float32, and the auction resolves it only to that precision. The transposed block is
    ``kernel_score(phi_cols, psi_rows, c.T, decay_x, decay_y)``.
    """
    k_y = max(1, int(np.count_nonzero(decay_y > DECAY_CUTOFF)))
    k_x = max(1, int(np.count_nonzero(decay_x > DECAY_CUTOFF)))
    left = (psi_rows[:, :k_y] * decay_y[:k_y]).astype(np.float32) @ c[:k_y, :k_x].astype(np.float32)
    right = (phi_cols[:, :k_x] * decay_x[:k_x]).astype(np.float32)
    return left @ right.T


def descriptor_similarity(f_rows: np.ndarray, f_cols: np.ndarray) -> np.ndarray:
    """(r, c) float32: negative squared descriptor distances between rows and columns, scaled to [-1, 0]."""
    fr32, fc32 = f_rows.astype(np.float32), f_cols.astype(np.float32)
    d2 = (fr32 ** 2).sum(1)[:, None] + (fc32 ** 2).sum(1)[None, :] - 2.0 * fr32 @ fc32.T
    return -d2 / max(float(d2.max()), 1e-30)


def shape_descriptors(source, target, spec_x, spec_y, kind: str):
    """Standardised descriptors of both shapes."""
    desc_x = mesh_descriptors(source, kind, spectrum=spec_x) if kind != "shot" else mesh_descriptors(source, kind)
    desc_y = mesh_descriptors(target, kind, spectrum=spec_y) if kind != "shot" else mesh_descriptors(target, kind)
    return standardised(desc_x, desc_y)


def with_orientation(desc_x, desc_y, or_x, or_y, weight: float):
    """The descriptors with the standardised orientation blocks appended (total variance ``weight`` × theirs)."""
    if weight <= 0:
        return desc_x, desc_y
    scale = weight * np.sqrt(desc_x.shape[1] / or_x.shape[1])
    return np.hstack([desc_x, scale * or_x]), np.hstack([desc_y, scale * or_y])


def heat_decays(evals: np.ndarray, area: float, tau: float) -> np.ndarray:
    """(k,) float: ``e^{-tλ}`` at the time ``t = τ · area`` (relative times make the kernel scale-invariant)."""
    return np.exp(-tau * area * evals)


def most_similar_matches(confidence: np.ndarray, fraction: float) -> np.ndarray:
    """Indices of the ``max(1, round(fraction · n))`` matches with the highest ``confidence`` (n,), best first."""
    return np.argsort(-confidence, kind="stable")[:max(1, round(fraction * confidence.size))]
