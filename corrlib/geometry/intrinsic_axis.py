"""The longest intrinsic axis of a shape, as a coordinate that a filled silhouette and a surface share.

The first non-constant Laplace–Beltrami eigenfunction φ_1 (the Fiedler
function) of an elongated shape increases monotonically from one end of its
longest intrinsic extent to the other (the 1D intuition: ``cos(π s / L)``).
It does so on a filled 2D silhouette and on the closed surface it depicts,
and it is invariant to isometric deformations, to the units and to the
vertex order. Its values are not comparable between the two domains, but
its **mass quantile** is:

.. math::

    a(x) = \\frac{1}{A} \\int_{\\{y : φ_1(y) < φ_1(x)\\}} dA(y) \\in [0, 1],

the share of the area "before" ``x`` along the axis. ``a`` is 0.5 in the
middle and 0 and 1 at the two ends on both shapes: the head of a side
silhouette and the head of the surface get about the same value.

The sign of an eigenfunction is arbitrary, so ``a`` is known up to
``a ↦ 1 - a``; the 2D-to-3D matching solves both readings and keeps the
lower energy (:mod:`corrlib.methods.contour3d`).

How much the axis can be trusted is measured by the spectral gap
(eigenvector perturbation, Davis–Kahan): when ``λ_1 ≈ λ_2`` (a round or
square shape) φ_1 is an arbitrary mix of two eigenfunctions and the axis is
meaningless. :attr:`IntrinsicAxis.confidence` is ``1 - λ_1/λ_2``: 0 for a
disc or a sphere, about 3/4 for a long thin strip (``λ_j ∝ j²``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.errors import ParameterError


@dataclass(frozen=True)
class IntrinsicAxis:
    """Mass-quantile coordinate along the first non-constant eigenfunction.

    Attributes
    ----------
    coordinate : (n,) float
        ``a(x)`` in [0, 1] at every vertex.
    confidence : float
        ``1 - λ_1 / λ_2`` in [0, 1].
    """

    coordinate: np.ndarray
    confidence: float


def intrinsic_axis(evals: np.ndarray, evecs: np.ndarray, mass: np.ndarray) -> IntrinsicAxis:
    """The longest intrinsic axis of a connected shape.

    Parameters
    ----------
    evals : (k,) float
        Laplace–Beltrami eigenvalues in ascending order, ``k >= 3``,
        ``evals[0] ≈ 0`` (a connected shape).
    evecs : (n, k) float
        Eigenfunctions (any normalisation).
    mass : (n,) float
        Vertex areas (lumped mass).

    Returns
    -------
    IntrinsicAxis
    """
    evals = np.asarray(evals, dtype=np.float64)
    mass = np.asarray(mass, dtype=np.float64)
    if evals.ndim != 1 or evals.shape[0] < 3:
        raise ParameterError(f"the intrinsic axis needs at least 3 eigenvalues, got shape {evals.shape}")
    if evecs.shape != (mass.shape[0], evals.shape[0]):
        raise ParameterError(f"evecs must be (n, k) = ({mass.shape[0]}, {evals.shape[0]}), got {evecs.shape}")
    if not (evals[1] > 0 and np.all(mass > 0)):
        raise ParameterError("the intrinsic axis needs a connected shape (evals[1] > 0) and positive vertex areas")
    fiedler = np.asarray(evecs[:, 1], dtype=np.float64)
    order = np.argsort(fiedler, kind="stable")
    sorted_mass = mass[order]
    coordinate = np.empty_like(fiedler)
    # quantile at the vertex's own position: the area strictly before it plus half its own
    coordinate[order] = (np.cumsum(sorted_mass) - 0.5 * sorted_mass) / sorted_mass.sum()
    confidence = float(np.clip(1.0 - evals[1] / evals[2], 0.0, 1.0)) if evals[2] > 0 else 0.0
    return IntrinsicAxis(coordinate, confidence)


def axis_mismatch(contour_axis: np.ndarray, mesh_axis: np.ndarray, *, flipped: bool = False) -> np.ndarray:
    """``|a_contour(i) - a_mesh(j)|`` ((m, n) float), with ``a_contour ↦ 1 - a_contour`` if ``flipped``."""
    a = 1.0 - np.asarray(contour_axis, dtype=np.float64) if flipped else np.asarray(contour_axis, dtype=np.float64)
    return np.abs(a[:, None] - np.asarray(mesh_axis, dtype=np.float64)[None, :])

