"""Drawn outlines scored by landmarks (``corr bench-contour --drawn FOLDER``).

A cut query (:mod:`corrlib.contour_bench`) is the mesh's own outline; a user draws something else: other
proportions, corners, a few clicked points. Such a drawing has no point-wise ground truth on a mesh, but
its tips can be named. Layout:

* a folder of drawings, ``NAME.txt`` (or any contour file :func:`corrlib.io.load_contour` reads) with
  ``NAME.landmarks`` beside it, one landmark per line: ``label x y`` in the drawing's coordinates;
* in a dataset, ``<mesh>.landmarks`` beside a mesh: ``label vertex`` (0-based).

A drawing is matched to every mesh of the datasets that names at least one of its labels. A label given
more than once is a set of interchangeable landmarks: a side view cannot tell the near paw from the far
one, a front view the left hand from the right. The **landmark error** of a drawn landmark is the geodesic
distance (exact, divided by √area of the mesh) from the vertex matched to the contour point nearest it to
the nearest true landmark of its label.

**Redrawn variants** (``redraws``): the same drawing with every point moved at random by
:data:`REDRAW_JITTER` of its size (Gaussian, seeded; a variant that crosses itself is drawn again), as the
user's hand would draw it another time. A match that holds only for one exact set of corners is not a
result a user can count on, so the benchmark reports the mean landmark error over the variants and the
worst of them beside the error of the drawing as given.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corrlib.bench import failure_fields, load_dataset, path_search_fields
from corrlib.errors import ContourError, FileFormatError, InputError
from corrlib.outputs import lost_working_folder
from corrlib.shapes import Contour2D

#: suffix of a landmark file, beside its drawing (``NAME.landmarks``) or its mesh (``<mesh>.landmarks``)
LANDMARKS_SUFFIX = ".landmarks"
#: how far a redrawn variant moves each point (standard deviation, a fraction of the drawing's size)
REDRAW_JITTER = 0.01
#: attempts at a redrawn variant that does not cross itself
REDRAW_ATTEMPTS = 100
#: farthest a drawing's landmark may lie from its outline, a fraction of the drawing's size: a landmark off the
#: outline (other units, a typing error) would otherwise be scored silently at whatever outline point is nearest
LANDMARK_TOLERANCE = 0.05
#: points of the outline the tolerance is checked against
OUTLINE_SAMPLES = 4000
#: most redrawn variants per drawing (each is a full match; more would run for hours and say no more)
MAX_REDRAWS = 100


def read_landmarks(path, *, n_vertices: int | None = None) -> list[tuple[str, object]]:
    """The landmarks of a file: ``label x y`` per line for a drawing (``n_vertices`` None), ``label vertex``
    for a mesh of ``n_vertices`` vertices. Blank lines and ``#`` comments are skipped.

    Returns
    -------
    list of (label, (2,) float array or int)

    Raises
    ------
    FileFormatError
        The file is missing or unreadable, a line has the wrong number of fields or values that are not
        numbers (finite coordinates, whole vertex numbers in range), or no landmark is given.
    """
    from corrlib.io import read_text

    text = read_text(path, "landmark")
    expected = "label x y" if n_vertices is None else "label vertex"
    out = []
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        if len(fields) != len(expected.split()):
            raise FileFormatError(f"{path}, line {number}: expected '{expected}', got {line.strip()!r}")
        out.append((fields[0], _landmark_value(fields[1:], n_vertices, f"{path}, line {number}")))
    if not out:
        raise FileFormatError(f"{path}: no landmarks (one '{expected}' per line)")
    return out


def _landmark_value(fields: list[str], n_vertices: int | None, where: str):
    if n_vertices is None:
        try:
            point = np.array([float(v) for v in fields])
        except ValueError:
            point = np.array([np.nan])
        if not np.all(np.isfinite(point)):
            raise FileFormatError(f"{where}: the coordinates must be finite numbers, got {' '.join(fields)!r}")
        return point
    try:
        vertex = int(fields[0])
    except ValueError:
        raise FileFormatError(f"{where}: the vertex must be a whole number, got {fields[0]!r}") from None
    if not 0 <= vertex < n_vertices:
        raise FileFormatError(f"{where}: vertex {vertex} is out of range for a mesh of {n_vertices} vertices "
                              "(0-based)")
    return vertex


@dataclass
class DrawnQuery:
    """A drawing with named landmarks.

    Attributes
    ----------
    name : str
    contour_path : Path
    landmarks : list of (label, (2,) float)
    """

    name: str
    contour_path: Path
    landmarks: list

    @property
    def labels(self) -> set[str]:
        return {label for label, _ in self.landmarks}


def drawn_queries(folder) -> list[DrawnQuery]:
    """The drawings of a folder that have a landmark file (``NAME.landmarks`` beside ``NAME.<ext>``); each
    drawing and its landmarks are read here, so that a malformed one is a named error before any matching."""
    from corrlib.io import load_contour

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder (expected drawings NAME.txt with NAME{LANDMARKS_SUFFIX})"
                         f"{lost_working_folder(folder)}")
    found = []
    for marks in sorted(folder.glob(f"*{LANDMARKS_SUFFIX}")):
        name = marks.name[:-len(LANDMARKS_SUFFIX)]
        drawings = [p for p in sorted(folder.glob(f"{name}.*")) if p != marks and p.is_file()]
        if len(drawings) != 1:
            raise FileFormatError(f"{marks}: expected one drawing {name}.<ext> beside it, found "
                                  f"{len(drawings)}{': ' + ', '.join(p.name for p in drawings) if drawings else ''}")
        landmarks = read_landmarks(marks)
        check_on_outline(landmarks, load_contour(drawings[0]), marks)
        found.append(DrawnQuery(name, drawings[0], landmarks))
    if not found:
        raise FileFormatError(f"{folder}: no drawings with landmarks (NAME{LANDMARKS_SUFFIX} beside NAME.txt)")
    return found


def check_on_outline(landmarks: list, contour: Contour2D, path) -> None:
    """Raise a :class:`FileFormatError` naming the first landmark farther than :data:`LANDMARK_TOLERANCE` of the
    drawing's size (the larger side of its bounding box) from its outline."""
    outline = contour.resample(OUTLINE_SAMPLES).points
    size = float(np.ptp(contour.points, axis=0).max())
    for label, point in landmarks:
        gap = float(np.linalg.norm(outline - point, axis=1).min())
        if gap > LANDMARK_TOLERANCE * size:
            raise FileFormatError(f"{path}: landmark {label} ({point[0]:g}, {point[1]:g}) lies {gap:.3g} from the "
                                  f"outline of {contour.name}, more than {LANDMARK_TOLERANCE:.0%} of its size "
                                  f"({size:.3g}); landmarks are points on the outline, in its coordinates")


