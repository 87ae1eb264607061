"""2D-to-3D benchmark with ground truth: plane-section queries (thesis §7.6), ``corr bench-contour``.

A query is built from a mesh as in the thesis: the mesh is cut with a plane
through its centroid, the longest section loop is kept and its in-plane
coordinates are the 2D contour. Every point of that contour lies on a mesh
edge, so its ground-truth vertex on the mesh it was cut from is known; the
ground truth is carried to the other meshes of the class through the
dataset's correspondences (``.vts`` rows or identical connectivity, the
layouts of :func:`corrlib.bench.load_dataset`).

Three section planes are offered:

* ``main``: spanned by the two principal axes of largest variance (normal:
  the axis of smallest variance);
* ``symmetry``: the principal plane across which the mesh is most nearly
  mirror-symmetric (smallest mean distance from the reflected vertices to the
  surface's vertices; for bilateral shapes the sagittal plane). Where it is
  the ``main`` plane (most quadrupeds) the query is skipped, not counted twice;
* ``cross``: spanned by the first and third principal axes (for a quadruped
  the horizontal section of the torso).

and two silhouettes, the queries a user draws:

* ``silhouette``: the outline of the orthographic projection onto the
  ``main`` plane (a side view, rendered at 400 pixels); the ground truth of
  an outline point are the vertices that project onto it, the nearest and
  the farthest from the viewer (a silhouette cannot tell the near side of
  the rim from the far side), and the nearer of the two is scored;
* ``top``: the same along the axis of middle variance (up: the first axis;
  a quadruped seen from above, a standing person from the side).

A dataset folder may also hold maps between shapes of different classes,
one 0-based target vertex per line for every source vertex, named
``<source>__<target>.txt`` or ``<source>2<target>`` (as the Sumner lion → cat
map is shipped); a name may be a shape or a class with a single shape. Such
a pair is matched with that (possibly approximate) ground truth too.

**Drawn sketches with part labels** (``sketches``: folders in the layout of
the CVPR 2016 sketches, ``NAME_contour.txt`` — the outline — with
``NAME.off``, the planar triangulated sketch, and ``NAME_segmentation.txt``,
one part label per sketch vertex, 0 = unlabelled). Such a query has no
point-wise ground truth on a mesh, only parts: it is matched to every mesh
of the datasets that carries part labels in the same vocabulary
(``<mesh>_segmentation.txt``, one label per vertex), and scored by the
**part agreement**, the share of the contour points labelled on both sides
whose matched vertex carries the point's label (mirror accepted where the
target has a ``.sym.vts``: the label of the matched vertex's mirror
partner). The labels are never given to the solver.

**Drawings with landmarks** (``drawings``): outlines a user drew, with named tips (nose, paws, hands…)
matched to every mesh that names them, scored by the geodesic error at the landmarks, and over redrawn
variants of each drawing (:mod:`corrlib.landmark_bench`).

The length of the ground-truth curve on another pose is the section's length
scaled by the square root of the area ratio (the deformations are nearly
isometric; a polygon through the transferred ground-truth vertices would
zig-zag and overstate it).

Every query is matched to the mesh it was cut from and to the other meshes of
its class. Per match: mean geodesic error / √area and the fractions within
0.05 and 0.1; **coverage**, the length of the matched closed curve on the
mesh divided by the length of the ground-truth curve (a collapsed optimum has
a small coverage); the share of the ground-truth points **reached**, within 0.05 √area of the matched curve
(a curve crowded into one part of the shape that wiggles to the truth's length passes the coverage, not
this); the number of distinct vertices the curve visits; the view
(side or front) and the shape model the solver read the query as (CSV);
energy, optimality gap and runtime. Where the target has a mirrored ground truth
(``<target>.sym.vts`` next to its ``.vts``), the **mirror-accepted** mean
error is the smaller of the mean errors against the ground truth and against
its left–right mirror image: a view across the plane of symmetry (a person
from the front) cannot tell left from right, so both readings are correct.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from corrlib.bench import checked_ground_truth, csv_cell, failure_fields, load_dataset, path_search_fields
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.sections import SilhouetteProjection, principal_frame
from corrlib.landmark_bench import MAX_REDRAWS, drawn_jobs, drawn_markdown, drawn_summary, match_drawn_query
from corrlib.outputs import lost_working_folder
from corrlib.shapes import Contour2D, TriMesh

PLANES = ("main", "symmetry", "cross")
SILHOUETTES = ("silhouette", "top")
QUERY_KINDS = PLANES + SILHOUETTES
SILHOUETTE_RESOLUTION = 400
DEFAULT_PLANES = ("main", "symmetry", "silhouette")
COLLAPSE_COVERAGE = 0.7  # a matched curve shorter than this fraction of the ground truth counts as collapsed
#: a ground-truth point within this geodesic distance (per √area) of the matched curve counts as reached (the
#: benchmark's first error threshold)
REACHED_DISTANCE = 0.05


@dataclass
class CutQuery:
    """A plane-section query with point-wise ground truth on the mesh it was cut from.

    Attributes
    ----------
    mesh_name : str
    plane : str
        One of :data:`PLANES`.
    contour : Contour2D
        The section loop in the plane's (u, v) coordinates (mesh units).
    points_3d : (p, 3) float
        The same loop on the mesh surface.
    edges : (p, 2) int
        Mesh edge each loop point lies on.
    """

    mesh_name: str
    plane: str
    contour: Contour2D
    points_3d: np.ndarray
    edges: np.ndarray

    @property
    def length_3d(self) -> float:
        """Length of the section curve on the mesh it was cut from."""
        return float(np.linalg.norm(np.roll(self.points_3d, -1, axis=0) - self.points_3d, axis=1).sum())

    def ground_truth(self, points_2d: np.ndarray, mesh_vertices: np.ndarray) -> np.ndarray:
        """Ground-truth vertex of arbitrary points on the contour.

        Each point is projected onto the nearest segment of the closed section
        polygon; the surface point at the same position between the two loop
        points is assigned the nearest endpoint of their two mesh edges.

        Parameters
        ----------
        points_2d : (m, 2) float
            Points on (or next to) the contour, e.g. a resampling of it.
        mesh_vertices : (n, 3) float
            Vertices of the mesh the query was cut from.

        Returns
        -------
        (m,) int
        """
        p2 = self.contour.points
        a, b = p2, np.roll(p2, -1, axis=0)
        ab = b - a
        rel = np.asarray(points_2d, dtype=np.float64)[:, None, :] - a[None]
        t = np.clip(np.einsum("mpk,pk->mp", rel, ab) / np.maximum(np.sum(ab * ab, axis=1), 1e-300), 0.0, 1.0)
        dist2 = np.sum((rel - t[..., None] * ab[None]) ** 2, axis=2)
        seg = np.argmin(dist2, axis=1)
        u = t[np.arange(len(seg)), seg]
        nxt = (seg + 1) % len(p2)
        surface = (1 - u)[:, None] * self.points_3d[seg] + u[:, None] * self.points_3d[nxt]
        candidates = np.hstack([self.edges[seg], self.edges[nxt]])  # (m, 4)
        d = np.linalg.norm(mesh_vertices[candidates] - surface[:, None, :], axis=2)
        return candidates[np.arange(len(seg)), np.argmin(d, axis=1)]


def symmetry_normal(mesh: TriMesh) -> np.ndarray:
    """Normal (3,) of the principal plane across which the mesh is most nearly mirror-symmetric."""
    centre, axes = principal_frame(mesh)
    tree = cKDTree(mesh.vertices)
    scores = []
    for normal in axes:
        reflected = mesh.vertices - 2.0 * ((mesh.vertices - centre) @ normal)[:, None] * normal[None]
        scores.append(tree.query(reflected)[0].mean())
    return axes[int(np.argmin(scores))]


def section_plane(mesh: TriMesh, plane: str) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (3,) and unit normal (3,) of a named section plane (see the module docstring)."""
    if plane not in PLANES:
        raise ParameterError(f"plane must be one of {', '.join(PLANES)}, got {plane!r}")
    centre, axes = principal_frame(mesh)
    if plane == "symmetry":
        return centre, symmetry_normal(mesh)
    return centre, axes[2] if plane == "main" else axes[1]


