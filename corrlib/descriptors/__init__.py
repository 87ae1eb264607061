"""Point descriptors: spectral (HKS, WKS) and SHOT. All return ``(n_vertices, n_dims)`` arrays."""

from __future__ import annotations

import numpy as np

from corrlib.descriptors.spectral import hks, hks_times, wks, wks_energies  # noqa: F401
from corrlib.errors import ParameterError

DESCRIPTOR_KINDS = ("wks", "hks", "shot")


def mesh_descriptors(mesh, kind: str = "wks", *, spectrum=None, n_scales: int = 100,
                     use_cache: bool = True) -> np.ndarray:
    """Descriptors of every vertex of a mesh, cached on disk by mesh content.

    Parameters
    ----------
    mesh : TriMesh
    kind : {"wks", "hks", "shot"}
    spectrum : Spectrum, optional
        Needed for the spectral kinds (computed with 100 eigenpairs if absent).
    n_scales : int
        Scales of HKS/WKS.
    use_cache : bool
        Read and write the on-disk cache (:mod:`corrlib.cache`); the key holds
        the mesh content, the kind and its parameters (and, for HKS/WKS, the
        eigenvalues used), so a collection is described once.

    Returns
    -------
    (n, d) float
    """
    from corrlib import cache

    if kind not in DESCRIPTOR_KINDS:
        raise ParameterError(f"unknown descriptor {kind!r} (use one of {', '.join(DESCRIPTOR_KINDS)})")
    if kind in {"wks", "hks"} and spectrum is None:
        from corrlib.geometry.spectrum import available_eigenpairs, mesh_spectrum

        spectrum = mesh_spectrum(mesh, available_eigenpairs(mesh, 100, f"{kind.upper()} descriptors"))
    if kind == "shot":
        key = cache.make_key("descriptor-v1", mesh.content_hash, kind)
    else:
        evals_hash = cache.make_key(np.ascontiguousarray(spectrum.evals, dtype="<f8").tobytes().hex())
        key = cache.make_key("descriptor-v1", mesh.content_hash, kind, n_scales, evals_hash)
    if use_cache:
        entry = cache.load("descriptors", key, {"values": cache.Array("f", (mesh.n_vertices, None))})
        if entry is not None:
            return entry["values"]
    if kind == "shot":
        from corrlib.descriptors.shot import shot

        values = shot(mesh.vertices, mesh.faces, normals=mesh.vertex_normals)
    else:
        fn = wks if kind == "wks" else hks
        values = fn(spectrum.evals, spectrum.evecs, n_scales)
    if use_cache:
        cache.store("descriptors", key, {"values": values})
    return values
