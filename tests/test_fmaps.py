"""Functional maps: the quadratic energy and its operators (corrlib.geometry.fmaps, orientation operators)."""

import numpy as np
import pytest

from corrlib.descriptors.orientation import orientation_operators
from corrlib.geometry.fmaps import functional_map, multiplication_operators, pointwise_to_functional, resolvent_mask
from corrlib.geometry.spectrum import mesh_spectrum
from corrlib.io import load_mesh, load_vts
from corrlib.methods import solve
from corrlib.evaluation import evaluate
from corrlib.shapes import TriMesh

from _data import TOSCA


def _residual_rows(coef_x, coef_y, mask, operator_pairs, weights):
    """The energy as an explicit least-squares system ``‖R vec(C) − r‖²`` with every term scaled by
    the square root of its weight over its Hessian trace (an independent implementation)."""
    k_y, k_x = coef_y.shape[0], coef_x.shape[0]
    n = k_y * k_x
    blocks = []
    # descriptor preservation, entry (i, d): Σ_j C_ij A_jd − B_id
    rows = np.zeros((k_y * coef_x.shape[1], n))
    rhs = np.zeros(k_y * coef_x.shape[1])
    for i in range(k_y):
        for d in range(coef_x.shape[1]):
            rows[i * coef_x.shape[1] + d, i * k_x:(i + 1) * k_x] = coef_x[:, d]
            rhs[i * coef_x.shape[1] + d] = coef_y[i, d]
    blocks.append((rows, rhs))
    blocks.append((np.diag(np.sqrt(mask.ravel())), np.zeros(n)))
    for ops_x, ops_y in operator_pairs:
        rows = []
        for ox, oy in zip(ops_x, ops_y):
            # entry (i, j) of C X − Y C, column by column of the unit matrices E_ab
            op = np.zeros((n, n))
            for a in range(k_y):
                for b in range(k_x):
                    e = np.zeros((k_y, k_x))
                    e[a, b] = 1.0
                    op[:, a * k_x + b] = (e @ ox - oy @ e).ravel()
            rows.append(op)
        stacked = np.vstack(rows)
        blocks.append((stacked, np.zeros(stacked.shape[0])))
    system, target = [], []
    for w, (rows, rhs) in zip(weights, blocks):
        scale = np.sqrt(w / np.sum(rows ** 2))  # the trace of RᵀR is the squared Frobenius norm of R
        system.append(scale * rows)
        target.append(scale * rhs)
    return np.vstack(system), np.concatenate(target)


def test_functional_map_is_the_least_squares_minimiser():
    rng = np.random.default_rng(0)
    k_x, k_y, d = 5, 4, 7
    coef_x, coef_y = rng.normal(size=(k_x, d)), rng.normal(size=(k_y, d))
    mask = resolvent_mask(np.sort(rng.random(k_x)) * 10, np.sort(rng.random(k_y)) * 10)
    pairs = [(rng.normal(size=(3, k_x, k_x)), rng.normal(size=(3, k_y, k_y))),
             (rng.normal(size=(2, k_x, k_x)), rng.normal(size=(2, k_y, k_y)))]
    weights = (1.0, 0.3, 2.0, 0.7)
    c = functional_map(coef_x, coef_y, mask, pairs, weights)
    system, target = _residual_rows(coef_x, coef_y, mask, pairs, weights)
    reference = np.linalg.lstsq(system, target, rcond=None)[0].reshape(k_y, k_x)
    np.testing.assert_allclose(c, reference, rtol=1e-7, atol=1e-9)
    with pytest.raises(ValueError, match="weights"):
        functional_map(coef_x, coef_y, mask, pairs, (1.0, 1.0))


