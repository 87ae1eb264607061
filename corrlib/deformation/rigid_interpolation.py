"""As-rigid-as-possible interpolation from a mesh to the image of a point-to-point map.

Linear interpolation of vertex positions, ``(1 − t) x + t y``, shrinks whatever turns: half way through a
turn of 90° a segment is 0.71 of its length, and a shape turned by 180° passes through its own centroid. The
as-rigid-as-possible interpolation of Alexa, Cohen-Or and Levin (SIGGRAPH 2000), carried to surfaces as a
Poisson problem (Xu, Zhang, Wang, Bao, Solid and Physical Modeling 2005), interpolates how each face is
*deformed* instead:

1. Every face's deformation gradient ``J_f = E_Y E_X⁻¹`` (its two edges and a normal of length ``√|e₁ × e₂|``
   on either side, Sumner & Popović 2004) is split by the polar decomposition ``J_f = R_f S_f`` into a rotation
   and a symmetric positive stretch.
2. At time ``t`` the face is turned by the fraction ``t`` of its rotation and stretched by ``S_f^t``:
   ``J_f(t) = exp(t [ω_f]ₓ) S_f^t``, ``ω_f`` the rotation vector of ``R_f``. ``S^t`` (rather than Alexa's
   ``(1 − t) I + t S``, equal at both ends) stays positive when ``t > 1`` extrapolates.
3. The positions are those whose face gradients are closest to ``J_f(t)`` in the least-squares sense,
   ``min_x Σ_f A_f ‖∇_f x − J_f(t)‖²`` over the source's faces, i.e. the Poisson equation
   ``L x = Gᵀ A J(t)`` (``L = Gᵀ A G`` the cotangent stiffness), with each connected component's
   area-weighted centroid moving linearly from the source's to the image's.

At ``t = 0`` this is the source; at ``t = 1`` the image of the map, since the image's own face gradients are
those of one surface. Two things make the gradients differ from the image's, and both are put back by adding
the residual at ``t = 1`` in proportion to ``t``, so that both ends are exact for every map: stretches raised
to stay positive (a face the map collapses), and the diffusion of the gradients over the map's resolution
(``resolution``): a vertex map onto another mesh snaps every vertex to the target's nearest vertex, which
turns single faces at random by up to 180°, and interpolating those turns would make the intermediate shapes
rough, while their average over a target edge length is the deformation of the surface.

Rotation vectors are defined up to turns of 2π about their axis. Each face's is chosen closest to that of
its neighbour on a minimum spanning tree of the faces, weighted by the angle between adjacent faces'
rotations (quality-guided unwrapping, as phase unwrapping does it: Ghiglia & Pritt 1998), from the face
whose rotation is nearest the mean rotation. So a limb twisted by more than 180° turns continuously, and a
face that the map sends astray is reached last, from its least-turned neighbour, and misleads no other
face.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.sparse.linalg import splu
from scipy.spatial.transform import Rotation

from corrlib.errors import InputError
from corrlib.geometry.laplacian import gradient_operator
from corrlib.shapes import face_components

#: stretches below this (relative: 1 is the face's own size) are raised to it before ``S^t`` is formed; a face
#: the map collapses to a point or a segment has none, and its end state comes from the residual
STRETCH_FLOOR = 1e-6


def deformation_gradients(source: np.ndarray, image: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(f, 3, 3) float: every face's deformation gradient ``J_f = E_Y E_X⁻¹`` (Sumner & Popović 2004).

    ``E = [v₁ − v₀, v₂ − v₀, (v₁ − v₀) × (v₂ − v₀) / √|(v₁ − v₀) × (v₂ − v₀)|]`` on either side; ``J_f`` maps
    the source face's edges onto the image's. A face of zero area in the source gets the identity.
    """
    def edge_frames(points):
        p = points[faces]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        normal = np.cross(e1, e2)
        length = np.sqrt(np.linalg.norm(normal, axis=1))
        normal /= np.where(length > 0, length, 1.0)[:, None]
        return np.stack([e1, e2, normal], axis=2), length > 0  # columns: the two edges and the normal

    e_x, proper = edge_frames(source)
    e_y, _ = edge_frames(image)
    gradients = np.broadcast_to(np.eye(3), (faces.shape[0], 3, 3)).copy()
    # J E_X = E_Y  ⇔  E_Xᵀ Jᵀ = E_Yᵀ
    gradients[proper] = np.linalg.solve(np.transpose(e_x[proper], (0, 2, 1)),
                                        np.transpose(e_y[proper], (0, 2, 1))).transpose(0, 2, 1)
    return gradients


