"""Kernel matching: DC theory on brute-force instances, real shapes, invariance, refinement, bad input."""

import itertools

import numpy as np
import pytest
import trimesh

from corrlib.assignment import linear_assignment
from corrlib.errors import InputError, MeshError, ParameterError
from corrlib.evaluation import geodesic_errors
from corrlib.methods import solve
from corrlib.methods.base import InitialMatch
from corrlib.shapes import TriMesh


def random_psd(rng, n):
    a = rng.normal(size=(n, n))
    return a @ a.T / n


def qap_value(perm_matrix, k_y, k_x):
    return float(np.sum(perm_matrix * (k_y @ perm_matrix @ k_x)))


def perm_matrix(perm):
    p = np.zeros((perm.size, perm.size))
    p[perm, np.arange(perm.size)] = 1.0  # column x -> row perm[x]
    return p


@pytest.mark.parametrize("n", [4, 5, 6])
def test_relaxation_optimum_is_a_permutation_and_dc_is_monotone(n):
    rng = np.random.default_rng(n)
    for _ in range(5):
        k_x, k_y = random_psd(rng, n), random_psd(rng, n)
        best = max(qap_value(perm_matrix(np.array(p)), k_y, k_x) for p in itertools.permutations(range(n)))
        # Corollary 2: a convex function on the Birkhoff polytope is maximal at a vertex (a permutation)
        for _ in range(300):
            d = rng.random((n, n)) + 1e-3
            for _ in range(200):  # Sinkhorn: doubly stochastic
                d /= d.sum(axis=0, keepdims=True)
                d /= d.sum(axis=1, keepdims=True)
            assert qap_value(d, k_y, k_x) <= best + 1e-9
        # DC: each linear assignment on the gradient never decreases the objective
        perm = rng.permutation(n)
        values = [qap_value(perm_matrix(perm), k_y, k_x)]
        for _ in range(10):
            grad = k_y @ perm_matrix(perm) @ k_x
            perm = linear_assignment(grad.T)  # x -> y
            values.append(qap_value(perm_matrix(perm), k_y, k_x))
        assert np.all(np.diff(values) >= -1e-10)
        assert values[-1] <= best + 1e-9


@pytest.fixture(scope="module")
def wolf_result(wolf_pair):
    return solve("kernel-matching", *wolf_pair)


@pytest.mark.slow
def test_wolf_recovers_the_identity(wolf_pair, wolf_result):
    wolf0, wolf1 = wolf_pair
    ident = np.arange(wolf0.n_vertices)
    err = geodesic_errors(wolf_result.map_xy, wolf1, ident, ident).summary()
    assert err["within_0.025"] >= 0.99, err  # measured 99.9 % (98 % with one final ZoomOut step)
    err_yx = geodesic_errors(wolf_result.map_yx, wolf0, ident, ident).summary()
    assert err_yx["within_0.025"] >= 0.9, err_yx
    assert wolf_result.extras["monotone"]
    assert wolf_result.extras["unmatched_x"] == 0 and wolf_result.extras["unmatched_y"] == 0


def test_energy_trace_never_decreases_within_a_time(wolf_result):
    energy = wolf_result.energy_trace
    taus = wolf_result.extras["tau_trace"]
    for tau in np.unique(taus):
        e = energy[taus == tau]
        assert np.all(np.diff(e) >= -1e-5 * np.abs(e).max())


@pytest.mark.slow
def test_cat_pair_with_symmetric_ground_truth(cat_pair):
    cat0, cat1, gt = cat_pair
    result = solve("kernel-matching", cat0, cat1)
    report = geodesic_errors(result.map_xy, cat1, gt["cat0"], gt["cat1"], gt_target_sym=gt["cat1.sym"]).summary()
    # cat0/cat1 are remeshed independently and not quite isometric. Measured with the defaults: mean 0.020 and
    # 94.5 % of points within 0.05 (symmetric), 100 % within 0.1 (91.5 % with one final ZoomOut step instead
    # of the repeated one, 88.8 % before that step); the first issue's target was 80 %, issue 19 keeps 87 % as
    # the floor of any speed change. (With seeds at vertices instead of surface points: 77 %.)
    assert report["mean_sym"] <= 0.023, report
    assert report["within_0.05_sym"] >= 0.92, report
    assert report["within_0.1_sym"] >= 0.99, report
    # left matched to left everywhere (orientation-aware initialisation, initial alignment from the most similar
    # matches as a second start): the same without symmetry. With the first start only (init_fraction=1) the
    # front legs end swapped (77 % without symmetry, 84 % with, measured with 3000 seeds); without the
    # orientation features 44 % / 87 %.
    assert report["mean"] <= 0.023, report
    assert report["within_0.05"] >= 0.92, report
    back = solve("kernel-matching", cat1, cat0)  # the other direction: mean 0.0204, 93.0 % (one step: 91.6 %)
    back_report = geodesic_errors(back.map_xy, cat0, gt["cat1"], gt["cat0"]).summary()
    assert back_report["mean"] <= 0.023 and back_report["within_0.05"] >= 0.92, back_report
    assert result.extras["start"] == "initial alignment"  # the second start wins here (see above)


@pytest.mark.slow
def test_mirror_image_of_the_target_gives_the_mirrored_map(cat_pair):
    """cat0 -> the mirror image of cat1 (x -> -x, faces reversed): an orientation-keeping map sends left to
    the mirror image's left, which is cat1's mirrored partner, so it is scored against cat1.sym.vts and must be
    as good as cat0 -> cat1. Measured 0.030 (cat0 -> cat1: 0.029). The synthetic people of
    ``tests/_humanoid.py`` still fail this (docs/decisions.md)."""
    cat0, cat1, gt = cat_pair
    mirror = TriMesh(cat1.vertices * [-1.0, 1.0, 1.0], cat1.faces[:, ::-1], name="cat1-mirror")
    result = solve("kernel-matching", cat0, mirror)
    report = geodesic_errors(result.map_xy, mirror, gt["cat0"], gt["cat1.sym"], gt_target_sym=gt["cat1"]).summary()
    assert report["mean"] <= 0.035 and report["within_0.05"] >= 0.83, report
    assert report["mean"] <= 1.3 * report["mean_sym"], report


def test_area_capacities_andsample_masses(cat_pair):
    from corrlib.geometry.laplacian import mass_matrix
    from corrlib.assignment import area_capacities
    from corrlib.methods.kernel_matching.state import sample_masses

    cat1 = cat_pair[1]
    areas = mass_matrix(cat1.vertices, cat1.faces).diagonal()
    everything = np.random.default_rng(0).permutation(cat1.n_vertices)
    np.testing.assert_array_equal(sample_masses(cat1, areas, everything), areas[everything])
    sample = everything[:700]
    masses = sample_masses(cat1, areas, sample)
    assert masses.sum() == pytest.approx(cat1.area) and np.all(masses > 0)
    caps = area_capacities(1000, masses)
    share = 1000 * masses / masses.sum()
    assert np.all(caps >= share - 1e-9) and np.all(caps < share + 1) and np.all(caps >= 1)
    assert caps.sum() >= 1000


def test_bijective_cells_option(wolf_pair):
    wolf0, wolf1 = wolf_pair
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    result = solve("kernel-matching", wolf0, wolf1, capacity="one", cell_overlap=0.0, smooth_k=0, **fast)
    # a bijection within every cell (the final ZoomOut step, off here, is not one); a source cell larger than
    # its transferred target cell leaves a few rows to their best-scoring partner (measured: 97.5 % distinct
    # targets)
    assert np.unique(result.map_xy).size >= 0.95 * wolf0.n_vertices
    ident = np.arange(wolf0.n_vertices)
    assert geodesic_errors(result.map_xy, wolf1, ident, ident).summary()["within_0.05"] > 0.9


@pytest.mark.slow
def test_result_does_not_depend_on_vertex_order(wolf_pair):
    wolf0, wolf1 = wolf_pair
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    base = solve("kernel-matching", wolf0, wolf1, **fast)
    perm = np.random.default_rng(4).permutation(wolf1.n_vertices)
    inv = np.argsort(perm)
    shuffled = TriMesh(wolf1.vertices[perm], inv[wolf1.faces], name="shuffled")
    other = solve("kernel-matching", wolf0, shuffled, **fast)
    assert np.mean(perm[other.map_xy] == base.map_xy) > 0.97


