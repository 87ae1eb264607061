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

from corrlib.cli_common import (add_output, add_scale_out, check_output_stem, command, load_input,
                                match_output_names, parse_overrides, print_collapse_note, print_result_notes,
                                progress_printer, say_failures, stage_match_outputs, with_options,
                                write_match_outputs)
from corrlib.cli_contour import add_contour_bench_parsers, add_match_contour_parser, add_retrieve_parser
from corrlib.errors import CorrError, FileFormatError

EXIT_BAD_INPUT = 2
#: the exit status of a command whose standard output was closed by its reader (128 + SIGPIPE, as the shell's)
EXIT_BROKEN_PIPE = 141


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
    from corrlib.io import (check_map_record, check_output_file, check_outputs_apart, load_map, load_mesh,
                            load_vts)

    outputs = [(option, value) for option, value in (("--errors", args.errors), ("--plot", args.plot)) if value]
    for option, value in outputs:
        check_output_file(value, option)
    check_outputs_apart(outputs, [("the map", args.map), ("--gt-source", args.gt_source),
                                  ("--gt-target", args.gt_target), ("--target", args.target),
                                  ("--gt-target-sym", args.gt_target_sym)])
    target = load_mesh(args.target)
    map_xy = load_map(args.map, n_target=target.n_vertices, allow_unmatched=True)
    check_map_record(args.map, target=target)
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


def _init_choices(spec) -> tuple:
    """The named initialisations a method offers (the choices of its ``init`` parameter), e.g. "fmap"."""
    import dataclasses

    for f in dataclasses.fields(spec.params):
        if f.name == "init":
            return tuple(f.metadata.get("choices") or ())
    return ()


def _initial_match(value: str, source, target, spec=None):
    """``--init``: a map file (one target index per source vertex) or a landmarks file (two columns)."""
    from corrlib.io import check_map_record, load_map, load_pairs, read_text
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
    check_map_record(path, source, target)
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

    check_output_stem(args, [("source", args.source), ("target", args.target), ("--init", args.init)])
    source, target = load_input(args.source), load_input(args.target)
    overrides = parse_overrides(args.param)
    spec = get_method(args.method) if args.method else _best_method(source, target)
    check_inputs(spec, source, target)
    initial = None
    if args.init:
        if args.init in _init_choices(spec):
            overrides = with_options(overrides, args, {"init": "--init"})
        elif spec.refines:
            initial = _initial_match(args.init, source, target, spec)
        else:
            raise CorrError(f"method {spec.name!r} does not take an initial map (--init)")
    if args.times:
        overrides = with_options(overrides, args, {"times": "--times"})
    plotting = _preload_plotting() if args.pictures else None
    result = solve(spec, source, target, callback=progress_printer(args.quiet), initial=initial, **overrides)
    if plotting is not None:
        plotting.join()
    # the files first: a closed or full standard output must not cost the result
    write_match_outputs(result, source, target, Path(args.output), quiet=args.quiet, pictures=args.pictures)
    print(f"method {result.method}: energy {result.energy}, {result.timings.get('total', 0):.2f} s")
    if result.search is not None:
        print(f"path search: {result.search.describe()}")
    print_result_notes(result)
    print_collapse_note(result, source, target)
    if result.energy_trace is not None:
        trace = result.energy_trace
        print(f"energy trace ({trace.size} assignments): " + ", ".join(f"{e:.5g}" for e in trace))
    return 0


