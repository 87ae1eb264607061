"""Kernel matching stages on tiny meshes: the objective, the seed score and the DC step against dense forms."""

import numpy as np
import pytest
import scipy.linalg as sla
import trimesh

from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.methods.kernel_matching.dc import (
    MONOTONE_RTOL,
    SeedProblem,
    dc_objective,
    dc_step,
    free_assignment,
    seed_alignment,
    seed_score,
    updated_alignment,
)
from corrlib.methods.kernel_matching.multiscale import cell_centres, split_large_cells
from corrlib.methods.kernel_matching.scores import heat_decays, kernel_energy, most_similar_matches
from corrlib.methods.resolution import surplus_partners
from corrlib.shapes import TriMesh

TAU = 0.01  # relative time: t = τ · area ≈ 0.12 on the unit icosphere, decays from 1 to ~1e-4
#: a larger time for the DC steps: at TAU the kernels are so local that a random permutation is already a fixed
#: point (the diagonal K_Y(π_i, π_i) K_X(i, i) dominates its score)
TAU_DC = 0.05


def full_basis(mesh):
    """Every eigenpair of ``S φ = λ M φ`` (dense), the eigenvectors M-orthonormal."""
    stiffness, mass = mesh_laplacian(mesh)
    evals, evecs = sla.eigh(stiffness.toarray(), mass.toarray())
    return evals, evecs, stiffness, mass


def dense_heat_kernel(stiffness, mass, t):
    """(n, n) heat kernel values ``exp(-t M⁻¹ S) M⁻¹`` by a matrix exponential (no eigenvectors)."""
    m_inv = np.diag(1.0 / mass.diagonal())
    return sla.expm(-t * m_inv @ stiffness.toarray()) @ m_inv


@pytest.fixture(scope="module")
def pair():
    """Two different 42-vertex shapes (a sphere and an ellipsoid), full bases, dense heat kernels."""
    ico = trimesh.creation.icosphere(subdivisions=1)
    meshes = TriMesh(ico.vertices, ico.faces, name="x"), TriMesh(ico.vertices * [1.2, 1.0, 0.8], ico.faces, name="y")
    out = {}
    for key, mesh in zip("xy", meshes):
        evals, evecs, stiffness, mass = full_basis(mesh)
        out[key] = {"mesh": mesh, "evecs": evecs, "decay": heat_decays(evals, mesh.area, TAU),
                    "decay_dc": heat_decays(evals, mesh.area, TAU_DC),
                    "kernel": dense_heat_kernel(stiffness, mass, TAU * mesh.area)}
    return out


def permutation_matrix(map_xy, n_y):
    """(n_y, n_x) Π with Π[map_xy[i], i] = 1."""
    p = np.zeros((n_y, map_xy.size))
    p[map_xy, np.arange(map_xy.size)] = 1.0
    return p


def test_spectral_basis_gives_the_dense_heat_kernel(pair):
    for side in pair.values():
        spectral = (side["evecs"] * side["decay"]) @ side["evecs"].T
        np.testing.assert_allclose(spectral, side["kernel"], rtol=0, atol=1e-10 * np.abs(side["kernel"]).max())


def test_objective_in_spectral_form_equals_the_dense_form(pair):
    x, y = pair["x"], pair["y"]
    n = x["mesh"].n_vertices
    rng = np.random.default_rng(0)
    desc_block = -rng.random((n, n)).astype(np.float32)  # (x, y), like F_Y F_Xᵀ transposed
    for _ in range(3):
        map_xy = rng.permutation(n)
        p = permutation_matrix(map_xy, n)
        dense = float(np.sum(p * (y["kernel"] @ p @ x["kernel"])))  # <Π, K_Y Π K_X>
        c = y["evecs"][map_xy].T @ x["evecs"]
        assert kernel_energy(c, y["decay"], x["decay"]) == pytest.approx(dense, rel=1e-10)
        assert dc_objective(map_xy, c, 3.0, y["decay"], x["decay"]) == pytest.approx(0.5 * dense / 3.0, rel=1e-10)
        with_desc = 0.5 * dense / 3.0 + 0.25 * float(np.sum(p * desc_block.T.astype(np.float64)))
        assert dc_objective(map_xy, c, 3.0, y["decay"], x["decay"], desc_block, 0.25) == pytest.approx(with_desc,
                                                                                                      rel=1e-6)
    # not vacuous: a different map has a different value
    other = np.roll(map_xy, 1)
    c_other = y["evecs"][other].T @ x["evecs"]
    assert abs(kernel_energy(c_other, y["decay"], x["decay"]) - dense) > 1e-6 * abs(dense)


