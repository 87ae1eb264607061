"""The ``corr`` command line.

Subcommands (``corr --help`` lists them with one line each): ``info``, ``eval``, ``match``,
``match-contour``, ``match-contours``, ``retrieve``, ``bench``, ``bench-retrieval``,
``bench-contour``, ``refine``, ``morph``, ``demo``, ``methods``, ``perf``.
Bad input prints ``error: <message>`` on stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from corrlib.errors import CorrError, FileFormatError

EXIT_BAD_INPUT = 2
#: the exit status of a command whose standard output was closed by its reader (128 + SIGPIPE, as the shell's)
EXIT_BROKEN_PIPE = 141
#: help of the retrieval commands' --n-contour (the value is corrlib.retrieval.RETRIEVAL_N_CONTOUR; not imported
#: here, so that `corr --help` does not load the method)
RETRIEVAL_N_CONTOUR_HELP = "contour resampling (default 100, the retrieval default of the studio and the CLI)"


# ----------------------------------------------------------------------------- info


def _info_mesh(path: Path) -> tuple[dict, str | None]:
    """Statistics and findings of a mesh loaded exactly as ``corr match`` loads it (:func:`corrlib.io.load_mesh`).

    Returns the report and, when ``load_mesh`` refuses the content, its error message (the
    report then lists every finding of the arrays the file holds). Unreadable files raise.
    """
    from corrlib.errors import MeshError
    from corrlib.io import load_mesh, read_mesh_arrays
    from corrlib.shapes import inspect_mesh

    try:
        mesh = load_mesh(path)
    except MeshError as exc:
        vertices, faces = read_mesh_arrays(path)
        findings = inspect_mesh(vertices, faces)
        info = {"file": str(path), "kind": "mesh", "vertices": len(vertices), "faces": len(faces),
                "valid": False}
        return _with_findings(info, findings), str(exc)
    info = {"file": str(path), "kind": "mesh", "vertices": mesh.n_vertices, "faces": mesh.n_faces, "valid": True,
            "area": mesh.area, "bbox_diagonal": mesh.bbox_diagonal, "closed": mesh.is_closed,
            "boundary_loops": len(mesh.boundary_loops), "mean_edge_length": float(mesh.edge_lengths.mean()),
            "enclosed_volume": mesh.enclosed_volume()}
    return _with_findings(info, mesh.report()), None


def _with_findings(info: dict, findings) -> dict:
    info["findings"] = [{"level": fd.level, "code": fd.code, "message": fd.message} for fd in findings]
    return info


def _info_contour(path: Path) -> dict:
    from corrlib.io import load_contour

    contour = load_contour(path)
    return {"file": str(path), "kind": "contour", "points": contour.n_points, "length": contour.length,
            "area": contour.area, "orientation": "counter-clockwise (after loading)", "valid": True,
            "findings": []}


def cmd_info(args) -> int:
    from corrlib.io import lost_working_folder, shape_kind

    path = Path(args.file)
    if not path.exists():
        raise FileFormatError(f"{path}: file not found{lost_working_folder(path)}")
    info, error = _info_mesh(path) if shape_kind(path) == "mesh" else (_info_contour(path), None)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        for key, value in info.items():
            if key == "findings":
                continue
            print(f"{key:>16}: {value:.6g}" if isinstance(value, float) else f"{key:>16}: {value}")
        for fd in info["findings"]:
            print(f"{fd['level']:>16}: [{fd['code']}] {fd['message']}")
        if not info["findings"]:
            print(f"{'validation':>16}: no problems found")
    if error is not None:  # the same message as 'corr match' gives for this file
        print(f"error: {error}", file=sys.stderr)
    return 0 if info["valid"] else EXIT_BAD_INPUT


def cmd_repair(args) -> int:
    from corrlib.repair import index_file, repair_file

    result = repair_file(args.mesh, args.output)
    for note in result.notes or ["no repair was needed"]:
        print(f"{Path(args.mesh).name}: {note}")
    for warning in result.warnings:  # what the loader still says and no repair here removes
        print(f"warning: {Path(args.mesh).name}: {warning}", file=sys.stderr)
    print(f"wrote {args.output} ({len(result.vertices)} vertices, {len(result.faces)} faces) and "
          f"{index_file(args.output)} (the input vertex of each vertex, one per line)")
    return 0


# ----------------------------------------------------------------------------- eval


def cmd_eval(args) -> int:
    import numpy as np

    from corrlib.evaluation import cumulative_curve, matched_errors
    from corrlib.io import check_output_file, check_outputs_apart, load_map, load_mesh, load_vts

    outputs = [(option, value) for option, value in (("--errors", args.errors), ("--plot", args.plot)) if value]
    for option, value in outputs:
        check_output_file(value, option)
    check_outputs_apart(outputs, [("the map", args.map), ("--gt-source", args.gt_source),
                                  ("--gt-target", args.gt_target), ("--target", args.target),
                                  ("--gt-target-sym", args.gt_target_sym)])
    target = load_mesh(args.target)
    map_xy = load_map(args.map, n_target=target.n_vertices, allow_unmatched=True)
    gt_source = load_vts(args.gt_source)
    if gt_source.max() >= map_xy.shape[0]:
        raise FileFormatError(f"{args.map}: the map has {map_xy.shape[0]} entries, but the ground truth "
                              f"{args.gt_source} refers to source vertex {gt_source.max()} (is the map short, or "
                              f"for another source?)")
    gt_target = load_vts(args.gt_target, target.n_vertices)
    gt_sym = load_vts(args.gt_target_sym, target.n_vertices) if args.gt_target_sym else None
    for option, path, rows in (("--gt-target", args.gt_target, gt_target),
                               ("--gt-target-sym", args.gt_target_sym, gt_sym)):
        if rows is not None and rows.shape != gt_source.shape:  # row i of each names one point of the truth
            raise FileFormatError(f"{path} ({option}) has {rows.size} rows, but {args.gt_source} (--gt-source) has "
                                  f"{gt_source.size}; the ground-truth files must have one row per corresponding "
                                  "point")
    start = time.perf_counter()
    report, matched = matched_errors(map_xy, target, gt_source, gt_target, gt_target_sym=gt_sym,
                                     normalize=args.normalize, method=args.geodesics)
    if report is None:
        raise FileFormatError(f"{args.map}: every ground-truth row's source vertex is unmatched (-1)")
    elapsed = time.perf_counter() - start
    summary = report.summary()
    summary["rows"] = int(report.errors.size)
    if not matched.all():  # a partial map: its errors where it matches, and how much of the truth it leaves out
        summary["unmatched_rows"] = int(np.count_nonzero(~matched))
    summary["seconds"] = elapsed
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for key, value in summary.items():
            print(f"{key:>18}: {value:.4f}" if isinstance(value, float) else f"{key:>18}: {value}")
    written = []
    try:  # both files or neither
        if args.errors:
            from corrlib.io import atomic_write

            with atomic_write(args.errors) as fh:
                np.savetxt(fh, report.errors, fmt="%.6g")
            written.append(Path(args.errors))
        if args.plot:
            from corrlib.plotting import save_error_curves

            curves = {"direct": cumulative_curve(report.errors, report.thresholds)}
            if report.errors_sym is not None:
                curves["symmetry-aware"] = cumulative_curve(report.errors_sym, report.thresholds)
            save_error_curves(args.plot, curves, report.thresholds)
            written.append(Path(args.plot))
    except BaseException:
        for path in written:
            path.unlink(missing_ok=True)
        raise
    for path in written:
        print(f"wrote {path}")
    return 0


# ----------------------------------------------------------------------------- match / demo


def _load_shape(path: str):
    """A mesh, contour or silhouette from ``path``, its warnings said (:func:`_warned`)."""
    from corrlib.io import load_shape

    return _warned(load_shape(path))


def _warned(shape):
    """``shape``, after what its validation warns of went to stderr (the studio shows the same in its shapes
    panel)."""
    for finding in getattr(shape, "report", lambda: [])():
        if finding.level == "warning":
            print(f"warning: {shape.name}: {finding.message}", file=sys.stderr)
    return shape


def _parse_overrides(pairs: list[str]) -> dict:
    """``--param NAME=VALUE`` items as a dict; a name given twice is refused (the last would win unseen)."""
    out = {}
    for item in pairs or []:
        if "=" not in item:
            raise CorrError(f"parameter {item!r} must be NAME=VALUE")
        key, value = item.split("=", 1)
        if key.strip() in out:
            raise CorrError(f"--param {key.strip()} is given twice ({out[key.strip()]!r} and {value.strip()!r}); "
                            "give it once")
        out[key.strip()] = value.strip()
    return out


def _with_options(overrides: dict, args, options: dict[str, str]) -> dict:
    """``overrides`` with the options that set a parameter (``{parameter: option}``, e.g. ``{"k": "--k"}``) where
    given; a parameter set by both its option and ``--param`` is refused (one would win unseen)."""
    for key, option in options.items():
        value = getattr(args, key, None)
        if value is None:
            continue
        if key in overrides:
            raise CorrError(f"{option} {value} and --param {key}={overrides[key]} both set {key}; give one")
        overrides[key] = value
    return overrides


def _preload_plotting():
    """Start importing the plotting library in a thread; returns it (join before writing the pictures).

    The pictures are written after the solver, and importing matplotlib takes about half a second; the
    solvers spend most of their time in compiled code that releases the GIL, so the import runs alongside.
    """
    import threading

    def load():
        from corrlib.plotting import preload

        preload()

    thread = threading.Thread(target=load, name="preload-plotting", daemon=True)
    thread.start()
    return thread


def _write_match_outputs(result, source, target, out: Path, *, quiet: bool = False, pictures: bool = False) -> None:
    """The result files of a match beside the stem ``out``, all or none of them (the pictures if asked)."""
    from corrlib.io import staged_output

    with staged_output(out.parent, replaces=_match_output_names(out.name).__contains__) as stage:
        written = [out.parent / p.name for p in _stage_match_outputs(result, source, target, stage / out.name,
                                                                     pictures)]
    if not quiet:
        for path in written:
            print(f"wrote {path}")


def _stage_match_outputs(result, source, target, out: Path, pictures: bool) -> list[Path]:
    from corrlib.io import save_map

    npz, js = result.save(out)
    written = [npz, js]
    if result.map_xy is not None:
        written.append(save_map(_beside(out, ".map_xy.txt"), result.map_xy))
    if result.map_yx is not None:
        written.append(save_map(_beside(out, ".map_yx.txt"), result.map_yx))
    if pictures:
        written += _stage_match_pictures(result, source, target, out)
    return [Path(p) for p in written]


def _stage_match_pictures(result, source, target, out: Path) -> list:
    written = []
    if result.energy_trace is not None:
        from corrlib.plotting import save_energy_trace

        written.append(save_energy_trace(_beside(out, ".energy.png"), result.energy_trace,
                                         result.extras.get("tau_trace")))
    from corrlib.shapes import Contour2D, TriMesh

    if result.map_yx is not None and isinstance(source, TriMesh) and isinstance(target, TriMesh):
        from corrlib.plotting import save_colour_transfer

        written.append(save_colour_transfer(_beside(out, ".png"), source, target, result.map_yx,
                                            title=f"{result.method}"))
    elif isinstance(source, Contour2D) and isinstance(target, Contour2D):
        from corrlib.plotting import save_torus_pictures

        written.append(save_torus_pictures(_beside(out, ".png"), result))
    elif isinstance(source, Contour2D) and result.path is not None:  # 2D-to-3D: the query and its curve on the mesh
        from corrlib.plotting import save_contour_match

        path = result.path
        written.append(save_contour_match(_beside(out, ".png"), path.contour_points, target, path.vertices,
                                          path.contour_index, title=f"energy {result.energy:.4g}"))
    return written


#: what a match may write beside its ``-o`` stem (the result, the maps, the pictures)
MATCH_OUTPUT_SUFFIXES = (".npz", ".json", ".map_xy.txt", ".map_yx.txt", ".png", ".energy.png")


def _check_output_stem(args, inputs) -> Path:
    """The ``-o`` stem, checked before any work (its folder created and writable, no folder where one of its
    files goes, and none of its files one of the ``inputs``, ``(role, path)`` pairs)."""
    from corrlib.io import check_output_file, check_outputs_apart

    stem = check_output_file(Path(args.output), "-o")
    for suffix in MATCH_OUTPUT_SUFFIXES:
        check_output_file(_beside(stem, suffix), "-o")
    check_outputs_apart([("-o", _beside(stem, suffix)) for suffix in MATCH_OUTPUT_SUFFIXES], inputs)
    return stem


def _match_output_names(stem: str) -> set[str]:
    """Every file name a match may write beside the stem named ``stem``: a new match replaces them as a set, so that
    an earlier match's picture or reverse map is not left beside the new result."""
    return {stem + suffix for suffix in MATCH_OUTPUT_SUFFIXES}