def cut_query(mesh: TriMesh, plane: str = "main") -> CutQuery:
    """The longest section loop of ``mesh`` with a principal plane through its centroid.

    Raises
    ------
    ParameterError
        Unknown plane.
    InputError
        The plane does not cut a closed loop of at least 10 points.
    """
    from corrlib.geometry.sections import plane_section

    centre, normal = section_plane(mesh, plane)
    loops = plane_section(mesh, centre, normal)
    if not loops or len(loops[0].points) < 10:
        raise InputError(f"{mesh.name}: the {plane} plane does not cut a closed section loop of 10 or more points")
    loop = loops[0]
    contour = Contour2D(loop.points_2d, name=f"{mesh.name}-{plane}", validate=False)
    # the contour drops (near-)duplicate points: keep the loop points it kept, in order
    position = {tuple(p): i for i, p in enumerate(loop.points_2d)}
    kept = np.array([position[tuple(p)] for p in contour.points])
    return CutQuery(mesh.name, plane, contour, loop.points[kept], loop.edges[kept])


@dataclass
class SilhouetteQuery:
    """A side-view silhouette query with its rim ground truth (see the module docstring).

    Attributes
    ----------
    mesh_name : str
    plane : str
        ``"silhouette"`` or ``"top"``.
    contour : Contour2D
        The outline in pixel units.
    projection : SilhouetteProjection
        The mesh's vertices in the same units, with their depth.
    length_3d : float
        Length of the outline in mesh units, about the length of the rim's
        projection (a polyline through the rim vertices would zig-zag
        between the near and the far side and overstate it).
    """

    mesh_name: str
    plane: str
    contour: Contour2D
    projection: SilhouetteProjection
    length_3d: float

    def ground_truth(self, points_2d: np.ndarray, mesh_vertices: np.ndarray) -> np.ndarray:
        """Near-side and far-side rim vertex of arbitrary outline points ((m, 2) int)."""
        from corrlib.geometry.sections import rim_vertices

        return rim_vertices(points_2d, self.projection)