@pytest.mark.slow
def test_refinement_of_a_noisy_map_and_of_landmarks(wolf_pair):
    wolf0, wolf1 = wolf_pair
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    rng = np.random.default_rng(5)
    noisy = np.arange(wolf0.n_vertices)
    bad = rng.random(noisy.size) < 0.3
    noisy[bad] = rng.integers(0, wolf1.n_vertices, bad.sum())
    ident = np.arange(wolf0.n_vertices)
    before = geodesic_errors(noisy, wolf1, ident, ident).summary()["within_0.025"]
    refined = solve("kernel-matching", wolf0, wolf1, initial=InitialMatch(map_xy=noisy), **fast)
    after = geodesic_errors(refined.map_xy, wolf1, ident, ident).summary()["within_0.025"]
    assert before < 0.75 and after > 0.9
    assert refined.extras["monotone"]
    landmarks = rng.choice(wolf0.n_vertices, 15, replace=False)
    from_landmarks = solve("kernel-matching", wolf0, wolf1, initial=InitialMatch(landmarks_x=landmarks,
                                                                                 landmarks_y=landmarks), **fast)
    # the start from the landmarks' kernel score alone (measured 99.5 %; from the nearest landmarks' partners
    # alone: 83 %)
    assert geodesic_errors(from_landmarks.map_xy, wolf1, ident, ident).summary()["within_0.05"] > 0.97
    # landmarks stay matched (without the final ZoomOut step, which moves every vertex to its nearest partner
    # in the basis); many of them fix seeds, whose neighbours the assignments place around them
    many = rng.choice(wolf0.n_vertices, 1500, replace=False)
    partners = rng.permutation(many)  # wrong on purpose: kept all the same
    kept = solve("kernel-matching", wolf0, wolf1, initial=InitialMatch(landmarks_x=many, landmarks_y=partners),
                 smooth_k=0, **fast)
    np.testing.assert_array_equal(kept.map_xy[many], partners)
    assert np.all(kept.map_xy >= 0)
    # right landmarks on 30 % of the vertices: the rest is placed from them
    rest = np.setdiff1d(ident, many)
    placed = solve("kernel-matching", wolf0, wolf1, initial=InitialMatch(landmarks_x=many, landmarks_y=many),
                   smooth_k=0, **fast)
    assert geodesic_errors(placed.map_xy, wolf1, rest, rest).summary()["within_0.05"] > 0.97


@pytest.mark.slow
def test_the_better_of_the_two_starts_goes_on(wolf_pair):
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    single = solve("kernel-matching", *wolf_pair, init_fraction=1.0, **fast)
    double = solve("kernel-matching", *wolf_pair, **fast)
    assert single.extras["start"] == "initial map"
    assert double.extras["start"] in ("initial map", "initial alignment")

    def first_time_objective(result):  # the objective after the DC iterations of the first (largest) time
        taus = result.extras["tau_trace"]
        return result.energy_trace[taus == taus[0]][-1]

    # both runs share the first start and its scale; the second start only replaces it when it ends higher
    assert first_time_objective(double) >= first_time_objective(single)
    if double.extras["start"] == "initial map":
        np.testing.assert_array_equal(double.map_xy, single.map_xy)


@pytest.mark.slow
def test_partial_shape_and_unequal_sizes(wolf_pair):
    wolf0, wolf1 = wolf_pair
    # the front 60 % of wolf1 (a partial shape with boundary) against the whole wolf0
    axis = np.linalg.svd(wolf1.vertices - wolf1.vertices.mean(0), full_matrices=False)[2][0]
    coord = (wolf1.vertices - wolf1.vertices.mean(0)) @ axis
    keep_face = np.all(coord[wolf1.faces] > np.quantile(coord, 0.4), axis=1)
    part = TriMesh.from_arrays(wolf1.vertices, wolf1.faces[keep_face], largest_component=True)
    assert part.n_vertices < wolf0.n_vertices
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    result = solve("kernel-matching", part, wolf0, **fast)
    truth = part.original_indices
    err = geodesic_errors(result.map_xy, wolf0, np.arange(part.n_vertices), truth).summary()
    # a cut changes the heat kernels near the cut (Neumann boundary): measured 62 % within 0.1 (random
    # partners: ~5 %), so only a loose threshold; partial shapes are the hard case of this method
    assert err["within_0.1"] > 0.5, err
    assert np.all(result.map_xy >= 0)
    partial = solve("kernel-matching", part, wolf0, partial=True, **fast)
    assert partial.extras["unmatched_y"] > 0.2 * wolf0.n_vertices  # most of the missing back stays unmatched


@pytest.mark.slow
def test_a_target_at_half_the_resolution(wolf_pair, wolf1_half):
    """wolf0 (4,344 vertices) against wolf1 decimated to half its vertices: every target vertex would take two
    source vertices under capacities with little rounding slack, where the matches drifted (0.018–0.027,
    docs/decisions.md); the source is sampled up to the target's count (measured 0.0071; the functional-map
    baseline 0.0096)."""
    wolf0, (target, truth) = wolf_pair[0], wolf1_half
    result = solve("kernel-matching", wolf0, target)
    assert np.all(result.map_xy >= 0) and np.all(result.map_yx >= 0)
    err = geodesic_errors(result.map_xy, target, np.arange(wolf0.n_vertices), truth).summary()
    assert err["mean"] < 0.012, err


@pytest.mark.slow
def test_a_source_at_a_quarter_of_the_resolution(wolf_pair):
    """wolf0 decimated to a quarter of its vertices against wolf1: every source vertex is a seed, so its partner
    is a target sample and sits about one target edge off; the final step's functional map from the map
    alone carried that offset (mean 0.0188, median 0.0168, measured), with the reverse map's estimate
    averaged in it is 0.0142 (`fmap-zoomout` 0.0104). Both directions are checked."""
    from scipy.spatial import cKDTree

    from conftest import decimated

    wolf0, wolf1 = wolf_pair
    source, nearest = decimated(wolf0, 0.25, "wolf0-quarter")
    truth = cKDTree(wolf0.vertices).query(source.vertices)[1]  # wolf0 and wolf1 share their vertex order
    result = solve("kernel-matching", source, wolf1)
    err = geodesic_errors(result.map_xy, wolf1, np.arange(source.n_vertices), truth).summary()
    assert err["mean"] < 0.016 and err["median"] < 0.014, err
    err_yx = geodesic_errors(result.map_yx, source, np.arange(wolf1.n_vertices), nearest).summary()
    assert err_yx["mean"] < 0.016, err_yx


@pytest.mark.slow
def test_a_source_at_half_the_resolution_in_another_pose(cat_pair):
    """cat0 decimated to half its vertices against cat1 (rearing, remeshed independently): the Voronoi borders
    of the finer scale's cells part at the joints by more than the cells' overlap, and a front paw's rows,
    whose partners lay outside their target cell, went to the head (27 vertices over 0.3 √area, mean 0.040,
    measured). The target cells now hold the neighbourhoods of the rows' current partners."""
    from scipy.spatial import cKDTree

    from conftest import decimated

    cat0, cat1, gt = cat_pair
    source, _ = decimated(cat0, 0.5, "cat0-half")
    rows = cKDTree(cat0.vertices[gt["cat0"]]).query(source.vertices)[1]  # nearest .vts row of every vertex
    result = solve("kernel-matching", source, cat1)
    err = geodesic_errors(result.map_xy, cat1, np.arange(source.n_vertices), gt["cat1"][rows])
    assert err.summary()["mean"] < 0.03 and np.sum(err.errors > 0.3) < 0.002 * source.n_vertices, err.summary()


def test_every_row_can_reach_its_current_partner_in_its_target_cell():
    """Target cells transferred through the centres alone miss a row's partner where the two shapes' Voronoi
    borders differ (here: the centres' images swapped); with the neighbourhoods of the current partners every
    row's partner is in its cell."""
    from corrlib.methods.kernel_matching.multiscale import transferred_cells

    sphere = trimesh.creation.icosphere(subdivisions=3)
    mesh = TriMesh(sphere.vertices, sphere.faces, name="sphere")
    everything = np.arange(mesh.n_vertices)
    north, south = int(np.argmax(mesh.vertices[:, 2])), int(np.argmin(mesh.vertices[:, 2]))
    x_cells, y_cells = transferred_cells(mesh, mesh, np.array([north, south]), np.array([south, north]),
                                         everything, everything, 0.1, everything, everything)
    for rows, members in zip(x_cells, y_cells):
        assert rows.size > 0 and np.isin(rows, members).all()
    # the Voronoi part is still there: the cell of the centre's image
    assert north in y_cells[1] and south in y_cells[0]