def _beside(stem: Path, suffix: str) -> Path:
    """The file ``stem`` + ``suffix`` (one of :data:`MATCH_OUTPUT_SUFFIXES`: the ones checked before any work)."""
    if suffix not in MATCH_OUTPUT_SUFFIXES:
        raise ValueError(f"{suffix!r} is not among the suffixes checked before the work")
    return stem.with_name(stem.name + suffix)


def _progress_printer(quiet: bool):
    def callback(report):
        if not quiet:
            frac = f"{100 * report.fraction:5.1f}%" if report.fraction >= 0 else "   ..."
            print(f"  [{frac}] {report.stage} {report.message}", file=sys.stderr)

    return callback


def _init_choices(spec) -> tuple:
    """The named initialisations a method offers (the choices of its ``init`` parameter), e.g. "fmap"."""
    import dataclasses

    for f in dataclasses.fields(spec.params):
        if f.name == "init":
            return tuple(f.metadata.get("choices") or ())
    return ()


def _initial_match(value: str, source, target, spec=None):
    """``--init``: a map file (one target index per source vertex) or a landmarks file (two columns)."""
    from corrlib.io import load_map, load_pairs, read_text
    from corrlib.methods.base import InitialMatch

    path = Path(value)
    if not path.exists():
        if spec is None or not _init_choices(spec):
            raise FileFormatError(f"{path}: --init is not an existing file")
        named = ", ".join(repr(c) for c in _init_choices(spec))
        raise FileFormatError(f"{path}: --init is neither a named initialisation of {spec.name} ({named}) "
                              f"nor an existing file")
    if path.suffix.lower() != ".npz":
        rows = [line.split("#", 1)[0].split() for line in read_text(path, "--init").splitlines()]
        rows = [row for row in rows if row]
        if rows and len(rows[0]) == 2:
            pairs = load_pairs(path, "--init landmarks")
            initial = InitialMatch(landmarks_x=pairs[:, 0], landmarks_y=pairs[:, 1])
            n_x, n_y = getattr(source, "n_vertices", None), getattr(target, "n_vertices", None)
            if n_x is not None and n_y is not None:
                try:
                    initial.pairs(n_x, n_y)
                except CorrError as exc:
                    raise FileFormatError(f"{path}: {exc}") from None
            return initial
    map_xy = load_map(path, n_target=target.n_vertices, n_source=source.n_vertices)
    from corrlib.evaluation import collapse_note

    note = collapse_note(map_xy, source, target, what=f"the initial map {path.name}",
                         advice="it carries no correspondence to refine")
    if note:  # refined all the same (a refinement may recover), but the user should know
        print(f"warning: {note}", file=sys.stderr)
    return InitialMatch(map_xy=map_xy)


