"""Sketch-based shape retrieval: rank a collection of meshes for a drawn outline.

The query contour is prepared once (resampling, filling, features); every
mesh is matched independently (:func:`corrlib.methods.contour3d.match_prepared`)
in a process pool. Mesh spectra are cached on disk by file content, so a
collection is decomposed once.

Two measures, and how they are combined (:func:`retrieve`'s ``ranking``):

* the 2D-to-3D matching **energy** of ``contour3d`` (thesis ch. 7; comparable
  across meshes because both shapes are scale-normalised, see
  :mod:`corrlib.methods.contour3d`): intrinsic, so it holds across poses, but
  it asks the drawing to have the proportions of a curve of the surface;
* the **view dissimilarity** (:mod:`corrlib.outline_views`): the drawing
  against the mesh's rendered outlines, 2D to 2D, by the inner-distance shape
  context; it takes a drawing as a view of the mesh, and forgives the
  proportions the energy does not.

``ranking="fused"`` (the default) ranks by the product of the two measures
(:func:`fused_scores`), ``"energy"`` by the energy alone (the thesis'
ranking).

A collection is a folder of meshes, searched with its subfolders. Class labels
come from the layout: a mesh in a subfolder belongs to the class named by the
subfolder (``collection/cat/0.off`` is class ``cat``, as class-per-folder
benchmarks are laid out); a mesh directly in the folder to the class its name
gives without suffix, trailing digits and separators (``cat0`` and ``cat-12``
are class ``cat``). A flat mesh in it (a triangulated 2D sketch, such as the
bundled ``sketch2d`` files) is left out of the ranking, said in the progress
reports: it is a drawing, not a 3D shape, and would match a drawing of its
class as no view of a surface can (:data:`FLAT_CANDIDATE`).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from corrlib.errors import CorrError, InputError, ParameterError
from corrlib.io import MESH_SUFFIXES, load_mesh, lost_working_folder
from corrlib.parallel import check_jobs, job_executor
from corrlib.methods.contour3d import Contour3DParams, PreparedQuery, curve_collapsed, match_prepared, prepare_query
from corrlib.outline_views import QueryOutline, query_outline, view_dissimilarity
from corrlib.progress import CancelToken, Progress, run
from corrlib.shapes import Contour2D, TriMesh, plane_coordinates

#: how :func:`retrieve` ranks: by the product of the two measures, or by the matching energy alone
RANKINGS = ("fused", "energy")
#: why a flat mesh of a collection is not ranked: it is a drawing (a query), not a shape a drawing is a view of
FLAT_CANDIDATE = ("a flat mesh (all its vertices in one plane) is a 2D sketch, not a 3D shape to rank (use it as "
                  "a query instead)")


def retrieval_params(**overrides) -> Contour3DParams:
    """The ``contour3d`` parameters a retrieval uses: the method's defaults with the
    view decided by the outline alone (``view="outline"``: one reading of the query
    for every mesh, so that its energies compare; the default ``"auto"`` also asks
    each mesh), then ``overrides`` (named errors for bad values). The command line,
    the studio and ``corr bench-retrieval`` share them, so that they rank alike, and
    a hit opened in the studio shows the curve the ranking scored."""
    from corrlib.methods.base import make_params

    return make_params(Contour3DParams, **{"view": "outline", **overrides})


def class_of(path, root=None) -> str:
    """Class label of a file of a collection rooted at ``root`` (see the module): the subfolder of ``root`` it is
    in (``root/cat/0.off`` -> ``cat``), or from its name (``cat0.off`` / ``cat-12.off`` -> ``cat``) for a file
    directly in ``root`` or without one."""
    parts = Path(collection_name(path, root)).parts
    if len(parts) > 1:
        return parts[0]
    stem = Path(path).stem
    return re.sub(r"[\s_\-.]*\d+$", "", stem) or stem


def collection_name(path, root=None) -> str:
    """The name of a file within a collection rooted at ``root``: its path relative to ``root`` (``cat/0.off``),
    or its file name without a root or outside it."""
    path = Path(path)
    if root is not None:
        try:
            return path.relative_to(root).as_posix()
        except ValueError:
            pass
    return path.name


def files_under(folder, suffixes, what: str) -> list[Path]:
    """Files of ``folder`` and its subfolders (hidden ones left out, links to folders not followed) whose suffix
    is one of ``suffixes``, sorted by their names within it; an :class:`InputError` naming ``what`` it lacks."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder{lost_working_folder(folder)}")
    found = []
    for here, folders, names in os.walk(folder):
        folders[:] = [name for name in folders if not name.startswith(".")]
        found += [Path(here) / name for name in names if Path(name).suffix.lower() in suffixes]
    if not found:
        raise InputError(f"{folder}: no {what} ({', '.join(sorted(suffixes))}) in it or its subfolders")
    return sorted(found, key=lambda path: collection_name(path, folder))


