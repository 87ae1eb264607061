"""Maps found on remeshed copies of fine meshes, carried back to the meshes' vertices (corrlib.geometry.lifting)."""

import numpy as np
import pytest
import trimesh

from corrlib.geometry.laplacian import mesh_laplacian
from corrlib.geometry.lifting import carried_basis, closest_surface_points, lifted_maps, matched_copy, nearest_lift
from corrlib.geometry.spectrum import mesh_spectrum
from corrlib.shapes import TriMesh


@pytest.fixture(scope="module")
def fine_sphere():
    ico = trimesh.creation.icosphere(subdivisions=5)  # 10,242 vertices
    return TriMesh(ico.vertices, ico.faces, name="fine sphere")


@pytest.fixture(scope="module")
def sphere_copy(fine_sphere):
    return matched_copy(fine_sphere, 2000)


def test_a_mesh_within_twice_the_budget_is_matched_as_it_is(fine_sphere):
    for budget in (0, 5121, 20000):
        copy = matched_copy(fine_sphere, budget)
        assert copy.mesh is fine_sphere and not copy.remeshed
    copy = matched_copy(fine_sphere, 5120)
    assert copy.remeshed and abs(copy.mesh.n_vertices - 5120) <= 60


def test_the_closest_surface_points_are_the_brute_force_ones(fine_sphere, sphere_copy):
    """Against trimesh's closest point over every triangle of the copy (an independent implementation), for
    every 20th vertex of the fine sphere and for points off the surface in and out."""
    from scipy.spatial import cKDTree
    from trimesh.triangles import closest_point

    from corrlib.geometry.lifting import STAR_CENTRES

    copy = sphere_copy.mesh
    points = np.vstack([fine_sphere.vertices[::20], 0.97 * fine_sphere.vertices[5::97],
                        1.04 * fine_sphere.vertices[7::97]])
    faces, weights = closest_surface_points(points, copy, cKDTree(copy.vertices).query(points, k=STAR_CENTRES)[1])
    assert np.all(weights >= 0) and np.allclose(weights.sum(axis=1), 1.0)
    found = np.einsum("pj,pjd->pd", weights, copy.vertices[copy.faces[faces]])
    triangles = copy.vertices[copy.faces]
    for point, mine in zip(points, found):
        reference = closest_point(triangles, np.repeat(point[None], len(triangles), axis=0))
        assert np.linalg.norm(mine - point) == pytest.approx(np.linalg.norm(reference - point, axis=1).min(),
                                                             abs=1e-12)


def test_the_carried_eigenfunctions_are_the_fine_spheres(fine_sphere, sphere_copy):
    """The copy's low eigenfunctions carried to the fine vertices keep their Rayleigh quotients under the fine
    mesh's own Laplacian (the sphere's l(l+1): 2, 6, 12) and are orthonormal under its mass, to within what
    the copy's resolution allows (the interpolation loses up to 3 % of the norm of the degree-3 functions)."""
    spectrum = mesh_spectrum(sphere_copy.mesh, 16)
    carried = carried_basis(spectrum, sphere_copy, fine_sphere)
    stiffness, mass = mesh_laplacian(fine_sphere)
    phi = carried.evecs
    gram = phi.T @ (mass @ phi)
    assert np.allclose(gram, np.eye(16), atol=0.04)
    quotients = np.einsum("ij,ij->j", phi, stiffness @ phi) / np.diag(gram)
    exact = np.array([0] + [2] * 3 + [6] * 5 + [12] * 7, dtype=float)
    assert np.allclose(quotients[1:], exact[1:], rtol=0.02)
    assert np.array_equal(carried.evals, spectrum.evals)


def test_a_copy_that_is_the_mesh_carries_nothing(fine_sphere):
    copy = matched_copy(fine_sphere, 0)
    spectrum = mesh_spectrum(fine_sphere, 6)
    assert carried_basis(spectrum, copy, fine_sphere) is spectrum
    identity = np.arange(fine_sphere.n_vertices)
    assert np.array_equal(nearest_lift(identity, copy, copy), identity)


def test_the_identity_of_the_copies_lifts_to_the_identity(fine_sphere, sphere_copy):
    """The copy matched to itself, carried to the fine sphere: the nearest lift is off by up to about a copy
    edge (the quantisation of the copy), the final steps in the carried basis bring every vertex home or next
    to it, and unmatched rows stay unmatched."""
    copy = sphere_copy
    identity = np.arange(copy.mesh.n_vertices)
    edge = np.sqrt(4 * np.pi / copy.mesh.n_vertices)  # about the copy's vertex spacing on the unit sphere
    lifted = nearest_lift(identity, copy, copy)
    offset = np.linalg.norm(fine_sphere.vertices[lifted] - fine_sphere.vertices, axis=1)
    assert offset.max() < 1.5 * edge and offset.mean() > 0.1 * edge
    map_copy = identity.copy()
    map_copy[:10] = -1
    spectrum = mesh_spectrum(copy.mesh, 60)
    map_xy, map_yx = lifted_maps(map_copy, map_copy, fine_sphere, fine_sphere, copy, copy, spectrum, spectrum, 60)
    matched = map_xy >= 0
    assert np.array_equal(matched, nearest_lift(map_copy, copy, copy) >= 0) and not matched.all()
    stepped = np.linalg.norm(fine_sphere.vertices[map_xy[matched]] - fine_sphere.vertices[matched], axis=1)
    assert stepped.mean() < 0.5 * offset[matched].mean()