def _best_method(source, target):
    """The best-ranked registered method for this pair of inputs (:func:`~corrlib.methods.registry.methods_for`)."""
    from corrlib.methods import methods_for
    from corrlib.methods.registry import kind_of

    specs = methods_for(source, target)
    if not specs:
        raise CorrError(f"no method matches a {kind_of(source)} to a {kind_of(target)} (a contour is matched to a "
                        "mesh, not a mesh to a contour: swap the two inputs)")
    return specs[0]


def cmd_match(args) -> int:
    from corrlib.methods import get_method, solve
    from corrlib.methods.registry import check_inputs

    _check_output_stem(args, [("source", args.source), ("target", args.target), ("--init", args.init)])
    source, target = _load_shape(args.source), _load_shape(args.target)
    overrides = _parse_overrides(args.param)
    spec = get_method(args.method) if args.method else _best_method(source, target)
    check_inputs(spec, source, target)
    initial = None
    if args.init:
        if args.init in _init_choices(spec):
            overrides = _with_options(overrides, args, {"init": "--init"})
        elif spec.refines:
            initial = _initial_match(args.init, source, target, spec)
        else:
            raise CorrError(f"method {spec.name!r} does not take an initial map (--init)")
    if args.times:
        overrides = _with_options(overrides, args, {"times": "--times"})
    plotting = _preload_plotting() if args.pictures else None
    result = solve(spec, source, target, callback=_progress_printer(args.quiet), initial=initial, **overrides)
    if plotting is not None:
        plotting.join()
    # the files first: a closed or full standard output must not cost the result
    _write_match_outputs(result, source, target, Path(args.output), quiet=args.quiet, pictures=args.pictures)
    print(f"method {result.method}: energy {result.energy}, {result.timings.get('total', 0):.2f} s")
    if result.search is not None:
        print(f"path search: {result.search.describe()}")
    _print_result_notes(result)
    _print_collapse_note(result, source, target)
    if result.energy_trace is not None:
        trace = result.energy_trace
        print(f"energy trace ({trace.size} assignments): " + ", ".join(f"{e:.5g}" for e in trace))
    return 0