@dataclass
class RetrievalHit:
    """One ranked mesh.

    Attributes
    ----------
    path : Path
    energy : float
        Matching energy (``inf`` if the mesh could not be matched).
    error : str
        Why it failed (empty on success).
    path_vertices, path_contour_index : (p,) int
        The matched closed curve on the mesh.
    seconds : float
    contour_points : (m, 2) float or None
        The resampled query contour that ``path_contour_index`` indexes (the same for every mesh remeshed to
        the budget; a coarser mesh may have been matched with fewer points).
    root : Path or None
        The collection's folder, which names the mesh and its class (:attr:`name`, :attr:`label`).
    view_distance : float
        :func:`~corrlib.outline_views.view_dissimilarity` (NaN where not measured: ``ranking="energy"``, or no
        view of the mesh has an outline).
    score : float
        What the ranking sorts by (lower first): :func:`fused_scores` (energy times view dissimilarity) or the
        energy (``inf`` for a failed hit).
    left_out : bool
        The mesh is not a candidate (a flat sketch, :data:`FLAT_CANDIDATE`, the reason in :attr:`error`):
        :func:`retrieve` reports it and leaves it out of the ranking.
    """

    path: Path
    energy: float
    error: str = ""
    path_vertices: np.ndarray | None = field(default=None, repr=False)
    path_contour_index: np.ndarray | None = field(default=None, repr=False)
    seconds: float = 0.0
    contour_points: np.ndarray | None = field(default=None, repr=False)
    root: Path | None = None
    view_distance: float = float("nan")
    score: float = float("nan")
    curve_length_ratio: float = float("nan")
    left_out: bool = False

    def measured(self) -> str:
        """One line for a progress report: the mesh and what was measured on it (a collapsed curve said so)."""
        if self.left_out:
            return f"{self.name}: left out, {FLAT_CANDIDATE}"
        if self.error:
            return f"{self.name}: not matched"
        views = f", view dissimilarity {self.view_distance:.3f}" if np.isfinite(self.view_distance) else ""
        collapsed = self.collapse_note()
        return f"{self.name}: energy {self.energy:.6g}{views}" + (f"; {collapsed}" if collapsed else "")

    def collapse_note(self) -> str:
        """A short warning where the matched curve has probably collapsed onto a part of the mesh
        (:func:`~corrlib.methods.contour3d.curve_collapsed`), else an empty string."""
        if not curve_collapsed(self.curve_length_ratio):
            return ""
        return f"the matched curve is {self.curve_length_ratio:.2f} of the outline's length: probably collapsed"

    @property
    def name(self) -> str:
        """The mesh's name within the collection (:func:`collection_name`)."""
        return collection_name(self.path, self.root)

    @property
    def label(self) -> str:
        """The mesh's class (:func:`class_of`)."""
        return class_of(self.path, self.root)


def _match_one(query: PreparedQuery, item: str | TriMesh, params: Contour3DParams,
               outline: QueryOutline | None) -> RetrievalHit:
    """Worker: match the prepared query to one mesh (a file, or a loaded :class:`~corrlib.shapes.TriMesh` named by
    its ``name``) and, given the query's ``outline``, compare it with the mesh's views (errors become a failed
    hit)."""
    import time

    start = time.perf_counter()
    path = item.name if isinstance(item, TriMesh) else item
    try:
        mesh = item if isinstance(item, TriMesh) else load_mesh(item)
        if plane_coordinates(mesh.vertices) is not None:
            return RetrievalHit(Path(path), np.inf, f"{path}: {FLAT_CANDIDATE}", score=np.inf, left_out=True)
        # a mesh that cannot be remeshed is not matched as given: its energy would not compare with the others'
        result = run(match_prepared(query, mesh, params, CancelToken(), as_given_if_unremeshable=False))
        view_distance = float("nan") if outline is None else view_dissimilarity(outline, mesh)
    except CorrError as exc:
        return RetrievalHit(Path(path), np.inf, str(exc), seconds=time.perf_counter() - start, score=np.inf)
    return RetrievalHit(Path(path), float(result.energy), "", result.path.vertices, result.path.contour_index,
                        time.perf_counter() - start, result.path.contour_points, view_distance=view_distance,
                        curve_length_ratio=float(result.extras.get("curve_length_ratio", np.nan)))