def cmd_refine(args) -> int:
    from corrlib.methods import get_method, solve
    from corrlib.methods.registry import check_inputs

    check_output_stem(args, [("source", args.source), ("target", args.target), ("--init", args.init)])
    source, target = load_input(args.source), load_input(args.target)
    spec = get_method(args.method)
    if not spec.refines:
        raise CorrError(f"method {spec.name!r} does not refine a map (methods that do: "
                        f"{', '.join(m.name for m in _refining_methods())})")
    check_inputs(spec, source, target)
    initial = _initial_match(args.init, source, target)
    plotting = _preload_plotting() if args.pictures else None
    result = solve(spec, source, target, callback=progress_printer(args.quiet), initial=initial,
                   **parse_overrides(args.param))
    if plotting is not None:
        plotting.join()
    write_match_outputs(result, source, target, Path(args.output), quiet=args.quiet, pictures=args.pictures)
    print(f"method {result.method}: {result.timings.get('total', 0):.2f} s")
    print_result_notes(result)
    print_collapse_note(result, source, target)
    kept = result.extras.get("kept_matches")
    if kept is not None and not args.quiet:
        given_back = result.extras.get("isometric_matches")
        isometric = int(given_back.sum()) if given_back is not None else 0
        print(f"{int(kept.sum())} of {kept.size} rows kept their input partner ({int(kept.sum()) - isometric} moved "
              f"by less than the refinement's kernel width, {isometric} farther but the more isometric partner); "
              "the others were corrected")
    return 0


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
    say_failures(failures, runner.out / "errors.csv")
    return 0 if all(entry["failed"] == 0 for entry in summary.values()) else 1


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
    if args.interpolation == "flow":
        from corrlib.methods import get_method

        if args.map is not None or not get_method(args.method or MORPH_METHOD).deforms:
            what = "a map" if args.map is not None else f"--method {args.method}"
            raise CorrError(f"--interpolation flow follows a method's flow (a deformation, as {MORPH_METHOD} fits), "
                            f"and {what} has none: use rigid or linear (or auto)")
    if not 2 <= args.frames <= MAX_FRAMES:
        raise CorrError(f"--frames must be between 2 and {MAX_FRAMES}, got {args.frames}")
    if not (np.isfinite(args.t_max) and 0 < args.t_max <= SEQUENCE_T_MAX):
        raise CorrError(f"--t-max must be a positive number of at most {SEQUENCE_T_MAX:g} (the way between the "
                        f"shapes extrapolated {SEQUENCE_T_MAX:g} times), got {args.t_max}")


def _morph_result(args, source, target):
    """The match a morph moves through: the method's (``--method``, divergence-free by default), or the map of
    ``--map`` as a :class:`~corrlib.morph.GivenMap`."""
    from corrlib.methods import get_method, solve

    if args.map is None:
        spec = get_method(args.method or MORPH_METHOD)
        return solve(spec, source, target, callback=progress_printer(args.quiet), **parse_overrides(args.param))
    from corrlib.io import check_map_record, load_map
    from corrlib.morph import GivenMap

    map_xy = load_map(args.map, n_target=target.n_vertices, n_source=source.n_vertices, allow_unmatched=True)
    check_map_record(args.map, source, target)
    return GivenMap(map_xy, method=f"the map {Path(args.map).name}")


def cmd_morph(args) -> int:
    from corrlib.morph import (describe_sequence, export_sequence, frame_positions, frame_times,
                               largest_volume_change, last_frame_note)
    from corrlib.shapes import TriMesh

    _check_morph_options(args)
    from corrlib.io import check_outputs_apart, ensure_output_folder, staged_output

    out = ensure_output_folder(args.output, "-o")
    # the folder's set: the result, every frame; an earlier morph's frames and result files go
    replaced_names = match_output_names("result") | {"animation.glb", "volumes.csv"}

    def replaced(name: str) -> bool:
        return name.startswith("frame_") or name in replaced_names

    inputs = [("source", args.source), ("target", args.target)] + ([("--map", args.map)] if args.map else [])
    check_outputs_apart([("-o", out / Path(path).name) for _, path in inputs if replaced(Path(path).name)], inputs)
    source, target = load_input(args.source), load_input(args.target)
    if not (isinstance(source, TriMesh) and isinstance(target, TriMesh)):
        raise CorrError("corr morph takes two meshes")
    result = _morph_result(args, source, target)
    times = frame_times(args.frames, args.t_max)
    frames = frame_positions(result, source, target, times, interpolation=args.interpolation)
    with staged_output(out, replaces=replaced) as stage:  # the result and every frame, or nothing
        if args.map is None:  # a given map is the user's file already
            stage_match_outputs(result, source, target, stage / "result", pictures=True)
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
    folds = last_frame_note(result, source, target, times, frames, args.interpolation)
    if folds:
        print(folds)
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
    result = solve(spec, source, target, callback=progress_printer(args.quiet))
    print(f"  finished in {result.timings.get('total', 0):.2f} s")
    # the demo pair shares its vertex order: the ground truth is the identity
    ident = np.arange(source.n_vertices)
    report = geodesic_errors(result.map_xy, target, ident, ident)
    for key, value in report.summary().items():
        print(f"  {key:>14}: {value:.4f}")
    out = Path(args.output) / "demo"
    write_match_outputs(result, source, target, out, quiet=args.quiet, pictures=True)
    return 0