def silhouette_query(mesh: TriMesh, resolution: int = SILHOUETTE_RESOLUTION, view: str = "silhouette"
                     ) -> SilhouetteQuery:
    """The outline of ``mesh`` seen along its axis of least variance (up: the second axis), or for
    ``view="top"`` along its axis of middle variance (up: the first axis)."""
    from corrlib.geometry.sections import rendered_view

    if view not in SILHOUETTES:
        raise ParameterError(f"unknown silhouette view {view!r}; expected one of {', '.join(SILHOUETTES)}")
    _, axes = principal_frame(mesh)
    direction, up = (axes[2], axes[1]) if view == "silhouette" else (axes[1], axes[0])
    contour, projection = rendered_view(mesh, direction, resolution, up=up)
    length = contour.length / projection.pixels_per_unit
    return SilhouetteQuery(mesh.name, view, Contour2D(contour.points, name=f"{mesh.name}-{view}", validate=False),
                           projection, length)


def _vts_transfer(source_vertices: np.ndarray, rows_source: np.ndarray, rows_target: np.ndarray):
    """Vertex map source -> target through corresponding ``.vts`` rows (nearest row on the source)."""
    tree = cKDTree(source_vertices[rows_source])

    def transfer(vertices: np.ndarray) -> np.ndarray:
        return rows_target[tree.query(source_vertices[vertices])[1]]

    return transfer


def point_errors(map_xy: np.ndarray, gt: np.ndarray, target: TriMesh, solver) -> np.ndarray:
    """(m,) float: the geodesic error / √area of every matched contour point against its ground-truth vertex, or
    the nearest of its acceptable vertices (``gt`` (m,) or (m, k) int); ``solver``: the target's
    :class:`~corrlib.geometry.geodesics.GeodesicSolver`."""
    candidates = np.asarray(gt).reshape(len(map_xy), -1)
    return np.min([solver.pair_distances(map_xy, column) for column in candidates.T], axis=0) / np.sqrt(target.area)


def score_curve(map_xy: np.ndarray, path_vertices: np.ndarray, gt: np.ndarray, target: TriMesh,
                gt_length: float, solver=None) -> dict:
    """Accuracy and coverage of a matched closed curve.

    Parameters
    ----------
    map_xy : (m,) int
        Matched vertex of every contour point.
    path_vertices : (p,) int
        The closed path on the mesh (first = last).
    gt : (m,) or (m, k) int
        Ground-truth vertex of every contour point, or k acceptable vertices
        (the error is the distance to the nearest of them).
    target : TriMesh
    gt_length : float
        Length of the ground-truth curve on the target.
    solver : GeodesicSolver, optional
        The target's, if already built (scoring against another ground truth).

    Returns
    -------
    dict
        ``mean_error``, ``median_error`` (geodesic / √area), ``within_005``,
        ``within_01``, ``coverage`` (path length / ``gt_length``),
        ``distinct_vertices`` of the path and ``gt_distinct_vertices``, and ``reached``: the share of the
        ground-truth points within :data:`REACHED_DISTANCE` of the matched curve, wherever on it. A curve crowded
        into one part of the shape can be as long as the truth (it wiggles) and so pass the coverage, but it
        leaves most of the true curve unreached; a curve in the right place whose points slide along it
        reaches it all while its point errors are large.
    """
    from corrlib.geometry.geodesics import GeodesicSolver

    solver = solver or GeodesicSolver(target)
    candidates = np.asarray(gt).reshape(len(map_xy), -1)
    errors = point_errors(map_xy, candidates, target, solver)
    length = np.linalg.norm(np.diff(target.vertices[path_vertices], axis=0), axis=1).sum()
    to_curve = solver.distances_to_nearest(path_vertices)[candidates].min(axis=1) / np.sqrt(target.area)
    return {"n_points": int(len(map_xy)), "mean_error": float(errors.mean()), "median_error": float(np.median(errors)),
            "within_005": float(np.mean(errors <= 0.05)), "within_01": float(np.mean(errors <= 0.1)),
            "coverage": float(length / gt_length), "distinct_vertices": int(len(np.unique(path_vertices))),
            "gt_distinct_vertices": int(len(np.unique(candidates[:, 0]))),
            "reached": float(np.mean(to_curve <= REACHED_DISTANCE))}