def redrawn(contour: Contour2D, rng: np.random.Generator) -> Contour2D:
    """The drawing with every point moved by a Gaussian of :data:`REDRAW_JITTER` of its size (the larger
    side of its bounding box), drawn again until it does not cross itself."""
    size = float(np.ptp(contour.points, axis=0).max())
    for _ in range(REDRAW_ATTEMPTS):
        points = contour.points + REDRAW_JITTER * size * rng.standard_normal(contour.points.shape)
        try:
            return Contour2D(points, name=contour.name, min_points=3)
        except ContourError:
            continue
    raise ContourError(f"{contour.name}: no redrawn variant that does not cross itself in {REDRAW_ATTEMPTS} "
                       "attempts (its gaps are narrower than the jitter)")


def landmark_errors(result, target, drawn: list, truth: dict, solver) -> list[tuple[str, float]]:
    """(label, error) of every drawn landmark whose label the mesh names (the module's definition).

    Parameters
    ----------
    result : MatchResult
        A ``contour3d`` result (its path's contour points are in the drawing's coordinates).
    target : TriMesh
    drawn : list of (label, (2,) float)
    truth : dict
        label -> list of the mesh's landmark vertices.
    solver : GeodesicSolver
        The target's.
    """
    points, map_xy = result.path.contour_points, np.asarray(result.map_xy)
    scale = float(np.sqrt(target.area))
    out = []
    for label, point in drawn:
        if label not in truth:
            continue
        matched = int(map_xy[np.linalg.norm(points - point, axis=1).argmin()])
        candidates = np.asarray(truth[label])
        distances = solver.pair_distances(np.full(candidates.size, matched), candidates)  # exact geodesics
        out.append((label, float(distances.min()) / scale))
    return out


