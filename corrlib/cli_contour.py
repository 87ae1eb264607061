"""The ``corr`` commands of 2D-to-3D matching: ``match-contour``, ``retrieve``, ``bench-retrieval`` and
``bench-contour``, with their parsers (:func:`corrlib.cli.build_parser` places them in its list).

Bad input raises :class:`~corrlib.errors.CorrError`, which :func:`corrlib.cli.main` prints as ``error: ...``
with exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from corrlib.cli_common import (add_output, add_scale_out, check_output_stem, command, match_output_names,
                                parse_overrides, print_result_notes, progress_printer, say_failures,
                                stage_match_pictures, warned, with_options)
from corrlib.errors import CorrError, FileFormatError


#: help of the contour commands' --n-contour (the value is Contour3DParams.n_contour; not imported here, so that
#: `corr --help` does not load the method)
N_CONTOUR_HELP = "contour resampling (default 200, the method's)"


#: corrlib.retrieval.RANKINGS, named here so that building the parser does not import the retrieval module
RANKING_CHOICES = ("fused", "energy")


def add_ranking(p: argparse.ArgumentParser) -> None:
    """``--ranking`` of the retrieval commands (corrlib.retrieval.retrieve)."""
    p.add_argument("--ranking", choices=RANKING_CHOICES, default=RANKING_CHOICES[0],
                   help="fused (default): the matching energy times the drawing's dissimilarity to the mesh's "
                        "rendered views; energy: the matching energy alone (the thesis' ranking)")


def query_contour(path: str, labels: str | None = None):
    """The query of a 2D-to-3D command: a contour file, SVG or image, or a planar sketch mesh (its longest
    boundary loop), with its part labels from ``labels`` (one per contour point or per sketch vertex)."""
    from corrlib.io import load_shape
    from corrlib.shapes import Contour2D, TriMesh, sketch_outline

    contour = sketch = load_shape(path)
    if isinstance(sketch, TriMesh):
        contour, loop = sketch_outline(sketch)
    if labels:
        from corrlib.io import load_labels

        values = load_labels(labels, what="--query-labels")
        if isinstance(sketch, TriMesh) and values.shape[0] == sketch.n_vertices:
            values = values[loop]  # per-vertex labels of the sketch mesh
        if values.shape[0] != contour.n_points:
            expected = f"{contour.n_points} (one per contour point)" + (
                f" or {sketch.n_vertices} (one per sketch vertex)" if isinstance(sketch, TriMesh) else "")
            raise FileFormatError(f"{labels}: the --query-labels file has {values.shape[0]} labels, expected "
                                  f"{expected} for {contour.name}")
        contour = Contour2D(contour.points, name=contour.name, labels=values)
    return contour


def contour3d_params(args, *, retrieval: bool = False):
    """``contour3d`` parameters from ``--param`` and the options ``--eps``, ``--k``, ``--n-contour``: the
    method's defaults, or a retrieval's (:func:`corrlib.retrieval.retrieval_params`) if ``retrieval``."""
    overrides = with_options(parse_overrides(args.param or []), args,
                              {"eps": "--eps", "k": "--k", "n_contour": "--n-contour"})
    if retrieval:
        from corrlib.retrieval import retrieval_params

        return retrieval_params(**overrides)
    from corrlib.methods.base import make_params
    from corrlib.methods.contour3d import Contour3DParams

    return make_params(Contour3DParams, **overrides)


def cmd_match_contour(args) -> int:
    """``corr match-contour``: one contour matched to one mesh by ``contour3d``, the result files written."""
    from corrlib.io import load_mesh
    from corrlib.methods import solve

    out = check_output_stem(args, [("query", args.query), ("mesh", args.mesh), ("--query-labels", args.query_labels),
                                    ("--mesh-labels", args.mesh_labels)])
    contour = query_contour(args.query, args.query_labels)
    mesh = warned(load_mesh(args.mesh))
    if args.mesh_labels:
        from corrlib.io import load_labels

        mesh = mesh.with_labels(load_labels(args.mesh_labels, mesh.n_vertices, what="--mesh-labels"))
    result = solve("contour3d", contour, mesh, contour3d_params(args), callback=progress_printer(args.quiet))
    search = result.search
    print(f"energy {result.energy:.6g} (lower bound {search.lower_bound:.6g}, "
          f"{search.describe()}), {search.iterations} branch-and-bound "
          f"iterations, {search.dijkstra_runs} layered Dijkstra runs of {search.seconds_per_dijkstra:.3f} s, "
          f"{result.timings['total']:.2f} s in total")
    print_result_notes(result)  # e.g. a mesh matched as given because it could not be remeshed
    from corrlib.io import staged_output

    with staged_output(out.parent, replaces=match_output_names(out.name).__contains__) as stage:
        staged = [*result.save(stage / out.name), *stage_match_pictures(result, contour, mesh, stage / out.name)]
    if not args.quiet:
        for written in staged:
            print(f"wrote {out.parent / Path(written).name}")
    return 0


def cmd_retrieve(args) -> int:
    """``corr retrieve``: the meshes of a folder ranked for a query contour."""
    import numpy as np

    from corrlib.progress import run
    from corrlib.retrieval import (check_picture_names, class_of, mean_average_precision, mesh_files, retrieve,
                                   write_ranking)

    if args.top < 1:
        raise CorrError(f"--top must be at least 1, got {args.top}")
    if args.pictures and not args.output:
        raise CorrError("--pictures writes its pictures beside the ranking: give the ranking's file with -o")
    files = mesh_files(args.folder)
    if args.output:
        from corrlib.io import check_output_file, check_outputs_apart

        check_output_file(args.output, "-o")
        check_outputs_apart([("-o", args.output)], [("the query", args.query),
                                                     *[("a mesh of the folder", path) for path in files]])
        if args.pictures:
            check_picture_names(Path(args.output), files, args.top, args.folder)
    contour = query_contour(args.query)
    params = contour3d_params(args, retrieval=True)
    hits = run(retrieve(contour, files, params, jobs=args.jobs, scheduler=args.scheduler, root=args.folder,
                        ranking=args.ranking), callback=progress_printer(args.quiet))
    written = write_ranking(hits, Path(args.output), args.top if args.pictures else 0) if args.output else []
    print(f"{'rank':>4}  {'score':>8}  {'energy':>12}  {'views':>7}  {'seconds':>7}  mesh")
    for rank, hit in enumerate(hits[: args.top], 1):
        said = hit.error or hit.collapse_note()
        extra = f"  ({said})" if said else ""
        views = f"{hit.view_distance:.4f}" if np.isfinite(hit.view_distance) else "-"  # not measured
        print(f"{rank:>4}  {hit.score:>8.4g}  {hit.energy:>12.6g}  {views:>7}  {hit.seconds:>7.2f}  {hit.name}{extra}")
    query_class = class_of(args.query)
    labels = [h.label for h in hits]
    if query_class in labels:
        print(f"average precision for class {query_class!r}: "
              f"{mean_average_precision([(query_class, labels)]):.4f}")
    for path in written:
        print(f"wrote {path}")
    failed = sum(1 for hit in hits if hit.error)
    if failed:  # as corr bench: exit 1 when a mesh could not be ranked, with every reason above
        print(f"error: {failed} of {len(hits)} meshes could not be matched"
              f"{' (none ranked)' if failed == len(hits) else ''}; see the reasons above", file=sys.stderr)
        return 1
    return 0


def cmd_bench_retrieval(args) -> int:
    """``corr bench-retrieval``: a folder of queries against a collection, MAP and per-class AP."""
    from corrlib.bench import retrieval_benchmark
    from corrlib.io import ensure_output_folder

    params = contour3d_params(args, retrieval=True)  # named errors before any work
    ensure_output_folder(args.output, "-o")  # named as the option; the library checks the rest before any query

    failures = []

    def progress(done, total, row):
        if row["error"]:
            failures.append(f"{row['query']}: {row['error']}")
        if not args.quiet:
            what = f"AP {row['ap']:.3f}" if not row["error"] else f"FAILED: {row['error']}"
            print(f"  [{done}/{total}] {row['query']} ({row['class']}): {what}", file=sys.stderr)

    summary = retrieval_benchmark(args.queries, args.collection, args.output, params=params, jobs=args.jobs,
                                  scheduler=args.scheduler, callback=progress, ranking=args.ranking,
                                  own_meshes=args.own_meshes)
    print((Path(args.output) / "retrieval_summary.md").read_text(encoding="utf-8"))
    say_failures(failures, Path(args.output) / "retrieval.csv")
    return 0 if summary["failed"] == 0 and not summary["failed_meshes"] else 1


def cmd_bench_contour(args) -> int:
    """``corr bench-contour``: plane-section, sketch and drawing queries matched to the meshes of datasets."""
    from corrlib.contour_bench import contour_benchmark

    params = with_options(parse_overrides(args.param or []), args, {"n_contour": "--n-contour"})
    planes = [p.strip() for p in args.planes.split(",") if p.strip() and p.strip() != "none"]

    failures = []

    def progress(done, total, row):
        if row["status"] not in ("ok", "skipped"):
            failures.append(f"{row['query']} -> {row['target']}: {row['error']}")
        if args.quiet or row["status"] == "skipped":
            return
        if row["status"] != "ok":
            what = f"FAILED: {row['error']}"
        elif row["plane"] == "sketch":
            what = (f"part agreement {row['part_agreement']:.2f} (mirror accepted {row['part_agreement_sym']:.2f}), "
                    f"{row['seconds']:.1f} s")
        elif row["plane"] == "drawn":
            redrawn = f", redrawn {row['redraw_error']:.3f} (worst {row['redraw_worst']:.3f})" if row["redraws"] else ""
            what = f"landmark error {row['landmark_error']:.3f}{redrawn}, {row['seconds']:.1f} s"
        else:
            what = f"mean error {row['mean_error']:.3f}, coverage {row['coverage']:.2f}, {row['seconds']:.1f} s"
        print(f"  [{done}/{total}] {row['query']} -> {row['target']}: {what}", file=sys.stderr)

    summary = contour_benchmark(args.datasets, args.output, planes=planes, params=params, jobs=args.jobs,
                                scheduler=args.scheduler, pictures=not args.no_pictures, callback=progress,
                                sketches=args.sketches or (), drawings=args.drawn or (), redraws=args.redraws,
                                method=args.method)
    print((Path(args.output) / "contour_summary.md").read_text(encoding="utf-8"))
    say_failures(failures, Path(args.output) / "contour_bench.csv")
    failed = summary["all"]["failed"] + summary.get("sketches", {}).get("failed", 0) + \
        summary.get("drawings", {}).get("all", {}).get("failed", 0)
    return 0 if failed == 0 else 1


def add_retrieve_parser(sub) -> None:
    """``retrieve``."""
    p = command(sub, "retrieve", "rank the meshes of a folder against a query contour",
                 "Rank the meshes of a folder for a query contour: by its matching energy and its likeness to "
                 "each mesh's rendered views (--ranking).", func=cmd_retrieve)
    p.add_argument("query")
    p.add_argument("folder", help="the collection: meshes in it and its subfolders; a subfolder per class "
                                  "(cat/0.off) or class names in the file names (cat0.off)")
    p.add_argument("--top", type=int, default=10, help="how many ranks to print")
    add_scale_out(p)
    p.add_argument("--eps", type=float, default=0.0,
                   help="approximation factor (default 0: rank by the exact optima)")
    p.add_argument("--k", type=int)
    p.add_argument("--n-contour", dest="n_contour", type=int, help=N_CONTOUR_HELP)
    p.add_argument("--param", action="append", metavar="NAME=VALUE")
    add_ranking(p)
    p.add_argument("--pictures", action="store_true",
                   help="also write, beside the ranking (-o), the query and its matched curve on each of the --top "
                        "meshes (STEM.RANK-MESH.png)")
    add_output(p, None, "write the full ranking as TSV (with --pictures, the pictures of an earlier ranking of "
                         "these meshes under its name are replaced)")


def add_match_contour_parser(sub) -> None:
    """``match-contour``."""
    p = command(sub, "match-contour", "match a closed 2D contour to a mesh (2D-to-3D)",
                 "2D-to-3D elastic matching of a closed contour to a mesh.", func=cmd_match_contour)
    p.add_argument("query", help="contour: point file, SVG, silhouette image or planar sketch mesh")
    p.add_argument("mesh")
    p.add_argument("--eps", type=float, help="approximation factor (0 = global optimum)")
    p.add_argument("--k", type=int, help="Laplace-Beltrami eigenpairs for the features (default 25)")
    p.add_argument("--n-contour", dest="n_contour", type=int, help=N_CONTOUR_HELP)
    p.add_argument("--query-labels", help="part label per contour point (or per sketch-mesh vertex)")
    p.add_argument("--mesh-labels", help="part label per mesh vertex")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="other method parameter")
    add_output(p, "contour_match")


def add_contour_bench_parsers(sub) -> None:
    """``bench-retrieval`` and ``bench-contour``."""
    p = command(sub, "bench-retrieval", "retrieval benchmark: mean average precision",
                 "Retrieval benchmark: queries against a collection, MAP and per-class average precision.",
                 func=cmd_bench_retrieval)
    p.add_argument("queries", help="folder of silhouette images / contour files (class = name without number)")
    p.add_argument("collection", help="folder of meshes (class = name without number)")
    add_scale_out(p)
    p.add_argument("--eps", type=float, default=0.0,
                   help="approximation factor (default 0: rank by the exact optima)")
    p.add_argument("--n-contour", dest="n_contour", type=int, help=N_CONTOUR_HELP)
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="another contour3d parameter (repeatable)")
    p.add_argument("--own-meshes", dest="own_meshes", metavar="FILE",
                   help="lines 'QUERY MESH': the mesh of the collection each listed query was made from (e.g. "
                        "rendered); each is also scored with that mesh left out of its ranking, and the MAP of the "
                        "queries not listed is given apart (scripts/retrieval_set.py writes OUT/sources.txt, "
                        "scripts/retrieval_views.py OUT/views.txt)")
    add_ranking(p)
    add_output(p, "retrieval_output", "output folder")

    p = command(sub, "bench-contour", "2D-to-3D benchmark with plane-section queries",
                 "2D-to-3D benchmark: plane-section queries with ground truth matched to their mesh and to the "
                 "other poses of its class.", func=cmd_bench_contour)
    p.add_argument("datasets", nargs="+", help="dataset folders (the layouts of 'corr bench'; the class of a mesh "
                                                "is its name without a trailing number)")
    p.add_argument("--planes", default="main,symmetry,silhouette",
                   help="comma-separated queries: the sections main, symmetry, cross, the side-view "
                        "silhouette and the top-view outline top, or none (default: main,symmetry,silhouette)")
    p.add_argument("--sketches", action="append", metavar="FOLDER",
                   help="folder of labelled sketches (NAME_contour.txt, NAME.off, NAME_segmentation.txt), matched "
                        "to every mesh with part labels (MESH_segmentation.txt) and scored by part agreement "
                        "(repeatable)")
    p.add_argument("--drawn", action="append", metavar="FOLDER",
                   help="folder of drawings with landmarks (NAME.txt, NAME.landmarks: 'label x y' per line), matched "
                        "to every mesh with landmarks (MESH.landmarks: 'label vertex') and scored by the geodesic "
                        "error at the landmarks (repeatable)")
    p.add_argument("--redraws", type=int, default=0,
                   help="with --drawn: also match this many redrawn variants of each drawing (every point moved "
                        "by 1 %% of its size) and report their mean and worst landmark error (0-100, default 0)")
    p.add_argument("--method", default="contour3d",
                   help="the 2D-to-3D method: contour3d (default) or contour-views (the drawing read as a view)")
    p.add_argument("--n-contour", dest="n_contour", type=int, help="contour points (default: the method's)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="a parameter of the method (repeatable)")
    p.add_argument("--no-pictures", action="store_true", help="do not write a picture per query")
    add_scale_out(p)
    add_output(p, "contour_bench_output", "output folder")
