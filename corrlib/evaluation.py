"""Evaluation of point-to-point maps with the Princeton protocol (Kim et al. 2011).

For ground-truth rows r, the source vertex ``gt_source[r]`` on X and the
target vertex ``gt_target[r]`` on Y are the same surface point. The error of
a map ``map_xy`` at row r is the geodesic distance on Y between
``map_xy[gt_source[r]]`` and ``gt_target[r]``, divided by ``sqrt(area(Y))``
(default) or the geodesic diameter of Y. With mirrored ground truth
(``gt_target_sym``) the symmetry-aware error is the smaller of the two.

The cumulative error curve gives, for thresholds ``0 .. max_threshold``, the
fraction of rows with error at most the threshold; its area under the curve
is normalised to [0, 1] by the threshold range.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corrlib.errors import InputError, ParameterError
from corrlib.geometry.geodesics import GeodesicSolver, geodesic_diameter
from corrlib.shapes import TriMesh, fits_record

DEFAULT_THRESHOLDS = np.linspace(0.0, 0.25, 101)


@dataclass
class ErrorReport:
    """Per-row errors and summary statistics.

    Attributes
    ----------
    errors : (r,) float
        Normalised geodesic errors.
    errors_sym : (r,) float or None
        Symmetry-aware errors (minimum over ground truth and its mirror).
    normalization : float
        The length the distances were divided by.
    """

    errors: np.ndarray
    errors_sym: np.ndarray | None = None
    normalization: float = 1.0
    thresholds: np.ndarray = field(default_factory=lambda: DEFAULT_THRESHOLDS.copy())

    def summary(self) -> dict:
        """Mean, median, fractions within 0.025 / 0.05 / 0.1 and AUC (and the same, symmetric)."""
        out = _stats(self.errors, self.thresholds)
        if self.errors_sym is not None:
            out.update({f"{k}_sym": v for k, v in _stats(self.errors_sym, self.thresholds).items()})
        return out


def _stats(errors: np.ndarray, thresholds: np.ndarray) -> dict:
    curve = cumulative_curve(errors, thresholds)
    return {
        "mean": float(np.mean(errors)),
        "median": float(np.median(errors)),
        "within_0.025": float(np.mean(errors <= 0.025)),
        "within_0.05": float(np.mean(errors <= 0.05)),
        "within_0.1": float(np.mean(errors <= 0.1)),
        "auc": curve_auc(curve, thresholds),
    }


def cumulative_curve(errors, thresholds=DEFAULT_THRESHOLDS) -> np.ndarray:
    """(t,) float: fraction of errors ``<= thresholds[i]``."""
    e = np.sort(np.asarray(errors, dtype=np.float64))
    return np.searchsorted(e, np.asarray(thresholds), side="right") / max(e.size, 1)


def curve_auc(curve, thresholds=DEFAULT_THRESHOLDS) -> float:
    """Area under a cumulative curve, normalised by the threshold range (1 = perfect)."""
    t = np.asarray(thresholds, dtype=np.float64)
    c = np.asarray(curve, dtype=np.float64)
    return float(np.sum(0.5 * (c[1:] + c[:-1]) * np.diff(t)) / (t[-1] - t[0]))


def _check_indices(name: str, idx, n: int) -> np.ndarray:
    """``idx`` as a 1-D int64 array of indices in ``[0, n)``: whole numbers in a float array (a map read with
    ``np.loadtxt``) are taken, as by :func:`~corrlib.io.vertex_indices` everywhere else."""
    from corrlib.io import vertex_indices

    a = vertex_indices(idx, name)
    if a.ndim != 1:
        raise InputError(f"{name} must be a 1-D array of indices, got shape {a.shape}")
    if a.size and (a.min() < 0 or a.max() >= n):
        raise InputError(f"{name} has indices outside [0, {n - 1}]")
    return a


def geodesic_errors(map_xy, target, gt_source, gt_target, *, gt_target_sym=None, normalize: str = "sqrt_area",
                    method: str = "exact", solver: GeodesicSolver | None = None) -> ErrorReport:
    """Princeton-protocol geodesic errors of a map.

    Parameters
    ----------
    map_xy : (n_x,) int
        Target vertex of each source vertex.
    target : TriMesh
        The shape Y on which distances are measured.
    gt_source : (r,) int
        Source vertices of the ground-truth rows (0-based).
    gt_target : (r,) int
        Their true partners on Y.
    gt_target_sym : (r,) int, optional
        Mirrored partners (left/right symmetry) for the symmetry-aware error.
    normalize : {"sqrt_area", "diameter", "none"}
    method : {"exact", "heat", "graph"}
        Geodesic distance method (see :mod:`corrlib.geometry.geodesics`).
    solver : GeodesicSolver, optional
        Reuse a solver (and its factorisations) across calls.

    Returns
    -------
    ErrorReport
    """
    from corrlib.shapes import TriMesh

    if not isinstance(target, TriMesh):
        raise InputError(f"the target must be the mesh the map points into (a TriMesh: the errors are geodesic "
                         f"distances on it), got {type(target).__name__}")
    n_y = target.n_vertices
    map_xy = _check_indices("map_xy", map_xy, n_y)
    gt_source = _check_indices("gt_source", gt_source, map_xy.shape[0])
    gt_target = _check_indices("gt_target", gt_target, n_y)
    if gt_source.shape != gt_target.shape:
        raise InputError(f"ground truth rows differ: {gt_source.size} source vs {gt_target.size} target")
    if gt_source.size == 0:
        raise InputError("the ground truth is empty")
    if normalize == "sqrt_area":
        norm = float(np.sqrt(target.area))
    elif normalize == "diameter":
        norm = geodesic_diameter(target)
    elif normalize == "none":
        norm = 1.0
    else:
        raise ParameterError(f"unknown normalisation {normalize!r} (use 'sqrt_area', 'diameter' or 'none')")
    solver = solver or GeodesicSolver(target)
    predicted = map_xy[gt_source]
    errors = solver.pair_distances(predicted, gt_target, method=method) / norm
    errors_sym = None
    if gt_target_sym is not None:
        gt_target_sym = _check_indices("gt_target_sym", gt_target_sym, n_y)
        if gt_target_sym.shape != gt_target.shape:
            raise InputError("mirrored ground truth has a different number of rows")
        # The straight line is a lower bound of the geodesic: a mirrored partner farther away in space
        # than the direct error cannot lower it, so only the others are measured.
        chord = np.linalg.norm(target.vertices[predicted] - target.vertices[gt_target_sym], axis=1) / norm
        closer = np.flatnonzero(chord < errors)
        errors_sym = errors.copy()
        if closer.size:
            mirrored = solver.pair_distances(predicted[closer], gt_target_sym[closer], method=method) / norm
            errors_sym[closer] = np.minimum(errors[closer], mirrored)
    return ErrorReport(errors=errors, errors_sym=errors_sym, normalization=norm)


def matched_errors(map_xy, target, gt_source, gt_target, *, gt_target_sym=None,
                   **options) -> tuple[ErrorReport | None, np.ndarray]:
    """:func:`geodesic_errors` of a map that may leave source vertices unmatched (-1, partial matching).

    The ground-truth rows whose source vertex is matched are measured as a map of their own; the others are
    counted, not scored (a partial map is judged by both: its errors where it matches, and how much of the
    truth it leaves out).

    Parameters
    ----------
    map_xy : (n_x,) int
        Target vertex of each source vertex, -1 where unmatched.
    target, gt_source, gt_target, gt_target_sym, **options
        As for :func:`geodesic_errors`.

    Returns
    -------
    report : ErrorReport or None
        The matched rows' errors, in the order of the ground truth; None if no row is matched.
    matched : (r,) bool
        Which ground-truth rows were matched.
    """
    map_xy = np.asarray(map_xy)
    if map_xy.ndim == 1 and np.issubdtype(map_xy.dtype, np.integer) and map_xy.size and map_xy.min() < -1:
        raise InputError(f"map_xy has indices below -1 (-1: unmatched), e.g. {int(map_xy.min())}")
    gt_source = _check_indices("gt_source", gt_source, map_xy.shape[0] if map_xy.ndim == 1 else 0)
    matched = map_xy[gt_source] >= 0
    if not matched.any():
        return None, matched
    rows = [np.asarray(gt_target), None if gt_target_sym is None else np.asarray(gt_target_sym)]
    if any(r is not None and r.shape != gt_source.shape for r in rows):  # before rows are picked by the mask
        raise InputError(f"the ground-truth files differ in their number of rows ({gt_source.size} source rows)")
    # only matched rows are read, so the -1 entries stand in as 0 for the index checks
    report = geodesic_errors(np.maximum(map_xy, 0), target, gt_source[matched], rows[0][matched],
                             gt_target_sym=None if rows[1] is None else rows[1][matched], **options)
    return report, matched


def evaluate(result, target, gt_source, gt_target, **options) -> ErrorReport:
    """Princeton-protocol errors of a method's result (or of a bare map) on the target.

    Parameters
    ----------
    result : MatchResult or (n_x,) int
        A result with ``map_xy``, or the map itself.
    target : TriMesh
    gt_source, gt_target : (r,) int
        Ground-truth rows (see :func:`geodesic_errors`).
    **options
        Passed to :func:`geodesic_errors` (``gt_target_sym``, ``normalize``, ``method``, ``solver``).

    Returns
    -------
    ErrorReport
    """
    import inspect

    known = [name for name, p in inspect.signature(geodesic_errors).parameters.items() if p.kind == p.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ParameterError(f"evaluate: unknown option {unknown[0]!r} (known: {', '.join(known)})")
    map_xy = getattr(result, "map_xy", result)
    if map_xy is None:
        raise InputError(f"the result of {getattr(result, 'method', '?')!r} has no point-to-point map to evaluate")
    matched = (getattr(result, "inputs", None) or {}).get("target", {})
    map_yx = getattr(result, "map_yx", None)
    expected = matched.get("vertices", None if map_yx is None else len(map_yx))
    other_size = expected is not None and getattr(target, "n_vertices", None) not in (None, expected)
    if other_size or (isinstance(target, TriMesh) and not fits_record(target, matched)):
        said = f"{matched['name']!r}, {expected} vertices" if matched.get("name") else f"{expected} vertices"
        why = "" if other_size else (", another shape of as many vertices; the same mesh moved, turned or scaled "
                                     "would be taken")
        raise InputError(f"the result maps onto another target ({said}) than {getattr(target, 'name', 'this')!r} "
                         f"({target.n_vertices} vertices{why}): measure its errors on the target it was computed "
                         f"for")
    return geodesic_errors(map_xy, target, gt_source, gt_target, **options)


#: a map of one surface onto another whose image holds less than this fraction of the target's area has
#: collapsed (every point sent to a few): no correspondence, whatever the method's energy says
COLLAPSED_AREA = 0.01


def image_area_share(map_xy, target) -> float:
    """The share of ``target``'s area that ``map_xy`` ((n_x,) int, -1 unmatched) reaches: the area of the target
    vertices some source vertex is sent to, each vertex holding a third of its faces' areas (1 for a map onto
    every vertex; resolution-free, unlike a count of vertices). NaN without a map."""
    if map_xy is None:
        return float("nan")
    matched = np.asarray(map_xy)
    matched = np.unique(matched[matched >= 0])
    vertex_areas = np.bincount(target.faces.ravel(), np.repeat(target.face_areas / 3.0, 3),
                               minlength=target.n_vertices)
    return float(vertex_areas[matched].sum() / vertex_areas.sum())


def collapse_note(map_xy, source, target, what: str = "the map",
                  advice: str = "the inputs give the method nothing to tell points apart (try another method or "
                                "descriptor)") -> str | None:
    """A warning when a mesh-to-mesh map sends its vertices onto a negligible part of the target (the image's
    vertices hold less than :data:`COLLAPSED_AREA` of its area, each vertex a third of its faces' areas), else
    None. A method can return such a map without failing (descriptors that barely vary on a very regular
    shape make a functional map of rank one); the user is told rather than handed it as a result. Only a map
    from a mesh is judged: a contour's points lie along a curve, which covers no area.

    Parameters
    ----------
    map_xy : (n_x,) int or None
        Target vertex of every source vertex; -1 unmatched.
    source, target : TriMesh or Contour2D
    what, advice : str
        How the map is named, and what the user is advised.
    """
    from corrlib.shapes import TriMesh

    if map_xy is None or not (isinstance(source, TriMesh) and isinstance(target, TriMesh)):
        return None
    matched = np.asarray(map_xy)
    matched = np.unique(matched[matched >= 0])
    if matched.size == 0:
        return f"{what} matches no vertex"
    share = image_area_share(map_xy, target)
    if share >= COLLAPSED_AREA:
        return None
    return (f"{what} has collapsed: its {np.count_nonzero(np.asarray(map_xy) >= 0)} matched vertices land on "
            f"{matched.size} vertices of {target.name}, {100 * share:.2g} % of its area; {advice}")
