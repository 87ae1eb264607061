"""Careless and hostile input to `corr`: a named error and exit status 2, never a traceback, a hang, a
silently wrong answer or a half-written result set (issue 20)."""

import csv
import json
import os
import re
import resource
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from _data import TOSCA
from corrlib.assignment import linear_assignment
from corrlib.cli import main

WOLF0, WOLF1 = str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off")
FAST = ["--method", "descriptor-nn"]


def corr(*args):
    """The `corr` command in a fresh interpreter: (exit status, stderr)."""
    done = subprocess.run([sys.executable, "-m", "corrlib.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300, env={**os.environ, "MPLBACKEND": "Agg"})
    return done.returncode, done.stderr


def error_of(capsys, argv) -> str:
    """Run ``corr`` in-process; it must exit with status 2 and one ``error:`` line, which is returned."""
    assert main(list(map(str, argv))) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("error: ") and "Traceback" not in "\n".join(err)
    return err[-1]


def files_in(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else []


# ----------------------------------------------------------------------------- output locations


def test_output_locations_are_checked_before_any_work(tmp_path, capsys):
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for argv in (["match", WOLF0, WOLF1, *FAST, "-o", blocker / "res"],
                 ["refine", WOLF0, WOLF1, "--init", tmp_path / "missing.txt", "-o", blocker / "res"],
                 ["morph", WOLF0, WOLF1, *FAST, "-o", blocker / "m"],
                 ["eval", tmp_path / "missing.txt", "--gt-source", TOSCA / "wolf0.vts", "--gt-target",
                  TOSCA / "wolf1.vts", "--target", WOLF1, "--plot", blocker / "c.png"]):
        start = time.perf_counter()
        message = error_of(capsys, argv)
        assert "afile" in message and "is a file" in message, message
        assert time.perf_counter() - start < 5  # nothing was computed first
    assert "does not name a file" in error_of(capsys, ["match", WOLF0, WOLF1, *FAST, "-o", ""])
    assert "is a folder" in error_of(capsys, ["match", WOLF0, WOLF1, *FAST, "-o", tmp_path])
    assert "Dask scheduler address" in error_of(capsys, ["bench", tmp_path, "-o", tmp_path / "b", "--scheduler",
                                                        "not a url"])
    assert not (tmp_path / "b").exists()
    dataset = tmp_path / "pair"
    dataset.mkdir()
    for name in ("wolf0", "wolf1"):
        (dataset / f"{name}.off").symlink_to(TOSCA / f"{name}.off")
    for argv in (["bench", dataset, *FAST, "--jobs", "-3", "-o", tmp_path / "b"],
                 # found by fuzzing: bench-retrieval started, failed every query and left its outputs
                 ["bench-retrieval", dataset, dataset, "--jobs", "-3", "-o", tmp_path / "b"]):
        with pytest.raises(SystemExit) as stopped:
            main(list(map(str, argv)))
        assert stopped.value.code == 2
        assert "argument --jobs: expected 0 (all cores) or a positive number of worker processes, got -3" in \
            capsys.readouterr().err
        assert not (tmp_path / "b").exists()  # not even environment.json


def test_a_folder_where_an_output_file_goes_stops_before_any_work_and_a_dotted_stem_keeps_its_dot(tmp_path,
                                                                                                   capsys):
    from corrlib.io import staged_output
    from corrlib.methods.base import MatchResult

    (tmp_path / "x.map_yx.txt").mkdir()
    start = time.perf_counter()
    message = error_of(capsys, ["match", WOLF0, WOLF1, *FAST, "-o", tmp_path / "x"])
    assert "x.map_yx.txt" in message and "is a folder" in message, message
    assert time.perf_counter() - start < 5 and files_in(tmp_path) == ["x.map_yx.txt"]
    # the staging itself moves nothing where one destination is a folder
    (tmp_path / "set").mkdir()
    (tmp_path / "set" / "b.txt").mkdir()
    with pytest.raises(Exception, match="b.txt: an output file goes there, but it is a folder"):
        with staged_output(tmp_path / "set") as stage:
            (stage / "a.txt").write_text("a")
            (stage / "b.txt").write_text("b")
    assert files_in(tmp_path / "set") == ["b.txt"]
    # "run.v1" and "run.v2" are two result sets, not one overwritten by the other
    for stem in ("run.v1", "run.v2"):
        assert main(["match", WOLF0, WOLF1, *FAST, "-o", str(tmp_path / "dots" / stem), "-q"]) == 0
    assert files_in(tmp_path / "dots") == sorted(f"run.{v}{suffix}" for v in ("v1", "v2")
                                                 for suffix in (".json", ".map_xy.txt", ".map_yx.txt", ".npz"))
    assert MatchResult.load(tmp_path / "dots" / "run.v1").method == "descriptor-nn"


def test_a_morph_extrapolates_at_most_as_far_as_the_studio_scrubs(capsys, tmp_path):
    """--t-max 1e308 wrote frames of infinite coordinates; the last time is bounded as in the studio."""
    from corrlib.methods.divergence_free import SEQUENCE_T_MAX

    for t_max in ("1e308", str(SEQUENCE_T_MAX * 1.01)):
        message = error_of(capsys, ["morph", WOLF0, WOLF1, *FAST, "--t-max", t_max, "-o", tmp_path / "m"])
        assert f"at most {SEQUENCE_T_MAX:g}" in message, message
    assert not (tmp_path / "m").exists() or files_in(tmp_path / "m") == []


def test_a_failed_command_leaves_no_empty_folder_and_fewer_frames_replace_the_sequence(capsys, tmp_path):
    """Found by fuzzing: a morph stopped by its input left its new, empty output folder behind, and a morph of
    fewer frames into the folder of an earlier one left that one's last frames beside the new ones."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    from corrlib.io import save_mesh

    save_mesh(tmp_path / "two.off", np.vstack([corners, corners + 5]), np.vstack([faces, faces + 4]))  # two parts
    assert "connected components" in error_of(capsys, ["morph", tmp_path / "two.off", WOLF1, *FAST,
                                                       "-o", tmp_path / "new" / "deep"])
    assert not (tmp_path / "new").exists()
    out = tmp_path / "m"
    for frames in ("5", "3"):
        assert main(["morph", WOLF0, WOLF1, *FAST, "--frames", frames, "-o", str(out), "-q"]) == 0
    assert sorted(p.name for p in out.glob("frame_*")) == ["frame_000.obj", "frame_001.obj", "frame_002.obj"]


def test_only_the_failed_command_s_own_empty_folders_are_removed(tmp_path):
    """The record of created folders starts afresh with every command: an earlier command's folder, even an
    empty one, is the user's once that command succeeded."""
    from corrlib.io import ensure_output_folder, remove_created_empty_folders

    ensure_output_folder(tmp_path / "earlier" / "deep")
    remove_created_empty_folders(remove=False)  # that command succeeded
    ensure_output_folder(tmp_path / "later" / "deep")
    (tmp_path / "existing").mkdir()
    ensure_output_folder(tmp_path / "existing")
    remove_created_empty_folders()  # this one failed
    assert (tmp_path / "earlier" / "deep").is_dir() and (tmp_path / "existing").is_dir()
    assert not (tmp_path / "later").exists()


def test_a_retrieval_in_which_meshes_fail_exits_with_one(capsys, tmp_path):
    """Found by fuzzing: a ranking of which every mesh failed was written with exit status 0."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n")
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    np.savetxt(tmp_path / "q.txt", np.column_stack([np.cos(angles), np.sin(angles)]))
    assert main(["retrieve", str(tmp_path / "q.txt"), str(tmp_path / "meshes"), "--jobs", "1", "-q",
                 "-o", str(tmp_path / "ranking.tsv")]) == 1
    err = capsys.readouterr().err
    assert "1 of 1 meshes could not be matched (none ranked)" in err and "Traceback" not in err
    assert "broken.off" in (tmp_path / "ranking.tsv").read_text()


def test_a_file_path_ending_in_a_separator_and_unreadable_ply_and_obj_files_are_named(capsys, tmp_path):
    """Found by fuzzing: `eval --plot DIR/` wrote a picture named like the folder; a PLY without the y
    property and an OBJ face beyond its vertices gave trimesh's bare KeyError / IndexError text."""
    from corrlib.io import check_output_file
    from corrlib.errors import InputError

    with pytest.raises(InputError, match="ends with a separator, so it names a folder"):
        check_output_file(f"{tmp_path}/plots/", "--plot")
    assert not (tmp_path / "plots").exists()
    (tmp_path / "bad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n"
                                      "0\n1\n2\n")
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    message = error_of(capsys, ["match", tmp_path / "bad.ply", WOLF1, *FAST, "-o", tmp_path / "r"])
    assert "bad.ply: cannot read mesh: the property 'y' is missing" in message
    message = error_of(capsys, ["match", tmp_path / "bad.obj", WOLF1, *FAST, "-o", tmp_path / "r"])
    assert "bad.obj: cannot read mesh: a face refers to a vertex the file does not have" in message


def test_a_target_that_cannot_be_remeshed_is_said_and_left_out_of_a_ranking(capsys, tmp_path):
    """Found by fuzzing: at 800 vertices the quadric collapse pinches wolf0's tail into an edge of four faces.
    The match fell back to the mesh as given silently, and retrieval ranked that energy among those of meshes
    remeshed alike (first). A match now says so; a ranking leaves the mesh out, without matching it."""
    angles = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    np.savetxt(tmp_path / "q.txt", np.column_stack([2 * np.cos(angles), np.sin(angles)]))
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "wolf0.off").write_text(Path(WOLF0).read_text())
    assert main(["retrieve", str(tmp_path / "q.txt"), str(tmp_path / "meshes"), "--jobs", "1", "-q",
                 "--param", "mesh_vertices=800"]) == 1
    out = capsys.readouterr()
    assert "inf" in out.out and "remeshing to 800 vertices gave an invalid mesh" in out.out, out.out
    # the input is not at fault (found by fuzzing: the loader's advice to repair it was passed on)
    assert "corr repair" not in out.out and "mesh_vertices" in out.out, out.out
    assert main(["match", str(tmp_path / "q.txt"), WOLF0, "--method", "contour3d", "--param", "mesh_vertices=800",
                 "--param", "n_contour=60", "-q", "-o", str(tmp_path / "m")]) == 0
    assert "note: the target could not be remeshed" in capsys.readouterr().err
    # match-contour said nothing (found by fuzzing)
    assert main(["match-contour", str(tmp_path / "q.txt"), WOLF0, "--param", "mesh_vertices=800",
                 "--param", "n_contour=60", "-q", "-o", str(tmp_path / "mc")]) == 0
    assert "note: the target could not be remeshed" in capsys.readouterr().err


def test_counts_below_one_are_refused(capsys, tmp_path):
    assert "--top must be at least 1" in error_of(capsys, ["retrieve", tmp_path / "q.txt", tmp_path, "--top", "-5"])
    assert "--repeat must be at least 1" in error_of(capsys, ["perf", "foundation", "--repeat", "0"])


def test_descriptors_that_cannot_tell_points_apart_are_named(capsys, tmp_path):
    """SHOT on a coarse round surface is empty at every vertex: a nearest-neighbour map would send every
    vertex to one, and a functional map would divide by zero; both methods say why instead."""
    import trimesh

    from corrlib.io import save_mesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    path = tmp_path / "ball.off"
    save_mesh(path, sphere.vertices, sphere.faces)
    for method in ("descriptor-nn", "fmap-zoomout"):
        message = error_of(capsys, ["match", path, path, "--method", method, "--param", "descriptor=shot",
                                    "-o", tmp_path / method])
        assert "ball.off: the shot descriptors are the same at every vertex" in message, message


@pytest.mark.skipif(os.geteuid() != 0, reason="needs root to become another user (setpriv)")
def test_read_only_folder_for_another_user():
    """As root, a folder is never read-only; as the unprivileged user `nobody` it is."""
    import shutil
    import tempfile

    base = Path(tempfile.mkdtemp())  # pytest's own folders are private to root
    base.chmod(0o755)
    read_only = base / "ro"
    read_only.mkdir(mode=0o555)
    read_only.chmod(0o555)
    home = base / "home"  # numba may not write beside an installed package nor in root's home
    home.mkdir()
    home.chmod(0o777)
    done = subprocess.run(["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", sys.executable, "-m",
                           "corrlib.cli", "match", WOLF0, WOLF1, *FAST, "-o", str(read_only / "res")],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "HOME": str(home)})
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines()[-1] == f"error: {read_only}: cannot write -o there (permission denied)"
    assert files_in(read_only) == []
    shutil.rmtree(base, ignore_errors=True)


def _limit_file_size(kilobytes):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (kilobytes * 1024, kilobytes * 1024))