def test_seed_score_against_brute_force(pair):
    x, y = pair["x"], pair["y"]
    k_x, k_y = x["kernel"], y["kernel"]
    n = x["mesh"].n_vertices
    rng = np.random.default_rng(1)
    m = 15
    sx, sy = rng.choice(n, m, replace=False), rng.choice(n, m, replace=False)  # seeds at vertices
    ax, ay = np.array([0, 7]), np.array([3, 11])  # anchors (landmarks)
    seed_map = rng.permutation(m)
    desc_block = -rng.random((m, m)).astype(np.float32)
    problem = SeedProblem(x["evecs"][sx], y["evecs"][sy], y["evecs"][ay].T @ x["evecs"][ax], desc_block, 0.3)
    c = seed_alignment(problem, seed_map)
    # brute force: G[i, j] = Σ_matches K_Y(y_j, y_match) K_X(x_match, x_i), matches = seed pairs and anchors
    pairs = [(sx[a], sy[seed_map[a]]) for a in range(m)] + list(zip(ax, ay))
    brute = np.zeros((m, m))
    for i in range(m):
        for j in range(m):
            brute[i, j] = sum(k_y[sy[j], py] * k_x[px, sx[i]] for px, py in pairs)
    scale = np.abs(brute).max()
    g, found = seed_score(problem.phi_s, problem.psi_s, c, y["decay"], x["decay"], None, desc_block, 0.3)
    assert g.dtype == np.float32 and g.shape == (m, m)
    assert found == pytest.approx(scale, rel=1e-5)
    np.testing.assert_allclose(g, brute / scale + 0.3 * desc_block, rtol=0, atol=1e-5)
    # a given scale is kept; without descriptors the kernel term comes unscaled
    g2, kept = seed_score(problem.phi_s, problem.psi_s, c, y["decay"], x["decay"], 2.0 * scale, desc_block, 0.3)
    assert kept == 2.0 * scale
    np.testing.assert_allclose(g2, brute / (2.0 * scale) + 0.3 * desc_block, rtol=0, atol=1e-5)
    g3, _ = seed_score(problem.phi_s, problem.psi_s, c, y["decay"], x["decay"])
    np.testing.assert_allclose(g3, brute, rtol=0, atol=1e-5 * scale)


@pytest.mark.parametrize("n_changed", [0, 1, 7, 40])
def test_updated_alignment_equals_the_direct_product(n_changed):
    """C of a changed map from C of the old one, whatever the number of changed seeds (few: the changed
    terms exchanged; half or more: afresh), equals ``Ψ_s[map]ᵀ Φ_s + C_anchors`` formed directly."""
    rng = np.random.default_rng(n_changed)
    m, k = 60, 9
    problem = SeedProblem(rng.standard_normal((m, k)), rng.standard_normal((m, k)), rng.standard_normal((k, k)),
                          None, 0.0)
    old = rng.permutation(m)
    new = old.copy()
    moved = rng.choice(m, n_changed, replace=False)
    new[moved] = rng.permutation(new[moved]) if n_changed > 1 else new[moved]
    if n_changed == 1:  # a single seed moves onto another seed's partner (a map, not a permutation)
        new[moved] = old[(moved + 1) % m]
    c_old = seed_alignment(problem, old)
    updated = updated_alignment(problem, c_old, old, new)
    np.testing.assert_allclose(updated, seed_alignment(problem, new), rtol=0, atol=1e-12)
    if n_changed == 0:
        assert updated is c_old


def seed_problem_of(pair, mu, seed):
    x, y = pair["x"], pair["y"]
    n = x["mesh"].n_vertices
    desc = -np.random.default_rng(seed).random((n, n)).astype(np.float32) if mu > 0 else None
    return SeedProblem(x["evecs"], y["evecs"], 0.0, desc, mu)


