"""Laplacians and spectra against analytic spectra, an independent implementation, and identities."""

import numpy as np
import potpourri3d as pp3d
import pytest
import scipy.sparse as sp
import trimesh

from conftest import grid_mesh
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.laplacian import cotan_stiffness, curve_laplacian, mass_matrix, mesh_laplacian
from corrlib.geometry.spectrum import eigenpairs, mesh_spectrum
from corrlib.shapes import TriMesh


def sphere_eigs(subdivisions, k=17):
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = s.vertices / np.linalg.norm(s.vertices, axis=1, keepdims=True)
    mesh = TriMesh(v, s.faces)
    stiff, mass = mesh_laplacian(mesh)
    return eigenpairs(stiff, mass, k)[0], mesh.n_vertices


def test_unit_sphere_spectrum_and_refinement():
    exact = np.array([l * (l + 1) for l in range(5) for _ in range(2 * l + 1)])[1:17]
    coarse, n_coarse = sphere_eigs(3)
    fine, n_fine = sphere_eigs(4)
    assert 2000 < n_fine < 3000
    rel_fine = np.abs(fine[1:17] - exact) / exact
    rel_coarse = np.abs(coarse[1:17] - exact) / exact
    assert rel_fine.max() < 0.02, rel_fine
    assert fine[0] == pytest.approx(0.0, abs=1e-8)
    # multiplicities 3, 5, 7: the groups are separated by large gaps
    assert np.all(np.diff(fine[1:4]) < 0.05) and fine[4] / fine[3] > 2.5
    assert rel_fine.max() < 0.5 * rel_coarse.max()


def test_flat_torus_spectrum_converges():
    # Clifford torus (cos u, sin u, cos v, sin v) in R^4 is flat with periods 2π: eigenvalues m² + n²
    exact = np.sort([m * m + n * n for m in range(-3, 4) for n in range(-3, 4)])[:17]
    errors = []
    for n in (24, 48):
        uv, faces = grid_mesh(n, n, periodic=True)
        u, v = 2 * np.pi * uv[:, 0], 2 * np.pi * uv[:, 1]
        x = np.column_stack([np.cos(u), np.sin(u), np.cos(v), np.sin(v)])
        evals, _ = eigenpairs(cotan_stiffness(x, faces), mass_matrix(x, faces), 17)
        errors.append(np.max(np.abs(evals[1:] - exact[1:]) / exact[1:]))
    assert errors[1] < 0.01
    assert errors[1] < 0.35 * errors[0]  # second-order convergence: ~1/4 when h halves


def test_unit_square_neumann_spectrum():
    uv, faces = grid_mesh(40, 40)
    x = np.column_stack([uv, np.zeros(len(uv))])
    evals, _ = eigenpairs(cotan_stiffness(x, faces), mass_matrix(x, faces), 6)
    exact = np.pi ** 2 * np.array([0, 1, 1, 2, 4, 4])
    assert np.allclose(evals[1:], exact[1:], rtol=0.01)


def test_cotan_weights_of_a_sliver_triangle_match_their_analytic_values():
    """A triangle (0, 0), (1, 0), (1/2, h) has cotangents 1/(2h) at its base and (h² − 1/4)/h at its apex
    (|a × b| = h for both corners' edge vectors). At h = 1e-9 the squares of Lagrange's identity lose h²
    below the rounding of 1/16, which made the apex weight −1e299; in 3D and embedded in 4D alike."""
    h = 1e-9
    for dim in (3, 4):
        x = np.zeros((3, dim))
        x[1, 0], x[2, 0], x[2, 1] = 1.0, 0.5, h
        s = cotan_stiffness(x, np.array([[0, 1, 2]])).toarray()
        # S_ij = −(cot of the angle opposite edge ij) / 2
        assert -s[0, 1] == pytest.approx(0.5 * (h * h - 0.25) / h, rel=1e-6)
        assert -s[1, 2] == pytest.approx(0.5 * 0.5 / h, rel=1e-6)
        assert -s[0, 2] == pytest.approx(0.5 * 0.5 / h, rel=1e-6)


def test_a_mesh_with_a_cap_keeps_its_spectrum():
    """A grid vertex moved to within 1e-10 of the opposite edge of one of its triangles (a *cap*, as an edge
    collapse leaves): the linear FEM is still a discretisation of the same square, so its Neumann eigenvalues
    stay near those of the grid as it was, with one zero eigenvalue (the shape is connected)."""
    uv, faces = grid_mesh(20, 20)
    x = np.column_stack([uv, np.zeros(len(uv))])
    regular, _ = eigenpairs(cotan_stiffness(x, faces), mass_matrix(x, faces), 6)
    centre = int(np.argmin(np.linalg.norm(uv - 0.5, axis=1)))
    face = faces[np.flatnonzero((faces == centre).any(axis=1))[0]]
    a, b = (v for v in face if v != centre)
    midpoint = 0.5 * (x[a] + x[b])
    inward = x[centre] - midpoint
    x[centre] = midpoint + 1e-10 * inward / np.linalg.norm(inward)
    evals, _ = eigenpairs(cotan_stiffness(x, faces), mass_matrix(x, faces), 6)
    assert evals[0] == 0.0 and evals[1] > 1.0
    assert np.allclose(evals[1:], regular[1:], rtol=0.05)