def redrawn_errors(contour: Contour2D, target, drawn: list, truth: dict, solver, params: dict, redraws: int,
                   seed: int, method: str = "contour3d") -> list[float]:
    """The mean landmark error of each of ``redraws`` redrawn variants of ``contour`` (:func:`redrawn`, from
    the seed ``seed``) matched to ``target`` by the 2D-to-3D ``method`` with its parameters ``params``."""
    from corrlib.methods import solve

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(redraws):
        result = solve(method, redrawn(contour, rng), target, **params)
        out.append(float(np.mean([e for _, e in landmark_errors(result, target, drawn, truth, solver)])))
    return out


def match_drawn_query(query: DrawnQuery, target_path, landmarks_path, params: dict, *, redraws: int = 0,
                      seed: int = 0, picture: str | None = None, method: str = "contour3d") -> dict:
    """Match a drawing (and ``redraws`` redrawn variants) to a mesh with landmarks by the 2D-to-3D ``method``
    (its parameters ``params``); one benchmark row.

    Returns
    -------
    dict
        ``landmark_error`` (mean over the scored landmarks of the drawing as given), ``landmark_within_01``,
        ``worst_landmark`` (its label and error), ``redraw_error`` and ``redraw_worst`` (mean and largest
        landmark error over the variants; NaN without), ``scored_landmarks``, ``distinct_vertices``, energy,
        gap, optimality and time of the drawing as given; ``status`` ``"ok"`` or ``"failed"`` with ``error``.
    """
    from corrlib.geometry.geodesics import GeodesicSolver
    from corrlib.io import load_contour, load_mesh
    from corrlib.methods import solve
    from corrlib.retrieval import class_of

    row = {"query": query.name, "target": Path(target_path).stem, "plane": "drawn", "self": False,
           "other_class": class_of(query.contour_path) != class_of(target_path), "status": "ok", "error": ""}
    try:
        target = load_mesh(target_path)
        truth = {}
        for label, vertex in read_landmarks(landmarks_path, n_vertices=target.n_vertices):
            truth.setdefault(label, []).append(vertex)
        solver = GeodesicSolver(target)
        contour = load_contour(query.contour_path)
        start = time.perf_counter()
        result = solve(method, contour, target, **params)
        seconds = time.perf_counter() - start
        errors = landmark_errors(result, target, query.landmarks, truth, solver)
        if not errors:
            raise InputError(f"{query.name} and {row['target']} name no landmark in common")
        values = np.array([e for _, e in errors])
        worst = errors[int(values.argmax())]
        variants = redrawn_errors(contour, target, query.landmarks, truth, solver, params, redraws, seed, method)
        path = np.asarray(result.path.vertices)
        row.update(landmark_error=float(values.mean()), landmark_within_01=float(np.mean(values <= 0.1)),
                   worst_landmark=f"{worst[0]} {worst[1]:.3f}", scored_landmarks=len(errors),
                   redraw_error=float(np.mean(variants)) if variants else float("nan"),
                   redraw_worst=float(np.max(variants)) if variants else float("nan"), redraws=redraws,
                   **path_search_fields(result, seconds))
        if picture is not None:
            from corrlib.plotting import save_contour_match

            save_contour_match(picture, result.path.contour_points, target, path, result.path.contour_index,
                               title=f"{query.name} -> {row['target']}: landmark error {values.mean():.3f}")
    except Exception as exc:  # a failing match is recorded; the others go on
        row.update(failure_fields(exc))
    return row


@dataclass
class DrawnJob:
    query: DrawnQuery
    target: Path
    landmarks: Path


