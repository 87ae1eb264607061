"""The `corr` command: every subcommand runs, bad input exits with status 2 and a message."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from _data import SILHOUETTES, TOSCA
from corrlib.cli import main
from corrlib.evaluation import geodesic_errors
from corrlib.io import load_mesh


def test_info_mesh_and_contour(capsys):
    assert main(["info", str(TOSCA / "cat0.off")]) == 0
    out = capsys.readouterr().out
    assert "5000" in out and "no problems found" in out
    assert main(["info", "--json", str(SILHOUETTES / "mpeg7" / "dog-1.gif")]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["kind"] == "contour" and info["points"] > 100


def test_info_reports_invalid_mesh(tmp_path, capsys):
    p = tmp_path / "nm.off"
    p.write_text("OFF\n5 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 -1\n3 0 1 2\n3 1 2 3\n3 1 2 4\n3 0 2 3\n")
    assert main(["info", str(p)]) == 2
    out = capsys.readouterr().out
    assert "non-manifold-edge" in out


def test_bad_input_exit_status(tmp_path, capsys):
    assert main(["info", str(tmp_path / "missing.off")]) == 2
    assert "file not found" in capsys.readouterr().err
    (tmp_path / "junk.off").write_text("garbage")
    assert main(["info", str(tmp_path / "junk.off")]) == 2
    assert "junk.off" in capsys.readouterr().err
    assert main(["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "nope"]) == 2
    assert "unknown method" in capsys.readouterr().err
    assert main(["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "fmap-zoomout",
                 "--param", "k_init=-3",
                 "-o", str(tmp_path / "r")]) == 2
    assert "below its minimum" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["eval"])
    assert exc.value.code == 2


def test_eval_identity_and_plot(tmp_path, capsys):
    n = 4344
    np.savetxt(tmp_path / "id.txt", np.arange(n), fmt="%d")
    plot = tmp_path / "curve.png"
    assert main(["eval", str(tmp_path / "id.txt"), "--gt-source", str(TOSCA / "wolf0.vts"), "--gt-target",
                 str(TOSCA / "wolf1.vts"), "--target", str(TOSCA / "wolf1.off"), "--plot", str(plot),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.split("wrote")[0])
    assert summary["mean"] == 0 and summary["rows"] > 0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_match_writes_outputs(tmp_path, capsys):
    out = tmp_path / "res"
    assert main(["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "descriptor-nn",
                 "-o", str(out), "-q"]) == 0
    mp = np.loadtxt(tmp_path / "res.map_xy.txt", dtype=int)
    assert mp.shape == (4344,) and (tmp_path / "res.json").exists() and (tmp_path / "res.map_yx.txt").exists()
    assert not list(tmp_path.glob("*.png"))  # pictures only when asked
    assert main(["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "descriptor-nn",
                 "--pictures", "-o", str(tmp_path / "pic"), "-q"]) == 0
    assert (tmp_path / "pic.png").stat().st_size > 10_000
    assert np.array_equal(np.loadtxt(tmp_path / "pic.map_xy.txt", dtype=int), mp)


def test_a_saved_map_is_refused_on_other_meshes_of_its_size(tmp_path, capsys):
    """A result's map read on meshes it was not computed for (the wolves share their vertex count and faces, so
    every size check passed): eval, morph --map and match --init name the file and the mesh it was computed for,
    exit with status 2 and write nothing; the same meshes, or the map alone without its record, are taken."""
    wolf0, wolf1 = str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off")
    assert main(["match", wolf0, wolf1, "--method", "descriptor-nn", "-o", str(tmp_path / "r"), "-q"]) == 0
    truth = ["--gt-source", str(TOSCA / "wolf0.vts"), "--gt-target", str(TOSCA / "wolf0.vts")]
    for argv in (["eval", str(tmp_path / "r.npz"), "--target", wolf0, "--plot", str(tmp_path / "e.png"), *truth],
                 ["morph", wolf1, wolf0, "--map", str(tmp_path / "r.map_xy.txt"), "-o", str(tmp_path / "m")],
                 ["match", wolf1, wolf0, "--method", "product-manifold", "--init", str(tmp_path / "r.npz"),
                  "-o", str(tmp_path / "p"), "-q"]):
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "the map was computed for the " in err and "'wolf1.off'" in err and "'wolf0.off'" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json", "r.map_xy.txt", "r.map_yx.txt", "r.npz"]
    assert main(["eval", str(tmp_path / "r.npz"), "--target", wolf1, *truth[:2], "--gt-target",
                 str(TOSCA / "wolf1.vts")]) == 0
    (tmp_path / "r.json").unlink()  # without the record only the sizes are checked
    assert main(["eval", str(tmp_path / "r.npz"), "--target", wolf0, *truth]) == 0


def test_methods_listing(capsys):
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    assert "fmap-zoomout" in out and "descriptor-nn" in out and "--param k_init=35" in out


@pytest.mark.slow
def test_demo_console_script(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "corrlib.cli", "demo", "-o", str(tmp_path), "-q"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "demo.png").stat().st_size > 10_000
    assert (tmp_path / "demo.npz").exists()
    assert "mean" in proc.stdout


@pytest.mark.slow
def test_perf_quick_runs(capsys):
    assert main(["perf", "foundation", "--quick", "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    assert "200 eigenpairs, method=slicing" in out and "SHOT" in out and "geodesic error" in out
    # every suite first times the machine, so that figures of different days can be read against each other
    reference = next(line for line in out.splitlines() if line.startswith("machine: reference workload"))
    assert float(reference.split()[-2]) > 0
    assert main(["perf", "morph", "--quick", "--repeat", "1"]) == 0
    out = capsys.readouterr().out
    assert "as-rigid-as-possible interpolation wolf0 -> wolf1, 4344 vertices: preparation" in out


@pytest.mark.slow
def test_match_contour_and_retrieve(tmp_path, capsys):
    from _data import SKETCH2D

    out = tmp_path / "mc"
    assert main(["match-contour", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(TOSCA / "wolf1.off"),
                 "--n-contour", "60", "--eps", "0.05", "-o", str(out), "-q"]) == 0
    text = capsys.readouterr().out
    assert "energy" in text and "branch-and-bound" in text
    assert (tmp_path / "mc.png").stat().st_size > 10_000
    arrays = np.load(tmp_path / "mc.npz")
    assert arrays["map_xy"].shape == (60,) and arrays["path_vertices"][0] == arrays["path_vertices"][-1]
    # a planar sketch mesh with per-vertex part labels works as a query
    assert main(["match-contour", str(SKETCH2D / "human_sketch_a.off"), str(TOSCA / "wolf0.off"), "--query-labels",
                 str(SKETCH2D / "human_sketch_a_segmentation.txt"), "--n-contour", "40", "--eps", "0.1",
                 "-o", str(tmp_path / "sk"), "-q"]) == 0
    capsys.readouterr()
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in ("wolf0.off", "wolf1.off", "cat0.off"):
        (folder / name).write_bytes((TOSCA / name).read_bytes())
    assert main(["retrieve", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(folder), "--jobs", "1",
                 "--n-contour", "50", "-o", str(tmp_path / "rank.tsv"), "-q", "--pictures", "--top", "2"]) == 0
    lines = (tmp_path / "rank.tsv").read_text().strip().split("\n")
    assert len(lines) == 4 and lines[0].startswith("rank")
    ranked = [Path(line.split("\t")[2]).stem for line in lines[1:]]
    pictures = sorted(p.name for p in tmp_path.glob("rank.*.png"))
    assert pictures == [f"rank.1-{ranked[0]}.png", f"rank.2-{ranked[1]}.png"]  # the query's curve on the top two
    assert all((tmp_path / name).stat().st_size > 10_000 for name in pictures)
    # a new ranking under the same name replaces the earlier one's pictures as a whole
    assert main(["retrieve", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(folder), "--jobs", "1",
                 "--n-contour", "50", "-o", str(tmp_path / "rank.tsv"), "-q", "--pictures", "--top", "1"]) == 0
    assert sorted(p.name for p in tmp_path.glob("rank.*.png")) == [f"rank.1-{ranked[0]}.png"]


def test_retrieve_from_a_collection_with_a_folder_per_class(tmp_path, capsys):
    """Meshes of one file name in two class folders: each ranked under its name in the collection, each with a
    picture of its own, and the query's class found among the folders."""
    collection = tmp_path / "collection"
    for name, source in (("wolf/0.off", "wolf0.off"), ("wolf/1.off", "wolf1.off"), ("cat/0.off", "cat0.off")):
        (collection / name).parent.mkdir(parents=True, exist_ok=True)
        (collection / name).write_bytes((TOSCA / source).read_bytes())
    query = tmp_path / "wolf-7.gif"
    query.write_bytes((SILHOUETTES / "mpeg7" / "dog-1.gif").read_bytes())
    assert main(["retrieve", str(query), str(collection), "--jobs", "1", "--n-contour", "50",
                 "-o", str(tmp_path / "rank.tsv"), "-q", "--pictures", "--top", "3"]) == 0
    text = capsys.readouterr().out
    assert "average precision for class 'wolf'" in text and "cat/0.off" in text
    rows = [line.split("\t") for line in (tmp_path / "rank.tsv").read_text().strip().split("\n")]
    assert rows[0] == ["rank", "energy", "mesh", "error", "name", "score", "view_distance", "curve_length_ratio"]
    names = [row[4] for row in rows[1:]]
    assert sorted(names) == ["cat/0.off", "wolf/0.off", "wolf/1.off"]
    pictures = sorted(p.name for p in tmp_path.glob("rank.*.png"))
    assert pictures == sorted(f"rank.{rank}-{name[:-4].replace('/', '-')}.png" for rank, name in enumerate(names, 1))
    # a second ranking under the same name replaces these pictures, found through the names column
    assert main(["retrieve", str(query), str(collection), "--jobs", "1", "--n-contour", "50",
                 "-o", str(tmp_path / "rank.tsv"), "-q", "--pictures", "--top", "1"]) == 0
    assert len(list(tmp_path.glob("rank.*.png"))) == 1


