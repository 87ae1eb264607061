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


def intrinsic_axis(evals: np.ndarray, evecs: np.ndarray, mass: np.ndarray, mode: int = 1) -> IntrinsicAxis:
    """The intrinsic axis of a connected shape along its ``mode``-th eigenfunction.

    ``mode = 1`` is the longest axis (the Fiedler function); higher modes are
    the next axes of the shape's spectral embedding (for a person with arms
    out: head to feet, then left to right). Their confidence is the smaller
    relative gap to the neighbouring eigenvalues,
    ``1 - max(λ_{mode-1}/λ_mode, λ_mode/λ_{mode+1})`` (for mode 1 this is
    ``1 - λ_1/λ_2``, as ``λ_0 = 0``).

    Parameters
    ----------
    evals : (k,) float
        Laplace–Beltrami eigenvalues in ascending order, ``k >= mode + 2``,
        ``evals[0] ≈ 0`` (a connected shape).
    evecs : (n, k) float
        Eigenfunctions (any normalisation).
    mass : (n,) float
        Vertex areas (lumped mass).
    mode : int
        Which eigenfunction, ``>= 1``.

    Returns
    -------
    IntrinsicAxis
    """
    evals = np.asarray(evals, dtype=np.float64)
    mass = np.asarray(mass, dtype=np.float64)
    if not (isinstance(mode, (int, np.integer)) and mode >= 1):
        raise ParameterError(f"mode must be an integer >= 1, got {mode!r}")
    if evals.ndim != 1 or evals.shape[0] < mode + 2:
        raise ParameterError(f"the intrinsic axis of mode {mode} needs at least {mode + 2} eigenvalues, got shape "
                             f"{evals.shape}")
    if evecs.shape != (mass.shape[0], evals.shape[0]):
        raise ParameterError(f"evecs must be (n, k) = ({mass.shape[0]}, {evals.shape[0]}), got {evecs.shape}")
    if not (evals[1] > 0 and np.all(mass > 0)):
        raise ParameterError("the intrinsic axis needs a connected shape (evals[1] > 0) and positive vertex areas")
    function = np.asarray(evecs[:, mode], dtype=np.float64)
    order = np.argsort(function, kind="stable")
    sorted_mass = mass[order]
    coordinate = np.empty_like(function)
    # quantile at the vertex's own position: the area strictly before it plus half its own
    coordinate[order] = (np.cumsum(sorted_mass) - 0.5 * sorted_mass) / sorted_mass.sum()
    gap_below = evals[mode - 1] / evals[mode]
    gap_above = evals[mode] / evals[mode + 1] if evals[mode + 1] > 0 else 1.0
    confidence = float(np.clip(1.0 - max(gap_below, gap_above), 0.0, 1.0))
    return IntrinsicAxis(coordinate, confidence)


def spectral_axes(evals: np.ndarray, evecs: np.ndarray, mass: np.ndarray, n_axes: int) -> list[IntrinsicAxis]:
    """The intrinsic axes of modes ``1 .. n_axes`` (see :func:`intrinsic_axis`)."""
    return [intrinsic_axis(evals, evecs, mass, mode) for mode in range(1, n_axes + 1)]


def axis_mismatch(contour_axis: np.ndarray, mesh_axis: np.ndarray, *, flipped: bool = False) -> np.ndarray:
    """``|a_contour(i) - a_mesh(j)|`` ((m, n) float), with ``a_contour ↦ 1 - a_contour`` if ``flipped``."""
    a = 1.0 - np.asarray(contour_axis, dtype=np.float64) if flipped else np.asarray(contour_axis, dtype=np.float64)
    return np.abs(a[:, None] - np.asarray(mesh_axis, dtype=np.float64)[None, :])

