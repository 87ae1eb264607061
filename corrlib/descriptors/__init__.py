"""Point descriptors: spectral (HKS, WKS) and SHOT. All return ``(n_vertices, n_dims)`` arrays."""

from __future__ import annotations

import numpy as np

from corrlib.descriptors.spectral import hks, hks_times, wks, wks_energies  # noqa: F401
from corrlib.errors import ParameterError

DESCRIPTOR_KINDS = ("wks", "hks", "shot")


def mesh_descriptors(mesh, kind: str = "wks", *, spectrum=None, n_scales: int = 100) -> np.ndarray:
    """Descriptors of every vertex of a mesh.

    Parameters
    ----------
    mesh : TriMesh
    kind : {"wks", "hks", "shot"}
    spectrum : Spectrum, optional
        Needed for the spectral kinds (computed with 100 eigenpairs if absent).
    n_scales : int
        Scales of HKS/WKS.

    Returns
    -------
    (n, d) float
    """
    if kind in {"wks", "hks"}:
        if spectrum is None:
            from corrlib.geometry.spectrum import mesh_spectrum

            spectrum = mesh_spectrum(mesh, min(100, mesh.n_vertices - 1))
        fn = wks if kind == "wks" else hks
        return fn(spectrum.evals, spectrum.evecs, n_scales)
    if kind == "shot":
        from corrlib.descriptors.shot import shot

        return shot(mesh.vertices, mesh.faces, normals=mesh.vertex_normals)
    raise ParameterError(f"unknown descriptor {kind!r} (use one of {', '.join(DESCRIPTOR_KINDS)})")
