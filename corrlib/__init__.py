"""corrlib: continuous non-rigid shape correspondence (Qt-free library).

What a script needs is importable from here::

    import corrlib
    x, y = corrlib.load_mesh("wolf0.off"), corrlib.load_mesh("wolf1.off")
    result = corrlib.solve("kernel-matching", x, y)

``TriMesh``, ``Contour2D``, ``load_mesh``, ``load_contour``, ``load_shape``,
``solve``, ``MatchResult`` and ``evaluate`` are loaded on first use, so
``import corrlib`` stays light (no NumPy or SciPy);
``corrlib.methods.all_methods()`` lists the registered methods.

Map convention used throughout: ``map_xy[i]`` is the index on shape Y of the
partner of vertex ``i`` of shape X. Laplacians are positive semi-definite in
weak form ``S phi = lambda M phi`` with M-orthonormal eigenvectors.
"""

__version__ = "0.1.0"


def _writable_numba_cache() -> None:
    """Point numba's kernel cache at a temporary folder when the installed package cannot hold it.

    numba caches compiled kernels beside the sources, else in the user's
    cache folder, and raises at import when neither can be written (a
    read-only install run by a user without a writable home).
    """
    import os
    import tempfile

    if "NUMBA_CACHE_DIR" not in os.environ and not os.access(os.path.dirname(os.path.abspath(__file__)), os.W_OK):
        uid = os.getuid() if hasattr(os, "getuid") else "user"
        os.environ["NUMBA_CACHE_DIR"] = os.path.join(tempfile.gettempdir(), f"corrlib-numba-cache-{uid}")


_writable_numba_cache()

from corrlib.errors import (  # noqa: F401
    Cancelled,
    ContourError,
    CorrError,
    FileFormatError,
    InputError,
    MeshError,
    ParameterError,
    SolverError,
)

#: lazily re-exported names -> the module defining them (NumPy and SciPy load with the first of them)
_EXPORTS = {
    "TriMesh": "corrlib.shapes", "Contour2D": "corrlib.shapes",
    "load_mesh": "corrlib.io", "load_contour": "corrlib.io", "load_shape": "corrlib.io",
    "solve": "corrlib.methods", "MatchResult": "corrlib.methods.base", "evaluate": "corrlib.evaluation",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'corrlib' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_EXPORTS])
