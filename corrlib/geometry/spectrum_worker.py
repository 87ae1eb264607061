"""A second process for :func:`corrlib.geometry.spectrum.mesh_spectra`: one eigendecomposition.

``python -m corrlib.geometry.spectrum_worker IN OUT``: reads the stiffness and
mass matrices and ``k`` from the ``.npz`` file ``IN``, writes ``evals`` and
``evecs`` (:func:`corrlib.geometry.spectrum.eigenpairs`) to ``OUT`` and exits
0; any failure exits non-zero with the reason on stderr (the caller then
decomposes the mesh itself and reports its error).
"""

from __future__ import annotations

import sys


def _matrix(data, prefix: str):
    import scipy.sparse as sp

    return sp.csr_matrix((data[f"{prefix}_data"], data[f"{prefix}_indices"], data[f"{prefix}_indptr"]),
                         shape=tuple(data[f"{prefix}_shape"]))


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: python -m corrlib.geometry.spectrum_worker IN.npz OUT.npz", file=sys.stderr)
        return 2
    import numpy as np

    from corrlib.geometry.spectrum import eigenpairs

    try:
        with np.load(argv[0], allow_pickle=False) as data:
            stiffness, mass = _matrix(data, "stiffness"), _matrix(data, "mass")
            k, name = int(data["k"]), str(data["name"])
        evals, evecs = eigenpairs(stiffness, mass, k, name=name)
        with open(argv[1], "wb") as fh:
            np.savez(fh, evals=evals, evecs=evecs)
    except Exception as exc:  # the parent decomposes the mesh itself and raises its own, named error
        print(f"{type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
