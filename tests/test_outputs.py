"""What `corr` writes: never over its own inputs, never two outputs to one file, and each output set replaces
the earlier set under the same name as a whole (no stale picture, map or frame left looking current)."""

import csv
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from _data import SILHOUETTES
from corrlib.cli import main
from corrlib.errors import InputError, ParameterError
from corrlib.io import save_mesh

R = ["--jobs", "1", "--n-contour", "40", "--param", "mesh_vertices=0", "-q"]


def ellipsoid(path: Path, axes) -> Path:
    """A closed 150-vertex ellipsoid (Fibonacci points on the sphere, hull faces turned outwards)."""
    n = 150
    i = np.arange(n) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    sphere = np.column_stack([np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar), np.cos(polar)])
    faces = ConvexHull(sphere).simplices
    inward = np.einsum("ij,ij->i", np.cross(sphere[faces[:, 1]] - sphere[faces[:, 0]],
                                            sphere[faces[:, 2]] - sphere[faces[:, 0]]), sphere[faces].mean(1)) < 0
    faces[inward] = faces[inward][:, ::-1]
    return save_mesh(path, sphere * np.asarray(axes), faces)


@pytest.fixture
def shapes(tmp_path):
    """Two ellipsoids in a folder and an ellipse contour."""
    folder = tmp_path / "meshes"
    folder.mkdir()
    ellipsoid(folder / "egg0.off", (2, 1, 0.7))
    ellipsoid(folder / "cigar0.off", (3, 0.8, 0.8))
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    np.savetxt(tmp_path / "ellipse.txt", np.column_stack([2 * np.cos(t), np.sin(t)]))
    return tmp_path


def names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith("."))


def error(capsys, argv) -> str:
    assert main([str(a) for a in argv]) == 2
    return capsys.readouterr().err


def test_an_output_is_never_an_input_nor_another_output(shapes, capsys):
    """Each of these overwrote an input (the query silhouette with the match's picture, the query or a mesh of
    the collection with the ranking, the map with the error plot) or wrote one file twice, with exit 0."""
    t = shapes
    egg = t / "meshes" / "egg0.off"
    (t / "q.png").write_bytes((SILHOUETTES / "horse.png").read_bytes())
    before = (t / "q.png").read_bytes()
    assert "is the input file given as query" in error(capsys, ["match-contour", t / "q.png", egg, "-o", t / "q"])
    assert "given as source" in error(capsys, ["match", t / "q.png", egg, "--pictures", "-o", t / "q"])
    assert (t / "q.png").read_bytes() == before
    assert "given as the query" in error(capsys, ["retrieve", t / "ellipse.txt", t / "meshes", "-o",
                                                  t / "ellipse.txt", *R])
    assert "given as a mesh of the folder" in error(capsys, ["retrieve", t / "ellipse.txt", t / "meshes", "-o",
                                                             egg, *R])
    np.savetxt(t / "map.txt", np.arange(150), fmt="%d")
    np.savetxt(t / "id.vts", np.arange(1, 151), fmt="%d")
    evaluate = ["eval", t / "map.txt", "--gt-source", t / "id.vts", "--gt-target", t / "id.vts", "--target", egg]
    assert "given as the map" in error(capsys, [*evaluate, "--plot", t / "map.txt"])
    assert "--errors and --plot would both write this file" in error(capsys, [*evaluate, "--plot", t / "p.png",
                                                                              "--errors", t / "p.png"])
    np.savetxt(t / "short.vts", np.arange(1, 20), fmt="%d")
    message = error(capsys, [*evaluate[:3], t / "short.vts", *evaluate[4:]])
    assert "id.vts (--gt-target) has 150 rows, but" in message and "short.vts (--gt-source) has 19" in message
    frames = t / "frames"
    frames.mkdir()
    (frames / "frame_000.off").write_bytes(egg.read_bytes())
    assert "given as source" in error(capsys, ["morph", frames / "frame_000.off", egg, "-o", frames])
    assert names(t / "meshes") == ["cigar0.off", "egg0.off"] and (t / "map.txt").read_text().count("\n") == 150