def test_a_needle_vertex_does_not_read_as_a_disconnected_shape():
    """A vertex 1e-10 of an edge from its end (mass ~1e-10 of a typical vertex, cotangents ~1e10) made the
    mean Rayleigh quotient of the unit vectors, against which a second zero eigenvalue was judged, 10^7 times
    the typical one: a connected sphere was refused as disconnected (a remeshed 80k-vertex cat met this). The
    spectrum is the sphere's, and two such spheres are still told disconnected."""
    from _data import with_needle_vertex

    sphere = trimesh.creation.icosphere(subdivisions=3)
    v, f = sphere.vertices, sphere.faces
    regular, _ = eigenpairs(cotan_stiffness(v, f), mass_matrix(v, f), 6)
    v, f = with_needle_vertex(v, f, 1e-10)
    for method in ("eigsh", "slicing"):
        evals, _ = eigenpairs(cotan_stiffness(v, f), mass_matrix(v, f), 6, method=method)
        assert evals[0] == 0.0
        assert np.allclose(evals[1:], regular[1:], rtol=1e-3)
    two_v = np.vstack([v, v + [5.0, 0.0, 0.0]])
    two_f = np.vstack([f, f + len(v)])
    with pytest.raises(InputError, match="disconnected"):
        eigenpairs(cotan_stiffness(two_v, two_f), mass_matrix(two_v, two_f), 6)


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_circle_spectrum_converges(mass):
    exact = np.array([0, 1, 1, 4, 4, 9, 9, 16, 16])
    errs = []
    for m in (100, 200):
        t = np.linspace(0, 2 * np.pi, m, endpoint=False)
        stiff, mass_mat = curve_laplacian(np.column_stack([np.cos(t), np.sin(t)]), mass=mass)
        evals, evecs = eigenpairs(stiff, mass_mat, 9)
        errs.append(np.max(np.abs(evals[1:] - exact[1:]) / exact[1:]))
        assert np.allclose(evecs.T @ mass_mat @ evecs, np.eye(9), atol=1e-8)
    assert errs[1] < 0.005
    assert errs[1] < 0.3 * errs[0]
    assert mass_mat.sum() == pytest.approx(2 * m * np.sin(np.pi / m))


def test_curve_laplacian_hand_computed():
    # unit square, segment lengths 1: S = [[2,-1,0,-1],...], consistent M = [[2/3,1/6,0,1/6],...]
    p = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    stiff, mass = curve_laplacian(p)
    ring = np.array([[2, -1, 0, -1], [-1, 2, -1, 0], [0, -1, 2, -1], [-1, 0, -1, 2]], float)
    assert np.allclose(stiff.toarray(), ring)
    assert np.allclose(mass.toarray(), np.array([[4, 1, 0, 1], [1, 4, 1, 0], [0, 1, 4, 1], [1, 0, 1, 4]]) / 6)
    with pytest.raises(InputError, match="zero or invalid length"):
        curve_laplacian(np.array([[0, 0], [0, 0], [1, 1]], float))


def test_cotan_matches_independent_implementation(cat_pair):
    cat = cat_pair[0]
    stiff, mass = mesh_laplacian(cat)
    ref = pp3d.cotan_laplacian(cat.vertices, cat.faces)
    areas = pp3d.vertex_areas(cat.vertices, cat.faces)
    assert abs(stiff - ref).max() < 1e-10 * abs(ref).max()
    assert np.allclose(mass.diagonal(), areas, rtol=1e-12)
    assert np.allclose(stiff @ np.ones(cat.n_vertices), 0, atol=1e-10)
    assert abs(stiff - stiff.T).max() < 1e-12
    consistent = mass_matrix(cat.vertices, cat.faces, "consistent")
    assert consistent.sum() == pytest.approx(cat.area)
    assert np.allclose(np.asarray(consistent.sum(axis=1)).ravel(), mass.diagonal())


def test_slicing_equals_single_shift_invert(cat_pair):
    cat = cat_pair[0]
    stiff, mass = mesh_laplacian(cat)
    w1, v1 = eigenpairs(stiff, mass, 300, method="eigsh")
    w2, v2 = eigenpairs(stiff, mass, 300, method="slicing")
    assert np.allclose(w1, w2, rtol=1e-9, atol=1e-12)
    assert np.allclose(v2.T @ (mass @ v2), np.eye(300), atol=1e-9)
    # same invariant subspaces: |<v1_i, v2_i>_M| = 1 for simple eigenvalues
    overlap = np.abs(np.einsum("ij,ij->j", v1, mass @ v2))
    gaps = np.minimum(np.diff(w1, prepend=-1), np.diff(w1, append=1e9))
    simple = gaps > 1e-6 * w1[-1]
    assert np.all(overlap[simple] > 1 - 1e-6)