def test_commutator_gram_against_the_explicit_commutators():
    """The Gram matrix of ``Σ_d ‖C X_d − Y_d C‖²`` from Kronecker identities equals the one formed from the
    explicit commutator matrices ``I ⊗ X_dᵀ − Y_d ⊗ I`` (non-square C), and it is the quadratic form of the
    term."""
    from corrlib.geometry.fmaps import _commutator_gram

    rng = np.random.default_rng(1)
    k_x, k_y, d = 4, 3, 5
    ops_x, ops_y = rng.normal(size=(d, k_x, k_x)), rng.normal(size=(d, k_y, k_y))
    explicit = np.zeros((k_y * k_x, k_y * k_x))
    for op_x, op_y in zip(ops_x, ops_y):
        commutator = np.kron(np.eye(k_y), op_x.T) - np.kron(op_y, np.eye(k_x))
        explicit += commutator.T @ commutator
    gram = _commutator_gram(ops_x, ops_y)
    np.testing.assert_allclose(gram, explicit, rtol=1e-12, atol=1e-12)
    c = rng.normal(size=(k_y, k_x))
    energy = sum(np.linalg.norm(c @ op_x - op_y @ c) ** 2 for op_x, op_y in zip(ops_x, ops_y))
    assert c.ravel() @ gram @ c.ravel() == pytest.approx(energy, rel=1e-12)


def test_pointwise_to_functional_against_the_explicit_permutation_matrix():
    """``C_yx = Ψᵀ M_Y Π_yx Φ`` with Π built entry by entry (unmatched rows zero); the identity map of a
    shape onto itself gives the identity (M-orthonormal eigenfunctions), a sparse or a lumped mass alike."""
    import scipy.sparse as sp

    rng = np.random.default_rng(3)
    n_x, n_y, k = 9, 7, 4
    evecs_x, evecs_y = rng.standard_normal((n_x, k)), rng.standard_normal((n_y, k + 1))
    masses = rng.uniform(0.5, 2.0, n_y)
    map_yx = rng.integers(0, n_x, n_y)
    map_yx[[1, 4]] = -1
    permutation = np.zeros((n_y, n_x))
    permutation[np.flatnonzero(map_yx >= 0), map_yx[map_yx >= 0]] = 1.0
    expected = evecs_y.T @ np.diag(masses) @ permutation @ evecs_x
    assert np.allclose(pointwise_to_functional(map_yx, evecs_x, evecs_y, masses), expected)
    assert np.allclose(pointwise_to_functional(map_yx, evecs_x, evecs_y, sp.diags(masses)), expected)
    spectrum = mesh_spectrum(load_mesh(TOSCA / "wolf0.off"), 20)
    identity = pointwise_to_functional(np.arange(spectrum.evecs.shape[0]), spectrum.evecs, spectrum.evecs,
                                       spectrum.mass)
    assert np.allclose(identity, np.eye(20), atol=1e-8)


def test_resolvent_mask_vanishes_between_equal_eigenvalues_and_grows_apart():
    evals = np.array([0.0, 1.0, 4.0, 9.0])
    mask = resolvent_mask(evals, evals)
    np.testing.assert_allclose(np.diag(mask), 0.0, atol=1e-15)
    np.testing.assert_allclose(mask, mask.T)
    assert np.all(mask[0, 1:] > 0) and mask[0, 3] > mask[0, 1]


def test_operators_of_a_shape_to_itself():
    wolf = load_mesh(TOSCA / "wolf0.off")
    spectrum = mesh_spectrum(wolf, 20)
    mass = spectrum.mass.diagonal()
    ones = multiplication_operators(spectrum.evecs, mass, np.ones((wolf.n_vertices, 1)))
    np.testing.assert_allclose(ones[0], np.eye(20), atol=1e-8)  # multiplying by 1 is the identity
    f = spectrum.evecs[:, 1:4] ** 2
    ops = orientation_operators(wolf, spectrum.evecs, f)
    # n · (∇f × ∇g) integrated against h is skew in (g, h) on a closed surface (integration by parts)
    skew = np.linalg.norm(ops + ops.transpose(0, 2, 1)) / np.linalg.norm(ops)
    assert skew < 0.05, skew
    # a mirror image reverses the orientation: the operators change sign
    mirrored = TriMesh(wolf.vertices * [-1.0, 1.0, 1.0], wolf.faces, name="mirror")
    np.testing.assert_allclose(orientation_operators(mirrored, spectrum.evecs, f), -ops, atol=1e-9 * np.abs(ops).max())


