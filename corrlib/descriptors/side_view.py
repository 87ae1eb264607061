"""Where the outline of a side view lies on a bilaterally symmetric surface.

A shape seen across its plane of symmetry (an animal from the side) shows an
outline that runs along the shape's curve of symmetry ``C``, the fixed
curve of its left–right reflection ``S`` (back, belly, head, tail), and
round the limbs of the near side. A section through the plane of symmetry is
``C`` itself. Two facts about such an outline, both intrinsic, give a prior
for 2D-to-3D matching (:mod:`corrlib.methods.contour3d`):

* **On the curve of symmetry.** A point of the outline is on ``C`` unless it
  is on a limb. ``C`` is where a point is its own mirror image, so the cost
  of a surface point is its distance to its mirror image ``|x − S(x)|``
  (:func:`symmetry_curve_cost`). Limbs come in mirror pairs: a protrusion of
  the surface (:func:`~corrlib.geometry.segmentation.protrusion_parts`) whose
  mirror image is another protrusion is a limb, and costs nothing
  (:func:`paired_limbs`). The head and the tail are their own mirror images,
  so ``C`` runs through them and the cost stays.
* **One half on the same side.** The outline goes once round the body and
  keeps the near half on one side all the way: it separates the left half
  from the right. Without this an outline could run along the back and come
  back along the back, and every point would still lie on ``C``. The lowest
  odd eigenfunction ``g`` (``g ∘ S = −g``; :func:`~corrlib.descriptors.symmetry.odd_eigenfunction`)
  is of one sign on each half, so ``∇g`` crosses ``C`` from one half to the
  other, and a curve with the positive half on its left has
  ``(n × t) · ∇g ≥ 0`` for its unit tangent ``t`` and the surface normal
  ``n``. :func:`edge_orientation` gives that number for every directed edge
  of the mesh; its negative part is the cost of walking the edge the wrong
  way round. Which half is near is unknown, so both signs are searched.

A view *within* the plane of symmetry (a person from the front, an animal
from above) shows an outline that is its own mirror image in 2D and crosses
``C`` instead of following it. :func:`mirror_asymmetry` tells the two kinds
of view apart from the 2D outline alone. A front view of a *posed* shape (a
person with one arm raised) is not its own mirror image, but it stays
intrinsically symmetric: the pose bends the outline without stretching it,
so some reflection of the outline onto itself still carries every point to
one with the same intrinsic features (:func:`intrinsic_asymmetry`). A side
view has neither symmetry (head and tail differ), so a view is taken for a
side view only when the outline is asymmetric in both senses.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from corrlib.descriptors.orientation import face_gradients
from corrlib.errors import InputError

#: points per unit of the outline's scale at which its mirror image is compared with it
MIRROR_SAMPLES = 4000


def mirror_asymmetry(points: np.ndarray) -> float:
    """How far a closed 2D outline is from its own mirror image (0: mirror symmetric).

    The outline is centred and scaled to enclose area 1/2 (the convention of
    :mod:`corrlib.methods.contour3d`); a mirror symmetry's axis is a principal
    axis of the outline's points, so both principal axes are tried. The result
    is the mean distance of the reflected points to the outline (densely
    resampled), for the better axis.

    Parameters
    ----------
    points : (m, 2) float
        The outline, closed implicitly, roughly evenly spaced.

    Returns
    -------
    float
        In units of the outline normalised to area 1/2; independent of the
        input's position, rotation, scale and orientation.
    """
    from corrlib.shapes import Contour2D

    contour = Contour2D(np.asarray(points, dtype=np.float64), validate=False)
    area = abs(contour.area)
    if contour.n_points < 3 or area <= 0:
        raise InputError(f"mirror_asymmetry needs a closed outline enclosing an area, got {contour.n_points} points "
                         f"enclosing {area:g}")
    centred = (contour.points - contour.points.mean(axis=0)) * np.sqrt(0.5 / area)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    aligned = centred @ axes.T
    tree = cKDTree(Contour2D(aligned, validate=False).resample(MIRROR_SAMPLES).points)
    best = np.inf
    for axis in (0, 1):
        reflected = aligned.copy()
        reflected[:, axis] *= -1.0
        best = min(best, float(tree.query(reflected)[0].mean()))
    return best


def intrinsic_asymmetry(features: np.ndarray) -> float:
    """How far a closed outline is from an intrinsic mirror symmetry (0: symmetric).

    A reflection of a closed curve onto itself reverses its direction and
    keeps arc length, so on an outline resampled evenly by arc length it maps
    point ``i`` to point ``(s − i) mod m`` for one shift ``s`` (the axis passes
    through point ``s/2``, or between two points for odd ``s``). The outline is
    intrinsically symmetric if, for some ``s``, every point has the features of
    its image:

    .. math::

        \\min_s \\frac{1}{m} \\sum_i \\lVert f_i - f_{(s-i) \\bmod m} \\rVert_1
        \\Big/ \\frac{1}{m^2} \\sum_{i,j} \\lVert f_i - f_j \\rVert_1 .

    The denominator (two points chosen at random) makes it unit-free: 0 for a
    perfect symmetry, about 1 when the best reflection pairs points no better
    than chance. With intrinsic features (spectral descriptors of the filled
    outline) it does not change under bendings of the outline's parts. It is
    ill-conditioned on round outlines, whose points all look alike (a regular
    decagon reads 0.65: the denominator is tiny); those are their own mirror
    images, which :func:`mirror_asymmetry` sees, and a view is a side view
    only if both measures say so.

    Parameters
    ----------
    features : (m, d) float
        Descriptors of the outline's points, in order along the outline,
        evenly spaced by arc length.

    Returns
    -------
    float
    """
    return float(_reflection_scores(features).min())


def mirror_shift(features: np.ndarray) -> int:
    """The outline's best intrinsic reflection ``i ↦ (s − i) mod m``: the shift ``s`` that minimises
    :func:`intrinsic_asymmetry` (its axis crosses the outline at points ``s/2`` and ``(s + m)/2``).

    Parameters
    ----------
    features : (m, d) float
        As for :func:`intrinsic_asymmetry`.

    Returns
    -------
    int
        ``s`` in ``0 .. m-1``.
    """
    return int(np.argmin(_reflection_scores(features)))


def _reflection_scores(features: np.ndarray) -> np.ndarray:
    """(m,) float: the normalised feature distance of every point to its image, per reflection shift ``s``."""
    features = np.asarray(features, dtype=np.float64)
    if features.ndim != 2 or features.shape[0] < 3 or not np.all(np.isfinite(features)):
        raise InputError(f"intrinsic_asymmetry needs (m, d) finite features of m >= 3 points, got shape "
                         f"{features.shape}")
    m = features.shape[0]
    pairwise = cdist(features, features, "cityblock")
    scale = pairwise.mean()
    if scale <= 0.0:
        return np.zeros(m)  # every point alike: any reflection keeps the features
    points = np.arange(m)
    images = (points[:, None] - points[None, :]) % m  # [s, i] -> the image of point i under the reflection s
    return pairwise[points[None, :], images].mean(axis=1) / scale


def paired_limbs(labels: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """(n,) bool: vertices on a protrusion whose mirror image is mostly another protrusion (a limb).

    Parameters
    ----------
    labels : (n,) int
        Protrusions (0: body), e.g. :func:`~corrlib.geometry.segmentation.protrusion_parts`.
    mirror : (n,) int
        The reflection ``S`` as a vertex map.
    """
    labels, mirror = np.asarray(labels), np.asarray(mirror)
    if labels.shape != mirror.shape:
        raise InputError(f"labels {labels.shape} and mirror {mirror.shape} must both have one entry per vertex")
    limb = np.zeros(labels.shape, dtype=bool)
    for part in range(1, int(labels.max(initial=0)) + 1):
        members = labels == part
        if members.any() and np.mean(labels[mirror[members]] == part) < 0.5:
            limb |= members
    return limb


def symmetry_curve_cost(vertices: np.ndarray, mirror: np.ndarray, limbs: np.ndarray) -> np.ndarray:
    """(n,) float ≥ 0: distance to the mirror image ``|x − S(x)|``, divided by its mean; 0 on limbs.

    Zero on the curve of symmetry; one at a typical point of the body. Unit-free.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    distance = np.linalg.norm(vertices - vertices[np.asarray(mirror)], axis=1)
    mean = float(distance.mean())
    if mean <= 0:
        raise InputError("the reflection maps every vertex to itself: the shape has no curve of symmetry")
    return np.where(limbs, 0.0, distance / mean)