@pytest.mark.parametrize("kilobytes", [20, 75])
def test_full_disk_leaves_no_partial_result_set(tmp_path, kilobytes):
    """``ulimit -f``: the first file (20 kB) or the picture after the maps (75 kB) cannot be written."""
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "corrlib.cli", "match", WOLF0, WOLF1, *FAST, "--pictures",
                           "-o", out / "res"],
                          capture_output=True, text=True, timeout=300, preexec_fn=_limit_file_size(kilobytes),
                          env={**os.environ, "MPLBACKEND": "Agg"})
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {out}/res") and "file too large" in last and ".partial" not in last, last
    assert not out.exists()  # not even hidden temporary files: the folder the command made is gone too


@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_interrupted_morph_leaves_nothing(tmp_path, sig, status):
    """Interrupted while writing 2,000 frames: the staging folder goes, nothing is half-written. SIGHUP (the
    terminal or the ssh session closed) left the spectrum worker, a pool's processes and their temporary
    files behind; it is now a termination like SIGTERM."""
    out = tmp_path / "m"
    # the linear motion, whose frames are ready at once: the writing, which is what is interrupted, starts sooner.
    # As a user's Ctrl-C would find it: a test run started in the background (no job control) ignores SIGINT, and
    # its children inherit that
    proc = subprocess.Popen([sys.executable, "-m", "corrlib.cli", "morph", WOLF0, WOLF1, *FAST, "--frames", "2000",
                             "--interpolation", "linear", "-o", out], stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 120
    while not any(p.name.startswith(".partial-") for p in (out.iterdir() if out.exists() else [])):
        assert proc.poll() is None and time.time() < deadline, "the frames were never being written"
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(sig)
    code = proc.wait(timeout=60)
    stderr = proc.stderr.read()
    assert code == status, stderr
    assert "Traceback" not in stderr
    assert not out.exists()  # the staging folder and the output folder the command made


# ----------------------------------------------------------------------------- bad files


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG that announces ``width x height`` pixels (greyscale) and holds one compressed row."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(b"\0" * 64))
                     + chunk(b"IEND", b""))


