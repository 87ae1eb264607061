"""corrlib: continuous non-rigid shape correspondence (Qt-free library).

Map convention used throughout: ``map_xy[i]`` is the index on shape Y of the
partner of vertex ``i`` of shape X. Laplacians are positive semi-definite in
weak form ``S phi = lambda M phi`` with M-orthonormal eigenvectors.
"""

__version__ = "0.1.0"

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
from corrlib.shapes import Contour2D, TriMesh  # noqa: F401
