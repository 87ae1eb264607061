"""HKS / WKS: conventions, identities and invariance to pose."""

import numpy as np
import pytest

from corrlib.descriptors import hks, hks_times, mesh_descriptors, wks, wks_energies
from corrlib.errors import InputError, ParameterError
from corrlib.geometry.spectrum import mesh_spectrum


@pytest.fixture(scope="module")
def wolf_spectra(wolf_pair):
    return [mesh_spectrum(m, 100) for m in wolf_pair]


def test_scale_conventions(wolf_spectra):
    evals = wolf_spectra[0].evals
    t = hks_times(evals, 100)
    assert t[0] == pytest.approx(4 * np.log(10) / evals[-1]) and t[-1] == pytest.approx(4 * np.log(10) / evals[1])
    assert np.allclose(np.diff(np.log(t)), np.log(t[1] / t[0]))
    e = wks_energies(evals, 100)
    assert e[0] == pytest.approx(np.log(evals[1])) and e[-1] == pytest.approx(np.log(evals[-1]) / 1.02)


@pytest.mark.parametrize("fn", [hks, wks])
def test_normalised_descriptors_integrate_to_one(wolf_spectra, fn):
    # with M-orthonormal eigenvectors, sum_x M(x) phi_k(x)^2 = 1, so every normalised scale integrates to 1
    spec = wolf_spectra[0]
    desc = fn(spec.evals, spec.evecs, 50)
    assert desc.shape == (spec.evecs.shape[0], 50)
    assert np.allclose(spec.mass.diagonal() @ desc, 1.0, rtol=1e-8)
    assert np.all(desc >= 0)


def test_hks_matches_direct_sum(wolf_spectra):
    spec = wolf_spectra[0]
    t = np.array([10.0, 100.0])
    raw = hks(spec.evals, spec.evecs, times=t, normalize="none")
    direct = np.stack([(np.exp(-ti * spec.evals[1:]) * spec.evecs[:, 1:] ** 2).sum(axis=1) for ti in t], axis=1)
    assert np.allclose(raw, direct)


@pytest.mark.parametrize("fn", [hks, wks])
def test_pose_invariance(wolf_spectra, fn):
    a, b = (fn(s.evals, s.evecs, 100) for s in wolf_spectra)
    scale = np.median(np.abs(a))
    same = np.linalg.norm(a - b, axis=1) / scale
    perm = np.random.default_rng(0).permutation(a.shape[0])
    other = np.linalg.norm(a - b[perm], axis=1) / scale
    assert np.median(same) < 0.2 * np.median(other)
    assert np.mean(same < other) > 0.9


def test_descriptor_errors(wolf_spectra):
    spec = wolf_spectra[0]
    with pytest.raises(InputError, match="do not match"):
        hks(spec.evals[:10], spec.evecs, 10)
    with pytest.raises(InputError, match="at least 3"):
        wks(spec.evals[:2], spec.evecs[:, :2], 10)
    with pytest.raises(ParameterError, match="variance"):
        wks(spec.evals, spec.evecs, 10, variance=0)
    with pytest.raises(ParameterError, match="normalisation"):
        hks(spec.evals, spec.evecs, 10, normalize="l2")
    bad = spec.evecs.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        wks(spec.evals, bad, 10)


def test_mesh_descriptors_dispatch(wolf_pair):
    wolf = wolf_pair[0]
    assert mesh_descriptors(wolf, "wks").shape == (wolf.n_vertices, 100)
    assert mesh_descriptors(wolf, "shot").shape == (wolf.n_vertices, 352)
    with pytest.raises(ParameterError, match="unknown descriptor"):
        mesh_descriptors(wolf, "sift")


def test_descriptors_are_cached_by_mesh_content(wolf_pair, tmp_path, monkeypatch):
    import corrlib.descriptors.shot as shot_module
    from corrlib.shapes import TriMesh

    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    wolf = wolf_pair[0]
    first_shot, first_wks = mesh_descriptors(wolf, "shot"), mesh_descriptors(wolf, "wks")
    assert len(list((tmp_path / "descriptors").glob("*.npz"))) == 2

    def not_again(*args, **kwargs):
        raise AssertionError("SHOT recomputed although cached")

    monkeypatch.setattr(shot_module, "shot", not_again)
    copy = TriMesh(wolf.vertices.copy(), wolf.faces.copy())  # same content, another object
    assert np.array_equal(mesh_descriptors(copy, "shot"), first_shot)
    assert np.array_equal(mesh_descriptors(copy, "wks"), first_wks)
    # different content or parameters are different entries
    moved = TriMesh(wolf.vertices * 1.01, wolf.faces)
    with pytest.raises(AssertionError, match="recomputed"):
        mesh_descriptors(moved, "shot")
    assert mesh_descriptors(copy, "wks", n_scales=20).shape == (wolf.n_vertices, 20)
