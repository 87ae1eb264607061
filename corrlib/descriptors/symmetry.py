"""The intrinsic left–right reflection of a shape and the spectrum of its half.

**The reflection.** An intrinsic isometry ``S`` of a shape onto itself
commutes with the Laplace–Beltrami operator, so its functional map in the
eigenbasis, ``C = Φᵀ M Φ∘S``, is block diagonal over the eigenspaces and
``±1`` on simple eigenvalues (Ovsjanikov, Sun, Guibas, "Global intrinsic
symmetries of shapes", SGP 2008). For a reflection it is found like any
functional map (Ovsjanikov et al. 2012), with descriptors whose behaviour
under ``S`` is known:

* intrinsic descriptors (HKS, WKS) are invariant under every isometry:
  ``F ∘ S = F``;
* signed area forms ``n · (∇f × ∇g)`` of HKS pairs change sign under an
  orientation-reversing isometry (:mod:`corrlib.descriptors.orientation`):
  ``O ∘ S = -O``.

So ``C`` minimises ``‖C [F, O] − [F, −O]‖²`` plus the resolvent Laplacian
commutativity (coefficients of the descriptors;
:func:`~corrlib.geometry.fmaps.functional_map`), and ZoomOut (Melzi et
al. 2019) turns it into the pointwise map :func:`reflection_map`.

**More starts: the signs.** That least-squares start can take the wrong
sign on some of the lowest eigenfunctions of a posed shape, where the
descriptors' evidence is weak (a posed person: ``+0.89`` where the truth is
``−1``), and ZoomOut does not recover from a wrong coarse map. The search of
Ovsjanikov et al. 2008 gives more starts: every sign sequence ``s`` of
the :data:`SIGN_MODES` lowest non-constant eigenfunctions, each read as the
map to the nearest vertex in the sign-flipped coordinates ``s_i φ_i /
√λ_i``; the sequences whose map reverses orientation (the odd descriptors
change sign on average) and distorts the biharmonic distances
(:func:`reflection_distortion`) less than the first start's map. Each is
refined by ZoomOut, and of these maps and the first start's the one that
distorts the geodesic distances least (:func:`geodesic_distortion`) is the
reflection: the biharmonic distances rank the 63 candidates cheaply, the
geodesic ones judge the refined maps. (Only the best-ranked reversing
sequence was refined before; a sequence that reverses one half of the
shape and keeps the other has a mean orientation near zero, of either
sign, and on a person's finer mesh such a one ranked first.) The search needs
those eigenvalues simple: on a repeated one (a shape of revolution, a
sphere) the eigenfunctions are any basis of their eigenspace, the symmetry
rotates them, and no sign sequence follows it, so there only the first
start is used.

**The half shape.** Functions with ``f ∘ S = f`` are the functions on the
quotient ``X / S``, one half of the shape cut open along the curve of
symmetry, with a Neumann condition on that cut; their eigenpairs are the
even eigenpairs of ``X`` (:func:`even_spectrum`). A silhouette of a
bilaterally symmetric shape seen across its plane of symmetry (an animal
from the side, a human from the side) is that half, flattened: its outline
is the curve of symmetry (back, belly, head, tail) with the near limbs, and
its filled interior has the Neumann spectrum of a flat disk with boundary.
The spectral features of the even eigenpairs are therefore the 3D
counterpart of a filled silhouette's features, the boundary included, which
the features of the whole closed surface are not.
"""

from __future__ import annotations

import itertools
import threading

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from corrlib import cache
from corrlib.descriptors.orientation import orientation_descriptors
from corrlib.descriptors.spectral import biharmonic_embedding, hks, wks
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.distortion import GEODESIC_SAMPLES, geodesic_distortions as pair_distortions
from corrlib.geometry.fmaps import (ZOOMOUT_SAMPLES, ZoomOutSamples, functional_map, pointwise_to_functional,
                                    resolvent_mask, zoomout)

