"""Closed matchings of a symmetric outline whose two halves lie on the two halves of the surface.

A view of a bilaterally symmetric shape *within* its plane of symmetry (a
person from the front, an animal from above) has an outline that is its own
(intrinsic) mirror image: a reflection ``r(i) = (s − i) mod m`` of the
outline's evenly spaced points onto themselves
(:func:`~corrlib.descriptors.side_view.mirror_shift`), whose axis crosses
the outline twice (head and crotch, nose and tail). The curve such an outline
is on the surface crosses the surface's curve of symmetry at the same two
places, and between them it stays on one half of the surface: one half of
the outline runs down the left flank, the other up the right.

A free closed curve has no reason to do so: both halves of a symmetric
outline have the same features, and so do both halves of the surface, so
the optimum can run down one flank and back up the same flank. The sided
cost (:func:`sided_cost`) makes the structure a constraint: the lowest odd
eigenfunction ``g`` of the surface (:func:`~corrlib.descriptors.symmetry.odd_eigenfunction`,
``g ∘ S = −g``) has one sign on each half and vanishes on the curve of
symmetry, so the points of one half of the outline (:func:`outline_half`)
may only be matched where ``σ g ≥ 0`` and the others where ``σ g ≤ 0``;
vertices next to the curve of symmetry (:func:`symmetry_curve_vertices`)
belong to both. Every other node of the product graph is forbidden (an
infinite cost, which the layered Dijkstra never relaxes). A path from one half
to the other must pass a vertex next to the curve of symmetry, so the curve
crosses it where the outline changes halves. The constrained problem is
searched by the same branch-and-bound, so its optimum stays global; both
signs ``σ`` are searched (the outline's first half may be either flank).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corrlib.errors import InputError


def outline_half(m: int, shift: int) -> np.ndarray:
    """(m,) bool: the outline points from the reflection's first crossing to its second.

    The reflection ``i ↦ (shift − i) mod m`` fixes ``i`` where ``2i ≡ shift``
    (mod m). The half runs from ``⌈shift/2⌉`` to ``⌊(shift + m)/2⌋`` (indices
    modulo m); the other points are their mirror images.
    """
    if m < 4:
        raise InputError(f"a symmetric outline needs at least 4 points, got {m}")
    first = -(-shift // 2)
    last = (shift + m) // 2
    half = np.zeros(m, dtype=bool)
    half[np.arange(first, last + 1) % m] = True
    return half


def symmetry_curve_vertices(adjacency, odd: np.ndarray) -> np.ndarray:
    """(n,) bool: the vertices at an edge across which the odd function changes sign (and its zeros).

    The lowest odd eigenfunction vanishes exactly on the curve of symmetry and
    has one sign on each half, so these are the vertices next to that curve,
    found without a threshold.
    """
    odd = np.asarray(odd, dtype=np.float64)
    adj = sp.coo_matrix(adjacency)
    crossing = np.sign(odd[adj.row]) != np.sign(odd[adj.col])
    out = np.zeros(odd.shape[0], dtype=bool)
    out[adj.row[crossing]] = True
    out[adj.col[crossing]] = True
    out |= odd == 0.0
    return out


def sided_cost(cost: np.ndarray, shift: int, odd: np.ndarray, on_curve: np.ndarray, sign: float) -> np.ndarray:
    """(m, n) float: the node cost with every match on the wrong half of the surface forbidden (``inf``).

    Parameters
    ----------
    cost : (m, n) float
        Node cost of the closed matching.
    shift : int
        The outline's reflection ``r(i) = (shift − i) mod m``.
    odd : (n,) float
        The surface's lowest odd eigenfunction.
    on_curve : (n,) bool
        Vertices next to its curve of symmetry (allowed on both halves).
    sign : {1, -1}
        ``σ``: the outline's first half (:func:`outline_half`) is matched where ``σ g ≥ 0``.
    """
    cost = np.asarray(cost, dtype=np.float64)
    m, n = cost.shape
    odd, on_curve = np.asarray(odd, dtype=np.float64), np.asarray(on_curve, dtype=bool)
    if odd.shape != (n,) or on_curve.shape != (n,):
        raise InputError(f"the odd function and the curve of symmetry need one entry per vertex ({n}), got "
                         f"{odd.shape} and {on_curve.shape}")
    if sign not in (1, -1, 1.0, -1.0):
        raise InputError(f"sign must be +1 or -1, got {sign}")
    first = outline_half(m, shift)
    positive = (sign * odd > 0) | on_curve
    negative = (sign * odd < 0) | on_curve
    allowed = np.where(first[:, None], positive[None, :], negative[None, :])
    return np.where(allowed, cost, np.inf)