def match_cut_query(source_path, target_path, plane: str, params: dict, *, gt_rows=None, gt_map=None,
                    mirror_rows=None, picture: str | None = None, method: str = "contour3d") -> dict:
    """Cut a query from the source mesh, match it to the target and score it (one benchmark job).

    Parameters
    ----------
    source_path, target_path : path
        Mesh files; equal for the query's own mesh.
    plane : str
    params : dict
        Parameters of the 2D-to-3D ``method`` (``contour3d`` unless told).
    gt_rows : (rows_source, rows_target), optional
        Corresponding ``.vts`` rows (0-based).
    gt_map : (n_source,) int, optional
        Target vertex of every source vertex. Without ``gt_rows`` and
        ``gt_map``, source and target must share their connectivity.
    mirror_rows : (rows_target, rows_target_mirrored), optional
        The target's ``.vts`` and ``.sym.vts`` rows (0-based): the
        mirror-accepted error is reported too.
    picture : path, optional
        PNG of the query and the matched curve.

    Returns
    -------
    dict
        One row of the results (see the module docstring); ``status`` is
        ``"ok"`` or ``"failed"`` with ``error``.
    """
    from corrlib.io import load_mesh
    from corrlib.methods import solve

    from corrlib.retrieval import class_of

    row = {"query": f"{Path(source_path).stem}-{plane}", "target": Path(target_path).stem, "plane": plane,
           "self": Path(source_path).resolve() == Path(target_path).resolve(),
           "other_class": class_of(source_path) != class_of(target_path), "status": "ok", "error": ""}
    try:
        source = load_mesh(source_path)
        target = source if row["self"] else load_mesh(target_path)
        if plane == "symmetry" and abs(section_plane(source, "symmetry")[1] @ section_plane(source, "main")[1]) > 0.99:
            row.update(status="skipped", error="the symmetry plane is the main plane")
            return row
        query = silhouette_query(source, view=plane) if plane in SILHOUETTES else cut_query(source, plane)
        if row["self"]:
            transfer = None
        elif gt_rows is not None:
            transfer = _vts_transfer(source.vertices, *gt_rows)
        elif gt_map is not None:
            transfer = gt_map.__getitem__
        elif source.n_vertices == target.n_vertices:
            transfer = None  # same connectivity: vertex i is vertex i
        else:
            raise InputError(f"no ground truth from {source.name} ({source.n_vertices} vertices) to "
                             f"{target.name} ({target.n_vertices} vertices)")
        start = time.perf_counter()
        result = solve(method, query.contour, target, **params)
        seconds = time.perf_counter() - start
        matched = result.path
        gt = query.ground_truth(matched.contour_points, source.vertices)
        if transfer is not None:
            gt = transfer(gt)
        path = np.asarray(matched.vertices)
        from corrlib.geometry.geodesics import GeodesicSolver

        solver = GeodesicSolver(target)
        row.update(score_curve(result.map_xy, path, gt, target, query.length_3d * np.sqrt(target.area / source.area),
                               solver))
        row["mean_error_sym"] = row["mean_error"]
        if mirror_rows is not None:
            mirrored = point_errors(result.map_xy, _vts_transfer(target.vertices, *mirror_rows)(gt), target, solver)
            row["mean_error_sym"] = min(row["mean_error"], float(mirrored.mean()))
        row.update(view=result.extras.get("view", ""), model=result.extras.get("model", ""))
        row.update(path_search_fields(result, seconds))
        if picture is not None:
            from corrlib.plotting import save_curve_comparison

            near_side = np.asarray(gt).reshape(len(result.map_xy), -1)[:, 0]
            save_curve_comparison(picture, matched.contour_points, target, path, matched.contour_index,
                                  near_side,
                                  title=f"{row['query']} -> {row['target']}: mean error {row['mean_error']:.3f}, "
                                        f"coverage {row['coverage']:.2f}")
    except Exception as exc:  # a failing match is recorded; the others go on
        row.update(failure_fields(exc))
    return row


SKETCH_CONTOUR_SUFFIX = "_contour.txt"
PART_LABELS_SUFFIX = "_segmentation.txt"


@dataclass
class SketchQuery:
    """A drawn outline with part labels (the layout of the CVPR 2016 sketches, see the module docstring).

    Attributes
    ----------
    name : str
    contour_path, mesh_path, labels_path : Path
        The outline, the planar triangulated sketch and its labels (one per sketch vertex).
    """

    name: str
    contour_path: Path
    mesh_path: Path
    labels_path: Path

    def point_labels(self, points_2d: np.ndarray) -> np.ndarray:
        """(m,) int: the part label of arbitrary outline points, that of the nearest sketch vertex."""
        from corrlib.io import load_labels, load_mesh

        sketch = load_mesh(self.mesh_path)
        labels = load_labels(self.labels_path, sketch.n_vertices, "sketch part labels")
        return labels[cKDTree(sketch.vertices[:, :2]).query(np.asarray(points_2d, dtype=np.float64))[1]]


def sketch_queries(folder) -> list[SketchQuery]:
    """The labelled sketches of a folder (every ``NAME_contour.txt``; its mesh and labels must exist).

    Each outline, sketch mesh and label file is read once here, so that a malformed one is a named error
    before any matching (one label per sketch vertex)."""
    from corrlib.errors import FileFormatError
    from corrlib.io import load_contour, load_labels, load_mesh

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder (expected sketches: NAME{SKETCH_CONTOUR_SUFFIX}, NAME.off, "
                         f"NAME{PART_LABELS_SUFFIX}){lost_working_folder(folder)}")
    found = []
    for contour in sorted(folder.glob(f"*{SKETCH_CONTOUR_SUFFIX}")):
        name = contour.name[:-len(SKETCH_CONTOUR_SUFFIX)]
        mesh, labels = folder / f"{name}.off", folder / f"{name}{PART_LABELS_SUFFIX}"
        missing = [p.name for p in (mesh, labels) if not p.is_file()]
        if missing:
            raise FileFormatError(f"{contour}: the sketch's {' and '.join(missing)} are missing (a labelled "
                                  "sketch is an outline, its triangulated sketch and one label per sketch vertex)")
        load_contour(contour)
        load_labels(labels, load_mesh(mesh).n_vertices, "sketch part labels")
        found.append(SketchQuery(name, contour, mesh, labels))
    if not found:
        raise FileFormatError(f"{folder}: no sketches (NAME{SKETCH_CONTOUR_SUFFIX})")
    return found


