"""One loader and one table of formats: `corr info` agrees with `load_mesh`, `corr --help` lists every command."""

import argparse
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from corrlib import bench, io
from corrlib.cli import build_parser, main
from corrlib.errors import CorrError, FileFormatError
from corrlib.io import dialog_filter, load_mesh, load_shape, parse_svg_path
from corrlib.shapes import Contour2D, TriMesh

# ----------------------------------------------------------------------------- small files


def _octahedron_stl() -> str:
    """ASCII STL of an octahedron: 8 facets, 24 corners that weld into 6 vertices."""
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    faces = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    lines = ["solid octahedron"]
    for f in faces:
        n = np.cross(v[f[1]] - v[f[0]], v[f[2]] - v[f[0]])
        n /= np.linalg.norm(n)
        lines += [f"facet normal {n[0]:g} {n[1]:g} {n[2]:g}", "  outer loop"]
        lines += [f"    vertex {v[i][0]:g} {v[i][1]:g} {v[i][2]:g}" for i in f]
        lines += ["  endloop", "endfacet"]
    return "\n".join(lines + ["endsolid octahedron"]) + "\n"


def _hexagonal_prism_off() -> str:
    """A closed hexagonal prism: two hexagon faces and six quads (fan-triangulated: 20 triangles)."""
    top = [(math.cos(k * math.pi / 3), math.sin(k * math.pi / 3), 1.0) for k in range(6)]
    bottom = [(x, y, 0.0) for x, y, _ in top]
    text = "OFF\n12 8 0\n" + "".join(f"{x:.6f} {y:.6f} {z:.1f}\n" for x, y, z in top + bottom)
    text += "6 0 1 2 3 4 5\n6 11 10 9 8 7 6\n"
    text += "".join(f"4 {k} {k + 6} {(k + 1) % 6 + 6} {(k + 1) % 6}\n" for k in range(6))
    return text


TRIANGLE = "0 0 0\n1 0 0\n0 1 0\n"
TETRA_FACES = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"

CASES = {
    # name: (file name, content, accepted?, part of the message when refused)
    "stl": ("octahedron.stl", _octahedron_stl(), True, None),
    "hexagons": ("prism.off", _hexagonal_prism_off(), True, None),
    "header-face-count-lies": ("count.off", "OFF\n3 999999999 0\n" + TRIANGLE + "3 0 1 2\n", False,
                               "announces 3 vertices and 999999999 faces"),
    "face-line-lies": ("face.off", "OFF\n3 1 0\n" + TRIANGLE + "999999999 0 1 2\n", False,
                       "face 0 announces 999999999 vertices but lists 3"),
    "more-vertices-than-lines": ("short.off", "OFF\n5 4 0\n" + TRIANGLE + "0 0 1\n" + TETRA_FACES, False,
                                 "announces 5 vertices and 4 faces"),
    "face-line-read-as-vertex": ("shifted.off", "OFF\n5 3 0\n" + TRIANGLE + "0 0 1\n" + TETRA_FACES, False,
                                 "is a face line"),
    "non-manifold": ("nm.off", ("OFF\n5 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 -1\n"
                                "3 0 1 2\n3 1 2 3\n3 1 2 4\n3 0 2 3\n"), False, "shared by more than two faces"),
}


def _load(path):
    try:
        return load_mesh(path), None
    except CorrError as exc:
        return None, str(exc)


@pytest.mark.parametrize("case", list(CASES))
def test_info_and_load_mesh_agree(tmp_path, capsys, case):
    name, content, accepted, message = CASES[case]
    path = tmp_path / name
    path.write_text(content)
    mesh, error = _load(path)
    status = main(["info", "--json", str(path)])
    out, err = capsys.readouterr()
    if accepted:
        assert error is None, error
        assert status == 0, err
        info = json.loads(out)
        assert info["valid"] and info["kind"] == "mesh"
        assert (info["vertices"], info["faces"]) == (mesh.n_vertices, mesh.n_faces)
        assert not [fd for fd in info["findings"] if fd["level"] == "error"]
    else:
        assert mesh is None and message in error
        assert status == 2
        assert err.startswith("error: ") and name in err
        assert error in err  # the very message `corr match` would give
        assert "Traceback" not in err


def test_valid_stl_is_welded_and_closed(tmp_path, capsys):
    path = tmp_path / "octahedron.stl"
    path.write_text(_octahedron_stl())
    mesh = load_mesh(path)
    assert (mesh.n_vertices, mesh.n_faces) == (6, 8) and mesh.is_closed
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "no problems found" in out and "components" not in out


