"""The intrinsic reflection of a shape and the spectrum of its half (corrlib.descriptors.symmetry)."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from corrlib.descriptors.symmetry import even_spectrum, mesh_reflection, mesh_reflections, reflection_map
from corrlib.errors import InputError, ParameterError
from corrlib.evaluation import geodesic_errors
from corrlib.geometry.spectrum import mesh_spectrum
from corrlib.io import load_mesh, load_vts
from corrlib.resources import resource
from corrlib.shapes import TriMesh

from tests._data import TOSCA, with_vertex_noise


def one_mirror_blob():
    """A stretched sphere with a bump in the plane y = 0: its only reflection is y -> -y.

    Returns the mesh and, for every vertex, the index of the vertex at its mirror position (the icosphere's
    vertex set is symmetric under every coordinate reflection, and the deformation keeps y -> -y).
    """
    sphere = trimesh.creation.icosphere(subdivisions=3)
    p = sphere.vertices
    bump_at = np.array([0.6, 0.0, 0.8])
    radius = 1.0 + 0.5 * np.exp(-np.sum((p - bump_at) ** 2, axis=1) / 0.15)
    v = p * radius[:, None] * np.array([1.8, 1.0, 1.2])
    mirror_of = cKDTree(v).query(v * np.array([1.0, -1.0, 1.0]))[1]
    return TriMesh(v, sphere.faces, name="blob"), mirror_of


def test_reflection_of_a_shape_with_one_mirror_plane():
    mesh, truth = one_mirror_blob()
    spectrum = mesh_spectrum(mesh, 60, use_cache=False)
    mirror = reflection_map(mesh, spectrum)
    assert np.mean(mirror == truth) > 0.95
    assert np.mean(mirror[mirror] == np.arange(mesh.n_vertices)) > 0.95  # an involution
    # the vertices on the plane of symmetry are its fixed points
    on_plane = np.abs(mesh.vertices[:, 1]) < 1e-9
    assert on_plane.sum() > 10 and np.mean(mirror[on_plane] == np.flatnonzero(on_plane)) > 0.9


def test_reflection_is_intrinsic_vertex_order_and_pose_free():
    """The same blob with its vertices shuffled, mirrored in x and rotated gives the same reflection."""
    mesh, truth = one_mirror_blob()
    rng = np.random.default_rng(3)
    perm = rng.permutation(mesh.n_vertices)
    inverse = np.argsort(perm)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    moved = TriMesh((mesh.vertices * np.array([-1.0, 1.0, 1.0]))[perm] @ rotation.T, inverse[mesh.faces],
                    name="moved")
    mirror = reflection_map(moved, mesh_spectrum(moved, 60, use_cache=False))
    # vertex i of `moved` is vertex perm[i] of the blob
    assert np.mean(perm[mirror] == truth[perm]) > 0.95


def test_a_pairs_reflections_side_by_side_equal_one_at_a_time(tmp_path, monkeypatch):
    import corrlib.descriptors.symmetry as symmetry

    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path))
    blob, _ = one_mirror_blob()
    rng = np.random.default_rng(3)
    perm = rng.permutation(blob.n_vertices)
    shuffled = TriMesh(blob.vertices[perm], np.argsort(perm)[blob.faces], name="shuffled")
    spectra = [mesh_spectrum(m, 60, use_cache=False) for m in (blob, shuffled)]
    alone = [reflection_map(m, s) for m, s in zip((blob, shuffled), spectra)]
    computed = []
    original = symmetry.reflection_map
    monkeypatch.setattr(symmetry, "reflection_map", lambda m, s: computed.append(m.name) or original(m, s))
    together = mesh_reflections((blob, shuffled), spectra)  # two threads, single-threaded BLAS
    assert all(np.array_equal(a, b) for a, b in zip(alone, together)) and sorted(computed) == ["blob", "shuffled"]
    # cached now: loaded, not computed; a mesh given twice (a self-match) is computed once
    assert all(np.array_equal(a, b) for a, b in zip(alone, mesh_reflections((blob, shuffled), spectra)))
    assert len(computed) == 2
    monkeypatch.setenv("CORRLIB_CACHE_DIR", str(tmp_path / "other"))
    twice = mesh_reflections((blob, blob), spectra[:1] * 2)
    assert np.array_equal(twice[0], alone[0]) and np.array_equal(twice[1], alone[0]) and len(computed) == 3


def test_reflection_of_the_cat_against_its_mirrored_ground_truth():
    """cat0.sym.vts row r is the mirror partner of cat0.vts row r (measured: mean 0.005, median 0)."""
    cat = load_mesh(TOSCA / "cat0.off")
    mirror = mesh_reflection(cat, mesh_spectrum(cat, 75))
    rows, partners = load_vts(TOSCA / "cat0.vts"), load_vts(TOSCA / "cat0.sym.vts")
    error = np.linalg.norm(cat.vertices[mirror[rows]] - cat.vertices[partners], axis=1) / np.sqrt(cat.area)
    without_reflection = np.linalg.norm(cat.vertices[rows] - cat.vertices[partners], axis=1) / np.sqrt(cat.area)
    assert error.mean() < 0.02 and without_reflection.mean() > 0.1


@pytest.mark.slow
def test_reflection_of_posed_people_searches_the_signs():
    """The person with a front of tests/_humanoid.py: exactly mirror-symmetric at rest, its limbs posed unlike
    their mirror limbs in the other poses. The least-squares start alone took wrong signs on the lowest
    eigenfunctions there (measured against the mirrored truth: 0.214, 0.122, 0.137 √area); with the sign
    search as a second start 0.070, 0.023, 0.004, and the rest pose stays exact."""
    from tests._humanoid import humanoids

    shapes, mirror = humanoids(front=True)
    errors = {}
    for name, (vertices, faces) in shapes.items():
        mesh = TriMesh(vertices, faces, name=name)
        reflection = reflection_map(mesh, mesh_spectrum(mesh, 100))
        errors[name] = geodesic_errors(reflection, mesh, np.arange(mesh.n_vertices), mirror).summary()["mean"]
    assert errors["human0"] < 0.01, errors
    assert max(errors.values()) < 0.1, errors


@pytest.mark.slow
def test_reflection_of_posed_people_on_finer_meshes():
    """The same people subdivided to four times the vertices (the vertices kept first, so the mirrored truth
    still holds on them): the same surfaces, the same reflections. Before, only the best-ranked sign candidate
    that reversed orientation on average was refined; on the finer human1 and human3 that was one which reverses
    half the body (a mean of -0.035 against -0.71 for the reflection), and the reflections were 0.227 and 0.137
    from the truth (0.070 and 0.004 on the coarse meshes). Every reversing candidate is now refined and the
    geodesic distortion chooses. The finer meshes also take ZoomOut through samples (more than 10,000
    vertices)."""
    from tests._humanoid import humanoids

    shapes, mirror = humanoids(front=True)
    errors = {}
    for name in ("human1", "human3"):
        vertices, faces = trimesh.remesh.subdivide(*shapes[name])
        mesh = TriMesh(vertices, faces, name=f"{name}-fine")
        reflection = reflection_map(mesh, mesh_spectrum(mesh, 60))
        errors[name] = geodesic_errors(reflection, mesh, np.arange(mirror.size), mirror).summary()["mean"]
    assert errors["human1"] < 0.09 and errors["human3"] < 0.01, errors


def test_the_posed_capsule_person_is_reflected_left_to_right():
    """The fourth bundled person (resources/people/human3.off, the capsule body of tests/_humanoid.py in the
    retrieval pose). The sign candidate of least distortion there keeps orientation over all vertices, yet read
    as reversing it on the evenly strided sample of 400; accepted, it ended as a mixture of the left-right and
    the front-back mirror (0.28 √area from the truth, measured). Read over all vertices, the search goes on to
    the true reflection."""
    from tests._humanoid import rest_pose

    person = load_mesh(resource("people/human3.off"))
    rest, _ = rest_pose()
    left_right = cKDTree(rest).query(rest * np.array([-1.0, 1.0, 1.0]))[1]  # vertex i is the same point in every pose
    reflection = reflection_map(person, mesh_spectrum(person, 75, use_cache=False))
    assert geodesic_errors(reflection, person, np.arange(person.n_vertices), left_right).summary()["mean"] < 0.01


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_reflection_of_a_posed_person_with_vertex_noise(seed):
    """Vertex noise of 0.1 % of the bounding box diagonal on the posed person with a front (human2): the odd
    descriptors are formed from gradients and normals and carry the noise, so the orientation of a sign
    candidate is read over all vertices (seed 1 misread on the sample: 0.23 √area from the mirrored truth,
    measured; 0.065 now, as for seed 2)."""
    from tests._humanoid import humanoids

    shapes, mirror = humanoids(front=True)
    mesh = with_vertex_noise(TriMesh(*shapes["human2"], name="human2"), seed)
    reflection = reflection_map(mesh, mesh_spectrum(mesh, 75, use_cache=False))
    assert geodesic_errors(reflection, mesh, np.arange(mesh.n_vertices), mirror).summary()["mean"] < 0.1


@pytest.mark.slow
def test_reflection_of_a_noisy_wolf_is_judged_by_geodesic_distances():
    """Vertex noise of 0.1 % of the bounding box diagonal on wolf1 (seed 2): the sign search's candidate swaps
    the front legs and distorts the biharmonic distances *less* than the true reflection (0.160 against
    0.177; the noise raises the true one twentyfold), but the geodesic distances twice as much; the map
    judged by them is the clean wolf's reflection (0.052 √area off before, measured)."""
    from corrlib.descriptors.symmetry import geodesic_distortion

    clean = load_mesh(TOSCA / "wolf1.off")
    noisy = with_vertex_noise(clean, 2)
    truth = reflection_map(clean, mesh_spectrum(clean, 60))
    reflection = reflection_map(noisy, mesh_spectrum(noisy, 60, use_cache=False))
    assert geodesic_errors(reflection, clean, np.arange(clean.n_vertices), truth).summary()["mean"] < 0.02
    assert geodesic_distortion(noisy, reflection) <= geodesic_distortion(noisy, truth) * 1.05


