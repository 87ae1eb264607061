"""Princeton-protocol errors: identity, known perturbations, curves, symmetry."""

import numpy as np
import pytest

from corrlib.errors import InputError, ParameterError
from corrlib.evaluation import cumulative_curve, curve_auc, geodesic_errors
from corrlib.geometry.geodesics import GeodesicSolver


def test_identity_map_has_zero_error(wolf_pair):
    wolf0, wolf1 = wolf_pair
    ident = np.arange(wolf0.n_vertices)
    report = geodesic_errors(ident, wolf1, ident, ident)
    s = report.summary()
    assert s["mean"] == 0 and s["within_0.025"] == 1 and s["auc"] == pytest.approx(1.0)


def test_neighbour_shift_has_edge_length_error(wolf_pair):
    wolf1 = wolf_pair[1]
    # map every vertex to one of its neighbours: the geodesic between adjacent vertices is the edge
    adj = wolf1.adjacency
    neighbour = np.array([adj.indices[adj.indptr[i]] for i in range(wolf1.n_vertices)])
    ident = np.arange(wolf1.n_vertices)
    report = geodesic_errors(neighbour, wolf1, ident, ident)
    expected = np.linalg.norm(wolf1.vertices[neighbour] - wolf1.vertices, axis=1) / np.sqrt(wolf1.area)
    assert np.allclose(report.errors, expected, rtol=1e-6)
    diam = geodesic_errors(neighbour, wolf1, ident, ident, normalize="diameter")
    assert diam.normalization > np.sqrt(wolf1.area) * 0.5


@pytest.mark.slow
def test_symmetric_ground_truth(cat_pair):
    cat0, cat1, gt = cat_pair
    # the mirrored ground truth itself as a map: large direct error, zero symmetric error
    rows = np.unique(gt["cat0"], return_index=True)[1]  # the .vts may list a source vertex twice
    mirror = np.zeros(cat0.n_vertices, dtype=np.int64)
    mirror[gt["cat0"][rows]] = gt["cat1.sym"][rows]
    report = geodesic_errors(mirror, cat1, gt["cat0"][rows], gt["cat1"][rows], gt_target_sym=gt["cat1.sym"][rows])
    s = report.summary()
    assert s["mean_sym"] == 0 and s["mean"] > 0.1
    # a noisy map: the symmetric error (mirrored pairs pruned by the straight-line bound) equals the
    # brute-force minimum over both partners
    noisy = np.random.default_rng(2).integers(0, cat1.n_vertices, cat0.n_vertices)
    noisy[gt["cat0"][rows][::2]] = gt["cat1"][rows][::2]
    report = geodesic_errors(noisy, cat1, gt["cat0"][rows], gt["cat1"][rows], gt_target_sym=gt["cat1.sym"][rows])
    solver = GeodesicSolver(cat1)
    predicted = noisy[gt["cat0"][rows]]
    brute = np.minimum(solver.pair_distances(predicted, gt["cat1"][rows]),
                       solver.pair_distances(predicted, gt["cat1.sym"][rows])) / np.sqrt(cat1.area)
    assert np.allclose(report.errors_sym, brute, rtol=1e-12)


def test_curve_and_auc():
    errors = np.array([0.0, 0.01, 0.02, 0.3])
    thresholds = np.array([0.0, 0.01, 0.1, 0.25])
    assert np.allclose(cumulative_curve(errors, thresholds), [0.25, 0.5, 0.75, 0.75])
    assert curve_auc(np.ones(5), np.linspace(0, 1, 5)) == pytest.approx(1.0)
    assert curve_auc(np.linspace(0, 1, 101), np.linspace(0, 1, 101)) == pytest.approx(0.5)


def test_evaluation_errors(wolf_pair):
    wolf1 = wolf_pair[1]
    ident = np.arange(wolf1.n_vertices)
    with pytest.raises(InputError, match="map_xy has indices outside"):
        geodesic_errors(ident + 1, wolf1, ident, ident)
    with pytest.raises(InputError, match="ground truth rows differ"):
        geodesic_errors(ident, wolf1, ident[:5], ident[:4])
    with pytest.raises(InputError, match="empty"):
        geodesic_errors(ident, wolf1, ident[:0], ident[:0])
    with pytest.raises(ParameterError, match="normalisation"):
        geodesic_errors(ident, wolf1, ident, ident, normalize="bbox")


