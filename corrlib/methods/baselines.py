"""Baseline methods, registered like every method so comparisons mean something.

* ``descriptor-nn``: each vertex is matched to the vertex with the nearest
  descriptor (L2) on the other shape, in both directions.
* ``fmap-zoomout``: functional maps (Ovsjanikov et al. 2012) from descriptor
  preservation, resolvent Laplacian commutativity (Ren et al. 2019),
  descriptor commutativity (Nogneng & Ovsjanikov 2017) and
  orientation-preserving operators (Ren et al. 2018), solved exactly (the
  energy is quadratic), refined by ZoomOut (Melzi et al. 2019).

The functional-map building blocks (least squares, ZoomOut) and their
convention are in :mod:`corrlib.geometry.fmaps`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corrlib.descriptors import DESCRIPTOR_KINDS, mesh_descriptors
from corrlib.descriptors.orientation import orientation_operators
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.fmaps import (ZoomOutSamples, functional_map, multiplication_operators,
                                    nearest_rows_through_samples, resolvent_mask, zoomout)
from corrlib.geometry.spectrum import available_eigenpairs, mesh_spectra
from corrlib.methods.base import MatchResult, param
from corrlib.methods.registry import MethodSpec, register
from corrlib.neighbours import nearest_rows
from corrlib.progress import Progress, Stopwatch


def _standardize(desc_x: np.ndarray, desc_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scale every descriptor dimension by its joint standard deviation (shapes comparable)."""
    both = np.concatenate([desc_x, desc_y])
    scale = both.std(axis=0)
    scale[scale == 0] = 1.0
    return desc_x / scale, desc_y / scale


# ----------------------------------------------------------------------------- descriptor NN


@dataclass(frozen=True, kw_only=True)
class DescriptorNNParams:
    descriptor: str = param("wks", label="Descriptor", choices=DESCRIPTOR_KINDS,
                            help="Point descriptor compared in L2 (WKS/HKS spectral, SHOT extrinsic).")
    n_eigs: int = param(100, label="Eigenpairs", low=3, high=2000,
                        help="Laplace–Beltrami eigenpairs for the spectral descriptors.")
    n_scales: int = param(100, label="Scales", low=1, high=1000, help="Scales (times/energies) of HKS/WKS.")


def _spectra_and_descriptors(source, target, n_eigs: int, descriptor: str, n_scales: int, watch):
    """Laplacian spectra (``n_eigs`` pairs, capped by the vertex counts) of both shapes scaled to unit area
    (:meth:`~corrlib.geometry.spectrum.Spectrum.at_unit_area`: a pair in different units, millimetres against
    metres, is matched as the same pair), and the descriptors computed from them."""
    with watch("eigen"):
        spec_x, spec_y = mesh_spectra((source, target),
                                      (available_eigenpairs(source, n_eigs), available_eigenpairs(target, n_eigs)))
        spec_x, spec_y = spec_x.at_unit_area(source.area), spec_y.at_unit_area(target.area)
    with watch("descriptors"):
        desc_x = mesh_descriptors(source, descriptor, spectrum=spec_x, n_scales=n_scales)
        desc_y = mesh_descriptors(target, descriptor, spectrum=spec_y, n_scales=n_scales)
    for mesh, desc in ((source, desc_x), (target, desc_y)):
        if np.ptp(desc, axis=0).max() <= 1e-9 * max(float(np.abs(desc).max()), 1e-300):
            raise InputError(f"{mesh.name}: the {descriptor} descriptors are the same at every vertex (SHOT on a "
                             "surface too smooth or too coarse for its support), so they cannot tell its points "
                             "apart; try descriptor=wks")
    return spec_x, spec_y, desc_x, desc_y


def solve_descriptor_nn(source, target, params: DescriptorNNParams, token):
    watch = Stopwatch()
    yield Progress("eigenpairs", 0.0)
    spec_x, spec_y, desc_x, desc_y = _spectra_and_descriptors(source, target, params.n_eigs, params.descriptor,
                                                              params.n_scales, watch)
    token.raise_if_cancelled()
    yield Progress("nearest neighbours", 0.7)
    with watch("assignment"):
        desc_x, desc_y = _standardize(desc_x, desc_y)
        map_xy = nearest_rows(desc_x, desc_y)
        map_yx = nearest_rows(desc_y, desc_x)
    energy = float(np.mean(np.linalg.norm(desc_x - desc_y[map_xy], axis=1)))
    yield Progress("done", 1.0)
    return MatchResult("descriptor-nn", map_xy, map_yx, energy, watch.times,
                       energy_meaning="mean descriptor distance")


