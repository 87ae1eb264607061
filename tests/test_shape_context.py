"""The inner-distance shape context (corrlib.descriptors.shape_context), the view dissimilarity of a drawing and
a mesh (corrlib.outline_views) and the fused retrieval score (corrlib.retrieval.fused_scores)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from matplotlib.path import Path as PolygonPath

from _data import TOSCA

from corrlib.descriptors.shape_context import (chi2_costs, cyclic_alignment_cost, inner_distances,
                                               inner_shape_context, outline_dissimilarity, visibility)
from corrlib.methods.contour_views import mirror_image
from corrlib.shapes import Contour2D
from corrlib.retrieval import fused_scores

#: a U: two arms of height 3 joined by a base of height 1, the notch between the arms 1 wide
U_SHAPE = np.array([(0, 0), (3, 0), (3, 3), (2, 3), (2, 1), (1, 1), (1, 3), (0, 3)], dtype=float)


def star_polygon(rng, n=14):
    """A random simple polygon: radii about the origin at increasing angles (star-shaped, not convex)."""
    angles = np.sort(rng.uniform(0, 2 * np.pi, n))
    radii = rng.uniform(0.3, 1.0, n)
    return np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])


def test_inner_distances_of_a_convex_polygon_are_euclidean():
    t = np.linspace(0, 2 * np.pi, 17, endpoint=False)
    points = np.column_stack([2 * np.cos(t), np.sin(t)])
    distances, first_step = inner_distances(points)
    assert np.allclose(distances, np.linalg.norm(points[:, None] - points[None], axis=2))
    # in a convex polygon every shortest path is the chord: its first step is its end
    assert np.array_equal(first_step, np.broadcast_to(np.arange(17), (17, 17)))


def test_inner_distance_round_the_notch_of_a_u():
    """Between the inner tips of the arms (1, 3) and (2, 3) the path goes down the notch: 2 + 1 + 2."""
    distances, first_step = inner_distances(U_SHAPE)
    assert distances[6, 3] == pytest.approx(5.0)
    assert first_step[6, 3] == 5 and first_step[3, 6] == 4  # (1, 3) goes first to (1, 1); (2, 3) to (2, 1)
    # the chord between the outer corners (0, 0) and (3, 3) crosses the notch: the path bends at (2, 1)
    assert distances[0, 2] == pytest.approx(np.hypot(2, 1) + np.hypot(1, 2))
    assert not visibility(U_SHAPE)[0, 2] and visibility(U_SHAPE)[0, 4]


def test_inner_distances_against_brute_force_visibility():
    """Random star polygons: visibility by sampling every chord densely (matplotlib's point-in-polygon) and
    Floyd–Warshall over it agree with the visibility graph's distances."""
    rng = np.random.default_rng(3)
    for _ in range(5):
        points = star_polygon(rng)
        n = len(points)
        polygon = PolygonPath(points)
        t = np.linspace(0.01, 0.99, 300)
        brute = np.full((n, n), np.inf)
        for i, j in itertools.combinations(range(n), 2):
            chord = points[i] + t[:, None] * (points[j] - points[i])
            if abs(i - j) in (1, n - 1) or polygon.contains_points(chord).all():
                brute[i, j] = brute[j, i] = np.linalg.norm(points[i] - points[j])
        np.fill_diagonal(brute, 0.0)
        for k in range(n):
            brute = np.minimum(brute, brute[:, k:k + 1] + brute[k:k + 1, :])
        distances, _ = inner_distances(points)
        assert np.allclose(distances, brute)


def test_shape_context_histograms_and_invariances():
    rng = np.random.default_rng(5)
    points = star_polygon(rng, 40)  # counter-clockwise: increasing angles
    context = inner_shape_context(points)
    assert context.shape == (40, 60) and np.allclose(context.sum(axis=1), 1.0) and np.all(context >= 0)
    turned = points @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # a quarter turn, exact in floating point
    assert np.allclose(inner_shape_context(4.0 * turned + 7.0), context)
    assert np.allclose(inner_shape_context(np.roll(points, 9, axis=0)), np.roll(context, 9, axis=0))
    assert outline_dissimilarity(context, np.roll(context, 13, axis=0)) == pytest.approx(0.0, abs=1e-12)
    # a reflection is another shape (the angles turn the other way) unless the mirror is compared
    mirror = mirror_image(Contour2D(points, validate=False)).ccw().points
    assert outline_dissimilarity(context, inner_shape_context(mirror)) > 0.05


def brute_alignment(costs, gap):
    """Every order-preserving alignment of two closed sequences, by recursion over (i, j) from every start."""
    m, n = costs.shape

    def best(i, j, start):
        if i == m and j == n:
            return 0.0
        options = []
        if i < m and j < n:
            options.append(costs[i, (start + j) % n] + best(i + 1, j + 1, start))
        if i < m:
            options.append(gap + best(i + 1, j, start))
        if j < n:
            options.append(gap + best(i, j + 1, start))
        return min(options)

    return min(best(0, 0, start) for start in range(n)) / m


def test_cyclic_alignment_against_brute_force():
    rng = np.random.default_rng(0)
    for m, n in ((1, 1), (2, 3), (3, 3), (4, 3), (3, 5)):
        for gap in (0.05, 0.25, 2.0):
            costs = rng.uniform(0, 1, (m, n))
            assert cyclic_alignment_cost(costs, gap) == pytest.approx(brute_alignment(costs, gap))


def test_chi2_costs_by_hand():
    a = np.array([[0.5, 0.5, 0.0], [1.0, 0.0, 0.0]])
    b = np.array([[0.0, 0.5, 0.5]])
    # ½ (0.25/0.5 + 0 + 0.25/0.5) = 0.5; ½ (1 + 0.25/0.5 + 0.25/0.5) = 1
    assert np.allclose(chi2_costs(a, b), [[0.5], [1.0]])


def limb_shape(bend_degrees: float) -> np.ndarray:
    """A 4 × 1 body with a 3 × 0.4 limb at its right end, bent up by ``bend_degrees`` about its root (a
    polygon of 14 corners, resampled to 100 points by arc length)."""
    angle = np.radians(bend_degrees)
    axis, normal = np.array([np.cos(angle), np.sin(angle)]), np.array([-np.sin(angle), np.cos(angle)])
    root = np.array([4.0, 0.5])
    limb = [root - 0.2 * normal, root - 0.2 * normal + 3 * axis, root + 0.2 * normal + 3 * axis, root + 0.2 * normal]
    corners = [(0, 0), (4, 0), (4, 0.3), *limb, (4, 0.7), (4, 1), (0, 1)]
    return Contour2D(np.array(corners, dtype=float), validate=False).resample(100).ccw().points


def test_a_bent_limb_is_nearer_than_other_shapes():
    """The descriptor's purpose: an articulation (a limb bent by 60° about its root) keeps the outline's inner
    distances, so the bent shape is nearer the straight one than shapes of other parts: the body with a limb at
    each end, and with one limb standing up from its middle."""
    def context(corners):
        return inner_shape_context(Contour2D(np.array(corners, float), validate=False).resample(100).ccw().points)

    straight, bent = inner_shape_context(limb_shape(0.0)), inner_shape_context(limb_shape(60.0))
    two_limbs = context([(0, 0), (4, 0), (4, 0.3), (7, 0.3), (7, 0.7), (4, 0.7), (4, 1), (0, 1), (0, 0.7),
                         (-3, 0.7), (-3, 0.3), (0, 0.3)])
    upright = context([(0, 0), (4, 0), (4, 1), (2.2, 1), (2.2, 4), (1.8, 4), (1.8, 1), (0, 1)])
    assert outline_dissimilarity(straight, bent) < min(outline_dissimilarity(straight, two_limbs),
                                                       outline_dissimilarity(straight, upright))


def test_fused_scores_by_hand():
    """Energy times view dissimilarity: unchanged in order by a factor on either measure, independent of the
    other meshes; a failed mesh last; a mesh without views takes the others' median."""
    energies, views = np.array([100.0, 80.0, 120.0]), np.array([0.2, 0.3, 0.1])
    assert np.allclose(fused_scores(energies, views), [20.0, 24.0, 12.0])
    order = np.argsort(fused_scores(energies, views))
    assert np.array_equal(np.argsort(fused_scores(7.0 * energies, 0.01 * views)), order)
    assert np.allclose(fused_scores(energies[:2], views[:2]), fused_scores(energies, views)[:2])
    scores = fused_scores([1.0, np.inf, 3.0, 2.0], [0.1, 0.0, 0.3, np.nan])
    assert np.isinf(scores[1]) and np.allclose(scores[[0, 2, 3]], [0.1, 0.9, 2.0 * 0.2])


def test_views_of_the_drawn_class_are_nearest(tmp_path, monkeypatch):
    """Rendered outlines and a hand-drawn person against the bundled animals and people: each query's own
    class has the lowest view dissimilarities, on the mesh drawn and on its other pose; the cached views are
    the ones computed."""
    from corrlib.contour_bench import silhouette_query
    from corrlib.io import load_contour, load_mesh
    from corrlib.outline_views import query_outline, view_contexts, view_dissimilarity
    from corrlib.resources import resource

    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    meshes = {name: load_mesh(TOSCA / f"{name}.off") for name in ("cat0", "cat1", "wolf0", "wolf1")}
    meshes.update({name: load_mesh(resource(f"people/{name}.off")) for name in ("human0", "human1")})
    queries = {"wolf": silhouette_query(meshes["wolf0"]).contour, "person": silhouette_query(meshes["human0"]).contour,
               "drawn person": load_contour(resource("data/silhouettes/drawn/human.txt"))}
    for name, contour in queries.items():
        outline = query_outline(contour)
        distances = {mesh: view_dissimilarity(outline, meshes[mesh]) for mesh in meshes}
        mine = [mesh for mesh in meshes if mesh.startswith("wolf" if name == "wolf" else "human")]
        others = [d for m, d in distances.items() if m not in mine]
        assert max(distances[m] for m in mine) < min(others), (name, distances)
    assert np.array_equal(view_contexts(meshes["cat0"]), view_contexts(meshes["cat0"], use_cache=False))


def test_retrieve_ranks_by_the_chosen_measure():
    """``ranking="energy"`` sorts by the matching energy and renders no views; ``"fused"`` by energy times view
    dissimilarity, which the hits carry; another ranking is refused by name."""
    from corrlib.errors import ParameterError
    from corrlib.io import load_contour
    from corrlib.progress import run
    from corrlib.resources import resource
    from corrlib.retrieval import retrieval_params, retrieve

    query = load_contour(resource("data/silhouettes/drawn/wolf.txt"))
    meshes = [TOSCA / "cat0.off", TOSCA / "wolf0.off", resource("people/human0.off")]
    params = retrieval_params(n_contour=40)
    by_energy = run(retrieve(query, meshes, params, jobs=1, ranking="energy"))
    assert [h.energy for h in by_energy] == sorted(h.energy for h in by_energy)
    assert all(np.isnan(h.view_distance) and h.score == h.energy for h in by_energy)
    fused = run(retrieve(query, meshes, params, jobs=1))
    energies = {h.name: h.energy for h in by_energy}
    assert {h.name: h.energy for h in fused} == pytest.approx(energies)
    assert all(0.0 < h.view_distance < 1.0 for h in fused)
    assert np.allclose([h.score for h in fused], [h.energy * h.view_distance for h in fused])
    assert [h.score for h in fused] == sorted(h.score for h in fused)
    with pytest.raises(ParameterError, match="ranking must be one of fused, energy"):
        run(retrieve(query, meshes, params, jobs=1, ranking="views"))
    # the command line offers the same rankings (named there without importing the retrieval module)
    from corrlib.cli import build_parser
    from corrlib.cli_contour import RANKING_CHOICES
    from corrlib.retrieval import RANKINGS

    assert RANKING_CHOICES == RANKINGS
    assert build_parser().parse_args(["retrieve", "q", "f"]).ranking == RANKINGS[0]