@pytest.mark.slow
def test_fmap_zoomout_keeps_left_on_left_on_the_cats_and_their_mirror_image():
    """cat0 -> cat1 (remeshed independently): measured mean 0.023, 90 % within 0.05, the same error with the
    mirrored partner accepted; without the orientation term the map is the mirror image (0.22 direct).
    Matching cat0 to the mirror image of cat1 gives the mirrored map: its error against the mirrored
    ground truth is as small."""
    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    rows0, rows1, rows1_sym = (load_vts(TOSCA / f) for f in ("cat0.vts", "cat1.vts", "cat1.sym.vts"))
    direct = evaluate(solve("fmap-zoomout", cat0, cat1), cat1, rows0, rows1).summary()
    assert direct["mean"] < 0.05 and direct["within_0.05"] > 0.8, direct
    mirror = TriMesh(cat1.vertices * [-1.0, 1.0, 1.0], cat1.faces[:, ::-1], name="cat1-mirror")
    mirrored = evaluate(solve("fmap-zoomout", cat0, mirror), mirror, rows0, rows1_sym).summary()
    assert mirrored["mean"] < 0.05 and mirrored["within_0.05"] > 0.8, mirrored


def _scaled(mesh, factor: float) -> TriMesh:
    return TriMesh(mesh.vertices * factor, mesh.faces, name=f"{mesh.name}-x{factor:g}")


def test_unit_area_spectra_of_a_scaled_surface_are_equal(wolf_pair):
    """Scaling a surface by s multiplies its eigenvalues by 1/s² and its mass-orthonormal eigenvectors by 1/s;
    at unit area both spectra are the same (eigenvectors up to sign)."""
    wolf = wolf_pair[0]
    plain = mesh_spectrum(wolf, 30, use_cache=False)
    scaled = mesh_spectrum(_scaled(wolf, 1e3), 30, use_cache=False)
    assert np.allclose(scaled.evals[1:], plain.evals[1:] * 1e-6, rtol=1e-8)
    a, b = plain.at_unit_area(wolf.area), scaled.at_unit_area(wolf.area * 1e6)
    assert np.allclose(a.evals, b.evals, rtol=1e-8, atol=1e-10)
    signs = np.sign(np.sum(a.evecs * b.evecs, axis=0))
    assert np.allclose(a.evecs, b.evecs * signs, atol=1e-6)
    assert np.allclose(a.evecs.T @ (a.mass @ a.evecs), np.eye(30), atol=1e-8)  # orthonormal at unit area
    assert np.isclose(a.mass.diagonal().sum(), 1.0)


def test_pointwise_steps_do_not_depend_on_the_shapes_sizes(wolf_pair):
    """The final ZoomOut steps of wolf0 → wolf1 from a noisy map give the same maps with wolf1 in other units
    (millimetres against metres); unscaled bases would compare images off by the ratio of the areas."""
    from corrlib.geometry.fmaps import pointwise_from_basis, repeated_pointwise_from_basis

    x, y = wolf_pair
    rng = np.random.default_rng(3)
    noisy = np.where(rng.random(x.n_vertices) < 0.2, rng.integers(0, y.n_vertices, x.n_vertices),
                     np.arange(x.n_vertices))
    spec_x = mesh_spectrum(x, 60)
    results = []
    for factor in (1.0, 1e3, 1e-3):
        target = _scaled(y, factor)
        spec_y = mesh_spectrum(target, 60)
        one = pointwise_from_basis(noisy, noisy.copy(), spec_x, spec_y, 40)
        repeated = repeated_pointwise_from_basis(noisy, noisy.copy(), spec_x, spec_y, 40, x.adjacency,
                                                 target.adjacency)
        results.append((one, repeated))
    for one, repeated in results[1:]:
        assert np.mean(one[0] == results[0][0][0]) > 0.995 and np.mean(repeated[0] == results[0][1][0]) > 0.995
    def offset(m):  # mean distance to the true partner (the wolves share their vertex order)
        return np.linalg.norm(y.vertices[m] - y.vertices, axis=1).mean() / np.sqrt(y.area)

    assert offset(results[0][1][0]) < 0.2 * offset(noisy)  # and the steps correct the noise


