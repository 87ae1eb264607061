"""The studio's job factories: every computation the GUI needs runs here, in the worker thread.

Each ``*_job`` function returns a factory ``factory(token) -> Generator[Progress, None, payload]``
for :meth:`app.worker.JobRunner.start`. Payloads hold numpy arrays and corrlib objects only;
the GUI-thread slots turn them into widgets and VTK objects without computing anything.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corrlib.errors import CorrError, FileFormatError, MeshError
from corrlib.progress import Progress
from corrlib.shapes import Contour2D, TriMesh, sketch_outline

#: geodesic distance method of the studio's error figures: the one `corr bench` reports (and faster than the heat
#: method's one solve per ground-truth partner); the heat method where a pinched vertex rules it out
ERROR_GEODESICS = "exact"
FALLBACK_ERROR_GEODESICS = "heat"
#: eigenpairs computed for the pair view's "function" mode (the second one is drawn)
FUNCTION_EIGENPAIRS = 3


#: a word of the Shapes panel longer than this (a long file name) is shortened in its middle: a label wraps only
#: between words, and one long word widened the panel past its edge and cut every line of it
SHAPES_WORD_CHARS = 30


def shortened_words(text: str, longest: int = SHAPES_WORD_CHARS) -> str:
    """``text`` with every word longer than ``longest`` characters shortened in its middle ("…")."""
    keep = (longest - 1) // 2
    return re.sub(rf"\S{{{longest + 1},}}", lambda m: m.group()[:keep] + "…" + m.group()[-keep:], text)


def describe(shape) -> str:
    """One-paragraph summary of a shape for the Shapes dock (runs the mesh validation report)."""
    if isinstance(shape, TriMesh):
        warnings = [f.message for f in shape.report() if f.level == "warning"]
        text = f"{shape.name}: {shape.n_vertices} vertices, {shape.n_faces} faces, area {shape.area:.4g}"
        return text + ("\n  " + "\n  ".join(warnings) if warnings else "\n  validation: no problems")
    if isinstance(shape, Contour2D):
        return f"{shape.name}: contour, {shape.n_points} points, length {shape.length:.4g}"
    return "none"


# ---------------------------------------------------------------------- loading


@dataclass
class LoadedShape:
    """Payload of :func:`load_job`: the shape and its description (validation included)."""

    path: str
    shape: TriMesh | Contour2D
    description: str


def repair_job(path: str, out: str):
    """Job factory: repair the mesh ``path`` into ``out`` (:func:`corrlib.repair.repair_file`, with the file of
    its input vertices beside it) and load the result; returns a :class:`LoadedShape` whose description says
    what was repaired."""

    def factory(_token):
        from corrlib.repair import repair_file

        yield Progress("repairing", -1.0, str(path))
        repaired = repair_file(path, out, what="the repaired mesh")
        yield Progress("loading", -1.0, str(out))
        shape = read_shape(out)
        notes = "; ".join(repaired.notes) or "no repair was needed"
        return LoadedShape(str(out), shape, f"{describe(shape)}\n  repaired from {Path(path).name}: {notes}")

    return factory


def read_shape(path: str) -> TriMesh | Contour2D:
    """A mesh (by suffix) or a contour/silhouette; any failure becomes a :class:`CorrError` naming the file."""
    from corrlib.io import load_shape

    try:
        return load_shape(path)
    except CorrError:
        raise
    except Exception as exc:  # anything unexpected from a third-party reader
        raise FileFormatError(f"{path}: cannot load: {exc}") from exc


def load_job(path: str, as_query: bool = False):
    """Job factory: read and validate ``path``; returns a :class:`LoadedShape`.

    ``as_query`` (the source slot): a planar triangulated sketch is read as the query it draws, its outline
    (:func:`corrlib.shapes.sketch_outline`), as ``corr match-contour`` reads it; a mesh that is not flat stays a
    mesh, and so does a flat closed one (no outline)."""

    def factory(_token):
        yield Progress("loading", -1.0, str(path))
        shape = read_shape(path)
        yield Progress("validating", -1.0, shape.name)
        if as_query and isinstance(shape, TriMesh) and shape.boundary_loops:
            try:
                outline, _loop = sketch_outline(shape)
            except MeshError:  # not flat: the mesh it is (a degenerate flat outline still fails, by name)
                pass
            else:
                return LoadedShape(str(path), outline, f"{describe(outline)}\n  the outline of a planar sketch "
                                                       f"mesh ({shape.n_vertices} vertices), the 2D query")
        return LoadedShape(str(path), shape, describe(shape))

    return factory


# ---------------------------------------------------------------------- methods


@dataclass
class MapErrors:
    """Geodesic errors of a map against ground truth, unmatched vertices left out.

    Attributes
    ----------
    report : ErrorReport or None
        Errors of the ground-truth rows whose source vertex is matched (None if none is).
    per_vertex : (n_x,) float
        Error of every ground-truth source vertex; NaN elsewhere and where unmatched.
    n_unmatched : int
        Ground-truth rows left out because the map leaves their source vertex unmatched (-1).
    n_rows : int
        Ground-truth rows in total.
    note : str
        How the distances were measured where not as `corr bench` measures them (else empty).
    """

    report: object
    per_vertex: np.ndarray
    n_unmatched: int
    n_rows: int
    note: str = ""


def map_errors(map_xy, target: TriMesh, gt_source, gt_target, gt_target_sym=None) -> MapErrors:
    """Errors of ``map_xy`` on the ground-truth rows it matches; unmatched rows are counted, not scored.

    With ``gt_target_sym`` (the mirrored partners of the rows) the report also holds the mirror-accepted
    errors; ``per_vertex`` is always the direct error, so a left/right flip shows in a heat map.
    """
    from corrlib.evaluation import matched_errors

    map_xy = np.asarray(map_xy)
    gt_source = np.asarray(gt_source)
    note = ""
    try:
        report, matched = matched_errors(map_xy, target, gt_source, gt_target, gt_target_sym=gt_target_sym,
                                         method=ERROR_GEODESICS)
    except MeshError as exc:  # exact geodesics refuse a pinched vertex; the heat method's figures are approximate
        report, matched = matched_errors(map_xy, target, gt_source, gt_target, gt_target_sym=gt_target_sym,
                                         method=FALLBACK_ERROR_GEODESICS)
        note = f"errors by the heat method's distances (a few per cent low on short ones): {exc}"
    per_vertex = np.full(map_xy.shape[0], np.nan)
    if report is not None:
        per_vertex[gt_source[matched]] = report.errors
    return MapErrors(report, per_vertex, int(np.count_nonzero(~matched)), int(gt_source.size), note)


def source_function(source: TriMesh) -> np.ndarray:
    """(n_x,) the source's second Laplace-Beltrami eigenfunction (the pair view's "function" mode)."""
    from corrlib.geometry.spectrum import mesh_spectrum

    return np.asarray(mesh_spectrum(source, FUNCTION_EIGENPAIRS).evecs[:, 1])


def sequence_options(result, source: TriMesh, target: TriMesh) -> dict[str, tuple]:
    """Every motion the sequence view offers for a result, the default first: ``kind -> (positions,
    description)`` with kind ``"flow"`` (the method's own deformation, where it has one), ``"rigid"`` (the
    as-rigid-as-possible interpolation through its map) and ``"linear"`` (:func:`corrlib.morph.sequence_positions`).
    Built in the worker: the rigid interpolation factorises a Poisson system, too slow for the GUI thread on a
    fine mesh. A further motion that cannot be built (a named :class:`CorrError`) is left out of the choice."""
    from corrlib.methods.divergence_free import SEQUENCE_T_MAX
    from corrlib.morph import describe_sequence, sequence_kind, sequence_positions

    # "auto" first (what the method itself offers), then the interpolations through the map that it is not
    asked = ("auto", "rigid", "linear") if result.map_xy is not None else ("auto",)
    kinds = {}
    for interpolation in asked:
        kinds.setdefault(sequence_kind(result, interpolation), interpolation)
    options = {}
    for kind, interpolation in kinds.items():
        try:
            options[kind] = (sequence_positions(result, source, target, t_max=SEQUENCE_T_MAX,
                                                interpolation=interpolation), describe_sequence(result, interpolation))
        except CorrError:
            if not options:  # the default one: its error is the job's, as before there was a choice
                raise
    return options


@dataclass
class MethodOutcome:
    """Payload of :func:`method_job`: the result and everything the views need to show it.

    Attributes
    ----------
    result : MatchResult
    source, target
        The shapes the method ran on (a result is shown only if they are still loaded).
    errors : MapErrors or None
        With ground truth on a target mesh and a vertex map.
    function : (n_x,) float or None
        Source function for the pair view (see :func:`source_function`).
    n_unmatched : int
        Source vertices the map leaves unmatched (-1).
    note : str
        What the log says of the outcome (else empty): why the errors are missing although ground truth was
        given, or how they were measured where not as `corr bench` measures them, and how much the default
        motion's last frame folds (:func:`motion_note`).
    map_file : str or None
        The file of a map read by :func:`map_job` (None: a method's result).
    sequences : dict or None
        The motions the sequence view offers (:func:`sequence_options`): kind -> ``(positions, description)``,
        ``positions(t) -> (n_x, 3)``, the default first (the flow integrated up to
        :data:`~corrlib.methods.divergence_free.SEQUENCE_T_MAX` for a divergence-free result, else the
        as-rigid-as-possible interpolation through the map).
    """

    result: object
    source: object = None
    target: object = None
    errors: MapErrors | None = None
    function: np.ndarray | None = None
    n_unmatched: int = 0
    note: str = ""
    sequences: dict | None = None
    map_file: str | None = None

    @property
    def report(self):
        """The :class:`~corrlib.evaluation.ErrorReport` of the matched rows, or None."""
        return None if self.errors is None else self.errors.report


def method_job(name: str, source, target, params, gt=None, *, view_data: bool = True):
    """Job factory: run method ``name``, then its error report (with ``gt``: source rows, target rows and
    optionally the target's mirrored rows or None) and, with
    ``view_data``, the pair view's source function; returns a :class:`MethodOutcome`."""
    from corrlib.methods import solve_iter

    def factory(token):
        result = yield from solve_iter(name, source, target, params, token)
        return (yield from _outcome(result, source, target, gt, view_data))

    return factory


def map_job(path, source: TriMesh, target: TriMesh, gt=None, *, view_data: bool = True):
    """Job factory: a map read from a file (one 0-based target index per source vertex, or a result's .npz),
    shown as a method's result is (:func:`method_job`); the reverse map for the colour transfer is the nearest
    image of every target vertex (:func:`corrlib.neighbours.reverse_map`). Returns a :class:`MethodOutcome`."""

    def factory(token):
        from corrlib.io import check_map_record, load_map
        from corrlib.methods.base import MatchResult
        from corrlib.neighbours import reverse_map

        yield Progress("reading the map", -1.0, str(path))
        map_xy = load_map(path, n_target=target.n_vertices, n_source=source.n_vertices, allow_unmatched=True)
        check_map_record(path, source, target)
        result = MatchResult(f"the map {Path(path).name}", map_xy, reverse_map(map_xy, target.vertices))
        outcome = yield from _outcome(result, source, target, gt, view_data)
        outcome.map_file = str(path)
        return outcome

    return factory


def _outcome(result, source, target, gt, view_data: bool):
    """The :class:`MethodOutcome` of a result (a generator): errors against ``gt``, and with ``view_data`` the
    pair view's source function and the sequence."""
    outcome = MethodOutcome(result, source, target)
    map_xy = result.map_xy
    if map_xy is not None:
        outcome.n_unmatched = int(np.count_nonzero(np.asarray(map_xy) < 0))
    if gt is not None and map_xy is not None and isinstance(target, TriMesh):
        yield Progress("geodesic errors", -1.0, f"{np.asarray(gt[0]).size} ground-truth rows")
        try:
            outcome.errors = map_errors(map_xy, target, gt[0], gt[1], gt[2] if len(gt) > 2 else None)
            outcome.note = outcome.errors.note
        except CorrError as exc:  # a bad ground truth must not lose the result
            outcome.note = f"no error figures: {exc}"
    if view_data and isinstance(source, TriMesh) and isinstance(target, TriMesh):
        yield Progress("source function", -1.0, "eigenfunction for the pair view")
        outcome.function = source_function(source)
        yield Progress("sequence", -1.0, "positions between the poses")
        outcome.sequences = sequence_options(result, source, target)
        folds = motion_note(result, source, target, outcome.sequences)
        outcome.note = "; ".join(filter(None, [outcome.note, folds]))
    return outcome


def motion_note(result, source: TriMesh, target: TriMesh, sequences: dict) -> str | None:
    """What the log says of the default motion (the first of ``sequences``, :func:`sequence_options`): for a
    motion through the map, the share of faces its last frame turns over (:func:`corrlib.morph.last_frame_note`);
    None for a flow, which never folds."""
    from corrlib.morph import last_frame_note

    kind, (positions, _description) = next(iter(sequences.items()))
    return last_frame_note(result, source, target, [1.0], [positions(1.0)], kind)


def contour_reading(result) -> str:
    """One log line on how a 2D-to-3D match read its query: the energy's meaning and, for ``contour3d``, the
    view it took with the two measures that decided it (so that a wrong view can be forced); a second line
    warns when the matched curve is short enough to have collapsed (:func:`~corrlib.methods.contour3d.short_curve_note`)."""
    line = f"{result.method}: {result.energy_meaning or 'energy'} {result.energy:.6g}"
    extras = result.extras or {}
    if "view" in extras:
        overruled = extras["view"] == "front" and extras.get("mesh_seen_from_side") is False
        line += (f"; read as a {extras['view']} view (mirror asymmetry {extras.get('asymmetry', float('nan')):.3f}, "
                 f"intrinsic asymmetry {extras.get('intrinsic_asymmetry', float('nan')):.3f}"
                 + ("; a side view by the outline, but the target is not thinnest across its plane of symmetry"
                    if overruled else "")
                 + "; the parameter view=side or view=front forces one)")
    if extras.get("contour_points", 0) < extras.get("contour_points_asked", 0):
        line += (f"; the contour was matched at {extras['contour_points']} points instead of "
                 f"{extras['contour_points_asked']}: the target's mean edge is longer than the finer step, "
                 "which would press the curve short")
    from corrlib.methods.contour3d import remeshing_note, short_curve_note

    note = remeshing_note(extras)
    line += f"; {note}" if note else ""
    warning = short_curve_note(extras)
    return line + (f"\nwarning: {warning}" if warning else "")