def cmd_methods(args) -> int:
    from corrlib.methods import all_methods
    from corrlib.methods.base import param_fields, parameter_line

    for spec in all_methods():
        print(f"{spec.name}  ({spec.inputs[0]} -> {spec.inputs[1]}): {spec.label}")
        print(f"    {spec.description}")
        for f in param_fields(spec.params):
            print(f"    --param {parameter_line(f)}")
    return 0


def cmd_perf(args) -> int:
    from corrlib import perf

    if args.repeat < 1:
        raise CorrError(f"--repeat must be at least 1, got {args.repeat}")
    perf.run_suite(args.suite, repeat=args.repeat, quick=args.quick)
    return 0


# ----------------------------------------------------------------------------- parser


def _add_info_parser(sub) -> None:
    p = command(sub, "info", "statistics and validation report of a mesh or contour",
                 "Statistics and a validation report of a mesh or contour file (loaded as 'corr match' loads it). "
                 "Exit status 2 if the file cannot be used.", func=cmd_info)
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="print JSON")


def _add_repair_parser(sub) -> None:
    p = command(sub, "repair", "weld, drop bad faces and loose parts of a mesh",
                 "Write a mesh with the repairs a file may need before the methods accept it: vertices at one "
                 "position welded; faces dropped that repeat a vertex, have zero area or repeat another face; the "
                 "largest connected component kept; unused vertices dropped; face windings made to agree. Each "
                 "repair done is said. Beside the mesh, OUT.source_vertices.txt gives the input vertex of "
                 "each vertex (to carry ground truth). Refused, with the reason, where a problem has no such "
                 "repair (NaN coordinates, edges of three faces).", func=cmd_repair)
    p.add_argument("mesh")
    p.add_argument("-o", "--output", required=True, help="the repaired mesh (.off, .obj or .ply)")


