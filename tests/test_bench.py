"""The benchmark runner: protocol, resuming, failures, external maps, the Dask path."""

import json
import shutil

import numpy as np
import pytest

from _data import TOSCA
from corrlib.bench import Runner, load_dataset, methods_from_toml, parse_method
from corrlib.errors import FileFormatError, ParameterError

FAST = "descriptor-nn:n_eigs=30,n_scales=20"


@pytest.fixture
def cat_dataset(tmp_path):
    folder = tmp_path / "cats"
    (folder / "corres").mkdir(parents=True)
    for name in ("cat0", "cat1"):
        shutil.copy(TOSCA / f"{name}.off", folder)
        shutil.copy(TOSCA / f"{name}.vts", folder / "corres")
        shutil.copy(TOSCA / f"{name}.sym.vts", folder / "corres")
    (folder / "pairs.txt").write_text("cat0\tcat1\ncat1 cat0\n")
    return folder


@pytest.fixture
def wolf_dataset(tmp_path):
    folder = tmp_path / "wolves"
    folder.mkdir()
    for name in ("wolf0", "wolf1"):
        shutil.copy(TOSCA / f"{name}.off", folder)
    return folder


@pytest.mark.slow
def test_runner_reproduces_the_direct_evaluation(cat_dataset, tmp_path):
    from corrlib.evaluation import geodesic_errors
    from corrlib.io import load_map, load_mesh, load_vts

    ds = load_dataset(cat_dataset)
    assert ds.pairs == [("cat0", "cat1"), ("cat1", "cat0")] and not ds.identity
    out = tmp_path / "out"
    summary = Runner(ds, [parse_method(FAST + "@nn")], out).run(jobs=2)
    assert summary["nn"]["pairs"] == 2 and summary["nn"]["failed"] == 0
    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    map01 = load_map(out / "maps" / "nn" / "cat0__cat1.txt")
    direct = geodesic_errors(map01, cat1, load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat1.vts"),
                             gt_target_sym=load_vts(TOSCA / "cat1.sym.vts"))
    rows = (out / "errors.csv").read_text().splitlines()
    assert rows[0].startswith("method,source,target,status,mean")
    row = next(r.split(",") for r in rows[1:] if ",cat0,cat1," in r)
    assert float(row[4]) == pytest.approx(direct.summary()["mean"], rel=1e-5)
    map10 = load_map(out / "maps" / "nn" / "cat1__cat0.txt")
    other = geodesic_errors(map10, cat0, load_vts(TOSCA / "cat1.vts"), load_vts(TOSCA / "cat0.vts"))
    pooled = np.concatenate([direct.errors, other.errors])
    assert summary["nn"]["mean"] == pytest.approx(pooled.mean(), rel=1e-9)
    assert summary["nn"]["within_0.05"] == pytest.approx(np.mean(pooled <= 0.05))
    assert "mean_sym" in summary["nn"] and summary["nn"]["mean_sym"] <= summary["nn"]["mean"]
    assert (out / "curves.png").read_bytes()[:4] == b"\x89PNG"
    assert "| nn | 2 | 0 |" in (out / "summary.md").read_text()
    env = json.loads((out / "environment.json").read_text())
    assert env["methods"][0]["params"] == {"n_eigs": "30", "n_scales": "20"} and env["cores"] >= 1
    assert env["methods"][0]["all_params"]["n_eigs"] == 30 and "descriptor" in env["methods"][0]["all_params"]
    # external maps: the runner's own maps, evaluated like maps made elsewhere
    again = Runner(ds, [], tmp_path / "ext", external={"ours": str(out / "maps" / "nn")}).run(jobs=1)
    assert again["ours"]["mean"] == pytest.approx(summary["nn"]["mean"], rel=1e-12)