def test_match_contour_bad_input(tmp_path, capsys):
    t = np.linspace(0, 1.2 * np.pi, 30)
    np.savetxt(tmp_path / "open.txt", np.column_stack([np.cos(t), np.sin(t)]))
    assert main(["match-contour", str(tmp_path / "open.txt"), str(TOSCA / "wolf0.off")]) == 2
    assert "open contour" in capsys.readouterr().err
    assert main(["retrieve", str(SILHOUETTES / "horse.png"), str(tmp_path)]) == 2
    assert "no mesh files" in capsys.readouterr().err
    assert main(["retrieve", str(SILHOUETTES / "horse.png"), str(TOSCA), "--pictures"]) == 2
    assert "give the ranking's file with -o" in capsys.readouterr().err


def test_match_picks_the_method_of_the_inputs_and_names_a_wrong_pair(tmp_path, capsys):
    """Without --method, a contour and a mesh are matched by 2D-to-3D matching; a mesh and a contour (the wrong
    order), or a map file given to a method whose inputs do not fit, get a message, not a traceback."""
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    circle = tmp_path / "circle.txt"
    np.savetxt(circle, np.column_stack([np.cos(t), 0.6 * np.sin(t)]))
    mesh = str(TOSCA / "wolf0.off")
    np.savetxt(tmp_path / "map.txt", np.arange(60), fmt="%d")
    assert main(["match", str(circle), mesh, "--param", "n_contour=40", "-o", str(tmp_path / "c"), "-q"]) == 0
    assert "method contour3d" in capsys.readouterr().out
    assert not (tmp_path / "c.png").exists()  # pictures only when asked; asked, the query and its curve on the mesh
    assert main(["match", str(circle), mesh, "--param", "n_contour=40", "--pictures", "-o", str(tmp_path / "p"),
                 "-q"]) == 0
    picture = (tmp_path / "p.png").read_bytes()
    assert picture[:8] == b"\x89PNG\r\n\x1a\n" and len(picture) > 10_000
    capsys.readouterr()
    assert main(["match", mesh, str(circle), "-o", str(tmp_path / "m"), "-q"]) == 2
    assert "swap the two inputs" in capsys.readouterr().err
    for command in (["match", "--method", "kernel-matching"], ["refine"]):
        assert main([*command, str(circle), mesh, "--init", str(tmp_path / "map.txt"), "-o", str(tmp_path / "r"),
                     "-q"]) == 2
        err = capsys.readouterr().err
        assert "takes mesh + mesh, got contour + mesh" in err and "Traceback" not in err
    assert not list(tmp_path.glob("m.*")) and not list(tmp_path.glob("r.*"))