register(MethodSpec(
    name="descriptor-nn", label="Descriptor nearest neighbour", inputs=("mesh", "mesh"),
    params=DescriptorNNParams, solve=solve_descriptor_nn, rank=0,
    description="Match every vertex to the vertex with the most similar descriptor. A baseline."))


# ----------------------------------------------------------------------------- functional maps + ZoomOut


#: the ZoomOut schedule (Melzi et al. 2019): the basis size it starts from and the functions added per
#: iteration; also divergence-free's, which zooms out from its flow's map (:mod:`.divergence_free`)
ZOOMOUT_K_INIT, ZOOMOUT_STEP = 35, 5


@dataclass(frozen=True, kw_only=True)
class FmapZoomOutParams:
    descriptor: str = param("wks", label="Descriptor", choices=DESCRIPTOR_KINDS,
                            help="Descriptor whose preservation constrains the functional map.")
    n_descriptors: int = param(20, label="Descriptor functions", low=1, high=200,
                               help="How many descriptor scales (evenly picked from 100) enter the functional map.")
    k_init: int = param(ZOOMOUT_K_INIT, label="Initial basis size", low=2, high=80,
                        help="Size of the functional map solved from the descriptors (solved exactly: its "
                             "(k², k²) normal matrices: 2.4 GB at 80, growing as k⁴).")
    k_final: int = param(100, label="ZoomOut final size", low=2, high=1000,
                         help="ZoomOut upsamples the map from k_init to this spectral size.")
    step: int = param(ZOOMOUT_STEP, label="ZoomOut step", low=1, high=100,
                      help="Basis functions added per ZoomOut iteration.")
    commutativity: float = param(1.0, label="Laplacian commutativity", low=0.0, high=1e6,
                                 help="Weight of the resolvent Laplacian commutativity (Ren et al. 2019), relative "
                                      "to descriptor preservation.")
    descriptor_commutativity: float = param(1.0, label="Descriptor commutativity", low=0.0, high=1e6,
                                            help="Weight of the commutativity with the descriptors' multiplication "
                                                 "operators (Nogneng & Ovsjanikov 2017).")
    orientation: float = param(1.0, label="Orientation term", low=0.0, high=1e6,
                               help="Weight of the commutativity with orientation-preserving operators (Ren et "
                                    "al. 2018): keeps left on left; 0 leaves the map free to mirror.")

    def __post_init__(self):
        if isinstance(self.k_init, int) and isinstance(self.k_final, int) and self.k_init > self.k_final:
            raise ParameterError(f"k_init ({self.k_init}) must not exceed k_final ({self.k_final}): ZoomOut grows "
                                 "the functional map from k_init eigenfunctions to k_final")


#: every n-th descriptor function also gives an orientation operator (they are close neighbours in scale)
ORIENTATION_EVERY = 4


def descriptor_functional_map(source, target, spec_x, spec_y, desc_x, desc_y, k: int,
                              params: FmapZoomOutParams) -> np.ndarray:
    """The ``k × k`` functional map of the standard pipeline, solved exactly.

    Descriptor preservation, resolvent Laplacian commutativity, commutativity
    with the descriptors' multiplication operators and with their
    orientation-preserving operators (:func:`~corrlib.geometry.fmaps.functional_map`).
    """
    phi, psi = spec_x.evecs[:, :k], spec_y.evecs[:, :k]
    mass_x, mass_y = spec_x.mass.diagonal(), spec_y.mass.diagonal()
    coef_x = phi.T @ (mass_x[:, None] * desc_x)
    coef_y = psi.T @ (mass_y[:, None] * desc_y)
    pairs = [(multiplication_operators(phi, mass_x, desc_x), multiplication_operators(psi, mass_y, desc_y))]
    weights = [1.0, params.commutativity, params.descriptor_commutativity]
    if params.orientation > 0:
        pairs.append((orientation_operators(source, phi, desc_x[:, ::ORIENTATION_EVERY]),
                      orientation_operators(target, psi, desc_y[:, ::ORIENTATION_EVERY])))
        weights.append(params.orientation)
    return functional_map(coef_x, coef_y, resolvent_mask(spec_x.evals[:k], spec_y.evals[:k]), pairs, weights)


