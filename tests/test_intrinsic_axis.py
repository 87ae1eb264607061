"""The intrinsic axis: analytic strips and squares, identities, invariances, and its use in 2D-to-3D matching."""

import numpy as np
import pytest
import trimesh

from corrlib.errors import ParameterError
from corrlib.geometry.cyclic_paths import branch_and_bound, branch_and_bound_union
from corrlib.geometry.intrinsic_axis import axis_mismatch, intrinsic_axis, spectral_axes
from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.geometry.spectrum import eigenpairs
from corrlib.methods import solve
from corrlib.methods.contour3d import (Contour3DParams, axis_cost, axis_scales, feature_distances, prepare_mesh,
                                       prepare_query, product_graph)
from corrlib.progress import run
from corrlib.shapes import Contour2D, TriMesh


def rectangle(length, width=1.0, cells=(60, 12), perm_seed=None):
    """A triangulated [0, length] x [0, width] rectangle (z = 0), optionally with shuffled vertex order."""
    nx, ny = cells
    x, y = np.meshgrid(np.linspace(0, length, nx + 1), np.linspace(0, width, ny + 1), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    idx = np.arange(x.size).reshape(nx + 1, ny + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.vstack([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    if perm_seed is not None:
        perm = np.random.default_rng(perm_seed).permutation(len(vertices))
        vertices, faces = vertices[perm], np.argsort(perm)[faces]
    return TriMesh(vertices, faces, name=f"rectangle-{length}")


def axis_of(mesh, k=6):
    stiffness, mass = mesh_laplacian(mesh)
    evals, evecs = eigenpairs(stiffness, mass, k)
    return intrinsic_axis(evals, evecs, mass.diagonal()), mass.diagonal()


def test_a_long_strip_has_the_analytic_axis_and_confidence():
    """Neumann strip [0, L] x [0, 1], L = 5: φ_1 = cos(π x / L) is monotone in x, so the mass quantile of
    a vertex is the share of the area left (or right) of it, x / L; λ_j = (jπ/L)² for j ≤ 4 < L, so the
    confidence is 1 - λ_1/λ_2 = 3/4."""
    strip = rectangle(5.0)
    axis, _ = axis_of(strip)
    x = strip.vertices[:, 0] / 5.0
    expected = x if np.corrcoef(axis.coordinate, x)[0, 1] > 0 else 1.0 - x
    assert np.max(np.abs(axis.coordinate - expected)) < 0.02  # the quantile of a grid column, up to its width
    assert axis.confidence == pytest.approx(0.75, abs=0.01)


def test_a_square_has_no_axis():
    """λ_1 = λ_2 = π² on the unit square: φ_1 is any mix of cos(πx) and cos(πy), the confidence is 0."""
    axis, _ = axis_of(rectangle(1.0, cells=(24, 24)))
    assert axis.confidence < 0.02


def test_quantile_identities():
    """Mass quantiles lie in (0, 1), their mass-weighted mean is exactly 1/2, and they order the vertices
    as the eigenfunction does."""
    strip = rectangle(3.0, cells=(30, 10))
    stiffness, mass = mesh_laplacian(strip)
    evals, evecs = eigenpairs(stiffness, mass, 5)
    axis = intrinsic_axis(evals, evecs, mass.diagonal())
    m = mass.diagonal()
    assert np.all((axis.coordinate > 0) & (axis.coordinate < 1))
    assert np.sum(m * axis.coordinate) / m.sum() == pytest.approx(0.5, abs=1e-12)
    order = np.argsort(evecs[:, 1], kind="stable")
    assert np.all(np.diff(axis.coordinate[order]) > 0)
    # the sign of the eigenfunction only reverses the axis
    flipped = intrinsic_axis(evals, -evecs, m)
    assert np.allclose(flipped.coordinate, 1.0 - axis.coordinate, atol=1e-12)


def test_axis_is_invariant_to_vertex_order_scale_and_deformation():
    strip = rectangle(4.0, cells=(40, 10))
    shuffled = rectangle(4.0, cells=(40, 10), perm_seed=3)
    base, _ = axis_of(strip)
    other, _ = axis_of(shuffled)
    perm = np.random.default_rng(3).permutation(strip.n_vertices)
    same = other.coordinate[np.argsort(perm)]
    assert min(np.max(np.abs(same - base.coordinate)), np.max(np.abs(1 - same - base.coordinate))) < 1e-6
    # scale and a bend (an isometry of the plane strip into 3D) keep the axis
    theta = strip.vertices[:, 0] / 4.0 * np.pi  # roll the strip onto half a cylinder of radius 4/π
    r = 4.0 / np.pi
    bent = TriMesh(np.column_stack([r * np.sin(theta), strip.vertices[:, 1], r * (1 - np.cos(theta))]) * 7.0,
                   strip.faces)
    rolled, _ = axis_of(bent)
    assert min(np.max(np.abs(rolled.coordinate - base.coordinate)),
               np.max(np.abs(1 - rolled.coordinate - base.coordinate))) < 1e-3
    assert rolled.confidence == pytest.approx(base.confidence, abs=1e-3)


def test_axis_mismatch_and_errors():
    a, b = np.array([0.1, 0.5, 0.9]), np.array([0.0, 1.0])
    assert np.allclose(axis_mismatch(a, b), [[0.1, 0.9], [0.5, 0.5], [0.9, 0.1]])
    assert np.allclose(axis_mismatch(a, b, flipped=True), axis_mismatch(1 - a, b))
    with pytest.raises(ParameterError, match="at least 3 eigenvalues"):
        intrinsic_axis(np.array([0.0, 1.0]), np.ones((4, 2)), np.ones(4))
    with pytest.raises(ParameterError, match="connected"):
        intrinsic_axis(np.array([0.0, 0.0, 1.0]), np.ones((4, 3)), np.ones(4))
    with pytest.raises(ParameterError, match="evecs must be"):
        intrinsic_axis(np.array([0.0, 1.0, 2.0]), np.ones((5, 3)), np.ones(4))


def test_higher_modes_of_a_strip_and_their_confidence():
    """Neumann strip [0, 5] x [0, 1]: φ_2 = cos(2πx/5), not monotone, so its quantile is symmetric about the
    middle (x and L − x get the same value); λ_j ∝ j² gives the confidence 1 − max(1/4, 4/9) = 5/9 for mode 2.
    The axes of modes 1 .. 3 are the individual axes."""
    strip = rectangle(5.0)
    stiffness, mass = mesh_laplacian(strip)
    evals, evecs = eigenpairs(stiffness, mass, 6)
    second = intrinsic_axis(evals, evecs, mass.diagonal(), mode=2)
    assert second.confidence == pytest.approx(5 / 9, abs=0.01)
    x = strip.vertices[:, 0]
    mirror = np.lexsort((strip.vertices[:, 1], 5.0 - x))  # vertex at (5 − x, y), grid order
    original = np.lexsort((strip.vertices[:, 1], x))
    # equal up to the order within the tie: the two mirrored grid columns hold 2/61 of the area
    assert np.max(np.abs(second.coordinate[original] - second.coordinate[mirror])) <= 2 / 61 + 1e-9
    axes = spectral_axes(evals, evecs, mass.diagonal(), 3)
    assert [a.confidence for a in axes] == [intrinsic_axis(evals, evecs, mass.diagonal(), j).confidence
                                           for j in (1, 2, 3)]
    with pytest.raises(ParameterError, match="mode 4 needs at least 6"):
        intrinsic_axis(evals[:5], evecs[:, :5], mass.diagonal(), mode=4)
    with pytest.raises(ParameterError, match="mode must be"):
        intrinsic_axis(evals, evecs, mass.diagonal(), mode=0)


def test_two_axes_search_every_sign_reading():
    """axis_modes=2: the optimum is the lowest of the four sign readings of the two axes, each searched on
    its own, and the reported signs are the winner's."""
    contour, mesh = capsule_and_ellipse()
    params = Contour3DParams(n_contour=24, k=12, axis_modes=2, model="half")
    result = solve("contour3d", contour, mesh, n_contour=24, k=12, mesh_vertices=0, axis_modes=2, model="half")
    query, target = prepare_query(contour, params), prepare_mesh(mesh, params)
    scales = axis_scales(query, target, "half", 1.0, params)
    assert scales.shape == (2,)
    readings = [(a, b) for a in (False, True) for b in ((False, True) if scales[1] > 0 else (False,))]
    energies = {signs: solve_direction(query, target, mesh, params, signs).energy for signs in readings}
    best = min(energies, key=energies.get)
    assert result.energy == pytest.approx(energies[best], rel=1e-12)
    assert tuple(result.extras["axis_signs"][:len(best)]) == best


def capsule_and_ellipse():
    """An egg-shaped contour and a tapered capsule of elliptic section: no symmetry swaps the capsule's ends, so
    its left-right reflection (either plane through the long axis) keeps the long axis among the even functions
    (a capsule of revolution has every plane, and the one swapping the ends would take the axis away)."""
    capsule = trimesh.creation.capsule(height=3.0, radius=0.6, count=[16, 16])
    z = capsule.vertices[:, 2] - capsule.vertices[:, 2].mean()
    taper = 1.0 + 0.25 * z / np.abs(z).max()
    vertices = capsule.vertices * np.column_stack([taper, 0.8 * taper, np.ones_like(taper)])
    mesh = TriMesh(vertices, capsule.faces, name="capsule")
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    contour = Contour2D(np.column_stack([2.0 * np.cos(t), 0.5 * np.sin(t) * (1 + 0.4 * np.cos(t))]), name="egg")
    return contour, mesh


def solve_direction(query, target, mesh, params, signs, model="half", unit_model="half"):
    distances = feature_distances(query.model_features(model), target.features[model])
    unit = feature_distances(query.model_features(unit_model), target.features[unit_model]).mean()
    scales = axis_scales(query, target, model, unit, params)
    cost = distances + axis_cost(query, target, model, scales, signs)
    graph = product_graph(cost, query.points, target.vertices, mesh.adjacency, params, float(distances.mean()))
    return run(branch_and_bound(graph))


@pytest.mark.parametrize("energy", ["paper", "elastic"])
def test_both_axis_directions_are_solved_and_the_lower_energy_is_kept(energy):
    """One branch-and-bound over the graphs of both readings of the axis returns the optimum of the better
    one: compared with both directions solved independently."""
    contour, mesh = capsule_and_ellipse()
    one_axis = {"model": "half", "axis_modes": 1}
    params = Contour3DParams(n_contour=24, k=12, energy=energy, **one_axis)
    result = solve("contour3d", contour, mesh, n_contour=24, k=12, mesh_vertices=0, energy=energy, **one_axis)
    query, target = prepare_query(contour, params), prepare_mesh(mesh, params)
    as_is, reversed_ = (solve_direction(query, target, mesh, params, (f,)) for f in (False, True))
    assert axis_scales(query, target, "half", 1.0, params)[0] > 0.3  # the axis term is active
    assert result.energy == pytest.approx(min(as_is.energy, reversed_.energy), rel=1e-12)
    assert result.extras["axis_reversed"] == (reversed_.energy < as_is.energy)
    assert result.search.optimal
    assert result.search.lower_bound == pytest.approx(result.energy, rel=1e-12)
    # the axis term is what made the two differ; without it there is one search
    plain = solve("contour3d", contour, mesh, n_contour=24, k=12, mesh_vertices=0, energy=energy, axis_weight=0,
                  **one_axis)
    assert plain.extras["axis_reversed"] is False
    assert plain.energy < result.energy


def test_auto_model_keeps_the_lower_energy_of_both_shape_models():
    """model=auto searches the half-shape and the whole-surface readings (both axis directions each) at once:
    its optimum is the lowest of the four searched independently, in one unit (the whole model's)."""
    contour, mesh = capsule_and_ellipse()
    params = Contour3DParams(n_contour=24, k=12, model="auto", axis_modes=1)
    result = solve("contour3d", contour, mesh, n_contour=24, k=12, mesh_vertices=0, model="auto", axis_modes=1)
    query, target = prepare_query(contour, params), prepare_mesh(mesh, params)
    assert set(target.features) == {"whole", "half"}
    energies = {(model, flipped): solve_direction(query, target, mesh, params, (flipped,), model, "whole").energy
                for model in ("whole", "half") for flipped in (False, True)}
    best = min(energies, key=energies.get)
    assert result.energy == pytest.approx(energies[best], rel=1e-12)
    assert (result.extras["model"], result.extras["axis_reversed"]) == best
    assert result.search.optimal


@pytest.mark.parametrize("seeds", [(0, 1), (2, 3, 4), (5,)])
def test_union_branch_and_bound_equals_brute_force(seeds):
    """min over several tiny product graphs, each optimum from the explicitly built product graph."""
    from test_contour3d import explicit_product_optimum, tiny_graph

    exact = [explicit_product_optimum(tiny_graph(seed)) for seed in seeds]
    graphs = [tiny_graph(seed) for seed in seeds]
    result = run(branch_and_bound_union(graphs))
    assert result.energy == pytest.approx(min(exact), rel=1e-12)
    assert result.graph_index == int(np.argmin(exact))
    assert graphs[result.graph_index].path_energy(result.path) == pytest.approx(result.energy, rel=1e-12)
    assert result.lower_bound == pytest.approx(result.energy, rel=1e-12)
    approx = run(branch_and_bound_union([tiny_graph(seed) for seed in seeds], eps=0.2))
    assert min(exact) <= approx.energy <= 1.2 * min(exact) + 1e-12
    with pytest.raises(ParameterError, match="at least one"):
        run(branch_and_bound_union([]))


def test_paper_features_stay_selectable():
    contour, mesh = capsule_and_ellipse()
    wks_only = prepare_query(contour, Contour3DParams(n_contour=24, k=12))
    paper = prepare_query(contour, Contour3DParams(n_contour=24, k=12, features="paper"))
    assert wks_only.features.shape == (24, 100) and paper.features.shape == (24, 200)
    assert np.array_equal(paper.features[:, :100], wks_only.features)
    with pytest.raises(ParameterError, match="features"):
        solve("contour3d", contour, mesh, n_contour=24, k=12, mesh_vertices=0, features="hks")


def test_heuristics_computed_in_threads_equal_the_sequential_ones():
    """The backward searches of a union run on threads; each graph's heuristic is the one it computes alone."""
    import numba

    from corrlib.geometry.cyclic_paths import compute_heuristics
    from test_contour3d import tiny_graph

    alone = []
    for seed in range(4):
        graph = tiny_graph(seed)
        graph.compute_heuristic()
        alone.append(graph.heuristic.copy())
    graphs = [tiny_graph(seed) for seed in range(4)]
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
        compute_heuristics(graphs)
    finally:
        numba.set_num_threads(threads)
    for graph, expected in zip(graphs, alone):
        assert np.array_equal(graph.heuristic, expected)


def test_too_few_eigenpairs_for_the_axes_is_a_named_error():
    contour, mesh = capsule_and_ellipse()
    with pytest.raises(ParameterError, match="axis_modes=4 needs at least k=6 eigenpairs.*got k=5"):
        solve("contour3d", contour, mesh, n_contour=24, k=5, axis_modes=4)
    assert np.isfinite(solve("contour3d", contour, mesh, n_contour=24, k=6, axis_modes=4, model="whole").energy)