def test_evaluate_names_its_options_a_contour_and_another_target(wolf_pair, tmp_path):
    """``evaluate`` through a result: a misspelt option is named with the known ones; a contour is no target;
    the result records what it matched (kept by save and load) and is refused on a target of another size (a
    map of the wolves read on cat1 gave a mean error without a word) or on another shape of the same size (the
    source given as the target), but taken on its target moved, turned and scaled; a float map of whole numbers
    is taken."""
    from _data import TOSCA

    from corrlib.evaluation import evaluate
    from corrlib.io import load_mesh
    from corrlib.methods import solve
    from corrlib.methods.base import MatchResult
    from corrlib.shapes import Contour2D, TriMesh

    wolf0, wolf1 = wolf_pair
    rows = np.arange(wolf0.n_vertices)
    result = solve("descriptor-nn", wolf0, wolf1)
    assert result.inputs["target"] == {"name": "wolf1.off", "kind": "mesh", "vertices": wolf1.n_vertices,
                                       "faces": wolf1.faces.shape[0], "content_hash": wolf1.content_hash,
                                       "shape_print": list(wolf1.shape_print)}
    result.save(tmp_path / "r")
    loaded = MatchResult.load(tmp_path / "r")
    assert loaded.inputs == result.inputs
    means = [evaluate(given, wolf1, rows, rows).summary()["mean"] for given in (loaded, result)]
    assert means[0] == means[1]
    with pytest.raises(ParameterError, match="unknown option 'normalise' .*known: gt_target_sym, normalize"):
        evaluate(result, wolf1, rows, rows, normalise="diameter")
    circle = Contour2D(np.column_stack([np.cos(np.linspace(0, 6, 30)), np.sin(np.linspace(0, 6, 30))]))
    with pytest.raises(InputError, match="the target must be the mesh the map points into .* got Contour2D"):
        evaluate(result.map_xy, circle, rows, rows)
    cat1 = load_mesh(TOSCA / "cat1.off")
    for given in (loaded, MatchResult("m", result.map_xy, result.map_yx)):  # by the record, or by the reverse map
        with pytest.raises(InputError, match=f"maps onto another target .*{wolf1.n_vertices} vertices.* than "
                                             f"'cat1.off' \\({cat1.n_vertices} vertices\\)"):
            evaluate(given, cat1, rows, rows)
    with pytest.raises(InputError, match="than 'wolf0.off' \\(4344 vertices, another shape of as many vertices"):
        evaluate(loaded, wolf0, rows, rows)  # the wolves share their vertex count and faces, not their pose
    turn = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    in_mm = TriMesh(np.round(wolf1.vertices @ turn.T * 1000 + 5, 3), wolf1.faces, name="wolf1_mm.off")
    assert evaluate(loaded, in_mm, rows, rows).summary()["mean"] == pytest.approx(means[0], rel=1e-6)
    assert evaluate(rows.astype(float), wolf1, rows, rows).summary()["mean"] == 0.0  # the wolves share vertices


def test_a_collapsed_map_is_named_and_a_map_onto_a_part_is_not(wolf_pair):
    """Every vertex sent to one target vertex (a functional map of rank one, as from a sphere's nearly
    constant descriptors) is warned of; the identity, a map onto a fifth of the target, and a contour's map
    (its points lie along a curve) are not."""
    from corrlib.evaluation import collapse_note
    from corrlib.shapes import Contour2D

    wolf0, wolf1 = wolf_pair
    note = collapse_note(np.zeros(wolf0.n_vertices, dtype=int), wolf0, wolf1)
    assert note is not None and "land on 1 vertices of wolf1.off" in note
    assert collapse_note(np.arange(wolf0.n_vertices), wolf0, wolf1) is None
    upper = np.flatnonzero(wolf1.vertices[:, 1] > np.quantile(wolf1.vertices[:, 1], 0.8))  # the top fifth
    assert collapse_note(upper[np.arange(wolf0.n_vertices) % upper.size], wolf0, wolf1) is None
    assert collapse_note(np.full(wolf0.n_vertices, -1), wolf0, wolf1) == "the map matches no vertex"
    circle = Contour2D(np.column_stack([np.cos(np.linspace(0, 6.2, 40)), np.sin(np.linspace(0, 6.2, 40))]))
    assert collapse_note(np.zeros(40, dtype=int), circle, wolf1) is None


def test_the_area_a_map_reaches_by_hand():
    """A regular tetrahedron: every vertex holds a quarter of the area, so a map onto two of its vertices reaches
    half of it, a map onto all of them the whole, and no map nothing to measure."""
    from corrlib.evaluation import image_area_share
    from corrlib.shapes import TriMesh

    corners = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
    tetra = TriMesh(corners, np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]), name="tetrahedron")
    assert image_area_share(np.array([0, 0, 2, -1]), tetra) == pytest.approx(0.5)
    assert image_area_share(np.array([3, 2, 1, 0]), tetra) == pytest.approx(1.0)
    assert image_area_share(np.array([-1, -1, -1, -1]), tetra) == 0.0
    assert np.isnan(image_area_share(None, tetra))