def test_hexagon_faces_are_fan_triangulated(tmp_path, capsys):
    path = tmp_path / "prism.off"
    path.write_text(_hexagonal_prism_off())
    mesh = load_mesh(path)
    assert (mesh.n_vertices, mesh.n_faces) == (12, 20) and mesh.is_closed
    assert main(["info", "--json", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["closed"] is True and info["enclosed_volume"] == pytest.approx(mesh.enclosed_volume())


def test_info_of_an_invalid_mesh_still_reports_every_finding(tmp_path, capsys):
    name, content, _, _ = CASES["non-manifold"]
    path = tmp_path / name
    path.write_text(content)
    assert main(["info", str(path)]) == 2
    out, err = capsys.readouterr()
    assert "[non-manifold-edge]" in out and "valid: False" in out
    assert err.startswith(f"error: {name}: ")


# ----------------------------------------------------------------------------- load_shape


def test_load_shape_dispatches_on_the_table(tmp_path):
    assert isinstance(load_shape(_write(tmp_path / "p.off", _hexagonal_prism_off())), TriMesh)
    circle = "".join(f"{math.cos(t):.6f} {math.sin(t):.6f}\n" for t in np.linspace(0, 2 * np.pi, 40, endpoint=False))
    for suffix in sorted(io.POINT_SUFFIXES):
        assert isinstance(load_shape(_write(tmp_path / f"c{suffix}", circle)), Contour2D)
    with pytest.raises(FileFormatError, match=r"x\.abc: unsupported shape format '\.abc'"):
        load_shape(_write(tmp_path / "x.abc", "1 2\n"))


def _write(path, text):
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- the table of formats


def test_one_table_of_formats():
    assert dialog_filter("mesh") == "Meshes (*.off *.obj *.ply *.stl);;All files (*)"
    assert dialog_filter("mesh", save=True) == "Meshes (*.off *.obj *.ply)"
    assert dialog_filter("ground-truth", all_files=False) == "Ground truth (*.vts)"
    assert io.MESH_SUFFIXES == {".off", ".obj", ".ply", ".stl"}
    assert io.CONTOUR_SUFFIXES == io.IMAGE_SUFFIXES | io.POINT_SUFFIXES | io.SVG_SUFFIXES
    for fmt in io.FORMATS:
        assert fmt.kind in io.KIND_LABELS and fmt.suffixes and fmt.description
        assert all(s.startswith(".") and s == s.lower() for s in fmt.suffixes)
    # the benchmark reads the same table: every contour format; meshes that define a vertex order
    assert set(bench.CONTOUR_SUFFIXES) == io.CONTOUR_SUFFIXES
    assert set(bench.MESH_SUFFIXES) == io.MESH_SUFFIXES - {".stl"} == io.ORDERED_MESH_SUFFIXES
    # corr morph writes the writable mesh formats
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    fmt_action = next(a for a in sub.choices["morph"]._actions if a.dest == "format")
    assert {"." + c for c in fmt_action.choices} == io.MESH_WRITE_SUFFIXES
    with pytest.raises(ValueError, match="unknown file kind"):
        dialog_filter("meshes")


def test_svg_numbers_after_close_are_refused_not_looped_on():
    with pytest.raises(FileFormatError, match="numbers after Z"):
        parse_svg_path("M0 0 L1 0 L1 1 Z 5 5")


# ----------------------------------------------------------------------------- corr --help


def test_help_lists_every_subcommand_on_one_line():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    helps = {choice.dest: choice.help for choice in sub._choices_actions}
    assert set(helps) == set(sub.choices)
    env = dict(os.environ, COLUMNS="80")
    proc = subprocess.run([sys.executable, "-m", "corrlib.cli", "--help"], capture_output=True, text=True,
                          env=env, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    for name, help_text in helps.items():
        assert help_text and help_text.strip() and "\n" not in help_text, name
        rows = [i for i, line in enumerate(lines) if line.split()[:1] == [name]]
        assert len(rows) == 1, (name, proc.stdout)
        line = lines[rows[0]]
        assert line.split(None, 1)[1:] == [help_text], line  # the whole description, on the command's line
        follower = lines[rows[0] + 1] if rows[0] + 1 < len(lines) else ""
        assert not follower.startswith(" " * 8), f"{name}: its description wraps onto a second line"
