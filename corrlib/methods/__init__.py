"""Correspondence methods. Importing this package registers every method (see :mod:`.registry`)."""

from corrlib.methods import (baselines, contour2d, contour3d, contour_views, divergence_free,  # noqa: F401
                            kernel_matching, product_manifold)  # (importing them registers the methods)
from corrlib.methods.base import MatchResult, make_params, param  # noqa: F401
from corrlib.methods.registry import all_methods, get_method, methods_for, solve, solve_iter  # noqa: F401