def fused_scores(energies, view_distances) -> np.ndarray:
    """The ranking score of every mesh: ``E · D``, the matching energy times the view dissimilarity.

    The two measures have different units and spreads, and both vary with the query (a long, wiggly drawing
    costs more on every mesh), so neither can be added to the other as it is. Their product (the sum of their
    logarithms) is unchanged by any factor on either measure, so a relative difference counts the same in
    both: a mesh 10 % cheaper by energy and 10 % less alike by its views ties. There is no weight to choose,
    and a mesh's score depends on the query and that mesh alone, so that adding a mesh to a collection never
    reorders the others (standard scores over the collection, measured as well, do not have this property and
    tie every disagreement between two meshes; ``docs/decisions.md``). Both measures are non-negative costs,
    zero for a perfect fit. A mesh without a view dissimilarity (NaN: no view of it has an outline) takes
    the median of the others', as a typical mesh on that measure.

    Parameters
    ----------
    energies : (n,) float
        ``inf`` for a mesh that could not be matched.
    view_distances : (n,) float

    Returns
    -------
    (n,) float
        Lower ranks first; ``inf`` where the energy is not finite.
    """
    energies = np.asarray(energies, dtype=np.float64)
    views = np.asarray(view_distances, dtype=np.float64).copy()
    measured = np.isfinite(energies) & np.isfinite(views)
    views[~np.isfinite(views)] = np.median(views[measured]) if measured.any() else 1.0
    matched = np.isfinite(energies)
    scores = np.full(energies.shape, np.inf)
    scores[matched] = energies[matched] * views[matched]
    return scores


def collection_items(meshes) -> list[str | TriMesh]:
    """The meshes :func:`retrieve` ranks: file paths as strings, loaded meshes as they are; an
    :class:`InputError` for an empty collection or an entry of another kind (a contour, a number)."""
    items = []
    for index, item in enumerate(meshes):
        if isinstance(item, TriMesh):
            items.append(item)
        elif isinstance(item, (str, os.PathLike)):
            items.append(str(item))
        else:
            raise InputError(f"meshes[{index}] must be a mesh file or a TriMesh, got {type(item).__name__}")
    if not items:
        raise InputError("no meshes to rank")
    return items


def mesh_files(folder) -> list[Path]:
    """The mesh files (OFF/OBJ/PLY/STL) of a collection: in ``folder`` and its subfolders (:func:`files_under`)."""
    return files_under(folder, MESH_SUFFIXES, "mesh files")


