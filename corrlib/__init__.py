"""corrlib: continuous non-rigid shape correspondence (Qt-free library).

What a script needs is importable from here::

    import corrlib
    x, y = corrlib.load_mesh("wolf0.off"), corrlib.load_mesh("wolf1.off")
    result = corrlib.solve("kernel-matching", x, y)

The names a script uses are loaded on first use, so ``import corrlib`` stays
light (no NumPy or SciPy): shapes and files (``TriMesh``, ``Contour2D``,
``load_mesh``, ``load_contour``, ``load_shape``, ``load_vts`` for ground truth,
``load_map``), matching (``solve``, ``all_methods``, ``make_params``,
``MatchResult``, ``InitialMatch``, ``evaluate``), retrieval (``retrieve``, a
generator: ``run(retrieve(...))`` returns the ranked hits; ``mesh_files``)
and sequences between two poses (``frame_times``, ``frame_positions``,
``export_sequence``). Every submodule is reached the same way
(``corrlib.methods.all_methods()`` lists the registered methods).

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
    "load_mesh": "corrlib.io", "load_contour": "corrlib.io", "load_shape": "corrlib.io", "load_vts": "corrlib.io",
    "load_map": "corrlib.io",
    "solve": "corrlib.methods", "all_methods": "corrlib.methods", "make_params": "corrlib.methods",
    "MatchResult": "corrlib.methods.base", "InitialMatch": "corrlib.methods.base",
    "evaluate": "corrlib.evaluation",
    "retrieve": "corrlib.retrieval", "mesh_files": "corrlib.retrieval",
    "frame_positions": "corrlib.morph", "frame_times": "corrlib.morph", "export_sequence": "corrlib.morph",
    "run": "corrlib.progress",
}


def __getattr__(name: str):
    """The lazily exported names, and the submodules on first use (``corrlib.methods.all_methods()`` after a
    bare ``import corrlib``, as a package's submodules are reached in NumPy or SciPy)."""
    import importlib

    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    if name in _submodules():
        return importlib.import_module(f"corrlib.{name}")
    raise AttributeError(f"module 'corrlib' has no attribute {name!r}")


def _submodules() -> set[str]:
    """The names of the package's modules and subpackages (``methods``, ``io``, ``retrieval``, ``morph`` …)."""
    import pkgutil

    return {info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_")}


def __dir__():
    return sorted({*globals(), *_EXPORTS, *_submodules()})