def edge_orientation(vertices: np.ndarray, faces: np.ndarray, adjacency: sp.spmatrix,
                     odd: np.ndarray) -> sp.csr_matrix:
    """``(n̂ × t) · ∇g / mean |∇g|`` for every directed edge ``j → k`` of the mesh ((n, n) sparse).

    ``t`` is the unit edge vector, ``n̂`` the mean of the two vertex normals and
    ``∇g`` the mean of the two vertex gradients of the odd function ``g``
    (area-weighted face gradients). Positive where the edge keeps the half
    with ``g > 0`` on its left; antisymmetric (the edge ``k → j`` has the
    opposite sign). Divided by the mean gradient norm, so unit-free.

    Parameters
    ----------
    vertices : (n, 3) float
    faces : (f, 3) int
    adjacency : (n, n) sparse
        Edge graph (symmetric pattern).
    odd : (n,) float
        An odd function, e.g. the lowest odd eigenfunction.
    """
    from corrlib.shapes import area_weighted_normals

    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    odd = np.asarray(odd, dtype=np.float64)
    n = vertices.shape[0]
    if odd.shape != (n,) or not np.all(np.isfinite(odd)) or not np.ptp(odd) > 0:
        raise InputError(f"edge_orientation: the odd function must be finite, non-constant and have one value per "
                         f"vertex ({n}), got shape {odd.shape}")
    grads = face_gradients(vertices, faces, odd[:, None])[:, 0, :]  # (f, 3)
    face_area = 0.5 * np.linalg.norm(np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                                              vertices[faces[:, 2]] - vertices[faces[:, 0]]), axis=1)
    vertex_grad = np.zeros((n, 3))
    weight = np.zeros(n)
    for corner in range(3):
        np.add.at(vertex_grad, faces[:, corner], face_area[:, None] * grads)
        np.add.at(weight, faces[:, corner], face_area)
    vertex_grad /= np.maximum(weight, 1e-300)[:, None]
    scale = float(np.mean(np.linalg.norm(vertex_grad, axis=1)))
    normals = area_weighted_normals(vertices, faces)
    pattern = sp.csr_matrix(adjacency)
    pattern = (pattern + pattern.T).tocsr()
    pattern.sort_indices()
    rows = np.repeat(np.arange(n), np.diff(pattern.indptr))
    cols = pattern.indices
    tangent = vertices[cols] - vertices[rows]
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
    normal = normals[rows] + normals[cols]
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    value = np.einsum("ek,ek->e", np.cross(normal, tangent), 0.5 * (vertex_grad[rows] + vertex_grad[cols])) / scale
    return sp.csr_matrix((value, cols.copy(), pattern.indptr.copy()), shape=(n, n))