@pytest.mark.parametrize("backend", ["scipy", "auction"])
@pytest.mark.parametrize("mu", [0.0, 0.05])
def test_dc_step_never_decreases_the_objective(pair, backend, mu):
    decay_y, decay_x = pair["y"]["decay_dc"], pair["x"]["decay_dc"]
    n = pair["x"]["mesh"].n_vertices
    rng = np.random.default_rng(2)
    changed = 0
    for trial in range(4):
        problem = seed_problem_of(pair, mu, trial)
        seed_map, scale, prices = rng.permutation(n), None, np.zeros(n)
        first = None
        for _ in range(6):
            step = dc_step(problem, seed_map, decay_y, decay_x, scale, prices=prices, backend=backend)
            # the step reports the objective of its input and of its output, at the same scale
            c = seed_alignment(problem, seed_map)
            assert step.before == dc_objective(seed_map, c, step.kernel_scale, decay_y, decay_x,
                                               problem.desc_block, mu)
            # the new map's C is updated from the old one (updated_alignment): equal up to round-off
            assert step.value == pytest.approx(dc_objective(step.seed_map, seed_alignment(problem, step.seed_map),
                                                            step.kernel_scale, decay_y, decay_x,
                                                            problem.desc_block, mu), rel=1e-12)
            np.testing.assert_allclose(step.alignment, seed_alignment(problem, step.seed_map), rtol=0,
                                       atol=1e-12 * np.abs(step.alignment).max())
            assert np.unique(step.seed_map).size == n
            assert step.value >= step.before - MONOTONE_RTOL * abs(step.before), (trial, step)
            assert not step.decreased
            first = step.before if first is None else first
            seed_map, scale = step.seed_map, step.kernel_scale
            changed += step.changed
        assert step.value > first  # from a random permutation, DC does climb
    assert changed > 0


def test_dc_linearisation_bounds_the_objective_from_below(pair):
    """Convexity, on which the DC guarantee rests: f(Q) ≥ f(P) + <Q - P, G(P)> for the seed score G."""
    decay_y, decay_x = pair["y"]["decay_dc"], pair["x"]["decay_dc"]
    n = pair["x"]["mesh"].n_vertices
    rng = np.random.default_rng(3)
    problem = seed_problem_of(pair, 0.05, 0)
    for _ in range(10):
        p_map, q_map = rng.permutation(n), rng.permutation(n)
        c_p = seed_alignment(problem, p_map)
        g, scale = seed_score(problem.phi_s, problem.psi_s, c_p, decay_y, decay_x, None, problem.desc_block, 0.05)
        f_p = dc_objective(p_map, c_p, scale, decay_y, decay_x, problem.desc_block, 0.05)
        f_q = dc_objective(q_map, seed_alignment(problem, q_map), scale, decay_y, decay_x, problem.desc_block, 0.05)
        rows = np.arange(n)
        linear = f_p + float(g[rows, q_map].astype(np.float64).sum() - g[rows, p_map].astype(np.float64).sum())
        assert f_q >= linear - 1e-5 * abs(f_p)