def cmd_refine(args) -> int:
    from corrlib.methods import get_method, solve
    from corrlib.methods.registry import check_inputs

    _check_output_stem(args, [("source", args.source), ("target", args.target), ("--init", args.init)])
    source, target = _load_shape(args.source), _load_shape(args.target)
    spec = get_method(args.method)
    if not spec.refines:
        raise CorrError(f"method {spec.name!r} does not refine a map (methods that do: "
                        f"{', '.join(m.name for m in _refining_methods())})")
    check_inputs(spec, source, target)
    initial = _initial_match(args.init, source, target)
    plotting = _preload_plotting() if args.pictures else None
    result = solve(spec, source, target, callback=_progress_printer(args.quiet), initial=initial,
                   **_parse_overrides(args.param))
    if plotting is not None:
        plotting.join()
    _write_match_outputs(result, source, target, Path(args.output), quiet=args.quiet, pictures=args.pictures)
    print(f"method {result.method}: {result.timings.get('total', 0):.2f} s")
    _print_result_notes(result)
    _print_collapse_note(result, source, target)
    kept = result.extras.get("kept_matches")
    if kept is not None and not args.quiet:
        given_back = result.extras.get("isometric_matches")
        isometric = int(given_back.sum()) if given_back is not None else 0
        print(f"{int(kept.sum())} of {kept.size} rows kept their input partner ({int(kept.sum()) - isometric} moved "
              f"by less than the refinement's kernel width, {isometric} farther but the more isometric partner); "
              "the others were corrected")
    return 0


def _print_collapse_note(result, source, target) -> None:
    """Warn (on stderr) when a mesh-to-mesh map has collapsed onto a negligible part of the target."""
    from corrlib.evaluation import collapse_note

    note = collapse_note(result.map_xy, source, target)
    if note:
        print(f"warning: {note}", file=sys.stderr)


def _print_result_notes(result) -> None:
    """Warn (on stderr) when a mesh-to-mesh map reverses orientation on most of the shape, or was turned; note
    the other things a method tells about its result (copies, starts, a target matched unremeshed)."""
    from corrlib.methods.contour3d import remeshing_note
    from corrlib.methods.kernel_matching import copies_note, reversal_note, start_note, turn_note

    note = reversal_note(result.extras)
    if note:
        print(f"warning: {note}", file=sys.stderr)
    for said in (copies_note(result.extras), turn_note(result.extras), start_note(result.extras),
                 remeshing_note(result.extras)):
        if said:
            print(f"note: {said}", file=sys.stderr)


def _refining_methods():
    from corrlib.methods import all_methods

    return [m for m in all_methods() if m.refines]


def cmd_bench(args) -> int:
    from corrlib.bench import Runner, load_dataset, methods_from_toml, parse_method
    from corrlib.io import ensure_output_folder, exclusive_folder

    dataset = load_dataset(args.dataset, args.pairs)
    methods = [parse_method(m) for m in args.method or []]
    if args.methods_file:
        methods += methods_from_toml(args.methods_file)
    external = {}
    for item in args.maps or []:
        label, sep, folder = item.partition("=")
        if not sep or not Path(folder).is_dir():
            raise CorrError(f"--maps {item!r}: expected LABEL=FOLDER with an existing folder")
        external[label] = folder
    out = ensure_output_folder(args.output, "-o")
    with exclusive_folder(out, "corr bench"):  # a second run at once would mix its records with these
        return _run_bench(Runner(dataset, methods, out, external=external, geodesics=args.geodesics), args)


def _run_bench(runner, args) -> int:
    """The pending jobs of a :class:`~corrlib.bench.Runner` (``corr bench``), with progress and the summary."""
    todo = runner.pending()
    print(f"{len(runner.dataset.pairs)} pairs x {len(runner.methods) + len(runner.external)} methods: "
          f"{len(todo)} jobs to run ({len(runner.jobs()) - len(todo)} already done)", file=sys.stderr)

    failures = []

    def progress(done, total, label, record):
        if record["status"] != "ok":
            failures.append(f"{label} {record['source']} -> {record['target']}: {record['error']}")
        if not args.quiet:
            what = f"mean {record['mean']:.4f}" if record["status"] == "ok" else f"FAILED: {record['error']}"
            print(f"  [{done}/{total}] {label} {record['source']} -> {record['target']}: {what}", file=sys.stderr)

    summary = runner.run(jobs=args.jobs, scheduler=args.scheduler, callback=progress)
    print((runner.out / "summary.md").read_text(encoding="utf-8"))
    _say_failures(failures, runner.out / "errors.csv")
    return 0 if all(entry["failed"] == 0 for entry in summary.values()) else 1


def _say_failures(failures: list[str], where: Path) -> None:
    """After a benchmark: how many runs failed, the first one's reason, and where the others are (stderr)."""
    if failures:
        print(f"error: {len(failures)} run{'s' if len(failures) > 1 else ''} failed, e.g. {failures[0]} "
              f"(every reason is in {where})", file=sys.stderr)


def cmd_bench_retrieval(args) -> int:
    from corrlib.bench import retrieval_benchmark
    from corrlib.io import ensure_output_folder

    params = _contour3d_params(args, retrieval=True)  # named errors before any work
    ensure_output_folder(args.output, "-o")  # named as the option; the library checks the rest before any query

    failures = []

    def progress(done, total, row):
        if row["error"]:
            failures.append(f"{row['query']}: {row['error']}")
        if not args.quiet:
            what = f"AP {row['ap']:.3f}" if not row["error"] else f"FAILED: {row['error']}"
            print(f"  [{done}/{total}] {row['query']} ({row['class']}): {what}", file=sys.stderr)

    summary = retrieval_benchmark(args.queries, args.collection, args.output, params=params, jobs=args.jobs,
                                  scheduler=args.scheduler, callback=progress, ranking=args.ranking)
    print((Path(args.output) / "retrieval_summary.md").read_text(encoding="utf-8"))
    _say_failures(failures, Path(args.output) / "retrieval.csv")
    return 0 if summary["failed"] == 0 and not summary["failed_meshes"] else 1


def cmd_bench_contour(args) -> int:
    from corrlib.contour_bench import contour_benchmark

    params = _with_options(_parse_overrides(args.param or []), args, {"n_contour": "--n-contour"})
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
    _say_failures(failures, Path(args.output) / "contour_bench.csv")
    failed = summary["all"]["failed"] + summary.get("sketches", {}).get("failed", 0) + \
        summary.get("drawings", {}).get("all", {}).get("failed", 0)
    return 0 if failed == 0 else 1


#: the method ``corr morph`` runs unless told otherwise: the one with a deformation model of its own
MORPH_METHOD = "divergence-free"
#: most frames ``corr morph`` writes (the glTF animation's weights grow with the square of the count: 2,000
#: frames need 16 MB of them, and every frame is a mesh file)
MAX_FRAMES = 2000