def test_zoomout_both_ways_rebuilds_a_map_from_its_low_frequencies(wolf_pair):
    """wolf0 → wolf1 (one vertex order: the truth is the identity) with 40 % of the partners, in both
    directions, replaced by random vertices: the functional map on the first 20 eigenfunctions still holds
    the truth (the random rows only shrink it), and ZoomOut to 60 rebuilds the map from it; rows without a
    partner stay without one."""
    from corrlib.geometry.fmaps import zoomout_both_ways

    x, y = wolf_pair
    n = x.n_vertices
    rng = np.random.default_rng(5)
    truth = np.arange(n)
    noisy_xy = np.where(rng.random(n) < 0.4, rng.integers(0, n, n), truth)
    noisy_yx = np.where(rng.random(n) < 0.4, rng.integers(0, n, n), truth)
    noisy_xy[:7] = -1
    spec_x, spec_y = mesh_spectrum(x, 60), mesh_spectrum(y, 60)
    map_xy, map_yx = zoomout_both_ways(noisy_xy, noisy_yx, spec_x, spec_y, 20, 60, 5)
    assert np.all(map_xy[:7] == -1) and np.all(map_xy[7:] >= 0) and np.all(map_yx >= 0)

    def offset(m, shape):  # mean distance of the matched rows to their true partners, per √area
        rows = np.flatnonzero(m >= 0)
        return np.linalg.norm(shape.vertices[m[rows]] - shape.vertices[rows], axis=1).mean() / np.sqrt(shape.area)

    assert offset(map_xy, y) < 0.02 < 0.15 < offset(noisy_xy, y)  # 40 % of the rows about 0.5 off
    assert offset(map_yx, x) < 0.02 < 0.15 < offset(noisy_yx, x)


@pytest.mark.parametrize("method", ["fmap-zoomout", "descriptor-nn"])
def test_baselines_match_a_pair_in_different_units_as_the_same_pair(wolf_pair, method):
    """wolf1 in millimetres against wolf0 in metres: the spectra are taken at unit area, so the descriptors,
    the functional map and its nearest neighbours are those of the pair in one unit (before, the functional
    map of wolf0 → wolf1 × 1000 was random: 0.49 √area on the cats)."""
    x, y = wolf_pair
    plain = solve(method, x, y).map_xy
    scaled = solve(method, x, _scaled(y, 1e3)).map_xy
    assert np.mean(plain == scaled) > 0.995
    if method == "fmap-zoomout":  # and that map is the wolves' identity up to a few near misses
        assert np.linalg.norm(y.vertices[plain] - y.vertices, axis=1).mean() < 0.01 * np.sqrt(y.area)


def test_a_zoomout_that_would_shrink_the_map_is_refused():
    """k_init above k_final was accepted and quietly solved a 2 × 2 map (mean error 0.46 on the cats)."""
    from corrlib.errors import ParameterError
    from corrlib.methods.base import make_params
    from corrlib.methods.baselines import FmapZoomOutParams

    with pytest.raises(ParameterError, match=r"k_init \(60\) must not exceed k_final \(2\)"):
        make_params(FmapZoomOutParams, k_init=60, k_final=2)
    with pytest.raises(ParameterError, match="k_init = 200 is above its maximum 80"):  # 12 GB of normal matrices
        make_params(FmapZoomOutParams, k_init=200, k_final=300)
    assert make_params(FmapZoomOutParams, k_init=30, k_final=30).k_final == 30


def test_a_zoomout_beyond_the_meshes_says_where_it_stopped():
    """k_final above what the meshes give is capped (a default must run on small meshes), and said so: the
    result had a smaller functional map than asked without a word."""
    import trimesh

    sphere = trimesh.creation.icosphere(2)
    x = TriMesh(sphere.vertices, sphere.faces, name="ball")
    y = TriMesh(sphere.vertices * [1.0, 1.3, 0.8], sphere.faces, name="egg")
    reports = []
    result = solve("fmap-zoomout", x, y, k_final=700, callback=reports.append)
    assert result.extras["k_final"] == x.n_vertices - 1
    assert any(f"ZoomOut up to {x.n_vertices - 1} eigenfunctions, not k_final = 700" in r.message for r in reports)


def _samples_of_every_vertex(mesh, mass):
    """ZoomOutSamples holding every vertex (each its own cell): the sampled path must then be the exact one."""
    from corrlib.geometry.fmaps import ZoomOutSamples

    graph = mesh.adjacency
    return ZoomOutSamples(np.arange(mesh.n_vertices), np.arange(mesh.n_vertices), np.asarray(mass, dtype=float),
                          graph.indptr, graph.indices)