def test_a_new_match_replaces_the_earlier_set_under_its_name(shapes, capsys):
    """A mesh pair's match with pictures, then a contour's match under the same name: the pair's picture and
    reverse map stayed beside the contour's result, looking like its."""
    t = shapes
    egg, cigar = t / "meshes" / "egg0.off", t / "meshes" / "cigar0.off"
    pair = ["--method", "fmap-zoomout", "--param", "k_init=20", "--param", "k_final=60"]
    assert main([str(a) for a in ["match", egg, cigar, *pair, "--pictures", "-o", t / "out" / "m", "-q"]]) == 0
    assert names(t / "out") == ["m.json", "m.map_xy.txt", "m.map_yx.txt", "m.npz", "m.png"]
    (t / "out" / "mine.png").write_text("the user's")
    assert main([str(a) for a in ["match", t / "ellipse.txt", cigar, "--param", "n_contour=40", "--param",
                                  "mesh_vertices=0", "-o", t / "out" / "m", "-q"]]) == 0
    assert names(t / "out") == ["m.json", "m.map_xy.txt", "m.npz", "mine.png"]
    capsys.readouterr()


def test_a_ranking_replaces_its_own_pictures_only(shapes, capsys):
    """A ranking under the stem "rank" deleted another ranking's pictures ("rank.2.tsv" wrote "rank.2.1-...")
    and any file named like "rank.2024-notes.png"; a ranking without --pictures left the earlier ranking's."""
    t = shapes
    query, meshes, out = t / "ellipse.txt", t / "meshes", t / "out"
    retrieve = ["retrieve", query, meshes, *R]
    assert main([str(a) for a in [*retrieve, "--pictures", "--top", "2", "-o", out / "rank.tsv"]]) == 0
    assert main([str(a) for a in [*retrieve, "--pictures", "--top", "1", "-o", out / "rank.2.tsv"]]) == 0
    (out / "rank.2024-notes.png").write_text("the user's")
    with open(out / "rank.tsv", encoding="utf-8", newline="") as fh:
        ranked = [Path(row[2]).stem for row in list(csv.reader(fh, delimiter="\t"))[1:]]
    assert names(out) == sorted(["rank.2024-notes.png", f"rank.1-{ranked[0]}.png", f"rank.2-{ranked[1]}.png",
                                 "rank.tsv", "rank.2.tsv", f"rank.2.1-{ranked[0]}.png"])
    (meshes / f"{ranked[0]}.off").unlink()  # the earlier rank 1 is gone from the collection
    assert main([str(a) for a in [*retrieve, "-o", out / "rank.tsv"]]) == 0
    assert names(out) == sorted(["rank.2024-notes.png", "rank.tsv", "rank.2.tsv", f"rank.2.1-{ranked[0]}.png"])
    capsys.readouterr()


def test_a_ranking_names_a_mesh_with_a_tab_in_its_name_as_one_field(shapes, capsys):
    t = shapes
    odd = t / "odd"
    odd.mkdir()
    (odd / "e\tg.off").write_bytes((t / "meshes" / "egg0.off").read_bytes())
    assert main([str(a) for a in ["retrieve", t / "ellipse.txt", odd, *R, "-o", t / "r.tsv"]]) == 0
    with open(t / "r.tsv", encoding="utf-8", newline="") as fh:
        rows = list(csv.reader(fh, delimiter="\t"))
    assert len(rows) == 2 and Path(rows[1][2]).name == "e\tg.off"
    capsys.readouterr()