@pytest.mark.filterwarnings("error::RuntimeWarning")  # no raw overflow warnings before the message
def test_bad_files_give_named_errors(tmp_path, capsys):
    t = tmp_path
    (t / "labels.txt").write_text("a\n")
    (t / "random.bin").write_bytes(np.random.default_rng(0).bytes(400))
    (t / "folder").mkdir()
    np.savez(t / "frac.npz", map_xy=np.arange(4344) + 0.7)
    np.savez(t / "wide.npz", map_xy=np.zeros((4344, 2), dtype=int))
    np.savez(t / "nan.npz", map_xy=np.full(4344, np.nan))
    whole = (t / "frac.npz").read_bytes()
    (t / "cut.npz").write_bytes(whole[: len(whole) // 2])
    np.savetxt(t / "short.txt", np.arange(100), fmt="%d")
    (t / "landmarks.txt").write_text("0 0\n5 5\n99999 3\n")
    (t / "fraction.txt").write_text("0 12.5\n100 200\n")
    (t / "nan.txt").write_text("0 1\n100 200\n300 nan\n")
    lines = (TOSCA / "wolf0.off").read_text().splitlines()
    lines[-1] = "3 0 1 99999999999999999999"
    (t / "bigindex.off").write_text("\n".join(lines) + "\n")
    (t / "triangle.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    (t / "huge.off").write_text("OFF\n4 4 0\n0 0 0\n1e308 0 0\n0 1e308 0\n0 0 1e308\n3 0 2 1\n3 0 1 3\n3 0 3 2\n"
                                "3 1 2 3\n")
    (t / "liar.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n999999999 0 1 2\n")
    circle = np.column_stack([np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))])
    np.savetxt(t / "big.txt", circle * 1e300)
    np.savetxt(t / "tiny.txt", circle * 1e-300)
    np.savetxt(t / "good.txt", circle)
    _png_header_only(t / "bomb.png", 20000, 20000)
    gt = ["--gt-source", TOSCA / "wolf0.vts", "--gt-target", TOSCA / "wolf1.vts", "--target", WOLF1]
    out = ["-o", t / "out" / "r"]
    cases = {
        ("match-contour", t / "good.txt", WOLF0, "--mesh-labels", t / "labels.txt", *out):
            "non-numeric entry 'a'",
        ("match-contour", t / "good.txt", WOLF0, "--query-labels", t / "nowhere.txt", *out):
            "nowhere.txt: file not found",
        ("refine", WOLF0, WOLF1, "--init", t / "random.bin", *out): "random.bin",
        ("refine", WOLF0, WOLF1, "--init", t / "folder", *out): "folder: not a file",
        ("match", t / "folder", WOLF1, *FAST, *out): "folder: a folder, not a shape file",
        ("refine", WOLF0, WOLF1, "--init", t / "landmarks.txt", *out):
            "landmarks.txt: landmark 2: source vertex 99999 is out of range for a 4344-vertex source",
        ("refine", WOLF0, WOLF1, "--init", t / "fraction.txt", *out):
            "fraction.txt: the --init landmarks file must hold integer vertex indices; data line 1, column 2 is 12.5",
        ("refine", WOLF0, WOLF1, "--init", t / "nan.txt", *out): "data line 3, column 2 is nan",
        ("eval", t / "frac.npz", *gt): "must hold integer target indices; entry 0 is 0.7",
        ("eval", t / "wide.npz", *gt): "found shape (4344, 2)",
        ("eval", t / "nan.npz", *gt): "entry 0 is nan",
        ("eval", t / "cut.npz", *gt): "cut.npz: cannot read the .npz file",
        ("eval", t / "short.txt", *gt): "short.txt: the map has 100 entries, but the ground truth",
        ("match", t / "bigindex.off", WOLF1, *FAST, *out): "refers to vertex 99999999999999999999",
        ("match", t / "triangle.off", WOLF1, *FAST, *out): "triangle.off: a mesh of 3 vertices is too small",
        ("match", t / "huge.off", WOLF1, *FAST, *out): "huge.off: coordinates up to 1e+308 overflow",
        ("info", t / "liar.off"): "face 0 announces 999999999 vertices but lists 3",
        ("match-contour", t / "big.txt", WOLF0, *out): "big.txt: coordinates up to",
        ("match-contour", t / "tiny.txt", WOLF0, *out): "tiny.txt: the coordinates span only",
        ("match-contour", t / "bomb.png", WOLF0, *out): "downsample it first",
        ("morph", WOLF0, WOLF1, *FAST, "--frames", 10 ** 8, "-o", t / "m"): "--frames must be between 2 and 2000",
    }
    for argv, expected in cases.items():
        message = error_of(capsys, argv)
        assert expected in message, (argv, message)
    assert files_in(t / "out") == []