def test_geodesic_distortion_is_zero_for_an_exact_reflection_only():
    from corrlib.descriptors.symmetry import geodesic_distortion

    mesh, truth = one_mirror_blob()
    assert geodesic_distortion(mesh, truth) < 1e-9
    assert geodesic_distortion(mesh, np.arange(mesh.n_vertices)) < 1e-12  # the identity is an isometry too
    shuffled = np.random.default_rng(0).permutation(mesh.n_vertices)
    assert geodesic_distortion(mesh, shuffled) > 0.1
    # the vertex order does not enter: the samples are farthest points from the outermost vertex (on a shape
    # without the blob's exact ties of distance)
    rng = np.random.default_rng(1)
    uneven = TriMesh(mesh.vertices + rng.normal(scale=1e-3, size=mesh.vertices.shape), mesh.faces, name="uneven")
    order = rng.permutation(mesh.n_vertices)
    inverse = np.argsort(order)
    reordered = TriMesh(uneven.vertices[order], inverse[mesh.faces], name="uneven-reordered")
    assert geodesic_distortion(reordered, inverse[shuffled[order]]) == pytest.approx(
        geodesic_distortion(uneven, shuffled), rel=1e-12)


def test_geodesic_distortions_of_several_maps_equal_one_at_a_time():
    from corrlib.descriptors.symmetry import geodesic_distortion, geodesic_distortions

    mesh, truth = one_mirror_blob()
    shuffled = np.random.default_rng(0).permutation(mesh.n_vertices)
    together = geodesic_distortions(mesh, (shuffled, truth, np.arange(mesh.n_vertices)))
    assert together == [geodesic_distortion(mesh, m) for m in (shuffled, truth, np.arange(mesh.n_vertices))]
    assert together[0] > 0.1 > together[1]


