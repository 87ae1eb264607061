"""What the ``corr`` commands share: inputs loaded with their warnings said, method parameters from ``--param``
and the options, the output set of a match, progress and notes on stderr, and the parser's building blocks.

Imported by :mod:`corrlib.cli` and :mod:`corrlib.cli_contour`; at import it loads nothing numerical, so that
``corr --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from corrlib.errors import CorrError


def warned(shape):
    """``shape``, after what its validation warns of went to stderr (the studio shows the same in its shapes
    panel)."""
    for finding in getattr(shape, "report", lambda: [])():
        if finding.level == "warning":
            print(f"warning: {shape.name}: {finding.message}", file=sys.stderr)
    return shape


def load_input(path: str):
    """A mesh, contour or silhouette from ``path``, its warnings said (:func:`warned`)."""
    from corrlib.io import load_shape

    return warned(load_shape(path))


def parse_overrides(pairs: list[str]) -> dict:
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


def with_options(overrides: dict, args, options: dict[str, str]) -> dict:
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


#: what a match may write beside its ``-o`` stem (the result, the maps, the pictures)
MATCH_OUTPUT_SUFFIXES = (".npz", ".json", ".map_xy.txt", ".map_yx.txt", ".png", ".energy.png")


def check_output_stem(args, inputs) -> Path:
    """The ``-o`` stem, checked before any work (its folder created and writable, no folder where one of its
    files goes, and none of its files one of the ``inputs``, ``(role, path)`` pairs)."""
    from corrlib.io import check_output_file, check_outputs_apart

    stem = check_output_file(Path(args.output), "-o")
    for suffix in MATCH_OUTPUT_SUFFIXES:
        check_output_file(beside(stem, suffix), "-o")
    check_outputs_apart([("-o", beside(stem, suffix)) for suffix in MATCH_OUTPUT_SUFFIXES], inputs)
    return stem


def match_output_names(stem: str) -> set[str]:
    """Every file name a match may write beside the stem named ``stem``: a new match replaces them as a set, so that
    an earlier match's picture or reverse map is not left beside the new result."""
    return {stem + suffix for suffix in MATCH_OUTPUT_SUFFIXES}


def beside(stem: Path, suffix: str) -> Path:
    """The file ``stem`` + ``suffix`` (one of :data:`MATCH_OUTPUT_SUFFIXES`: the ones checked before any work)."""
    if suffix not in MATCH_OUTPUT_SUFFIXES:
        raise ValueError(f"{suffix!r} is not among the suffixes checked before the work")
    return stem.with_name(stem.name + suffix)


def stage_match_outputs(result, source, target, out: Path, pictures: bool) -> list[Path]:
    """Write a match's result (``.npz``, ``.json``), its maps and, if asked, its pictures beside the stem ``out``
    (inside a staging folder, :func:`corrlib.io.staged_output`); returns the paths written."""
    from corrlib.io import save_map

    npz, js = result.save(out)
    written = [npz, js]
    if result.map_xy is not None:
        written.append(save_map(beside(out, ".map_xy.txt"), result.map_xy))
    if result.map_yx is not None:
        written.append(save_map(beside(out, ".map_yx.txt"), result.map_yx))
    if pictures:
        written += stage_match_pictures(result, source, target, out)
    return [Path(p) for p in written]


def stage_match_pictures(result, source, target, out: Path) -> list:
    """The pictures of a match beside the stem ``out``: the energy trace, and the colour transfer (two meshes),
    the torus (two contours) or the matched curve on the mesh (2D-to-3D); returns the paths written."""
    written = []
    if result.energy_trace is not None:
        from corrlib.plotting import save_energy_trace

        written.append(save_energy_trace(beside(out, ".energy.png"), result.energy_trace,
                                         result.extras.get("tau_trace")))
    from corrlib.shapes import Contour2D, TriMesh

    if result.map_yx is not None and isinstance(source, TriMesh) and isinstance(target, TriMesh):
        from corrlib.plotting import save_colour_transfer

        written.append(save_colour_transfer(beside(out, ".png"), source, target, result.map_yx,
                                            title=f"{result.method}"))
    elif isinstance(source, Contour2D) and isinstance(target, Contour2D):
        from corrlib.plotting import save_torus_pictures

        written.append(save_torus_pictures(beside(out, ".png"), result))
    elif isinstance(source, Contour2D) and result.path is not None:  # 2D-to-3D: the query and its curve on the mesh
        from corrlib.plotting import save_contour_match

        path = result.path
        written.append(save_contour_match(beside(out, ".png"), path.contour_points, target, path.vertices,
                                          path.contour_index, title=f"energy {result.energy:.4g}"))
    return written