def test_bad_inputs(wolf_pair):
    two = trimesh.util.concatenate([trimesh.creation.icosphere(3), trimesh.creation.icosphere(3).apply_translation([3, 0, 0])])
    broken = TriMesh(two.vertices, two.faces, validate=False, name="two-spheres")
    with pytest.raises(InputError, match="two-spheres.*disconnected"):
        solve("kernel-matching", broken, broken, n_eigs=50, n_seeds=100)
    small = TriMesh(trimesh.creation.icosphere(1).vertices, trimesh.creation.icosphere(1).faces, name="small")
    with pytest.raises(ParameterError, match="500 eigenpairs requested but small has only 42 vertices"):
        solve("kernel-matching", small, wolf_pair[1])
    with pytest.raises(MeshError, match="zero area"):
        TriMesh(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 1, 3]]))
    with pytest.raises(ParameterError, match="times"):
        solve("kernel-matching", *wolf_pair, times="0.1,abc")
    with pytest.raises(ParameterError, match="times must decrease"):
        solve("kernel-matching", *wolf_pair, times="0.001,0.1")
    with pytest.raises(InputError, match=r"one target vertex per source vertex, shape \(4344,\); got shape \(5,\)"):
        solve("kernel-matching", *wolf_pair, initial=InitialMatch(map_xy=np.zeros(5, int)))
    for refiner in ("kernel-matching", "product-manifold", "divergence-free"):  # a plain array is a dense map
        with pytest.raises(InputError, match=r"shape \(4344,\); got shape \(5,\)"):
            solve(refiner, *wolf_pair, initial=np.zeros(5, int))
    with pytest.raises(InputError, match="does not take an initial map"):
        solve("descriptor-nn", *wolf_pair, initial=InitialMatch(map_xy=np.zeros(5, int)))


def test_bad_initial_matches_and_parameters_through_the_python_api_are_named(wolf_pair):
    """What the CLI checks, the Python API checks too, before any work: a float map (0.9 was cut to vertex 0),
    a scalar, a map below -1, landmarks that send one vertex to two targets, a map and landmarks together,
    params with keyword overrides (the overrides were dropped without a word), params of another method, a
    number beyond every float, an array where a choice is expected."""
    from corrlib.methods.base import make_params
    from corrlib.methods.baselines import DescriptorNNParams, FmapZoomOutParams
    from corrlib.methods.kernel_matching import KernelMatchingParams

    n = wolf_pair[0].n_vertices
    cases = [
        (dict(initial=np.full(n, 0.9)), InputError, r"the initial map must hold integer vertex indices; entry 0 is 0.9"),
        (dict(initial=5), InputError, r"shape \(4344,\); got shape \(\)"),
        (dict(initial=np.full(n, -7)), InputError, r"sends source vertex 0 to -7, outside a 4344-vertex target"),
        (dict(initial=InitialMatch(landmarks_x=[5, 5, 9], landmarks_y=[5, 300, 9])), InputError,
         r"landmarks send source vertex 5 to several targets \(5, 300\)"),
        (dict(initial=InitialMatch(landmarks_x=[0.7, 10], landmarks_y=[1, 2])), InputError,
         r"landmarks_x must hold integer vertex indices; entry 0 is 0.7"),
        (dict(params=make_params(DescriptorNNParams), n_eigs=3), ParameterError,
         r"give params or keyword overrides, not both \(got params and n_eigs\)"),
        (dict(params=make_params(FmapZoomOutParams)), ParameterError,
         r"params of 'product-manifold' must be a ProductManifoldParams"),
        (dict(params={"n_eigs": 50}), ParameterError, r"must be a ProductManifoldParams .* got dict"),
    ]
    for kwargs, error, message in cases:
        method = "descriptor-nn" if "n_eigs" in kwargs else "product-manifold"
        with pytest.raises(error, match=message):
            solve(method, *wolf_pair, **kwargs)
    with pytest.raises(InputError, match="a map or landmarks, not both"):
        InitialMatch(map_xy=np.arange(n), landmarks_x=[0], landmarks_y=[0])
    with pytest.raises(InputError, match="needs a map"):
        InitialMatch()
    with pytest.raises(ParameterError, match="n_eigs must be finite, got an integer of 401 digits"):
        make_params(KernelMatchingParams, n_eigs=10 ** 400)
    with pytest.raises(ParameterError, match="init = .* is not one of best, descriptors, fmap"):
        make_params(KernelMatchingParams, init=np.array(["best", "fmap"]))
    with pytest.raises(ParameterError, match="unknown method"):
        solve(["kernel-matching"], *wolf_pair)
    kept = InitialMatch(landmarks_x=[9, 5, 9], landmarks_y=[9, 5, 9]).pairs(n, n)  # a repeated pair counts once
    assert [list(side) for side in kept] == [[9, 5], [9, 5]]


@pytest.mark.parametrize("name, value", [("tau_min", -1e-3), ("tau_max", -0.5), ("tau_min", 0.0),
                                         ("tau_max", float("nan"))])
def test_a_non_positive_time_is_named_without_a_numerical_warning(name, value):
    import warnings

    from corrlib.methods import make_params
    from corrlib.methods.kernel_matching import KernelMatchingParams

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # geomspace of a negative or NaN time used to warn before the error
        with pytest.raises(ParameterError, match=name):
            make_params(KernelMatchingParams, **{name: value})


@pytest.mark.slow
def test_fmap_initialisation_and_final_smoothing(wolf_pair):
    wolf0, wolf1 = wolf_pair
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    ident = np.arange(wolf0.n_vertices)
    from_fmap = solve("kernel-matching", wolf0, wolf1, init="fmap", **fast)
    fmap_only = solve("fmap-zoomout", wolf0, wolf1)
    refined = geodesic_errors(from_fmap.map_xy, wolf1, ident, ident).summary()["within_0.05"]
    baseline = geodesic_errors(fmap_only.map_xy, wolf1, ident, ident).summary()["within_0.05"]
    # the functional-maps baseline is already near-exact on the wolves (measured 99.4 % within 0.05): kernel
    # matching started from it keeps it (measured 99.5 %)
    assert refined > 0.98 and refined >= baseline - 0.005, (refined, baseline)
    smoothed = solve("kernel-matching", wolf0, wolf1, smooth_k=100, **fast)
    assert smoothed.map_xy.min() >= 0 and smoothed.map_yx.min() >= 0
    unsmoothed = solve("kernel-matching", wolf0, wolf1, smooth_k=0, **fast)
    assert np.mean(smoothed.map_xy != unsmoothed.map_xy) > 0.001


def test_scores_without_negligible_decays_equal_the_full_product(cat_pair):
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.methods.kernel_matching.scores import DECAY_CUTOFF, kernel_score

    cat0, cat1 = cat_pair[0], cat_pair[1]
    s0, s1 = mesh_spectrum(cat0, 500), mesh_spectrum(cat1, 500)
    rows, cols = np.arange(0, 5000, 7), np.arange(0, 5000, 5)
    c = s1.evecs[cols].T @ s0.evecs[cols]
    d1, d0 = np.exp(-0.0259 * cat1.area * s1.evals), np.exp(-0.0259 * cat0.area * s0.evals)  # the largest time
    assert np.sum(d1 < DECAY_CUTOFF) > 100  # the cut-off does drop eigenpairs here
    full = (s1.evecs[rows] * d1) @ c @ (s0.evecs[cols] * d0).T  # float64, every eigenpair
    fast = kernel_score(s1.evecs[rows], s0.evecs[cols], c, d1, d0)
    assert fast.dtype == np.float32
    np.testing.assert_allclose(fast, full, rtol=0, atol=1e-5 * np.abs(full).max())
    np.testing.assert_allclose(kernel_score(s0.evecs[cols], s1.evecs[rows], c.T, d0, d1), fast.T, rtol=0,
                               atol=1e-6 * np.abs(full).max())


@pytest.mark.slow
@pytest.mark.parametrize("init", ["descriptors", "fmap"])
def test_non_isometric_pair_meets_issue_18s_target(init):
    """The Sumner lion -> cat (approximate ground truth lion2cat), issue 18's non-isometric target (median
    <= 0.05, mean <= 0.15), by default and from the orientation-aware functional map (figures in the
    decisions record)."""
    from _data import SUMNER
    from corrlib.io import load_mesh

    lion, cat = load_mesh(SUMNER / "lion-00.off"), load_mesh(SUMNER / "cat-00.off")
    truth = np.loadtxt(SUMNER / "lion2cat", dtype=np.int64)
    result = solve("kernel-matching", lion, cat, init=init)
    report = geodesic_errors(result.map_xy, cat, np.arange(lion.n_vertices), truth).summary()
    assert report["median"] <= 0.05 and report["mean"] <= 0.15, report