def _unit_norm_descriptors(desc_x, desc_y, spec_x, spec_y, source, target, kind: str):
    """The descriptor functions scaled to unit M-norm on each shape (the terms then compare shapes of any
    scale and vertex density), without those that vanish on either shape (SHOT on a smooth round surface:
    every histogram bin but a few is empty there); :class:`InputError` where none is left."""
    norm_x = np.sqrt(spec_x.mass.diagonal() @ desc_x ** 2)
    norm_y = np.sqrt(spec_y.mass.diagonal() @ desc_y ** 2)
    keep = (norm_x > 1e-12 * max(float(norm_x.max()), 1e-300)) & (norm_y > 1e-12 * max(float(norm_y.max()), 1e-300))
    if not keep.any():
        raise InputError(f"the {kind} descriptors vanish on {source.name} or {target.name}: nothing for a "
                         "functional map to preserve (try descriptor=wks)")
    return desc_x[:, keep] / norm_x[keep], desc_y[:, keep] / norm_y[keep]


def solve_fmap_zoomout(source, target, params: FmapZoomOutParams, token):
    watch = Stopwatch()
    k_final = min(available_eigenpairs(source, params.k_final, "functional maps"),
                  available_eigenpairs(target, params.k_final, "functional maps"))
    k_init = min(params.k_init, k_final)
    if k_final < params.k_final:  # said, not silently: the result then has a smaller functional map
        yield Progress("functional maps", 0.0, f"ZoomOut up to {k_final} eigenfunctions, not k_final = "
                                               f"{params.k_final}: {source.name} and {target.name} have "
                                               f"{source.n_vertices} and {target.n_vertices} vertices")
    yield Progress("eigenpairs and descriptors", 0.0)
    spec_x, spec_y, desc_x, desc_y = _spectra_and_descriptors(source, target, max(k_final, 100),
                                                              params.descriptor, 100, watch)
    token.raise_if_cancelled()
    with watch("descriptors"):
        pick = np.unique(np.linspace(0, desc_x.shape[1] - 1, params.n_descriptors).round().astype(int))
        desc_x, desc_y = desc_x[:, pick], desc_y[:, pick]
        desc_x, desc_y = _unit_norm_descriptors(desc_x, desc_y, spec_x, spec_y, source, target, params.descriptor)
    yield Progress("functional map", 0.4)
    with watch("fmap"):
        c_yx = descriptor_functional_map(source, target, spec_x, spec_y, desc_x, desc_y, k_init, params)
    with watch("zoomout"):
        phi, psi = spec_x.evecs, spec_y.evecs
        samples_x, samples_y = ZoomOutSamples.of_pair(source, target, spec_x.mass.diagonal(), spec_y.mass.diagonal())
        gen = zoomout(phi, psi, spec_y.mass, c_yx, k_final, params.step, token, samples_x, samples_y)
        while True:
            try:
                k = next(gen)
            except StopIteration as stop:
                map_yx, c_yx = stop.value
                break
            yield Progress("ZoomOut", 0.4 + 0.6 * (k - k_init) / max(k_final - k_init, 1), f"k = {k}")
        # the other direction with the adjoint (C_yx is near-orthogonal for near-isometries)
        map_xy = nearest_rows_through_samples(phi[:, :k_final], psi[:, :k_final] @ c_yx, samples_x, samples_y)
    k = c_yx.shape[0]
    off = c_yx - np.diag(np.diag(c_yx))
    energy = float(np.linalg.norm(c_yx.T @ c_yx - np.eye(k)) / k)
    yield Progress("done", 1.0)
    return MatchResult("fmap-zoomout", map_xy, map_yx, energy, watch.times,
                       energy_meaning="orthogonality defect of C",
                       extras={"c_yx": c_yx, "off_diagonal_norm": float(np.linalg.norm(off)), "k_final": int(k)})


register(MethodSpec(
    name="fmap-zoomout", label="Functional maps + ZoomOut", inputs=("mesh", "mesh"),
    params=FmapZoomOutParams, solve=solve_fmap_zoomout, rank=10,
    description="Functional map from descriptor preservation and commutativity with the Laplacian, the "
                "descriptors and orientation operators, refined by ZoomOut spectral upsampling."))