@pytest.mark.parametrize("slice_size, n_runs", [(100, 4), (40, 10)])
def test_slicing_wastes_no_shift(monkeypatch, slice_size, n_runs):
    """Every shift-invert run of the slicing reaches back to the last cut: the second shift is placed by the
    first slice's span (its radius is the whole span, the first slice being one-sided), so 300 eigenpairs in
    slices of s take a first slice of s and then slices of about 0.8 s (1 + ⌈(300 − s) / 0.8 s⌉ runs), no run
    thrown away."""
    import corrlib.geometry.spectrum as spectrum

    monkeypatch.setattr(spectrum, "SLICE_SIZE", slice_size)

    s = trimesh.creation.icosphere(subdivisions=4)
    mesh = TriMesh(np.asarray(s.vertices) * [3.0, 2.0, 1.0], s.faces)
    stiff, mass = mesh_laplacian(mesh)
    runs = []
    original = spectrum._ShiftInvert.run

    def counted(self, k, sigma, **kwargs):
        runs.append(sigma)
        return original(self, k, sigma, **kwargs)

    monkeypatch.setattr(spectrum._ShiftInvert, "run", counted)
    w, _ = eigenpairs(stiff, mass, 300, method="slicing")
    assert len(runs) == n_runs and np.all(np.diff(runs) > 0)
    monkeypatch.undo()
    assert np.allclose(w, eigenpairs(stiff, mass, 300, method="eigsh")[0], rtol=1e-9)


@pytest.mark.parametrize("mass_kind", ["lumped", "consistent"])
def test_symmetric_lu_solves_the_shifted_system(cat_pair, mass_kind):
    """The shift-invert operator (SuperLU in symmetric mode) solves ``(A − σM) x = b`` for a shift inside the
    spectrum, next to an eigenvalue, as accurately as partial pivoting does."""
    import scipy.sparse.linalg as spla

    from corrlib.geometry.spectrum import _ShiftInvert

    stiff, mass = mesh_laplacian(cat_pair[0], mass=mass_kind)
    op = _ShiftInvert(stiff, mass)
    w = eigenpairs(stiff, mass, 40, method="eigsh")[0]
    b = np.random.default_rng(0).standard_normal(op.a.shape[0])
    for sigma in (0.5 * (w[20] + w[21]), w[30] * (1 + 1e-7)):
        shifted = (op.a - sigma * (sp.identity(op.a.shape[0]) if op.diag_mass else op.mass)).tocsc()
        x = op._symmetric_lu(sigma) @ b
        reference = spla.spsolve(shifted, b)
        assert np.linalg.norm(x - reference) <= 1e-6 * np.linalg.norm(reference)


def test_eigenvector_signs_do_not_depend_on_the_decomposition(cat_pair):
    """Every simple eigenvector with a third moment comes out with Σ m φ³ > 0, whichever solver and k computed
    it, so a cold and a warm spectra cache give the same functions."""
    cat = cat_pair[0]
    stiff, mass = mesh_laplacian(cat)
    w1, v1 = eigenpairs(stiff, mass, 30, method="eigsh")
    w2, v2 = eigenpairs(stiff, mass, 60, method="slicing")
    moments = mass.diagonal() @ v1**3
    assert np.all(moments[1:] > -1e-6)
    gaps = np.minimum(np.diff(w1, prepend=-1), np.diff(w1, append=w2[30]))
    distinct = (gaps > 1e-6 * w1[-1]) & (np.abs(moments) > 1e-3)
    assert distinct.sum() >= 10
    assert np.allclose(v1[:, distinct], v2[:, :30][:, distinct], atol=1e-6)


def test_slicing_handles_degenerate_eigenspaces():
    s = trimesh.creation.icosphere(subdivisions=3)
    mesh = TriMesh(s.vertices, s.faces)
    stiff, mass = mesh_laplacian(mesh)
    import corrlib.geometry.spectrum as spectrum

    old = spectrum.SLICE_SIZE, spectrum.DENSE_LIMIT
    spectrum.SLICE_SIZE, spectrum.DENSE_LIMIT = 12, 10  # force many slice boundaries through multiplets
    try:
        w2, v2 = eigenpairs(stiff, mass, 60, method="slicing")
    finally:
        spectrum.SLICE_SIZE, spectrum.DENSE_LIMIT = old
    w1 = np.linalg.eigvalsh(np.diag(mass.diagonal() ** -0.5) @ stiff.toarray() @ np.diag(mass.diagonal() ** -0.5))
    assert np.allclose(w2, w1[:60], rtol=1e-8, atol=1e-10)
    assert np.allclose(v2.T @ (mass @ v2), np.eye(60), atol=1e-8)
    assert np.allclose(stiff @ v2, (mass @ v2) * w2, atol=1e-8 * w2.max())