@pytest.mark.slow
def test_a_given_map_competes_with_the_descriptor_start():
    """Refinement must not make a map worse, however poor the map. The nearest-neighbour map of the Sumner
    lion -> cat (descriptor-nn, 0.47 √area, 0.64 before its spectra were taken at unit area: a poor map)
    refined from its own start ended at 0.68; it now
    runs the first time's DC iterations beside the descriptor assignment, the default's start, and the higher
    objective goes on (measured 0.131, ``extras["start"] == "descriptors"``). A better map (the functional map,
    0.095) keeps its own start and improves on it."""
    from _data import SUMNER
    from corrlib.io import load_mesh
    from corrlib.methods.kernel_matching import start_note

    lion, cat = load_mesh(SUMNER / "lion-00.off"), load_mesh(SUMNER / "cat-00.off")
    truth = np.loadtxt(SUMNER / "lion2cat", dtype=np.int64)
    error = lambda m: geodesic_errors(m, cat, np.arange(lion.n_vertices), truth).summary()["mean"]  # noqa: E731
    nearest = solve("descriptor-nn", lion, cat).map_xy
    refined = solve("kernel-matching", lion, cat, initial=InitialMatch(map_xy=nearest))
    assert error(nearest) > 0.4 and error(refined.map_xy) < 0.15 and refined.extras["start"] == "descriptors"
    assert "continued from the descriptor assignment" in start_note(refined.extras)
    fmap = solve("fmap-zoomout", lion, cat).map_xy
    from_fmap = solve("kernel-matching", lion, cat, initial=InitialMatch(map_xy=fmap))
    assert from_fmap.extras["start"] == "initial map" and error(from_fmap.map_xy) < error(fmap)
    assert start_note(from_fmap.extras) is None


def test_the_final_zoomout_step_keeps_an_exact_isometry(wolf_pair):
    """One ZoomOut step from the exact map between a mesh and a vertex-shuffled copy of it returns that map:
    the nearest neighbour in the projected eigenfunctions. The best inner product instead (what the step
    used to take) moves partners towards target vertices of long spectral embedding."""
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.geometry.fmaps import pointwise_from_basis

    wolf0 = wolf_pair[0]
    perm = np.random.default_rng(3).permutation(wolf0.n_vertices)
    inverse = np.argsort(perm)
    shuffled = TriMesh(wolf0.vertices[perm], inverse[wolf0.faces])
    spec_x, spec_y = mesh_spectrum(wolf0, 160), mesh_spectrum(shuffled, 160)
    map_xy, map_yx = inverse.copy(), perm.copy()  # vertex i of wolf0 is vertex inverse[i] of the copy
    new_xy, new_yx = pointwise_from_basis(map_xy, map_yx, spec_x, spec_y, 160)
    assert np.mean(new_xy == map_xy) > 0.999 and np.mean(new_yx == map_yx) > 0.999
    c = spec_x.evecs.T @ (spec_x.mass.diagonal()[:, None] * spec_y.evecs[map_xy])
    inner = np.argmax((spec_x.evecs @ c) @ spec_y.evecs.T, axis=1)
    assert np.mean(inner == map_xy) < np.mean(new_xy == map_xy)
    # unmatched vertices stay unmatched
    map_xy[:10] = -1
    assert np.all(pointwise_from_basis(map_xy, map_yx, spec_x, spec_y, 160)[0][:10] == -1)


def test_the_final_step_estimates_one_functional_map_from_both_directions(wolf_pair):
    """The step's functional map is the mean of the map's own estimate ``C_xy`` and the adjoint ``C_yxᵀ`` of
    its reverse map's. For a bijection between a mesh and a vertex-shuffled copy (equal masses) the two are
    equal (an identity). Where the map's partners are each moved one edge off and the reverse map is exact,
    the map's own estimate carries the offsets back (measured 39 % of the partners exact; what the step used
    alone), the mean halves them, and both maps share what is left (65 % / 62 % exact)."""
    from corrlib.geometry.fmaps import pointwise_to_functional
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.geometry.fmaps import pointwise_from_basis
    from corrlib.neighbours import nearest_rows

    wolf0 = wolf_pair[0]
    perm = np.random.default_rng(5).permutation(wolf0.n_vertices)
    inverse = np.argsort(perm)
    shuffled = TriMesh(wolf0.vertices[perm], inverse[wolf0.faces])
    k = 100
    spec_x, spec_y = mesh_spectrum(wolf0, k), mesh_spectrum(shuffled, k)
    phi, psi = spec_x.evecs[:, :k], spec_y.evecs[:, :k]
    map_xy, map_yx = inverse.copy(), perm.copy()
    c_xy = pointwise_to_functional(map_xy, psi, phi, spec_x.mass.diagonal())
    c_yx = pointwise_to_functional(map_yx, phi, psi, spec_y.mass.diagonal())
    np.testing.assert_allclose(c_xy, c_yx.T, atol=1e-10)
    # every partner moved to a neighbouring vertex (one edge off), the reverse map exact
    neighbour = wolf0.adjacency.indices[wolf0.adjacency.indptr[:-1]]  # each vertex's first neighbour
    off_xy = inverse[neighbour]
    own = nearest_rows(phi @ pointwise_to_functional(off_xy, psi, phi, spec_x.mass.diagonal()), psi)
    new_xy, new_yx = pointwise_from_basis(off_xy, map_yx, spec_x, spec_y, k)
    exact_own, exact_new = np.mean(own == map_xy), np.mean(new_xy == map_xy)
    assert exact_own < 0.5 and exact_new > 0.55 and np.mean(new_yx == map_yx) > 0.55, (exact_own, exact_new)


def test_the_repeated_final_step_recovers_what_one_step_leaves(wolf_pair):
    """wolf0 -> wolf1 (another pose, truth the identity) with both maps' partners one edge off: one step of
    the final projection makes 52 % of either map's partners exact (measured), the step repeated while it
    moves fewer partners 75 % (ZoomOut's alternation at one basis size, each partner searched by descent
    from the current one). The exact maps between a mesh and its shuffled copy are a fixed point."""
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.geometry.fmaps import pointwise_from_basis, repeated_pointwise_from_basis

    wolf0, wolf1 = wolf_pair
    k = 100
    spec_0, spec_1 = mesh_spectrum(wolf0, k), mesh_spectrum(wolf1, k)
    truth = np.arange(wolf0.n_vertices)
    first_neighbour_1 = wolf1.adjacency.indices[wolf1.adjacency.indptr[:-1]]
    first_neighbour_0 = wolf0.adjacency.indices[wolf0.adjacency.indptr[:-1]]
    once_xy, once_yx = pointwise_from_basis(first_neighbour_1, first_neighbour_0, spec_0, spec_1, k)
    assert np.mean(once_xy == truth) < 0.6 and np.mean(once_yx == truth) < 0.6
    again_xy, again_yx = repeated_pointwise_from_basis(first_neighbour_1, first_neighbour_0, spec_0, spec_1, k,
                                                        wolf0.adjacency, wolf1.adjacency)
    assert np.mean(again_xy == truth) > 0.7 and np.mean(again_yx == truth) > 0.7

    perm = np.random.default_rng(5).permutation(wolf0.n_vertices)
    inverse = np.argsort(perm)
    shuffled = TriMesh(wolf0.vertices[perm], inverse[wolf0.faces])
    fixed_xy, fixed_yx = repeated_pointwise_from_basis(inverse.copy(), perm.copy(), spec_0,
                                                        mesh_spectrum(shuffled, k), k, wolf0.adjacency,
                                                        shuffled.adjacency)
    assert np.mean(fixed_xy == inverse) > 0.999 and np.mean(fixed_yx == perm) > 0.999


def test_the_functional_map_updated_by_the_moved_rows_equals_a_fresh_estimate(wolf_pair):
    from corrlib.geometry.fmaps import pointwise_to_functional
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.geometry.fmaps import moved_rows_change

    wolf0, wolf1 = wolf_pair
    k = 40
    phi, psi = mesh_spectrum(wolf0, k).evecs[:, :k], mesh_spectrum(wolf1, k).evecs[:, :k]
    mass = mesh_spectrum(wolf0, k).mass.diagonal()
    rng = np.random.default_rng(2)
    old = rng.integers(0, wolf1.n_vertices, wolf0.n_vertices)
    old[:5] = -1  # unmatched rows stay unmatched in both maps
    new = old.copy()
    moved = rng.choice(np.arange(5, wolf0.n_vertices), 300, replace=False)
    new[moved] = rng.integers(0, wolf1.n_vertices, 300)
    updated = pointwise_to_functional(old, psi, phi, mass) + moved_rows_change(old, new, psi, phi, mass)
    np.testing.assert_allclose(updated, pointwise_to_functional(new, psi, phi, mass), atol=1e-12)