def test_dc_step_with_fixed_seeds_is_the_best_permutation_that_keeps_them(pair):
    """Seeds fixed by landmarks keep their partners; the free ones take the linear assignment's optimum over
    the permutations that keep the fixed ones (brute force over all 5! of them), so the objective still does
    not fall."""
    import itertools

    decay_y, decay_x = pair["y"]["decay_dc"], pair["x"]["decay_dc"]
    rng = np.random.default_rng(6)
    n = pair["x"]["mesh"].n_vertices
    problem = seed_problem_of(pair, 0.05, 1)
    fixed = rng.choice(n, n - 5, replace=False)
    free_x = np.setdiff1d(np.arange(n), fixed)
    seed_map = rng.permutation(n)
    free_y = np.sort(seed_map[free_x])
    restricted = SeedProblem(problem.phi_s, problem.psi_s, 0.0, problem.desc_block, 0.05, free_x, free_y)
    for _ in range(3):
        c = seed_alignment(problem, seed_map)
        g, scale = seed_score(problem.phi_s, problem.psi_s, c, decay_y, decay_x, None, problem.desc_block, 0.05)
        g_free, scale_free = seed_score(*restricted.free_blocks[:2], c, decay_y, decay_x, None,
                                        restricted.free_blocks[2], 0.05)
        step = dc_step(restricted, seed_map, decay_y, decay_x, scale_free, backend="scipy")
        np.testing.assert_array_equal(step.seed_map[fixed], seed_map[fixed])
        assert np.unique(step.seed_map).size == n
        best = max(itertools.permutations(free_y), key=lambda ys: float(
            sum(g_free[i, np.searchsorted(free_y, yj)] for i, yj in enumerate(ys))))
        np.testing.assert_array_equal(step.seed_map[free_x], best)
        assert step.value >= step.before - MONOTONE_RTOL * abs(step.before)
        # the free block is the whole score's block (up to the scale, the free rows' own maximum)
        np.testing.assert_allclose((g_free - 0.05 * problem.desc_block[np.ix_(free_x, free_y)]) * scale_free,
                                   (g[np.ix_(free_x, free_y)] - 0.05 * problem.desc_block[np.ix_(free_x, free_y)])
                                   * scale, rtol=0, atol=1e-5 * scale)
        seed_map = step.seed_map
    # nothing free: the map stays as it is, without an assignment
    none_free = SeedProblem(problem.phi_s, problem.psi_s, 0.0, None, 0.0, np.zeros(0, np.int64), np.zeros(0, np.int64))
    np.testing.assert_array_equal(free_assignment(none_free, seed_map, np.zeros((0, 0))), seed_map)


def test_dc_step_from_a_non_permutation_is_not_checked(pair):
    decay_y, decay_x = pair["y"]["decay_dc"], pair["x"]["decay_dc"]
    n = pair["x"]["mesh"].n_vertices
    problem = seed_problem_of(pair, 0.0, 0)
    step = dc_step(problem, np.zeros(n, dtype=np.int64), decay_y, decay_x, backend="scipy")
    assert not step.from_permutation and not step.decreased
    assert np.unique(step.seed_map).size == n


def test_most_similar_matches():
    confidence = np.array([0.1, 0.9, 0.5, 0.9, -1.0, 0.3, 0.7, 0.2, 0.0, 0.6])
    np.testing.assert_array_equal(most_similar_matches(confidence, 0.3), [1, 3, 6])  # ties: first index first
    np.testing.assert_array_equal(most_similar_matches(confidence, 0.01), [1])  # at least one
    assert most_similar_matches(confidence, 1.0).size == confidence.size


def test_cell_centres_are_distinct_and_move_between_passes():
    rng = np.random.default_rng(4)
    vertices = rng.normal(size=(200, 3))
    matched_x = rng.choice(200, 120, replace=False)
    matched_y = rng.integers(0, 60, 120)  # several matches share a target vertex
    passes = [cell_centres(vertices, matched_x, matched_y, 12, p) for p in range(2)]
    for centres_x, centres_y in passes:
        assert 1 <= centres_x.size <= 12
        assert np.unique(centres_x).size == centres_x.size and np.unique(centres_y).size == centres_y.size
        lookup = dict(zip(matched_x, matched_y))
        assert all(lookup[cx] == cy for cx, cy in zip(centres_x, centres_y))
    assert set(passes[0][0]) != set(passes[1][0])