def test_eigenpairs_errors():
    s = trimesh.creation.icosphere(subdivisions=1)
    mesh = TriMesh(s.vertices, s.faces)
    stiff, mass = mesh_laplacian(mesh)
    with pytest.raises(ParameterError, match="only 42 vertices"):
        eigenpairs(stiff, mass, 50)
    with pytest.raises(ParameterError, match="positive integer"):
        eigenpairs(stiff, mass, 0)
    with pytest.raises(ParameterError, match="unknown eigensolver"):
        eigenpairs(stiff, mass, 3, method="magic")
    bad = stiff.copy().tolil()
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        eigenpairs(bad.tocsr(), mass, 3)
    # two disjoint spheres: two zero eigenvalues
    two_s = sp.block_diag([stiff, stiff]).tocsr()
    two_m = sp.block_diag([mass, mass]).tocsr()
    with pytest.raises(InputError, match="disconnected"):
        eigenpairs(two_s, two_m, 5)
    zero_mass = mass.copy().tolil()
    zero_mass[3, 3] = 0
    with pytest.raises(InputError, match="zero or negative mass"):
        eigenpairs(stiff, zero_mass.tocsr(), 3)


def test_large_sparse_disconnected_detected():
    a = trimesh.creation.icosphere(subdivisions=4)
    b = a.copy()
    b.apply_translation([5, 0, 0])
    v = np.vstack([a.vertices, b.vertices])
    f = np.vstack([a.faces, b.faces + len(a.vertices)])
    with pytest.raises(InputError, match="disconnected"):
        eigenpairs(cotan_stiffness(v, f), mass_matrix(v, f), 10)