def test_a_flat_closed_mesh_has_no_relative_volume_change_and_no_section(tmp_path, capsys):
    """A closed mesh pressed flat (every z = 0) encloses no volume: a morph from it reports no relative volume
    change (it divided by zero), and its section across the flat side encloses no area (it divided by zero in
    the contour's scaling); both are said, by name."""
    from corrlib.io import load_mesh, load_result, save_mesh

    wolf = load_mesh(WOLF0)
    flat = wolf.vertices * [1.0, 1.0, 0.0]
    save_mesh(tmp_path / "flat.off", flat, wolf.faces)
    argv = ["morph", tmp_path / "flat.off", WOLF1, "--param", "n_samples=300", "--param", "n_fields=100",
            "--param", "max_iter=2", "--frames", 3, "-o", tmp_path / "m", "-q"]
    assert main(list(map(str, argv))) == 0
    output = capsys.readouterr()
    assert "flat.off encloses none (a flat closed mesh)" in output.out and "Traceback" not in output.err
    result = load_result(tmp_path / "m" / "result")[1]
    assert "volume_change" not in result.get("extras", {})
    rows = (tmp_path / "m" / "volumes.csv").read_text().splitlines()[1:]
    assert rows and all(row.endswith("not applicable (no volume at t = 0)") for row in rows), rows
    (tmp_path / "dataset").mkdir()  # a benchmark of it fails, and says why even when quiet
    save_mesh(tmp_path / "dataset" / "flat.off", flat, wolf.faces)
    argv = ["bench-contour", tmp_path / "dataset", "--planes", "cross", "--no-pictures", "-q", "-o", tmp_path / "b"]
    assert main(list(map(str, argv))) == 1
    assert ("error: 1 run failed, e.g. flat-cross -> flat: flat.off-cross: the contour encloses no area"
            in capsys.readouterr().err)