def polar_parts(gradients: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The polar decomposition ``J = R S`` of every (3, 3) matrix: the rotation, and the stretch's eigenvectors
    and eigenvalues (``S = Q diag(s) Qᵀ``, ``s`` raised to :data:`STRETCH_FLOOR`).

    Returns
    -------
    rotations : (f, 3, 3) float
        Proper rotations (determinant +1), the closest to each ``J``.
    axes : (f, 3, 3) float
        ``Q``, the stretch's eigenvectors as columns.
    stretches : (f, 3) float
    """
    u, sigma, vt = np.linalg.svd(gradients)
    sign = _rotation_signs(u, vt)
    u[:, :, 2] *= sign[:, None]  # R = U D Vᵀ with D = diag(1, 1, det(U Vᵀ)): a rotation, not a reflection
    stretches = sigma.copy()
    stretches[:, 2] *= sign
    return u @ vt, np.transpose(vt, (0, 2, 1)), np.maximum(stretches, STRETCH_FLOOR)


def _rotation_signs(u: np.ndarray, vt: np.ndarray) -> np.ndarray:
    sign = np.sign(np.linalg.det(u @ vt))
    sign[sign == 0] = 1.0
    return sign


def nearest_rotations(matrices: np.ndarray) -> np.ndarray:
    """(m, 3, 3) float: the proper rotation nearest each (3, 3) matrix in the Frobenius norm (Umeyama 1991)."""
    u, _, vt = np.linalg.svd(matrices)
    u[:, :, 2] *= _rotation_signs(u, vt)[:, None]
    return u @ vt


def dual_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of faces (a, b), a < b, that share an edge (the faces around a non-manifold edge in a chain)."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    owner = np.tile(np.arange(faces.shape[0]), 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    edges, owner = edges[order], owner[order]
    same = np.all(edges[1:] == edges[:-1], axis=1)
    first, second = owner[:-1][same], owner[1:][same]
    return np.minimum(first, second), np.maximum(first, second)


def unwrapped_rotation_vectors(rotations: np.ndarray, faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(f, 3) float: a rotation vector for every rotation, chosen among ``ω + 2πk ω/|ω|`` to vary
    continuously over the surface (see the module's notes).

    Parameters
    ----------
    rotations : (f, 3, 3) float
    faces : (f, 3) int
        Their faces (adjacency by shared edges).
    weights : (f,) float
        The faces' areas (for the mean rotation that picks each part's first face).
    """
    principal = Rotation.from_matrix(rotations).as_rotvec()  # |ω| ≤ π
    angle = np.linalg.norm(principal, axis=1)
    axis = principal / np.where(angle > 0, angle, 1.0)[:, None]
    a, b = dual_edges(faces)
    n = faces.shape[0]
    cos_between = (np.einsum("fij,fij->f", rotations[a], rotations[b]) - 1.0) / 2.0  # of R_aᵀ R_b's angle
    # weighted by 2 − cos, which orders the angles as they are and is never 0 (a stored 0 is no edge)
    tree = minimum_spanning_tree(sp.coo_matrix((2.0 - cos_between, (a, b)), shape=(n, n)).tocsr())
    n_parts, part = connected_components(tree, directed=False)
    vectors = principal.copy()
    for p in range(n_parts):
        members = np.flatnonzero(part == p)
        mean = nearest_rotations(np.einsum("f,fij->ij", weights[members], rotations[members])[None])[0]
        root = members[np.argmax(np.einsum("fij,ij->f", rotations[members], mean))]  # least angle to the mean
        order, parent = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        for face in order[1:]:  # parents come before their children
            # the turn k that brings θ + 2πk nearest the parent's vector's component along this face's axis
            k = np.round((axis[face] @ vectors[parent[face]] - angle[face]) / (2.0 * np.pi))
            vectors[face] = axis[face] * (angle[face] + 2.0 * np.pi * k)
    return vectors


@dataclass(frozen=True)
class RigidInterpolation:
    """Positions between a mesh (t = 0) and the image of a map (t = 1), and beyond (t > 1): see the module.

    Build it with :func:`rigid_interpolation`; :meth:`positions` costs one batched matrix product, one sparse
    product and one solve with a factorisation made once.
    """

    source: np.ndarray
    image: np.ndarray
    rotation_vectors: np.ndarray
    stretch_axes: np.ndarray
    stretches: np.ndarray
    divergence: sp.csr_matrix
    solver: object
    free: np.ndarray
    components: np.ndarray
    lumped_area: np.ndarray
    loose: np.ndarray
    residual: np.ndarray

    def gradients(self, t: float) -> np.ndarray:
        """(f, 3, 3) float: ``J_f(t) = exp(t [ω_f]ₓ) S_f^t``."""
        turn = Rotation.from_rotvec(t * self.rotation_vectors).as_matrix()
        q = self.stretch_axes
        stretch = np.einsum("fik,fk,fjk->fij", q, self.stretches ** t, q)
        return turn @ stretch

    def _poisson(self, t: float) -> np.ndarray:
        """Positions whose face gradients fit :meth:`gradients` best, centroids moved linearly (no residual)."""
        gradients = self.gradients(t)
        # right-hand side Gᵀ A J(t): the per-face gradients of the three coordinates are J's rows
        rhs = self.divergence @ np.transpose(gradients, (0, 2, 1)).reshape(-1, 3)
        x = np.zeros_like(self.source)
        x[self.free] = self.solver.solve(rhs[self.free])
        goal = (1.0 - t) * self.source + t * self.image
        weight = np.bincount(self.components, weights=self.lumped_area)
        weight[weight <= 0] = 1.0  # a component of loose vertices only (set below)
        for axis in range(3):  # each component's area-weighted centroid onto the linear one
            now = np.bincount(self.components, weights=self.lumped_area * x[:, axis]) / weight
            want = np.bincount(self.components, weights=self.lumped_area * goal[:, axis]) / weight
            x[:, axis] += (want - now)[self.components]
        x[self.loose] = goal[self.loose]  # no face with area around them: nothing to keep rigid
        return x

    def positions(self, t: float) -> np.ndarray:
        """(n, 3) float: the vertex positions at time ``t`` (0: the source, 1: the image, > 1 extrapolated)."""
        t = float(t)
        if not np.isfinite(t):
            raise InputError(f"the time must be a finite number, got {t!r}")
        return self._poisson(t) + t * self.residual


def smoothed_gradients(gradients: np.ndarray, faces: np.ndarray, areas: np.ndarray, stiffness: sp.spmatrix,
                       lumped: np.ndarray, diffusion_time: float) -> np.ndarray:
    """(f, 3, 3) float: the faces' deformation gradients diffused over the source surface for ``diffusion_time``.

    Each of the nine entries, carried to the vertices (area-weighted means of the faces around them), takes one
    implicit heat step ``(M + t L) u = M u₀`` (``t`` the diffusion time; ``L`` the source's stiffness, ``M`` its
    lumped mass) and returns to the faces as the mean of their corners. A gradient that is the same over a part,
    such as a rigidly turned limb, stays as it is away from the part's border, however thin the part (smoothing
    the *positions* instead would shrink a tail); a face whose gradient disagrees with its neighbours' (a vertex
    map snapping to the target's vertices) is pulled towards theirs.

    Parameters
    ----------
    gradients : (f, 3, 3) float
    faces : (f, 3) int
    areas : (f,) float
    stiffness : (n, n) sparse
    lumped : (n,) float
        The lumped mass (a third of the area around each vertex).
    diffusion_time : float
    """
    n = lumped.size
    to_vertices = sp.csr_matrix((np.repeat(areas, 3), (faces.ravel(), np.repeat(np.arange(faces.shape[0]), 3))),
                                shape=(n, faces.shape[0]))
    weight = np.asarray(to_vertices.sum(axis=1)).ravel()
    at_vertices = (to_vertices @ gradients.reshape(-1, 9)) / np.where(weight > 0, weight, 1.0)[:, None]
    mass = sp.diags(lumped)
    diffused = splu((mass + diffusion_time * stiffness).tocsc()).solve(mass @ at_vertices)
    return diffused[faces].mean(axis=1).reshape(-1, 3, 3)


def rigid_interpolation(source: np.ndarray, faces: np.ndarray, image: np.ndarray,
                        resolution: float = 0.0) -> RigidInterpolation:
    """Prepare the as-rigid-as-possible interpolation from ``source`` to ``image`` (the module's notes).

    Parameters
    ----------
    source : (n, 3) float
        The source mesh's vertices.
    faces : (f, 3) int
        Its faces (the interpolated meshes keep them).
    image : (n, 3) float
        Where the map sends every source vertex (e.g. ``target.vertices[map_xy]``).
    resolution : float
        The length within which the image is known: for a vertex map onto a mesh, that mesh's mean edge length
        (the map snaps to its vertices). The faces' deformation gradients are diffused over it
        (:func:`smoothed_gradients`, diffusion time ``resolution²``) before they are split, so that the snapping
        does not turn faces at random; what the diffusion leaves out comes back through the residual. 0: the
        gradients as they are (an image on the source's own connectivity, e.g. a deformed copy).

    Returns
    -------
    RigidInterpolation
    """
    source = np.asarray(source, dtype=np.float64)
    image = np.asarray(image, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if source.ndim != 2 or source.shape[1] != 3 or image.shape != source.shape:
        raise InputError(f"the source and its image must both be (n, 3) arrays, got {source.shape} and "
                         f"{image.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.shape[0] == 0:
        raise InputError(f"faces must be a non-empty (f, 3) array, got {faces.shape}")
    if not (np.all(np.isfinite(source)) and np.all(np.isfinite(image))):
        raise InputError("the source and its image must have finite coordinates")
    n = source.shape[0]
    gradient, areas = gradient_operator(source, faces)  # (3f, n); Gᵀ A is the divergence
    divergence = (gradient.T @ sp.diags(np.repeat(areas, 3))).tocsr()
    stiffness = (divergence @ gradient).tocsc()  # the cotangent stiffness, with faces of zero area left out
    lumped = np.bincount(faces.ravel(), weights=np.repeat(areas / 3.0, 3), minlength=n)
    loose = lumped <= 0  # in no face or only in faces of zero area: moved linearly (RigidInterpolation._poisson)
    components = face_components(n, faces[areas > 0])[1]  # the parts the stiffness connects
    pinned = loose.copy()
    firsts = np.unique(components[~loose], return_index=True)[1]
    pinned[np.flatnonzero(~loose)[firsts]] = True  # one vertex fixes each part's translation
    free = np.flatnonzero(~pinned)
    solver = splu(stiffness[free][:, free].tocsc())
    gradients = deformation_gradients(source, image, faces)
    if resolution > 0:
        gradients = smoothed_gradients(gradients, faces, areas, stiffness, lumped, resolution ** 2)
    rotations, stretch_axes, stretches = polar_parts(gradients)
    prepared = RigidInterpolation(source, image, unwrapped_rotation_vectors(rotations, faces, areas), stretch_axes,
                                  stretches, divergence, solver, free, components, lumped, loose,
                                  residual=np.zeros_like(source))
    residual = image - prepared._poisson(1.0)
    return replace(prepared, residual=residual)