def test_spectrum_disk_cache(wolf_pair, tmp_path, monkeypatch):
    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    wolf = wolf_pair[0]
    first = mesh_spectrum(wolf, 30)
    assert list(tmp_path.glob("spectra/*.npz"))
    again = mesh_spectrum(wolf, 20)
    assert np.array_equal(again.evals, first.evals[:20])
    assert np.array_equal(again.evecs, first.evecs[:, :20])
    # a different mesh content gets a different entry
    moved = TriMesh(wolf.vertices * 1.01, wolf.faces)
    other = mesh_spectrum(moved, 20)
    assert np.allclose(other.evals, first.evals[:20] / 1.01 ** 2, rtol=1e-6)
    assert len(list(tmp_path.glob("spectra/*.npz"))) == 2
    # a corrupt entry is ignored and recomputed: garbage, and an entry cut in half (a full disk, a killed copy)
    for damage in (lambda data: b"garbage", lambda data: data[: len(data) // 2]):
        for f in tmp_path.glob("spectra/*.npz"):
            f.write_bytes(damage(f.read_bytes()))
        again = mesh_spectrum(wolf, 20)
        assert np.allclose(again.evals, first.evals[:20])


def _counting_popen(monkeypatch):
    """Count the second processes :func:`mesh_spectra` starts."""
    import subprocess

    started = []
    real = subprocess.Popen

    def popen(*args, **kwargs):
        started.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(subprocess, "Popen", popen)
    return started


def _same_spectrum(a, b):
    assert np.allclose(a.evals, b.evals, rtol=1e-9, atol=1e-12)
    # eigenvectors up to sign (no multiplets among the lowest 30 of the wolves)
    signs = np.sign(np.sum(a.evecs * b.evecs, axis=0))
    assert np.allclose(a.evecs * signs, b.evecs, atol=1e-7)


def test_pair_spectra_in_a_second_process(wolf_pair, tmp_path, monkeypatch):
    import corrlib.geometry.spectrum as spectrum

    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(spectrum, "PARALLEL_MIN_WORK", 0)
    monkeypatch.setattr(spectrum, "_second_process_allowed", lambda: True)
    started = _counting_popen(monkeypatch)
    both = spectrum.mesh_spectra(wolf_pair, (30, 25))
    assert len(started) == 1 and "corrlib.geometry.spectrum_worker" in started[0]
    assert [s.k for s in both] == [30, 25]
    for mesh, got, k in zip(wolf_pair, both, (30, 25)):
        _same_spectrum(got, mesh_spectrum(mesh, k, use_cache=False))
    # both went to the cache: asked again, nothing is decomposed and no process starts
    assert len(list(tmp_path.glob("spectra/*.npz"))) == 2
    again = spectrum.mesh_spectra(wolf_pair, 20)
    assert len(started) == 1
    assert np.array_equal(again[0].evals, both[0].evals[:20])


def test_pair_spectra_without_a_second_process(wolf_pair, monkeypatch):
    """A failing or unstartable second process, or one not allowed (a pool's worker), leaves the work to this
    process."""
    import multiprocessing
    import sys
    import tempfile

    import corrlib.geometry.spectrum as spectrum

    monkeypatch.setenv("CORRLIB_CACHE_DIR", "off")
    monkeypatch.setattr(spectrum, "PARALLEL_MIN_WORK", 0)
    started = _counting_popen(monkeypatch)
    reference = [mesh_spectrum(mesh, 20, use_cache=False) for mesh in wolf_pair]
    with monkeypatch.context() as patch:
        patch.setattr(spectrum, "_second_process_allowed", lambda: True)
        patch.setattr(sys, "executable", "/bin/false")
        failed = spectrum.mesh_spectra(wolf_pair, 20)
    assert len(started) == 1
    with monkeypatch.context() as patch:  # no interpreter to start, no writable temporary folder
        patch.setattr(spectrum, "_second_process_allowed", lambda: True)
        patch.setattr(sys, "executable", "/nonexistent/python3")
        unstartable = spectrum.mesh_spectra(wolf_pair, 20)
        patch.setattr(tempfile, "tempdir", "/nonexistent/tmp")
        no_tmp = spectrum.mesh_spectra(wolf_pair, 20)
    assert len(started) == 2  # the unstartable interpreter was tried; without a temporary folder nothing is
    with monkeypatch.context() as patch:
        patch.setattr(multiprocessing, "parent_process", lambda: object())
        assert not spectrum._second_process_allowed()
        in_worker = spectrum.mesh_spectra(wolf_pair, 20)
    assert len(started) == 2
    for got in (failed, unstartable, no_tmp, in_worker):
        for a, b in zip(got, reference):
            _same_spectrum(a, b)


def test_pair_spectra_name_a_disconnected_mesh(wolf_pair, monkeypatch):
    import corrlib.geometry.spectrum as spectrum

    monkeypatch.setenv("CORRLIB_CACHE_DIR", "off")
    monkeypatch.setattr(spectrum, "PARALLEL_MIN_WORK", 0)
    monkeypatch.setattr(spectrum, "_second_process_allowed", lambda: True)
    a = trimesh.creation.icosphere(subdivisions=3)
    v = np.vstack([a.vertices, a.vertices + [5.0, 0, 0]])
    f = np.vstack([a.faces, a.faces + len(a.vertices)])
    broken = TriMesh(v, f, name="two-spheres", validate=False)  # the solver must still name it
    with pytest.raises(InputError, match="two-spheres.*disconnected"):
        spectrum.mesh_spectra([broken, wolf_pair[0]], 20)


def test_consistent_mass_generalized_problem():
    s = trimesh.creation.icosphere(subdivisions=3)  # 642 vertices: above the dense limit
    mesh = TriMesh(s.vertices, s.faces)
    stiff, mass = mesh_laplacian(mesh, mass="consistent")
    dense, _ = eigenpairs(stiff, mass, 40, method="dense")
    for method in ("eigsh", "slicing"):
        evals, evecs = eigenpairs(stiff, mass, 40, method=method)
        assert np.allclose(evals, dense, rtol=1e-8, atol=1e-10)
        assert np.allclose(evecs.T @ (mass @ evecs), np.eye(40), atol=1e-8)


def test_eigensolver_retries_with_regularised_shift(monkeypatch):
    import scipy.sparse.linalg as spla

    import corrlib.geometry.spectrum as spectrum

    s = trimesh.creation.icosphere(subdivisions=3)
    stiff, mass = mesh_laplacian(TriMesh(s.vertices, s.faces))
    calls = []
    original = spectrum._ShiftInvert.run

    def flaky(self, k, sigma, ncv=None, tol=0.0, blocks=False):
        calls.append(sigma)
        if len(calls) == 1:
            raise spla.ArpackNoConvergence("no convergence", np.zeros(0), np.zeros((0, 0)))
        return original(self, k, sigma, ncv, tol, blocks)

    monkeypatch.setattr(spectrum._ShiftInvert, "run", flaky)
    evals, _ = eigenpairs(stiff, mass, 10, method="eigsh")
    assert len(calls) == 2 and calls[1] < calls[0] < 0
    assert evals[0] == pytest.approx(0, abs=1e-9) and evals[1] > 0

    def broken(self, k, sigma, ncv=None, tol=0.0, blocks=False):
        raise RuntimeError("factor is exactly singular")

    monkeypatch.setattr(spectrum._ShiftInvert, "run", broken)
    with pytest.raises(spectrum.SolverError, match="eigensolver failed"):
        eigenpairs(stiff, mass, 10, method="eigsh")


@pytest.mark.slow
def test_cholesky_solver_equals_superlu_and_rejects_indefinite_matrices(cat_pair):
    import scipy.sparse.linalg as spla

    from corrlib.errors import SolverError
    from corrlib.geometry.cholesky import CholeskySolver, nested_dissection

    stiff, mass = mesh_laplacian(cat_pair[0])
    spd = (stiff + 1e-3 * mass).tocsc()
    perm = nested_dissection(spd)
    assert np.array_equal(np.sort(perm), np.arange(spd.shape[0]))  # a permutation
    rhs = np.random.default_rng(0).standard_normal((spd.shape[0], 3))
    expected = spla.splu(spd).solve(rhs)
    for blocks in (True, False):  # supernodal panels, CHOLMOD's own solves
        solver = CholeskySolver(spd, blocks=blocks)
        x = solver.solve(rhs)
        assert np.allclose(x, expected, rtol=1e-8, atol=1e-10 * np.abs(x).max())
        assert np.allclose(solver.solve(rhs[:, 0]), x[:, 0], rtol=1e-12, atol=1e-12 * np.abs(x).max())
    with pytest.raises(SolverError, match="not positive definite"):
        CholeskySolver((stiff - 1e-3 * mass).tocsc())
    with pytest.raises(SolverError, match="square symmetric matrix"):
        CholeskySolver(sp.triu(spd).tocsc())


def test_multifrontal_factor_equals_dense_cholesky():
    """The supernodal factor (elimination tree, column counts, supernode rows, fronts) against LAPACK's dense
    Cholesky of the permuted matrix, entry by entry, on sparse random matrices of several shapes."""
    from corrlib.geometry.cholesky import _BLAS_MIN_WORK, CholeskySolver, _elimination_tree

    rng = np.random.default_rng(5)
    for n, density in ((1, 1.0), (7, 0.5), (60, 0.05), (150, 0.02), (300, 0.3)):
        m = sp.random(n, n, density=density, random_state=rng, data_rvs=lambda k: rng.uniform(-1, 1, k))
        spd = sp.csc_matrix(m + m.T + sp.identity(n) * (abs(m + m.T).sum(axis=1).max() + 1.0))
        solver = CholeskySolver(spd)
        perm = solver.perm
        assert np.array_equal(np.sort(perm), np.arange(n))
        dense_l = np.linalg.cholesky(spd.toarray()[np.ix_(perm, perm)])
        pattern = np.abs(dense_l) > 1e-13 * np.abs(dense_l).max()
        assert solver.nnz == int(pattern.sum())
        # elimination tree: the parent of j is the first row below the diagonal of column j of L
        low = sp.tril(spd[perm][:, perm]).tocsr()
        parent = _elimination_tree(low.indptr.astype(np.int64), low.indices.astype(np.int64))
        for j in range(n):
            below = np.flatnonzero(pattern[j + 1:, j])
            assert parent[j] == (j + 1 + below[0] if below.size else -1)
        rebuilt = np.zeros((n, n))
        for s in range(solver.starts.size):
            c0, c1 = solver.starts[s], solver.ends[s]
            w = c1 - c0
            rows = solver.rows[solver.row_ptr[s]:solver.row_ptr[s + 1]]
            panel = solver.panels[solver.panel_ptr[s]:solver.panel_ptr[s + 1]].reshape(-1, w)
            diag = np.tril(panel[:w])
            if w * (w + rows.size) >= _BLAS_MIN_WORK:  # stored inverted for the solves
                diag = np.linalg.inv(diag)
            rebuilt[c0:c1, c0:c1] = diag
            rebuilt[rows, c0:c1] = panel[w:]
        assert np.allclose(rebuilt, dense_l, atol=1e-12 * np.abs(dense_l).max())


@pytest.mark.parametrize("block", [1, 3, 8])
@pytest.mark.parametrize("diagonal_mass", [True, False])
def test_block_lanczos_equals_a_dense_eigensolver(block, diagonal_mass):
    """Shift-invert block Lanczos against LAPACK on a sphere Laplacian: degenerate eigenspaces (the
    multiplets 3, 5, 7, ... of the sphere), identity and consistent-mass inner products."""
    from corrlib.geometry.lanczos import block_lanczos

    s = trimesh.creation.icosphere(subdivisions=2)
    stiff, mass = mesh_laplacian(TriMesh(s.vertices, s.faces), mass="lumped" if diagonal_mass else "consistent")
    sigma = -1e-3
    if diagonal_mass:  # standard form M^-1/2 S M^-1/2
        d = mass.diagonal() ** -0.5
        a = (sp.diags(d) @ stiff @ sp.diags(d)).toarray()
        inverse = np.linalg.inv(a - sigma * np.eye(a.shape[0]))
        theta, vecs = block_lanczos(lambda x: inverse @ x, a.shape[0], 30, block=block, tol=1e-12)
        dense = np.linalg.eigvalsh(a)[:30]
        metric = np.eye(a.shape[0])
        residual = a @ vecs - vecs * (sigma + 1 / theta)
    else:
        inverse = np.linalg.inv((stiff - sigma * mass).toarray())
        theta, vecs = block_lanczos(lambda x: inverse @ (mass @ x), stiff.shape[0], 30, mass=mass, block=block,
                                    tol=1e-12)
        import scipy.linalg as sla

        dense = sla.eigh(stiff.toarray(), mass.toarray(), eigvals_only=True)[:30]
        metric = mass.toarray()
        residual = stiff @ vecs - (mass @ vecs) * (sigma + 1 / theta)
    evals = sigma + 1 / theta
    assert np.all(np.diff(theta) <= 0)
    assert np.allclose(evals, dense, rtol=1e-10, atol=1e-10)
    assert np.allclose(vecs.T @ metric @ vecs, np.eye(30), atol=1e-10)
    assert np.abs(residual).max() < 1e-8 * evals.max()


def test_block_lanczos_reports_what_did_not_converge():
    from corrlib.errors import SolverError
    from corrlib.geometry.lanczos import block_lanczos

    a = np.diag(np.linspace(1.0, 2.0, 700))  # a flat spectrum: far too slow for a small basis
    with pytest.raises(SolverError, match="have not converged with 96 basis vectors"):
        block_lanczos(lambda x: a @ x, 700, 40, block=8, max_dim=100, tol=1e-12)
    with pytest.raises(SolverError, match="need a basis larger"):
        block_lanczos(lambda x: a @ x, 700, 40, block=8, max_dim=40)


def test_cholesky_supernodal_solves_on_a_product_band():
    """A four-dimensional band (the product of two curves) has large dense supernodes: the BLAS path
    of the solves is taken, with blocks of right-hand sides and single vectors."""
    import scipy.sparse.linalg as spla

    from corrlib.geometry import product as pm
    from corrlib.geometry.cholesky import _BLAS_MIN_WORK, CholeskySolver

    t = np.linspace(0, 2 * np.pi, 160, endpoint=False)
    fx = pm.curve_factor(np.column_stack([np.cos(t), 0.6 * np.sin(t)]), 10)
    fy = pm.curve_factor(np.column_stack([1.2 * np.cos(t), np.sin(t)]), 10)
    width = 30
    pairs = np.column_stack([np.repeat(np.arange(160), width),
                             (np.arange(160)[:, None] + np.arange(width) - width // 2).ravel() % 160])
    stiff, mass = pm.product_operator(fx, fy, pairs)
    spd = (stiff + 1e-2 * mass).tocsc()
    solver = CholeskySolver(spd)
    work = (solver.ends - solver.starts) * (solver.ends - solver.starts + np.diff(solver.row_ptr))
    assert np.any(work >= _BLAS_MIN_WORK) and np.any(work < _BLAS_MIN_WORK)
    rhs = np.random.default_rng(1).standard_normal((spd.shape[0], 20))
    expected = spla.splu(spd).solve(rhs)
    for x in (solver.solve(rhs), np.column_stack([solver.solve(rhs[:, j]) for j in range(3)])):
        assert np.allclose(x, expected[:, :x.shape[1]], rtol=1e-8, atol=1e-10 * np.abs(expected).max())


@pytest.mark.parametrize("mass_kind", ["lumped", "consistent"])
@pytest.mark.parametrize("block_lanczos", [False, True])
def test_cholesky_shift_invert_equals_superlu_shift_invert(cat_pair, monkeypatch, mass_kind, block_lanczos):
    """The Cholesky path (ARPACK with CHOLMOD's solves, or block Lanczos with the supernodal solves) equals
    ARPACK with SuperLU, also near the singular shift of a closed surface (λ₀ = 0)."""
    import corrlib.geometry.spectrum as spectrum

    stiff, mass = mesh_laplacian(cat_pair[0], mass=mass_kind)
    w_lu, v_lu = eigenpairs(stiff, mass, 60, method="eigsh")
    monkeypatch.setattr(spectrum, "CHOLESKY_MIN_ROWS", 1000)  # the 5k cat takes the Cholesky path
    factored = []
    original = spectrum._ShiftInvert._cholesky
    monkeypatch.setattr(spectrum._ShiftInvert, "_cholesky",
                        lambda self, sigma, blocks=False: factored.append(original(self, sigma, blocks)) or factored[-1])
    w_ch, v_ch = eigenpairs(stiff, mass, 60, method="block" if block_lanczos else "eigsh")
    assert factored and factored[0] is not None
    assert np.allclose(w_ch, w_lu, rtol=1e-9, atol=1e-12)
    overlap = np.abs(np.einsum("ij,ij->j", v_lu, mass @ v_ch))
    simple = np.minimum(np.diff(w_lu, prepend=-1), np.diff(w_lu, append=1e9)) > 1e-6 * w_lu[-1]
    assert np.all(overlap[simple] > 1 - 1e-6)


def _glued_pillow(disk: TriMesh, boundary: np.ndarray) -> tuple[TriMesh, np.ndarray]:
    """Two copies of a planar disk glued along their boundary; returns the pillow and, per pillow vertex,
    the disk vertex it copies (the second copy's interior vertices are appended)."""
    n = disk.n_vertices
    interior = np.setdiff1d(np.arange(n), boundary)
    second = np.arange(n)
    second[interior] = n + np.arange(interior.size)
    vertices = np.vstack([disk.vertices, disk.vertices[interior]])
    faces = np.vstack([disk.faces, second[disk.faces][:, ::-1]])
    # validate=False: an edge between two boundary vertices is shared by both copies (four faces)
    return TriMesh(vertices, faces, name="pillow", validate=False), np.concatenate([np.arange(n), interior])


def test_doubled_spectrum_is_the_glued_pillow_spectrum():
    """The spectrum of two copies of a disk glued along the boundary is the union of the disk's Neumann and
    Dirichlet spectra, exactly also in the discrete setting (the swap of the copies is a symmetry of the
    cotangent Laplacian): compared with the Laplacian of the explicitly glued pillow, and with the analytic
    rectangle spectrum π²(i²/a² + j²/b²), i, j ≥ 0 (Neumann) and ≥ 1 (Dirichlet)."""
    from corrlib.geometry.spectrum import doubled_spectrum

    nx, ny, a, b = 32, 16, 2.0, 1.0
    x, y = np.meshgrid(np.linspace(0, a, nx + 1), np.linspace(0, b, ny + 1), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    idx = np.arange(x.size).reshape(nx + 1, ny + 1)
    p, q, r, s = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    disk = TriMesh(vertices, np.vstack([np.column_stack([p, q, r]), np.column_stack([p, r, s])]), name="rect")
    on_boundary = (np.isclose(vertices[:, 0], 0) | np.isclose(vertices[:, 0], a)
                   | np.isclose(vertices[:, 1], 0) | np.isclose(vertices[:, 1], b))
    boundary = np.flatnonzero(on_boundary)
    stiffness, mass = mesh_laplacian(disk)
    k = 12
    evals, evecs = doubled_spectrum(stiffness, mass, boundary, k, name="rect")
    pillow, copy_of = _glued_pillow(disk, boundary)
    p_stiff, p_mass = mesh_laplacian(pillow)
    p_evals, p_evecs = eigenpairs(p_stiff, p_mass, k)
    assert np.allclose(evals, p_evals, rtol=1e-8, atol=1e-8)
    # eigenfunctions of simple eigenvalues agree on the first copy, up to sign; normalised on the pillow
    simple = np.flatnonzero(np.min(np.abs(np.subtract.outer(evals, evals)) + np.eye(k) * 1e9, axis=1) > 1e-3)
    first = np.arange(disk.n_vertices)
    for j in simple:
        assert min(np.abs(evecs[:, j] - p_evecs[first, j]).max(), np.abs(evecs[:, j] + p_evecs[first, j]).max()) < 1e-6
    # Dirichlet functions vanish on the boundary; normalised on the pillow, i.e. orthonormal with respect to
    # twice the disk's mass within each parity (an odd and an even function are orthogonal on the pillow only)
    odd = np.abs(evecs[boundary]).max(axis=0) < 1e-12
    assert odd.any() and (~odd).any()
    for parity in (odd, ~odd):
        gram = evecs[:, parity].T @ (2 * mass) @ evecs[:, parity]
        assert np.allclose(gram, np.eye(int(parity.sum())), atol=1e-8)
    neumann = [np.pi ** 2 * (i * i / a ** 2 + j * j / b ** 2) for i in range(8) for j in range(8)]
    dirichlet = [np.pi ** 2 * (i * i / a ** 2 + j * j / b ** 2) for i in range(1, 8) for j in range(1, 8)]
    exact = np.sort(neumann + dirichlet)[:k]
    assert np.allclose(evals[1:], exact[1:], rtol=0.03)
    # with fewer interior vertices than k, all Dirichlet eigenpairs take part (the union is still complete)
    few = np.setdiff1d(np.arange(disk.n_vertices), [200, 201, 202])
    few_evals, few_evecs = doubled_spectrum(stiffness, mass, few, k, name="rect")
    expected = np.sort(np.concatenate([eigenpairs(stiffness, mass, k)[0],
                                       eigenpairs(stiffness[[200, 201, 202]][:, [200, 201, 202]],
                                                  mass[[200, 201, 202]][:, [200, 201, 202]], 3,
                                                  check_connected=False)[0]]))[:k]
    assert few_evecs.shape == (disk.n_vertices, k) and np.allclose(few_evals, expected)