def retrieve(query_contour, meshes: Iterable | str | os.PathLike, params: Contour3DParams | None = None, *, jobs: int | None = None,
             token: CancelToken | None = None, scheduler: str | None = None, root=None, ranking: str = "fused"):
    """Rank meshes by how well a query contour matches them: the matching energy times the view dissimilarity
    (``ranking="fused"``, the default) or the energy alone.

    A generator: ``corrlib.progress.run(retrieve(query, meshes))`` returns the ranked hits (``run(...,
    callback=print)`` also shows the progress).

    Parameters
    ----------
    query_contour : Contour2D
    meshes : folder, or iterable of mesh files or TriMesh
        A collection folder (its meshes and those of its subfolders, :func:`mesh_files`, named within it), or
        the meshes themselves: files, or meshes already loaded (named by their ``name``).
    params : Contour3DParams, optional
        Default: :func:`retrieval_params` (the exact optimum: an approximate
        energy may lie up to a factor ``1 + eps`` above it, which reorders
        meshes whose energies are that close, and saves little time).
    jobs : int, optional
        Worker processes (default: all cores; 1 runs in this process).
    token : CancelToken, optional
    scheduler : str, optional
        Address of a Dask scheduler: the meshes are matched on that cluster
        (:func:`corrlib.parallel.job_executor`) instead of local processes.
    root : path, optional
        The collection's folder (:func:`mesh_files`): the hits' names and classes are read within it.
    ranking : {"fused", "energy"}
        ``"fused"``: by :func:`fused_scores` of the energy and the view dissimilarity; ``"energy"``: by the
        matching energy alone (no views are rendered).

    Yields
    ------
    Progress
        One per finished mesh.

    Returns
    -------
    list of RetrievalHit
        Sorted by increasing :attr:`RetrievalHit.score` (failed meshes last, with their error); flat meshes
        left out (reported in the progress).

    Raises
    ------
    InputError
        Every mesh is flat: nothing to rank.
    """
    if ranking not in RANKINGS:
        raise ParameterError(f"ranking must be one of {', '.join(RANKINGS)}, got {ranking!r}")
    params = params or retrieval_params()
    if not isinstance(params, Contour3DParams):
        raise ParameterError(f"params must be contour3d's parameters (Contour3DParams, e.g. retrieval_params()), "
                             f"got {type(params).__name__}")
    if not isinstance(query_contour, Contour2D):
        raise InputError(f"the query must be a Contour2D (corrlib.load_contour), got {type(query_contour).__name__}")
    token = token or CancelToken()
    if isinstance(meshes, (str, os.PathLike)):  # one folder, not a sequence of one-letter paths
        if not Path(meshes).is_dir():
            raise InputError(f"meshes: {str(meshes)!r} is not a folder; give a collection folder or a list of "
                             f"meshes{lost_working_folder(Path(meshes))}")
        root = Path(meshes) if root is None else root
        meshes = mesh_files(meshes)
    items = collection_items(meshes)
    check_jobs(jobs)
    jobs = jobs or os.cpu_count() or 1
    yield Progress("query features", 0.0)
    query = prepare_query(query_contour, params)
    outline = query_outline(query_contour) if ranking == "fused" else None
    hits: list[RetrievalHit] = []
    if jobs == 1 and scheduler is None:
        for item in items:
            token.raise_if_cancelled()
            hits.append(_match_one(query, item, params, outline))
            hits[-1].root = root
            yield Progress("matching", len(hits) / len(items), hits[-1].measured())
    else:
        with job_executor(min(jobs, len(items)), scheduler) as pool:
            pending = {pool.submit(_match_one, query, item, params, outline) for item in items}
            try:
                while pending:
                    done, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                    token.raise_if_cancelled()
                    for fut in done:
                        hits.append(fut.result())
                        hits[-1].root = root
                        yield Progress("matching", len(hits) / len(items), hits[-1].measured())
            finally:
                for fut in pending:
                    fut.cancel()
    if all(hit.left_out for hit in hits):
        raise InputError(f"no 3D mesh to rank: every one of the {len(hits)} meshes is flat ({FLAT_CANDIDATE})")
    hits = [hit for hit in hits if not hit.left_out]
    energies = [h.energy for h in hits]
    scores = fused_scores(energies, [h.view_distance for h in hits]) if ranking == "fused" else energies
    for hit, score in zip(hits, scores):
        hit.score = float(score)
    hits.sort(key=lambda h: (h.score, h.name))
    return hits


def average_precision(ranked_labels: list[str], relevant: str) -> float:
    """Average precision of a ranking for the class ``relevant`` (0 if it never occurs)."""
    hits, total = 0, 0.0
    for rank, label in enumerate(ranked_labels, 1):
        if label == relevant:
            hits += 1
            total += hits / rank
    return total / hits if hits else 0.0


#: results the E-measure reads (the Princeton Shape Benchmark's choice, :func:`ranking_measures`)
E_MEASURE_RESULTS = 32
#: the measures of :func:`ranking_measures`, in the order the benchmark reports them
RANKING_MEASURES = ("nn", "first_tier", "second_tier", "e_measure", "dcg")


