"""2D-to-3D matching through rendered views (corrlib.methods.contour_views, ``--method contour-views``)."""

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from conftest import grid_mesh
from corrlib.cli import main
from corrlib.contour_bench import contour_benchmark
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.cyclic_paths import branch_and_bound
from corrlib.geometry.geodesics import GeodesicSolver, edge_paths
from corrlib.geometry.sections import (_fill_triangles, principal_frame, project_for_silhouette, rendered_view,
                                       rim_vertices)
from corrlib.io import load_contour, load_mesh
from corrlib.landmark_bench import DrawnQuery, match_drawn_query, read_landmarks
from corrlib.methods import solve
from corrlib.methods.contour2d import prepared_outline, torus_graph
from corrlib.methods.contour3d import node_costs
from corrlib.methods.contour_views import (ContourViewsParams, diagonal_length, mirror_image, render_view,
                                           view_directions)
from corrlib.progress import run
from corrlib.resources import resource
from corrlib.shapes import Contour2D, TriMesh

DRAWN = resource("data/silhouettes/drawn")


@pytest.fixture(scope="module")
def wolf():
    return load_mesh(resource("data/tosca/wolf0.off"))


def test_the_box_directions_are_thirteen_distinct_views():
    axes = np.linalg.qr(np.random.default_rng(3).standard_normal((3, 3)))[0].T
    directions = view_directions(axes)
    assert directions.shape == (13, 3) and np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    cosines = np.abs(directions @ directions.T)[np.triu_indices(13, 1)]
    assert cosines.max() < 1 - 1e-6  # no direction twice, nor its opposite (the mirror image)
    assert np.allclose(np.abs(directions[:3] @ axes.T), np.eye(3))  # the principal axes first
    assert np.allclose(view_directions(axes, "axes"), directions[:3])


def test_the_diagonal_length_of_a_torus():
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert diagonal_length(square, 2.0 * square) == pytest.approx(np.hypot(4.0, 8.0))
    circle = np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 2000, endpoint=False)),
                              np.sin(np.linspace(0, 2 * np.pi, 2000, endpoint=False))])
    assert diagonal_length(circle, circle[::7]) == pytest.approx(np.hypot(2 * np.pi, 2 * np.pi), rel=1e-4)


def test_the_triangle_fill_is_the_polygon_rasteriser(wolf):
    from skimage.draw import polygon as draw_polygon

    _, axes = principal_frame(wolf)
    for direction in (axes[2], view_directions(axes)[9]):
        projection = project_for_silhouette(wolf, direction, 128)
        rows, cols = -projection.pixels[:, 1], projection.pixels[:, 0]
        expected = np.zeros(projection.shape, dtype=bool)
        for face in wolf.faces:
            rr, cc = draw_polygon(rows[face], cols[face], projection.shape)
            expected[rr, cc] = True
        filled = np.zeros(projection.shape, dtype=np.bool_)
        _fill_triangles(rows.copy(), cols.copy(), wolf.faces.astype(np.int64), filled)
        assert expected.sum() > 1000 and np.array_equal(filled, expected)


def test_edge_paths_are_shortest_and_refuse_separate_components():
    uv, faces = grid_mesh(6, 5)
    mesh = TriMesh(np.column_stack([uv * [1.0, 1.7], np.zeros(len(uv))]), faces)
    rng = np.random.default_rng(0)
    starts, ends = rng.integers(0, mesh.n_vertices, 20), rng.integers(0, mesh.n_vertices, 20)
    distances = dijkstra(mesh.adjacency, indices=starts)
    for s, e, path, row in zip(starts, ends, edge_paths(mesh, starts, ends), distances):
        assert path[0] == s and path[-1] == e
        steps = np.linalg.norm(np.diff(mesh.vertices[path], axis=0), axis=1)
        assert all(mesh.adjacency[a, b] > 0 for a, b in zip(path[:-1], path[1:]))
        assert steps.sum() == pytest.approx(row[e])
    two = TriMesh(np.vstack([mesh.vertices, mesh.vertices + [5.0, 0, 0]]),
                  np.vstack([faces, faces + mesh.n_vertices]), validate=False)
    with pytest.raises(InputError, match="different connected components"):
        edge_paths(two, [0], [mesh.n_vertices])