def test_resolved_eigenpairs_counts_the_decays_above_one_over_e():
    from corrlib.geometry.fmaps import resolved_eigenpairs

    evals = np.array([0.0, 1.0, 2.0, 2.5, 4.0]) / 3.0  # on a shape of area 3
    assert resolved_eigenpairs(evals, 3.0, 0.5) == 3  # tau * lambda * area <= 1 for 0, 1, 2
    assert resolved_eigenpairs(evals, 3.0, 0.25) == 5
    assert resolved_eigenpairs(evals, 3.0, 100.0) == 1  # the constant always


@pytest.mark.slow
@pytest.mark.parametrize("source, target", [("cat1", "cat0"), ("wolf0", "wolf1")])
def test_refining_the_functional_map_lowers_its_error(source, target):
    """Kernel matching from the baseline's map (``initial``) must not undo its detail: rows moved by less than
    the smallest kernel's width keep their partner. Measured: cat1 -> cat0 0.0321 -> 0.0231 (the default
    0.028), wolf0 -> wolf1 0.0018 -> 0.0016 (before the rule 0.0030: the finer scales re-chose among
    partners the kernel cannot tell apart)."""
    from _data import TOSCA
    from corrlib.io import load_mesh

    x, y = load_mesh(TOSCA / f"{source}.off"), load_mesh(TOSCA / f"{target}.off")
    gx, gy = (np.loadtxt(TOSCA / f"{name}.vts", dtype=int) - 1 for name in (source, target))
    fmap = solve("fmap-zoomout", x, y).map_xy
    refined = solve("kernel-matching", x, y, initial=InitialMatch(map_xy=fmap))
    before, after = (geodesic_errors(m, y, gx, gy).summary()["mean"] for m in (fmap, refined.map_xy))
    assert after < before, (before, after)
    kept, isometric = refined.extras["kept_matches"], refined.extras["isometric_matches"]
    assert kept.shape == (x.n_vertices,) and 0.5 < kept.mean() < 1.0  # most rows stand, some are corrected
    assert not np.any(isometric & ~kept)  # rows given back as the more isometric partner are kept rows


@pytest.mark.slow
def test_a_refined_map_keeps_the_detail_of_a_good_input(cat_pair):
    """cat0 -> cat1 from the ground truth with 30 % of its rows random: the rows the refinement cannot resolve
    keep their input partner, and the final step projects the map with its own functional map (0.0161,
    measured), not with the mean of it and the reverse map's (0.0206), whose partners are the kernels' only."""
    from corrlib.contour_bench import _vts_transfer

    cat0, cat1, gt = cat_pair
    truth = _vts_transfer(cat0.vertices, gt["cat0"], gt["cat1"])(np.arange(cat0.n_vertices))
    corrupted = truth.copy()
    rng = np.random.default_rng(0)
    bad = rng.random(truth.size) < 0.3
    corrupted[bad] = rng.integers(0, cat1.n_vertices, bad.sum())
    refined = solve("kernel-matching", cat0, cat1, initial=InitialMatch(map_xy=corrupted))
    err = geodesic_errors(refined.map_xy, cat1, gt["cat0"], gt["cat1"]).summary()
    assert err["mean"] < 0.018, err


def _people_mirror_pair():
    """human3 and the mirror image of human0 (x -> -x, faces reversed) with the ground truth: the rest pose
    human0 is left-right symmetric, so the partner of vertex v is the vertex at v's mirrored position."""
    from scipy.spatial import cKDTree

    from corrlib.io import load_mesh
    from corrlib.resources import resource

    human3, human0 = load_mesh(resource("people/human3.off")), load_mesh(resource("people/human0.off"))
    mirror = TriMesh(human0.vertices * [-1.0, 1.0, 1.0], human0.faces[:, ::-1], name="human0-mirror")
    _, partner = cKDTree(human0.vertices).query(human0.vertices * [-1.0, 1.0, 1.0])
    return human3, mirror, partner


def test_orientation_agreement_changes_sign_under_a_reflection(wolf_pair):
    """The agreement along the identity is positive between a shape and itself and exactly its negative
    between the shape and its mirror image (the descriptors are odd under the reflection)."""
    from corrlib.geometry.spectrum import mesh_spectrum
    from corrlib.methods.kernel_matching import orientation_agreement

    wolf0, _ = wolf_pair
    mirror = TriMesh(wolf0.vertices * [-1.0, 1.0, 1.0], wolf0.faces[:, ::-1], name="wolf0-mirror")
    spec, spec_m = mesh_spectrum(wolf0, 60), mesh_spectrum(mirror, 60)
    identity = np.arange(wolf0.n_vertices)
    same = orientation_agreement(wolf0, wolf0, identity, spec, spec)
    reflected = orientation_agreement(wolf0, mirror, identity, spec, spec_m)
    assert same > 1.0
    assert reflected == pytest.approx(-same, rel=1e-4)  # the mirror's eigenpairs are computed anew
    assert orientation_agreement(wolf0, wolf0, -np.ones_like(identity), spec, spec) == 0.0


def test_a_map_that_reverses_orientation_is_reported(wolf_pair, wolf_result, capsys):
    """Every kernel-matching result carries its orientation agreement; a negative one (left matched to right,
    which the kernel energy cannot see) gets a warning, in the CLI as in the studio's log."""
    from corrlib.cli_common import print_result_notes
    from corrlib.methods.kernel_matching import reversal_note

    assert wolf_result.extras["orientation_agreement"] > 1.0  # wolf0 -> wolf1, the right orientation
    assert reversal_note(wolf_result.extras) is None and reversal_note({}) is None
    note = reversal_note({"orientation_agreement": -4.64})
    assert "reverses orientation" in note and "-4.64" in note and "landmarks" in note

    class Flipped:
        extras = {"orientation_agreement": -0.5}

    print_result_notes(Flipped())
    assert "warning: the map reverses orientation" in capsys.readouterr().err


@pytest.mark.slow
def test_best_of_both_starts_keeps_the_functional_maps_start_only_where_it_dominates():
    """init="best" on human3 -> mirror(human0): the descriptor start ends half flipped (measured 0.275 direct,
    0.095 mirror-accepted), the functional map's start at 0.070, with a higher kernel energy, a higher
    orientation agreement and a lower geodesic distortion, so it is kept. Progress stays within [0, 1] and
    never goes back."""
    from corrlib.methods import solve_iter
    from corrlib.methods.kernel_matching import start_note
    from corrlib.methods.kernel_matching.starts import kept_start
    from corrlib.progress import run

    human3, mirror, partner = _people_mirror_pair()
    fractions = []
    result = run(solve_iter("kernel-matching", human3, mirror, init="best"),
                 callback=lambda report: fractions.append(report.fraction))
    measures = result.extras["start_measures"]
    assert result.extras["init"] == kept_start(measures)
    assert result.extras["init"] == "fmap", measures
    assert "functional map's was kept" in start_note(result.extras)
    report = geodesic_errors(result.map_xy, mirror, np.arange(human3.n_vertices), partner).summary()
    assert report["mean"] <= 0.1, (report, measures)
    known = [f for f in fractions if f >= 0]
    assert known and 0.0 <= min(known) and max(known) <= 1.0 and np.all(np.diff(known) >= -1e-12)
    assert result.timings["other start"] > 0 and result.timings["eigen"] > 0


@pytest.mark.slow
def test_a_start_that_reverses_orientation_gives_way_to_one_that_keeps_it(tmp_path):
    """The noisy capsule people (issue 18's battery, 0.1 % vertex noise), human1 -> human2: the descriptor
    start ends as the mirror image of the truth (measured 0.464 direct, 0.019 mirror-accepted, orientation
    agreement -7.98), with a higher kernel energy and a distortion equal to the functional map's start, which
    is right (0.017, agreement +13.32). Neither the energy nor the distortion can see a mirror image, so the
    start whose map keeps orientation is kept, and the user is told why."""
    from _humanoid import write_kernel_battery

    from corrlib.io import load_mesh, load_vts
    from corrlib.methods.kernel_matching import start_note

    folder = write_kernel_battery(tmp_path, noise=0.001) / "capsule"
    source, target = load_mesh(folder / "human1.off"), load_mesh(folder / "human2.off")
    rows = [load_vts(folder / "corres" / name) for name in ("human1.vts", "human2.vts", "human2.sym.vts")]
    result = solve("kernel-matching", source, target)
    measures = result.extras["start_measures"]
    assert measures["descriptors"]["agreement"] < 0 < measures["fmap"]["agreement"], measures
    assert result.extras["init"] == "fmap" and "reversed orientation on most of the shape" in start_note(result.extras)
    report = geodesic_errors(result.map_xy, target, rows[0], rows[1], gt_target_sym=rows[2]).summary()
    assert report["mean"] <= 0.05 and report["mean"] <= 1.3 * report["mean_sym"], report


