"""Drawn outlines scored by landmarks (corrlib.landmark_bench, ``corr bench-contour --drawn``)."""

import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import grid_mesh
from corrlib.cli import main
from corrlib.contour_bench import contour_benchmark
from corrlib.errors import ContourError, FileFormatError, InputError, ParameterError
from corrlib.geometry.geodesics import GeodesicSolver
from corrlib.io import load_contour, load_mesh
from corrlib.landmark_bench import drawn_queries, landmark_errors, read_landmarks, redrawn
from corrlib.resources import resource
from corrlib.shapes import Contour2D, TriMesh

DRAWN = resource("data/silhouettes/drawn")


def test_landmark_files_are_read_and_their_errors_named(tmp_path):
    path = tmp_path / "a.landmarks"
    path.write_text("# a comment\nnose 1.5 -2\n\npaw 0 0  # the near one\npaw 1e-3 4\n")
    marks = read_landmarks(path)
    assert [label for label, _ in marks] == ["nose", "paw", "paw"] and np.allclose(marks[0][1], [1.5, -2.0])
    path.write_text("nose 7\npaw 0\n")
    assert read_landmarks(path, n_vertices=8) == [("nose", 7), ("paw", 0)]
    for text, n, message in (("nose 1\n", None, r"a.landmarks, line 1: expected 'label x y'"),
                             ("nose 1 x\n", None, "finite numbers, got '1 x'"),
                             ("nose 1 nan\n", None, "finite numbers"),
                             ("nose 8\n", 8, "vertex 8 is out of range for a mesh of 8 vertices"),
                             ("nose 1.5\n", 8, "whole number, got '1.5'"),
                             ("# nothing\n", None, "no landmarks")):
        path.write_text(text)
        with pytest.raises(FileFormatError, match=message):
            read_landmarks(path, n_vertices=n)
    with pytest.raises(FileFormatError, match="missing.landmarks: file not found"):
        read_landmarks(tmp_path / "missing.landmarks")


def test_the_error_is_the_geodesic_to_the_nearest_landmark_of_the_label():
    """On a flat square the exact geodesic is the straight line: a drawn landmark counts the distance from the
    vertex matched to the contour point nearest it to the nearer of its label's two true vertices."""
    uv, faces = grid_mesh(20, 20)
    mesh = TriMesh(np.column_stack([2.0 * uv, np.zeros(len(uv))]), faces, name="square")  # area 4
    xy = mesh.vertices[:, :2]
    at = lambda x, y: int(np.linalg.norm(xy - [x, y], axis=1).argmin())  # noqa: E731
    truth = {"paw": [at(0.0, 0.0), at(2.0, 2.0)], "nose": [at(1.0, 0.0)]}
    contour_points = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0]])
    map_xy = np.array([at(0.6, 0.8), at(1.6, 1.6), at(1.0, 1.0)])  # matched vertices of the three points
    result = SimpleNamespace(path=SimpleNamespace(contour_points=contour_points), map_xy=map_xy)
    drawn = [("paw", np.array([0.1, -0.1])), ("paw", np.array([4.0, 4.5])), ("nose", np.array([4.9, 0.2])),
             ("tail", np.array([0.0, 0.0]))]  # the mesh has no tail: not scored
    errors = landmark_errors(result, mesh, drawn, truth, GeodesicSolver(mesh))
    assert [label for label, _ in errors] == ["paw", "paw", "nose"]
    # (0.6, 0.8) to the origin; (1, 1) equally far from both paws; (1.6, 1.6) to the nose at (1, 0)
    expected = [1.0, np.sqrt(2.0), np.hypot(0.6, 1.6)]
    assert np.allclose([e for _, e in errors], np.array(expected) / 2.0, atol=1e-9)


def test_a_redrawn_variant_moves_every_point_a_little_and_never_crosses_itself():
    wolf = load_contour(DRAWN / "wolf.txt")
    size = np.ptp(wolf.points, axis=0).max()
    rng = np.random.default_rng(3)
    variants = [redrawn(wolf, rng) for _ in range(5)]
    for v in variants:
        moved = np.linalg.norm(v.points - wolf.points, axis=1)
        assert v.n_points == wolf.n_points and 0 < moved.mean() < 0.03 * size
        Contour2D(v.points, min_points=3)  # validated: no crossing
    again = redrawn(wolf, np.random.default_rng(3))
    assert np.array_equal(again.points, variants[0].points)  # seeded: the benchmark is reproducible
    # a comb of 40 teeth with slits far narrower than the jitter: some slit closes in every variant
    comb = [(0.0, 0.0), (40.0, 0.0)] + [p for x in range(39, 0, -1) for p in
                                        ((x + 0.0001, 20.0), (x + 0.0001, 1.0), (x - 0.0001, 1.0), (x - 0.0001, 20.0))]
    with pytest.raises(ContourError, match="no redrawn variant that does not cross itself in 100 attempts"):
        redrawn(Contour2D(comb + [(0.0, 20.0)], min_points=3), np.random.default_rng(0))