@pytest.mark.parametrize("view_choice", ["fused", "energy"])
def test_the_search_over_every_view_is_the_best_single_view(wolf, view_choice):
    """The branch-and-bound over every view and reading finds the lowest of their separate optima: the torus
    energy times the view's shape-context dissimilarity to that reading of the drawing (fused), or the torus
    energy alone."""
    from corrlib.descriptors.shape_context import inner_shape_context, outline_dissimilarity

    params = ContourViewsParams(directions="axes", n_contour=40, n_view=40, view_choice=view_choice)
    contour = load_contour(DRAWN / "wolf.txt")
    result = solve("contour-views", contour, wolf, **vars(params))
    _, axes = principal_frame(wolf)
    energies = []
    for direction in view_directions(axes, "axes"):
        view = render_view(wolf, direction, params)
        shape = inner_shape_context(view.outline.contour.resample(100).ccw().points)
        for query in (contour, mirror_image(contour)):
            outline = prepared_outline(query, 40, params.k, params.n_scales, finer="")
            cost = node_costs(outline.features, view.outline.features)
            if view_choice == "fused":  # both outlines at 100 points, counter-clockwise (the reflection turns one)
                cost = cost * outline_dissimilarity(inner_shape_context(query.resample(100).ccw().points), shape)
            graph = torus_graph(cost / diagonal_length(outline.points, view.outline.points), outline.points,
                                view.outline.points)
            energies.append(run(branch_and_bound(graph)).energy)
    assert result.energy == pytest.approx(min(energies), rel=1e-9)
    assert result.search.lower_bound == pytest.approx(result.search.upper_bound)
    assert (result.extras["view_unlikeness"] is None) == (view_choice == "energy")


def _outline_step(outline, projection, mesh, n_points=ContourViewsParams().n_view):
    """The spacing of the matched view's resampled outline, in √area of the mesh (the resolution of a match)."""
    return outline.length / projection.pixels_per_unit / n_points / np.sqrt(mesh.area)


def _rim_error(result, mesh, ground_truth_of):
    """Mean geodesic error / √area of the matched vertices against the rim vertices (near or far side)."""
    truth = ground_truth_of(result.path.contour_points)
    solver = GeodesicSolver(mesh)
    errors = np.min([solver.pair_distances(np.asarray(result.map_xy), column) for column in truth.T], axis=0)
    return float(errors.mean() / np.sqrt(mesh.area))


def test_a_mesh_seen_from_the_side_is_matched_on_its_rim(wolf):
    _, axes = principal_frame(wolf)
    outline, projection = rendered_view(wolf, axes[2])
    result = solve("contour-views", outline, wolf)
    assert abs(np.dot(result.extras["view_direction"], axes[2])) > 0.99
    assert _rim_error(result, wolf, lambda points: rim_vertices(points, projection)) < 0.5 * _outline_step(
        outline, projection, wolf)
    # the curve is closed and runs along mesh edges, every contour point on it
    path = result.path
    assert path.vertices[0] == path.vertices[-1]
    assert all(a == b or wolf.adjacency[a, b] > 0 for a, b in zip(path.vertices[:-1], path.vertices[1:]))
    assert set(path.contour_index.tolist()) == set(range(len(path.contour_points)))
    assert np.array_equal(path.vertices[np.searchsorted(path.layers, np.arange(len(path.contour_points)))],
                          result.map_xy)


@pytest.mark.slow
def test_how_the_outline_is_given_does_not_matter(wolf):
    """Rotated, scaled, mirrored, reversed and started elsewhere: the same outline, the same curve (within one
    step of the resampled outlines, whose points fall elsewhere)."""
    _, axes = principal_frame(wolf)
    outline, projection = rendered_view(wolf, axes[2])
    angle = np.deg2rad(37.0)
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    centre = outline.points.mean(axis=0)
    # (what is done to every point, how the points are reordered)
    variants = {"rotated and scaled": (lambda p: 5.0 * (p - centre) @ rotation.T + [3.0, -8.0], lambda p: p),
                "mirrored": (lambda p: p * [-1.0, 1.0], lambda p: p),
                "reversed, started elsewhere": (lambda p: p, lambda p: np.roll(p[::-1], 100, axis=0))}
    for name, (move, reorder) in variants.items():
        result = solve("contour-views", Contour2D(reorder(move(outline.points)), name=name), wolf)
        moved = move(outline.points)

        def truth(points, moved=moved):  # the matched contour's points back in the rendered outline's pixels
            return rim_vertices(outline.points[[np.argmin(np.linalg.norm(moved - p, axis=1)) for p in points]],
                                projection)

        assert _rim_error(result, wolf, truth) < _outline_step(outline, projection, wolf), name


@pytest.mark.slow
@pytest.mark.parametrize("drawing, mesh, limit", [("wolf", "data/tosca/wolf0", 0.1), ("wolf", "data/tosca/wolf1", 0.1),
                                                  ("human", "people/human1", 0.1), ("human", "people/human3", 0.1),
                                                  ("cat", "data/tosca/cat0", 0.3)])
def test_drawings_of_meshes_in_their_pose(drawing, mesh, limit):
    """The drawn outlines' landmarks where contour3d puts them at 0.19-0.53 √area (docs/decisions.md). The drawn
    cat on cat0 (measured 0.24) was read as the narrow view from the front by the torus energy alone (0.56):
    its stick legs and tail are not the cat's, and the compact outline's bland features half-matched them."""
    query = DrawnQuery(drawing, DRAWN / f"{drawing}.txt", read_landmarks(DRAWN / f"{drawing}.landmarks"))
    row = match_drawn_query(query, resource(f"{mesh}.off"), resource(f"{mesh}.landmarks"), {}, method="contour-views")
    assert row["status"] == "ok" and row["landmark_error"] < limit