def test_even_spectrum_is_the_spectrum_of_the_mirror_invariant_functions():
    mesh, truth = one_mirror_blob()
    spectrum = mesh_spectrum(mesh, 60, use_cache=False)
    evals, evecs = even_spectrum(spectrum, truth, 20)
    mass = spectrum.mass.diagonal()
    assert evals.shape == (20,) and evecs.shape == (mesh.n_vertices, 20)
    assert abs(evals[0]) < 1e-8 and np.all(np.diff(evals) >= -1e-12)
    np.testing.assert_allclose(evecs.T @ (mass[:, None] * evecs), np.eye(20), atol=1e-8)
    # even: unchanged by the reflection
    assert np.max(np.abs(evecs[truth] - evecs)) < 1e-6 * np.max(np.abs(evecs))
    # an exact symmetry: the even eigenvalues are those of the whole shape's eigenfunctions that the
    # reflection keeps (parity +1), the odd ones (parity -1) are left out
    parity = np.einsum("ij,ij->j", spectrum.evecs * mass[:, None], spectrum.evecs[truth])
    assert np.all(np.abs(np.abs(parity) - 1.0) < 1e-3)
    np.testing.assert_allclose(evals, spectrum.evals[parity > 0][:20], rtol=1e-8, atol=1e-10)
    assert (parity < 0).sum() > 10


def test_bad_arguments_are_named_errors():
    mesh, truth = one_mirror_blob()
    spectrum = mesh_spectrum(mesh, 30, use_cache=False)
    with pytest.raises(ParameterError, match="k_final"):
        reflection_map(mesh, spectrum, k_final=40)
    with pytest.raises(InputError, match="each of the"):
        even_spectrum(spectrum, truth[:-1], 5)
    with pytest.raises(ParameterError, match="even"):
        even_spectrum(spectrum, truth, 29)