def _check_morph_options(args) -> None:
    """Everything about ``corr morph``'s options that can be refused before any work."""
    import numpy as np

    from corrlib.methods.divergence_free import SEQUENCE_T_MAX
    from corrlib.morph import INTERPOLATIONS

    if args.interpolation not in INTERPOLATIONS:
        raise CorrError(f"--interpolation must be one of {', '.join(INTERPOLATIONS)}, got {args.interpolation!r}")
    if args.map is not None and (args.method is not None or args.param):
        given = "--method" if args.method is not None else "--param"
        raise CorrError(f"--map gives the map to interpolate through, so no method runs: give --map or {given}, "
                        "not both")
    if not 2 <= args.frames <= MAX_FRAMES:
        raise CorrError(f"--frames must be between 2 and {MAX_FRAMES}, got {args.frames}")
    if not (np.isfinite(args.t_max) and 0 < args.t_max <= SEQUENCE_T_MAX):
        raise CorrError(f"--t-max must be a positive number of at most {SEQUENCE_T_MAX:g} (the way between the "
                        f"shapes extrapolated {SEQUENCE_T_MAX:g} times), got {args.t_max}")


def _morph_result(args, source, target):
    """The match a morph moves through: the method's (``--method``, divergence-free by default), or a
    :class:`~corrlib.methods.base.MatchResult` holding the map of ``--map``."""
    from corrlib.methods import get_method, solve
    from corrlib.methods.base import MatchResult

    if args.map is None:
        spec = get_method(args.method or MORPH_METHOD)
        return solve(spec, source, target, callback=_progress_printer(args.quiet), **_parse_overrides(args.param))
    from corrlib.io import load_map

    map_xy = load_map(args.map, n_target=target.n_vertices, n_source=source.n_vertices, allow_unmatched=True)
    return MatchResult(f"the map {Path(args.map).name}", map_xy, None)


def cmd_morph(args) -> int:
    import numpy as np

    from corrlib.morph import describe_sequence, export_sequence, frame_positions, largest_volume_change
    from corrlib.shapes import TriMesh

    _check_morph_options(args)
    from corrlib.io import check_outputs_apart, ensure_output_folder, staged_output

    out = ensure_output_folder(args.output, "-o")
    # the folder's set: the result, every frame; an earlier morph's frames and result files go
    replaced_names = _match_output_names("result") | {"animation.glb", "volumes.csv"}

    def replaced(name: str) -> bool:
        return name.startswith("frame_") or name in replaced_names

    inputs = [("source", args.source), ("target", args.target)] + ([("--map", args.map)] if args.map else [])
    check_outputs_apart([("-o", out / Path(path).name) for _, path in inputs if replaced(Path(path).name)], inputs)
    source, target = _load_shape(args.source), _load_shape(args.target)
    if not (isinstance(source, TriMesh) and isinstance(target, TriMesh)):
        raise CorrError("corr morph takes two meshes")
    result = _morph_result(args, source, target)
    times = np.linspace(0.0, args.t_max, args.frames)
    frames = frame_positions(result, source, target, times, interpolation=args.interpolation)
    with staged_output(out, replaces=replaced) as stage:  # the result and every frame, or nothing
        if args.map is None:  # a given map is the user's file already
            _stage_match_outputs(result, source, target, stage / "result", pictures=True)
        written = export_sequence(stage, frames, source.faces, times, fmt=args.format, closed=source.is_closed)
    written["animation"] = written["animation"] and out / Path(written["animation"]).name
    print(f"{len(frames)} frames t = 0 .. {args.t_max:g} in {out}/, animation {written['animation']}: "
          f"{describe_sequence(result, args.interpolation)}")
    change = largest_volume_change(written["volume"], source.area)
    if change is not None:
        print(f"enclosed volume: largest relative change {change:.2e} over the frames")
    elif source.is_closed:
        print(f"enclosed volume: {source.name} encloses none (a flat closed mesh), so no relative change")
    else:
        print("enclosed volume: not applicable (the source mesh is not closed)")
    return 0


def cmd_demo(args) -> int:
    import numpy as np

    from corrlib.evaluation import geodesic_errors
    from corrlib.io import load_mesh
    from corrlib.methods import methods_for, solve
    from corrlib.resources import DEMO_PAIR, resource

    from corrlib.io import ensure_output_folder

    ensure_output_folder(args.output, "-o")
    source = load_mesh(resource(DEMO_PAIR[0]))
    target = load_mesh(resource(DEMO_PAIR[1]))
    spec = methods_for(source, target)[0]
    print(f"demo: {source.name} -> {target.name} with {spec.label} ({spec.name})")
    result = solve(spec, source, target, callback=_progress_printer(args.quiet))
    print(f"  finished in {result.timings.get('total', 0):.2f} s")
    # the demo pair shares its vertex order: the ground truth is the identity
    ident = np.arange(source.n_vertices)
    report = geodesic_errors(result.map_xy, target, ident, ident)
    for key, value in report.summary().items():
        print(f"  {key:>14}: {value:.4f}")
    out = Path(args.output) / "demo"
    _write_match_outputs(result, source, target, out, quiet=args.quiet, pictures=True)
    return 0


def _query_contour(path: str, labels: str | None = None):
    from corrlib.io import load_shape
    from corrlib.shapes import Contour2D, TriMesh

    contour = sketch = load_shape(path)
    if isinstance(sketch, TriMesh):
        # a planar triangulated sketch: its boundary loop is the contour
        loops = sketch.boundary_loops
        if not loops:
            raise FileFormatError(f"{path}: the sketch mesh has no boundary to use as a contour")
        loop = max(loops, key=len)
        contour = Contour2D(sketch.vertices[loop, :2], name=Path(path).name)
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


def _contour3d_params(args, *, retrieval: bool = False):
    """``contour3d`` parameters from ``--param`` and the options ``--eps``, ``--k``, ``--n-contour``: the
    method's defaults, or a retrieval's (:func:`corrlib.retrieval.retrieval_params`) if ``retrieval``."""
    overrides = _with_options(_parse_overrides(args.param or []), args,
                              {"eps": "--eps", "k": "--k", "n_contour": "--n-contour"})
    if retrieval:
        from corrlib.retrieval import retrieval_params

        return retrieval_params(**overrides)
    from corrlib.methods.base import make_params
    from corrlib.methods.contour3d import Contour3DParams

    return make_params(Contour3DParams, **overrides)