def test_the_bundled_landmarks_lie_on_their_drawings_and_meshes():
    queries = {q.name: q for q in drawn_queries(DRAWN)}
    assert set(queries) == {"cat", "wolf", "human"}
    for q in queries.values():
        outline = load_contour(q.contour_path).resample(4000).points
        size = np.ptp(outline, axis=0).max()
        for label, point in q.landmarks:  # on the outline, within 1 % of the drawing's size
            assert np.linalg.norm(outline - point, axis=1).min() < 0.01 * size, (q.name, label)
    for mesh_name, labels in (("data/tosca/wolf0", {"nose", "tail", "front_paw", "hind_paw"}),
                              ("data/tosca/cat1", {"nose", "tail", "front_paw", "hind_paw"}),
                              ("people/human2", {"head", "hand", "foot"})):
        mesh = load_mesh(resource(f"{mesh_name}.off"))
        marks = read_landmarks(resource(f"{mesh_name}.landmarks"), n_vertices=mesh.n_vertices)
        assert {label for label, _ in marks} == labels and len(marks) == len(labels) + 2  # pairs of limbs
        assert labels <= set().union(*(q.labels for q in queries.values()))


def test_drawings_folder_errors(tmp_path):
    with pytest.raises(InputError, match="not a folder"):
        drawn_queries(tmp_path / "nowhere")
    with pytest.raises(FileFormatError, match="no drawings with landmarks"):
        drawn_queries(tmp_path)
    (tmp_path / "wolf.landmarks").write_text("nose 12.2 7.05\n")
    with pytest.raises(FileFormatError, match="expected one drawing wolf.<ext> beside it, found 0"):
        drawn_queries(tmp_path)
    shutil.copy(DRAWN / "wolf.txt", tmp_path / "wolf.txt")
    assert drawn_queries(tmp_path)[0].labels == {"nose"}
    (tmp_path / "wolf.landmarks").write_text("nose 12.2 7.05\npaw 122 70.5\n")  # in other units: off the outline
    with pytest.raises(FileFormatError, match=r"wolf.landmarks: landmark paw \(122, 70.5\) lies .* from the outline "
                                              r"of wolf.txt, more than 5% of its size"):
        drawn_queries(tmp_path)


@pytest.fixture
def wolf_drawing_and_dataset(tmp_path):
    drawings, data = tmp_path / "drawings", tmp_path / "data"
    drawings.mkdir()
    data.mkdir()
    for name in ("wolf.txt", "wolf.landmarks"):
        shutil.copy(DRAWN / name, drawings / name)
    for name in ("wolf0.off", "wolf0.landmarks"):
        shutil.copy(resource(f"data/tosca/{name}"), data / name)
    return drawings, data


def test_benchmark_of_a_drawing_with_redrawn_variants(wolf_drawing_and_dataset, tmp_path):
    drawings, data = wolf_drawing_and_dataset
    out = tmp_path / "out"
    summary = contour_benchmark([data], out, planes=(), drawings=[drawings], redraws=1, params={"n_contour": 100})
    saved = json.loads((out / "contour_summary.json").read_text())
    (row,) = saved["drawn_rows"]
    assert row["status"] == "ok" and row["query"] == "wolf" and row["target"] == "wolf0" and not row["other_class"]
    assert row["scored_landmarks"] == 6 and row["redraws"] == 1
    for key in ("landmark_error", "redraw_error", "redraw_worst"):
        assert 0.0 <= row[key] < 2.0  # geodesics per √area on a body about 1.5 √area long
    assert row["redraw_error"] == row["redraw_worst"]  # one variant
    assert summary["drawings"]["all"]["landmark_error"] == pytest.approx(row["landmark_error"])
    assert summary["drawings"]["other class"] == {"queries": 0, "failed": 0}
    assert "| drawing | target | landmark error |" in (out / "contour_summary.md").read_text()
    header = (out / "contour_bench.csv").read_text().splitlines()[0].split(",")
    assert {"landmark_error", "redraw_error", "worst_landmark"} <= set(header)
    assert (out / "pictures" / "wolf-drawn__wolf0.png").is_file()
    (data / "wolf0.landmarks").unlink()
    with pytest.raises(InputError, match="no mesh of .* has landmarks"):
        contour_benchmark([data], tmp_path / "out2", planes=(), drawings=[drawings])
    for bad in (-1, 101, 2.5, True):
        with pytest.raises(ParameterError, match=f"redraws must be a whole number from 0 to 100, got {bad!r}"):
            contour_benchmark([data], tmp_path / "out3", planes=("main",), drawings=[drawings], redraws=bad)
    with pytest.raises(ParameterError, match="redraws are variants of drawings with landmarks; give them with --drawn"):
        contour_benchmark([data], tmp_path / "out3", planes=("main",), redraws=2)
    assert not (tmp_path / "out3").exists()  # refused before any output


def test_command_with_drawings(wolf_drawing_and_dataset, tmp_path, capsys):
    drawings, data = wolf_drawing_and_dataset
    code = main(["bench-contour", str(data), "--planes", "none", "--drawn", str(drawings), "--n-contour", "100",
                 "--no-pictures", "-o", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert code == 0 and "| all | 1 | 0 |" in captured.out and "wolf -> wolf0: landmark error" in captured.err