def test_sampled_zoomout_on_every_vertex_is_zoomout_itself():
    """With every vertex a sample of its own cell, the weighted least-squares functional map is
    ``Ψᵀ M Π Φ`` (``Ψᵀ M Ψ = I``): the same maps and functional map as the full iteration."""
    from corrlib.geometry.fmaps import zoomout

    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    spec_x, spec_y = mesh_spectrum(cat0, 40), mesh_spectrum(cat1, 40)
    c_init = np.eye(10)

    def finish(gen):
        while True:
            try:
                next(gen)
            except StopIteration as stop:
                return stop.value

    exact_map, exact_c = finish(zoomout(spec_x.evecs, spec_y.evecs, spec_y.mass, c_init, 40, 10))
    every_x = _samples_of_every_vertex(cat0, spec_x.mass.diagonal())
    every_y = _samples_of_every_vertex(cat1, spec_y.mass.diagonal())
    sampled_map, sampled_c = finish(zoomout(spec_x.evecs, spec_y.evecs, spec_y.mass, c_init, 40, 10,
                                            samples_x=every_x, samples_y=every_y))
    assert np.allclose(sampled_c, exact_c, atol=1e-8)
    assert np.array_equal(sampled_map, exact_map)


def test_nearest_rows_through_samples_against_brute_force():
    """On a smooth embedding (eigenfunctions of a 20k-vertex cat) the search through 1,000 samples finds the
    brute-force nearest row or one as near a few vertices away; given the brute-force rows as current partners
    it keeps rows at least as near as those (it returns the nearer of its two descents)."""
    import trimesh
    from scipy.spatial import cKDTree

    from corrlib.geometry.fmaps import ZoomOutSamples, nearest_rows_through_samples
    from corrlib.neighbours import nearest_rows

    cat0, cat1 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off")
    fine = [TriMesh(*trimesh.remesh.subdivide(m.vertices, m.faces)) for m in (cat0, cat1)]
    gt0, gt1 = load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat1.vts")  # vertices kept first by subdivision
    spec_x, spec_y = mesh_spectrum(cat0, 30), mesh_spectrum(cat1, 30)
    def embedded(mesh, fine_mesh, spec):
        """A smooth embedding of the fine mesh: the coarse eigenfunctions, linear along the split edges."""
        rows = np.zeros((fine_mesh.n_vertices, 30))
        rows[:mesh.n_vertices] = spec.evecs
        edges = mesh.edges  # subdivision adds one midpoint per edge: find each midpoint's edge by position
        midpoints = fine_mesh.vertices[mesh.n_vertices:]
        centre = 0.5 * (mesh.vertices[edges[:, 0]] + mesh.vertices[edges[:, 1]])
        which = cKDTree(centre).query(midpoints)[1]
        rows[mesh.n_vertices:] = 0.5 * (spec.evecs[edges[which, 0]] + spec.evecs[edges[which, 1]])
        return rows
    query, data = embedded(cat0, fine[0], spec_x), embedded(cat1, fine[1], spec_y)
    # align the second embedding to the first with the ground truth's functional map (signs and mixing)
    c = np.linalg.lstsq(data[gt1], query[gt0], rcond=None)[0]
    data = data @ c
    samples_q = ZoomOutSamples.of(fine[0], np.ones(fine[0].n_vertices), 1000)
    samples_d = ZoomOutSamples.of(fine[1], np.ones(fine[1].n_vertices), 1000)
    exact = nearest_rows(query, data)
    found = nearest_rows_through_samples(query, data, samples_q, samples_d)
    excess = np.linalg.norm(query - data[found], axis=1) - np.linalg.norm(query - data[exact], axis=1)
    apart = np.linalg.norm(fine[1].vertices[found] - fine[1].vertices[exact], axis=1) / np.sqrt(fine[1].area)
    # near-ties of a coarse embedding: another row, but as near (within 1 %) and a few vertices away
    assert np.mean(excess) < 0.01 * np.mean(np.linalg.norm(query - data[exact], axis=1))
    assert np.mean(apart) < 0.01 and np.mean(found == exact) > 0.6
    kept = nearest_rows_through_samples(query, data, samples_q, samples_d, current=exact)
    # the brute force's minimum is a local one, so its descent stays there, or finds a row nearer in float64
    # (the brute force compares in float32)
    assert np.all(np.linalg.norm(query - data[kept], axis=1) <= np.linalg.norm(query - data[exact], axis=1) + 1e-12)
    assert np.mean(kept == exact) > 0.99