def drawn_jobs(datasets, folders) -> list[DrawnJob]:
    """Every drawing of ``folders`` against every mesh of ``datasets`` whose landmark file names one of its
    labels (the mesh files are read and their landmarks checked here, before any matching)."""
    from corrlib.io import load_mesh

    queries = [q for folder in folders for q in drawn_queries(folder)]
    if not queries:
        return []
    jobs = []
    for folder in datasets:
        data = load_dataset(folder, require_pairs=False)
        for name, path in data.shapes.items():
            marks = path.with_name(f"{name}{LANDMARKS_SUFFIX}")
            if marks.is_file():
                labels = {label for label, _ in read_landmarks(marks, n_vertices=load_mesh(path).n_vertices)}
                jobs += [DrawnJob(q, path, marks) for q in queries if q.labels & labels]
    if not jobs:
        raise InputError(f"no mesh of {', '.join(str(d) for d in datasets)} has landmarks "
                         f"(<mesh>{LANDMARKS_SUFFIX}, 'label vertex' per line) with the drawings' labels "
                         f"({', '.join(sorted(set().union(*(q.labels for q in queries))))})")
    return jobs


def drawn_summary(rows: list[dict]) -> dict:
    """Means over the drawn rows that ran (and how many failed): ``{"all" | "same class" | "other class":
    {...}}`` (a drawing's class is its name without a trailing number, as a mesh's)."""
    return {"all": _drawn_block(rows), "same class": _drawn_block([r for r in rows if not r["other_class"]]),
            "other class": _drawn_block([r for r in rows if r["other_class"]])}


def _drawn_block(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["status"] == "ok"]
    if not ok:
        return {"queries": len(rows), "failed": len(rows)}
    col = lambda key: np.array([r[key] for r in ok], dtype=np.float64)  # noqa: E731
    redrawn_rows = [r for r in ok if r["redraws"]]
    return {"queries": len(rows), "failed": len(rows) - len(ok), "landmark_error": float(col("landmark_error").mean()),
            "worst_landmark_error": float(col("landmark_error").max()),
            "landmark_within_01": float(col("landmark_within_01").mean()),
            "redraw_error": float(np.mean([r["redraw_error"] for r in redrawn_rows])) if redrawn_rows else None,
            "redraw_worst": float(np.max([r["redraw_worst"] for r in redrawn_rows])) if redrawn_rows else None,
            "optimal": int(sum(r["optimal"] for r in ok)),
            "median_seconds": float(np.median(col("seconds"))), "max_seconds": float(col("seconds").max())}


def drawn_markdown(summary: dict, rows: list[dict]) -> str:
    """The drawn rows and their summary as Markdown tables."""
    s = summary
    fmt = lambda v: "–" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v:.3f}"  # noqa: E731
    lines = ["| drawings | n | failed | landmark error | worst | within 0.1 | redrawn: mean | redrawn: worst | "
             "optimal | median s | max s |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, b in s.items():
        if "landmark_error" in b:
            lines.append(f"| {name} | {b['queries']} | {b['failed']} | {b['landmark_error']:.3f} | "
                         f"{b['worst_landmark_error']:.3f} | {b['landmark_within_01']:.2f} | "
                         f"{fmt(b['redraw_error'])} | {fmt(b['redraw_worst'])} | {b['optimal']} | "
                         f"{b['median_seconds']:.2f} | {b['max_seconds']:.2f} |")
        elif b["queries"]:
            lines.append(f"| {name} | {b['queries']} | {b['failed']} | | | | | | | | |")
    lines += ["", "| drawing | target | landmark error | worst landmark | within 0.1 | redrawn: mean | "
                  "redrawn: worst | distinct vertices | energy | s | error |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['query']} | {r['target']} | | | | | | | | | {r['error']} |")
            continue
        lines.append(f"| {r['query']} | {r['target']} | {r['landmark_error']:.3f} | {r['worst_landmark']} | "
                     f"{r['landmark_within_01']:.2f} | {fmt(r['redraw_error'])} | {fmt(r['redraw_worst'])} | "
                     f"{r['distinct_vertices']} | {r['energy']:.4g} | {r['seconds']:.2f} | |")
    return "\n".join(lines) + "\n"
