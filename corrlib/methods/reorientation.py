"""The whole-shape left/right decision of a map: a reversed map is turned by the target's reflection.

A bilaterally symmetric target ``Y`` has an intrinsic reflection ``S_Y``, an
isometry of ``Y`` onto itself that reverses orientation
(:mod:`corrlib.descriptors.symmetry`). A map ``m`` and its turned version
``S_Y ∘ m`` preserve the same heat kernels, spectral descriptors and geodesic
distances, so no intrinsic energy (the kernel energy of kernel matching among
them) can choose between them: a solver that starts from a wrong orientation
ends at a map that sends left to right on the whole shape (measured: a start
whose orientation block is reversed gives the cats 0.21 √area instead of 0.03,
with the same kernel energy).

The orientation-aware descriptors ``O`` (signed area forms, odd under a
reflection: ``O ∘ S = −O``) can. Their mean agreement ``a(m) = ⟨O_X, O_Y ∘ m⟩``
(:func:`corrlib.methods.kernel_matching.orientation_agreement`) is positive
for a map that keeps left on left and changes sign under ``S_Y``:
``a(S_Y ∘ m) ≈ −a(m)``. :func:`turn_reversed_map` therefore returns
``S_Y ∘ m`` exactly when

    a(m) < 0 < a(S_Y ∘ m),

i.e. when the map reverses orientation on most of the shape *and* the
self-map found on the target really turns it. The second condition rejects
a target without a clean reflection (the computed self-map mixes several
near-symmetries, or there is none): the turned map is then no better oriented
and the map is left as it is (and reported as reversed). It cannot reject a
different clean reflection: on a shape with two (left–right and front–back),
the wrong one would turn a left–right flip into a half turn of the shape,
which preserves orientation too. No threshold enters.

A map reversed on one part only (an arm) keeps a positive agreement and is not
changed here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Turned:
    """A map composed with the target's reflection.

    Attributes
    ----------
    map_xy : (n_X,) int
        ``S_Y[m(x)]`` (-1 kept).
    map_yx : (n_Y,) int or None
        ``m⁻¹(S_Y(y))``: the backward map composed on its input side (``S_Y`` is an involution).
    agreement_before, agreement : float
        Orientation agreement of the input map and of the turned one.
    """

    map_xy: np.ndarray
    map_yx: np.ndarray | None
    agreement_before: float
    agreement: float


def turn_reversed_map(map_xy: np.ndarray, map_yx: np.ndarray | None, mirror_y: Callable[[], np.ndarray],
                      agreement: Callable[[np.ndarray], float]) -> Turned | None:
    """``S_Y ∘ m`` if ``a(m) < 0 < a(S_Y ∘ m)``, else None (see the module docstring).

    Parameters
    ----------
    map_xy : (n_X,) int
        Target vertex of every source vertex, -1 where unmatched.
    map_yx : (n_Y,) int or None
        The backward map, composed the same way if given.
    mirror_y : callable returning (n_Y,) int
        The target's reflection ``S_Y`` (vertex ``y`` goes to ``mirror[y]``); called only for a reversed map,
        so that a well oriented one costs nothing.
    agreement : callable
        ``a(map_xy)``, the orientation agreement of a forward map.

    Returns
    -------
    Turned or None
    """
    before = float(agreement(map_xy))
    if not before < 0:
        return None
    mirror = np.asarray(mirror_y(), dtype=np.int64)
    turned_xy = np.where(map_xy >= 0, mirror[np.maximum(map_xy, 0)], -1)
    after = float(agreement(turned_xy))
    if not after > 0:
        return None
    turned_yx = None if map_yx is None else np.asarray(map_yx)[mirror]
    return Turned(turned_xy, turned_yx, before, after)