@pytest.mark.slow
def test_match_kernel_with_init_file(tmp_path, capsys):
    n = 4344
    noisy = np.arange(n)
    noisy[::3] = np.random.default_rng(0).integers(0, n, noisy[::3].size)
    np.savetxt(tmp_path / "init.txt", noisy, fmt="%d")
    out = tmp_path / "km"
    args = ["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "kernel-matching",
            "--init", str(tmp_path / "init.txt"), "--param", "n_eigs=100", "--param", "n_seeds=600",
            "--times", "0.01,0.003,0.001", "--pictures", "-o", str(out), "-q"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "energy trace" in text
    refined = np.loadtxt(tmp_path / "km.map_xy.txt", dtype=int)
    wolf1, ident = load_mesh(TOSCA / "wolf1.off"), np.arange(n)
    before = geodesic_errors(noisy, wolf1, ident, ident).summary()["within_0.025"]
    after = geodesic_errors(refined, wolf1, ident, ident).summary()["within_0.025"]
    assert after > before + 0.08, (before, after)  # measured 0.67 -> 0.80
    assert (tmp_path / "km.energy.png").exists() and (tmp_path / "km.png").exists()
    np.savetxt(tmp_path / "lm.txt", np.array([[5, 5], [900, 900], [2000, 2000], [3000, 3000]]), fmt="%d")
    assert main(args[:5] + ["--init", str(tmp_path / "lm.txt"), "--param", "n_eigs=100", "--param", "n_seeds=600",
                            "-o", str(tmp_path / "lm"), "-q"]) == 0
    assert main(["match", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--method", "descriptor-nn",
                 "--init", str(tmp_path / "init.txt")]) == 2
    assert "does not take an initial map" in capsys.readouterr().err
    assert main(args[:5] + ["--init", str(tmp_path / "nothing.txt")]) == 2



def test_named_initialisations_come_from_the_method(tmp_path, capsys):
    """--init names are the method's own ``init`` choices; anything else must be a file, and the error lists
    the names (nothing is written)."""
    pair = [str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off")]
    out = tmp_path / "r"
    assert main(["match", *pair, "--method", "kernel-matching", "--init", "bestest", "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert "neither a named initialisation of kernel-matching" in err and "'best'" in err and "'fmap'" in err
    assert main(["match", *pair, "--method", "divergence-free", "--init", "best", "-o", str(out), "-q"]) == 2
    assert "'kernel-matching'" in capsys.readouterr().err  # divergence-free names its own choices
    assert main(["refine", *pair, "--method", "kernel-matching", "--init", "best", "-o", str(out), "-q"]) == 2
    assert "not an existing file" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())

def test_match_contours(tmp_path, capsys):
    out = tmp_path / "cc"
    assert main(["match-contours", str(SILHOUETTES / "mpeg7" / "dog-1.gif"), str(SILHOUETTES / "horse.png"),
                 "--param", "n_source=50", "--param", "n_target=40", "-o", str(out), "-q"]) == 0
    assert np.loadtxt(tmp_path / "cc.map_xy.txt", dtype=int).shape == (50,)
    assert (tmp_path / "cc.png").stat().st_size > 20_000
    assert main(["match-contours", str(SILHOUETTES / "horse.png"), str(TOSCA / "wolf0.off")]) == 2
    assert "takes contour + contour" in capsys.readouterr().err


def test_a_query_mesh_that_is_not_flat_is_refused_by_name(tmp_path, capsys):
    """A 2D query may be a flat triangulated sketch; a 3D mesh given as the query is named, not cut to its x and y
    coordinates (its longest boundary loop was taken as drawn in the xy plane, whatever its shape)."""
    from _data import SKETCH2D

    half = tmp_path / "half_wolf.off"  # an open 3D mesh: it has a boundary loop, but no plane
    from corrlib.io import load_mesh, save_mesh

    wolf = load_mesh(TOSCA / "wolf0.off")
    keep = wolf.faces[wolf.vertices[wolf.faces].mean(1)[:, 2] > np.median(wolf.vertices[:, 2])]
    used = np.unique(keep)
    save_mesh(half, wolf.vertices[used], np.searchsorted(used, keep))
    for query in (half, TOSCA / "wolf1.off"):
        assert main(["match-contour", str(query), str(TOSCA / "wolf0.off"), "-o", str(tmp_path / "r"), "-q"]) == 2
        assert f"{query.name}: not a planar sketch: its vertices do not lie in a plane" in capsys.readouterr().err
    assert not list(tmp_path.glob("r*"))
    turned = tmp_path / "turned_sketch.off"  # the sketch in another plane is still the sketch
    sketch = load_mesh(SKETCH2D / "human_sketch_a.off")
    save_mesh(turned, sketch.vertices[:, [0, 2, 1]], sketch.faces)
    from corrlib.cli_contour import query_contour

    assert np.allclose(query_contour(str(turned)).segment_lengths, query_contour(str(SKETCH2D / "human_sketch_a.off"))
                       .segment_lengths)


def test_retrieval_defaults_are_shared(capsys):
    """`corr retrieve`, `corr bench-retrieval`, the library and the studio rank with the same parameters."""
    import argparse

    from corrlib.cli_contour import N_CONTOUR_HELP, contour3d_params
    from corrlib.errors import ParameterError
    from corrlib.retrieval import retrieval_params

    args = argparse.Namespace(param=None, eps=0.0, k=None, n_contour=None)
    assert contour3d_params(args, retrieval=True) == retrieval_params()
    single = contour3d_params(args)  # a ranking matches as one match does, with the view read from the outline
    assert retrieval_params().n_contour == single.n_contour and f"default {single.n_contour}," in N_CONTOUR_HELP
    assert retrieval_params().view == "outline" != single.view
    args.n_contour, args.param = 70, ["axis_weight=0.5"]
    assert contour3d_params(args, retrieval=True) == retrieval_params(n_contour=70, axis_weight=0.5)
    with pytest.raises(ParameterError, match="n_contour"):
        retrieval_params(n_contour=3)
    for command in ("retrieve", "bench-retrieval", "match-contour"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert f"default {single.n_contour}," in capsys.readouterr().out