def cmd_match_contour(args) -> int:
    from corrlib.io import load_mesh
    from corrlib.methods import solve

    out = _check_output_stem(args, [("query", args.query), ("mesh", args.mesh), ("--query-labels", args.query_labels),
                                    ("--mesh-labels", args.mesh_labels)])
    contour = _query_contour(args.query, args.query_labels)
    mesh = _warned(load_mesh(args.mesh))
    if args.mesh_labels:
        from corrlib.io import load_labels

        mesh = mesh.with_labels(load_labels(args.mesh_labels, mesh.n_vertices, what="--mesh-labels"))
    result = solve("contour3d", contour, mesh, _contour3d_params(args), callback=_progress_printer(args.quiet))
    search = result.search
    print(f"energy {result.energy:.6g} (lower bound {search.lower_bound:.6g}, "
          f"{search.describe()}), {search.iterations} branch-and-bound "
          f"iterations, {search.dijkstra_runs} layered Dijkstra runs of {search.seconds_per_dijkstra:.3f} s, "
          f"{result.timings['total']:.2f} s in total")
    _print_result_notes(result)  # e.g. a mesh matched as given because it could not be remeshed
    from corrlib.io import staged_output

    with staged_output(out.parent, replaces=_match_output_names(out.name).__contains__) as stage:
        staged = [*result.save(stage / out.name), *_stage_match_pictures(result, contour, mesh, stage / out.name)]
    if not args.quiet:
        for written in staged:
            print(f"wrote {out.parent / Path(written).name}")
    return 0


def cmd_retrieve(args) -> int:
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
    contour = _query_contour(args.query)
    params = _contour3d_params(args, retrieval=True)
    hits = run(retrieve(contour, files, params, jobs=args.jobs, scheduler=args.scheduler, root=args.folder,
                        ranking=args.ranking), callback=_progress_printer(args.quiet))
    written = write_ranking(hits, Path(args.output), args.top if args.pictures else 0) if args.output else []
    print(f"{'rank':>4}  {'score':>8}  {'energy':>12}  {'views':>7}  {'seconds':>7}  mesh")
    for rank, hit in enumerate(hits[: args.top], 1):
        extra = f"  ({hit.error})" if hit.error else ""
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


def cmd_methods(args) -> int:
    from corrlib.methods import all_methods
    from corrlib.methods.base import param_fields

    for spec in all_methods():
        print(f"{spec.name}  ({spec.inputs[0]} -> {spec.inputs[1]}): {spec.label}")
        print(f"    {spec.description}")
        for f in param_fields(spec.params):
            m = f.metadata
            rng = f" choices {m['choices']}" if m.get("choices") else (
                f" [{m.get('low')}, {m.get('high')}]" if m.get("low") is not None else "")
            print(f"    --param {f.name}={f.default}{rng}: {m.get('help', '')}")
    return 0


def cmd_perf(args) -> int:
    from corrlib import perf

    if args.repeat < 1:
        raise CorrError(f"--repeat must be at least 1, got {args.repeat}")
    perf.run_suite(args.suite, repeat=args.repeat, quick=args.quick)
    return 0


# ----------------------------------------------------------------------------- parser


def _jobs_option(text: str) -> int:
    """``--jobs``: 0 (all cores) or a positive number of worker processes; argparse names the option otherwise."""
    from corrlib.parallel import check_jobs

    try:
        value = int(text)
        check_jobs(value)  # the library's rule
    except (ValueError, CorrError):
        raise argparse.ArgumentTypeError(f"expected 0 (all cores) or a positive number of worker processes, "
                                         f"got {text}") from None
    return value


def _add_scale_out(p: argparse.ArgumentParser) -> None:
    """``--jobs`` / ``--scheduler`` of the commands that run independent jobs (see corrlib.parallel.job_executor)."""
    p.add_argument("--jobs", type=_jobs_option, help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786) instead of local processes")


#: corrlib.retrieval.RANKINGS, named here so that building the parser does not import the retrieval module
RANKING_CHOICES = ("fused", "energy")


def _add_ranking(p: argparse.ArgumentParser) -> None:
    """``--ranking`` of the retrieval commands (corrlib.retrieval.retrieve)."""
    p.add_argument("--ranking", choices=RANKING_CHOICES, default=RANKING_CHOICES[0],
                   help="fused (default): the matching energy times the drawing's dissimilarity to the mesh's "
                        "rendered views; energy: the matching energy alone (the thesis' ranking)")


def _command(sub, name: str, help: str, description: str | None = None, **defaults) -> argparse.ArgumentParser:
    """A subcommand: ``help`` is its one line in ``corr --help``, ``description`` its text in ``corr NAME --help``."""
    p = sub.add_parser(name, help=help, description=description or help)
    p.set_defaults(**defaults)
    return p


#: the ``-o`` help of the commands that write a match's set of files beside one stem
STEM_HELP = ("output path without suffix; the files written there replace every file an earlier match wrote under "
             f"that stem ({', '.join(MATCH_OUTPUT_SUFFIXES)})")


def _add_output(p: argparse.ArgumentParser, default: str, help: str = STEM_HELP, *,
                quiet: bool = True) -> None:
    p.add_argument("-o", "--output", default=default, help=help)
    if quiet:
        p.add_argument("-q", "--quiet", action="store_true")


def _add_info_parser(sub) -> None:
    p = _command(sub, "info", "statistics and validation report of a mesh or contour",
                 "Statistics and a validation report of a mesh or contour file (loaded as 'corr match' loads it). "
                 "Exit status 2 if the file cannot be used.", func=cmd_info)
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="print JSON")


def _add_repair_parser(sub) -> None:
    p = _command(sub, "repair", "weld, drop bad faces and loose parts of a mesh",
                 "Write a mesh with the repairs a file may need before the methods accept it: vertices at one "
                 "position welded; faces dropped that repeat a vertex, have zero area or repeat another face; the "
                 "largest connected component kept; unused vertices dropped; face windings made to agree. Each "
                 "repair done is said. Beside the mesh, OUT.source_vertices.txt gives the input vertex of "
                 "each vertex (to carry ground truth). Refused, with the reason, where a problem has no such "
                 "repair (NaN coordinates, edges of three faces).", func=cmd_repair)
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True, help="the repaired mesh (.off, .obj or .ply)")