def test_a_mesh_with_turned_faces_is_matched_as_the_mesh_it_should_be(tmp_path, capsys):
    """Every third face of wolf0 turned (normals in and out): the faces are turned back on load, the user is
    warned, and the map is the one of the clean file (it was a left/right-swapped map, silently)."""
    from corrlib.io import load_mesh, save_mesh
    from corrlib.methods.base import MatchResult

    wolf = load_mesh(WOLF0)
    faces = wolf.faces.copy()
    faces[::3] = faces[::3, ::-1]
    save_mesh(tmp_path / "turned.off", wolf.vertices, faces)
    save_mesh(tmp_path / "clean.off", wolf.vertices, wolf.faces)  # the same digits
    for name, source in (("clean", tmp_path / "clean.off"), ("turned", tmp_path / "turned.off")):
        assert main(list(map(str, ["match", source, WOLF1, *FAST, "-o", tmp_path / name, "-q"]))) == 0
    err = capsys.readouterr().err
    assert f"warning: turned.off: {len(faces[::3])} faces were turned to agree with their neighbours" in err
    np.testing.assert_array_equal(MatchResult.load(tmp_path / "turned").map_xy,
                                  MatchResult.load(tmp_path / "clean").map_xy)


def test_a_damaged_result_file_is_refused_by_name(tmp_path):
    """A result archive cut short (a full disk, a copy interrupted) raised zipfile's BadZipFile."""
    from corrlib.errors import FileFormatError
    from corrlib.methods.base import MatchResult

    MatchResult("descriptor-nn", np.arange(10), np.arange(10), 1.0, {}).save(tmp_path / "r")
    whole = (tmp_path / "r.npz").read_bytes()
    (tmp_path / "r.npz").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(FileFormatError, match=r"r\.npz: cannot read result"):
        MatchResult.load(tmp_path / "r")
    MatchResult("descriptor-nn", np.arange(10), np.arange(10), 1.0, {}).save(tmp_path / "r")
    for sidecar, message in [("[1, 2]", "metadata is a JSON object, found a list"),
                             ('{"timings": 5}', "not a result written by corrlib"),
                             ('{"search": {"foo": 1}}', "not a result written by corrlib")]:
        (tmp_path / "r.json").write_text(sidecar)
        with pytest.raises(FileFormatError, match=message):
            MatchResult.load(tmp_path / "r")
    (tmp_path / "r.json").write_bytes(b"\xff\xfe{")
    with pytest.raises(FileFormatError, match="invalid JSON"):
        MatchResult.load(tmp_path / "r")


def test_a_hugely_negative_slack_is_no_slack():
    """A slack far below every score must not blow up the auction's ε: every row matched optimally."""
    from scipy.optimize import linear_sum_assignment

    score = np.random.default_rng(1).random((120, 120))
    optimum = score[np.arange(120), linear_sum_assignment(-score)[1]].sum()
    for slack in (-1.0, -1e10, -1e300):
        rows = linear_assignment(score, slack=slack)
        assert np.all(rows >= 0) and score[np.arange(120), rows].sum() == pytest.approx(optimum, rel=1e-12)


def test_interrupting_a_parallel_run_stops_its_workers():
    """Ctrl-C or SIGTERM (raised as an exception in the command) must not leave pool workers running their
    jobs after the command has ended."""
    from corrlib.parallel import job_executor

    with pytest.raises(KeyboardInterrupt):
        with job_executor(2, None) as pool:
            futures = [pool.submit(time.sleep, 120) for _ in range(2)]
            deadline = time.time() + 60
            while not all(f.running() for f in futures):
                assert time.time() < deadline
                time.sleep(0.05)
            workers = list(pool._processes.values())
            raise KeyboardInterrupt
    for worker in workers:
        worker.join(timeout=10)
        assert not worker.is_alive()