def part_agreement(point_labels: np.ndarray, matched_labels: np.ndarray) -> tuple[float, int]:
    """Share of the points labelled on both sides whose two labels agree.

    Parameters
    ----------
    point_labels : (m,) int
        Labels of the contour points (0: unlabelled).
    matched_labels : (m,) int
        Labels of their matched mesh vertices (0: unlabelled).

    Returns
    -------
    agreement : float
        NaN when no point is labelled on both sides.
    scored : int
        Points labelled on both sides.
    """
    point_labels, matched_labels = np.asarray(point_labels), np.asarray(matched_labels)
    scored = (point_labels != 0) & (matched_labels != 0)
    if not scored.any():
        return float("nan"), 0
    return float(np.mean(point_labels[scored] == matched_labels[scored])), int(scored.sum())


def match_sketch_query(sketch: SketchQuery, target_path, labels_path, params: dict, *, mirror_rows=None,
                       picture: str | None = None, method: str = "contour3d") -> dict:
    """Match a labelled sketch to a labelled mesh and score the part agreement (one benchmark job).

    Parameters
    ----------
    sketch : SketchQuery
    target_path, labels_path : path
        The mesh and its part labels (one per vertex).
    params : dict
        Parameters of the 2D-to-3D ``method`` (``contour3d`` unless told; the labels are not passed to it).
    mirror_rows : (rows_target, rows_target_mirrored), optional
        The target's ``.vts`` and ``.sym.vts`` rows: the mirror-accepted agreement is reported too.
    picture : path, optional

    Returns
    -------
    dict
        One row: ``part_agreement``, ``part_agreement_sym``, ``scored_points``, ``distinct_vertices``,
        energy, gap, optimality and time; ``status`` ``"ok"`` or ``"failed"`` with ``error``.
    """
    from corrlib.io import load_contour, load_labels, load_mesh
    from corrlib.methods import solve

    row = {"query": sketch.name, "target": Path(target_path).stem, "plane": "sketch", "self": False,
           "other_class": False, "status": "ok", "error": ""}
    try:
        target = load_mesh(target_path)
        mesh_labels = load_labels(labels_path, target.n_vertices, "mesh part labels")
        start = time.perf_counter()
        result = solve(method, load_contour(sketch.contour_path), target, **params)
        seconds = time.perf_counter() - start
        matched = result.path
        labels = sketch.point_labels(matched.contour_points)
        agreement, scored = part_agreement(labels, mesh_labels[result.map_xy])
        row.update(part_agreement=agreement, part_agreement_sym=agreement, scored_points=scored)
        if mirror_rows is not None:
            mirrored = _vts_transfer(target.vertices, *mirror_rows)(np.asarray(result.map_xy))
            row["part_agreement_sym"] = max(agreement, part_agreement(labels, mesh_labels[mirrored])[0])
        path = np.asarray(matched.vertices)
        row.update(path_search_fields(result, seconds))
        if picture is not None:
            from corrlib.plotting import save_contour_match

            save_contour_match(picture, matched.contour_points, target, path, matched.contour_index,
                               title=f"{sketch.name} -> {row['target']}: part agreement {agreement:.2f} "
                                     f"(mirror accepted {row['part_agreement_sym']:.2f})")
    except Exception as exc:  # a failing match is recorded; the others go on
        row.update(failure_fields(exc))
    return row


@dataclass
class ContourJob:
    source: Path
    target: Path
    plane: str
    gt_rows: tuple | None = None
    gt_map: np.ndarray | None = None
    mirror_rows: tuple | None = None


def _shape_maps(folder: Path, shapes: dict) -> list[tuple[str, str, Path]]:
    """(source, target, file) of the cross-class map files of a dataset folder (see the module docstring)."""
    from corrlib.retrieval import class_of

    def resolve(name):
        if name in shapes:
            return name
        members = [s for s in shapes if class_of(s) == name]
        return members[0] if len(members) == 1 else None

    found = []
    for path in sorted(folder.iterdir()):
        if not path.is_file():
            continue
        stem = path.stem if path.suffix == ".txt" else path.name if not path.suffix else None
        if stem is None:
            continue
        for sep in ("__", "2"):
            if sep in stem:
                a, b = stem.split(sep, 1)
                a, b = resolve(a), resolve(b)
                if a and b and a != b:
                    found.append((a, b, path))
                    break
    return found