def test_a_morph_replaces_its_result_files(shapes, capsys):
    t = shapes
    egg, cigar = t / "meshes" / "egg0.off", t / "meshes" / "cigar0.off"
    out = t / "morph"
    assert main([str(a) for a in ["morph", egg, cigar, "--frames", "3", "-o", out, "-q"]]) == 0
    assert "result.energy.png" in names(out) and "frame_002.obj" in names(out)
    assert main([str(a) for a in ["morph", egg, cigar, "--frames", "2", "--method", "fmap-zoomout", "--param",
                                  "k_init=20", "--param", "k_final=60", "-o", out, "-q"]]) == 0
    assert "result.energy.png" not in names(out) and "frame_002.obj" not in names(out)
    capsys.readouterr()


def test_the_api_names_a_bad_callback_and_a_huge_integer(shapes):
    from corrlib import load_mesh, solve
    from corrlib.io import load_contour

    mesh, contour = load_mesh(shapes / "meshes" / "egg0.off"), load_contour(shapes / "ellipse.txt")
    with pytest.raises(ParameterError, match="callback must be a function"):
        solve("contour3d", contour, mesh, callback=5, n_contour=40, mesh_vertices=0)
    with pytest.raises(ParameterError, match="n_contour = 99999999999999999999 is above its maximum 2000"):
        solve("contour3d", contour, mesh, n_contour="99999999999999999999")


def test_the_section_benchmark_keeps_only_the_pictures_of_its_rows(shapes, capsys):
    """A rerun of `corr bench-contour` into the same folder with other planes, or without pictures, left the
    earlier run's pictures beside a table that no longer held their rows."""
    t = shapes
    (t / "meshes" / "corres").mkdir()
    for name in ("egg0", "cigar0"):  # one connectivity: vertex i is vertex i
        np.savetxt(t / "meshes" / "corres" / f"{name}.vts", np.arange(1, 151), fmt="%d")
    (t / "meshes" / "pairs.txt").write_text("egg0 cigar0\n")
    bench = ["bench-contour", t / "meshes", "--n-contour", "40", "--param", "mesh_vertices=0", "--jobs", "1",
             "-o", t / "out", "-q"]
    assert main([str(a) for a in [*bench, "--planes", "main"]]) == 0
    first = names(t / "out" / "pictures")
    assert first and all("-main__" in name for name in first)
    (t / "out" / "pictures" / "notes.png").write_text("the user's")
    assert main([str(a) for a in [*bench, "--planes", "silhouette"]]) == 0
    second = names(t / "out" / "pictures")
    assert "notes.png" in second and not any("-main__" in name for name in second)
    assert any("-silhouette__" in name for name in second)
    assert main([str(a) for a in [*bench, "--planes", "silhouette", "--no-pictures"]]) == 0
    assert names(t / "out" / "pictures") == ["notes.png"]
    capsys.readouterr()


def test_an_output_name_is_checked_against_the_folder_s_limit_with_its_temporary_name(tmp_path):
    """A 250-byte file name passes the file system's 255 but not the temporary name it is written under first
    (a dot, the name, a dot, 8 random characters, ``.tmp``): that failed after the work; it is refused before."""
    from corrlib.outputs import atomic_write, check_output_file, longest_file_name

    longest = longest_file_name(tmp_path)
    fits = tmp_path / ("f" * longest)
    check_output_file(fits)
    with atomic_write(fits) as fh:
        fh.write("written")
    assert fits.read_text() == "written"
    with pytest.raises(InputError, match=f"at most {longest} bytes"):
        check_output_file(tmp_path / ("f" * (longest + 1)))


def test_an_output_folder_at_a_dangling_link_names_the_link(tmp_path):
    """``morph -o LINK`` where LINK points nowhere said only "(file exists)"."""
    from corrlib.outputs import ensure_output_folder

    (tmp_path / "link").symlink_to(tmp_path / "gone")
    with pytest.raises(InputError, match="is a symbolic link to .*gone, which does not exist"):
        ensure_output_folder(tmp_path / "link" / "frames")