def test_bad_arguments_of_the_python_api_are_named(tmp_path, wolf_pair):
    """Library calls that wrote a wrong file or walked a string: integer colours above 255 (wrapped round),
    NaN vertices and out-of-range faces (written as they were), a result saved to a folder (written beside
    it), frame times that are not finite (NaN positions), a folder given to retrieve (one path per letter)."""
    from corrlib.errors import CorrError
    from corrlib.io import save_mesh
    from corrlib.methods.base import MatchResult
    from corrlib.morph import frame_positions
    from corrlib.progress import run
    from corrlib.retrieval import retrieve
    from corrlib.shapes import Contour2D

    wolf0, wolf1 = wolf_pair
    v, f = wolf0.vertices, wolf0.faces
    for args, message in [((v, f, np.full((len(v), 3), 300)), "integer colours must be 0 to 255, got 300 to 300"),
                          ((v * np.nan, f), "with NaN or infinite values"),
                          ((v, f + len(v)), f"indices of the {len(v)} vertices"),
                          ((v[:, :2], f), "finite coordinates of shape (n, 3), got shape")]:
        with pytest.raises(CorrError, match=re.escape(message)):
            save_mesh(tmp_path / "m.off", *args)
    assert files_in(tmp_path) == []
    result = MatchResult("descriptor-nn", np.arange(wolf0.n_vertices), None, 1.0, {})
    with pytest.raises(CorrError, match="give a file stem"):
        result.save(tmp_path)
    assert files_in(tmp_path.parent).count(tmp_path.name + ".npz") == 0
    with pytest.raises(CorrError, match="times must be finite, got nan"):
        frame_positions(result, wolf0, wolf1, [0.5, float("nan")])
    circle = Contour2D(np.column_stack([np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))]))
    with pytest.raises(CorrError, match="no mesh files .* in it or its subfolders"):  # a folder is a collection
        run(retrieve(circle, str(tmp_path), jobs=1))
    with pytest.raises(CorrError, match="'.*missing' is not a folder"):
        run(retrieve(circle, str(tmp_path / "missing"), jobs=1))
    for collection, kind in (([wolf0, circle], "Contour2D"), ([3], "int")):
        with pytest.raises(CorrError, match=f"meshes\\[.\\] must be a mesh file or a TriMesh, got {kind}"):
            run(retrieve(circle, collection, jobs=1))
    with pytest.raises(CorrError, match="the query must be a Contour2D .*, got TriMesh"):
        run(retrieve(wolf0, [wolf1], jobs=1))


def test_an_outline_too_thin_to_fill_is_named(tmp_path, capsys):
    """An ellipse of aspect 10^7 is a valid outline, but its triangulation holds triangles of no area that cut
    the Laplacian apart; the eigensolver's "disconnected" was said instead of what is wrong with the drawing.
    Both 2D-to-3D methods and the command line name the outline, and nothing is written."""
    from corrlib.errors import ContourError
    from corrlib.io import load_mesh
    from corrlib.methods import solve
    from corrlib.shapes import Contour2D

    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    sliver = Contour2D(np.column_stack([np.cos(t), 1e-7 * np.sin(t)]), name="sliver")
    wolf = load_mesh(WOLF0)
    for method in ("contour3d", "contour-views"):
        with pytest.raises(ContourError, match="sliver: the outline is too thin somewhere to be filled"):
            solve(method, sliver, wolf)
    np.savetxt(tmp_path / "sliver.txt", sliver.points)
    assert main(["retrieve", str(tmp_path / "sliver.txt"), str(TOSCA), "-o", str(tmp_path / "r"), "-q"]) == 2
    assert "error: sliver.txt: the outline is too thin somewhere" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_counts_and_levels_of_contour_helpers_are_named(tmp_path):
    """A resampling to "x", None, NaN or 10^12 points (a MemoryError), an image threshold of "x" (a NumPy
    UFuncTypeError) and a bootstrap of 0 resamples (an IndexError) are refused by name."""
    from corrlib.errors import CorrError
    from corrlib.io import load_contour
    from corrlib.retrieval import map_interval
    from corrlib.shapes import Contour2D

    circle = Contour2D(np.column_stack([np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))]),
                       name="circle")
    for count in ("x", None, float("nan"), 10 ** 12, 2):
        with pytest.raises(CorrError, match="circle: cannot resample to"):
            circle.resample(count)
    assert circle.resample(np.int64(50)).n_points == 50
    image = np.zeros((40, 40), dtype=np.uint8)
    image[10:30, 12:28] = 255
    from PIL import Image

    Image.fromarray(image).save(tmp_path / "blob.png")
    with pytest.raises(CorrError, match="blob.png: threshold must be a grey level"):
        load_contour(tmp_path / "blob.png", threshold="x")
    assert load_contour(tmp_path / "blob.png", threshold=128).n_points >= 10
    for resamples in (0, -1, 2.5):
        with pytest.raises(CorrError, match="resamples must be a whole number"):
            map_interval([0.5, 1.0], resamples=resamples)