def contour_jobs(datasets, planes=DEFAULT_PLANES) -> list[ContourJob]:
    """Every (query mesh, plane, target) of the datasets: the query's own mesh and the others of its class.

    Parameters
    ----------
    datasets : list of path
        Folders in the layouts of :func:`corrlib.bench.load_dataset`.
    planes : sequence of str
    """
    from corrlib.io import load_map, load_mesh
    from corrlib.retrieval import class_of

    for plane in planes:
        if plane not in QUERY_KINDS:
            raise ParameterError(f"plane must be one of {', '.join(QUERY_KINDS)}, got {plane!r}")
    repeated = [name for name, count in Counter(planes).items() if count > 1] + [
        str(folder) for folder, count in Counter(Path(d).resolve() for d in datasets).items() if count > 1]
    if repeated:  # each query would be matched, and counted, twice
        raise ParameterError(f"{', '.join(repeated)} given twice; name each plane and dataset once")
    jobs = []
    for folder in datasets:
        data = load_dataset(folder, require_pairs=False)
        rows, mirror = checked_ground_truth(data, [(a, b) for a in data.shapes for b in data.shapes
                                                  if a != b and class_of(a) == class_of(b)])
        mirror = {name: (rows[name], sym) for name, sym in mirror.items()}
        maps = _shape_maps(data.folder, data.shapes)
        for name, path in data.shapes.items():
            for plane in planes:
                jobs.append(ContourJob(path, path, plane, mirror_rows=mirror.get(name)))
                for other, other_path in data.shapes.items():
                    if other == name or class_of(other) != class_of(name):
                        continue
                    jobs.append(ContourJob(path, other_path, plane, gt_rows=(rows[name], rows[other]) if rows else None,
                                           mirror_rows=mirror.get(other)))
        for name, other, map_path in maps:
            source, target = load_mesh(data.shapes[name]), load_mesh(data.shapes[other])
            gt_map = load_map(map_path, n_target=target.n_vertices, n_source=source.n_vertices)
            for plane in planes:
                jobs.append(ContourJob(data.shapes[name], data.shapes[other], plane, gt_map=gt_map))
    return jobs


@dataclass
class SketchJob:
    sketch: SketchQuery
    target: Path
    labels: Path
    mirror_rows: tuple | None = None


def sketch_jobs(datasets, sketch_folders) -> list[SketchJob]:
    """Every labelled sketch of ``sketch_folders`` against every mesh of ``datasets`` with part labels."""
    from corrlib.io import load_labels, load_mesh

    sketches = [q for folder in sketch_folders for q in sketch_queries(folder)]
    if not sketches:
        return []
    jobs = []
    for folder in datasets:
        data = load_dataset(folder, require_pairs=False)
        rows, mirror = checked_ground_truth(data, [])
        mirror = {name: (rows[name], sym) for name, sym in mirror.items()}
        for name, path in data.shapes.items():
            labels = path.with_name(f"{name}{PART_LABELS_SUFFIX}")
            if labels.is_file():
                load_labels(labels, load_mesh(path).n_vertices, "mesh part labels")  # named error before any work
                jobs += [SketchJob(q, path, labels, mirror.get(name)) for q in sketches]
    if not jobs:
        raise InputError(f"no mesh of {', '.join(str(d) for d in datasets)} has part labels "
                         f"(<mesh>{PART_LABELS_SUFFIX}, one label per vertex in the sketches' vocabulary) to score "
                         "the sketches against")
    return jobs


def _sketch_summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["status"] == "ok"]
    if not ok:
        return {"queries": len(rows), "failed": len(rows)}
    col = lambda key: np.array([r[key] for r in ok], dtype=np.float64)  # noqa: E731
    return {"queries": len(rows), "failed": len(rows) - len(ok),
            "part_agreement": float(np.nanmean(col("part_agreement"))),
            "part_agreement_sym": float(np.nanmean(col("part_agreement_sym"))),
            "worst_part_agreement_sym": float(np.nanmin(col("part_agreement_sym"))),
            "min_distinct_vertices": int(col("distinct_vertices").min()),
            "optimal": int(sum(r["optimal"] for r in ok)),
            "median_seconds": float(np.median(col("seconds"))), "max_seconds": float(col("seconds").max())}


def _summary(rows: list[dict]) -> dict:
    rows = [r for r in rows if r["status"] != "skipped"]

    def block(selected):
        ok = [r for r in selected if r["status"] == "ok"]
        if not ok:
            return {"queries": len(selected), "failed": len(selected)}
        col = lambda key: np.array([r[key] for r in ok], dtype=np.float64)  # noqa: E731
        return {"queries": len(selected), "failed": len(selected) - len(ok),
                "mean_error": float(col("mean_error").mean()), "worst_mean_error": float(col("mean_error").max()),
                "mean_error_sym": float(col("mean_error_sym").mean()),
                "within_005": float(col("within_005").mean()), "within_01": float(col("within_01").mean()),
                "mean_coverage": float(col("coverage").mean()), "min_coverage": float(col("coverage").min()),
                "collapsed": int(np.sum(col("coverage") < COLLAPSE_COVERAGE)),
                "mean_reached": float(col("reached").mean()), "min_reached": float(col("reached").min()),
                "optimal": int(sum(r["optimal"] for r in ok)),
                "median_seconds": float(np.median(col("seconds"))), "max_seconds": float(col("seconds").max())}

    other_pose = [r for r in rows if not r["self"] and not r["other_class"]]
    summary = {"all": block(rows), "same mesh": block([r for r in rows if r["self"]]),
               "other pose": block(other_pose), "other class": block([r for r in rows if r["other_class"]])}
    planes = sorted({r["plane"] for r in rows})
    if len(planes) > 1:  # the planes are different kinds of query (whole outline or a part of the shape)
        for plane in planes:
            summary[f"{plane} plane"] = block([r for r in rows if r["plane"] == plane])
            summary[f"{plane} plane, other pose"] = block([r for r in other_pose if r["plane"] == plane])
    return summary