@pytest.mark.slow
def test_resume_after_an_interruption_gives_the_same_table(wolf_dataset, tmp_path):
    ds = load_dataset(wolf_dataset)
    assert ds.identity and len(ds.pairs) == 2
    methods = [parse_method(FAST)]
    full = Runner(ds, methods, tmp_path / "full").run(jobs=1)
    partial = Runner(ds, methods, tmp_path / "resumed")
    partial.run(jobs=1, limit=1)  # interrupted after one job
    assert len(partial.pending()) == 1
    resumed = Runner(ds, methods, tmp_path / "resumed")
    summary = resumed.run(jobs=1)
    assert not resumed.pending()
    for key in ("mean", "within_0.025", "within_0.05", "pairs"):
        assert summary[methods[0].label][key] == full[methods[0].label][key]


def test_a_broken_mesh_is_recorded_and_skipped(wolf_dataset, tmp_path):
    from corrlib.cli import main

    (wolf_dataset / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n")
    (wolf_dataset / "pairs.txt").write_text("wolf0 wolf1\nbroken wolf1\n")
    out = tmp_path / "out"
    code = main(["bench", str(wolf_dataset), "--method", FAST, "-o", str(out), "--jobs", "1", "-q"])
    assert code == 1  # some pair failed
    rows = (out / "errors.csv").read_text().splitlines()
    broken = next(r for r in rows if ",broken," in r)
    assert ",failed," in broken and "broken.off" in broken
    summary = json.loads((out / "summary.json").read_text())
    entry = next(iter(summary.values()))
    assert entry["pairs"] == 2 and entry["failed"] == 1 and entry["within_0.1"] > 0.5


def test_bad_datasets_and_methods(tmp_path, wolf_dataset):
    with pytest.raises(FileFormatError, match="no meshes"):
        load_dataset(tmp_path)
    (wolf_dataset / "pairs.txt").write_text("wolf0 wolf9\n")
    with pytest.raises(FileFormatError, match="unknown shape 'wolf9'"):
        load_dataset(wolf_dataset)
    with pytest.raises(ParameterError, match="unknown method"):
        parse_method("no-such-method")
    with pytest.raises(ParameterError, match="n_eigs"):
        parse_method("descriptor-nn:n_eigs=0")
    toml = tmp_path / "methods.toml"
    toml.write_text('[[method]]\nname = "descriptor-nn"\nlabel = "nn30"\n[method.params]\nn_eigs = 30\n')
    assert methods_from_toml(toml)[0].label == "nn30"


def test_ground_truth_is_checked_before_any_method_runs(tmp_path, cat_dataset, wolf_dataset):
    """Found by fuzzing: meshes of other faces were scored against the identity, a target's .sym.vts of other
    length or a .vts index beyond the mesh gave a raw IndexError (bench-contour) or failed only after the
    method had run; a dataset of .sym.vts files alone was scored against the identity."""
    from corrlib.contour_bench import contour_jobs

    def refused(folder, message):
        for run in (lambda: Runner(load_dataset(folder), [parse_method(FAST)], tmp_path / "out").run(jobs=1),
                    lambda: contour_jobs([folder], ["main"])):
            with pytest.raises(FileFormatError, match=message):
                run()
        assert not (tmp_path / "out").exists()  # nothing written

    lines = (wolf_dataset / "wolf1.off").read_text().splitlines()
    header = 1 if lines[0].strip() == "OFF" else 0
    n_v, n_f = map(int, lines[header].split()[:2])
    first_face = header + 1 + n_v
    a, b, c = lines[first_face].split()[1:4]
    lines[first_face] = f"3 {a} {c} {b}"  # one face reversed: other faces, same vertex count
    (wolf_dataset / "wolf1.off").write_text("\n".join(lines) + "\n")
    refused(wolf_dataset, "the identity, which needs one connectivity")
    corres = cat_dataset / "corres"
    rows = (corres / "cat1.sym.vts").read_text().split()
    (corres / "cat1.sym.vts").write_text("\n".join(rows[:100]) + "\n")
    refused(cat_dataset, "cat1.sym.vts: 100 rows against")
    shutil.copy(TOSCA / "cat1.sym.vts", corres)
    (corres / "cat1.vts").write_text("\n".join((TOSCA / "cat1.vts").read_text().split()[:-10]) + "\n")
    (corres / "cat1.sym.vts").unlink()
    refused(cat_dataset, "the rows of a pair's .vts files are corresponding points")
    (corres / "cat1.vts").write_text((TOSCA / "cat1.vts").read_text().replace("\n1\n", "\n99999\n", 1))
    refused(cat_dataset, "cat1.vts: index 99999 exceeds")
    for name in ("cat0", "cat1"):
        (corres / f"{name}.vts").unlink()
        shutil.copy(TOSCA / f"{name}.sym.vts", corres)
    refused(cat_dataset, "mirrored ground truth")


def test_a_rerun_with_other_settings_is_refused_and_failures_are_retried(wolf_dataset, tmp_path):
    """A rerun into the same folder resumed every pair that had a record, whatever the method's parameters or
    the geodesics were then: the old numbers were reported under the new settings. Failed pairs were never
    retried after their input was fixed."""
    from corrlib.cli import main

    wolf1 = (wolf_dataset / "wolf1.off").read_text()
    (wolf_dataset / "wolf1.off").write_text("OFF\n3 1 0\n0 0 0\n1 nan 0\n")
    out = tmp_path / "out"
    args = ["bench", str(wolf_dataset), "-o", str(out), "--jobs", "1", "-q"]
    assert main(args + ["--method", FAST + "@nn"]) == 1  # both pairs failed: wolf1 cannot be read
    (wolf_dataset / "wolf1.off").write_text(wolf1)
    runner = Runner(load_dataset(wolf_dataset), [parse_method(FAST + "@nn")], out)
    assert len(runner.pending()) == 2  # the failures are run again
    assert main(args + ["--method", FAST + "@nn"]) == 0
    assert json.loads((out / "summary.json").read_text())["nn"]["failed"] == 0
    other = Runner(load_dataset(wolf_dataset), [parse_method("descriptor-nn:n_eigs=20,n_scales=20@nn")], out)
    with pytest.raises(ParameterError, match=r"other settings \(n_eigs=30 → 20\)"):
        other.pending()
    assert main(args + ["--method", FAST + "@nn", "--geodesics", "graph"]) == 2
    assert not Runner(load_dataset(wolf_dataset), [parse_method(FAST + "@nn")], out).pending()


def test_a_damaged_record_is_run_again(wolf_dataset, tmp_path):
    """A record cut short or edited into something else (a crash of the machine, a hand) stopped the rerun with
    a JSONDecodeError or an AttributeError traceback; its pair is now run again and its record replaced."""
    from corrlib.cli import main

    out = tmp_path / "out"
    args = ["bench", str(wolf_dataset), "--method", FAST + "@nn", "-o", str(out), "--jobs", "1", "-q"]
    assert main(args) == 0
    records = sorted((out / "records" / "nn").glob("*.json"))
    records[0].write_text(records[0].read_text()[:50])
    records[1].write_text("[1, 2]")
    runner = Runner(load_dataset(wolf_dataset), [parse_method(FAST + "@nn")], out)
    assert len(runner.pending()) == 2 and runner.records() == []
    assert main(args) == 0
    assert json.loads((out / "summary.json").read_text())["nn"]["pairs"] == 2
    assert all(json.loads(r.read_text())["status"] == "ok" for r in records)


def test_files_that_are_not_utf8_text_are_named(tmp_path, wolf_dataset):
    """A pairs file or a methods file of other bytes gave a UnicodeDecodeError traceback."""
    (wolf_dataset / "pairs.txt").write_bytes(b"\x00\xff\xfe junk\n")
    with pytest.raises(FileFormatError, match="pairs.txt:1: unknown shape"):
        load_dataset(wolf_dataset)
    (tmp_path / "m.toml").write_bytes(b'\xff\xfe[[method]]\nname="descriptor-nn"\n')
    with pytest.raises(FileFormatError, match="m.toml: cannot read the methods file"):
        methods_from_toml(tmp_path / "m.toml")


def test_labels_sharing_a_folder_and_bad_methods_files_are_refused(tmp_path, wolf_dataset):
    ds = load_dataset(wolf_dataset)
    with pytest.raises(ParameterError, match="share the results folder 'x_y'"):
        Runner(ds, [parse_method(FAST + "@x y"), parse_method(FAST + "@x_y")], tmp_path / "out")
    with pytest.raises(ParameterError, match="names no folder"):
        Runner(ds, [parse_method(FAST + "@..")], tmp_path / "out")
    toml = tmp_path / "methods.toml"
    for text, message in [('[[method]]\nname = "descriptor-nn"\nparams = "n_eigs=5"\n', "params must be a table"),
                          ('[[method]]\nname = "descriptor-nn"\nlabel = 5\n', "label must be a string"),
                          ('[method]\nname = "descriptor-nn"\n', "array of tables"),
                          ('[[method]]\nname = [1, 2]\n', "name must be a string"),
                          ('[[method]]\nname = "descriptor-nn"\nparam = {n_eigs = 5}\n', "unknown keys param")]:
        toml.write_text(text)
        with pytest.raises(FileFormatError, match=message):
            methods_from_toml(toml)


def test_what_would_be_run_and_counted_twice_is_refused(tmp_path, wolf_dataset):
    from corrlib.contour_bench import contour_jobs

    (wolf_dataset / "pairs.txt").write_text("wolf0 wolf1\n\nwolf1 wolf0\nwolf0 wolf1\n")
    with pytest.raises(FileFormatError, match="pairs.txt:4: the pair wolf0 wolf1 again \\(first on line 1\\)"):
        load_dataset(wolf_dataset)
    (wolf_dataset / "pairs.txt").unlink()
    with pytest.raises(ParameterError, match="main given twice"):
        contour_jobs([wolf_dataset], ["main", "silhouette", "main"])
    with pytest.raises(ParameterError, match="given twice"):
        contour_jobs([wolf_dataset, tmp_path / "wolves" / ".." / "wolves"], ["main"])


@pytest.mark.slow
def test_dask_cluster_gives_the_local_results(wolf_dataset, tmp_path):
    import distributed  # the dist extra is part of the test setup (scripts/test.sh)

    ds = load_dataset(wolf_dataset)
    methods = [parse_method(FAST)]
    local = Runner(ds, methods, tmp_path / "local").run(jobs=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = Runner(ds, methods, tmp_path / "dask").run(scheduler=cluster.scheduler_address)
    accuracy = ("pairs", "failed", "mean", "within_0.025", "within_0.05", "within_0.1")
    label = methods[0].label
    assert {k: remote[label][k] for k in accuracy} == {k: local[label][k] for k in accuracy}
    from corrlib.io import load_map

    for pair in ("wolf0__wolf1", "wolf1__wolf0"):
        assert np.array_equal(load_map(tmp_path / "dask" / "maps" / label / f"{pair}.txt"),
                              load_map(tmp_path / "local" / "maps" / label / f"{pair}.txt"))


@pytest.mark.slow
def test_retrieval_benchmark_local_and_on_dask(tmp_path):
    import distributed

    from corrlib.cli import main
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_mesh, save_contour
    from corrlib.retrieval import average_precision, class_of

    queries, collection = tmp_path / "queries", tmp_path / "collection"
    queries.mkdir()
    collection.mkdir()
    for name in ("cat1", "wolf1"):
        shutil.copy(TOSCA / f"{name}.off", collection)
    for name, cls in (("cat0", "cat"), ("wolf0", "wolf")):
        save_contour(queries / f"{cls}-1.txt", render_silhouette(load_mesh(TOSCA / f"{name}.off"), [0, 0, 1]))
    (queries / "broken-1.txt").write_text("0 0\n1 1\n")  # too few points: recorded, not fatal
    out = tmp_path / "out"
    code = main(["bench-retrieval", str(queries), str(collection), "-o", str(out), "--jobs", "2", "-q",
                 "--n-contour", "60"])
    assert code == 1  # one query failed
    summary = json.loads((out / "retrieval_summary.json").read_text())
    assert summary["queries"] == 3 and summary["failed"] == 1 and summary["collection"] == 2
    lines = (out / "retrieval.csv").read_text().splitlines()
    rows = [dict(zip(lines[0].split(","), r.split(","))) for r in lines[1:]]
    aps = {r["query"]: float(r["ap"]) for r in rows if r["ap"] != "nan"}
    for r in rows:
        if r["query"] in aps:
            ranked = [class_of(n) for n in r["top"].split()]
            assert aps[r["query"]] == pytest.approx(average_precision(ranked, r["class"]))
            # the query's class first exactly where the margin is positive
            assert (ranked[0] == r["class"]) == (float(r["margin"]) > 0)
    assert summary["map"] == pytest.approx(np.mean(list(aps.values())))
    low, high = summary["map_interval"]
    assert min(aps.values()) <= low <= summary["map"] <= high <= max(aps.values())
    assert summary["right_class_first"] == sum(float(r["margin"]) > 0 for r in rows if r["query"] in aps)
    assert set(summary["per_class"]) == {"cat", "wolf"}
    # the whole ranking of every answered query, in increasing score, gives the same AP
    ranking = [r.split(",") for r in (out / "retrieval_ranking.csv").read_text().splitlines()[1:]]
    assert {r[0] for r in ranking} == set(aps)
    for query, ap in aps.items():
        mine = [r for r in ranking if r[0] == query]
        assert [int(r[1]) for r in mine] == [1, 2] and {r[2] for r in mine} == {"cat1.off", "wolf1.off"}
        scores = [float(r[4]) for r in mine]
        assert scores == sorted(scores) and all(np.isfinite(scores))
        assert average_precision([r[3] for r in mine], class_of(query)) == pytest.approx(ap)
    from dataclasses import replace

    from corrlib.bench import retrieval_benchmark
    from corrlib.methods.contour3d import Contour3DParams

    params = replace(Contour3DParams(), eps=0.05, n_contour=60)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = retrieval_benchmark(queries, collection, tmp_path / "dask", params=params,
                                     scheduler=cluster.scheduler_address)
    assert remote["map"] == pytest.approx(summary["map"])
    assert remote["per_class"] == pytest.approx(summary["per_class"])


def test_retrieval_benchmark_names_broken_meshes_and_absent_classes(tmp_path, capsys):
    """A mesh of the collection that cannot be matched is named (and the exit status says so), a query whose
    class has no mesh has no AP (not 0), and a collection nothing of which can be matched gives no MAP (valid
    JSON, not NaN)."""
    from corrlib.cli import main
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_mesh, save_contour

    queries, collection, broken = tmp_path / "queries", tmp_path / "collection", tmp_path / "broken"
    for folder in (queries, collection, broken):
        folder.mkdir()
    shutil.copy(TOSCA / "cat1.off", collection)
    for folder in (collection, broken):
        (folder / "junk1.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n")  # truncated
    silhouette = render_silhouette(load_mesh(TOSCA / "cat0.off"), [0, 0, 1])
    save_contour(queries / "cat-1.txt", silhouette)
    save_contour(queries / "lion-1.txt", silhouette)

    def strict(path):  # NaN is not JSON
        return json.loads(path.read_text(), parse_constant=lambda name: pytest.fail(f"{name} in {path}"))

    assert main(["bench-retrieval", str(queries), str(collection), "-o", str(tmp_path / "a"), "--jobs", "1", "-q",
                 "--n-contour", "60"]) == 1
    summary = strict(tmp_path / "a" / "retrieval_summary.json")
    assert summary["failed_meshes"] == ["junk1.off"] and summary["failed"] == 1 and summary["map"] == 1.0
    rows = (tmp_path / "a" / "retrieval.csv").read_text()
    assert "no mesh of class 'lion' in the collection" in rows
    assert "junk1.off" in (tmp_path / "a" / "retrieval_summary.md").read_text()
    assert main(["bench-retrieval", str(queries), str(broken), "-o", str(tmp_path / "b"), "--jobs", "1", "-q",
                 "--n-contour", "60"]) == 1
    summary = strict(tmp_path / "b" / "retrieval_summary.json")
    assert summary["map"] is None and summary["failed"] == 2
    assert "no mesh of the collection could be matched" in (tmp_path / "b" / "retrieval.csv").read_text()


def test_retrieval_benchmark_scores_rendered_queries_without_their_own_mesh(tmp_path, capsys):
    """``--own-meshes``: a query rendered from a mesh of the collection is also scored with that mesh left out
    of its ranking (the AP of the rest of the ranking, recomputed here from ``retrieval_ranking.csv``); a query
    whose class has no other mesh is named, not scored 0; the queries not listed get a MAP of their own. A bad
    list stops the command with a message naming the file and line before any query is matched."""
    from corrlib.cli import main
    from corrlib.geometry.sections import render_silhouette
    from corrlib.io import load_mesh, save_contour
    from corrlib.retrieval import ap_without, average_precision

    queries, collection = tmp_path / "queries", tmp_path / "collection"
    for folder in (queries, collection):
        folder.mkdir()
    for name in ("cat0", "cat1", "wolf0"):
        shutil.copy(TOSCA / f"{name}.off", collection)
    side = {name: render_silhouette(load_mesh(TOSCA / f"{name}.off"), [0, 0, 1]) for name in ("cat0", "wolf0")}
    save_contour(queries / "cat-1.txt", side["cat0"])
    save_contour(queries / "wolf-1.txt", side["wolf0"])
    save_contour(queries / "cat-2.txt", side["cat0"])  # not listed
    listing = tmp_path / "own.txt"
    listing.write_text("# query mesh\ncat-1.txt cat0.off  rendered from the side\n\nwolf-1.txt wolf0.off\n")
    out = tmp_path / "out"
    assert main(["bench-retrieval", str(queries), str(collection), "-o", str(out), "--jobs", "1", "-q",
                 "--n-contour", "60", "--own-meshes", str(listing)]) == 0
    summary = json.loads((out / "retrieval_summary.json").read_text())
    lines = (out / "retrieval.csv").read_text().splitlines()
    rows = {r["query"]: r for r in (dict(zip(lines[0].split(","), line.split(","))) for line in lines[1:])}
    ranking = [line.split(",") for line in (out / "retrieval_ranking.csv").read_text().splitlines()[1:]]
    cat_ranking = [(r[2], r[3]) for r in ranking if r[0] == "cat-1.txt"]
    expected = average_precision([label for mesh, label in cat_ranking if mesh != "cat0.off"], "cat")
    assert float(rows["cat-1.txt"]["ap_own_left_out"]) == pytest.approx(expected)
    assert ap_without(*zip(*cat_ranking), "cat0.off", "cat") == pytest.approx(expected)
    assert rows["wolf-1.txt"]["ap_own_left_out"] == "nan" and rows["cat-2.txt"]["ap_own_left_out"] == "nan"
    own = summary["own_meshes"]
    assert own["left_out"] == 1 and own["map_left_out"] == pytest.approx(expected)
    assert own["no_other_member"] == ["wolf-1.txt"]
    assert own["not_listed"] == 1 and own["map_not_listed"] == pytest.approx(float(rows["cat-2.txt"]["ap"]))
    text = (out / "retrieval_summary.md").read_text()
    assert "own mesh left out" in text and "wolf-1.txt" in text
    # the Princeton measures of every query's ranking, and their means in the summary
    from corrlib.retrieval import RANKING_MEASURES, ranking_measures

    for query, row in rows.items():
        expected = ranking_measures([r[3] for r in ranking if r[0] == query], row["class"])
        assert {m: float(row[m]) for m in RANKING_MEASURES} == pytest.approx(expected)
    for measure in RANKING_MEASURES:
        assert summary[measure] == pytest.approx(np.mean([float(r[measure]) for r in rows.values()]))
    assert "first tier" in text
    # the mean interpolated precision–recall curve, as a table and a picture
    from corrlib.retrieval import RECALL_LEVELS, interpolated_precision

    curve = np.loadtxt(out / "retrieval_pr.csv", delimiter=",", skiprows=1)
    expected = np.mean([interpolated_precision([r[3] for r in ranking if r[0] == query], row["class"])
                        for query, row in rows.items()], axis=0)
    assert np.allclose(curve[:, 0], RECALL_LEVELS) and np.allclose(curve[:, 1], expected, atol=1e-6)
    assert summary["precision_at_recall"] == pytest.approx(list(expected))
    assert (out / "retrieval_pr.png").stat().st_size > 1000
    capsys.readouterr()
    for content, message in (("cat-1.txt\n", "own.txt, line 1: expected 'QUERY MESH'"),
                             ("cat-9.txt cat0.off\n", "own.txt, line 1: no query 'cat-9.txt'"),
                             ("\ncat-1.txt lion0.off\n", "own.txt, line 2: no mesh 'lion0.off'"),
                             ("cat-1.txt cat0.off\ncat-1.txt cat1.off\n", "line 2: query 'cat-1.txt' is listed"),
                             ("# nothing\n\n", "own.txt: lists no query")):
        listing.write_text(content)
        assert main(["bench-retrieval", str(queries), str(collection), "-o", str(tmp_path / "bad"), "-q",
                     "--own-meshes", str(listing)]) == 2
        assert message in capsys.readouterr().err
        assert not (tmp_path / "bad" / "retrieval.csv").exists()


@pytest.mark.parametrize("pairs_text,expected", [
    ("cat0 cat1 cat2\n", "line 1: expected 'source target'"),
    ("\ncat0 lion\n", "line 2: .*lion.off does not exist"),
    ("\n\n", "no pairs"),
])
def test_the_pyfm_reference_script_names_bad_input_before_it_needs_pyfm(tmp_path, cat_dataset, pairs_text,
                                                                        expected):
    """``scripts/pyfm_maps.py`` (pyFM's maps for ``corr bench --maps``) checks its dataset and pairs file
    before it imports pyFM, and ends with argparse's exit 2 and a message naming the file and line; nothing is
    written."""
    import re
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "scripts" / "pyfm_maps.py"
    pairs = tmp_path / "pairs.txt"
    pairs.write_text(pairs_text)
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, str(script), str(cat_dataset), str(pairs), str(out)],
                          capture_output=True, text=True)
    assert done.returncode == 2 and re.search(expected, done.stderr), done.stderr
    assert not out.exists()
    missing = subprocess.run([sys.executable, str(script), str(tmp_path / "nowhere"), str(pairs), str(out)],
                             capture_output=True, text=True)
    assert missing.returncode == 2 and "not a folder of meshes" in missing.stderr