@pytest.mark.slow
def test_a_map_half_turned_on_its_upper_body_takes_the_other_start_s_upper_body(tmp_path):
    """The people with a face meshed pose by pose (issue 18's battery, ``remesh=5000``), human1 -> human3: the
    kept start's map has the legs right and the upper body turned half round (measured 0.257 direct, 0.078
    mirror-accepted, geodesic distortion 0.048; the truth's 0.023), the other start's map the upper body
    right. Their combination, optimised once more, is right, and the user is told."""
    from _humanoid import write_kernel_battery

    from corrlib.io import load_mesh, load_vts
    from corrlib.methods.kernel_matching import turn_note

    folder = write_kernel_battery(tmp_path, remesh=5000) / "face"
    source, target = load_mesh(folder / "human1.off"), load_mesh(folder / "human3.off")
    rows = [load_vts(folder / "corres" / name) for name in ("human1.vts", "human3.vts", "human3.sym.vts")]
    result = solve("kernel-matching", source, target)
    combined = result.extras["combined_starts"]
    assert combined["kept"] and combined["distortions"][3] < combined["distortions"][0], combined
    assert "took the other start's partners" in turn_note(result.extras)
    report = geodesic_errors(result.map_xy, target, rows[0], rows[1], gt_target_sym=rows[2]).summary()
    assert report["mean"] <= 0.03 and report["mean"] <= 1.3 * report["mean_sym"], report


def test_a_start_gives_way_only_to_a_map_better_by_every_measure():
    """The functional map's start replaces the default's only where no measure finds it worse, or where the
    default's map reverses orientation and its own does not: a tie or one contrary measure keeps the descriptor
    start. The user is told when it was kept, with the measures."""
    from corrlib.methods.kernel_matching import start_note
    from corrlib.methods.kernel_matching.starts import dominates, kept_start

    base = {"energy": 1.0, "agreement": 5.0, "distortion": 0.05}
    assert dominates({"energy": 1.1, "agreement": 6.0, "distortion": 0.04}, base)
    assert not dominates(base, base)
    for measure, worse in (("energy", 0.9), ("agreement", 4.0), ("distortion", 0.06)):
        assert not dominates({"energy": 1.1, "agreement": 6.0, "distortion": 0.04, measure: worse}, base)
    measures = {"fmap": {"energy": 1.1, "agreement": 6.0, "distortion": 0.04}, "descriptors": base}
    note = start_note({"init": "fmap", "start_measures": measures})
    assert "functional map's was kept" in note and "1.1000×" in note and "6.00 against 5.00" in note
    assert "0.0400 against 0.0500" in note
    assert start_note({"init": "descriptors", "start_measures": measures}) is None
    # a map that reverses orientation on most of the shape gives way to one that does not, whatever else
    reversed_map = {"energy": 1.2, "agreement": -3.0, "distortion": 0.03}
    for kept in (base, {"energy": 0.9, "agreement": 0.0, "distortion": 0.06}):
        assert kept_start({"fmap": kept, "descriptors": reversed_map}) == "fmap"
        assert kept_start({"fmap": reversed_map, "descriptors": kept}) == "descriptors"
    assert kept_start({"fmap": reversed_map, "descriptors": dict(reversed_map, agreement=-4.0)}) == "descriptors"
    assert kept_start(measures) == "fmap" and kept_start({"fmap": base, "descriptors": base}) == "descriptors"
    note = start_note({"init": "fmap", "start_measures": {"fmap": base, "descriptors": reversed_map}})
    assert "reversed orientation on most of the shape (orientation agreement -3.00 against 5.00)" in note
    assert "1.2000× the functional map's" in note


def _starts_side_by_side(wolf_pair, monkeypatch, first_start_raises: bool):
    """Run init="best" on the wolves (small settings) until the descriptor start (the calling thread's) has
    made its first DC iteration, then cancel the caller's token as the studio does (through ``run``) or, with
    ``first_start_raises``, let that start raise. Returns the exception's type and message, the functional
    map's start state and the threads left over."""
    import gc
    import threading

    import corrlib.methods.kernel_matching.starts as starts
    from corrlib.methods import solve_iter
    from corrlib.progress import CancelToken, run

    states, solved = {}, starts.solved

    def recording(state, initial=None):  # a generator, as starts.solved
        states[state.params.init] = state
        if first_start_raises and state.params.init == "descriptors":
            raise ValueError("the first start failed")
        return (yield from solved(state, initial))

    monkeypatch.setattr(starts, "solved", recording)
    threads = threading.active_count()
    token = CancelToken()

    def cancel_at_the_first_iteration(report):
        if "start 1/2" in report.message and "iteration" in report.message:
            token.cancel()  # the run stops at its next check of the token

    steps = solve_iter("kernel-matching", *wolf_pair, token=token, init="best", n_eigs=150, n_seeds=800, n_times=5,
                       iters_per_time=2)
    try:
        run(steps, callback=cancel_at_the_first_iteration, token=token)
        raised = None
    except Exception as exc:  # noqa: BLE001 - its kind and message go to the test (not its traceback, which
        raised = (type(exc), str(exc))  # would keep the generator, and so its thread, alive)
    del steps
    gc.collect()
    return raised, states.get("fmap"), threading.active_count() - threads


def test_both_starts_stop_together_when_cancelled(wolf_pair, monkeypatch):
    """init="best" runs the functional map's start on a thread beside the calling one (two cores): a
    cancellation of the caller's token stops both, and no thread is left running."""
    from corrlib.errors import Cancelled

    raised, beside, threads_left = _starts_side_by_side(wolf_pair, monkeypatch, first_start_raises=False)
    assert raised is not None and raised[0] is Cancelled
    assert beside is not None and beside.token.cancelled  # its own token, set when the first start ended
    assert threads_left == 0


def test_an_error_of_one_start_stops_the_other(wolf_pair, monkeypatch):
    """The first start's error reaches the caller without waiting for the second start to finish: the second
    is cancelled (its own token) and its thread ends."""
    raised, beside, threads_left = _starts_side_by_side(wolf_pair, monkeypatch, first_start_raises=True)
    assert raised == (ValueError, "the first start failed")
    assert beside is not None and beside.token.cancelled
    assert threads_left == 0


def test_while_one_start_waits_for_the_other_each_of_its_reports_is_relayed_once(wolf_pair, monkeypatch):
    """Side by side, the descriptor start may end first and wait for the functional map's: the user then sees
    that start's own reports, each once (a report per poll of the wait filled the log with one line every
    0.1 s, for minutes on large meshes), and the bar shows both runs' work, never going back."""
    import time

    import corrlib.methods.kernel_matching.starts as starts

    solved, second_reports = starts.solved, []

    def slowed(state, initial=None):  # the functional map's start made slower than the descriptor start
        generator = solved(state, initial)
        while True:
            try:
                report = next(generator)
            except StopIteration as stop:
                return stop.value
            if state.params.init == "fmap":
                second_reports.append(report)
                time.sleep(0.05)
            yield report

    from corrlib import cores

    monkeypatch.setattr(starts, "solved", slowed)
    monkeypatch.setattr(cores, "_core_share", 2)  # side by side, as on the two-core machine
    reports = []
    result = solve("kernel-matching", *wolf_pair, callback=reports.append, n_eigs=150, n_seeds=800, n_times=5,
                   iters_per_time=2)
    assert result.extras["start_measures"] is not None  # both starts ran to the end
    relayed = [r for r in reports if r.message.startswith("start 2/2 (fmap)")]
    assert 0 < len(relayed) <= len(second_reports)
    assert all(a is not b and (a.message, a.fraction) != (b.message, b.fraction)
               for a, b in zip(relayed, relayed[1:]))
    known = [r.fraction for r in reports if r.fraction >= 0]
    assert np.all(np.diff(known) >= -1e-12) and known[-1] == 1.0
    first_done = max(r.fraction for r in reports if r.message.startswith("start 1/2"))
    assert first_done < 1.0  # half the bar is the other start's work