def _add_eval_parser(sub) -> None:
    p = _command(sub, "eval", "geodesic error of a map against ground truth",
                 "Princeton-protocol geodesic error of a map against ground truth.", func=cmd_eval)
    p.add_argument("map", help="map file: one 0-based target index per source vertex (or a result .npz)")
    p.add_argument("--gt-source", required=True, help=".vts ground truth of the source (1-based)")
    p.add_argument("--gt-target", required=True, help=".vts ground truth of the target (1-based)")
    p.add_argument("--gt-target-sym", help="mirrored .vts of the target for the symmetry-aware error")
    p.add_argument("--target", required=True, help="target mesh (distances are measured on it)")
    p.add_argument("--normalize", default="sqrt_area", choices=["sqrt_area", "diameter", "none"])
    p.add_argument("--geodesics", default="exact", choices=["exact", "heat", "graph"])
    p.add_argument("--plot", help="write the cumulative error curve to this PNG")
    p.add_argument("--errors", help="write the per-row errors to this text file")
    p.add_argument("--json", action="store_true")


def _add_pictures_flag(p) -> None:
    p.add_argument("--pictures", action="store_true",
                   help="also write the pictures (colour transfer onto the target, the energy trace, the contours "
                        "on their torus, a contour's matched curve on the mesh); they take about a second")


def _add_match_parsers(sub) -> None:
    """``match``, ``match-contour`` and ``match-contours``."""
    p = _command(sub, "match", "match two shapes with a registered method", func=cmd_match)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--method", help="registered method (see `corr methods`; default: the best-ranked method for the "
                                    "two inputs: kernel-matching for two meshes, contour3d for a contour and a mesh, "
                                    "contour2d for two contours)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    p.add_argument("--init", help="descriptors | fmap | best (both, kernel matching) | a map file (one target index "
                                  "per source vertex) | a landmarks file (source target per line), for methods "
                                  "that refine")
    p.add_argument("--times", help="comma-separated diffusion times relative to the area (kernel matching)")
    _add_pictures_flag(p)
    _add_output(p, "result")

    p = _command(sub, "match-contour", "match a closed 2D contour to a mesh (2D-to-3D)",
                 "2D-to-3D elastic matching of a closed contour to a mesh.", func=cmd_match_contour)
    p.add_argument("query", help="contour: point file, SVG, silhouette image or planar sketch mesh")
    p.add_argument("mesh")
    p.add_argument("--eps", type=float, help="approximation factor (0 = global optimum)")
    p.add_argument("--k", type=int, help="Laplace-Beltrami eigenpairs for the features (default 25)")
    p.add_argument("--n-contour", dest="n_contour", type=int, help="contour resampling (default 200)")
    p.add_argument("--query-labels", help="part label per contour point (or per sketch-mesh vertex)")
    p.add_argument("--mesh-labels", help="part label per mesh vertex")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="other method parameter")
    _add_output(p, "contour_match")

    p = _command(sub, "match-contours", "match two closed contours on their product torus",
                 func=cmd_match, method="contour2d", init=None, times=None, pictures=True)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    _add_output(p, "contours")


def _add_retrieve_parser(sub) -> None:
    p = _command(sub, "retrieve", "rank the meshes of a folder against a query contour",
                 "Rank the meshes of a folder for a query contour: by its matching energy and its likeness to "
                 "each mesh's rendered views (--ranking).", func=cmd_retrieve)
    p.add_argument("query")
    p.add_argument("folder", help="the collection: meshes in it and its subfolders; a subfolder per class "
                                  "(cat/0.off) or class names in the file names (cat0.off)")
    p.add_argument("--top", type=int, default=10, help="how many ranks to print")
    _add_scale_out(p)
    p.add_argument("--eps", type=float, default=0.0,
                   help="approximation factor (default 0: rank by the exact optima)")
    p.add_argument("--k", type=int)
    p.add_argument("--n-contour", dest="n_contour", type=int, help=RETRIEVAL_N_CONTOUR_HELP)
    p.add_argument("--param", action="append", metavar="NAME=VALUE")
    _add_ranking(p)
    p.add_argument("--pictures", action="store_true",
                   help="also write, beside the ranking (-o), the query and its matched curve on each of the --top "
                        "meshes (STEM.RANK-MESH.png)")
    _add_output(p, None, "write the full ranking as TSV (with --pictures, the pictures of an earlier ranking of "
                         "these meshes under its name are replaced)")