def test_large_cells_are_split_until_none_exceeds_the_limit():
    """A bundled person cut by farthest points of its matched vertices: the first centres go to the
    extremities and leave the trunk to one cell; the split adds centres (matched pairs, distinct on both
    sides) until no cell holds more than the limit, and changes nothing where no cell does."""
    from corrlib.geometry.sampling import voronoi_cells
    from corrlib.io import load_mesh
    from corrlib.resources import resource

    mesh = load_mesh(resource("people/human0.off"))
    rng = np.random.default_rng(7)
    matched_x = np.arange(mesh.n_vertices)
    matched_y = rng.permutation(mesh.n_vertices)
    centres_x, centres_y = cell_centres(mesh.vertices, matched_x, matched_y, 5, 0)
    labels, _ = voronoi_cells(mesh, centres_x)
    limit = 1000
    assert np.bincount(labels).max() > 2 * limit  # not vacuous: the trunk is one cell
    split_x, split_y = split_large_cells(mesh, centres_x, centres_y, matched_x, matched_y, matched_x, limit)
    labels, _ = voronoi_cells(mesh, split_x)
    assert np.bincount(labels).max() <= limit
    np.testing.assert_array_equal(split_x[:centres_x.size], centres_x)
    assert np.unique(split_x).size == split_x.size and np.unique(split_y).size == split_y.size
    np.testing.assert_array_equal(matched_y[split_x], split_y)  # every centre is a matched pair
    same_x, same_y = split_large_cells(mesh, split_x, split_y, matched_x, matched_y, matched_x, limit)
    np.testing.assert_array_equal(same_x, split_x)


def test_surplus_vertices_take_the_partner_of_their_nearest_matched_vertex():
    """A source with more vertices than the target is sampled up to the target's count; every other vertex
    takes the partner of the matched sample vertex nearest to it on the edge graph (brute force: every
    shortest path; equidistant ones tie), the landmarks and unmatched samples keep theirs."""
    from scipy.sparse.csgraph import dijkstra

    sphere = trimesh.creation.icosphere(subdivisions=2)
    mesh = TriMesh(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(3)
    sampled = rng.choice(mesh.n_vertices, 40, replace=False)
    map_xy = -np.ones(mesh.n_vertices, dtype=np.int64)
    map_xy[sampled] = rng.permutation(100)[:sampled.size]  # distinct: a partner names its sample vertex
    map_xy[sampled[:3]] = -1  # left unmatched by a partial cell
    anchors = np.setdiff1d(np.arange(mesh.n_vertices), sampled)[:5]
    before = map_xy.copy()
    surplus_partners(mesh, map_xy, sampled, anchors)
    matched = sampled[3:]
    distances = dijkstra(mesh.adjacency, directed=False, indices=matched)  # (matched, n)
    rest = np.setdiff1d(np.arange(mesh.n_vertices), np.concatenate([sampled, anchors]))
    chosen = np.array([np.flatnonzero(before[matched] == partner)[0] for partner in map_xy[rest]])
    np.testing.assert_allclose(distances[chosen, rest], distances[:, rest].min(axis=0), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(map_xy[sampled], before[sampled])
    np.testing.assert_array_equal(map_xy[anchors], -1)  # set by the caller


def test_a_second_pass_reuses_the_descriptors_of_the_first():
    """The descriptors and the seeds' descriptor similarity depend on the shapes and the seeds only: a state
    prepared again for a second pass (:meth:`KernelState.prepared`) carries them instead of recomputing them,
    and its seed problem is the first one's."""
    from corrlib.methods.base import make_params
    from corrlib.methods.kernel_matching import KernelMatchingParams
    from corrlib.methods.kernel_matching.seed_stage import seed_problem
    from corrlib.methods.kernel_matching.state import prepare
    from corrlib.progress import CancelToken, run

    ico = trimesh.creation.icosphere(subdivisions=3)
    source = TriMesh(ico.vertices * [1.3, 1.0, 0.8], ico.faces, name="x")
    target = TriMesh(ico.vertices * [1.2, 1.1, 0.7], ico.faces, name="y")
    params = make_params(KernelMatchingParams, n_eigs=40, n_seeds=120, descriptor="wks")
    state = run(prepare(source, target, params, CancelToken()))
    first = seed_problem(state)
    assert first.desc_block is not None
    fresh = state.prepared()
    assert fresh.desc_x is state.desc_x and fresh.seed_similarity is state.seed_similarity
    second = seed_problem(fresh)
    assert second.desc_block is first.desc_block
    np.testing.assert_array_equal(second.phi_s, first.phi_s)
    # and the carried block is the one a state without it computes
    state.desc_x = state.desc_y = state.seed_similarity = None
    np.testing.assert_allclose(seed_problem(state).desc_block, first.desc_block, rtol=0, atol=0)