@pytest.mark.slow
def test_most_redrawings_of_the_wolf_hold():
    """The drawn wolf redrawn six times (1 % of its size per corner) on wolf0: four of the six within 0.1 √area
    (measured 0.03-0.08, with either view choice). The other two are read head to tail in a side view (1.06 and
    1.08): neither the torus energy nor the shape context tells a drawn head from a drawn tail by much, and a
    redrawing can tip them. A distribution, not one lucky draw."""
    from corrlib.landmark_bench import redrawn_errors

    wolf0 = load_mesh(resource("data/tosca/wolf0.off"))
    truth = {}
    for label, vertex in read_landmarks(resource("data/tosca/wolf0.landmarks"), n_vertices=wolf0.n_vertices):
        truth.setdefault(label, []).append(vertex)
    errors = redrawn_errors(load_contour(DRAWN / "wolf.txt"), wolf0, read_landmarks(DRAWN / "wolf.landmarks"), truth,
                            GeodesicSolver(wolf0), {}, redraws=6, seed=0, method="contour-views")
    assert sum(error < 0.1 for error in errors) >= 4


@pytest.mark.slow
def test_the_mesh_may_be_moved_mirrored_reordered_or_remeshed(wolf):
    """The views come from the mesh's principal frame and a raster, so none of these changes the match."""
    from corrlib.geometry.remeshing import remeshed
    from corrlib.landmark_bench import landmark_errors
    from scipy.spatial import cKDTree

    contour, drawn = load_contour(DRAWN / "wolf.txt"), read_landmarks(DRAWN / "wolf.landmarks")
    truth = {}
    for label, vertex in read_landmarks(resource("data/tosca/wolf0.landmarks"), n_vertices=wolf.n_vertices):
        truth.setdefault(label, []).append(vertex)
    rng = np.random.default_rng(5)
    order = rng.permutation(wolf.n_vertices)
    new_index = np.argsort(order)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    coarse = remeshed(wolf, 3000).mesh
    nearest_coarse = cKDTree(coarse.vertices).query
    variants = [(TriMesh(37.0 * wolf.vertices[order] @ rotation.T + 5.0, new_index[wolf.faces]), new_index.__getitem__),
                (TriMesh(wolf.vertices * [-1.0, 1.0, 1.0], wolf.faces[:, ::-1]), lambda v: v),
                (coarse, lambda v: nearest_coarse(wolf.vertices[v])[1])]
    for mesh, carried in variants:
        result = solve("contour-views", contour, mesh)
        moved_truth = {label: [int(carried(v)) for v in vertices] for label, vertices in truth.items()}
        errors = [e for _, e in landmark_errors(result, mesh, drawn, moved_truth, GeodesicSolver(mesh))]
        assert len(errors) == 6 and np.mean(errors) < 0.1  # 0.039 as given


def test_a_view_too_thin_to_fill_is_skipped():
    """A flat square seen edge-on has no outline; the other views still match."""
    uv, faces = grid_mesh(12, 12)
    square = TriMesh(np.column_stack([uv, np.zeros(len(uv))]), faces)
    contour = Contour2D(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float), name="square",
                        min_points=3).resample(40)
    result = solve("contour-views", contour, square, n_contour=40, n_view=40)
    assert result.extras["views_skipped"] >= 1 and result.extras["views"] >= 1
    assert len(result.map_xy) == 40


def test_bad_input_is_named(wolf, tmp_path, capsys):
    contour = load_contour(DRAWN / "wolf.txt")
    with pytest.raises(ParameterError, match="directions"):
        solve("contour-views", contour, wolf, directions="sphere")
    with pytest.raises(ParameterError, match="does not match a contour to a mesh; the 2D-to-3D methods are "
                                             "contour3d, contour-views"):
        contour_benchmark([resource("data/tosca")], tmp_path / "out", planes=("main",), method="kernel-matching")
    assert not (tmp_path / "out").exists()
    code = main(["bench-contour", str(resource("data/tosca")), "--planes", "main", "--method", "contour-viewz",
                 "-o", str(tmp_path / "out")])
    assert code != 0 and "unknown method 'contour-viewz'" in capsys.readouterr().err
    with pytest.raises(InputError, match="wolf0.off: no view of the mesh has an outline that can be matched .*k=60"):
        solve("contour-views", contour, wolf, n_contour=400, n_view=10, k=60)  # views of 10 points fill too coarsely
    code = main(["match", str(DRAWN / "wolf.txt"), str(resource("data/tosca/wolf0.off")), "--method",
                 "contour-views", "--param", "k=400", "-o", str(tmp_path / "r")])
    assert code != 0 and "k=400" in capsys.readouterr().err