@pytest.mark.parametrize("share", [1, 2])
def test_a_failed_functional_map_start_leaves_the_descriptor_starts_map(wolf_pair, monkeypatch, share):
    """Both starts are the default, so the functional map's failing (here its descriptors refused, as on a
    shape too regular for them) must not fail the match: the descriptor start's map is returned, the same as
    init="descriptors" gives, and the user is told why. Side by side (two cores) and one after the other."""
    import corrlib.methods.baselines as baselines
    from corrlib import cores
    from corrlib.errors import InputError
    from corrlib.methods.kernel_matching import start_note

    def refused(source, target, params, token):
        raise InputError(f"{source.name}: the wks descriptors are the same at every vertex")
        yield  # a generator, as the solver

    monkeypatch.setattr(baselines, "solve_fmap_zoomout", refused)
    monkeypatch.setattr(cores, "_core_share", share)
    fast = dict(n_eigs=150, n_seeds=800, n_times=5, iters_per_time=2)
    result = solve("kernel-matching", *wolf_pair, **fast)
    alone = solve("kernel-matching", *wolf_pair, init="descriptors", **fast)
    assert result.extras["init"] == "descriptors" and result.extras["start_measures"] is None
    assert "the same at every vertex" in result.extras["other_start_error"]
    assert "functional map's start failed" in start_note(result.extras)
    np.testing.assert_array_equal(result.map_xy, alone.map_xy)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["cat to lion", "noisy lion to cat", "remeshed lion to cat"])
def test_both_starts_hold_on_non_isometric_and_noisy_pairs(case):
    """The Sumner cat -> lion, lion -> cat with Gaussian vertex noise (0.1 % of the bounding-box diagonal) on
    both shapes, and the lion remeshed to 4,000 vertices -> cat: from the descriptor start some legs land on the
    wrong leg (measured 0.110, 0.206 and 0.157 mean; without noise lion -> cat is 0.117, and 0.12–0.26 with
    noise of other seeds and sizes), from the functional map's start they do not (0.035, 0.036, 0.036), and
    that map is better by all three measures, so the default (both starts) keeps it."""
    from _data import SUMNER, with_vertex_noise
    from corrlib.geometry.remeshing import remeshed
    from corrlib.io import load_mesh

    lion, cat = load_mesh(SUMNER / "lion-00.off"), load_mesh(SUMNER / "cat-00.off")
    lion_to_cat = np.loadtxt(SUMNER / "lion2cat", dtype=np.int64)
    if case == "cat to lion":
        source, target, rows, partners = cat, lion, lion_to_cat, np.arange(lion.n_vertices)
    elif case == "noisy lion to cat":
        source, target = with_vertex_noise(lion, 1), with_vertex_noise(cat, 11)
        rows, partners = np.arange(lion.n_vertices), lion_to_cat
    else:  # every vertex of the remeshed lion is scored by the lion's vertex it came from
        coarse = remeshed(lion, 4000)
        source, target = coarse.mesh, cat
        rows, partners = np.arange(source.n_vertices), lion_to_cat[coarse.to_original]
    result = solve("kernel-matching", source, target)
    report = geodesic_errors(result.map_xy, target, rows, partners).summary()
    assert result.extras["init"] == "fmap", result.extras["start_measures"]
    assert report["mean"] <= 0.06 and report["median"] <= 0.05, report


@pytest.mark.slow
def test_a_pair_in_different_units_is_matched_as_the_same_pair(wolf_pair, wolf_result):
    """wolf1 in millimetres against wolf0 in metres: the times are relative to each shape's area and the final
    steps search partners in unit-area bases, so the map is the one of the pair in one unit (the steps in the
    raw bases gave the cats 0.030 instead of 0.019 at a factor of 1000). Its energy is the same too: it is
    reported at unit areas (before, the target in millimetres reported a millionth of it)."""
    x, y = wolf_pair
    plain = wolf_result.map_xy  # the pair in one unit, default parameters
    scaled = solve("kernel-matching", x, TriMesh(y.vertices * 1e3, y.faces, name="wolf1-mm"))
    assert np.mean(plain == scaled.map_xy) > 0.99
    assert scaled.energy == pytest.approx(wolf_result.energy, rel=1e-3)


@pytest.mark.slow
def test_a_part_turned_against_the_rest_is_matched_again_from_the_rest():
    """Capsule human0 -> mirror(human3) (the bundled people: an upper body alike in front and behind). The
    first passes leave the upper body turned half round against the hips (measured 0.190 direct, 0.005
    mirror-accepted; issue 18's 1.3× fails). The map is two near-isometries that disagree; each part kept as
    landmarks and the other matched again, the run of lower geodesic distortion is right (measured 0.002)."""
    from scipy.spatial import cKDTree

    from corrlib.io import load_mesh
    from corrlib.methods.kernel_matching import turn_note
    from corrlib.resources import resource

    human0, human3 = load_mesh(resource("people/human0.off")), load_mesh(resource("people/human3.off"))
    mirror = TriMesh(human3.vertices * [-1.0, 1.0, 1.0], human3.faces[:, ::-1], name="human3-mirror")
    _, partner = cKDTree(human0.vertices).query(human0.vertices * [-1.0, 1.0, 1.0])  # human0 is symmetric
    fractions = []
    result = solve("kernel-matching", human0, mirror, callback=lambda report: fractions.append(report.fraction))
    report = geodesic_errors(result.map_xy, mirror, np.arange(human0.n_vertices), partner).summary()
    assert report["mean"] <= 0.02, report
    known = [f for f in fractions if f >= 0]
    assert 0.0 <= min(known) and max(known) <= 1.0 and np.all(np.diff(known) >= -1e-12)  # never goes back
    distortions = result.extras["disagreement_distortions"]
    assert result.extras["replaced_part"] > 0 and min(distortions[1:]) < distortions[0], result.extras
    assert result.extras["disagreement_ratio"] > 3 and "two parts of the map disagreed" in turn_note(result.extras)
    assert result.timings["disagreeing parts"] > 0


def test_a_right_map_is_not_split(wolf_result):
    """The wolves' map (nearly exact): its parts do not disagree, so no part is matched again."""
    assert wolf_result.extras["disagreement_ratio"] > 0
    assert "replaced_part" not in wolf_result.extras


@pytest.mark.slow
def test_parts_matched_again_replace_a_right_map_only_where_nearer_an_isometry(wolf_pair, monkeypatch):
    """The check forced onto the wolves' nearly exact map (thresholds at zero): both parts are matched again,
    and a run replaces the map only where its geodesic distortion is lower; either way the map stays right."""
    import corrlib.geometry.distortion as distortion

    monkeypatch.setattr(distortion, "DISAGREEMENT_RATIO", 0.0)
    monkeypatch.setattr(distortion, "RESOLVED_EDGES", 0.0)
    wolf0, wolf1 = wolf_pair
    result = solve("kernel-matching", wolf0, wolf1, init="descriptors")
    found, *runs = result.extras["disagreement_distortions"]
    replaced = result.extras["replaced_part"]
    assert (replaced > 0) == (min(runs) < found), result.extras
    ident = np.arange(wolf0.n_vertices)
    assert geodesic_errors(result.map_xy, wolf1, ident, ident).summary()["within_0.025"] >= 0.97


def test_a_map_turned_on_one_half_is_replaced_by_a_run_nearer_an_isometry():
    """Stage 9 on its own: the capsule surface onto itself, the map the identity below the middle and the half
    turn about the axis above it (each half an isometry, the seam not). Both halves are matched again from the
    other; either run is an isometry of the capsule (the identity, or the whole turn), so the map is replaced
    and its distortion drops to near zero. Progress stays within [0, 1] and never goes back."""
    from scipy.spatial import cKDTree
    from test_distortion import capsule_surface

    from corrlib.geometry.distortion import geodesic_distortions
    from corrlib.methods import make_params
    from corrlib.methods.base import MatchResult
    from corrlib.methods.kernel_matching import KernelMatchingParams
    from corrlib.methods.kernel_matching.passes import replaced_disagreeing_part
    from corrlib.methods.kernel_matching.state import prepare
    from corrlib.progress import CancelToken, run

    mesh = capsule_surface()
    z = mesh.vertices[:, 2]
    _, turned = cKDTree(mesh.vertices).query(mesh.vertices * [-1.0, -1.0, 1.0])
    twisted = np.where(z > 0, turned, np.arange(mesh.n_vertices))
    params = make_params(KernelMatchingParams, n_eigs=100, n_seeds=400, init="descriptors")
    state = run(prepare(mesh, mesh, params, CancelToken()))
    found = MatchResult("kernel-matching", twisted, None, 0.0, {"total": 1.0}, extras={})
    fractions = []
    result = run(replaced_disagreeing_part(state, found), callback=lambda report: fractions.append(report.fraction))
    before, first, second = result.extras["disagreement_distortions"]
    assert result is not found and result.extras["replaced_part"] > 0
    assert min(first, second) < 0.3 * before, (before, first, second)
    assert geodesic_distortions(mesh, mesh, [result.map_xy])[0] == pytest.approx(min(first, second))
    assert all(0.0 <= f <= 1.0 for f in fractions if f >= 0) and np.all(np.diff([f for f in fractions if f >= 0]) >= 0)