def _add_eval_parser(sub) -> None:
    p = command(sub, "eval", "geodesic error of a map against ground truth",
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
    p = command(sub, "match", "match two shapes with a registered method", func=cmd_match)
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
    add_output(p, "result")

    add_match_contour_parser(sub)

    p = command(sub, "match-contours", "match two closed contours on their product torus",
                 func=cmd_match, method="contour2d", init=None, times=None, pictures=True)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    add_output(p, "contours")


def _add_bench_parsers(sub) -> None:
    """``bench``, ``bench-retrieval`` and ``bench-contour``."""
    from corrlib.formats import suffixes

    meshes = " ".join("*" + s for s in suffixes("mesh", vertex_order=True))
    p = command(sub, "bench", "run methods over a benchmark dataset",
                 "Run methods over a benchmark dataset with the standard protocol.", func=cmd_bench)
    p.add_argument("dataset", help=f"folder: meshes ({meshes}), corres/<name>.vts (+ .sym.vts), pairs.txt; or "
                                   "meshes with one connectivity (identity ground truth)")
    p.add_argument("--method", action="append", metavar="NAME[:k=v,...][@LABEL]",
                   help="a registered method with parameters (repeatable)")
    p.add_argument("--methods-file", help="TOML file of [[method]] tables (name, label, params)")
    p.add_argument("--maps", action="append", metavar="LABEL=FOLDER",
                   help="evaluate external map files <source>__<target>.txt from FOLDER (repeatable)")
    p.add_argument("--pairs", help="pairs file (default: DATASET/pairs.txt, else all ordered pairs)")
    add_scale_out(p)
    p.add_argument("--geodesics", default="exact", choices=["exact", "heat", "graph"])
    add_output(p, "bench_output", "output folder (a rerun resumes it)")

    add_contour_bench_parsers(sub)


def _add_refine_parser(sub) -> None:
    p = command(sub, "refine", "refine an initial map or landmarks into a dense map", func=cmd_refine)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--init", required=True,
                   help="map file (one target index per source vertex) or landmarks (two columns: source target)")
    p.add_argument("--method", default="product-manifold", help="a refining method (default product-manifold)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    _add_pictures_flag(p)
    add_output(p, "refined")


def _add_morph_parser(sub) -> None:
    from corrlib.formats import suffixes

    p = command(sub, "morph", "deform the source into the target, export the frames",
                 "Deform the source into the target and export the meshes in between (and beyond, with --t-max "
                 "above 1).",
                 func=cmd_morph)
    p.add_argument("source")
    p.add_argument("target")
    p.add_argument("--method", default=None,
                   help=f"registered method (default {MORPH_METHOD}: its flow; others: interpolation through the map)")
    p.add_argument("--map", default=None, metavar="MAPFILE",
                   help="interpolate through this map instead of running a method (one 0-based target index per "
                        "source vertex, -1 unmatched; or a result .npz)")
    p.add_argument("--interpolation", default="auto",
                   help="auto (default): the method's flow if it has one, else rigid; flow: the method's flow "
                        f"(e.g. {MORPH_METHOD}'s); rigid: as rigid as possible "
                        "(every face turns and stretches by a share of its deformation); linear: vertex positions "
                        "(shrinks what turns)")
    p.add_argument("--frames", type=int, default=11,
                   help="number of frames, evenly spaced from t = 0 (default 11; one more where a --t-max above 1 "
                        "leaves none at t = 1, the target)")
    p.add_argument("--t-max", dest="t_max", type=float, default=1.0,
                   help="last time: 1 is the target (default), above 1 extrapolates along the motion, at most 3")
    p.add_argument("--format", default="obj", choices=[s.lstrip(".") for s in suffixes("mesh", writable=True)],
                   help="mesh format of the frames")
    p.add_argument("--param", action="append", metavar="NAME=VALUE", help="method parameter (repeatable)")
    add_output(p, "frames", "output folder (an earlier morph's frames and result files there are replaced)")


def _add_tool_parsers(sub) -> None:
    """``demo``, ``methods`` and ``perf``."""
    p = command(sub, "demo", "match the bundled demo pair, write result and picture",
                 "Match the bundled demo pair and write a result and a picture.", func=cmd_demo)
    add_output(p, "demo_output", "output folder")

    command(sub, "methods", "list the registered methods and their parameters", func=cmd_methods)

    p = command(sub, "perf", "benchmark figures, and the machine's speed", func=cmd_perf)
    p.add_argument("suite", nargs="?", default="foundation", help="benchmark suite (default: foundation)")
    p.add_argument("--repeat", type=int, default=3, help="repetitions; the best time is reported")
    p.add_argument("--quick", action="store_true", help="a short smoke run with fewer cases")


def build_parser() -> argparse.ArgumentParser:
    """The ``corr`` parser: one subcommand per ``_add_*_parser`` call, in the order ``corr --help`` lists them."""
    parser = argparse.ArgumentParser(prog="corr", description="Continuous non-rigid shape correspondence.")
    sub = parser.add_subparsers(dest="command", required=True)
    for add in (_add_info_parser, _add_repair_parser, _add_eval_parser, _add_match_parsers, add_retrieve_parser,
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
