"""The product manifold X × Y: Kronecker operators against their factors, Theorem 5, localized harmonics,
and map refinement on the wolf pair."""

import re

import numpy as np
import pytest
import scipy.linalg as sl

from corrlib.errors import InputError, ParameterError
from corrlib.geometry import product as pm
from _data import TOSCA


def ellipse(n, a=1.0, b=1.0, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    th = np.sort(np.linspace(0, 2 * np.pi, n, endpoint=False) + jitter * rng.uniform(-1, 1, n) * 2 * np.pi / n)
    return np.column_stack([a * np.cos(th), b * np.sin(th)])


@pytest.fixture(scope="module")
def curves():
    fx = pm.curve_factor(ellipse(24, 1.0, 0.7, 0.3, 1), 24)
    fy = pm.curve_factor(ellipse(20, 2.0, 1.0, 0.3, 2), 20)
    return fx, fy


def test_kronecker_operator_spectrum_is_the_sum_of_the_factor_spectra(curves):
    fx, fy = curves
    stiff, mass = pm.product_operator(fx, fy)
    dense = sl.eigh(stiff.toarray(), mass.toarray(), eigvals_only=True)
    evals, index = pm.product_eigenbasis(fx, fy, fx.k * fy.k)
    assert np.allclose(np.sort(dense), evals, atol=1e-9 * evals.max())
    # φ_i ⊗ ψ_j are eigenvectors of the sparse operator, A-orthonormal
    vecs = np.stack([np.kron(fx.evecs[:, i], fy.evecs[:, j]) for i, j in index[:40]], axis=1)
    residual = stiff @ vecs - (mass @ vecs) * evals[:40]
    assert np.abs(residual).max() < 1e-9 * np.abs(stiff @ vecs).max()
    assert np.allclose(vecs.T @ (mass @ vecs), np.eye(40), atol=1e-10)


def test_kronecker_operator_on_meshes(wolf_pair):
    from corrlib.shapes import TriMesh

    # two small patches of the wolf meshes keep the dense check cheap
    def patch(mesh, n):
        keep = mesh.faces[np.all(mesh.faces < n, axis=1)]
        return TriMesh.from_arrays(mesh.vertices[:n], keep, name="patch", largest_component=True)

    px, py = patch(wolf_pair[0], 60), patch(wolf_pair[1], 50)
    from corrlib.geometry.laplacian import mesh_laplacian

    sx, ax = mesh_laplacian(px)
    sy, ay = mesh_laplacian(py)
    fx = pm.Factor(sx, ax, *sl.eigh(sx.toarray(), ax.toarray()))
    fy = pm.Factor(sy, ay, *sl.eigh(sy.toarray(), ay.toarray()))
    stiff, mass = pm.product_operator(fx, fy)
    dense = sl.eigh(stiff.toarray(), mass.toarray(), eigvals_only=True, subset_by_index=[0, 49])
    evals, _ = pm.product_eigenbasis(fx, fy, 50)
    assert np.allclose(dense, evals, atol=1e-8 * evals.max())


def test_restriction_to_a_band_equals_the_submatrix(curves):
    fx, fy = curves
    stiff, mass = pm.product_operator(fx, fy)
    rng = np.random.default_rng(3)
    keys = rng.choice(fx.n * fy.n, 150, replace=False)
    pairs = np.column_stack(np.unravel_index(keys, (fx.n, fy.n)))
    s_band, m_band = pm.product_operator(fx, fy, pairs)
    assert abs(s_band - stiff[keys][:, keys]).max() < 1e-14
    assert abs(m_band - mass[keys][:, keys]).max() < 1e-14
    with pytest.raises(InputError, match="duplicates"):
        pm.product_operator(fx, fy, np.vstack([pairs, pairs[:1]]))
    with pytest.raises(InputError, match="out of range"):
        pm.product_operator(fx, fy, [[fx.n, 0]])
    with pytest.raises(InputError, match="non-empty"):
        pm.product_operator(fx, fy, np.zeros((0, 2)))


def test_theorem5_functional_map_equals_the_product_coefficients(curves, wolf_pair):
    fx, fy = curves
    rng = np.random.default_rng(4)
    map_xy = rng.integers(0, fy.n, fx.n)
    density = pm.map_density(map_xy, fy)
    # expansion coefficients computed on the product: <F, φ_a ⊗ ψ_b>_A with the Kronecker mass
    _, mass = pm.product_operator(fx, fy)
    basis = np.stack([np.kron(fx.evecs[:, a], fy.evecs[:, b]) for a in range(fx.k) for b in range(fy.k)], 1)
    coeffs_product = (basis.T @ (mass @ np.asarray(density).ravel())).reshape(fx.k, fy.k)
    fmap = pm.functional_map(map_xy, fx, fy)
    assert np.abs(coeffs_product - fmap).max() < 1e-12 * np.abs(fmap).max()
    # the functional map pulls functions back: g∘T = Φ C Ψᵀ A_Y g for g in the span of Ψ
    g = fy.evecs[:, :5] @ rng.standard_normal(5)
    pulled = fx.evecs @ (fmap @ (fy.evecs.T @ (fy.mass @ g)))
    assert np.allclose(pulled, g[map_xy], atol=1e-10)  # complete bases: exact
    # on meshes with the lumped mass, the same identity via product_coefficients
    wx, wy = pm.mesh_factor(wolf_pair[0], 20), pm.mesh_factor(wolf_pair[1], 15)
    wmap = np.random.default_rng(5).integers(0, wy.n, wx.n)
    c1 = pm.product_coefficients(pm.map_density(wmap, wy), wx, wy)
    assert np.abs(c1 - pm.functional_map(wmap, wx, wy)).max() < 1e-12 * np.abs(c1).max()


def test_diffusion_is_the_heat_kernel_of_the_product(curves):
    import dataclasses

    fx, fy = (dataclasses.replace(f, unit=1.0) for f in curves)  # absolute times: compare with expm
    stiff, mass = pm.product_operator(fx, fy)
    f0 = np.random.default_rng(6).standard_normal((fx.n, fy.n))
    t = 0.05
    spectral = pm.density_values(pm.diffuse(pm.product_coefficients(f0, fx, fy), fx, fy, t), fx, fy)
    # reference: u(t) = exp(-t A⁻¹ S) u(0) on the full Kronecker operator (complete factor bases)
    w, v = sl.eigh(stiff.toarray(), mass.toarray())
    ref = v @ (np.exp(-t * w) * (v.T @ (mass @ f0.ravel())))
    assert np.allclose(spectral.ravel(), ref, atol=1e-10 * np.abs(ref).max())
    assert np.isclose(curves[0].unit, curves[0].mass.sum() ** 2)  # relative times use the squared length


def test_localized_harmonics_match_a_dense_solve_and_stay_in_the_band(curves):
    fx, fy = curves
    identity_like = np.round(np.arange(fx.n) * fy.n / fx.n).astype(int) % fy.n
    pairs = pm.band_around_map(identity_like, ellipse(20, 2.0, 1.0, 0.3, 2), 0.25)
    pairs = pm.largest_piece(fx, fy, pairs)
    evals, evecs = pm.localized_harmonics(fx, fy, pairs, 10)
    s_band, m_band = pm.product_operator(fx, fy, pairs)
    ref = sl.eigh(s_band.toarray(), m_band.toarray(), eigvals_only=True, subset_by_index=[0, 9])
    assert np.allclose(evals, ref, rtol=1e-8)
    # Dirichlet harmonics lie above the full product spectrum (min-max principle)
    full, _ = pm.product_eigenbasis(fx, fy, 10)
    assert np.all(evals >= full - 1e-9)
    # the Hamiltonian variant tends to the Dirichlet one as the step potential grows
    domain = pm.dilate(fx, fy, pairs)
    low, _ = pm.localized_harmonics(fx, fy, pairs, 5, potential=1e2, domain=domain)
    high, _ = pm.localized_harmonics(fx, fy, pairs, 5, potential=1e8, domain=domain)
    assert np.all(low <= high + 1e-9) and np.all(high <= evals[:5] * (1 + 1e-3) + 1e-9)


def test_bad_bands_and_parameters(curves):
    fx, fy = curves
    two_blobs = np.array([[0, 0], [0, 1], [1, 0], [10, 10], [10, 11], [11, 10]])
    with pytest.raises(InputError, match="falls apart into 2 pieces"):
        pm.localized_harmonics(fx, fy, two_blobs, 2)
    with pytest.raises(ParameterError, match="band fraction"):
        pm.band_around_map(np.zeros(fx.n, int), np.zeros((fy.n, 2)), 0.0)
    with pytest.raises(ParameterError, match="product eigenpairs"):
        pm.product_eigenbasis(fx, fy, 0)
    with pytest.raises(InputError, match="target indices"):
        pm.map_density(np.array([fy.n]), fy)


def test_a_band_too_wide_for_the_localized_stage_is_refused_before_any_work(wolf_pair, monkeypatch):
    """A band of 5 % on two 5k meshes would be an eigenproblem of 1.25M product vertices (it ran for more than
    ten minutes): refused with the widest fraction these shapes take, before the initial map is computed."""
    from corrlib.methods import product_manifold as P
    from corrlib.methods import solve

    P.check_band_size([], 10 ** 6, 10 ** 6, 7.0, 7.0)  # no bands: the global stage alone
    P.check_band_size([0.05], 200, 200, 3.0, 3.0)  # curves: 2,000 product vertices
    with pytest.raises(ParameterError, match="at most") as refused:
        P.check_band_size([0.05], 5000, 5000, 7.0, 7.0)
    widest = float(re.search(r"at most ([0-9.e-]+)", str(refused.value)).group(1))
    P.check_band_size([widest], 5000, 5000, 7.0, 7.0)  # the fraction the message offers is taken
    with pytest.raises(ParameterError, match="a band of 0.05"):  # the widest band, wherever it is in the list
        P.check_band_size([0.001, 0.05], 5000, 5000, 7.0, 7.0)
    called = []
    monkeypatch.setattr("corrlib.methods.baselines.solve_fmap_zoomout", lambda *a, **k: called.append(a))
    with pytest.raises(ParameterError, match="bands: a band of 0.05 of the 4344 target vertices"):
        solve("product-manifold", *wolf_pair, bands="0.05")
    assert not called


def noisy_landmarks(n, seed=0):
    rng = np.random.default_rng(seed)
    lx = rng.choice(n, n // 10, replace=False)
    ly = lx.copy()
    bad = rng.random(lx.size) < 0.2
    ly[bad] = rng.integers(0, n, bad.sum())
    return lx, ly


def test_refinement_of_sparse_noisy_matches_on_the_wolf(wolf_pair):
    """10 % of the ground-truth matches, 20 % of them corrupted. Measured: 99.7 % within 0.05 with the
    assignment, 86 % with maximum likelihood (the issue asks for 90 %)."""
    from corrlib.evaluation import geodesic_errors
    from corrlib.methods import solve
    from corrlib.methods.base import InitialMatch

    wolf0, wolf1 = wolf_pair
    lx, ly = noisy_landmarks(wolf0.n_vertices)
    result = solve("product-manifold", wolf0, wolf1, initial=InitialMatch(landmarks_x=lx, landmarks_y=ly))
    ident = np.arange(wolf0.n_vertices)
    summary = geodesic_errors(result.map_xy, wolf1, ident, ident).summary()
    assert summary["within_0.05"] >= 0.95 and summary["within_0.1"] >= 0.97, summary
    ml = solve("product-manifold", wolf0, wolf1, initial=InitialMatch(landmarks_x=lx, landmarks_y=ly),
               extraction="ml")
    ml_summary = geodesic_errors(ml.map_xy, wolf1, ident, ident).summary()
    assert 0.75 <= ml_summary["within_0.05"] < summary["within_0.05"]  # ML snaps to the matches
    back = geodesic_errors(result.map_yx, wolf0, ident, ident).summary()
    assert back["within_0.05"] >= 0.95, back
    with pytest.raises(InputError, match="landmarks"):
        solve("product-manifold", wolf0, wolf1, initial=InitialMatch(landmarks_x=[], landmarks_y=[]))


def test_cli_refine(tmp_path, capsys):
    from _data import TOSCA
    from corrlib.cli import main
    from corrlib.io import load_map

    lx, ly = noisy_landmarks(4344)
    init = tmp_path / "landmarks.txt"
    init.write_text("\n".join(f"{a} {b}" for a, b in zip(lx, ly)))
    out = tmp_path / "refined"
    code = main(["refine", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--init", str(init), "-o", str(out),
                 "-q"])
    assert code == 0
    assert load_map(tmp_path / "refined.map_xy.txt").shape == (4344,)
    assert main(["refine", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--init",
                 str(tmp_path / "missing.txt"), "-o", str(out), "-q"]) == 2
    # a dense map with 30 % of its rows random: the right rows stand, the random ones are corrected
    rng = np.random.default_rng(1)
    noisy = np.arange(4344)
    bad = rng.random(4344) < 0.3
    noisy[bad] = rng.integers(0, 4344, bad.sum())
    np.savetxt(tmp_path / "noisy.txt", noisy, fmt="%d")
    capsys.readouterr()
    assert main(["refine", str(TOSCA / "wolf0.off"), str(TOSCA / "wolf1.off"), "--init", str(tmp_path / "noisy.txt"),
                 "-o", str(tmp_path / "dense")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if "kept their input partner" in ln)
    kept = int(line.split()[0])
    assert 0.6 * 4344 < kept < 0.75 * 4344, line
    close, isometric = (int(w) for w in re.search(r"\((\d+) moved by less .*, (\d+) farther", line).groups())
    assert close + isometric == kept, line
    assert np.mean(load_map(tmp_path / "dense.map_xy.txt") == np.arange(4344)) > 0.9


# ----------------------------------------------------------------------------- curves


def resample_with_parameter(points, n):
    """Uniform arc-length resampling of a closed polyline, with the (fractional) input index of every sample."""
    seg = np.linalg.norm(np.roll(points, -1, 0) - points, axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])
    s = np.linspace(0, cum[-1], n, endpoint=False)
    idx = np.searchsorted(cum, s, side="right") - 1
    frac = (s - cum[idx]) / seg[idx]
    nxt = (idx + 1) % len(points)
    return points[idx] * (1 - frac)[:, None] + points[nxt] * frac[:, None], idx + frac


@pytest.fixture(scope="module")
def warped_silhouette():
    """A silhouette and a smooth non-rigid warp of it, resampled at 200 and 250 points; the true partner of
    every point of A on B (by the parameter of the dense input curve)."""
    from _data import SILHOUETTES
    from corrlib.io import load_contour

    dense = load_contour(SILHOUETTES / "mpeg7" / "dog-1.gif", 2000).points
    dense = (dense - dense.mean(0)) / np.ptp(dense, axis=0).max()
    warped = dense + 0.08 * np.column_stack([np.sin(3 * dense[:, 1]), np.cos(2 * dense[:, 0])])
    a, param_a = resample_with_parameter(dense, 200)
    b, param_b = resample_with_parameter(warped, 250)
    gap = np.abs(param_b[None, :] - param_a[:, None])
    truth = np.minimum(gap, 2000 - gap).argmin(axis=1)
    return a, b, truth


@pytest.mark.slow
def test_localized_harmonics_beat_the_functional_map_truncation(warped_silhouette):
    """Thesis Figure 9.6 with numbers: k = 100 coefficients. Measured mean errors (fraction of the length):
    functional map 10×10 0.0029, first 100 product eigenfunctions 0.0092, localized harmonics on bands of
    1 % 0.0002, 5 % 0.0027, 25 % 0.0050, 90 % 0.0034: narrow bands win (the 1 % band by a factor of 13),
    wide bands are no better than the truncated functional map."""
    from corrlib.methods.product_manifold import basis_reconstruction

    a, b, truth = warped_silhouette
    fx, fy = pm.curve_factor(a, len(a)), pm.curve_factor(b, len(b))
    res = basis_reconstruction(fx, fy, truth, b, 100)
    err = {name: v["mean_error"] for name, v in res.items()}
    fmap = err["functional map 10x10"]
    assert err["localized 1% band"] < 0.25 * fmap and err["localized 5% band"] < fmap, err
    assert err["localized 1% band"] == min(err.values())
    assert err["product eigenbasis k=100"] > fmap  # the first product eigenfunctions are the worst choice
    assert res["localized 1% band"]["exact"] > 0.8


def test_contour_pair_with_a_known_warp(warped_silhouette):
    """Path on the torus + product refinement recover the warp to the sampling resolution (1/250 = 0.4 % of
    the length): measured mean 0.40 %, 91 % within 1 %."""
    from corrlib.methods import solve
    from corrlib.shapes import Contour2D

    a, b, truth = warped_silhouette
    result = solve("contour2d", Contour2D(a), Contour2D(b), n_source=200, n_target=250)
    gap = np.abs(result.map_xy - truth)
    err = np.minimum(gap, 250 - gap) / 250
    assert err.mean() <= 0.006 and np.mean(err <= 0.01) >= 0.85 and err.max() <= 0.03, (err.mean(), err.max())
    functions = result.path.product_functions
    assert {"cost", "density", "harmonic_1"} <= set(functions)
    for values in functions.values():
        assert values.shape == (200, 250)
    # the band harmonic is localized: zero away from the correspondence
    assert np.count_nonzero(functions["harmonic_1"]) <= 0.06 * 200 * 250


def test_a_contour_pair_facing_opposite_ways_is_matched_through_the_mirror_image(warped_silhouette):
    """B mirrored left to right (the warped dog facing the other way) corresponds to A in reverse order. With
    ``mirror`` (the default) the reversed reading of B wins and the warp is recovered as well as for B as given
    (measured: mean 0.6 % of the length from the true point, the same energy up to 0.02 %); read in its own order
    alone, the best path is another, dearer correspondence (measured mean 8.5 %)."""
    from corrlib.methods import solve
    from corrlib.shapes import Contour2D

    a, b, truth = warped_silhouette
    length = np.linalg.norm(np.diff(np.vstack([b, b[:1]]), axis=0), axis=1).sum()

    def matched(points_b, **params):
        result = solve("contour2d", Contour2D(a), Contour2D(points_b), n_source=200, n_target=250, **params)
        error = np.linalg.norm(result.path.target_points[result.map_xy] - points_b[truth], axis=1) / length
        return result, error

    given, given_error = matched(b)
    mirrored, mirrored_error = matched(b * [-1.0, 1.0])
    assert not given.extras["b_mirrored"] and mirrored.extras["b_mirrored"]
    assert mirrored_error.mean() <= 0.01 and mirrored_error.mean() <= 1.2 * given_error.mean()
    assert mirrored.energy == pytest.approx(given.energy, rel=1e-3) and mirrored.search.optimal
    one_way, one_way_error = matched(b * [-1.0, 1.0], mirror=False)
    assert one_way.energy > mirrored.energy and one_way_error.mean() > 5 * mirrored_error.mean()


def test_contours_of_very_different_sizes_and_samplings(warped_silhouette):
    """Both contours are scaled to unit area before matching, so a 100× larger copy matches like the original;
    very different samplings (30 vs 300 points) still give a complete, monotone cyclic map."""
    from corrlib.methods import solve
    from corrlib.shapes import Contour2D

    a, b, _ = warped_silhouette
    small = solve("contour2d", Contour2D(a), Contour2D(b), n_source=60, n_target=80)
    large = solve("contour2d", Contour2D(100 * a), Contour2D(b), n_source=60, n_target=80)
    assert np.array_equal(small.map_xy, large.map_xy)
    uneven = solve("contour2d", Contour2D(a), Contour2D(b), n_source=30, n_target=300)
    assert uneven.map_xy.shape == (30,) and uneven.map_xy.min() >= 0
    steps = np.diff(np.concatenate([uneven.map_xy, uneven.map_xy[:1] + 300])) % 300
    assert steps.sum() == 300  # winds once around B


def test_the_kernel_width_is_where_a_diffused_match_falls_to_one_over_e():
    """A match diffused on the product of two circles: along the target its density is the heat kernel
    ``exp(-d² / 4t)`` (the circle's length 10, far above the width), 1/e of its peak at :func:`kernel_width`."""
    from corrlib.methods.resolution import kernel_width

    n = 400
    circle = ellipse(n, 10 / (2 * np.pi), 10 / (2 * np.pi))
    fx = fy = pm.curve_factor(circle, 201)
    t = 6.25e-4  # relative to the squared length: a width of 0.05 of the circle
    width = kernel_width(t, fy.unit)
    assert np.isclose(width, 0.5, rtol=1e-4)  # the inscribed polygon is a little shorter than the circle
    density = pm.density_values(pm.diffuse(np.outer(fx.evecs[0], fy.evecs[0]), fx, fy, t), fx, fy, rows=[0])[0]
    arc = np.linspace(0, 10, n, endpoint=False)
    at_width = np.interp(width, arc, density)
    assert np.isclose(at_width / density[0], np.exp(-1), rtol=0.01)
    assert np.isclose(np.interp(2 * width, arc, density) / density[0], np.exp(-4), rtol=0.03)


def test_matches_moved_by_less_than_the_kernel_width_keep_their_partner():
    """Rows whose refined partner lies within the width of their single input partner get it back; rows
    with several input matches and rows without any keep the refined partner."""
    from corrlib.methods.resolution import keep_input_partners

    target = np.column_stack([np.arange(10.0), np.zeros(10)])
    source = target[:5]
    refined = np.array([0, 5, 9, 3, 4])
    ix = np.array([0, 1, 2, 3, 3])  # row 1 moved farther than the width, row 3 has two input matches, row 4 none
    iy = np.array([1, 1, 8, 0, 9])
    resolved, _ = keep_input_partners(refined, ix, iy, source, target, 1.5, 1.5)
    assert refined[[0, 2, 3, 4]].tolist() == [1, 8, 3, 4]
    assert resolved.tolist() == [True, False, True, False, False]
    unmatched = np.array([-1, 5])  # a row the refinement left unmatched (slack) stays unmatched
    resolved, _ = keep_input_partners(unmatched, np.array([0, 1]), np.array([0, 5]), target[:2], target, 1.5, 1.5)
    assert resolved.tolist() == [False, True] and unmatched.tolist() == [-1, 5]


def _line_map():
    """Ten points on a line (source and target alike), the identity as refined map."""
    points = np.column_stack([np.arange(10.0), np.zeros(10)])
    return points, np.arange(10)


def test_a_moved_row_keeps_its_input_partner_where_that_one_is_the_more_isometric():
    """Row 5's refined partner (9) is 4 away from its input partner (5), farther than the width: the input
    partner keeps the distances to the neighbours' partners (4 and 6), the refined one does not (brute force:
    |1 - 5| + |1 - 3| against 0)."""
    from corrlib.methods.resolution import keep_input_partners

    points, refined = _line_map()
    refined[5] = 9
    resolved, isometric = keep_input_partners(refined, np.array([5]), np.array([5]), points, points, 1.5, 1.5)
    assert refined[5] == 5 and not resolved.any() and isometric.tolist() == [i == 5 for i in range(10)]


def test_a_moved_row_keeps_its_refined_partner_where_that_one_is_the_more_isometric():
    """The same row with a wrong input partner (0) keeps the refined partner (5); so do rows with several
    input matches and rows the refinement left unmatched. Neighbours without a partner are left out of the
    distortion (read as the last target point, 9, they would make row 5's input partner 9 look better)."""
    from corrlib.methods.resolution import keep_input_partners

    points, refined = _line_map()
    refined[8] = -1
    ix, iy = np.array([5, 3, 3, 8]), np.array([0, 9, 0, 0])
    resolved, isometric = keep_input_partners(refined, ix, iy, points, points, 1.5, 1.5)
    assert not resolved.any() and not isometric.any()
    assert refined[:8].tolist() == list(range(8)) and refined[8] == -1
    refined = np.arange(10)
    refined[[4, 6]] = -1  # row 5's neighbours have no partner
    resolved, isometric = keep_input_partners(refined, np.array([5]), np.array([9]), points, points, 1.5, 1.5)
    assert refined[5] == 5 and not isometric.any()


def test_the_isometric_choice_ignores_rigid_motions_reflections_and_scale():
    """Distances only: the target mirrored, turned and scaled (widths scaled with it) gives the same choice."""
    from corrlib.methods.resolution import keep_input_partners

    rng = np.random.default_rng(3)
    source = rng.random((60, 3))
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    target = 2.5 * (source * np.array([-1.0, 1.0, 1.0])) @ rotation.T + 7.0
    truth = np.arange(60)
    refined = truth.copy()
    moved = np.array([4, 17, 33])
    refined[moved] = rng.permutation(60)[:3]
    ix = np.arange(60)
    iy = truth.copy()
    for row in (10, 20):  # wrong input partners, the farthest points, that the refinement corrected
        iy[row] = np.argmax(np.linalg.norm(source - source[row], axis=1))
    decided = []
    for tgt, width_y in ((source, 0.3), (target, 0.75)):
        out = refined.copy()
        keep_input_partners(out, ix, iy, source, tgt, 0.3, width_y)
        decided.append(out)
    assert np.array_equal(decided[0], decided[1])
    assert np.array_equal(decided[0][moved], truth[moved]) and decided[0][10] == 10 and decided[0][20] == 20


@pytest.mark.slow
@pytest.mark.parametrize("source, target", [("cat0", "cat1"), ("cat1", "cat0"), ("wolf0", "wolf1"),
                                            ("wolf1", "wolf0")])
def test_refinement_lowers_the_error_of_the_baselines_maps(source, target):
    """The functional-maps baseline's map and the descriptors' nearest neighbours, refined on the product
    (the global stage): the mean error must go down. Measured figures: docs/decisions.md (product-manifold
    refinement)."""
    from corrlib.evaluation import geodesic_errors
    from corrlib.io import load_mesh
    from corrlib.methods import solve
    from corrlib.methods.base import InitialMatch

    x, y = load_mesh(TOSCA / f"{source}.off"), load_mesh(TOSCA / f"{target}.off")
    gx, gy = (np.loadtxt(TOSCA / f"{name}.vts", dtype=int) - 1 for name in (source, target))
    for init in ("fmap-zoomout", "descriptor-nn"):
        before = solve(init, x, y).map_xy
        after = solve("product-manifold", x, y, initial=InitialMatch(map_xy=before)).map_xy
        error_before, error_after = (geodesic_errors(m, y, gx, gy).summary()["mean"] for m in (before, after))
        assert error_after < error_before, (init, error_before, error_after)


@pytest.mark.slow
def test_refinement_on_a_target_at_half_the_resolution(wolf_pair, wolf1_half):
    """wolf0 against wolf1 decimated to half its vertices, refined from the functional-maps baseline's map: the
    refinement must lower its error (measured 0.0096 -> 0.0082; four times worse when every source vertex
    entered the extraction's assignment, docs/decisions.md), and the source's sample must not depend on its
    vertex order."""
    from corrlib.evaluation import geodesic_errors
    from corrlib.methods import solve
    from corrlib.methods.base import InitialMatch
    from corrlib.shapes import TriMesh

    wolf0, (target, truth) = wolf_pair[0], wolf1_half
    before = solve("fmap-zoomout", wolf0, target).map_xy
    after = solve("product-manifold", wolf0, target, initial=InitialMatch(map_xy=before)).map_xy
    rows = np.arange(wolf0.n_vertices)
    error_before, error_after = (geodesic_errors(m, target, rows, truth).summary()["mean"] for m in (before, after))
    assert np.all(after >= 0) and error_after < error_before, (error_before, error_after)
    order = np.random.default_rng(0).permutation(wolf0.n_vertices)  # vertex i of the copy is order[i] of wolf0
    shuffled = TriMesh(wolf0.vertices[order], np.argsort(order)[wolf0.faces], name="wolf0-shuffled")
    again = solve("product-manifold", shuffled, target, initial=InitialMatch(map_xy=before[order])).map_xy
    assert np.mean(again != after[order]) < 0.01


def test_refinement_of_a_corrupted_dense_map_on_independently_remeshed_cats(cat_pair):
    """A dense ground-truth map with 30 % of its rows replaced by random vertices, refined between the
    independently remeshed TOSCA cats. The map is extracted with area capacities; a bijection between
    meshes of different vertex density has to slide vertices (measured: the ground truth projected onto the
    nearest bijection has 68 % within 0.05). Measured: 0.145 -> 0.007 mean (0.013 before the matches that
    the diffusion moves by less than its kernel's width kept their partner)."""
    from scipy.spatial import cKDTree

    from corrlib.evaluation import geodesic_errors
    from corrlib.methods import solve
    from corrlib.methods.base import InitialMatch

    cat0, cat1, gt = cat_pair
    gx, gy = gt["cat1"], gt["cat0"]
    truth = np.full(cat1.n_vertices, -1)
    truth[gx] = gy
    missing = np.flatnonzero(truth < 0)
    if missing.size:
        truth[missing] = gy[cKDTree(cat1.vertices[gx]).query(cat1.vertices[missing])[1]]
    rng = np.random.default_rng(0)
    corrupted = truth.copy()
    bad = rng.random(truth.size) < 0.3
    corrupted[bad] = rng.integers(0, cat0.n_vertices, bad.sum())
    before = geodesic_errors(corrupted, cat0, gx, gy).summary()["mean"]
    result = solve("product-manifold", cat1, cat0, initial=InitialMatch(map_xy=corrupted))
    after = geodesic_errors(result.map_xy, cat0, gx, gy).summary()
    assert before > 0.1 and after["mean"] < 0.011 and after["within_0.05"] > 0.95, (before, after)


def test_refinement_turns_a_mirrored_input_map_of_a_person():
    """The person with a front (tests/_humanoid.py) in two poses, refined from its mirror-image map (every
    vertex sent to its true partner's mirror image, a clean left/right reversal): the diffusion follows the
    input's orientation, which no product-manifold energy can tell from its mirror image, so without the
    orientation stage the map stays mirrored; with it (kernel matching's, ``reorient``) it is turned by the
    target's reflection and the direct error is small."""
    from _humanoid import humanoids

    from corrlib.evaluation import geodesic_errors
    from corrlib.methods import solve
    from corrlib.shapes import TriMesh

    shapes, mirror = humanoids(front=True)
    source, target = (TriMesh(*shapes[name], name=name) for name in ("human0", "human2"))
    ident = np.arange(source.n_vertices)

    def errors(map_xy):
        summary = geodesic_errors(map_xy, target, ident, ident, gt_target_sym=mirror).summary()
        return summary["mean"], summary["mean_sym"]

    kept = solve("product-manifold", source, target, initial=mirror, reorient=False)
    direct, sym = errors(kept.map_xy)
    assert direct > 0.15 and sym < 0.02, (direct, sym)
    turned = solve("product-manifold", source, target, initial=mirror)
    assert turned.extras["turned"] or turned.extras["turned_regions"] >= 2, turned.extras
    direct, sym = errors(turned.map_xy)
    assert direct < 0.03 and direct <= 1.3 * sym, (direct, sym)
    assert turned.extras["orientation_agreement"] > 0
    # the turned map was refined once more, from the first pass's turned map
    assert turned.extras["first_pass"]["turned"] or turned.extras["first_pass"]["turned_regions"] >= 2
    first_direct, _ = errors(turned.extras["first_pass_map_xy"])
    assert direct <= first_direct + 1e-3, (direct, first_direct)


@pytest.mark.slow
def test_swapped_legs_are_reported_and_left_as_found(monkeypatch):
    """The person with a front, human2 -> human1, refined from kernel matching's first-pass map, which sends
    each leg with its hip onto the other leg, mirror-inverted (measured 0.133, mirror-accepted 0.014): the
    diffusion keeps them swapped and cannot place them again, so the orientation stage reports the pair
    (``swapped_regions``), the user is told, and the map is left as found."""
    from _humanoid import humanoids

    import corrlib.methods.kernel_matching.passes as kernel_passes
    from corrlib.evaluation import geodesic_errors
    from corrlib.methods import solve
    from corrlib.methods.kernel_matching import turn_note
    from corrlib.shapes import TriMesh

    shapes, mirror = humanoids(front=True)
    source, target = (TriMesh(*shapes[name], name=name) for name in ("human2", "human1"))
    ident = np.arange(source.n_vertices)
    with monkeypatch.context() as patch:  # kernel matching's first pass from the descriptors: no second pass,
        patch.setattr(kernel_passes, "turned_anything", lambda extras: False)  # and its parts not split
        patch.setattr(kernel_passes, "inconsistent_parts", lambda *args: None)
        first = solve("kernel-matching", source, target, init="descriptors")
    assert first.extras["released_regions"] == 2
    result = solve("product-manifold", source, target, initial=first.map_xy)
    assert result.extras["swapped_regions"] == 2, result.extras
    assert "matched swapped" in turn_note(result.extras) and "left as found" in turn_note(result.extras)
    before, after = (geodesic_errors(m, target, ident, ident, gt_target_sym=mirror).summary()
                     for m in (first.map_xy, result.map_xy))
    assert after["mean"] > 0.1 and after["mean_sym"] < 0.03 and abs(after["mean"] - before["mean"]) < 0.01