def write_match_outputs(result, source, target, out: Path, *, quiet: bool = False, pictures: bool = False) -> None:
    """The result files of a match beside the stem ``out``, all or none of them (the pictures if asked)."""
    from corrlib.io import staged_output

    with staged_output(out.parent, replaces=match_output_names(out.name).__contains__) as stage:
        written = [out.parent / p.name for p in stage_match_outputs(result, source, target, stage / out.name,
                                                                     pictures)]
    if not quiet:
        for path in written:
            print(f"wrote {path}")


def progress_printer(quiet: bool):
    """A solver callback that prints each progress report on stderr (nothing if ``quiet``)."""
    def callback(report):
        if not quiet:
            frac = f"{100 * report.fraction:5.1f}%" if report.fraction >= 0 else "   ..."
            print(f"  [{frac}] {report.stage} {report.message}", file=sys.stderr)

    return callback


def print_result_notes(result) -> None:
    """Warn (on stderr) when a mesh-to-mesh map reverses orientation on most of the shape, or a 2D-to-3D match's
    curve is short enough to have collapsed; note the other things a method tells about its result (a turn,
    copies, starts, a target matched unremeshed)."""
    from corrlib.methods.contour3d import remeshing_note, short_curve_note
    from corrlib.methods.kernel_matching import copies_note, reversal_note, start_note, turn_note

    for note in (reversal_note(result.extras), short_curve_note(result.extras)):
        if note:
            print(f"warning: {note}", file=sys.stderr)
    for said in (copies_note(result.extras), turn_note(result.extras), start_note(result.extras),
                 remeshing_note(result.extras)):
        if said:
            print(f"note: {said}", file=sys.stderr)


def print_collapse_note(result, source, target) -> None:
    """Warn (on stderr) when a mesh-to-mesh map has collapsed onto a negligible part of the target."""
    from corrlib.evaluation import collapse_note

    note = collapse_note(result.map_xy, source, target)
    if note:
        print(f"warning: {note}", file=sys.stderr)


def say_failures(failures: list[str], where: Path) -> None:
    """After a benchmark: how many runs failed, the first one's reason, and where the others are (stderr)."""
    if failures:
        print(f"error: {len(failures)} run{'s' if len(failures) > 1 else ''} failed, e.g. {failures[0]} "
              f"(every reason is in {where})", file=sys.stderr)


def jobs_option(text: str) -> int:
    """``--jobs``: 0 (all cores) or a positive number of worker processes; argparse names the option otherwise."""
    from corrlib.parallel import check_jobs

    try:
        value = int(text)
        check_jobs(value)  # the library's rule
    except (ValueError, CorrError):
        raise argparse.ArgumentTypeError(f"expected 0 (all cores) or a positive number of worker processes, "
                                         f"got {text}") from None
    return value


def add_scale_out(p: argparse.ArgumentParser) -> None:
    """``--jobs`` / ``--scheduler`` of the commands that run independent jobs (see corrlib.parallel.job_executor)."""
    p.add_argument("--jobs", type=jobs_option, help="local worker processes (default: all cores)")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786) instead of local processes")


def command(sub, name: str, help: str, description: str | None = None, **defaults) -> argparse.ArgumentParser:
    """A subcommand: ``help`` is its one line in ``corr --help``, ``description`` its text in ``corr NAME --help``."""
    p = sub.add_parser(name, help=help, description=description or help)
    p.set_defaults(**defaults)
    return p


#: the ``-o`` help of the commands that write a match's set of files beside one stem
STEM_HELP = ("output path without suffix; the files written there replace every file an earlier match wrote under "
             f"that stem ({', '.join(MATCH_OUTPUT_SUFFIXES)})")


def add_output(p: argparse.ArgumentParser, default: str, help: str = STEM_HELP, *,
                quiet: bool = True) -> None:
    """``-o`` (with its default and help) and, unless ``quiet`` is false, ``-q``."""
    p.add_argument("-o", "--output", default=default, help=help)
    if quiet:
        p.add_argument("-q", "--quiet", action="store_true")