#: scales of the even probes (HKS and WKS each) and of the HKS whose pairs give the odd probes
EVEN_SCALES = 16
ODD_SCALES = 8
#: the reflection's functional map is estimated on this many eigenfunctions, then refined by ZoomOut
K_INIT = 20
K_FINAL = 60
ZOOMOUT_STEP = 5
#: weights of descriptor preservation and resolvent Laplacian commutativity, as in the functional-maps baseline
COMMUTATIVITY = 1.0
#: the signs of this many lowest non-constant eigenfunctions are searched (2^k − 1 sequences) for a second start:
#: the coarse layout of a shape (its limbs) is in the first few
SIGN_MODES = 6
#: leaf size of the k-d tree of the sign search (a speed setting only: every leaf size gives the same images)
SIGN_SEARCH_LEAF_SIZE = 128
#: eigenvalues closer than this (relative) count as one repeated eigenvalue: the eigensolver's precision, far
#: below the splitting of a near-degenerate pair by a pose (1e-3 and more)
MULTIPLET_TOLERANCE = 1e-6


def _normalised(functions: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Mean-free columns of unit M-norm."""
    centred = functions - (mass @ functions) / mass.sum()
    return centred / np.maximum(np.sqrt(mass @ centred ** 2), 1e-300)[None, :]


def reflection_map(mesh, spectrum, *, k_init: int = K_INIT, k_final: int = K_FINAL) -> np.ndarray:
    """The intrinsic orientation-reversing self-map of a closed mesh.

    Parameters
    ----------
    mesh : TriMesh
    spectrum : Spectrum
        At least ``k_final`` eigenpairs of ``mesh``.
    k_init, k_final : int
        Size of the estimated functional map and of the ZoomOut result.

    Returns
    -------
    (n,) int
        ``mirror[x]``: the vertex that ``x`` is mirrored to (for a shape
        without a reflection: the map that best reverses orientation while
        keeping the intrinsic descriptors).
    """
    if not 3 <= k_init <= k_final <= spectrum.k:
        raise ParameterError(f"the reflection needs 3 <= k_init <= k_final <= {spectrum.k} eigenpairs, "
                             f"got k_init={k_init}, k_final={k_final}")
    spectrum = spectrum.truncated(k_final)  # the result depends on these eigenpairs only
    mass = spectrum.mass.diagonal()
    even = np.hstack([hks(spectrum.evals, spectrum.evecs, EVEN_SCALES),
                      wks(spectrum.evals, spectrum.evecs, EVEN_SCALES)])
    odd = orientation_descriptors(mesh, spectrum, ODD_SCALES)
    probes = _normalised(np.hstack([even, odd]), mass)
    mirrored = probes * np.r_[np.ones(even.shape[1]), -np.ones(odd.shape[1])][None, :]
    phi = spectrum.evecs[:, :k_init]
    evals = spectrum.evals[:k_init]
    c = functional_map(phi.T @ (mass[:, None] * probes), phi.T @ (mass[:, None] * mirrored),
                       resolvent_mask(evals, evals), weights=(1.0, COMMUTATIVITY))
    embedding = biharmonic_embedding(spectrum.evals, spectrum.evecs)
    samples = ZoomOutSamples.of(mesh, mass)  # a finer mesh iterates on samples
    mirror = _zoomout(spectrum, c, k_final, samples)
    # the sign candidates that start better than the first start ends (ZoomOut then lowers them further)
    searched = _sign_search(spectrum, probes[:, even.shape[1]:], embedding,
                            below=reflection_distortion(mirror, embedding))
    if not searched:
        return mirror
    refined = [mirror] + [_zoomout(spectrum, pointwise_to_functional(images, phi, phi, mass), k_final, samples)
                          for images in searched]
    return refined[int(np.argmin(geodesic_distortions(mesh, refined)))]  # the first one on a tie


def _zoomout(spectrum, c: np.ndarray, k_final: int, samples=None) -> np.ndarray:
    """The pointwise self-map ZoomOut refines a functional map into (through ``samples``, if given)."""
    steps = zoomout(spectrum.evecs, spectrum.evecs, spectrum.mass, c, k_final, ZOOMOUT_STEP,
                    samples_x=samples, samples_y=samples)
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value[0]


def _sign_search(spectrum, odd: np.ndarray, embedding: np.ndarray, below: float = np.inf) -> list[np.ndarray]:
    """The orientation-reversing sign candidates that distort less than ``below`` (the module's other starts),
    in order of distortion; none where a searched eigenvalue is repeated.

    The candidates are ranked by their distortion (:func:`reflection_distortion`, on the evenly strided
    sample); every one whose map reverses orientation over *all* vertices is kept, and the caller decides
    between them by geodesic distortion after refinement. The orientation is a mean of per-vertex products of
    odd descriptors, which are formed from gradients and normals and so carry the mesh's noise: a sample of a
    few hundred vertices can misread it where all of them do not; and a candidate that reverses one half of
    the shape and keeps the other has a mean near zero of either sign, so the first candidate that reverses
    orientation need not be the reflection (a person's finer mesh: a mean of −0.035 for a wrong candidate
    against −0.71 for the reflection, ranked after it by distortion).

    Parameters
    ----------
    spectrum : Spectrum
    odd : (n, d) float
        Normalised orientation-aware descriptors, negated by a reflection.
    embedding : (n, e) float
        The biharmonic embedding the candidates' distortion is measured in.
    below : float
        Only candidates that distort less are looked at (the caller's other start: one that does not
        improve on it would not be used).
    """
    modes = min(SIGN_MODES, spectrum.k - 2)
    evals = spectrum.evals[1:modes + 2]
    if modes < 1 or np.any(np.diff(evals) <= MULTIPLET_TOLERANCE * evals[1:]):
        return []  # a repeated eigenvalue: its eigenfunctions are any basis of their space, signs mean nothing
    coordinates = spectrum.evecs[:, 1:modes + 1] / np.sqrt(np.maximum(spectrum.evals[1:modes + 1], 1e-300))
    # Most sign vectors are no symmetry: their images lie far from every vertex, where a k-d tree with small
    # leaves visits most of its nodes. One query of all candidates on large leaves (exact all the same).
    tree = cKDTree(coordinates, leafsize=SIGN_SEARCH_LEAF_SIZE)
    sample = distortion_sample(coordinates.shape[0])
    distances = cdist(embedding[sample], embedding[sample])
    candidates = np.array([signs for signs in itertools.product((1.0, -1.0), repeat=modes) if min(signs) < 0])
    flipped = coordinates[sample][None, :, :] * candidates[:, None, :]
    all_images = tree.query(flipped.reshape(-1, modes), workers=-1)[1].reshape(len(candidates), sample.size)
    distortions = [_distortion(distances, embedding[images]) for images in all_images]
    reversing = []
    for index in np.argsort(distortions, kind="stable"):
        if not distortions[index] < below:
            break
        images = tree.query(coordinates * candidates[index], workers=-1)[1]
        if np.mean(np.sum(odd * odd[images], axis=1)) < 0:
            reversing.append(images)
    return reversing


#: vertices (evenly strided) on which a reflection's distortion is measured
REFLECTION_SAMPLES = 400


def reflection_distortion(mirror: np.ndarray, embedding: np.ndarray) -> float:
    """Mean ``|d(x, y) − d(S x, S y)|`` of the biharmonic distances over pairs of evenly strided vertices.

    Zero for an exact intrinsic isometry; it measures how well a computed self-map ``S``
    (:func:`reflection_map`) is one, without any ground truth.

    Parameters
    ----------
    mirror : (n,) int
    embedding : (n, d) float
        :func:`~corrlib.descriptors.spectral.biharmonic_embedding` of the shape (divided by √area to compare
        shapes).
    """
    rows = distortion_sample(mirror.size)
    return _distortion(cdist(embedding[rows], embedding[rows]), embedding[np.asarray(mirror)[rows]])


def geodesic_distortion(mesh, mirror: np.ndarray) -> float:
    """Mean ``|d(x, y) − d(S x, S y)|`` of the geodesic distances (shortest edge paths) between farthest-point
    samples, divided by √area.

    The definition of an isometry, measured directly; it decides between the two refined starts of
    :func:`reflection_map`. The biharmonic distances of :func:`reflection_distortion` are smooth, which makes
    them cheap to compare for many candidates, but they barely tell close parallel limbs apart (a wolf's front
    legs), and a little vertex noise, which makes a mesh slightly asymmetric at every scale, raises them for
    the true reflection as much as a swap of two legs does. A path between two legs runs through the body,
    so a swap changes it by the body's width.

    Parameters
    ----------
    mesh : TriMesh
    mirror : (n,) int
    """
    return geodesic_distortions(mesh, (mirror,))[0]


def geodesic_distortions(mesh, mirrors) -> list[float]:
    """:func:`geodesic_distortion` of several self-maps of one mesh, the sample's own distances computed once
    (:func:`corrlib.geometry.distortion.geodesic_distortions` with the mesh as source and target).

    Parameters
    ----------
    mesh : TriMesh
    mirrors : sequence of (n,) int

    Returns
    -------
    list of float
        One distortion per map, in their order.
    """
    return pair_distortions(mesh, mesh, mirrors)


def distortion_sample(n: int) -> np.ndarray:
    """The evenly strided vertices (about :data:`REFLECTION_SAMPLES`) a distortion is measured on."""
    return np.arange(0, n, max(1, n // REFLECTION_SAMPLES))


def _distortion(sample_distances: np.ndarray, image_points: np.ndarray) -> float:
    """Mean ``|d(x, y) − d(S x, S y)|`` given the sample's distances and its images' embedding."""
    return float(np.mean(np.abs(sample_distances - cdist(image_points, image_points))))


def even_spectrum(spectrum, mirror: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The lowest ``k`` eigenpairs of the functions that the reflection leaves unchanged.

    The even subspace of the span of the eigenfunctions is the range of the
    projector ``P = (I + C_s) / 2``, ``C_s`` the symmetrised functional map
    of the reflection; the Laplacian is diagonalised on it (Rayleigh–Ritz).

    Parameters
    ----------
    spectrum : Spectrum
        Eigenpairs of the mesh; about twice ``k`` of them are needed.
    mirror : (n,) int
        The reflection (:func:`reflection_map`).
    k : int

    Returns
    -------
    evals : (k,) float
        Ascending, the first ≈ 0 (the constant is even).
    evecs : (n, k) float
        M-orthonormal even eigenfunctions.
    """
    return _parity_spectrum(spectrum, mirror, k, even=True)


def odd_eigenfunction(spectrum, mirror: np.ndarray) -> np.ndarray:
    """(n,) float: the lowest eigenfunction that the reflection negates (``g ∘ S = −g``).

    Rayleigh–Ritz on the range of ``(I − C_s) / 2``, as :func:`even_spectrum`
    on the even one. It is of one sign on each half of the shape (the
    Dirichlet ground state of a half, extended oddly) and zero on the curve
    of symmetry.
    """
    return _parity_spectrum(spectrum, mirror, 1, even=False)[1][:, 0]


def _parity_spectrum(spectrum, mirror: np.ndarray, k: int, even: bool) -> tuple[np.ndarray, np.ndarray]:
    phi = spectrum.evecs
    mirror = np.asarray(mirror)
    if mirror.shape != (phi.shape[0],):
        raise InputError(f"the reflection must map each of the {phi.shape[0]} vertices, got shape {mirror.shape}")
    mass = spectrum.mass.diagonal()
    c = pointwise_to_functional(mirror, phi, phi, mass)
    projector_evals, projector_evecs = np.linalg.eigh(0.5 * np.eye(c.shape[0]) + 0.25 * (c + c.T))
    basis = projector_evecs[:, projector_evals > 0.5] if even else projector_evecs[:, projector_evals < 0.5]
    if basis.shape[1] < k:
        parity = "even" if even else "odd"
        raise ParameterError(f"only {basis.shape[1]} of {spectrum.k} eigenfunctions are {parity}; "
                             f"{k} {parity} eigenpairs need more eigenpairs of the mesh")
    laplacian = basis.T @ (spectrum.evals[:, None] * basis)
    evals, ritz = np.linalg.eigh(0.5 * (laplacian + laplacian.T))
    return evals[:k], phi @ (basis @ ritz[:, :k])


#: held while reflections are computed or read (:func:`mesh_reflections`)
_REFLECTING = threading.Lock()


def _reflection_key(mesh) -> str:
    return cache.make_key("reflection-v6", mesh.content_hash, K_INIT, K_FINAL, EVEN_SCALES, ODD_SCALES, ZOOMOUT_STEP,
                          COMMUTATIVITY, SIGN_MODES, REFLECTION_SAMPLES, GEODESIC_SAMPLES, ZOOMOUT_SAMPLES)


def _cached_reflection(mesh) -> np.ndarray | None:
    entry = cache.load("reflections", _reflection_key(mesh),
                       {"mirror": cache.Array("i", (mesh.n_vertices,), below=mesh.n_vertices)})
    if entry is not None:
        return entry["mirror"].astype(np.int64)
    return None


def _stored_reflection(mesh, spectrum) -> np.ndarray:
    mirror = reflection_map(mesh, spectrum)
    cache.store("reflections", _reflection_key(mesh), {"mirror": mirror})
    return mirror


def mesh_reflection(mesh, spectrum) -> np.ndarray:
    """:func:`reflection_map` with the default sizes, cached on disk by mesh content like the spectra."""
    mirror = _cached_reflection(mesh)
    return _stored_reflection(mesh, spectrum) if mirror is None else mirror


def mesh_reflections(meshes, spectra) -> list[np.ndarray]:
    """:func:`mesh_reflection` of several meshes (a pair), the ones not cached on two threads (the two cores).

    ZoomOut's nearest-row searches are half matrix products and half a single-threaded arg-min, so two
    reflections on two threads with single-threaded BLAS each take less wall time than one after the other
    with two-threaded BLAS; the maps are the same (:func:`reflection_map` is deterministic). Meshes of equal
    content are computed once, and so are concurrent calls for the same meshes (the two starts of kernel
    matching): one call at a time, so the second finds the first one's maps in the cache.
    """
    with _REFLECTING:
        return _reflections(list(meshes), list(spectra))


def _reflections(meshes: list, spectra: list) -> list[np.ndarray]:
    """:func:`mesh_reflections` without its lock."""
    from threadpoolctl import threadpool_limits

    from corrlib.cores import side_threads

    found = [_cached_reflection(mesh) for mesh in meshes]
    first_of = {}
    for i, mesh in enumerate(meshes):
        first_of.setdefault(mesh.content_hash, i)
    todo = [i for i, mirror in enumerate(found) if mirror is None and first_of[meshes[i].content_hash] == i]
    if len(todo) >= 2:
        with threadpool_limits(1), side_threads(2) as pool:
            for i, mirror in zip(todo, pool.map(lambda i: _stored_reflection(meshes[i], spectra[i]), todo)):
                found[i] = mirror
    for i, mesh in enumerate(meshes):
        if found[i] is None:
            first = first_of[mesh.content_hash]
            found[i] = found[first] if found[first] is not None else _stored_reflection(mesh, spectra[i])
    return found