def test_a_closed_standard_output_keeps_the_written_results(tmp_path):
    """``corr match … -o r | true``: the results were printed before the files were written, so the closed pipe
    ended the command with "error: broken pipe" and no files. The files now come first, and the closed pipe
    ends the command quietly with the shell's status for it."""
    out = tmp_path / "r"
    command = [sys.executable, "-m", "corrlib.cli", "match", WOLF0, WOLF1, *FAST, "-o", str(out)]
    done = subprocess.run(["bash", "-c", "set -o pipefail; \"$@\" | true", "bash", *command], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 141 and "error" not in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert (tmp_path / "r.map_xy.txt").exists() and (tmp_path / "r.npz").exists()


def test_two_benchmarks_into_one_folder_at_once_are_refused(tmp_path, capsys):
    """Two ``corr bench`` runs writing one folder at once each reported the other's records as its own; the
    second is now refused while the first holds the folder."""
    from corrlib.io import exclusive_folder

    out = tmp_path / "bench"
    out.mkdir()
    with exclusive_folder(out, "corr bench"):
        code = main(["bench", str(TOSCA), "--pairs", str(_wolf_pairs(tmp_path)), "--method", "descriptor-nn",
                     "-o", str(out), "--jobs", "1", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "another corr bench is writing into this folder" in err and str(out) in err, err
    assert list(out.iterdir()) == []


def _wolf_pairs(folder: Path) -> Path:
    pairs = folder / "pairs.txt"
    pairs.write_text("wolf0 wolf1\n")
    return pairs


def test_a_benchmark_in_the_c_locale_with_a_file_name_that_is_not_utf8(tmp_path):
    """``LC_ALL=C`` and a mesh named with a Latin-1 byte: the summary's "≤" and the name's byte made the
    writers raise UnicodeEncodeError after every pair had run; files are now written as UTF-8, the name as its
    own bytes."""
    data = tmp_path / "data"
    data.mkdir()
    odd = os.fsencode(str(data)) + b"/\xe9wolf0.off"
    with open(odd, "wb") as fh:
        fh.write(Path(WOLF0).read_bytes())
    (data / "wolf1.off").write_bytes(Path(WOLF1).read_bytes())
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
    done = subprocess.run([sys.executable, "-m", "corrlib.cli", "bench", str(data), *FAST, "-o", str(tmp_path / "b"),
                           "--jobs", "1", "-q"], capture_output=True, timeout=300, env=env)
    assert done.returncode == 0 and b"Traceback" not in done.stderr, done.stderr.decode(errors="replace")
    summary = (tmp_path / "b" / "summary.md").read_text(encoding="utf-8")
    assert "≤0.05" in summary
    assert b"\xe9wolf0" in (tmp_path / "b" / "errors.csv").read_bytes()
    done = subprocess.run([sys.executable, "-m", "corrlib.cli", "match", odd, WOLF1, *FAST, "--pictures", "-o",
                           str(tmp_path / "m")], capture_output=True, timeout=300, env=env)
    assert done.returncode == 0 and (tmp_path / "m.png").exists(), done.stderr.decode(errors="replace")


@pytest.mark.parametrize("length, fails", [(75, False), (76, True)])
def test_a_temporary_folder_too_long_for_the_workers_socket_is_named(tmp_path, monkeypatch, length, fails):
    """``TMPDIR`` of more than 75 bytes: the pool failed at its first job with "AF_UNIX path too long", naming
    neither the folder nor the variable. 75 bytes still work (measured with the fork server)."""
    import tempfile

    from corrlib.errors import InputError
    from corrlib.parallel import process_pool

    folder = "/" + "t" * (length - 1)
    monkeypatch.setattr(tempfile, "gettempdir", lambda: folder)
    if fails:
        with pytest.raises(InputError, match="TMPDIR"):
            process_pool(1)
    else:
        process_pool(1).shutdown()


def test_numba_threads_of_zero_are_named(monkeypatch, capsys):
    """``NUMBA_NUM_THREADS=0`` gave numba's traceback while it was imported."""
    monkeypatch.setenv("NUMBA_NUM_THREADS", "0")
    assert main(["match", WOLF0, WOLF1, *FAST, "-o", "unused"]) == 2
    assert "NUMBA_NUM_THREADS=0 must be a positive number" in capsys.readouterr().err


def test_a_picture_name_too_long_for_the_folder_is_named_before_the_retrieval(tmp_path, capsys):
    """``retrieve --pictures`` with a mesh named by 240 characters: its picture's name (the ranking's stem, the
    rank and the mesh's stem) is too long; that was found after the whole retrieval, and the ranking was lost."""
    from _data import SILHOUETTES

    folder = tmp_path / "meshes"
    folder.mkdir()
    long_name = "w" * 240 + ".off"
    (folder / long_name).write_bytes(Path(WOLF0).read_bytes())
    started = time.perf_counter()
    code = main(["retrieve", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(folder), "--jobs", "1", "-q",
                 "--pictures", "-o", str(tmp_path / "ranking.tsv")])
    err = capsys.readouterr().err
    assert code == 2 and long_name in err and "longer file name" in err, err
    assert time.perf_counter() - started < 5 and not (tmp_path / "ranking.tsv").exists()


def test_a_partial_match_can_be_evaluated_and_benchmarked(tmp_path, capsys):
    """``partial=true`` writes -1 for unmatched vertices; ``corr eval``, ``corr bench`` (every pair failed
    with "map_xy has indices outside [0, n]") and ``--maps`` refused the tool's own output. The matched rows
    are now scored and the unmatched ones counted; a command that needs a complete map says so."""
    import numpy as np

    from corrlib.io import load_vts

    from corrlib.io import load_mesh

    gt_source, gt_target = load_vts(TOSCA / "wolf0.vts"), load_vts(TOSCA / "wolf1.vts")
    partial = np.full(load_mesh(WOLF0).n_vertices, 0)
    partial[gt_source] = gt_target  # the ground truth itself, with its first 100 rows' sources unmatched
    partial[gt_source[:100]] = -1
    unmatched = int(np.count_nonzero(partial[gt_source] < 0))
    np.savetxt(tmp_path / "partial.txt", partial, fmt="%d")
    assert main(["eval", str(tmp_path / "partial.txt"), "--gt-source", str(TOSCA / "wolf0.vts"), "--gt-target",
                 str(TOSCA / "wolf1.vts"), "--target", WOLF1, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["unmatched_rows"] == unmatched >= 100 and summary["rows"] == gt_source.size - unmatched
    assert summary["mean"] < 1e-9
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "wolf0__wolf1.txt").write_text((tmp_path / "partial.txt").read_text())
    assert main(["bench", str(TOSCA), "--pairs", str(_wolf_pairs(tmp_path)), "--maps", f"part={maps}",
                 "-o", str(tmp_path / "b"), "--jobs", "1", "-q"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "b" / "errors.csv")))
    assert rows[0]["status"] == "ok" and abs(float(rows[0]["unmatched"]) - unmatched / gt_source.size) < 1e-9
    capsys.readouterr()
    assert main(["refine", WOLF0, WOLF1, "--init", str(tmp_path / "partial.txt"), "-o", str(tmp_path / "r")]) == 2
    assert f"{np.count_nonzero(partial < 0)} source vertices are unmatched (-1, a partial match); a complete map " \
           "is needed" in capsys.readouterr().err


def test_a_deleted_working_folder_is_named_as_the_reason(tmp_path, monkeypatch, capsys):
    """Run from a folder deleted while a shell was in it, every relative path names nothing: the messages say
    so (they said "file not found" or named the output "."), and absolute paths still work."""
    gone = tmp_path / "gone"
    gone.mkdir()
    monkeypatch.chdir(gone)
    gone.rmdir()
    wolf0, wolf1 = str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off")
    reason = "relative to the working folder, which no longer exists"
    for argv, named in ((["match", wolf0, wolf1, "--method", "descriptor-nn", "-o", "r"], "r: cannot write -o"),
                        (["info", "wolf0.off"], "wolf0.off: file not found"),
                        (["match", "wolf0.off", wolf1, "-o", str(tmp_path / "m")], "wolf0.off: file not found"),
                        (["retrieve", wolf0, "collection"], "collection: not a folder"),
                        (["bench", "dataset", "--method", "descriptor-nn", "-o", str(tmp_path / "b")],
                         "dataset: not a folder"),
                        (["bench-retrieval", str(tmp_path), str(tmp_path), "-o", "res"], "res: cannot write -o")):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert f"error: {named}" in err and reason in err, err
    assert main(["match", wolf0, wolf1, "--method", "descriptor-nn", "-o", str(tmp_path / "abs"), "-q"]) == 0


def test_a_retrieval_benchmark_s_output_folder_is_checked_before_any_work(tmp_path, capsys):
    """Found by fuzzing: `bench-retrieval -o` inside its queries folder was accepted, and the next run read the
    results as queries; a file, or a folder under a file, was named only by the OS's words."""
    queries, collection = tmp_path / "queries", tmp_path / "collection"
    queries.mkdir()
    collection.mkdir()
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    np.savetxt(queries / "wolf1.txt", np.column_stack([np.cos(angles), 2 * np.sin(angles)]))
    (collection / "wolf0.off").symlink_to(TOSCA / "wolf0.off")
    (tmp_path / "afile").write_text("x")
    for out, named in ((queries / "res", "is inside"), (queries, "is inside"),
                       (tmp_path / "afile", "afile: cannot write -o there"),
                       (tmp_path / "afile" / "sub", "cannot write -o there")):
        message = error_of(capsys, ["bench-retrieval", queries, collection, "-o", out])
        assert named in message, message
    assert sorted(p.name for p in queries.iterdir()) == ["wolf1.txt"]


def test_a_parameter_set_twice_is_refused(tmp_path, capsys):
    """Found by fuzzing: `--param k=10 --k 12` ran with 12 and `--param n=1 --param n=2` with 2, unseen."""
    query = tmp_path / "q.txt"
    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    np.savetxt(query, np.column_stack([np.cos(angles), 2 * np.sin(angles)]))
    message = error_of(capsys, ["match-contour", query, WOLF0, "--param", "k=10", "--k", "12", "-o", tmp_path / "m"])
    assert "--k 12 and --param k=10 both set k; give one" in message, message
    (tmp_path / "coll").mkdir()
    (tmp_path / "coll" / "wolf0.off").symlink_to(TOSCA / "wolf0.off")
    message = error_of(capsys, ["retrieve", query, tmp_path / "coll", "--param", "eps=0.1", "--param", "eps=0.2"])
    assert "--param eps is given twice ('0.1' and '0.2')" in message, message
    message = error_of(capsys, ["match", WOLF0, WOLF1, "--method", "kernel-matching", "--init", "fmap", "--param",
                                "init=descriptors", "-o", tmp_path / "k"])
    assert "--init fmap and --param init=descriptors both set init" in message, message