def _add_bench_parsers(sub) -> None:
    """``bench``, ``bench-retrieval`` and ``bench-contour``."""
    from corrlib.formats import suffixes

    meshes = " ".join("*" + s for s in suffixes("mesh", vertex_order=True))
    p = _command(sub, "bench", "run methods over a benchmark dataset",
                 "Run methods over a benchmark dataset with the standard protocol.", func=cmd_bench)
    p.add_argument("dataset", help=f"folder: meshes ({meshes}), corres/<name>.vts (+ .sym.vts), pairs.txt; or "
                                   "meshes with one connectivity (identity ground truth)")
    p.add_argument("--method", action="append", metavar="NAME[:k=v,...][@LABEL]",
                   help="a registered method with parameters (repeatable)")
    p.add_argument("--methods-file", help="TOML file of [[method]] tables (name, label, params)")
    p.add_argument("--maps", action="append", metavar="LABEL=FOLDER",
                   help="evaluate external map files <source>__<target>.txt from FOLDER (repeatable)")
    p.add_argument("--pairs", help="pairs file (default: DATASET/pairs.txt, else all ordered pairs)")
    _add_scale_out(p)
    p.add_argument("--geodesics", default="exact", choices=["exact", "heat", "graph"])
    _add_output(p, "bench_output", "output folder (a rerun resumes it)")

    p = _command(sub, "bench-retrieval", "retrieval benchmark: mean average precision",
                 "Retrieval benchmark: queries against a collection, MAP and per-class average precision.",
                 func=cmd_bench_retrieval)
    p.add_argument("queries", help="folder of silhouette images / contour files (class = name without number)")
    p.add_argument("collection", help="folder of meshes (class = name without number)")
    _add_scale_out(p)
    p.add_argument("--eps", type=float, default=0.0,
                   help="approximation factor (default 0: rank by the exact optima)")
    p.add_argument("--n-contour", dest="n_contour", type=int, help=RETRIEVAL_N_CONTOUR_HELP)
    p.add_argument("--param", action="append", metavar="KEY=VALUE", help="another contour3d parameter (repeatable)")
    _add_ranking(p)
    _add_output(p, "retrieval_output", "output folder")

    p = _command(sub, "bench-contour", "2D-to-3D benchmark with plane-section queries",
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
    _add_scale_out(p)
    _add_output(p, "contour_bench_output", "output folder")


def _add_refine_parser(sub) -> None:
    p = _command(sub, "refine", "refine an initial map or landmarks into a dense map", func=cmd_refine)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--init", required=True,
                   help="map file (one target index per source vertex) or landmarks (two columns: source target)")
    p.add_argument("--method", default="product-manifold", help="a refining method (default product-manifold)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    _add_pictures_flag(p)
    _add_output(p, "refined")


def _add_morph_parser(sub) -> None:
    from corrlib.formats import suffixes

    p = _command(sub, "morph", "deform the source into the target, export the frames",
                 "Deform the source into the target and export interpolated and extrapolated meshes.",
                 func=cmd_morph)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--method", default=None,
                   help=f"registered method (default {MORPH_METHOD}: its flow; others: interpolation through the map)")
    p.add_argument("--map", default=None, metavar="MAPFILE",
                   help="interpolate through this map instead of running a method (one 0-based target index per "
                        "source vertex, -1 unmatched; or a result .npz)")
    p.add_argument("--interpolation", default="auto",
                   help="auto (default): the method's flow if it has one, else rigid; rigid: as rigid as possible "
                        "(every face turns and stretches by a share of its deformation); linear: vertex positions "
                        "(shrinks what turns)")
    p.add_argument("--frames", type=int, default=11, help="number of frames (default 11)")
    p.add_argument("--t-max", dest="t_max", type=float, default=1.5,
                   help="last time: 1 is the target, above 1 extrapolates, at most 3 (default 1.5)")
    p.add_argument("--format", default="obj", choices=[s.lstrip(".") for s in suffixes("mesh", writable=True)],
                   help="mesh format of the frames")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    _add_output(p, "frames", "output folder (an earlier morph's frames and result files there are replaced)")


def _add_tool_parsers(sub) -> None:
    """``demo``, ``methods`` and ``perf``."""
    p = _command(sub, "demo", "match the bundled demo pair, write result and picture",
                 "Match the bundled demo pair and write a result and a picture.", func=cmd_demo)
    _add_output(p, "demo_output", "output folder")

    _command(sub, "methods", "list the registered methods and their parameters", func=cmd_methods)

    p = _command(sub, "perf", "performance benchmarks (prints figures)", func=cmd_perf)
    p.add_argument("suite", nargs="?", default="foundation", help="benchmark suite (default: foundation)")
    p.add_argument("--repeat", type=int, default=3, help="repetitions; the best time is reported")
    p.add_argument("--quick", action="store_true", help="a short smoke run with fewer cases")


def build_parser() -> argparse.ArgumentParser:
    """The ``corr`` parser: one subcommand per ``_add_*_parser`` call, in the order ``corr --help`` lists them."""
    parser = argparse.ArgumentParser(prog="corr", description="Continuous non-rigid shape correspondence.")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (_add_info_parser, _add_repair_parser, _add_eval_parser, _add_match_parsers, _add_retrieve_parser,
                _add_bench_parsers, _add_refine_parser, _add_morph_parser, _add_tool_parsers):
        add(sub)
    return parser


class Terminated(BaseException):
    """SIGTERM or SIGHUP, raised like KeyboardInterrupt so that every half-written output is cleaned up."""

    def __init__(self, signum: int = 15):
        super().__init__(signum)
        self.signum = signum


def _terminate_like_interrupt() -> dict:
    """Make SIGTERM and SIGHUP (the terminal or the ssh session closed) raise :class:`Terminated` (main thread
    only); returns the handlers to restore."""
    import signal
    import threading

    def handler(signum, frame):
        raise Terminated(signum)

    if threading.current_thread() is not threading.main_thread():
        return {}
    hangup = getattr(signal, "SIGHUP", None)  # not on Windows
    return {signum: signal.signal(signum, handler) for signum in (signal.SIGTERM, hangup) if signum is not None}


def main(argv: list[str] | None = None) -> int:
    for stream in (sys.stdout, sys.stderr):  # a message never fails on a character the terminal cannot show
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    parser = build_parser()
    args = parser.parse_args(argv)
    threads = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    if threads.lstrip("-").isdigit() and int(threads) < 1:  # numba would raise while it is imported
        print(f"error: NUMBA_NUM_THREADS={threads} must be a positive number of threads (or unset)", file=sys.stderr)
        return EXIT_BAD_INPUT
    previous = _terminate_like_interrupt()
    code = 1  # until the command returns: an exception is a failure
    try:
        if getattr(args, "scheduler", None) is not None:
            from corrlib.parallel import check_scheduler_address

            check_scheduler_address(args.scheduler)  # before any output exists
        code = int(args.func(args) or 0)
        return code
    except CorrError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader of the standard output left (`corr … | head`): the files are written
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return EXIT_BROKEN_PIPE
    except OSError as exc:  # the environment: permissions, a full disk, a vanished file
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{(exc.strerror or str(exc)).lower()}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        print("error: out of memory; try smaller inputs or fewer parallel jobs", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Terminated as exc:
        print("terminated" if exc.signum == 15 else "hung up", file=sys.stderr)
        return 128 + exc.signum
    finally:
        if previous:
            import signal

            for signum, handler in previous.items():
                signal.signal(signum, handler)
        if "corrlib.io" in sys.modules:  # a failed command leaves no empty output folder
            from corrlib.io import remove_created_empty_folders

            remove_created_empty_folders(remove=code != 0)


if __name__ == "__main__":
    sys.exit(main())