def ranking_measures(ranked_labels: list[str], relevant: str) -> dict[str, float]:
    """The Princeton Shape Benchmark's measures of one ranking (Shilane, Min, Kazhdan, Funkhouser, *The
    Princeton Shape Benchmark*, SMI 2004), which the SHREC sketch-based retrieval tracks report beside the mean
    average precision (Li et al., SHREC'13/'14).

    With ``C`` the number of meshes of the class ``relevant`` in the ranking (the query is not in the
    collection, so all of them count) and ``r(k)`` the number of them among the first ``k``:

    * ``nn``: 1 if the first mesh is of the class, else 0 (nearest-neighbour precision);
    * ``first_tier``, ``second_tier``: ``r(C) / C`` and ``r(2C) / C`` (recall within the first ``C`` and ``2C``);
    * ``e_measure``: ``2 / (1/P + 1/R)`` of the first ``k = min(32, n)`` results, with ``P = r(k)/k`` and
      ``R = r(k)/C``, i.e. ``2 r(k) / (k + C)`` (0 where ``r(k) = 0``);
    * ``dcg``: ``G_1 + Σ_{i≥2} G_i / log2 i`` (``G_i`` 1 for a mesh of the class) divided by its value for the
      ideal ranking, all ``C`` first (1 for a perfect ranking).

    Returns
    -------
    dict
        The five measures (:data:`RANKING_MEASURES`), NaN where the ranking holds no mesh of the class.
    """
    gains = np.array([label == relevant for label in ranked_labels], dtype=float)
    members = int(gains.sum())
    if members == 0:
        return dict.fromkeys(RANKING_MEASURES, float("nan"))
    found = np.cumsum(gains)  # r(k) at index k - 1
    k = min(E_MEASURE_RESULTS, gains.size)
    discounts = 1.0 / np.log2(np.maximum(np.arange(1, gains.size + 1), 2))  # 1, 1/log2 2, 1/log2 3, ...
    return {"nn": float(gains[0]), "first_tier": float(found[members - 1] / members),
            "second_tier": float(found[min(2 * members, gains.size) - 1] / members),
            "e_measure": float(2.0 * found[k - 1] / (k + members)),
            "dcg": float(gains @ discounts / discounts[:members].sum())}


#: recall levels of the interpolated precision–recall curve (:func:`interpolated_precision`: the 11 levels of
#: TREC and of the SHREC retrieval tracks' diagrams)
RECALL_LEVELS = np.linspace(0.0, 1.0, 11)


def interpolated_precision(ranked_labels: list[str], relevant: str) -> np.ndarray:
    """(11,) float: the interpolated precision of a ranking at :data:`RECALL_LEVELS` (NaN where the ranking holds
    no mesh of the class ``relevant``).

    After the ``k``-th result the precision is ``r(k)/k`` and the recall ``r(k)/C`` (``r(k)`` meshes of the class
    among the first ``k``, ``C`` in all); the interpolated precision at recall level ``ρ`` is the highest precision
    at any recall ``≥ ρ`` (Manning, Raghavan, Schütze, *Introduction to Information Retrieval*, 2008, §8.4), so
    the curve never rises and a ranking with every member first is 1 at every level.
    """
    gains = np.array([label == relevant for label in ranked_labels], dtype=float)
    members = gains.sum()
    if members == 0:
        return np.full(RECALL_LEVELS.size, np.nan)
    found = np.cumsum(gains)
    precision = found / np.arange(1, gains.size + 1)
    recall = found / members
    # the highest precision at this recall or beyond, then read at the first rank that reaches each level
    best_after = np.maximum.accumulate(precision[::-1])[::-1]
    reached = np.searchsorted(recall, RECALL_LEVELS - 1e-12, side="left")
    return best_after[reached]


def ap_without(ranked_names: list[str], ranked_labels: list[str], left_out: str, relevant: str) -> float:
    """:func:`average_precision` of a ranking with the mesh named ``left_out`` taken out of it; NaN where no mesh
    of the class ``relevant`` is left (the precision of a class without members is undefined, not 0)."""
    labels = [label for name, label in zip(ranked_names, ranked_labels) if name != left_out]
    return average_precision(labels, relevant) if relevant in labels else float("nan")