def test_a_failed_run_of_the_two_leaves_the_other(monkeypatch):
    """Stage 9 with the run that keeps the first part failing (a CorrError): its distortion is infinite, the
    other run still replaces the map; with both failing, the map found stands."""
    from scipy.spatial import cKDTree
    from test_distortion import capsule_surface

    import corrlib.methods.kernel_matching.passes as passes
    from corrlib.errors import InputError
    from corrlib.geometry.distortion import inconsistent_parts
    from corrlib.methods import make_params
    from corrlib.methods.base import MatchResult
    from corrlib.progress import CancelToken, run

    mesh = capsule_surface()
    z = mesh.vertices[:, 2]
    _, turned = cKDTree(mesh.vertices).query(mesh.vertices * [-1.0, -1.0, 1.0])
    twisted = np.where(z > 0, turned, np.arange(mesh.n_vertices))
    from corrlib.methods.kernel_matching import KernelMatchingParams
    from corrlib.methods.kernel_matching.state import prepare

    params = make_params(KernelMatchingParams, n_eigs=100, n_seeds=400, init="descriptors")
    state = run(prepare(mesh, mesh, params, CancelToken()))
    original = passes.solve_prepared
    failing = set()

    def solve_or_fail(fresh, initial, compete=True):
        if initial.landmarks_x.size in failing:
            raise InputError("this run fails")
        return (yield from original(fresh, initial, compete))

    monkeypatch.setattr(passes, "solve_prepared", solve_or_fail)
    parts = inconsistent_parts(mesh, mesh, twisted, state.pair_distances())
    failing.add(int(np.sum(parts.part)))  # the run keeping the first part
    found = MatchResult("kernel-matching", twisted, None, 0.0, {"total": 1.0}, extras={})
    result = run(passes.replaced_disagreeing_part(state, found))
    before, first, second = result.extras["disagreement_distortions"]
    assert first == np.inf and second < before and result is not found
    failing.add(int(np.sum(~parts.part)))
    found = MatchResult("kernel-matching", twisted, None, 0.0, {"total": 1.0}, extras={})
    assert run(passes.replaced_disagreeing_part(state, found)) is found
    assert found.extras["disagreement_distortions"][1:] == [np.inf, np.inf] and found.extras["replaced_part"] == 0


def test_a_mesh_vertex_budget_within_the_eigenpairs_is_refused(wolf_pair):
    with pytest.raises(ParameterError, match="mesh_vertices must be 0 .* or more than the 500 eigenpairs"):
        solve("kernel-matching", *wolf_pair, mesh_vertices=300)


def test_meshes_are_matched_at_full_resolution_by_default(wolf_result):
    assert "matched_on" not in wolf_result.extras and "lift" not in wolf_result.timings


@pytest.mark.slow
def test_fine_cats_are_matched_on_copies_at_the_budget(tmp_path):
    """TOSCA cat0 and cat1 subdivided once and written to files (19,994 vertices each), ``mesh_vertices=5000``:
    matched on copies of 5,000 vertices and carried back, the map is as good as the full-resolution match
    (measured 0.0204 / 0.0205 against 0.0208) in a third of the time, and complete in both directions."""
    from _data import TOSCA
    from corrlib.io import load_mesh, load_vts, save_mesh
    from corrlib.methods.kernel_matching import copies_note

    meshes = []
    for name in ("cat0", "cat1"):
        cat = load_mesh(TOSCA / f"{name}.off")
        fine = trimesh.Trimesh(cat.vertices, cat.faces, process=False).subdivide()
        save_mesh(tmp_path / f"{name}.off", fine.vertices, fine.faces)
        meshes.append(load_mesh(tmp_path / f"{name}.off"))
    result = solve("kernel-matching", *meshes, mesh_vertices=5000)
    assert result.extras["matched_on"][0] < 5100 and result.extras["matched_on"][1] < 5100
    assert "matched on copies remeshed to" in copies_note(result.extras) and copies_note({}) is None
    assert result.map_xy.shape == (meshes[0].n_vertices,) and result.map_yx.shape == (meshes[1].n_vertices,)
    assert np.all(result.map_xy >= 0) and np.all(result.map_yx >= 0)
    rows = [load_vts(TOSCA / f"{name}.vts", 5000) for name in ("cat0", "cat1")]  # the original vertices come first
    err = geodesic_errors(result.map_xy, meshes[1], *rows).summary()
    assert err["mean"] <= 0.025 and err["within_0.05"] >= 0.9, err
    back = geodesic_errors(result.map_yx, meshes[0], rows[1], rows[0]).summary()
    assert back["mean"] <= 0.025, back


def test_large_meshes_at_full_resolution_are_told_of_the_copies(wolf_pair, monkeypatch):
    """Above LARGE_MESH_VERTICES the first progress message suggests mesh_vertices (the run itself is stopped
    there: the message comes before any work)."""
    from corrlib.methods import kernel_matching as km
    from corrlib.methods.kernel_matching import solver as km_solver
    from corrlib.progress import CancelToken

    monkeypatch.setattr(km_solver, "LARGE_MESH_VERTICES", 1000)
    solver = km.solve_kernel_matching(*wolf_pair, km.KernelMatchingParams(), CancelToken())
    first = next(solver)
    solver.close()
    assert "mesh_vertices=5000 matches on remeshed copies" in first.message
    monkeypatch.setattr(km_solver, "LARGE_MESH_VERTICES", 10_000)
    solver = km.solve_kernel_matching(*wolf_pair, km.KernelMatchingParams(), CancelToken())
    assert "mesh_vertices" not in next(solver).message
    solver.close()


def test_paired_t_against_its_formula():
    """t = mean(d) / (std(d) / √k) of the differences d; ±inf for equal non-zero differences, 0 for none."""
    from corrlib.methods.kernel_matching.starts import paired_t

    reference = np.array([0.5, 0.125, 0.75, 0.25])  # binary fractions: the shifted differences are exact
    assert paired_t(reference + np.array([1.0, 2.0, 3.0, 2.0]), reference) == pytest.approx(2.0 / (np.sqrt(2 / 3) / 2))
    assert paired_t(reference - 0.5, reference) == -np.inf and paired_t(reference + 0.5, reference) == np.inf
    assert paired_t(reference, reference) == 0.0


def test_the_kept_map_takes_the_part_the_other_start_has_right():
    """On a capsule (every turn about its axis is an isometry): the kept map right below the middle and half
    turned above it, the other start's map the other way round. Each part is an isometry of its own and the
    two disagree at the seam; the combination of the kept map's lower part and the other's upper part is the
    identity. Two maps that agree, and a whole turn against the identity (as isometric, and each combination
    twisted), are left alone."""
    from scipy.spatial import cKDTree
    from test_distortion import capsule_surface

    from corrlib.geometry.distortion import PairDistances
    from corrlib.methods.kernel_matching.starts import combined_map

    mesh = capsule_surface()
    identity = np.arange(mesh.n_vertices)
    _, turned = cKDTree(mesh.vertices).query(mesh.vertices * [-1.0, -1.0, 1.0])
    above = mesh.vertices[:, 2] > 0
    kept, other = np.where(above, turned, identity), np.where(above, identity, turned)
    distances = PairDistances(mesh, mesh)
    combined = combined_map(kept, other, distances)
    assert combined is not None
    z = np.abs(mesh.vertices[:, 2])
    away = (z > 0.3) & (z < 1.0)  # the split follows the samples: by the seam, and the poles the turn keeps, either way
    assert np.all(combined.map_xy[away] == identity[away]) and np.all(combined.taken[away] == above[away])
    assert combined.distortions[2] < 0.2 * min(combined.distortions[:2]), combined.distortions
    assert combined_map(identity, identity.copy(), distances) is None
    assert combined_map(identity, turned, distances) is None