def test_zoomout_samples_of_a_pair_and_of_one_mesh_asked_twice():
    """Samples go to a pair only where both meshes are finer than twice the count (a search uses them only
    then); one mesh's samples are computed once (read-only arrays, shared) and the weights follow the masses."""
    from corrlib.geometry.fmaps import ZoomOutSamples

    cat0, wolf0 = load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "wolf0.off")
    ones_cat, ones_wolf = np.ones(cat0.n_vertices), np.ones(wolf0.n_vertices)
    assert ZoomOutSamples.of_pair(cat0, wolf0, ones_cat, ones_wolf, 2500) == (None, None)  # cat0 at 5,000
    first, second = ZoomOutSamples.of_pair(cat0, wolf0, ones_cat, ones_wolf, 1000)
    assert first.index.size == second.index.size == 1000
    again = ZoomOutSamples.of(cat0, 2 * ones_cat, 1000)
    assert again.index is first.index and again.owner is first.owner and not again.index.flags.writeable
    assert np.allclose(again.weight, 2 * first.weight)


def test_zoomout_samples_are_none_for_a_mesh_at_the_budget_and_cover_a_finer_one():
    from corrlib.geometry.fmaps import ZoomOutSamples

    cat0 = load_mesh(TOSCA / "cat0.off")
    mass = np.ones(cat0.n_vertices)
    assert ZoomOutSamples.of(cat0, mass, cat0.n_vertices) is None
    samples = ZoomOutSamples.of(cat0, mass, 500)
    assert samples.index.shape == (500,) and np.unique(samples.index).size == 500
    assert samples.owner.shape == (cat0.n_vertices,) and samples.owner.min() >= 0 and samples.owner.max() < 500
    assert np.array_equal(samples.owner[samples.index], np.arange(500))  # a sample lies in its own cell
    assert samples.weight.sum() == pytest.approx(cat0.n_vertices)  # every vertex's mass in exactly one cell


@pytest.mark.slow
def test_zoomout_through_samples_on_a_finer_pair_is_as_accurate_as_on_every_vertex(monkeypatch):
    """The cats subdivided to 20k vertices (the `.vts` rows still hold: subdivision keeps the vertices
    first): ``fmap-zoomout`` iterating on 5,000 samples, and the final repeated steps searching through them,
    are within 5 % of the same computations over every pair of vertices (which take several times longer)."""
    import trimesh

    from corrlib.evaluation import geodesic_errors
    from corrlib.geometry import fmaps

    fine = [TriMesh(*trimesh.remesh.subdivide(m.vertices, m.faces), name=f"{m.name}-fine")
            for m in (load_mesh(TOSCA / "cat0.off"), load_mesh(TOSCA / "cat1.off"))]
    gt0, gt1 = load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat1.vts")

    def error(map_xy):
        return geodesic_errors(map_xy, fine[1], gt0, gt1).summary()["mean"]

    sampled = solve("fmap-zoomout", *fine)
    spec_x, spec_y = mesh_spectrum(fine[0], 100), mesh_spectrum(fine[1], 100)
    through = fmaps.ZoomOutSamples.of(fine[0], spec_x.mass.diagonal()), fmaps.ZoomOutSamples.of(
        fine[1], spec_y.mass.diagonal())
    assert through[0] is not None and through[0].index.size == fmaps.ZOOMOUT_SAMPLES
    steps_sampled = fmaps.repeated_pointwise_from_basis(sampled.map_xy, sampled.map_yx, spec_x, spec_y, 100,
                                                        fine[0].adjacency, fine[1].adjacency, None, *through)
    steps_exact = fmaps.repeated_pointwise_from_basis(sampled.map_xy, sampled.map_yx, spec_x, spec_y, 100,
                                                      fine[0].adjacency, fine[1].adjacency)
    monkeypatch.setattr(fmaps.ZoomOutSamples, "of", classmethod(lambda cls, *args, **kwargs: None))
    exact = solve("fmap-zoomout", *fine)
    assert error(sampled.map_xy) <= 1.05 * error(exact.map_xy) and error(exact.map_xy) < 0.03
    assert error(steps_sampled[0]) <= 1.05 * error(steps_exact[0])