def read_own_meshes(path, query_names, mesh_names) -> dict[str, str]:
    """The mesh of the collection that each listed query was made from (``corr bench-retrieval --own-meshes``).

    A query rendered from a mesh of the collection finds that mesh first at almost no cost, so its average
    precision as given says little; ranked with that mesh left out (:func:`ap_without`) it says how the query
    ranks the *other* members of its class (an outline against the shape's other poses). The file has one
    line ``QUERY MESH`` per listed query; whatever follows the two names is ignored (so that
    ``scripts/retrieval_views.py``'s ``views.txt`` serves as it is), as are blank lines and ``#`` comments.
    Names are those the benchmark gives (:func:`collection_name`: the path within the folder).

    Returns
    -------
    dict
        ``{query name: mesh name}``.

    Raises
    ------
    InputError
        Naming the file (and line) where it cannot be read, a line has fewer than two names, a query or mesh
        is not in the benchmark, a query is listed twice, or no query is listed.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the own-mesh list ({exc}){lost_working_folder(path)}") from None
    queries, meshes, own = set(query_names), set(mesh_names), {}
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        where = f"{path}, line {number}"
        if len(words) < 2:
            raise InputError(f"{where}: expected 'QUERY MESH' (the query and the mesh it was made from), "
                             f"got {line.strip()!r}")
        query, mesh = words[:2]
        if query not in queries:
            raise InputError(f"{where}: no query {query!r} among the queries")
        if mesh not in meshes:
            raise InputError(f"{where}: no mesh {mesh!r} in the collection")
        if query in own:
            raise InputError(f"{where}: query {query!r} is listed a second time")
        own[query] = mesh
    if not own:
        raise InputError(f"{path}: lists no query (expected lines 'QUERY MESH')")
    return own


#: resamples of the bootstrap interval of a MAP (:func:`map_interval`): with another seed its ends move by a
#: standard deviation of 0.001-0.003 on the bundled retrieval sets (21 and 60 queries)
BOOTSTRAP_RESAMPLES = 4000


def map_interval(aps, level: float = 0.95, resamples: int = BOOTSTRAP_RESAMPLES,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``aps`` over the choice of queries.

    The queries are drawn again with replacement ``resamples`` times and the interval holds the central
    ``level`` of the resampled means (Efron & Tibshirani, *An Introduction to the Bootstrap*, 1993, ch. 13).
    It says how much a MAP depends on which queries a benchmark happens to hold: two settings whose
    intervals overlap widely are not told apart by that set. Deterministic (a fixed ``seed``).

    Parameters
    ----------
    aps : (q,) float
        Average precision of every answered query.

    Returns
    -------
    (low, high) : float
    """
    aps = np.asarray(aps, dtype=float)
    if aps.ndim != 1 or aps.size == 0:
        raise InputError(f"map_interval needs one finite AP per query, got an array of shape {aps.shape}")
    if not np.all(np.isfinite(aps)):
        raise InputError(f"map_interval needs one finite AP per query, got {int(np.sum(~np.isfinite(aps)))} "
                         f"that are not finite")
    if not 0.0 < level < 1.0:
        raise ParameterError(f"level must lie in (0, 1), got {level}")
    if isinstance(resamples, bool) or not isinstance(resamples, (int, np.integer)) or resamples < 1:
        raise ParameterError(f"resamples must be a whole number of at least 1, got {resamples!r}")
    rng = np.random.default_rng(seed)
    means = aps[rng.integers(0, aps.size, size=(resamples, aps.size))].mean(axis=1)
    low, high = np.quantile(means, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return float(low), float(high)


def class_margin(labels: list[str], scores, relevant: str) -> float:
    """Relative margin of a ranking: ``(S_o − S_r) / ((S_o + S_r) / 2)``.

    ``S_r`` is the lowest score (:attr:`RetrievalHit.score`: energy, or energy times view dissimilarity) of a
    mesh of the query's class, ``S_o`` the lowest of any other class (meshes that could not be matched, at
    infinite score, do not count). Positive: the query's class comes first, by that fraction of the score;
    negative: another class does. It tells a decisive ranking from a near-tie that the AP alone does not show.

    Returns
    -------
    float
        In ``(−2, 2)``; NaN where either class has no matched mesh.
    """
    scores = np.asarray(scores, dtype=float)
    mine = np.array([label == relevant for label in labels], dtype=bool)
    finite = np.isfinite(scores)
    if not (np.any(mine & finite) and np.any(~mine & finite)):
        return float("nan")
    s_r, s_o = float(scores[mine & finite].min()), float(scores[~mine & finite].min())
    mean = (s_o + s_r) / 2.0
    return (s_o - s_r) / mean if mean > 0 else 0.0


def mean_average_precision(rankings: list[tuple[str, list[str]]]) -> float:
    """Mean of :func:`average_precision` over ``(query class, ranked labels)`` pairs."""
    if not rankings:
        raise InputError("no rankings to average")
    return float(np.mean([average_precision(labels, cls) for cls, labels in rankings]))


def write_ranking(hits, out: Path, pictures: int) -> list[Path]:
    """Write a ranking (:func:`retrieve`'s hits) as TSV at ``out`` and, for the first ``pictures`` ranks that
    were matched, the query and its matched curve on the mesh (``STEM.RANK-MESH.png`` beside it), as one set:
    pictures that an earlier ranking of these meshes wrote under the same stem go, with or without new ones
    (they would show other ranks). Returns the files written."""
    import csv

    from corrlib.io import staged_output

    picture = re.compile(re.escape(out.stem) + r"\.[0-9]+-(.+)\.png")
    meshes = {picture_key(hit.name) for hit in hits} | _ranked_mesh_keys(out)

    def earlier_picture(name: str) -> bool:
        match = picture.fullmatch(name)
        return match is not None and match.group(1) in meshes

    with staged_output(out.parent, replaces=earlier_picture) as stage:
        written = [stage / out.name]
        with open(written[0], "w", encoding="utf-8", errors="surrogateescape", newline="") as fh:
            table = csv.writer(fh, delimiter="\t", lineterminator="\n")  # quotes a name with a tab or line break
            table.writerow(["rank", "energy", "mesh", "error", "name", "score", "view_distance", "curve_length_ratio"])
            for rank, hit in enumerate(hits, 1):
                table.writerow([rank, f"{hit.energy:.9g}", hit.path, hit.error, hit.name, f"{hit.score:.9g}",
                                f"{hit.view_distance:.9g}", f"{hit.curve_length_ratio:.4g}"])
        for rank, hit in enumerate(hits[:pictures], 1):
            if hit.error:
                continue
            from corrlib.plotting import save_contour_match

            written.append(save_contour_match(stage / picture_name(out, rank, pictures, hit.name),
                                              hit.contour_points, load_mesh(hit.path), hit.path_vertices,
                                              hit.path_contour_index,
                                              title=f"rank {rank}: {hit.name}, energy {hit.energy:.4g}"))
    return [out.parent / path.name for path in written]


def picture_key(name: str) -> str:
    """The part of a picture's file name that names a mesh of the collection (its :func:`collection_name`):
    the name without suffix, its folders joined by ``-`` (``cat/0.off`` -> ``cat-0``)."""
    return "-".join(Path(name).with_suffix("").parts)


def picture_name(out: Path, rank: int, pictures: int, mesh: str) -> str:
    """``STEM.RANK-MESH.png``, the picture of rank ``rank`` (of ``pictures``, zero-padded to their width) of the
    ranking ``out`` (:func:`write_ranking`) for the mesh named ``mesh`` in the collection (:func:`picture_key`)."""
    return f"{out.stem}.{rank:0{len(str(pictures))}d}-{picture_key(mesh)}.png"


def check_picture_names(out: Path, meshes, pictures: int, root=None) -> None:
    """Before a retrieval: an :class:`InputError` naming a mesh (a path, in the collection ``root``) whose
    picture's name (:func:`picture_name`) the ranking's folder cannot hold, instead of a failure after the
    whole retrieval."""
    import os

    from corrlib.outputs import longest_file_name

    longest = longest_file_name(out.parent)
    for mesh in meshes:
        name = picture_name(out, pictures, pictures, collection_name(mesh, root))
        if len(os.fsencode(name)) > longest:
            raise InputError(f"{mesh}: the picture of this mesh, {name}, is a longer file name than {out.parent} "
                             f"takes here ({longest} bytes); shorten the ranking's name (-o) or the mesh's")


def _ranked_mesh_keys(ranking: Path) -> set[str]:
    """The :func:`picture_key` of the meshes an earlier ranking at ``ranking`` (a TSV written by ``corr
    retrieve``; by their names in the collection, or their file names in a ranking without that column)
    holds; none where there is no readable one."""
    import csv

    try:
        with open(ranking, encoding="utf-8", newline="") as fh:
            rows = list(csv.reader(fh, delimiter="\t"))
    except (OSError, UnicodeDecodeError, csv.Error):
        return set()
    if not rows or rows[0][:3] != ["rank", "energy", "mesh"]:
        return set()
    named = len(rows[0]) > 4 and rows[0][4] == "name"
    return {picture_key(row[4] if named and len(row) > 4 else Path(row[2]).name) for row in rows[1:] if len(row) > 2}