def _markdown(summary: dict, rows: list[dict]) -> str:
    def fmt(value, spec=".3f"):
        return "–" if value is None else format(value, spec)

    lines = ["| queries | n | failed | mean error | mirror accepted | worst mean | ≤0.05 | ≤0.1 | coverage | "
             f"min coverage | collapsed (<{COLLAPSE_COVERAGE}) | truth reached | min reached | optimal | median s | "
             "max s |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for label, s in summary.items():
        g = s.get
        lines.append(f"| {label} | {s['queries']} | {s['failed']} | {fmt(g('mean_error'))} | "
                     f"{fmt(g('mean_error_sym'))} | "
                     f"{fmt(g('worst_mean_error'))} | {fmt(g('within_005'))} | {fmt(g('within_01'))} | "
                     f"{fmt(g('mean_coverage'), '.2f')} | {fmt(g('min_coverage'), '.2f')} | {g('collapsed', '–')} | "
                     f"{fmt(g('mean_reached'), '.2f')} | {fmt(g('min_reached'), '.2f')} | {g('optimal', '–')} | "
                     f"{fmt(g('median_seconds'), '.2f')} | {fmt(g('max_seconds'), '.2f')} |")
    lines += ["", "| query | target | mean error | mirror accepted | ≤0.05 | ≤0.1 | coverage | distinct vertices (gt) | "
                  "truth reached | energy | gap | s | error |", "|---" * 13 + "|"]
    for r in rows:
        if r["status"] == "skipped":
            continue
        if r["status"] != "ok":
            lines.append(f"| {r['query']} | {r['target']} | | | | | | | | | | | {r['error']} |")
            continue
        lines.append(f"| {r['query']} | {r['target']} | {r['mean_error']:.3f} | {r['mean_error_sym']:.3f} | "
                     f"{r['within_005']:.2f} | "
                     f"{r['within_01']:.2f} | {r['coverage']:.2f} | {r['distinct_vertices']} "
                     f"({r['gt_distinct_vertices']}) | {r['reached']:.2f} | {r['energy']:.4g} | {r['gap']:.2g} | "
                     f"{r['seconds']:.2f} | |")
    return "\n".join(lines) + "\n"


def _sketch_markdown(summary: dict, rows: list[dict]) -> str:
    s = summary
    lines = ["| sketches | n | failed | part agreement | mirror accepted | worst (mirror accepted) | "
             "fewest distinct vertices | optimal | median s | max s |", "|---|---|---|---|---|---|---|---|---|---|"]
    if "part_agreement" in s:
        lines.append(f"| all | {s['queries']} | {s['failed']} | {s['part_agreement']:.3f} | "
                     f"{s['part_agreement_sym']:.3f} | {s['worst_part_agreement_sym']:.3f} | "
                     f"{s['min_distinct_vertices']} | {s['optimal']} | {s['median_seconds']:.2f} | "
                     f"{s['max_seconds']:.2f} |")
    else:
        lines.append(f"| all | {s['queries']} | {s['failed']} | | | | | | | |")
    lines += ["", "| sketch | target | part agreement | mirror accepted | scored points | distinct vertices | energy | "
                  "gap | s | error |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"| {r['query']} | {r['target']} | | | | | | | | {r['error']} |")
            continue
        lines.append(f"| {r['query']} | {r['target']} | {r['part_agreement']:.3f} | {r['part_agreement_sym']:.3f} | "
                     f"{r['scored_points']} | {r['distinct_vertices']} | {r['energy']:.4g} | {r['gap']:.2g} | "
                     f"{r['seconds']:.2f} | |")
    return "\n".join(lines) + "\n"


COLUMNS = ("query", "target", "plane", "self", "other_class", "status", "n_points", "mean_error", "mean_error_sym",
           "median_error", "within_005",
           "within_01", "coverage", "distinct_vertices", "gt_distinct_vertices", "reached", "view", "model", "energy",
           "gap",
           "optimal",
           "iterations", "seconds", "part_agreement", "part_agreement_sym", "scored_points", "landmark_error",
           "landmark_within_01", "worst_landmark", "scored_landmarks", "redraws", "redraw_error", "redraw_worst",
           "error")


def contour_benchmark(datasets, out, *, planes=DEFAULT_PLANES, params: dict | None = None, jobs: int | None = 1,
                      scheduler: str | None = None, pictures: bool = True, callback=None, sketches=(),
                      drawings=(), redraws: int = 0, method: str = "contour3d") -> dict:
    """Run the plane-section benchmark; write ``contour_bench.csv``, ``contour_summary.{json,md}``, pictures.

    Parameters
    ----------
    datasets : list of path
    out : path
        Output folder (created; checked for writing before any work).
    planes : sequence of str
        Section and silhouette queries; may be empty when ``sketches`` are given.
    sketches : sequence of path
        Folders of labelled sketches, matched to the datasets' meshes with part labels (module docstring).
    drawings : sequence of path
        Folders of drawings with landmarks, matched to the datasets' meshes with landmarks
        (:mod:`corrlib.landmark_bench`).
    redraws : int
        Redrawn variants of every drawing (:func:`corrlib.landmark_bench.redrawn`).
    method : str
        A registered method that matches a contour to a mesh (``contour3d`` or ``contour-views``).
    params : dict, optional
        The method's parameters (validated before any work).
    jobs, scheduler
        See :func:`corrlib.parallel.job_executor`.
    pictures : bool
        One PNG per match in ``out/pictures``.
    callback : callable(done, total, row), optional

    Returns
    -------
    dict
        The summary: ``{"all" | "same mesh" | "other pose" | "other class": {...}}``, and ``"sketches"`` and
        ``"drawings"`` when they were given.
    """
    from corrlib.io import atomic_write, ensure_output_folder
    from corrlib.methods import all_methods, get_method, make_params
    from corrlib.parallel import job_executor

    params = dict(params or {})
    spec = get_method(method)
    if spec.inputs != ("contour", "mesh"):
        raise ParameterError(f"method {method!r} does not match a contour to a mesh; the 2D-to-3D methods are "
                             + ", ".join(m.name for m in all_methods() if m.inputs == ("contour", "mesh")))
    make_params(spec.params, **params)  # named errors before any work
    if not isinstance(redraws, (int, np.integer)) or isinstance(redraws, bool) or not 0 <= redraws <= MAX_REDRAWS:
        raise ParameterError(f"redraws must be a whole number from 0 to {MAX_REDRAWS}, got {redraws!r}")
    if redraws and not drawings:
        raise ParameterError("redraws are variants of drawings with landmarks; give them with --drawn")
    todo = contour_jobs(datasets, planes)
    sketched = sketch_jobs(datasets, sketches)
    drawn = drawn_jobs(datasets, drawings)
    if not todo and not sketched and not drawn:
        raise ParameterError("nothing to run: give section planes (--planes), labelled sketches (--sketches) or "
                             "drawings with landmarks (--drawn)")
    executor = job_executor(jobs, scheduler)
    out = ensure_output_folder(out)
    if pictures:
        ensure_output_folder(out / "pictures")
    rows = []
    with executor as pool:
        futures, picture_of = [], []
        for job in todo:
            picture = None
            if pictures:
                picture = str(out / "pictures" / f"{job.source.stem}-{job.plane}__{job.target.stem}.png")
            futures.append(pool.submit(match_cut_query, str(job.source), str(job.target), job.plane, params,
                                       gt_rows=job.gt_rows, gt_map=job.gt_map, mirror_rows=job.mirror_rows,
                                       picture=picture, method=method))
            picture_of.append(picture)
        for job in sketched:
            picture = None
            if pictures:
                picture = str(out / "pictures" / f"{job.sketch.name}__{job.target.stem}.png")
            futures.append(pool.submit(match_sketch_query, job.sketch, str(job.target), str(job.labels), params,
                                       mirror_rows=job.mirror_rows, picture=picture, method=method))
            picture_of.append(picture)
        for job in drawn:
            picture = str(out / "pictures" / f"{job.query.name}-drawn__{job.target.stem}.png") if pictures else None
            futures.append(pool.submit(match_drawn_query, job.query, str(job.target), str(job.landmarks), params,
                                       redraws=redraws, picture=picture, method=method))
            picture_of.append(picture)
        for number, future in enumerate(futures, 1):
            rows.append(future.result())
            if callback is not None:
                callback(number, len(futures), rows[-1])
    drawn_now = {Path(picture).name for picture, row in zip(picture_of, rows) if picture and row["status"] == "ok"}
    sketch_rows = [r for r in rows if r["plane"] == "sketch"]
    drawn_rows = [r for r in rows if r["plane"] == "drawn"]
    rows = [r for r in rows if r["plane"] not in ("sketch", "drawn")]
    summary = _summary(rows) if rows else {"all": {"queries": 0, "failed": 0}}
    if sketch_rows:
        summary["sketches"] = _sketch_summary(sketch_rows)
    if drawn_rows:
        summary["drawings"] = drawn_summary(drawn_rows)
    with atomic_write(out / "contour_bench.csv") as fh:
        fh.write(",".join(COLUMNS) + "\n")
        for r in rows + sketch_rows + drawn_rows:
            fh.write(",".join(csv_cell(r.get(c, "")) for c in COLUMNS) + "\n")
    with atomic_write(out / "contour_summary.json") as fh:
        json.dump({"summary": summary, "method": method, "params": params, "planes": list(planes), "rows": rows,
                   "sketch_rows": sketch_rows, "drawn_rows": drawn_rows, "redraws": redraws}, fh, indent=1)
    with atomic_write(out / "contour_summary.md") as fh:
        tables = [_markdown({k: v for k, v in summary.items() if k not in ("sketches", "drawings")}, rows)] if rows \
            else []
        if sketch_rows:
            tables.append(_sketch_markdown(summary["sketches"], sketch_rows))
        if drawn_rows:
            tables.append(drawn_markdown(summary["drawings"], drawn_rows))
        fh.write("\n".join(tables))
    remove_stale_pictures(out / "pictures", drawn_now)
    return summary


def remove_stale_pictures(folder: Path, kept: set[str]) -> None:
    """Remove the match pictures (``*__*.png``) in ``folder`` that this run did not draw (``kept``: file names):
    an earlier run's pictures of other planes, of matches that failed this time, or all of them after a run
    with ``--no-pictures``, would stand beside a table that no longer holds their rows."""
    from corrlib.outputs import remove_replaced_files

    if folder.is_dir():
        remove_replaced_files(folder, "*__*.png", kept)
