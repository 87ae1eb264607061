"""The on-disk cache trusts only the entry it asked for: damaged, foreign or malformed entries are dropped and
recomputed, an unusable cache folder is said once and bypassed, and no write leaves a temporary file."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from corrlib import cache
from corrlib.descriptors import mesh_descriptors
from corrlib.descriptors.symmetry import mesh_reflection
from corrlib.geometry.remeshing import remeshed
from corrlib.geometry.spectrum import mesh_spectrum
from corrlib.shapes import TriMesh


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(cache, "_UNUSABLE", set())
    return tmp_path / "cache"


def _blob(scale=(1.0, 1.0, 1.0), subdivisions=3):
    sphere = trimesh.creation.icosphere(subdivisions)
    v = sphere.vertices
    bumps = 1 + 0.4 * np.exp(-3 * ((v - [1, 0, 0]) ** 2).sum(1)) + 0.25 * np.exp(-5 * ((v - [0, 1, 0.3]) ** 2).sum(1))
    return TriMesh(v * bumps[:, None] * scale, sphere.faces, name="blob")


def _only_entry(folder):
    entries = list(folder.glob("*.npz"))
    assert len(entries) == 1
    return entries[0]


def test_an_entry_copied_from_another_mesh_of_the_same_size_is_not_used(own_cache):
    """Another mesh's spectrum in this mesh's place (same vertex count, every array well formed) was read as
    this mesh's: its key does not match, so it is dropped and the spectrum recomputed."""
    blob, other = _blob(), _blob(scale=(1.3, 0.8, 1.0))
    truth = mesh_spectrum(blob, 20, use_cache=False)
    mesh_spectrum(blob, 20)
    entry = _only_entry(own_cache / "spectra")
    mesh_spectrum(other, 20)
    foreign = next(path for path in (own_cache / "spectra").glob("*.npz") if path != entry)
    entry.write_bytes(foreign.read_bytes())
    again = mesh_spectrum(blob, 20)
    np.testing.assert_allclose(again.evals, truth.evals, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("damage", [
    {"evals": np.full(20, np.nan)},  # not finite
    {"evecs": np.zeros(642)},  # 1-D
    {"evals": np.array(3.0)},  # 0-d
    {"evals": np.array(["a"] * 20)},  # strings
    {"evecs": np.zeros((642, 5))},  # fewer eigenvectors than eigenvalues
    {"evals": None},  # missing
])
def test_a_malformed_spectrum_entry_is_recomputed(own_cache, damage):
    """Each of these gave a traceback, or a wrong map with exit 0, on every later run."""
    blob = _blob()
    truth = mesh_spectrum(blob, 20)
    path = _only_entry(own_cache / "spectra")
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    for name, value in damage.items():
        if value is None:
            del arrays[name]
        else:
            arrays[name] = value
    np.savez(path, **arrays)
    again = mesh_spectrum(blob, 20)
    np.testing.assert_allclose(again.evals, truth.evals, rtol=1e-9, atol=1e-12)
    assert again.evecs.shape == (blob.n_vertices, 20)


def test_a_lone_array_in_place_of_an_archive_is_recomputed(own_cache):
    blob = _blob()
    truth = mesh_descriptors(blob, "shot")
    path = _only_entry(own_cache / "descriptors")
    with open(path, "wb") as fh:
        np.save(fh, np.zeros(3))
    np.testing.assert_allclose(mesh_descriptors(blob, "shot"), truth)


def test_indices_out_of_range_in_a_remeshing_or_a_reflection_are_recomputed(own_cache):
    blob = _blob(subdivisions=4)
    first = remeshed(blob, 500)
    mirror = mesh_reflection(blob, mesh_spectrum(blob, 100))
    for kind, name in (("remeshed", "faces"), ("remeshed", "to_original"), ("reflections", "mirror")):
        path = _only_entry(own_cache / kind)
        with np.load(path) as data:
            arrays = {key: data[key] for key in data.files}
        arrays[name] = arrays[name].copy()
        arrays[name].flat[0] = 10 ** 6
        np.savez(path, **arrays)
    again = remeshed(blob, 500)
    np.testing.assert_array_equal(again.mesh.faces, first.mesh.faces)
    np.testing.assert_array_equal(again.to_original, first.to_original)
    np.testing.assert_array_equal(mesh_reflection(blob, mesh_spectrum(blob, 100)), mirror)


def test_conforms_checks_named_lengths_and_bounds_across_arrays():
    schema = {"points": cache.Array("f", ("n", 3)), "faces": cache.Array("i", (None, 3), below="n")}
    points, faces = np.zeros((4, 3)), np.array([[0, 1, 2], [1, 2, 3]])
    assert cache.conforms({"points": points, "faces": faces}, schema)
    assert not cache.conforms({"points": points, "faces": faces + 1}, schema)  # index 4 of 4 points
    assert not cache.conforms({"points": points, "faces": faces - 1}, schema)  # negative
    assert not cache.conforms({"points": points[:, :2], "faces": faces}, schema)
    assert not cache.conforms({"points": points, "faces": faces.astype(float)}, schema)
    lengths = {"a": cache.Array("f", ("k",)), "b": cache.Array("f", (5, "k"))}
    assert cache.conforms({"a": np.zeros(3), "b": np.zeros((5, 3))}, lengths)
    assert not cache.conforms({"a": np.zeros(3), "b": np.zeros((5, 2))}, lengths)


def test_an_entry_this_user_may_not_read_is_left_to_its_owner(own_cache, monkeypatch):
    """In a cache shared between users, an entry another user wrote (mode 0600) was taken for a corrupt one and
    deleted; it is now left alone and this run computes its own result."""
    blob = _blob()
    truth = mesh_spectrum(blob, 20)
    path = _only_entry(own_cache / "spectra")

    def not_mine(entry):
        raise PermissionError(13, "Permission denied", str(entry))

    monkeypatch.setattr(cache, "_read_npz", not_mine)
    monkeypatch.setattr(cache, "store", lambda *args: None)  # the owner's entry cannot be replaced either
    again = mesh_spectrum(blob, 20)
    assert path.exists()
    np.testing.assert_allclose(again.evals, truth.evals, rtol=1e-9, atol=1e-12)


def test_a_cache_folder_that_cannot_be_searched_is_said_once_and_bypassed(tmp_path, monkeypatch, capsys):
    """A cache path whose name is too long for the file system aborted every command ("file name too long");
    the computation now runs without the cache, with one warning that names the folder."""
    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path / ("c" * 300)))
    monkeypatch.setattr(cache, "_UNUSABLE", set())
    blob = _blob()
    first = mesh_spectrum(blob, 10)
    again = mesh_spectrum(blob, 10)
    np.testing.assert_array_equal(first.evals, again.evals)
    err = capsys.readouterr().err
    assert err.count("warning: the cache folder") == 1 and "cccc" in err and "CORRLIB_CACHE_DIR" in err


def test_a_failed_write_leaves_no_temporary_file(own_cache, monkeypatch):
    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    cache.store("spectra", "k" * 40, {"evals": np.zeros(3)})
    assert list((own_cache / "spectra").iterdir()) == []


def test_the_cache_folder_may_start_at_the_home_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("CORRLIB_CACHE_DIR", "~/corr-cache")
    assert cache.cache_dir() == tmp_path / "corr-cache"