def test_the_pyfm_reference_script_names_a_failed_pair_and_keeps_the_maps_it_wrote(tmp_path, cat_dataset):
    """A stand-in for pyFM (first pair fine, second failing inside the fit): the failure ends with exit 2
    naming the pair, the first map is whole, nothing half-written stays; a rerun skips the written map."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    fake = tmp_path / "fake" / "pyFM"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    (fake / "mesh.py").write_text("class TriMesh:\n    def __init__(self, path):\n        self.path = path\n")
    (fake / "functional.py").write_text(
        "import numpy as np\n"
        "class FunctionalMapping:\n"
        "    def __init__(self, target, source):\n"
        "        self.source = source.path\n"
        "    def preprocess(self, **kw):\n"
        "        pass\n"
        "    def fit(self, **kw):\n"
        "        if self.source.endswith('cat1.off'):\n"
        "            raise RuntimeError('the fit diverged')\n"
        "    def zoomout_refine(self, **kw):\n"
        "        pass\n"
        "    def get_p2p(self):\n"
        "        return np.arange(3)\n")
    script = Path(__file__).resolve().parents[1] / "scripts" / "pyfm_maps.py"
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(fake.parent)}
    command = [sys.executable, str(script), str(cat_dataset), str(cat_dataset / "pairs.txt"), str(out)]
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    assert done.returncode == 2 and "cat1 -> cat0: pyFM failed (RuntimeError: the fit diverged)" in done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["cat0__cat1.txt"]
    assert (out / "cat0__cat1.txt").read_text().split() == ["0", "1", "2"]
    again = subprocess.run(command, capture_output=True, text=True, env=env)
    assert again.returncode == 2 and "cat0 -> cat1" not in again.stdout  # the written map is skipped
