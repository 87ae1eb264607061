"""Closed-form divergence-free vector fields on the unit cube (thesis §10.4.1, Eq. 10.11).

The scalar potentials are the Dirichlet eigenfunctions of the Laplacian on
Ω = [0, 1]³,

    φ_j(x) = sin(π j₁ x₁) sin(π j₂ x₂) sin(π j₃ x₃),   j ∈ {1, 2, ...}³,

with eigenvalue π²|j|². Every potential gives three fields by the curl of
``φ_j e_d`` (d = 1, 2, 3)::

    v_{j,1} = ∇ × (φ_j e₁) = (0,     ∂₃φ_j, −∂₂φ_j)
    v_{j,2} = ∇ × (φ_j e₂) = (−∂₃φ_j, 0,     ∂₁φ_j)
    v_{j,3} = ∇ × (φ_j e₃) = (∂₂φ_j, −∂₁φ_j, 0    )

A curl has zero divergence, and on the face x_d ∈ {0, 1} the normal
component of each field contains a factor sin(π j_d x_d) = 0, so no field
has flux through ∂Ω: a flow of these fields maps Ω onto itself and
preserves volume.

Ordering (documented so coefficients are portable): potentials by
increasing |j|², ties by lexicographic (j₁, j₂, j₃); field index
``k = 3 q + (d - 1)`` for the q-th potential. The first ``K`` fields are
used. Prior variances (Eq. 10.18): ``λ_k = (π² |j|²)^(−D/2)`` with D = 3.

Evaluation is separable: per point, per-axis tables ``sin(π m x_d)`` and
``π m cos(π m x_d)`` (m ≤ max j) make every value a product of three table
entries.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from corrlib.errors import ParameterError

#: Spatial dimension of Ω (D in Eq. 10.18).
DIM = 3


@lru_cache(maxsize=16)
def potential_indices(n_fields: int) -> np.ndarray:
    """(Q, 3) int64: the frequency triples j of the first ``ceil(n_fields / 3)`` potentials, in basis order."""
    if int(n_fields) != n_fields or n_fields < 1:
        raise ParameterError(f"the number of basis fields must be a positive integer, got {n_fields!r}")
    n_pot = -(-int(n_fields) // 3)
    # the smallest cube {1..m}³ that contains the n_pot smallest |j|² (a ball of radius r holds ~π r³/6 triples)
    m = 1
    while True:
        grid = np.stack(np.meshgrid(*[np.arange(1, m + 1)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
        norm2 = (grid ** 2).sum(axis=1)
        order = np.lexsort((grid[:, 2], grid[:, 1], grid[:, 0], norm2))
        if len(order) >= n_pot and norm2[order[n_pot - 1]] <= (m + 1) ** 2:
            # any triple with a coordinate > m has |j|² ≥ (m+1)² + 2 > the largest chosen value
            out = grid[order[:n_pot]].astype(np.int64)
            out.flags.writeable = False
            return out
        m += 1


class DivFreeBasis:
    """The first ``n_fields`` divergence-free fields of Eq. 10.11.

    Parameters
    ----------
    n_fields : int
        K ≥ 1.

    Attributes
    ----------
    n_fields : int
        K.
    freqs : (Q, 3) int64
        Frequency triple of every potential (Q = ceil(K / 3)).
    field_freq : (K, 3) int64
        Frequency triple of every field.
    field_axis : (K,) int64
        d - 1 of every field (which ``e_d`` was curled).
    prior_variance : (K,) float
        λ_k = (π² |j|²)^(−3/2) (Eq. 10.18).
    max_freq : int
        Largest frequency along any axis (size of the per-axis tables).
    """

    def __init__(self, n_fields: int):
        self.freqs = potential_indices(int(n_fields))
        self.n_fields = int(n_fields)
        self.field_freq = np.repeat(self.freqs, 3, axis=0)[: self.n_fields]
        self.field_axis = np.tile(np.arange(3), len(self.freqs))[: self.n_fields]
        eig = math.pi ** 2 * (self.field_freq ** 2).sum(axis=1)
        self.prior_variance = eig ** (-DIM / 2.0)
        self.max_freq = int(self.freqs.max())

    def __repr__(self) -> str:
        return f"DivFreeBasis(n_fields={self.n_fields}, max_freq={self.max_freq})"

    def padded(self, coeffs) -> np.ndarray:
        """(3 Q,) float: ``coeffs`` (K,) zero-padded to whole potentials (the compiled kernels' layout)."""
        a = np.asarray(coeffs, dtype=np.float64).ravel()
        if a.shape != (self.n_fields,):
            raise ParameterError(f"expected {self.n_fields} coefficients, got shape {np.shape(coeffs)}")
        if not np.all(np.isfinite(a)):
            raise ParameterError("the deformation coefficients contain NaN or inf")
        out = np.zeros(3 * len(self.freqs))
        out[: self.n_fields] = a
        return out

    def _tables(self, points: np.ndarray):
        m = np.arange(1, self.max_freq + 1) * math.pi
        arg = points[:, :, None] * m  # (n, 3, M)
        s = np.sin(arg)
        c = m * np.cos(arg)
        ss = -(m ** 2) * s
        return s, c, ss

    def potential_derivatives(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Gradients and Hessians of every potential (reference NumPy evaluation).

        Parameters
        ----------
        points : (n, 3) float

        Returns
        -------
        grad : (n, Q, 3) float
            ∂_d φ_j.
        hess : (n, Q, 3, 3) float
            ∂_d ∂_e φ_j.
        """
        p = np.asarray(points, dtype=np.float64)
        s, c, ss = self._tables(p)
        j = self.freqs - 1
        S = [s[:, d, j[:, d]] for d in range(3)]
        C = [c[:, d, j[:, d]] for d in range(3)]
        SS = [ss[:, d, j[:, d]] for d in range(3)]
        grad = np.stack([C[0] * S[1] * S[2], S[0] * C[1] * S[2], S[0] * S[1] * C[2]], axis=-1)
        hess = np.empty(p.shape[:1] + (len(self.freqs), 3, 3))
        for d in range(3):
            for e in range(3):
                factors = [S[0], S[1], S[2]]
                if d == e:
                    factors[d] = SS[d]
                else:
                    factors[d], factors[e] = C[d], C[e]
                hess[..., d, e] = factors[0] * factors[1] * factors[2]
        return grad, hess

    def values(self, points) -> np.ndarray:
        """(n, 3, K) float: every field at every point (reference NumPy evaluation)."""
        grad, _ = self.potential_derivatives(points)
        g1, g2, g3 = grad[..., 0], grad[..., 1], grad[..., 2]
        zero = np.zeros_like(g1)
        # columns per potential: curl(φ e1), curl(φ e2), curl(φ e3)
        fields = np.stack([np.stack([zero, g3, -g2], axis=1),
                           np.stack([-g3, zero, g1], axis=1),
                           np.stack([g2, -g1, zero], axis=1)], axis=-1)  # (n, 3, Q, 3)
        return fields.reshape(len(grad), 3, -1)[:, :, : self.n_fields]

    def jacobians(self, points) -> np.ndarray:
        """(n, K, 3, 3) float: ``∂ v_k / ∂ x`` (rows: component, columns: derivative axis)."""
        _, hess = self.potential_derivatives(points)
        n, q = hess.shape[:2]
        jac = np.zeros((n, q, 3, 3, 3))  # (..., field axis d, component, derivative)
        # curl(φ e_d)_c = ε_{c a d} ∂_a φ  ->  ∂_e of it = ε_{c a d} ∂_a ∂_e φ
        for d in range(3):
            for c in range(3):
                for a in range(3):
                    eps = _levi_civita(c, a, d)
                    if eps:
                        jac[:, :, d, c, :] += eps * hess[:, :, a, :]
        return jac.reshape(n, 3 * q, 3, 3)[:, : self.n_fields]

    def velocity(self, points, coeffs) -> np.ndarray:
        """(n, 3) float: ``Σ_k a_k v_k(x)`` (reference NumPy evaluation)."""
        return np.einsum("nck,k->nc", self.values(points), np.asarray(coeffs, dtype=np.float64))

    def random_coefficients(self, scale: float = 1.0, seed: int | None = None) -> np.ndarray:
        """(K,) float: a draw from the prior N(0, scale² λ_k) (smooth random deformations)."""
        rng = np.random.default_rng(seed)
        return scale * rng.standard_normal(self.n_fields) * np.sqrt(self.prior_variance)


def _levi_civita(i: int, j: int, k: int) -> int:
    return int((i - j) * (j - k) * (k - i) / 2)