def seen_from_the_side(vertices: np.ndarray, mirror: np.ndarray, mass: np.ndarray) -> bool:
    """Whether a shape's natural outline is a side view: it is thinnest across its plane of symmetry.

    An outline is drawn, as a rendered silhouette is taken, along the shape's
    thinnest direction: the axis of least variance of its area-weighted
    covariance ``Σ_i m_i (x_i − x̄)(x_i − x̄)ᵀ``. The normal of the plane of
    symmetry is the dominant direction of the displacements to the mirror
    images, the top eigenvector of ``Σ_i m_i d_i d_iᵀ`` with
    ``d_i = x_i − x_S(i)`` (for an exact reflection ``d_i = 2 ((x_i − p) · ν) ν``,
    so that sum has rank one along the normal ``ν``). The outline crosses the
    plane of symmetry, and is a side view, where the normal is closest to the
    least-variance axis of the three principal axes: a quadruped is thinnest
    from side to side, a person (arms out or not) from front to back. Extrinsic,
    so it judges the pose the mesh is in, which is the pose its outline shows.

    Parameters
    ----------
    vertices : (n, 3) float
    mirror : (n,) int
        The reflection ``S`` as a vertex map.
    mass : (n,) float
        Vertex areas.

    Returns
    -------
    bool
        False also where the reflection moves no vertex (no plane to speak of).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    mirror, mass = np.asarray(mirror), np.asarray(mass, dtype=np.float64)
    if not (vertices.ndim == 2 and vertices.shape[1] == 3 and mirror.shape == mass.shape == vertices.shape[:1]):
        raise InputError(f"vertices {vertices.shape}, mirror {mirror.shape} and mass {mass.shape} must be "
                         "(n, 3), (n,) and (n,)")
    centred = vertices - (mass @ vertices) / mass.sum()
    _, axes = np.linalg.eigh((centred * mass[:, None]).T @ centred)  # columns by increasing variance
    displacement = vertices - vertices[mirror]
    spread, directions = np.linalg.eigh((displacement * mass[:, None]).T @ displacement)
    if spread[-1] <= 0.0:
        return False
    normal = directions[:, -1]
    return int(np.argmax(np.abs(axes.T @ normal))) == 0
